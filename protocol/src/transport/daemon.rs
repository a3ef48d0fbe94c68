//! The daemon's ports: [`Ingress`] (creates the services, receives input,
//! blocks on the WaitSet) and [`Outlet`] (publishes snapshots, switches and
//! rejections).

use super::services::{self, Access, Event, Namespace, Topic};
use super::{node, shm, TransportError};
use crate::message::{
    DaemonStatus, Edge, GpsFix, Keyframe, Pose, Rejection, SnapshotHeader, Switch, SwitchesHeader,
};
use crate::service::Qos;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::update_connections::UpdateConnections;
use iceoryx2::prelude::*;
use iceoryx2::waitset::WaitSetRunResult;
use std::time::Duration;

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
// A wake lives on the stack for one call; boxing the message (an edge's
// 264 bytes) would allocate once per message received.
#[allow(clippy::large_enum_variant)]
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
    _keyframes: Topic<Keyframe>,
    _edges: Topic<Edge>,
    _gps: Topic<GpsFix>,
    _poses: Topic<[Pose], SnapshotHeader>,
    _changes: Topic<[Pose], SnapshotHeader>,
    _rejections: Topic<Rejection>,
    _switches: Topic<[Switch], SwitchesHeader>,
    _status: Topic<DaemonStatus>,
    _ingest: Event,
    _published: Event,
}

impl Ingress {
    /// Checks `/dev/shm`, cleans up after dead processes, creates every
    /// service of `namespace` with `qos` (or opens it after a restart, if
    /// it offers at least those sizes) and subscribes.
    pub fn create(namespace: &str, qos: &Qos) -> Result<Self, TransportError> {
        shm::check_room(qos.shared_memory_bytes())?;
        let ns = Namespace::new(namespace);
        let node = node("slamd-daemon", true)?;
        let cleaned = node.try_cleanup_dead_nodes().cleanups;
        let access = Access::Create(qos);
        let keyframes = services::keyframes(&node, &ns, access)?;
        let edges = services::edges(&node, &ns, access)?;
        let gps = services::gps(&node, &ns, access)?;
        let poses = services::poses(&node, &ns, access)?;
        if let Some(pid) = publisher_pid(&poses) {
            return Err(TransportError::AlreadyServed {
                namespace: namespace.to_string(),
                pid,
            });
        }
        let changes = services::changes(&node, &ns, access)?;
        let rejections = services::rejections(&node, &ns, access)?;
        let switches = services::switches(&node, &ns, access)?;
        let status = services::status(&node, &ns, access)?;
        let ingest = services::ingest(&node, &ns, access)?;
        let published = services::published(&node, &ns, access)?;
        let names = &ns.services;
        let kf_sub = keyframes
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("subscribe to", &names.keyframes, &e))?;
        let edge_sub = edges
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("subscribe to", &names.edges, &e))?;
        let gps_sub = gps
            .subscriber_builder()
            .create()
            .map_err(|e| ns.fail("subscribe to", &names.gps, &e))?;
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
                _changes: changes,
                _rejections: rejections,
                _switches: switches,
                _status: status,
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

    /// Hands every queued message to `on`, then [`Wake::Drained`] if there
    /// was any (see [`drain_queues`]).
    fn drain(&self, on: &mut impl FnMut(Wake) -> bool) -> Result<(), TransportError> {
        let rx = |what: &str, e: &dyn std::fmt::Debug| TransportError::other(&format!("receive {what}"), e);
        let next = |queue: usize| -> Result<Option<Input>, TransportError> {
            Ok(match queue {
                0 => (self.keyframes.receive().map_err(|e| rx("keyframes", &e))?)
                    .map(|s| Input::Keyframe(*s.payload())),
                1 => (self.edges.receive().map_err(|e| rx("edges", &e))?).map(|s| Input::Edge(*s.payload())),
                _ => (self.gps.receive().map_err(|e| rx("gps", &e))?).map(|s| Input::Gps(*s.payload())),
            })
        };
        drain_queues(next, on)
    }
}

/// The process id of a live publisher of snapshots, if any: a daemon
/// already serving the namespace (dead ones were cleaned up before).
fn publisher_pid(poses: &Topic<[Pose], SnapshotHeader>) -> Option<i32> {
    let mut pid = None;
    poses.dynamic_config().list_publishers(|details| {
        pid = details.node_id.pid::<ipc::Service>().ok().map(|p| p.value());
        CallbackProgression::Stop
    });
    pid
}

