//! [`Publish`]: the calls a frontend makes, whoever solves.

#[cfg(feature = "embedded")]
use slamd::engine::EngineError;
use slamd_protocol::transport::TransportError;
use slamd_protocol::Frontend;
use slamd_types::{EdgeInput, FixInput, KeyframeId, Pose2, RigidMotion};
use std::fmt;

/// A failed call: the transport (daemon) or the engine (embedded) refused.
#[derive(Debug)]
#[non_exhaustive]
pub enum ClientError {
    /// Publishing to the daemon failed.
    Transport(TransportError),
    /// The in-process engine refused the change.
    #[cfg(feature = "embedded")]
    Engine(EngineError),
}

impl fmt::Display for ClientError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ClientError::Transport(e) => e.fmt(f),
            #[cfg(feature = "embedded")]
            ClientError::Engine(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for ClientError {}

impl From<TransportError> for ClientError {
    fn from(e: TransportError) -> Self {
        ClientError::Transport(e)
    }
}

#[cfg(feature = "embedded")]
impl From<EngineError> for ClientError {
    fn from(e: EngineError) -> Self {
        ClientError::Engine(e)
    }
}

/// Keyframes, edges and GPS fixes in, a new snapshot at each flush. Implemented by
/// [`Frontend`] (a daemon over shared memory) and
/// `Embedded` (an engine in this process; feature `embedded`), so a frontend
/// can be written once for both.
///
/// A daemon checks what it receives asynchronously and reports refusals on
/// its rejection topic; an embedded engine refuses at once, in the `Err`.
pub trait Publish<P: RigidMotion = Pose2> {
    /// A new keyframe, with an initial guess in the map frame if known.
    fn add_keyframe(
        &mut self,
        id: KeyframeId,
        timestamp_ns: u64,
        guess: Option<P>,
    ) -> Result<(), ClientError>;
    /// A new edge between keyframes (which may arrive later, for a daemon).
    fn add_edge(&mut self, edge: &EdgeInput<P>) -> Result<(), ClientError>;
    /// A GPS fix taken at a keyframe (which may arrive later, for a daemon).
    fn add_gps(&mut self, fix: &FixInput) -> Result<(), ClientError>;
    /// Marks the end of a batch: the solver takes it in and publishes.
    fn flush(&mut self) -> Result<(), ClientError>;
}

impl<P: RigidMotion> Publish<P> for Frontend<P> {
    fn add_keyframe(
        &mut self,
        id: KeyframeId,
        timestamp_ns: u64,
        guess: Option<P>,
    ) -> Result<(), ClientError> {
        Frontend::add_keyframe(self, id, timestamp_ns, guess)?;
        Ok(())
    }

    fn add_edge(&mut self, edge: &EdgeInput<P>) -> Result<(), ClientError> {
        Frontend::add_edge(self, edge)?;
        Ok(())
    }

    fn add_gps(&mut self, fix: &FixInput) -> Result<(), ClientError> {
        Frontend::add_gps(self, fix)?;
        Ok(())
    }

    fn flush(&mut self) -> Result<(), ClientError> {
        Frontend::flush(self)?;
        Ok(())
    }
}
