//! The messages, as they sit in shared memory.
//!
//! Every type is `#[repr(C)]`, holds only integers, floats and fixed arrays,
//! and derives iceoryx2's `ZeroCopySend` with an explicit `type_name`: it is
//! self-contained, holds no pointers and has one layout in every process
//! (the contract of `iceoryx2-bb/elementary-traits/src/zero_copy_send.rs`).
//! iceoryx2 matches a service's type by name, size and alignment; the
//! protocol version in each message and in the services' attributes catches
//! the rest.

use iceoryx2::prelude::*;

/// The layout version of every message below. Bump it on any change.
pub const PROTOCOL_VERSION: u32 = 6;

/// Numbers that write a pose in [`Keyframe::guess`] and [`Edge::measurement`]:
/// the first 3 in the plane, all 7 in space.
pub const POSE_PARAMS: usize = 7;

/// Entries of an information matrix in [`Edge::information`]: the first 6
/// in the plane, all 21 in space.
pub const INFORMATION_UPPER: usize = 21;

/// Frontends whose progress a snapshot header reports.
pub const MAX_FRONTENDS: usize = 8;

/// What produced an edge, on the wire.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EdgeKindWire {
    /// Consecutive keyframes.
    Odometry = 0,
    /// A place-recognition match.
    LoopClosure = 1,
    /// Anything else.
    Other = 2,
    /// A loop closure the outlier filter never switches off.
    TrustedLoopClosure = 3,
}

impl EdgeKindWire {
    /// The kind encoded as `v`, if valid.
    pub fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Self::Odometry),
            1 => Some(Self::LoopClosure),
            2 => Some(Self::Other),
            3 => Some(Self::TrustedLoopClosure),
            _ => None,
        }
    }
}

/// A new keyframe.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("slamd::Keyframe")]
pub struct Keyframe {
    /// The frontend's id for it.
    pub id: u64,
    /// When it was taken (ns, the frontend's clock).
    pub timestamp_ns: u64,
    /// Initial pose in the map frame, valid if `has_guess != 0`: in the
    /// plane `(x, y, θ)` (m, m, rad) then zeros; in space `(x, y, z, qx,
    /// qy, qz, qw)` (m; a unit quaternion, REP-103 axes).
    pub guess: [f64; POSE_PARAMS],
    /// 1 when `guess` is set.
    pub has_guess: u32,
    /// The sending frontend.
    pub frontend: u32,
    /// The frontend's running message number.
    pub sequence: u64,
    /// [`PROTOCOL_VERSION`] of the sender.
    pub protocol: u32,
    /// 2 or 3: the dimension `guess` is written in and the daemon must serve.
    pub dimension: u32,
}

/// A relative-pose measurement `T_ij` with its information matrix.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("slamd::Edge")]
pub struct Edge {
    /// Keyframe `i`.
    pub from: u64,
    /// Keyframe `j`.
    pub to: u64,
    /// `T_ij`, written as [`Keyframe::guess`] is.
    pub measurement: [f64; POSE_PARAMS],
    /// Ω's upper triangle row by row, in g2o order: in the plane the first
    /// 6 over `(x, y, θ)`; in space all 21 over `(x, y, z, qx, qy, qz)`,
    /// the error of g2o's EdgeSE3.
    pub information: [f64; INFORMATION_UPPER],
    /// An [`EdgeKindWire`] as `u32`.
    pub kind: u32,
    /// The sending frontend.
    pub frontend: u32,
    /// The frontend's running message number.
    pub sequence: u64,
    /// [`PROTOCOL_VERSION`] of the sender.
    pub protocol: u32,
    /// 2 or 3, as in [`Keyframe::dimension`].
    pub dimension: u32,
}

/// A GPS fix attached to a keyframe.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("slamd::GpsFix")]
pub struct GpsFix {
    /// The keyframe it belongs to.
    pub keyframe: u64,
    /// WGS84 latitude (degrees).
    pub latitude: f64,
    /// WGS84 longitude (degrees).
    pub longitude: f64,
    /// Height above the ellipsoid (m), valid if `has_altitude != 0`.
    pub altitude: f64,
    /// Covariance of (east, north) in m², row-major 2×2.
    pub covariance: [f64; 4],
    /// Variance of the altitude (m²), read if `has_altitude != 0`: a 3-D
    /// daemon holds the keyframe's height to the fix with it; 0 leaves the
    /// height free.
    pub altitude_variance: f64,
    /// 1 when `altitude` (and `altitude_variance`) are set.
    pub has_altitude: u32,
    /// The sending frontend.
    pub frontend: u32,
    /// The frontend's running message number.
    pub sequence: u64,
    /// [`PROTOCOL_VERSION`] of the sender.
    pub protocol: u32,
    /// Zero.
    pub reserved: u32,
}

