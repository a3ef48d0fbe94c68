//! slamd's wire protocol over iceoryx2 shared memory.
//!
//! Frontends publish [`Keyframe`]s, [`Edge`]s and [`GpsFix`]es, then poke
//! the daemon with an event; the daemon publishes a [`SnapshotHeader`] plus
//! the [`Pose`]s that changed after each batch (and the whole map now and
//! then, [`MapSnapshot`]), a [`Rejection`] for every
//! message it refuses, and the outlier filter's [`Switch`] of every loop
//! closure when they change. All names live under one namespace ([`ServiceNames`]).
//!
//! - [`message`]: the `#[repr(C)]` types, identical in every process.
//! - [`service`]: service names and QoS numbers, in one place.
//! - [`snapshot`]: a subscriber's copy of the map, built from whole maps
//!   and the changes between them.
//! - [`codec`]: slamd's input types ([`slamd_types`]) to messages and
//!   back, every inbound field checked into a typed [`Rejection`].
//! - [`Frontend`]: what a frontend publishes with: numbered keyframes,
//!   edges and fixes, then a poke.
//! - [`transport`]: the only code in slamd that touches iceoryx2: the
//!   daemon's [`Ingress`](transport::Ingress) and
//!   [`Outlet`](transport::Outlet), the frontend's
//!   [`FrontendLink`](transport::FrontendLink) and
//!   [`SnapshotLink`](transport::SnapshotLink).
//!
//! A protocol version travels in every message and in every service's
//! attributes: a frontend built against another layout gets a clear error
//! at connect (or a rejection), never garbage.

#![deny(missing_docs)]

pub mod codec;
mod frontend;
pub mod message;
pub mod service;
pub mod snapshot;
pub mod transport;

pub use frontend::{Endpoint, Frontend, Waiting, SAY_EVERY};
pub use message::{
    DaemonStatus, Edge, EdgeKindWire, FrontendAck, GpsFix, Keyframe, Pose, Rejection, RejectionReason,
    SnapshotHeader, Switch, SwitchState, SwitchesHeader, INFORMATION_UPPER, MAX_FRONTENDS, POSE_PARAMS,
    PROTOCOL_VERSION, REJECTED_BELOW,
};
pub use service::ServiceNames;
pub use snapshot::MapSnapshot;
