//! [`FrontendLink`]: a frontend's publishers into the daemon.

use super::{classify, node, protocol_attributes, service_name, TransportError};
use crate::message::{Edge, GpsFix, Keyframe};
use crate::service::ServiceNames;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::{BackpressureAction, BackpressureInfo};
use iceoryx2::prelude::*;
use std::time::Duration;

/// Publishers for keyframes, edges and fixes, and the poke that wakes the
/// daemon. Opening never creates a service: no daemon, no link.
pub struct FrontendLink {
    _node: Node<ipc::Service>,
    names: ServiceNames,
    keyframes: Publisher<ipc::Service, Keyframe, ()>,
    edges: Publisher<ipc::Service, Edge, ()>,
    gps: Publisher<ipc::Service, GpsFix, ()>,
    ingest: Notifier<ipc::Service>,
}

impl FrontendLink {
    /// Opens the daemon's input services under `namespace`. A send that
    /// finds the daemon's queue full retries for `backpressure`, then fails.
    pub fn open(namespace: &str, backpressure: Duration) -> Result<Self, TransportError> {
        let names = ServiceNames::new(namespace);
        let node = node("slamd-frontend", false)?;
        let attrs = protocol_attributes();
        let handler = move |info: &BackpressureInfo| {
            if info.elapsed_time < backpressure {
                BackpressureAction::Retry
            } else {
                BackpressureAction::DiscardDataAndFail
            }
        };
        let keyframes = node
            .service_builder(&service_name(&names.keyframes)?)
            .publish_subscribe::<Keyframe>()
            .open_with_attributes(&attrs)
            .map_err(|e| classify("open", namespace, &names.keyframes, &e))?
            .publisher_builder()
            .set_backpressure_handler(handler)
            .create()
            .map_err(|e| classify("open", namespace, &names.keyframes, &e))?;
        let edges = node
            .service_builder(&service_name(&names.edges)?)
            .publish_subscribe::<Edge>()
            .open_with_attributes(&attrs)
            .map_err(|e| classify("open", namespace, &names.edges, &e))?
            .publisher_builder()
            .set_backpressure_handler(handler)
            .create()
            .map_err(|e| classify("open", namespace, &names.edges, &e))?;
        let gps = node
            .service_builder(&service_name(&names.gps)?)
            .publish_subscribe::<GpsFix>()
            .open_with_attributes(&attrs)
            .map_err(|e| classify("open", namespace, &names.gps, &e))?
            .publisher_builder()
            .set_backpressure_handler(handler)
            .create()
            .map_err(|e| classify("open", namespace, &names.gps, &e))?;
        let ingest = node
            .service_builder(&service_name(&names.ingest)?)
            .event()
            .open_with_attributes(&attrs)
            .map_err(|e| classify("open", namespace, &names.ingest, &e))?
            .notifier_builder()
            .create()
            .map_err(|e| classify("open", namespace, &names.ingest, &e))?;
        Ok(Self {
            _node: node,
            names,
            keyframes,
            edges,
            gps,
            ingest,
        })
    }

    /// Publishes a keyframe (the daemon sees it at the next [`Self::poke`]).
    pub fn send_keyframe(&self, m: Keyframe) -> Result<(), TransportError> {
        self.keyframes
            .send_copy(m)
            .map(|_| ())
            .map_err(|e| self.send_err(&self.names.keyframes, e))
    }

    /// Publishes an edge.
    pub fn send_edge(&self, m: Edge) -> Result<(), TransportError> {
        self.edges
            .send_copy(m)
            .map(|_| ())
            .map_err(|e| self.send_err(&self.names.edges, e))
    }

    /// Publishes a GPS fix.
    pub fn send_gps(&self, m: GpsFix) -> Result<(), TransportError> {
        self.gps
            .send_copy(m)
            .map(|_| ())
            .map_err(|e| self.send_err(&self.names.gps, e))
    }

    /// Wakes the daemon to take what was published.
    pub fn poke(&self) -> Result<(), TransportError> {
        self.ingest
            .notify()
            .map(|_| ())
            .map_err(|e| TransportError::other("notify the daemon", e))
    }

    fn send_err(&self, service: &str, e: impl std::fmt::Debug) -> TransportError {
        let text = format!("{e:?}");
        if text.contains("UnableToDeliver") {
            TransportError::Backpressure {
                service: service.into(),
            }
        } else {
            TransportError::other(&format!("send on `{service}`"), e)
        }
    }
}