/// One pose of a snapshot, in the map frame (REP-103: x forward, y left,
/// z up). Both dimensions fill every field: a planar pose has `z = 0` and
/// the quaternion of its heading; a spatial pose's `theta` is its yaw.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("slamd::Pose")]
pub struct Pose {
    /// Keyframe id.
    pub id: u64,
    /// Map-frame x (m).
    pub x: f64,
    /// Map-frame y (m).
    pub y: f64,
    /// Map-frame z (m).
    pub z: f64,
    /// Orientation, a unit quaternion with `qw ≥ 0`: x part.
    pub qx: f64,
    /// y part.
    pub qy: f64,
    /// z part.
    pub qz: f64,
    /// Real part.
    pub qw: f64,
    /// Heading, the rotation about z (rad): in the plane the pose's own
    /// angle, in space the yaw of `R = R_z(yaw) R_y(pitch) R_x(roll)`.
    pub theta: f64,
    /// East of the geodetic origin (m), when the header says georeferenced.
    pub east: f64,
    /// North of the geodetic origin (m), when georeferenced.
    pub north: f64,
    /// Up from the geodetic origin (m), when georeferenced (0 in the plane).
    pub up: f64,
    /// Heading from east, counter-clockwise (rad), when georeferenced.
    pub heading: f64,
    /// The keyframe's [`Keyframe::timestamp_ns`] (0: the frontend gave
    /// none).
    pub timestamp_ns: u64,
}

impl Pose {
    /// The pose in the dimension the daemon serves: `(x, y, θ)` in the
    /// plane, `(x, y, z, qx, qy, qz, qw)` in space; `None` if a number is
    /// not finite or the quaternion is not of unit norm.
    pub fn pose<P: slamd_types::RigidMotion>(&self) -> Option<P> {
        if P::DIMENSION == 2 {
            P::from_params(&[self.x, self.y, self.theta])
        } else {
            P::from_params(&[self.x, self.y, self.z, self.qx, self.qy, self.qz, self.qw])
        }
    }
}

/// The outlier filter's current weight of one loop closure.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("slamd::Switch")]
pub struct Switch {
    /// Keyframe `i` of the edge.
    pub from: u64,
    /// Keyframe `j`.
    pub to: u64,
    /// The frontend that sent it (0: unknown).
    pub frontend: u32,
    /// 1 while the filter has not decided it: it is held out of the
    /// estimate, at weight 0.
    pub pending: u32,
    /// Its message number.
    pub sequence: u64,
    /// The switch `s ∈ [0, 1]`: the edge's information counts `s²` times;
    /// below 0.5 (and not pending) the filter holds it wrong.
    pub weight: f64,
}

/// A decided switch below this is a loop closure the filter holds wrong
/// (what `rejected` counts).
pub const REJECTED_BELOW: f64 = 0.5;

/// What the outlier filter holds of a loop closure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SwitchState {
    /// In the estimate: decided, weight at least [`REJECTED_BELOW`].
    Kept,
    /// Decided wrong: weight below [`REJECTED_BELOW`].
    Off,
    /// Not decided yet, held out of the estimate.
    Pending,
}

impl SwitchState {
    /// Every state, in this order.
    pub const ALL: [SwitchState; 3] = [SwitchState::Kept, SwitchState::Off, SwitchState::Pending];

    /// Its name: `"kept"`, `"off"` or `"pending"`.
    pub fn name(self) -> &'static str {
        match self {
            SwitchState::Kept => "kept",
            SwitchState::Off => "off",
            SwitchState::Pending => "pending",
        }
    }
}

impl Switch {
    /// What the filter holds of this loop closure.
    pub fn state(&self) -> SwitchState {
        if self.pending != 0 {
            SwitchState::Pending
        } else if self.weight < REJECTED_BELOW {
            SwitchState::Off
        } else {
            SwitchState::Kept
        }
    }
}

