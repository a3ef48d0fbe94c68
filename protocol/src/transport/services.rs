//! One builder per slamd service, used by every role.
//!
//! The daemon reaches each service with [`Access::Create`]: it opens the
//! service or creates it with the full QoS derived from its [`Qos`]. Every
//! other port reaches it with [`Access::Open`], which never creates, so a
//! missing daemon is [`TransportError::NoDaemon`]. Both require
//! [`protocol_attributes`]. A role only adds its port (publisher,
//! subscriber, notifier or listener) and that port's own settings.

use super::classify::{classify, Explain};
use super::{protocol_attributes, service_name, TransportError};
use crate::message::{
    DaemonStatus, Edge, GpsFix, Keyframe, Pose, Rejection, SnapshotHeader, Switch, SwitchesHeader,
};
use crate::service::{Qos, ServiceNames};
use iceoryx2::prelude::*;
use iceoryx2::service::attribute::AttributeVerifier;
use iceoryx2::service::builder::publish_subscribe::{
    Builder, PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError,
};
use iceoryx2::service::port_factory::{event, publish_subscribe};
use std::fmt::Debug;

/// Samples a subscriber of the latest-value topics (poses, switches) may
/// borrow at once: the one its caller keeps (the last snapshot), the newest
/// held while looking for a newer one, and the one being received. With
/// fewer, a caller that keeps its last snapshot gets `ExceedsMaxBorrows`
/// whenever two snapshots arrive between its calls.
pub(crate) const MAX_BORROWED: usize = 3;

/// A publish-subscribe service of payload `T` and user header `H`.
pub(crate) type Topic<T, H = ()> = publish_subscribe::PortFactory<ipc::Service, T, H>;

/// An event service.
pub(crate) type Event = event::PortFactory<ipc::Service>;

/// How a role reaches a service.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Access<'a> {
    /// Opens the service, or creates it with the sizes this [`Qos`] gives
    /// when it does not exist. An existing service must offer at least
    /// those sizes. Only the daemon creates.
    Create(&'a Qos),
    /// Opens the service as its creator sized it; never creates.
    Open,
}

impl Access<'_> {
    /// The operation a failure reports: "create" or "open".
    fn operation(self) -> &'static str {
        match self {
            Access::Create(_) => "create",
            Access::Open => "open",
        }
    }
}

/// A namespace and the names of its services: what a builder names its
/// service with, and what a [`TransportError::NoDaemon`] reports.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Namespace {
    /// The namespace as given by the caller.
    pub(crate) name: String,
    /// Its services.
    pub(crate) services: ServiceNames,
}

impl Namespace {
    /// The services under `name`.
    pub(crate) fn new(name: &str) -> Self {
        Self {
            name: name.into(),
            services: ServiceNames::new(name),
        }
    }

    /// Words an iceoryx2 failure met while doing `operation` on `service`.
    pub(crate) fn fail(&self, operation: &str, service: &str, e: &impl Explain) -> TransportError {
        classify(operation, &self.name, service, e)
    }
}

