//! The iceoryx2 transport: every port slamd opens, behind concrete types.
//!
//! - [`Ingress`]: the daemon's input side. It creates every service of its
//!   namespace (full QoS, protocol attribute), subscribes to keyframes,
//!   edges and GPS fixes, and blocks on a WaitSet until a frontend pokes
//!   it, SIGINT or SIGTERM arrives, or its timer ticks.
//! - [`Outlet`]: the daemon's output side (snapshots and rejections), opened
//!   on the thread that publishes (iceoryx2 ports are not `Send`).
//! - [`FrontendLink`]: what a frontend publishes with. It only opens
//!   services, so a missing daemon is a clear error, not a silent creation.
//! - [`SnapshotLink`]: what a frontend or monitor reads snapshots with.
//!
//! Every role reaches a service through the one builder for it in
//! `services` (the daemon creates, everyone else opens), and every
//! iceoryx2 failure is worded by its error type in `classify`.

mod classify;
mod daemon;
mod error;
mod frontend;
mod services;
pub mod shm;
mod snapshots;

pub use daemon::{Exit, Ingress, Input, Outlet, Wake};
pub use error::TransportError;
pub use frontend::FrontendLink;
pub use snapshots::{SnapshotLink, SwitchesSample};

use crate::message::PROTOCOL_VERSION;
use crate::service::PROTOCOL_KEY;
use iceoryx2::prelude::*;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue, AttributeVerifier};

/// The attribute requirement every slamd service carries.
pub(crate) fn protocol_attributes() -> AttributeVerifier {
    let key = AttributeKey::try_from(PROTOCOL_KEY).expect("short key");
    let value = AttributeValue::try_from(PROTOCOL_VERSION.to_string().as_str()).expect("short value");
    AttributeVerifier::new()
        .require(&key, &value)
        .expect("one attribute")
}

/// A node for one slamd process role; signals are handled by slamd's own
/// loops (the daemon's WaitSet), so frontends do not intercept them.
pub(crate) fn node(name: &str, handle_signals: bool) -> Result<Node<ipc::Service>, TransportError> {
    static QUIET: std::sync::Once = std::sync::Once::new();
    QUIET.call_once(quiet_logs);
    let mode = if handle_signals {
        SignalHandlingMode::HandleTerminationRequests
    } else {
        SignalHandlingMode::Disabled
    };
    let name = NodeName::new(name).map_err(|e| TransportError::other("node name", e))?;
    NodeBuilder::new()
        .name(&name)
        .signal_handling_mode(mode)
        .create::<ipc::Service>()
        .map_err(|e| TransportError::other("create node", e))
}

/// Parses a service name.
/// The newest sample `subscriber` was delivered since the last call,
/// copied out, if any (never blocks): the reading of a latest-value topic.
pub(crate) fn newest<T>(
    subscriber: &iceoryx2::port::subscriber::Subscriber<ipc::Service, T, ()>,
    what: &str,
) -> Result<Option<T>, TransportError>
where
    T: std::fmt::Debug + Copy + ZeroCopySend,
{
    let mut newest = None;
    while let Some(s) = subscriber
        .receive()
        .map_err(|e| TransportError::other(&format!("receive {what}"), e))?
    {
        newest = Some(*s.payload());
    }
    Ok(newest)
}

pub(crate) fn service_name(name: &str) -> Result<ServiceName, TransportError> {
    ServiceName::new(name).map_err(|e| TransportError::other(&format!("service name `{name}`"), e))
}

/// Lowers iceoryx2's own log output to errors: at start it warns that no
/// `iceoryx2.toml` was found, which is how slamd runs. Done once, before
/// the first node.
pub fn quiet_logs() {
    iceoryx2::prelude::set_log_level(LogLevel::Error);
}
