//! [`SnapshotLink`]: reading the daemon's snapshots, switches and rejections.

use super::services::{self, Access, Namespace};
use super::{node, TransportError};
use crate::message::{DaemonStatus, Pose, Rejection, SnapshotHeader, Switch, SwitchesHeader};
use crate::snapshot::{Assembly, MapSnapshot};
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use std::time::{Duration, Instant};

/// The loop closures' switches in shared memory, borrowed while held.
pub struct SwitchesSample(Sample<ipc::Service, [Switch], SwitchesHeader>);

impl SwitchesSample {
    /// The header.
    pub fn header(&self) -> &SwitchesHeader {
        self.0.user_header()
    }

    /// One switch per loop closure, read in place.
    pub fn switches(&self) -> &[Switch] {
        self.0.payload()
    }
}

/// The shortest wait handed to iceoryx2's timed wait, whose socket
/// timeout has microsecond resolution and reads zero as "forever".
const MIN_WAIT: Duration = Duration::from_micros(2);

/// How often [`SnapshotLink::wait`] looks for a snapshot that came without
/// an event.
const LOOK_EVERY: Duration = Duration::from_millis(50);

/// Subscriber to snapshots, switches and rejections of one namespace. It
/// keeps its own copy of the map ([`MapSnapshot`]), built from the whole maps
/// and changes the daemon publishes ([`crate::snapshot`]): taking a
/// snapshot costs what changed, not the map's size.
pub struct SnapshotLink {
    _node: Node<ipc::Service>,
    poses: Subscriber<ipc::Service, [Pose], SnapshotHeader>,
    changes: Subscriber<ipc::Service, [Pose], SnapshotHeader>,
    map: Assembly,
    switches: Subscriber<ipc::Service, [Switch], SwitchesHeader>,
    published: Listener<ipc::Service>,
    rejections: Subscriber<ipc::Service, Rejection, ()>,
    status: Subscriber<ipc::Service, DaemonStatus, ()>,
}