/// Most passes one drain makes: a frontend that publishes faster than the
/// daemon drains still lets the timer through.
const MAX_PASSES: usize = 64;

/// Hands what the three input queues hold (`next(0)` keyframes, `next(1)`
/// edges, `next(2)` fixes) to `on`, in passes until one finds every queue
/// empty, then [`Wake::Drained`] if there was any.
///
/// A frontend numbers its messages across the three queues. One pass can
/// receive an edge yet miss the keyframe published just before it, if the
/// keyframe queue was read while still empty; the next pass finds it. So a
/// batch holds, of a frontend publishing from one thread, every message
/// sent before the newest one it holds: receiving a sample acquires what
/// its publisher released, the earlier samples included. The daemon's
/// rule that a new frontend's count starts at its first batch relies on
/// this.
fn drain_queues(
    mut next: impl FnMut(usize) -> Result<Option<Input>, TransportError>,
    on: &mut impl FnMut(Wake) -> bool,
) -> Result<(), TransportError> {
    let mut any = false;
    for _ in 0..MAX_PASSES {
        let mut got = false;
        for queue in 0..3 {
            while let Some(m) = next(queue)? {
                got = true;
                on(Wake::Input(m));
            }
        }
        if !got {
            break;
        }
        any = true;
    }
    if any {
        on(Wake::Drained);
    }
    Ok(())
}

/// The daemon's output side: snapshots and rejections.
pub struct Outlet {
    _node: Node<ipc::Service>,
    poses: Publisher<ipc::Service, [Pose], SnapshotHeader>,
    changes: Publisher<ipc::Service, [Pose], SnapshotHeader>,
    max_changes: usize,
    published: Notifier<ipc::Service>,
    rejections: Publisher<ipc::Service, Rejection, ()>,
    switches: Publisher<ipc::Service, [Switch], SwitchesHeader>,
    status: Publisher<ipc::Service, DaemonStatus, ()>,
}

