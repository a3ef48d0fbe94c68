//! [`SnapshotLink`]: reading the daemon's snapshots, switches and rejections.

use super::services::{self, Access, Namespace};
use super::{node, TransportError};
use crate::message::{DaemonStatus, Pose, Rejection, SnapshotHeader, Switch, SwitchesHeader};
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::sample::Sample;
use std::time::{Duration, Instant};

/// A snapshot in shared memory, borrowed for as long as it is held (at most
/// two at a time per link).
pub struct SnapshotSample(Sample<ipc::Service, [Pose], SnapshotHeader>);

impl SnapshotSample {
    /// The header.
    pub fn header(&self) -> &SnapshotHeader {
        self.0.user_header()
    }

    /// The poses, read in place.
    pub fn poses(&self) -> &[Pose] {
        self.0.payload()
    }
}

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

/// Subscriber to snapshots, switches and rejections of one namespace.
pub struct SnapshotLink {
    _node: Node<ipc::Service>,
    poses: Subscriber<ipc::Service, [Pose], SnapshotHeader>,
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
            switches,
            published,
            rejections,
            status,
        })
    }

    /// The newest snapshot delivered since the last call, if any (never
    /// blocks).
    pub fn latest(&self) -> Result<Option<SnapshotSample>, TransportError> {
        let mut newest = None;
        while let Some(s) = self
            .poses
            .receive()
            .map_err(|e| TransportError::other("receive snapshot", e))?
        {
            newest = Some(SnapshotSample(s));
        }
        Ok(newest)
    }

    /// Waits up to `timeout` for a snapshot newer than the last one taken;
    /// `None` when none came, or when a signal cut the wait short. The
    /// event wakes it for every new snapshot; it also looks every 50 ms
    /// for the latest snapshot, which a daemon at rest hands a new
    /// subscriber without an event.
    pub fn wait(&self, timeout: Duration) -> Result<Option<SnapshotSample>, TransportError> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(s) = self.latest()? {
                return Ok(Some(s));
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
