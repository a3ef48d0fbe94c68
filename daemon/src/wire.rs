//! The daemon's outgoing messages: poses, switches, and the engine's
//! refusals as rejections. Input messages are encoded and decoded, both
//! ways side by side, by [`slamd_protocol::codec`].

use crate::engine::EngineError;
use crate::geometry::Pose2;
use crate::gps::Georef;
use crate::graph::{GraphError, KeyframeId};
use slamd_protocol::codec::{gps_reason, reject, Origin};
use slamd_protocol::{Pose, Rejection, RejectionReason, Switch};

/// Keyframe `id`'s pose `p` in the map frame, with its ENU pose when the
/// map is georeferenced (zeros before).
pub fn pose_out(id: KeyframeId, p: &Pose2, georef: Option<&Georef>) -> Pose {
    let enu = georef.map_or(Pose2::new(0.0, 0.0, 0.0), |g| g.to_enu(p));
    Pose {
        id,
        x: p.x,
        y: p.y,
        theta: p.theta,
        east: enu.x,
        north: enu.y,
        heading: enu.theta,
    }
}

/// The filter's switch `weight` of the loop closure `from → to` that
/// frontend message `o` carried.
pub fn switch_out(from: KeyframeId, to: KeyframeId, o: Origin, weight: f64) -> Switch {
    Switch {
        from,
        to,
        frontend: o.frontend,
        reserved: 0,
        sequence: o.sequence,
        weight,
    }
}

/// The rejection for a change the engine refused.
pub fn engine_rejection(o: Origin, message: u32, ids: [u64; 2], e: &EngineError) -> Rejection {
    let reason = match e {
        EngineError::Graph(GraphError::DuplicateKeyframe(_)) => RejectionReason::DuplicateKeyframe,
        EngineError::Graph(GraphError::UnknownKeyframe(_)) => RejectionReason::UnknownKeyframe,
        EngineError::Graph(GraphError::SelfEdge(_)) => RejectionReason::SelfEdge,
        EngineError::Graph(GraphError::NonFinite(_)) => RejectionReason::NonFinite,
        EngineError::Graph(GraphError::Information(_)) => RejectionReason::NotPositiveDefinite,
        EngineError::Gps(e) => gps_reason(e),
        EngineError::FixKeyframe(_) => RejectionReason::UnknownKeyframe,
        _ => RejectionReason::Other,
    };
    reject(o, message, reason, ids, &e.to_string())
}
