//! [`FrontendLink`]: a frontend's publishers into the daemon.

use super::services::{self, Access, Namespace};
use super::{node, TransportError};
use crate::message::{DaemonStatus, Edge, GpsFix, Keyframe};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use std::time::Duration;

/// Publishers for keyframes, edges and fixes, and the poke that wakes the
/// daemon. Opening never creates a service: no daemon, no link.
pub struct FrontendLink {
    _node: Node<ipc::Service>,
    ns: Namespace,
    keyframes: Publisher<ipc::Service, Keyframe, ()>,
    edges: Publisher<ipc::Service, Edge, ()>,
    gps: Publisher<ipc::Service, GpsFix, ()>,
    ingest: Notifier<ipc::Service>,
    status: Subscriber<ipc::Service, DaemonStatus, ()>,
}

impl FrontendLink {
    /// Opens the daemon's input services under `namespace`. A send that
    /// finds the daemon's queue full retries for `backpressure`, then fails
    /// with [`TransportError::Backpressure`].
    pub fn open(namespace: &str, backpressure: Duration) -> Result<Self, TransportError> {
        let ns = Namespace::new(namespace);
        let names = &ns.services;
        let node = node("slamd-frontend", false)?;
        let handler = move |info: &BackpressureInfo| {
            if info.elapsed_time < backpressure {
                BackpressureAction::Retry
            } else {
                BackpressureAction::DiscardDataAndFail
            }
        };
        let keyframes = services::keyframes(&node, &ns, Access::Open)?
            .publisher_builder()
            .set_backpressure_handler(handler)
            .create()
            .map_err(|e| ns.fail("open", &names.keyframes, &e))?;
        let edges = services::edges(&node, &ns, Access::Open)?
            .publisher_builder()
            .set_backpressure_handler(handler)
            .create()
            .map_err(|e| ns.fail("open", &names.edges, &e))?;
        let gps = services::gps(&node, &ns, Access::Open)?
            .publisher_builder()
            .set_backpressure_handler(handler)
            .create()
            .map_err(|e| ns.fail("open", &names.gps, &e))?;
        let ingest = services::ingest(&node, &ns, Access::Open)?
            .notifier_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.ingest, &e))?;
        let status = services::status(&node, &ns, Access::Open)?
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.status, &e))?;
        Ok(Self {
            _node: node,
            ns,
            keyframes,
            edges,
            gps,
            ingest,
            status,
        })
    }

    /// Publishes a keyframe (the daemon sees it at the next [`Self::poke`]).
    pub fn send_keyframe(&self, m: Keyframe) -> Result<(), TransportError> {
        self.keyframes
            .send_copy(m)
            .map(|_| ())
            .map_err(|e| self.ns.fail("send on", &self.ns.services.keyframes, &e))
    }

    /// Publishes an edge.
    pub fn send_edge(&self, m: Edge) -> Result<(), TransportError> {
        self.edges
            .send_copy(m)
            .map(|_| ())
            .map_err(|e| self.ns.fail("send on", &self.ns.services.edges, &e))
    }

    /// Publishes a GPS fix.
    pub fn send_gps(&self, m: GpsFix) -> Result<(), TransportError> {
        self.gps
            .send_copy(m)
            .map(|_| ())
            .map_err(|e| self.ns.fail("send on", &self.ns.services.gps, &e))
    }

    /// The newest daemon status delivered since the last call, if any
    /// (never blocks).
    pub fn latest_status(&self) -> Result<Option<DaemonStatus>, TransportError> {
        super::newest(&self.status, "status")
    }

    /// Wakes the daemon to take what was published.
    pub fn poke(&self) -> Result<(), TransportError> {
        self.ingest
            .notify()
            .map(|_| ())
            .map_err(|e| TransportError::other("notify the daemon", e))
    }
}
