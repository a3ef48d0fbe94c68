//! What a frontend links to use slamd.
//!
//! With default features off, this crate links only `slamd-protocol` and
//! `slamd-types`: a frontend that publishes to a daemon compiles no
//! solver. The default feature `embedded` adds the in-process engine
//! (`Embedded`), the daemon on a thread (`Server`) and its `Config`.
//!
//! - [`Frontend`] publishes keyframes, edges and GPS fixes to a running daemon over
//!   shared memory; [`Snapshots`] reads the daemon's pose snapshots in
//!   place (blocking [`wait`](Snapshots::wait) or non-blocking
//!   [`latest`](Snapshots::latest)) and its rejections.
//! - `Embedded` is the same [`Publish`] API on an engine in this process,
//!   for applications that embed slamd instead of talking to a daemon.
//! - Both dimensions share one API, typed by the pose: `Frontend<Pose2>`
//!   (the default) publishes to a daemon serving 2-D graphs,
//!   `Frontend<Pose3>` to one serving 3-D graphs (`dimension = 3`), and
//!   [`Pose::pose`] reads a snapshot's pose back as either; [`Publish`]
//!   and `Embedded` take the same parameter.
//!
//! The example runs a daemon on a thread, so it needs `embedded`:
#![cfg_attr(feature = "embedded", doc = "```")]
#![cfg_attr(not(feature = "embedded"), doc = "```ignore")]
//! use slamd_client::{Config, EdgeInput, EdgeKind, Frontend, Information, Pose2, Publish, Server, Snapshots};
//! use std::time::Duration;
//!
//! // A daemon on a thread of this process (in production: `slamd run`).
//! let config = Config { namespace: format!("doc-client-{}", std::process::id()), ..Config::default() };
//! let server = Server::spawn(config.clone()).unwrap();
//!
//! let mut snapshots = Snapshots::open(&config.namespace).unwrap();
//! let mut frontend = Frontend::connect(&config).unwrap();
//! frontend.add_keyframe(0, 0, None).unwrap();
//! frontend.add_keyframe(1, 0, None).unwrap();
//! let step = EdgeInput::new(0, 1, Pose2::new(1.0, 0.0, 0.0), Information::identity(), EdgeKind::Odometry);
//! frontend.add_edge(&step).unwrap();
//! frontend.flush().unwrap();
//!
//! // the daemon may publish before the edge has joined keyframe 1 to the
//! // map: wait for the snapshot that holds both poses (`wait` gives None
//! // after 5 s of silence)
//! let snap = loop {
//!     let snap = snapshots.wait(Duration::from_secs(5)).unwrap().expect("a snapshot");
//!     if snap.poses().len() == 2 {
//!         break snap;
//!     }
//! };
//! assert_eq!(snap.header().keyframes, 2);
//! let p1 = snap.poses().iter().find(|p| p.id == 1).unwrap();
//! assert!((p1.x - 1.0).abs() < 1e-12);
//! drop(snap);
//! server.join().unwrap();
//! ```

#![deny(missing_docs)]

#[cfg(feature = "embedded")]
mod embedded;
mod publish;

#[cfg(feature = "embedded")]
pub use embedded::Embedded;
pub use publish::{ClientError, Publish};
#[cfg(feature = "embedded")]
pub use slamd::config::Config;
#[cfg(feature = "embedded")]
pub use slamd::engine::{EngineConfig, Snapshot};
#[cfg(feature = "embedded")]
pub use slamd::gps::GpsConfig;
#[cfg(feature = "embedded")]
pub use slamd::ipc::Server;
pub use slamd_protocol::transport::{SnapshotLink as Snapshots, SwitchesSample, TransportError};
pub use slamd_protocol::{
    Endpoint, Frontend, MapSnapshot, Pose, Rejection, RejectionReason, SnapshotHeader, Switch,
    SwitchesHeader, Waiting,
};
pub use slamd_types::{
    EdgeInput, EdgeKind, FixInput, Geodetic, Information, Information6, KeyframeId, Pose2, Pose3,
};
