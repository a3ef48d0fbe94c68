//! Service names and quality-of-service numbers, in one place.

/// The attribute key carrying [`PROTOCOL_VERSION`](crate::PROTOCOL_VERSION)
/// on every service.
pub const PROTOCOL_KEY: &str = "slamd.protocol";

/// The namespace slamd uses unless configured otherwise.
pub const DEFAULT_NAMESPACE: &str = "slamd";

/// The services of one namespace: `{ns}/keyframes`, `{ns}/edges`,
/// `{ns}/gps`, `{ns}/poses`, `{ns}/changes`, `{ns}/rejections`, `{ns}/switches`,
/// `{ns}/status`, and the events `{ns}/ingest`
/// (frontends → daemon) and `{ns}/published` (daemon → subscribers).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ServiceNames {
    /// Keyframes, frontends → daemon.
    pub keyframes: String,
    /// Edges, frontends → daemon.
    pub edges: String,
    /// GPS fixes, frontends → daemon.
    pub gps: String,
    /// Whole pose snapshots, daemon → subscribers.
    pub poses: String,
    /// What each snapshot changed, daemon → subscribers.
    pub changes: String,
    /// Rejections, daemon → frontends.
    pub rejections: String,
    /// Loop-closure switches, daemon → subscribers.
    pub switches: String,
    /// The daemon's status and acknowledgements, daemon → frontends.
    pub status: String,
    /// "New input" event, frontends → daemon.
    pub ingest: String,
    /// "New snapshot" event, daemon → subscribers.
    pub published: String,
}

impl ServiceNames {
    /// The names under `namespace` (trailing slashes ignored).
    pub fn new(namespace: &str) -> Self {
        let ns = namespace.trim_end_matches('/');
        let n = |s: &str| format!("{ns}/{s}");
        Self {
            keyframes: n("keyframes"),
            edges: n("edges"),
            gps: n("gps"),
            poses: n("poses"),
            changes: n("changes"),
            rejections: n("rejections"),
            switches: n("switches"),
            status: n("status"),
            ingest: n("ingest"),
            published: n("published"),
        }
    }
}

/// Sizes of the services. The daemon creates them with these; frontends
/// open whatever the daemon created.
#[derive(Clone, Debug, PartialEq)]
pub struct Qos {
    /// Frontends (publishers) per input service.
    pub max_frontends: usize,
    /// Snapshot subscribers.
    pub max_subscribers: usize,
    /// Keyframes the daemon's queue holds.
    pub keyframe_buffer: usize,
    /// Edges the daemon's queue holds.
    pub edge_buffer: usize,
    /// GPS fixes the daemon's queue holds.
    pub gps_buffer: usize,
    /// Poses the snapshot publisher reserves at start (grows by powers of 2).
    pub initial_poses: usize,
    /// Changed poses one sample of `{ns}/changes` holds at most; a snapshot
    /// that changed more goes out whole on `{ns}/poses`.
    pub max_changes: usize,
    /// Samples of `{ns}/changes` a subscriber's queue holds (and the
    /// topic's history, for a late subscriber).
    pub change_buffer: usize,
    /// Rejections kept for late subscribers.
    pub rejection_history: usize,
}

impl Default for Qos {
    fn default() -> Self {
        Self {
            max_frontends: 16,
            max_subscribers: 8,
            keyframe_buffer: 1024,
            edge_buffer: 4096,
            gps_buffer: 1024,
            initial_poses: 16384,
            max_changes: 256,
            change_buffer: 32,
            rejection_history: 16,
        }
    }
}

impl Qos {
    /// Shared memory the services need at start, in bytes: every
    /// subscriber's queue plus what publishers loan, for inputs and for one
    /// snapshot of `initial_poses` (which grows later).
    pub fn shared_memory_bytes(&self) -> u64 {
        use crate::message::*;
        use std::mem::size_of;
        let inputs = self.max_frontends as u64
            * (self.keyframe_buffer * size_of::<Keyframe>()
                + self.edge_buffer * size_of::<Edge>()
                + self.gps_buffer * size_of::<GpsFix>()) as u64;
        // each subscriber: buffer 1 + borrowed 2, plus history 1 and a loan
        let snapshot = (self.max_subscribers as u64 * 3 + 2)
            * (self.initial_poses * size_of::<Pose>() + size_of::<SnapshotHeader>()) as u64;
        let rejections = (self.max_subscribers as u64 * 16 + self.rejection_history as u64)
            * size_of::<Rejection>() as u64;
        // each subscriber: its queue + borrowed 2, plus the history and a loan
        let changes = ((self.max_subscribers * (self.change_buffer + 2) + self.change_buffer + 1) as u64)
            * (self.max_changes * size_of::<Pose>() + size_of::<SnapshotHeader>()) as u64;
        let switches = (self.max_subscribers as u64 * 3 + 2)
            * (self.initial_poses * size_of::<Switch>() + size_of::<SwitchesHeader>()) as u64;
        let status =
            ((self.max_frontends + self.max_subscribers) as u64 * 3 + 2) * size_of::<DaemonStatus>() as u64;
        inputs + snapshot + changes + rejections + switches + status
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_live_under_the_namespace() {
        let n = ServiceNames::new("robot7/slamd/");
        assert_eq!(n.edges, "robot7/slamd/edges");
        assert_eq!(n.published, "robot7/slamd/published");
    }
}
