//! The daemon's outgoing messages: poses, switches, and the engine's
//! refusals as rejections. Input messages are encoded and decoded, both
//! ways side by side, by [`slamd_protocol::codec`].

use crate::engine::EngineError;
use crate::geometry::Pose2;
use crate::gps::Georef;
use crate::graph::{GraphError, KeyframeId};
use slamd_protocol::codec::{gps_reason, reject, Origin};
use slamd_protocol::{Pose, Rejection, RejectionReason, Switch};
use slamd_types::RigidMotion;

/// Keyframe `id`'s pose `p` in the map frame and its timestamp, with its
/// ENU position and heading when the map is georeferenced (zeros before).
pub fn pose_out<P: RigidMotion>(id: KeyframeId, p: &P, timestamp_ns: u64, georef: Option<&Georef>) -> Pose {
    let [x, y, z] = p.position3();
    let [qx, qy, qz, qw] = p.orientation();
    let theta = p.heading();
    let enu = georef.map_or(Pose2::new(0.0, 0.0, 0.0), |g| g.to_enu(&Pose2::new(x, y, theta)));
    Pose {
        id,
        x,
        y,
        z,
        qx,
        qy,
        qz,
        qw,
        theta,
        east: enu.x,
        north: enu.y,
        up: georef.map_or(0.0, |g| z + g.up),
        heading: enu.theta,
        timestamp_ns,
    }
}

/// The filter's switch `weight` of the loop closure `from → to` that
/// frontend message `o` carried.
pub fn switch_out(from: KeyframeId, to: KeyframeId, o: Origin, weight: f64, pending: bool) -> Switch {
    Switch {
        from,
        to,
        frontend: o.frontend,
        pending: u32::from(pending),
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