/// The header of a switch list; the payload is `count` [`Switch`]es, one
/// per loop closure, in arrival order.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("slamd::SwitchesHeader")]
pub struct SwitchesHeader {
    /// [`PROTOCOL_VERSION`] of the daemon.
    pub protocol: u32,
    /// How many of them are pending.
    pub pending: u32,
    /// The snapshot version these weights belong to.
    pub version: u64,
    /// Number of switches that follow.
    pub count: u64,
    /// How many of them are decided and below 0.5.
    pub rejected: u64,
}

/// How far the daemon has got with one frontend's messages.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("slamd::FrontendAck")]
pub struct FrontendAck {
    /// The frontend (0: unused slot).
    pub frontend: u32,
    /// Zero.
    pub reserved: u32,
    /// Every message of this frontend numbered up to here was taken in
    /// (applied, held for a missing keyframe, or rejected) and, with a
    /// state directory, is on disk.
    pub sequence: u64,
}

/// The daemon's status, daemon → frontends and operators, published with
/// every snapshot and on every tick: which daemon is serving, how far each
/// of the most recent frontends has got, and its health.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("slamd::DaemonStatus")]
pub struct DaemonStatus {
    /// [`PROTOCOL_VERSION`] of the daemon.
    pub protocol: u32,
    /// 1 while the journal cannot be written (a full disk):
    /// acknowledgements wait until it can.
    pub journal_failing: u32,
    /// Differs for every start of a daemon: a frontend that sees it change
    /// sends again what the new daemon has not acknowledged.
    pub instance: u64,
    /// When this daemon started (ns since the UNIX epoch).
    pub started_at_ns: u64,
    /// When it last wrote a checkpoint (0: not yet, or no state directory).
    pub checkpoint_at_ns: u64,
    /// Bytes in the journal (0 without a state directory).
    pub journal_bytes: u64,
    /// Frontends heard from in the last minute.
    pub frontends: u64,
    /// Batch latency over the last minute, from the first message the
    /// engine thread took to the snapshot out: median and 99th percentile
    /// (µs; 0 without batches).
    pub latency_p50_us: f64,
    /// See `latency_p50_us`.
    pub latency_p99_us: f64,
    /// The header of the last snapshot published (its acknowledgements
    /// are the ones below).
    pub snapshot: SnapshotHeader,
    /// Progress of the most recent frontends.
    pub acks: [FrontendAck; MAX_FRONTENDS],
}

impl DaemonStatus {
    /// How far `frontend` has got, if it is listed.
    pub fn ack_of(&self, frontend: u32) -> Option<u64> {
        (self.acks.iter())
            .find(|a| a.frontend == frontend && frontend != 0)
            .map(|a| a.sequence)
    }
}

