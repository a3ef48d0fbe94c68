//! [`TransportError`]: what went wrong talking to the other side.

use std::fmt;

/// A transport failure, worded for the person running slamd.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum TransportError {
    /// No daemon serves this namespace (its services do not exist).
    NoDaemon {
        /// The namespace looked up.
        namespace: String,
    },
    /// The daemon speaks another protocol version.
    ProtocolMismatch {
        /// The service that disagreed.
        service: String,
    },
    /// The service holds another message layout (type name, size or
    /// alignment differ): a frontend built against other message types.
    IncompatibleLayout {
        /// The service that disagreed.
        service: String,
    },
    /// `/dev/shm` cannot hold the configured pools.
    SharedMemoryTooSmall {
        /// Bytes the pools need.
        need: u64,
        /// Bytes free.
        free: u64,
    },
    /// The daemon's queue stayed full past the backpressure timeout.
    Backpressure {
        /// The service that was full.
        service: String,
    },
    /// The daemon stopped answering and no daemon came back within the
    /// frontend's reconnect bound.
    DaemonGone {
        /// The namespace.
        namespace: String,
        /// Seconds waited.
        waited_s: f64,
    },
    /// Another daemon, alive, already serves this namespace.
    AlreadyServed {
        /// The namespace.
        namespace: String,
        /// That daemon's process id.
        pid: i32,
    },
    /// Any other iceoryx2 failure, with its operation and cause.
    Other {
        /// What was attempted.
        operation: String,
        /// iceoryx2's error.
        cause: String,
    },
}

impl TransportError {
    /// [`TransportError::Other`]: `operation` as given, `cause` as its
    /// `Debug` text.
    pub(crate) fn other(operation: &str, cause: impl fmt::Debug) -> Self {
        TransportError::Other {
            operation: operation.to_string(),
            cause: format!("{cause:?}"),
        }
    }
}

impl fmt::Display for TransportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TransportError::NoDaemon { namespace } => write!(
                f,
                "no slamd daemon serves namespace `{namespace}` (start one with `slamd run`, or set SLAMD_NAMESPACE)"
            ),
            TransportError::ProtocolMismatch { service } => write!(
                f,
                "`{service}` speaks another slamd protocol version than this build ({}); rebuild the frontend or the daemon",
                crate::PROTOCOL_VERSION
            ),
            TransportError::IncompatibleLayout { service } => write!(
                f,
                "`{service}` carries another message layout than this build; rebuild against the daemon's slamd-protocol"
            ),
            TransportError::SharedMemoryTooSmall { need, free } => write!(
                f,
                "/dev/shm has {} MiB free but the configured pools need {} MiB; enlarge /dev/shm or lower the buffer sizes",
                free / (1 << 20),
                need.div_ceil(1 << 20)
            ),
            TransportError::Backpressure { service } => {
                write!(f, "the daemon's `{service}` queue stayed full; it is not keeping up or has stopped")
            }
            TransportError::DaemonGone { namespace, waited_s } => write!(
                f,
                "the daemon serving `{namespace}` stopped answering and none came back within {waited_s:.1} s"
            ),
            TransportError::AlreadyServed { namespace, pid } => {
                write!(f, "namespace {namespace} is already served by slamd (pid {pid})")
            }
            TransportError::Other { operation, cause } => write!(f, "{operation}: {cause}"),
        }
    }
}

impl std::error::Error for TransportError {}
