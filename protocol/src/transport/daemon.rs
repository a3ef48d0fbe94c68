//! The daemon's ports: [`Ingress`] (creates the services, receives input,
//! blocks on the WaitSet) and [`Outlet`] (publishes snapshots, switches and
//! rejections).

use super::{classify, node, protocol_attributes, service_name, shm, TransportError};
use crate::message::{Edge, GpsFix, Keyframe, Pose, Rejection, SnapshotHeader, Switch, SwitchesHeader};
use crate::service::{Qos, ServiceNames};
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, publish_subscribe};
use iceoryx2::waitset::WaitSetRunResult;
use std::time::Duration;

/// Samples a subscriber of the latest-value topics (poses, switches) may
/// hold at once: one kept by the caller (the last snapshot), the newest
/// inside `Snapshots::latest`, and the one it is receiving. With 2 a
/// replay that kept its last snapshot failed with `ExceedsMaxBorrows`
/// whenever two snapshots arrived between calls.
const MAX_BORROWED: usize = 3;

/// Opens or creates a frontend → daemon topic of `T` named `name`: up to
/// `max_frontends` publishers, the daemon's subscriber and one spare, a
/// queue of `buffer` samples, no history, and no safe overflow (a full
/// queue never overwrites input).
fn input_topic<T: std::fmt::Debug + ZeroCopySend>(
    node: &Node<ipc::Service>,
    namespace: &str,
    name: &str,
    max_frontends: usize,
    buffer: usize,
) -> Result<publish_subscribe::PortFactory<ipc::Service, T, ()>, TransportError> {
    node.service_builder(&service_name(name)?)
        .publish_subscribe::<T>()
        .max_publishers(max_frontends)
        .max_subscribers(2)
        .subscriber_max_buffer_size(buffer)
        .history_size(0)
        .enable_safe_overflow(false)
        .open_or_create_with_attributes(&protocol_attributes())
        .map_err(|e| classify("create", namespace, name, &e))
}

/// One message from a frontend.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Input {
    /// A keyframe.
    Keyframe(Keyframe),
    /// An edge.
    Edge(Edge),
    /// A GPS fix.
    Gps(GpsFix),
}

/// Why [`Ingress::run`] returned.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Exit {
    /// SIGINT or SIGTERM.
    Signal,
    /// The callback asked to stop.
    Stopped,
}

/// What woke the daemon, as handed to [`Ingress::run`]'s callback.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Wake {
    /// One input message.
    Input(Input),
    /// Every queued message has been handed over.
    Drained,
    /// The timer ticked (dead nodes have just been cleaned up).
    Tick,
}

/// The daemon's input side; it also owns every service of the namespace.
pub struct Ingress {
    node: Node<ipc::Service>,
    cleaned: u64,
    keyframes: Subscriber<ipc::Service, Keyframe, ()>,
    edges: Subscriber<ipc::Service, Edge, ()>,
    gps: Subscriber<ipc::Service, GpsFix, ()>,
    ingest: Listener<ipc::Service>,
    _services: Services,
}

/// Keeps every service open for the daemon's lifetime.
struct Services {
    _keyframes: publish_subscribe::PortFactory<ipc::Service, Keyframe, ()>,
    _edges: publish_subscribe::PortFactory<ipc::Service, Edge, ()>,
    _gps: publish_subscribe::PortFactory<ipc::Service, GpsFix, ()>,
    _poses: publish_subscribe::PortFactory<ipc::Service, [Pose], SnapshotHeader>,
    _rejections: publish_subscribe::PortFactory<ipc::Service, Rejection, ()>,
    _switches: publish_subscribe::PortFactory<ipc::Service, [Switch], SwitchesHeader>,
    _ingest: event::PortFactory<ipc::Service>,
    _published: event::PortFactory<ipc::Service>,
}