/// The header of a pose snapshot; the payload is `poses` [`Pose`]s. On
/// `{ns}/poses` the payload is the whole map (`whole` 1); on `{ns}/changes`
/// it is the poses that changed since version `base` (new keyframes
/// included), or nothing with `whole` 1 when this version's map went out
/// whole on `{ns}/poses` instead.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[type_name("slamd::SnapshotHeader")]
pub struct SnapshotHeader {
    /// [`PROTOCOL_VERSION`] of the daemon.
    pub protocol: u32,
    /// The dimension the daemon serves: 2 or 3.
    pub dimension: u32,
    /// Increases with every snapshot of one daemon start (a restarted
    /// daemon counts again; its status names the start).
    pub version: u64,
    /// Number of poses that follow.
    pub poses: u64,
    /// χ² of the estimate.
    pub chi2: f64,
    /// When the estimate was solved (ns since the UNIX epoch).
    pub solved_at_ns: u64,
    /// Keyframes received so far.
    pub keyframes: u64,
    /// Edges received so far.
    pub edges: u64,
    /// Messages rejected so far (details on the rejection topic).
    pub rejected: u64,
    /// Edges and fixes waiting for a keyframe that has not arrived.
    pub held: u64,
    /// Re-solves completed.
    pub resolves: u64,
    /// GPS fixes received so far.
    pub fixes: u64,
    /// 1 when GPS has georeferenced the map: the poses' `east`, `north`,
    /// `heading` are valid, in the ENU frame at `origin`.
    pub georeferenced: u32,
    /// 1 when `origin` is set (the configured origin, or the first fix).
    pub has_origin: u32,
    /// The ENU frame's origin: WGS84 latitude, longitude (degrees), height
    /// above the ellipsoid (m).
    pub origin: [f64; 3],
    /// Progress of the most recent frontends.
    pub acks: [FrontendAck; MAX_FRONTENDS],
    /// 1 when `covariance` holds the marginal covariance of keyframe
    /// `covariance_keyframe`, the newest in the snapshot (the daemon's
    /// `snapshot.covariance` setting).
    pub has_covariance: u32,
    /// Loop closures held out of the estimate until the outlier filter
    /// decides them (0 from a daemon that holds none).
    pub pending: u32,
    /// The keyframe whose covariance `covariance` is.
    pub covariance_keyframe: u64,
    /// Its covariance's upper triangle row by row, in the pose's own frame
    /// (GTSAM's `Marginals`, though its Pose3 puts the rotation first):
    /// the first 6 over `(x, y, θ)` in
    /// the plane, all 21 over `(x, y, z, rx, ry, rz)` in space (m, rad;
    /// the rotation as a rotation vector). Relative to the gauge keyframe.
    pub covariance: [f64; INFORMATION_UPPER],
    /// On `{ns}/changes`: the version whose map these poses change (the
    /// previous one published). 0 on `{ns}/poses`.
    pub base: u64,
    /// The daemon start that published it, as [`DaemonStatus::instance`]:
    /// versions count again after a restart.
    pub instance: u64,
    /// 1 when this version's map is whole: the payload on `{ns}/poses`; on
    /// `{ns}/changes`, a sample without poses saying to read it there.
    pub whole: u32,
    /// 1 while the daemon still works on the input so far (input came
    /// within a tick, a re-solve runs, the outlier filter has not caught
    /// up); 0 on the settled map, which the daemon publishes once that
    /// work is done: the final map of a stream.
    pub settling: u32,
}

impl SnapshotHeader {
    /// The number through which every message of `frontend` was taken in.
    pub fn ack_of(&self, frontend: u32) -> Option<u64> {
        self.acks
            .iter()
            .find(|a| a.frontend == frontend && frontend != 0)
            .map(|a| a.sequence)
    }
}

/// Why a message was refused.
#[repr(u32)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RejectionReason {
    /// A NaN or infinite number.
    NonFinite = 1,
    /// An information matrix or covariance that is not positive definite.
    NotPositiveDefinite = 2,
    /// An edge or fix names a keyframe that never arrived in time.
    UnknownKeyframe = 3,
    /// A keyframe id that already exists.
    DuplicateKeyframe = 4,
    /// An edge from a keyframe to itself.
    SelfEdge = 5,
    /// A message built against another protocol version.
    ProtocolVersion = 6,
    /// An edge kind outside [`EdgeKindWire`].
    BadKind = 7,
    /// A GPS fix out of range (|lat| > 90, |lon| > 180).
    OutOfRange = 8,
    /// Too many edges waiting for keyframes; the oldest was dropped.
    HeldOverflow = 9,
    /// Any other refusal; see the text.
    Other = 10,
    /// A message of the other dimension: each daemon serves one.
    Dimension = 11,
    /// A code this build does not know.
    Unknown = 0,
}

impl RejectionReason {
    /// Decodes a reason, [`Self::Unknown`] for anything new.
    pub fn from_u32(v: u32) -> Self {
        match v {
            1 => Self::NonFinite,
            2 => Self::NotPositiveDefinite,
            3 => Self::UnknownKeyframe,
            4 => Self::DuplicateKeyframe,
            5 => Self::SelfEdge,
            6 => Self::ProtocolVersion,
            7 => Self::BadKind,
            8 => Self::OutOfRange,
            9 => Self::HeldOverflow,
            10 => Self::Other,
            11 => Self::Dimension,
            _ => Self::Unknown,
        }
    }
}

/// Which message a rejection refers to.
pub mod kind {
    /// A keyframe.
    pub const KEYFRAME: u32 = 1;
    /// An edge.
    pub const EDGE: u32 = 2;
    /// A GPS fix.
    pub const GPS: u32 = 3;
}

