//! The daemon's outgoing messages: poses, switches, and the engine's
//! refusals as rejections. Input messages are encoded and decoded, both
//! ways side by side, by [`slamd_protocol::codec`].

use crate::engine::{Engine, EngineError, EnginePose};
use crate::geometry::Pose2;
use crate::gps::Georef;
use crate::graph::{EdgeKind, GraphError, KeyframeId};
use crate::outliers::REJECTED_BELOW;
use slamd_protocol::codec::{gps_reason, reject, Origin};
use slamd_protocol::{Pose, Rejection, RejectionReason, Switch, SwitchesHeader, PROTOCOL_VERSION};
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

/// The switch of every loop closure of `engine`, in arrival order, and
/// their header for snapshot `version` (its `count` left 0: the transport
/// sets it).
pub fn switches_out<P: EnginePose>(engine: &Engine<P>, version: u64) -> (SwitchesHeader, Vec<Switch>) {
    let (graph, switches) = (engine.graph(), engine.switches());
    let edges = graph.edges();
    let loops = (0..edges.len()).filter(|&e| edges[e].kind != EdgeKind::Odometry);
    let out: Vec<Switch> = loops
        .map(|e| {
            let (edge, pending) = (&edges[e], engine.is_pending(e));
            let (from, to) = (graph.id_of(edge.from), graph.id_of(edge.to));
            switch_out(from, to, engine.edge_origin(e), switches[e], pending)
        })
        .collect();
    let pending = out.iter().filter(|s| s.pending != 0).count();
    let rejected = (out.iter())
        .filter(|s| s.weight < REJECTED_BELOW && s.pending == 0)
        .count();
    let header = SwitchesHeader {
        protocol: PROTOCOL_VERSION,
        pending: pending as u32,
        version,
        count: 0,
        rejected: rejected as u64,
    };
    (header, out)
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