impl Ingress {
    /// Checks `/dev/shm`, cleans up after dead processes, creates every
    /// service of `namespace` (or opens it after a restart) and subscribes.
    pub fn create(namespace: &str, qos: &Qos) -> Result<Self, TransportError> {
        shm::check_room(qos.shared_memory_bytes())?;
        let names = ServiceNames::new(namespace);
        let node = node("slamd-daemon", true)?;
        let cleaned = node.try_cleanup_dead_nodes().cleanups;
        let attrs = protocol_attributes();
        let frontends = qos.max_frontends;
        let keyframes =
            input_topic::<Keyframe>(&node, namespace, &names.keyframes, frontends, qos.keyframe_buffer)?;
        let edges = input_topic::<Edge>(&node, namespace, &names.edges, frontends, qos.edge_buffer)?;
        let gps = input_topic::<GpsFix>(&node, namespace, &names.gps, frontends, qos.gps_buffer)?;
        let poses = node
            .service_builder(&service_name(&names.poses)?)
            .publish_subscribe::<[Pose]>()
            .user_header::<SnapshotHeader>()
            .max_publishers(1)
            .max_subscribers(qos.max_subscribers)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(MAX_BORROWED)
            .history_size(1)
            .enable_safe_overflow(true)
            .open_or_create_with_attributes(&attrs)
            .map_err(|e| classify("create", namespace, &names.poses, &e))?;
        let rejections = node
            .service_builder(&service_name(&names.rejections)?)
            .publish_subscribe::<Rejection>()
            .max_publishers(1)
            .max_subscribers(qos.max_subscribers)
            .subscriber_max_buffer_size(64)
            .history_size(qos.rejection_history)
            .enable_safe_overflow(true)
            .open_or_create_with_attributes(&attrs)
            .map_err(|e| classify("create", namespace, &names.rejections, &e))?;
        let switches = node
            .service_builder(&service_name(&names.switches)?)
            .publish_subscribe::<[Switch]>()
            .user_header::<SwitchesHeader>()
            .max_publishers(1)
            .max_subscribers(qos.max_subscribers)
            .subscriber_max_buffer_size(1)
            .subscriber_max_borrowed_samples(MAX_BORROWED)
            .history_size(1)
            .enable_safe_overflow(true)
            .open_or_create_with_attributes(&attrs)
            .map_err(|e| classify("create", namespace, &names.switches, &e))?;
        let ingest = node
            .service_builder(&service_name(&names.ingest)?)
            .event()
            .max_notifiers(qos.max_frontends)
            .max_listeners(2)
            .open_or_create_with_attributes(&attrs)
            .map_err(|e| classify("create", namespace, &names.ingest, &e))?;
        let published = node
            .service_builder(&service_name(&names.published)?)
            .event()
            .max_notifiers(2)
            .max_listeners(qos.max_subscribers)
            .open_or_create_with_attributes(&attrs)
            .map_err(|e| classify("create", namespace, &names.published, &e))?;
        let kf_sub = keyframes
            .subscriber_builder()
            .create()
            .map_err(|e| classify("subscribe to", namespace, &names.keyframes, &e))?;
        let edge_sub = edges
            .subscriber_builder()
            .create()
            .map_err(|e| classify("subscribe to", namespace, &names.edges, &e))?;
        let gps_sub = gps
            .subscriber_builder()
            .create()
            .map_err(|e| classify("subscribe to", namespace, &names.gps, &e))?;
        let listener = ingest
            .listener_builder()
            .create()
            .map_err(|e| TransportError::other("listen on ingest", e))?;
        Ok(Self {
            node,
            cleaned,
            keyframes: kf_sub,
            edges: edge_sub,
            gps: gps_sub,
            ingest: listener,
            _services: Services {
                _keyframes: keyframes,
                _edges: edges,
                _gps: gps,
                _poses: poses,
                _rejections: rejections,
                _switches: switches,
                _ingest: ingest,
                _published: published,
            },
        })
    }

    /// Dead processes whose iceoryx2 resources were removed at start.
    pub fn cleaned_at_start(&self) -> u64 {
        self.cleaned
    }

    /// Blocks on a WaitSet until SIGINT or SIGTERM (or `on` returns
    /// `false`). On a poke from a frontend, and on every `tick` as a safety
    /// net, hands each queued message to `on`, then [`Wake::Drained`]; on a
    /// tick it first cleans up dead nodes, then [`Wake::Tick`]. Never spins:
    /// the poke is consumed before the queues are drained.
    pub fn run(&self, tick: Duration, mut on: impl FnMut(Wake) -> bool) -> Result<Exit, TransportError> {
        let waitset = WaitSetBuilder::new()
            .signal_handling_mode(SignalHandlingMode::HandleTerminationRequests)
            .create::<ipc::Service>()
            .map_err(|e| TransportError::other("create WaitSet", e))?;
        let poke = waitset
            .attach_notification(&self.ingest)
            .map_err(|e| TransportError::other("attach ingest listener", e))?;
        let timer = waitset
            .attach_interval(tick)
            .map_err(|e| TransportError::other("attach timer", e))?;
        let mut stop = false;
        let mut failure = None;
        let result = waitset.wait_and_process(|id| {
            if id.has_event_from(&timer) {
                self.node.try_cleanup_dead_nodes();
                if let Err(e) = self.drain(&mut on) {
                    failure = Some(e);
                    return CallbackProgression::Stop;
                }
                stop |= !on(Wake::Tick);
            }
            if id.has_event_from(&poke) {
                // consume the notification, then the data it announced
                let _ = self.ingest.try_wait(|_| {});
                if let Err(e) = self.drain(&mut on) {
                    failure = Some(e);
                    return CallbackProgression::Stop;
                }
            }
            if stop {
                CallbackProgression::Stop
            } else {
                CallbackProgression::Continue
            }
        });
        if let Some(e) = failure {
            return Err(e);
        }
        match result {
            Ok(WaitSetRunResult::Interrupt) | Ok(WaitSetRunResult::TerminationRequest) => Ok(Exit::Signal),
            Ok(_) => Ok(Exit::Stopped),
            Err(e) => Err(TransportError::other("wait", e)),
        }
    }