/// A refused message, with the reason in words.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("slamd::Rejection")]
pub struct Rejection {
    /// The frontend that sent it.
    pub frontend: u32,
    /// A [`RejectionReason`] as `u32`.
    pub reason: u32,
    /// Its message number.
    pub sequence: u64,
    /// [`kind`] of message.
    pub message: u32,
    /// Zero.
    pub reserved: u32,
    /// The ids involved (keyframe; edge ends).
    pub ids: [u64; 2],
    /// NUL-padded UTF-8 explanation.
    pub text: [u8; 120],
}

impl Rejection {
    /// Builds a rejection, cutting `text` at a character boundary to fit.
    pub fn new(
        frontend: u32,
        sequence: u64,
        message: u32,
        reason: RejectionReason,
        ids: [u64; 2],
        text: &str,
    ) -> Self {
        let mut buf = [0u8; 120];
        let mut end = text.len().min(buf.len());
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        buf[..end].copy_from_slice(&text.as_bytes()[..end]);
        Self {
            frontend,
            reason: reason as u32,
            sequence,
            message,
            reserved: 0,
            ids,
            text: buf,
        }
    }

    /// The reason.
    pub fn reason(&self) -> RejectionReason {
        RejectionReason::from_u32(self.reason)
    }

    /// The explanation.
    pub fn text(&self) -> &str {
        let end = self.text.iter().position(|&b| b == 0).unwrap_or(self.text.len());
        std::str::from_utf8(&self.text[..end]).unwrap_or("(invalid text)")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_round_trip_and_unknown_codes_are_tolerated() {
        for r in [
            RejectionReason::NonFinite,
            RejectionReason::HeldOverflow,
            RejectionReason::Other,
        ] {
            assert_eq!(RejectionReason::from_u32(r as u32), r);
        }
        assert_eq!(RejectionReason::from_u32(999), RejectionReason::Unknown);
        assert_eq!(EdgeKindWire::from_u32(3), Some(EdgeKindWire::TrustedLoopClosure));
        assert_eq!(EdgeKindWire::from_u32(4), None);
    }

    #[test]
    fn a_switch_is_kept_at_one_half_off_below_and_pending_while_undecided() {
        let s = |weight, pending| Switch {
            weight,
            pending,
            ..Switch::default()
        };
        assert_eq!(s(0.5, 0).state(), SwitchState::Kept);
        assert_eq!(s(0.499, 0).state(), SwitchState::Off);
        assert_eq!(s(1.0, 1).state(), SwitchState::Pending);
        assert_eq!(SwitchState::Off.name(), "off");
    }

    #[test]
    fn rejection_text_is_cut_at_a_character_boundary() {
        let long = "é".repeat(100);
        let r = Rejection::new(1, 2, kind::EDGE, RejectionReason::Other, [0, 0], &long);
        assert_eq!(r.text().chars().count(), 60);
        assert_eq!(r.reason(), RejectionReason::Other);
    }

    #[test]
    fn layouts_are_what_the_protocol_says() {
        assert_eq!(std::mem::size_of::<Keyframe>(), 96);
        assert_eq!(std::mem::size_of::<Edge>(), 264);
        assert_eq!(std::mem::size_of::<GpsFix>(), 96);
        assert_eq!(std::mem::size_of::<Pose>(), 112);
        assert_eq!(std::mem::size_of::<SnapshotHeader>(), 456);
        assert_eq!(std::mem::size_of::<DaemonStatus>(), 648);
        assert_eq!(std::mem::size_of::<Switch>(), 40);
        assert_eq!(std::mem::size_of::<SwitchesHeader>(), 32);
        assert_eq!(std::mem::size_of::<Rejection>(), 160);
        assert_eq!(std::mem::offset_of!(Pose, timestamp_ns), 104);
        assert_eq!(std::mem::offset_of!(SnapshotHeader, acks), 120);
        assert_eq!(std::mem::offset_of!(SnapshotHeader, has_covariance), 248);
        assert_eq!(std::mem::offset_of!(SnapshotHeader, covariance_keyframe), 256);
        assert_eq!(std::mem::offset_of!(SnapshotHeader, covariance), 264);
        assert_eq!(std::mem::offset_of!(DaemonStatus, snapshot), 64);
        assert_eq!(std::mem::offset_of!(SnapshotHeader, base), 432);
        assert_eq!(std::mem::offset_of!(SnapshotHeader, whole), 448);
        assert_eq!(std::mem::offset_of!(DaemonStatus, acks), 520);
        assert_eq!(std::mem::align_of::<SnapshotHeader>(), 8);
    }
}