impl Outlet {
    /// Opens the output services an [`Ingress`] created. The snapshot and
    /// switches publishers first reserve `qos.initial_poses` elements (at
    /// least 1) and grow by powers of two; the changes publisher holds
    /// `qos.max_changes` poses a sample, always.
    pub fn open(namespace: &str, qos: &Qos) -> Result<Self, TransportError> {
        let ns = Namespace::new(namespace);
        let names = &ns.services;
        let node = node("slamd-daemon-outlet", false)?;
        let topic = services::poses(&node, &ns, Access::Open)?;
        // a daemon started in the same instant as another gets this far
        let poses = topic
            .publisher_builder()
            .initial_max_slice_len(qos.initial_poses.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| match publisher_pid(&topic) {
                Some(pid) => TransportError::AlreadyServed {
                    namespace: namespace.to_string(),
                    pid,
                },
                None => ns.fail("open", &names.poses, &e),
            })?;
        let max_changes = qos.max_changes.max(1);
        let changes = services::changes(&node, &ns, Access::Open)?
            .publisher_builder()
            .initial_max_slice_len(max_changes)
            .create()
            .map_err(|e| ns.fail("open", &names.changes, &e))?;
        let rejections = services::rejections(&node, &ns, Access::Open)?
            .publisher_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.rejections, &e))?;
        let switches = services::switches(&node, &ns, Access::Open)?
            .publisher_builder()
            .initial_max_slice_len(qos.initial_poses.max(1))
            .allocation_strategy(AllocationStrategy::PowerOfTwo)
            .create()
            .map_err(|e| ns.fail("open", &names.switches, &e))?;
        let published = services::published(&node, &ns, Access::Open)?
            .notifier_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.published, &e))?;
        let status = services::status(&node, &ns, Access::Open)?
            .publisher_builder()
            .create()
            .map_err(|e| ns.fail("open", &names.status, &e))?;
        Ok(Self {
            _node: node,
            poses,
            changes,
            max_changes,
            published,
            rejections,
            switches,
            status,
        })
    }

    /// Publishes one snapshot whole: `header` and `count` poses taken from
    /// `poses` (written straight into shared memory) on `{ns}/poses`, a
    /// sample on `{ns}/changes` saying so, then wakes the subscribers.
    pub fn publish_whole(
        &self,
        header: SnapshotHeader,
        count: usize,
        poses: impl Iterator<Item = Pose>,
    ) -> Result<(), TransportError> {
        let header = SnapshotHeader {
            poses: count as u64,
            whole: 1,
            ..header
        };
        send_slice(
            &self.poses,
            SnapshotHeader { base: 0, ..header },
            count,
            poses,
            "snapshot",
        )?;
        let marker = SnapshotHeader { poses: 0, ..header };
        send_slice(&self.changes, marker, 0, std::iter::empty(), "snapshot changes")?;
        let _ = self.published.notify();
        Ok(())
    }

    /// Publishes what one snapshot changed since version `header.base`:
    /// `count` poses (at most `qos.max_changes`) on `{ns}/changes`,
    /// then wakes the subscribers.
    pub fn publish_changes(
        &self,
        header: SnapshotHeader,
        count: usize,
        poses: impl Iterator<Item = Pose>,
    ) -> Result<(), TransportError> {
        if count > self.max_changes {
            return Err(TransportError::other(
                "send snapshot changes",
                format_args!("{count} poses, more than the {} a sample holds", self.max_changes),
            ));
        }
        let header = SnapshotHeader {
            poses: count as u64,
            whole: 0,
            ..header
        };
        send_slice(&self.changes, header, count, poses, "snapshot changes")?;
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

    /// Publishes the daemon's status with its acknowledgements (before the
    /// snapshot that carries the same). A snapshot or switches subscriber
    /// that arrived since the last publish gets the latest one now (the
    /// topics' history), so one that subscribes to a daemon at rest need
    /// not wait for new input.
    pub fn publish_status(&self, m: DaemonStatus) -> Result<(), TransportError> {
        let _ = self.poses.update_connections();
        let _ = self.changes.update_connections();
        let _ = self.switches.update_connections();
        self.status
            .send_copy(m)
            .map(|_| ())
            .map_err(|e| TransportError::other("send status", e))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::{edge_out, keyframe_out, Origin};
    use slamd_types::{EdgeInput, EdgeKind, Information, Pose2};
    use std::collections::VecDeque;

    fn from(sequence: u64) -> Origin {
        Origin {
            frontend: 1,
            sequence,
        }
    }

    fn keyframe(sequence: u64) -> Input {
        Input::Keyframe(keyframe_out::<Pose2>(sequence, 0, None, from(sequence)))
    }

    fn edge(sequence: u64) -> Input {
        let e = EdgeInput::new(1, 2, Pose2::IDENTITY, Information::identity(), EdgeKind::Odometry);
        Input::Edge(edge_out(&e, from(sequence)))
    }

    fn sequence(w: &Wake) -> Option<u64> {
        match w {
            Wake::Input(Input::Keyframe(k)) => Some(k.sequence),
            Wake::Input(Input::Edge(e)) => Some(e.sequence),
            Wake::Input(Input::Gps(g)) => Some(g.sequence),
            _ => None,
        }
    }

    #[test]
    fn a_keyframe_published_before_a_received_edge_is_in_the_same_batch() {
        // the frontend publishes keyframes 1 and 2 and edge 3 after the
        // keyframe queue was read empty, before the edge queue is read
        let mut queues: [VecDeque<Input>; 3] = Default::default();
        let mut reads = 0;
        let next = |q: usize| {
            reads += 1;
            if reads == 2 {
                queues[0].extend([keyframe(1), keyframe(2)]);
                queues[1].push_back(edge(3));
            }
            Ok(queues[q].pop_front())
        };
        let mut wakes = Vec::new();
        drain_queues(next, &mut |w| {
            wakes.push(w);
            true
        })
        .unwrap();
        let order: Vec<Option<u64>> = wakes.iter().map(sequence).collect();
        assert_eq!(order, [Some(3), Some(1), Some(2), None]);
        assert_eq!(wakes.last(), Some(&Wake::Drained));
    }

    #[test]
    fn empty_queues_hand_over_nothing() {
        let mut wakes = Vec::new();
        drain_queues(|_| Ok(None), &mut |w| {
            wakes.push(w);
            true
        })
        .unwrap();
        assert!(wakes.is_empty());
    }
}