    /// Hands every queued message to `on`, keyframes first, then
    /// [`Wake::Drained`] if there was any.
    fn drain(&self, on: &mut impl FnMut(Wake) -> bool) -> Result<(), TransportError> {
        let mut any = false;
        let rx = |what: &str, e: &dyn std::fmt::Debug| TransportError::other(&format!("receive {what}"), e);
        while let Some(s) = self.keyframes.receive().map_err(|e| rx("keyframes", &e))? {
            any = true;
            on(Wake::Input(Input::Keyframe(*s.payload())));
        }
        while let Some(s) = self.edges.receive().map_err(|e| rx("edges", &e))? {
            any = true;
            on(Wake::Input(Input::Edge(*s.payload())));
        }
        while let Some(s) = self.gps.receive().map_err(|e| rx("gps", &e))? {
            any = true;
            on(Wake::Input(Input::Gps(*s.payload())));
        }
        if any {
            on(Wake::Drained);
        }
        Ok(())
    }
}

/// The daemon's output side: snapshots and rejections.
pub struct Outlet {
    _node: Node<ipc::Service>,
    poses: Publisher<ipc::Service, [Pose], SnapshotHeader>,
    published: Notifier<ipc::Service>,
    rejections: Publisher<ipc::Service, Rejection, ()>,
    switches: Publisher<ipc::Service, [Switch], SwitchesHeader>,
}

impl Outlet {
    /// Opens the output services an [`Ingress`] created.
    pub fn open(namespace: &str, qos: &crate::service::Qos) -> Result<Self, TransportError> {
        let names = ServiceNames::new(namespace);
        let node = node("slamd-daemon-outlet", false)?;
        let attrs = protocol_attributes();
        let poses = node
            .service_builder(&service_name(&names.poses)?)
            .publish_subscribe::<[Pose]>()
            .user_header::<SnapshotHeader>()
            .open_with_attributes(&attrs)
            .map_err(|e| classify("open", namespace, &names.poses, &e))?
            .publisher_builder()
            .initial_max_slice_len(qos.initial_poses.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| classify("open", namespace, &names.poses, &e))?;
        let rejections = node
            .service_builder(&service_name(&names.rejections)?)
            .publish_subscribe::<Rejection>()
            .open_with_attributes(&attrs)
            .map_err(|e| classify("open", namespace, &names.rejections, &e))?
            .publisher_builder()
            .create()
            .map_err(|e| classify("open", namespace, &names.rejections, &e))?;
        let switches = node
            .service_builder(&service_name(&names.switches)?)
            .publish_subscribe::<[Switch]>()
            .user_header::<SwitchesHeader>()
            .open_with_attributes(&attrs)
            .map_err(|e| classify("open", namespace, &names.switches, &e))?
            .publisher_builder()
            .initial_max_slice_len(qos.initial_poses.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| classify("open", namespace, &names.switches, &e))?;
        let published = node
            .service_builder(&service_name(&names.published)?)
            .event()
            .open_with_attributes(&attrs)
            .map_err(|e| classify("open", namespace, &names.published, &e))?
            .notifier_builder()
            .create()
            .map_err(|e| classify("open", namespace, &names.published, &e))?;
        Ok(Self {
            _node: node,
            poses,
            published,
            rejections,
            switches,
        })
    }

    /// Publishes one snapshot: `header` and `count` poses taken from
    /// `poses` (written straight into shared memory), then wakes the
    /// subscribers.
    pub fn publish(
        &self,
        header: SnapshotHeader,
        count: usize,
        poses: impl Iterator<Item = Pose>,
    ) -> Result<(), TransportError> {
        let header = SnapshotHeader {
            poses: count as u64,
            ..header
        };
        send_slice(&self.poses, header, count, poses, "snapshot")?;
        let _ = self.published.notify();
        Ok(())
    }

    /// Publishes the switch of every loop closure (`count` taken from
    /// `switches`, written straight into shared memory).
    pub fn publish_switches(
        &self,
        header: SwitchesHeader,
        count: usize,
        switches: impl Iterator<Item = Switch>,
    ) -> Result<(), TransportError> {
        let header = SwitchesHeader {
            count: count as u64,
            ..header
        };
        send_slice(&self.switches, header, count, switches, "switches")
    }

    /// Publishes a rejection.
    pub fn reject(&self, r: Rejection) -> Result<(), TransportError> {
        self.rejections
            .send_copy(r)
            .map(|_| ())
            .map_err(|e| TransportError::other("send rejection", e))
    }
}

/// Loans `count` elements, writes `header` and the items (defaults if the
/// iterator runs short) straight into shared memory, and sends.
fn send_slice<T, H>(
    publisher: &Publisher<ipc::Service, [T], H>,
    header: H,
    count: usize,
    mut items: impl Iterator<Item = T>,
    what: &str,
) -> Result<(), TransportError>
where
    T: std::fmt::Debug + Default + ZeroCopySend + 'static,
    H: std::fmt::Debug + Default + ZeroCopySend + 'static,
{
    let mut sample = publisher
        .loan_slice_uninit(count)
        .map_err(|e| TransportError::other(&format!("loan {what} memory"), e))?;
    *sample.user_header_mut() = header;
    let sample = sample.write_from_fn(|_| items.next().unwrap_or_default());
    sample
        .send()
        .map_err(|e| TransportError::other(&format!("send {what}"), e))?;
    Ok(())
}
