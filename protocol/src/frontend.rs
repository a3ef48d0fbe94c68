//! [`Frontend`]: publishing keyframes, edges and GPS fixes to a running daemon.

use crate::codec::{edge_out, gps_out, keyframe_out, Origin};
use crate::transport::{FrontendLink, TransportError};
use slamd_types::{EdgeInput, FixInput, KeyframeId, Pose2};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::Duration;

/// Where a frontend connects: the daemon's namespace, and how long a send
/// that finds the daemon's queue full retries before it fails.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Endpoint {
    /// The daemon's namespace (`slamd run --namespace`).
    pub namespace: String,
    /// The send timeout on a full queue.
    pub backpressure: Duration,
}

static NEXT: AtomicU32 = AtomicU32::new(1);

/// A frontend's connection: each message gets the next number; the daemon
/// acknowledges numbers in snapshot headers and names them in rejections.
pub struct Frontend {
    link: FrontendLink,
    id: u32,
    sequence: u64,
}

impl Frontend {
    /// Connects to the daemon at `endpoint` (for example a daemon's
    /// configuration: its namespace and backpressure).
    pub fn connect(endpoint: impl Into<Endpoint>) -> Result<Self, TransportError> {
        let e = endpoint.into();
        Self::connect_to(&e.namespace, e.backpressure)
    }

    /// Connects to the daemon serving `namespace`.
    pub fn connect_to(namespace: &str, backpressure: Duration) -> Result<Self, TransportError> {
        let link = FrontendLink::open(namespace, backpressure)?;
        // nonzero and distinct across processes and connections
        let id = (std::process::id().wrapping_mul(2654435761) ^ NEXT.fetch_add(1, Ordering::Relaxed)).max(1);
        Ok(Self {
            link,
            id,
            sequence: 0,
        })
    }

    /// This frontend's id in acknowledgements and rejections.
    pub fn id(&self) -> u32 {
        self.id
    }

    /// The number of the last message sent.
    pub fn last_sequence(&self) -> u64 {
        self.sequence
    }

    fn next(&mut self) -> Origin {
        self.sequence += 1;
        Origin {
            frontend: self.id,
            sequence: self.sequence,
        }
    }

    /// Publishes a keyframe; returns its message number.
    pub fn add_keyframe(
        &mut self,
        id: KeyframeId,
        timestamp_ns: u64,
        guess: Option<Pose2>,
    ) -> Result<u64, TransportError> {
        let o = self.next();
        self.link
            .send_keyframe(keyframe_out(id, timestamp_ns, guess, o))?;
        Ok(o.sequence)
    }

    /// Publishes an edge; returns its message number.
    pub fn add_edge(&mut self, edge: &EdgeInput) -> Result<u64, TransportError> {
        let o = self.next();
        self.link.send_edge(edge_out(edge, o))?;
        Ok(o.sequence)
    }

    /// Publishes a GPS fix; returns its message number.
    pub fn add_gps(&mut self, fix: &FixInput) -> Result<u64, TransportError> {
        let o = self.next();
        self.link.send_gps(gps_out(fix, o))?;
        Ok(o.sequence)
    }

    /// Publishes a raw edge message as is (tests of hostile input).
    pub fn send_raw_edge(&mut self, mut m: crate::Edge) -> Result<u64, TransportError> {
        let o = self.next();
        m.frontend = o.frontend;
        m.sequence = o.sequence;
        self.link.send_edge(m)?;
        Ok(o.sequence)
    }

    /// Wakes the daemon to take everything published so far.
    pub fn flush(&self) -> Result<(), TransportError> {
        self.link.poke()
    }
}