/// Keyframes, frontends → daemon: see [`input_topic`].
pub(crate) fn keyframes(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Topic<Keyframe>, TransportError> {
    input_topic(node, ns, &ns.services.keyframes, access, |q| q.keyframe_buffer)
}

/// Edges, frontends → daemon: see [`input_topic`].
pub(crate) fn edges(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Topic<Edge>, TransportError> {
    input_topic(node, ns, &ns.services.edges, access, |q| q.edge_buffer)
}

/// GPS fixes, frontends → daemon: see [`input_topic`].
pub(crate) fn gps(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Topic<GpsFix>, TransportError> {
    input_topic(node, ns, &ns.services.gps, access, |q| q.gps_buffer)
}

/// A frontend → daemon topic of `T` named `name`. Created with up to
/// `max_frontends` publishers, the daemon's subscriber and one spare, a
/// queue of `buffer(qos)` samples, no history, and no safe overflow (a full
/// queue never overwrites input).
fn input_topic<T: Debug + ZeroCopySend>(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    name: &str,
    access: Access,
    buffer: fn(&Qos) -> usize,
) -> Result<Topic<T>, TransportError> {
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<T>();
    topic(builder, ns, name, access, |q| TopicSizes {
        publishers: q.max_frontends,
        subscribers: 2,
        buffer: buffer(q),
        borrowed: None,
        history: 0,
        safe_overflow: false,
    })
}

/// Pose snapshots, daemon → subscribers. Created with one publisher,
/// `max_subscribers` subscribers that each keep only the newest snapshot
/// (buffer 1, safe overflow) and may borrow [`MAX_BORROWED`], and a history
/// of 1 so a late subscriber gets the current snapshot.
pub(crate) fn poses(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Topic<[Pose], SnapshotHeader>, TransportError> {
    let name = &ns.services.poses;
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<[Pose]>()
        .user_header::<SnapshotHeader>();
    topic(builder, ns, name, access, latest_value)
}

/// What each snapshot changed, daemon → subscribers. Created with one
/// publisher and `max_subscribers` subscribers that each queue
/// `change_buffer` samples (safe overflow: a reader that falls behind loses
/// the oldest and waits for the next whole map), and a history of
/// `change_buffer` so a late subscriber can catch up from the last whole
/// map.
pub(crate) fn changes(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Topic<[Pose], SnapshotHeader>, TransportError> {
    let name = &ns.services.changes;
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<[Pose]>()
        .user_header::<SnapshotHeader>();
    topic(builder, ns, name, access, |q| TopicSizes {
        publishers: 1,
        subscribers: q.max_subscribers,
        buffer: q.change_buffer.max(1),
        borrowed: Some(MAX_BORROWED),
        history: q.change_buffer.max(1),
        safe_overflow: true,
    })
}

/// Loop-closure switches, daemon → subscribers; sized as [`poses`].
pub(crate) fn switches(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Topic<[Switch], SwitchesHeader>, TransportError> {
    let name = &ns.services.switches;
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<[Switch]>()
        .user_header::<SwitchesHeader>();
    topic(builder, ns, name, access, latest_value)
}

/// The sizes of the latest-value topics ([`poses`], [`switches`]).
fn latest_value(q: &Qos) -> TopicSizes {
    TopicSizes {
        publishers: 1,
        subscribers: q.max_subscribers,
        buffer: 1,
        borrowed: Some(MAX_BORROWED),
        history: 1,
        safe_overflow: true,
    }
}

/// Rejections, daemon → frontends. Created with one publisher,
/// `max_subscribers` subscribers with a queue of 64 that overwrites its
/// oldest entry when full, and a history of `rejection_history`.
pub(crate) fn rejections(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Topic<Rejection>, TransportError> {
    let name = &ns.services.rejections;
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<Rejection>();
    topic(builder, ns, name, access, |q| TopicSizes {
        publishers: 1,
        subscribers: q.max_subscribers,
        buffer: 64,
        borrowed: None,
        history: q.rejection_history,
        safe_overflow: true,
    })
}

/// DaemonStatus, daemon → frontends. Created with one publisher,
/// subscribers for every frontend and every snapshot subscriber, each
/// keeping only the newest (buffer 1, safe overflow), and a history of 1
/// so a frontend learns at once which daemon serves it.
pub(crate) fn status(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Topic<DaemonStatus>, TransportError> {
    let name = &ns.services.status;
    let builder = node
        .service_builder(&service_name(name)?)
        .publish_subscribe::<DaemonStatus>();
    topic(builder, ns, name, access, |q| TopicSizes {
        publishers: 1,
        subscribers: q.max_frontends + q.max_subscribers,
        buffer: 1,
        borrowed: None,
        history: 1,
        safe_overflow: true,
    })
}

/// The "new input" event, frontends → daemon. Created with `max_frontends`
/// notifiers and two listeners (the daemon's and one spare).
pub(crate) fn ingest(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Event, TransportError> {
    event_service(node, ns, &ns.services.ingest, access, |q| (q.max_frontends, 2))
}

/// The "new snapshot" event, daemon → subscribers. Created with two
/// notifiers (the daemon's and one spare) and `max_subscribers` listeners.
pub(crate) fn published(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    access: Access,
) -> Result<Event, TransportError> {
    event_service(node, ns, &ns.services.published, access, |q| {
        (2, q.max_subscribers)
    })
}

/// The event service `name`, created with the `(notifiers, listeners)`
/// that `sizes` gives.
fn event_service(
    node: &Node<ipc::Service>,
    ns: &Namespace,
    name: &str,
    access: Access,
    sizes: fn(&Qos) -> (usize, usize),
) -> Result<Event, TransportError> {
    let builder = node.service_builder(&service_name(name)?).event();
    let attrs = protocol_attributes();
    match access {
        Access::Create(qos) => {
            let (notifiers, listeners) = sizes(qos);
            builder
                .max_notifiers(notifiers)
                .max_listeners(listeners)
                .open_or_create_with_attributes(&attrs)
                .map_err(|e| ns.fail(access.operation(), name, &e))
        }
        Access::Open => builder
            .open_with_attributes(&attrs)
            .map_err(|e| ns.fail(access.operation(), name, &e)),
    }
}

/// The sizes a publish-subscribe service is created with.
struct TopicSizes {
    publishers: usize,
    subscribers: usize,
    buffer: usize,
    /// Samples a subscriber may borrow at once; iceoryx2's default if
    /// `None`.
    borrowed: Option<usize>,
    history: usize,
    safe_overflow: bool,
}

impl TopicSizes {
    /// Sets every size on `builder`.
    fn apply<T, H>(&self, builder: Builder<T, H, ipc::Service>) -> Builder<T, H, ipc::Service>
    where
        T: Debug + IceoryxSend + ?Sized,
        H: Debug + ZeroCopySend,
    {
        let builder = builder
            .max_publishers(self.publishers)
            .max_subscribers(self.subscribers)
            .subscriber_max_buffer_size(self.buffer)
            .history_size(self.history)
            .enable_safe_overflow(self.safe_overflow);
        match self.borrowed {
            Some(n) => builder.subscriber_max_borrowed_samples(n),
            None => builder,
        }
    }
}

/// Reaches the publish-subscribe service `name` through `builder`: with
/// [`Access::Create`], sets the sizes `sizes` gives and opens or creates;
/// with [`Access::Open`], opens. Both require [`protocol_attributes`].
fn topic<T, H>(
    builder: Builder<T, H, ipc::Service>,
    ns: &Namespace,
    name: &str,
    access: Access,
    sizes: impl FnOnce(&Qos) -> TopicSizes,
) -> Result<Topic<T, H>, TransportError>
where
    T: Debug + IceoryxSend + ?Sized,
    H: Debug + ZeroCopySend,
    Builder<T, H, ipc::Service>: Reach<T, H>,
{
    let attrs = protocol_attributes();
    match access {
        Access::Create(qos) => sizes(qos)
            .apply(builder)
            .reach_or_create(&attrs)
            .map_err(|e| ns.fail(access.operation(), name, &e)),
        Access::Open => builder
            .reach(&attrs)
            .map_err(|e| ns.fail(access.operation(), name, &e)),
    }
}

/// The two ways to reach a publish-subscribe service, for sized and slice
/// payloads alike (iceoryx2 offers them in separate `impl` blocks).
trait Reach<T: Debug + IceoryxSend + ?Sized, H: Debug + ZeroCopySend> {
    /// `open_or_create_with_attributes`.
    fn reach_or_create(
        self,
        attrs: &AttributeVerifier,
    ) -> Result<Topic<T, H>, PublishSubscribeOpenOrCreateError>;
    /// `open_with_attributes`.
    fn reach(self, attrs: &AttributeVerifier) -> Result<Topic<T, H>, PublishSubscribeOpenError>;
}

impl<T: Debug + ZeroCopySend, H: Debug + ZeroCopySend> Reach<T, H> for Builder<T, H, ipc::Service> {
    fn reach_or_create(
        self,
        attrs: &AttributeVerifier,
    ) -> Result<Topic<T, H>, PublishSubscribeOpenOrCreateError> {
        self.open_or_create_with_attributes(attrs)
    }

    fn reach(self, attrs: &AttributeVerifier) -> Result<Topic<T, H>, PublishSubscribeOpenError> {
        self.open_with_attributes(attrs)
    }
}

impl<T: Debug + ZeroCopySend, H: Debug + ZeroCopySend> Reach<[T], H> for Builder<[T], H, ipc::Service> {
    fn reach_or_create(
        self,
        attrs: &AttributeVerifier,
    ) -> Result<Topic<[T], H>, PublishSubscribeOpenOrCreateError> {
        self.open_or_create_with_attributes(attrs)
    }

    fn reach(self, attrs: &AttributeVerifier) -> Result<Topic<[T], H>, PublishSubscribeOpenError> {
        self.open_with_attributes(attrs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::message::PROTOCOL_VERSION;
    use crate::service::PROTOCOL_KEY;
    use crate::transport::{node, Exit, FrontendLink, Ingress, Outlet, SnapshotLink};
    use iceoryx2::service::attribute::{AttributeKey, AttributeValue};
    use std::time::Duration;

    /// A namespace no other test or process uses.
    fn unique(tag: &str) -> Namespace {
        Namespace::new(&format!("slamd-test-{}-{tag}", std::process::id()))
    }

    /// Sizes small enough for any `/dev/shm`, all distinct where they can be.
    fn small() -> Qos {
        Qos {
            max_frontends: 3,
            max_subscribers: 4,
            keyframe_buffer: 5,
            edge_buffer: 6,
            gps_buffer: 7,
            initial_poses: 8,
            max_changes: 10,
            change_buffer: 11,
            rejection_history: 9,
        }
    }

    /// The protocol attribute with `version` as its value.
    fn protocol(version: u32) -> AttributeSpecifier {
        let key = AttributeKey::try_from(PROTOCOL_KEY).unwrap();
        let value = AttributeValue::try_from(version.to_string().as_str()).unwrap();
        AttributeSpecifier::new().define(&key, &value).unwrap()
    }

    #[test]
    fn without_a_daemon_every_service_and_every_link_is_no_daemon() {
        let ns = unique("absent");
        let node = node("slamd-test", false).unwrap();
        let none = Some(TransportError::NoDaemon {
            namespace: ns.name.clone(),
        });
        let open = Access::Open;
        assert_eq!(keyframes(&node, &ns, open).err(), none);
        assert_eq!(edges(&node, &ns, open).err(), none);
        assert_eq!(gps(&node, &ns, open).err(), none);
        assert_eq!(poses(&node, &ns, open).err(), none);
        assert_eq!(changes(&node, &ns, open).err(), none);
        assert_eq!(rejections(&node, &ns, open).err(), none);
        assert_eq!(switches(&node, &ns, open).err(), none);
        assert_eq!(ingest(&node, &ns, open).err(), none);
        assert_eq!(published(&node, &ns, open).err(), none);
        assert_eq!(FrontendLink::open(&ns.name, Duration::ZERO).err(), none);
        assert_eq!(SnapshotLink::open(&ns.name).err(), none);
        assert_eq!(Outlet::open(&ns.name, &small()).err(), none);
    }

    #[test]
    fn create_applies_the_full_qos_and_open_reaches_what_was_created() {
        let ns = unique("sizes");
        let node = node("slamd-test", false).unwrap();
        let q = small();
        let create = Access::Create(&q);
        let keyframes_ = keyframes(&node, &ns, create).unwrap();
        let edges_ = edges(&node, &ns, create).unwrap();
        let gps_ = gps(&node, &ns, create).unwrap();
        let inputs = [
            (keyframes_.static_config(), 5),
            (edges_.static_config(), 6),
            (gps_.static_config(), 7),
        ];
        for (c, buffer) in inputs {
            assert_eq!(c.max_publishers(), 3);
            assert_eq!(c.max_subscribers(), 2);
            assert_eq!(c.subscriber_max_buffer_size(), buffer);
            assert_eq!(c.history_size(), 0);
            assert!(!c.has_safe_overflow());
        }
        let poses_ = poses(&node, &ns, create).unwrap();
        let switches_ = switches(&node, &ns, create).unwrap();
        for c in [poses_.static_config(), switches_.static_config()] {
            assert_eq!(c.max_publishers(), 1);
            assert_eq!(c.max_subscribers(), 4);
            assert_eq!(c.subscriber_max_buffer_size(), 1);
            assert_eq!(c.subscriber_max_borrowed_samples(), MAX_BORROWED);
            assert_eq!(c.history_size(), 1);
            assert!(c.has_safe_overflow());
        }
        let changes_ = changes(&node, &ns, create).unwrap();
        let c = changes_.static_config();
        assert_eq!((c.max_publishers(), c.max_subscribers()), (1, 4));
        assert_eq!((c.subscriber_max_buffer_size(), c.history_size()), (11, 11));
        assert!(c.has_safe_overflow());
        let rejections_ = rejections(&node, &ns, create).unwrap();
        let c = rejections_.static_config();
        assert_eq!((c.max_publishers(), c.max_subscribers()), (1, 4));
        assert_eq!((c.subscriber_max_buffer_size(), c.history_size()), (64, 9));
        assert!(c.has_safe_overflow());
        let ingest_ = ingest(&node, &ns, create).unwrap();
        let c = ingest_.static_config();
        assert_eq!((c.max_notifiers(), c.max_listeners()), (3, 2));
        let published_ = published(&node, &ns, create).unwrap();
        let c = published_.static_config();
        assert_eq!((c.max_notifiers(), c.max_listeners()), (2, 4));

        let open = Access::Open;
        assert!(keyframes(&node, &ns, open).is_ok());
        assert!(edges(&node, &ns, open).is_ok());
        assert!(gps(&node, &ns, open).is_ok());
        assert!(poses(&node, &ns, open).is_ok());
        assert!(changes(&node, &ns, open).is_ok());
        assert!(rejections(&node, &ns, open).is_ok());
        assert!(switches(&node, &ns, open).is_ok());
        assert!(ingest(&node, &ns, open).is_ok());
        assert!(published(&node, &ns, open).is_ok());
        assert!(poses(&node, &ns, create).is_ok(), "a restarted daemon reopens");
    }

    #[test]
    fn another_protocol_version_is_a_protocol_mismatch() {
        let ns = unique("version");
        let node = node("slamd-test", false).unwrap();
        let other = protocol(PROTOCOL_VERSION + 1);
        let _poses = node
            .service_builder(&service_name(&ns.services.poses).unwrap())
            .publish_subscribe::<[Pose]>()
            .user_header::<SnapshotHeader>()
            .create_with_attributes(&other)
            .unwrap();
        let _ingest = node
            .service_builder(&service_name(&ns.services.ingest).unwrap())
            .event()
            .create_with_attributes(&other)
            .unwrap();
        let q = small();
        let poses_mismatch = Some(TransportError::ProtocolMismatch {
            service: ns.services.poses.clone(),
        });
        assert_eq!(poses(&node, &ns, Access::Open).err(), poses_mismatch);
        assert_eq!(poses(&node, &ns, Access::Create(&q)).err(), poses_mismatch);
        let ingest_mismatch = Some(TransportError::ProtocolMismatch {
            service: ns.services.ingest.clone(),
        });
        assert_eq!(ingest(&node, &ns, Access::Open).err(), ingest_mismatch);
        assert_eq!(ingest(&node, &ns, Access::Create(&q)).err(), ingest_mismatch);
    }

    #[test]
    fn another_payload_type_is_an_incompatible_layout() {
        let ns = unique("layout");
        let node = node("slamd-test", false).unwrap();
        let _keyframes = node
            .service_builder(&service_name(&ns.services.keyframes).unwrap())
            .publish_subscribe::<u64>()
            .create_with_attributes(&protocol(PROTOCOL_VERSION))
            .unwrap();
        let layout = Some(TransportError::IncompatibleLayout {
            service: ns.services.keyframes.clone(),
        });
        assert_eq!(keyframes(&node, &ns, Access::Open).err(), layout);
        assert_eq!(keyframes(&node, &ns, Access::Create(&small())).err(), layout);
    }

    #[test]
    fn a_full_daemon_queue_is_backpressure() {
        let ns = unique("full");
        let q = Qos {
            keyframe_buffer: 1,
            ..small()
        };
        let daemon = Ingress::create(&ns.name, &q).unwrap();
        let link = FrontendLink::open(&ns.name, Duration::ZERO).unwrap();
        // the daemon's subscriber connects to the link's publishers when it
        // next receives: one tick, then stop
        assert_eq!(daemon.run(Duration::from_millis(1), |_| false), Ok(Exit::Stopped));
        let keyframe = Keyframe {
            id: 1,
            timestamp_ns: 0,
            guess: [0.0; 7],
            has_guess: 0,
            frontend: 0,
            sequence: 0,
            protocol: PROTOCOL_VERSION,
            dimension: 2,
        };
        assert_eq!(link.send_keyframe(keyframe), Ok(()));
        assert_eq!(
            link.send_keyframe(keyframe),
            Err(TransportError::Backpressure {
                service: ns.services.keyframes.clone()
            })
        );
    }
}
