//! [`EngineError`]: why the engine refused a change.

use crate::gps::GpsError;
use crate::graph::{GraphError, KeyframeId};
use crate::sparse::dynamic::UpdateError;
use std::fmt;

/// Why the engine refused a change. A refused change is not stored.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum EngineError {
    /// The graph refused it (duplicate or unknown id, self-edge, NaN).
    Graph(GraphError),
    /// No edge has this index.
    UnknownEdge(usize),
    /// A weight that is negative or not finite.
    InvalidWeight(f64),
    /// Odometry edges are never switched off.
    OdometrySwitch(usize),
    /// A downdate lost positive definiteness; the engine refactorised.
    Numeric(UpdateError),
    /// A GPS fix out of range, non-finite, or with a bad covariance.
    Gps(GpsError),
    /// A GPS fix for a keyframe that has not arrived.
    FixKeyframe(KeyframeId),
    /// A saved map could not be taken up.
    Restore(String),
    /// Something this dimension's engine does not do.
    Unsupported(&'static str),
    /// A marginal covariance that cannot be read: the keyframe has no edge
    /// to the map yet, the graph leaves it a free direction, or no
    /// Gauss–Newton system is kept.
    NoCovariance(KeyframeId, &'static str),
}

impl fmt::Display for EngineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EngineError::Graph(e) => e.fmt(f),
            EngineError::UnknownEdge(e) => write!(f, "no edge with index {e}"),
            EngineError::InvalidWeight(w) => write!(f, "edge weight {w} is not a finite number ≥ 0"),
            EngineError::OdometrySwitch(e) => write!(f, "edge {e} is odometry and cannot be switched off"),
            EngineError::Numeric(e) => write!(f, "{e}; refactorised"),
            EngineError::Gps(e) => e.fmt(f),
            EngineError::FixKeyframe(id) => write!(f, "GPS fix for unknown keyframe {id}"),
            EngineError::Restore(e) => write!(f, "cannot restore the map: {e}"),
            EngineError::Unsupported(what) => f.write_str(what),
            EngineError::NoCovariance(id, why) => write!(f, "no covariance for keyframe {id}: {why}"),
        }
    }
}

impl std::error::Error for EngineError {}

impl From<GraphError> for EngineError {
    fn from(e: GraphError) -> Self {
        EngineError::Graph(e)
    }
}