impl SnapshotLink {
    /// Opens the daemon's output services under `namespace`.
    pub fn open(namespace: &str) -> Result<Self, TransportError> {
        let ns = Namespace::new(namespace);
        let names = &ns.services;
        let node = node("slamd-snapshots", false)?;
        let poses = services::poses(&node, &ns, Access::Open)?
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.poses, &e))?;
        let changes = services::changes(&node, &ns, Access::Open)?
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.changes, &e))?;
        let rejections = services::rejections(&node, &ns, Access::Open)?
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.rejections, &e))?;
        let switches = services::switches(&node, &ns, Access::Open)?
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.switches, &e))?;
        let published = services::published(&node, &ns, Access::Open)?
            .listener_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.published, &e))?;
        let status = services::status(&node, &ns, Access::Open)?
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.status, &e))?;
        Ok(Self {
            _node: node,
            poses,
            changes,
            map: Assembly::default(),
            switches,
            published,
            rejections,
            status,
        })
    }

    /// The map as of the newest snapshot delivered, if it moved on since
    /// the last call (never blocks).
    pub fn latest(&mut self) -> Result<Option<&MapSnapshot>, TransportError> {
        Ok(if self.take_in()? { self.map.current() } else { None })
    }

    /// The newest map taken in so far (whether or not a call returned it).
    pub fn current(&self) -> Option<&MapSnapshot> {
        self.map.current()
    }

    /// Takes every whole map and change delivered into the map; whether it
    /// moved on.
    fn take_in(&mut self) -> Result<bool, TransportError> {
        // the whole maps first: a change that follows one is placed on it
        let mut newest = None;
        while let Some(s) = self
            .poses
            .receive()
            .map_err(|e| TransportError::other("receive snapshot", e))?
        {
            newest = Some(s);
        }
        if let Some(s) = newest {
            self.map.whole(s.user_header(), s.payload());
        }
        while let Some(s) = self
            .changes
            .receive()
            .map_err(|e| TransportError::other("receive snapshot changes", e))?
        {
            self.map.change(s.user_header(), s.payload());
        }
        Ok(self.map.take_advanced())
    }

    /// Waits up to `timeout` for a snapshot newer than the last one taken;
    /// `None` when none came, or when a signal cut the wait short. The
    /// event wakes it for every new snapshot; it also looks every 50 ms
    /// for the latest snapshot, which a daemon at rest hands a new
    /// subscriber without an event.
    pub fn wait(&mut self, timeout: Duration) -> Result<Option<&MapSnapshot>, TransportError> {
        let deadline = Instant::now() + timeout;
        loop {
            if self.take_in()? {
                return Ok(self.map.current());
            }
            let left = deadline.saturating_duration_since(Instant::now());
            // below a microsecond the socket timeout would be {0, 0}: no
            // timeout at all, a wait without end
            if left < MIN_WAIT {
                return Ok(None);
            }
            match self.published.timed_wait(|_| {}, left.min(LOOK_EVERY)) {
                Ok(_) => {}
                // a signal cut the wait short: the caller decides what it
                // means (its own handler has run)
                Err(ListenerWaitError::InterruptSignal) => return Ok(None),
                Err(e) => return Err(TransportError::other("wait for a snapshot", e)),
            }
        }
    }

    /// The newest loop-closure switches delivered since the last call, if
    /// any (never blocks; the daemon publishes them when they change).
    pub fn switches(&self) -> Result<Option<SwitchesSample>, TransportError> {
        let mut newest = None;
        while let Some(s) = self
            .switches
            .receive()
            .map_err(|e| TransportError::other("receive switches", e))?
        {
            newest = Some(SwitchesSample(s));
        }
        Ok(newest)
    }

    /// The newest daemon status delivered since the last call, if any
    /// (never blocks; one is published with every snapshot, and a new
    /// subscriber gets the last one).
    pub fn status(&self) -> Result<Option<DaemonStatus>, TransportError> {
        super::newest(&self.status, "status")
    }

    /// Every rejection delivered since the last call.
    pub fn rejections(&self) -> Result<Vec<Rejection>, TransportError> {
        let mut out = Vec::new();
        while let Some(s) = self
            .rejections
            .receive()
            .map_err(|e| TransportError::other("receive rejection", e))?
        {
            out.push(*s.payload());
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::service::Qos;
    use crate::transport::{Ingress, Outlet};

    fn pose(id: u64, x: f64) -> Pose {
        Pose {
            id,
            x,
            ..Pose::default()
        }
    }

    fn header(version: u64, base: u64) -> SnapshotHeader {
        SnapshotHeader {
            version,
            base,
            instance: 5,
            ..SnapshotHeader::default()
        }
    }

    fn xs(s: &MapSnapshot) -> Vec<(u64, f64)> {
        s.poses().iter().map(|p| (p.id, p.x)).collect()
    }

    #[test]
    fn a_link_builds_the_map_from_whole_maps_and_changes_and_a_late_one_catches_up() {
        let ns = format!("slamd-test-{}-changes", std::process::id());
        let qos = Qos {
            max_subscribers: 3,
            keyframe_buffer: 2,
            edge_buffer: 2,
            gps_buffer: 2,
            initial_poses: 4,
            max_changes: 2,
            change_buffer: 4,
            ..Qos::default()
        };
        let _daemon = Ingress::create(&ns, &qos).unwrap();
        let out = Outlet::open(&ns, &qos).unwrap();
        let mut early = SnapshotLink::open(&ns).unwrap();
        out.publish_whole(header(1, 0), 2, [pose(0, 0.0), pose(1, 1.0)].into_iter())
            .unwrap();
        out.publish_changes(header(2, 1), 1, [pose(2, 2.0)].into_iter())
            .unwrap();
        let s = early.wait(Duration::from_secs(1)).unwrap().expect("a map");
        assert_eq!(xs(s), [(0, 0.0), (1, 1.0), (2, 2.0)]);
        assert_eq!((s.header().version, s.header().poses), (2, 3));
        // more than a sample holds is refused: the daemon sends those whole
        let three = [pose(0, 9.0), pose(1, 9.0), pose(2, 9.0)];
        assert!(out.publish_changes(header(3, 2), 3, three.into_iter()).is_err());
        out.publish_changes(header(3, 2), 2, [pose(1, 1.5), pose(3, 3.0)].into_iter())
            .unwrap();
        // a subscriber that comes now gets the last whole map and the changes
        // since from the topics' history, once the daemon looks for new
        // subscribers (with every status)
        let mut late = SnapshotLink::open(&ns).unwrap();
        out.publish_status(DaemonStatus::default()).unwrap();
        let s = late.wait(Duration::from_secs(1)).unwrap().expect("a map");
        assert_eq!(xs(s), [(0, 0.0), (1, 1.5), (2, 2.0), (3, 3.0)]);
        let s = early.wait(Duration::from_secs(1)).unwrap().expect("a map");
        assert_eq!(xs(s), [(0, 0.0), (1, 1.5), (2, 2.0), (3, 3.0)]);
        // a reader that falls more than `change_buffer` behind loses changes
        // and stays at its map until the next whole one
        for v in 4..10 {
            out.publish_changes(header(v, v - 1), 1, [pose(0, v as f64)].into_iter())
                .unwrap();
        }
        assert!(early.latest().unwrap().is_none());
        assert_eq!(early.current().unwrap().header().version, 3);
        let all = [
            pose(0, 10.0),
            pose(1, 10.0),
            pose(2, 10.0),
            pose(3, 10.0),
            pose(4, 10.0),
        ];
        out.publish_whole(header(10, 0), 5, all.into_iter()).unwrap();
        out.publish_changes(header(11, 10), 1, [pose(4, 11.0)].into_iter())
            .unwrap();
        let s = early.latest().unwrap().expect("a map");
        assert_eq!(s.header().version, 11);
        assert_eq!(s.pose(4).map(|p| p.x), Some(11.0));
        assert_eq!(s.poses().len(), 5);
    }
}
