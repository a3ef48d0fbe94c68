//! The daemon's engine thread: applies each batch of messages, holds edges
//! for missing keyframes, journals what it took and publishes one snapshot
//! per batch (its state directory is in [`super::durable`]).

use super::durability::{now_ns, Durability};
use super::health::Latency;
use super::held::{Held, Waiting};
use super::publication::{Carry, Publication};
use crate::config::Config;
use crate::engine::{upper_triangle, EdgeInput, Engine, EngineError, EnginePose, FixInput};
use crate::graph::{EdgeKind, GraphError, KeyframeId, KeyframeInput};
use crate::store::Record;
use crate::wire::{self, engine_rejection};
use crossbeam::channel::{Receiver, RecvTimeoutError};
use slamd_protocol::codec::Origin;
use slamd_protocol::message::kind;
use slamd_protocol::transport::{Outlet, TransportError};
use slamd_protocol::{
    DaemonStatus, Pose, Rejection, RejectionReason, SnapshotHeader, INFORMATION_UPPER, PROTOCOL_VERSION,
};
use std::time::{Duration, Instant};

/// What the IPC thread hands over; `P` is the pose type the daemon serves.
#[derive(Clone, Debug)]
pub enum Msg<P: EnginePose> {
    /// A checked keyframe.
    Keyframe(Origin, KeyframeInput<P>),
    /// A checked edge.
    Edge(Origin, EdgeInput<P>),
    /// A checked GPS fix.
    Gps(Origin, FixInput),
    /// A message refused on arrival; publish and count it.
    Rejected(Rejection),
    /// The IPC thread has handed over everything it had.
    Drained,
    /// The IPC thread's timer ticked.
    Tick,
    /// A background re-solve finished: swapped in at once when input has
    /// paused for [`QUIET_INPUT`], else with the next batch.
    Resolved,
    /// Stop (SIGINT or SIGTERM).
    Shutdown,
}

/// The switches of every loop closure go out at most this often while the
/// daemon works on input (and with every settled snapshot).
const SWITCHES_EVERY: Duration = Duration::from_millis(100);

/// A pause in input after which a finished re-solve is published at once.
const QUIET_INPUT: Duration = Duration::from_millis(20);

/// Counters the snapshot header reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Keyframes accepted.
    pub keyframes: u64,
    /// Edges accepted (including those still held).
    pub edges: u64,
    /// GPS fixes accepted (including those still held).
    pub fixes: u64,
    /// Messages rejected.
    pub rejected: u64,
    /// Messages dropped as repeats of one taken before.
    pub duplicates: u64,
}

/// The engine thread's state.
pub struct EngineLoop<P: EnginePose> {
    pub(super) engine: Engine<P>,
    outlet: Outlet,
    pub(super) held: Held<EdgeInput<P>>,
    pub(super) held_fixes: Held<FixInput>,
    pub(super) config: Config,
    pub(super) counters: Counters,
    /// Acknowledgements, the journal and checkpoints.
    pub(super) durability: Durability,
    /// Taking up a saved map: refusals were published before the restart
    /// and are not published again.
    pub(super) recovering: bool,
    /// This daemon start's number in the acknowledgements.
    instance: u64,
    /// When it started (ns since the UNIX epoch).
    started_at_ns: u64,
    /// When the engine thread took the first message of the batch being
    /// gathered.
    batch_start: Option<Instant>,
    latency: Latency,
    /// The last snapshot's header.
    last_header: SnapshotHeader,
    pub(super) dirty: bool,
    last_publish: Option<Instant>,
    last_input: Instant,
    /// When the last snapshot that answered input went out (a frontend
    /// waiting for it is not a pause in input), and whether input came
    /// since.
    last_answer: Instant,
    answer_due: bool,
    /// Input came since the engine was last told it is idle.
    idle_due: bool,
    /// A loop closure arrived or a switch changed since the switches were
    /// last published, and when they were.
    switches_due: bool,
    last_switches: Option<Instant>,
    /// Whole maps or changes, and how much went out.
    publication: Publication,
}

impl<P: EnginePose> EngineLoop<P> {
    pub fn new(config: Config, outlet: Outlet) -> Self {
        let durability = Durability::new(config.state.checkpoint_interval_s);
        let publication = Publication::new(
            config.ipc.max_changes,
            Duration::from_millis(config.snapshot.whole_every_ms),
        );
        Self {
            engine: Engine::create(config.engine()),
            outlet,
            held: Held::default(),
            held_fixes: Held::default(),
            config,
            counters: Counters::default(),
            durability,
            recovering: false,
            instance: new_instance(),
            started_at_ns: now_ns(),
            batch_start: None,
            latency: Latency::default(),
            // the status says which dimension is served before any snapshot
            last_header: SnapshotHeader {
                protocol: PROTOCOL_VERSION,
                dimension: P::DIMENSION,
                ..SnapshotHeader::default()
            },
            dirty: false,
            last_publish: None,
            last_input: Instant::now(),
            last_answer: Instant::now(),
            answer_due: false,
            idle_due: false,
            switches_due: false,
            last_switches: None,
            publication,
        }
    }

    /// Runs until [`Msg::Shutdown`] or the channel closes. Each wake
    /// applies every message already queued, then publishes once.
    pub fn run(mut self, rx: Receiver<Msg<P>>) -> Counters {
        let tick = Duration::from_millis(self.config.ipc.tick_ms);
        // frontends learn at once that this daemon serves them
        self.publish_status();
        loop {
            let first = match rx.recv_timeout(self.wait_time(tick)) {
                Ok(m) => m,
                Err(RecvTimeoutError::Timeout) => Msg::Tick,
                Err(RecvTimeoutError::Disconnected) => break,
            };
            if matches!(first, Msg::Keyframe(..) | Msg::Edge(..) | Msg::Gps(..)) {
                self.batch_start.get_or_insert_with(Instant::now);
            }
            if !self.handle(first) {
                break;
            }
            let mut open = true;
            while let Ok(m) = rx.try_recv() {
                if !self.handle(m) {
                    open = false;
                    break;
                }
            }
            self.publish_if_due();
            if self.durability.checkpoint_due() {
                self.checkpoint();
            }
            if !open {
                break;
            }
        }
        // whatever arrived last goes out, and into a checkpoint
        self.last_publish = None;
        self.publish_if_due();
        self.checkpoint();
        let p = &self.publication;
        tracing::info!(
            snapshots = p.published,
            whole = p.whole,
            poses = p.poses,
            bytes_per_snapshot = (p.poses * size_of::<Pose>() as u64) / p.published.max(1),
            "Snapshots published."
        );
        self.counters
    }

    /// How long to block: until the rate cap allows the pending snapshot,
    /// else a tick, or less when input paused: the engine hears that it is
    /// idle (and starts its re-solve) a tick after the last input, not up
    /// to two.
    fn wait_time(&self, tick: Duration) -> Duration {
        let floor = Duration::from_micros(100);
        let wait = match (self.dirty, self.min_interval(), self.last_publish) {
            (true, Some(min), Some(last)) => min.saturating_sub(last.elapsed()).max(floor),
            _ => tick,
        };
        if self.idle_due {
            wait.min(tick.saturating_sub(self.quiet_for()).max(floor))
        } else {
            wait
        }
    }

    fn min_interval(&self) -> Option<Duration> {
        let hz = self.config.snapshot.max_rate_hz;
        (hz > 0.0).then(|| Duration::from_secs_f64(1.0 / hz))
    }

    /// Applies one message; `false` means stop.
    fn handle(&mut self, msg: Msg<P>) -> bool {
        match msg {
            Msg::Keyframe(o, k) => self.take(Record::Keyframe(o, k)),
            Msg::Edge(o, edge) => self.take(Record::Edge(o, edge)),
            Msg::Gps(o, fix) => self.take(Record::Fix(o, fix)),
            Msg::Rejected(r) => {
                let o = Origin {
                    frontend: r.frontend,
                    sequence: r.sequence,
                };
                if self.admit(Record::Refused(o)) {
                    self.reject(r);
                }
            }
            Msg::Drained => self.durability.seal(),
            Msg::Tick => self.tick(),
            // while input flows the next batch swaps it in; an update for
            // it alone would hold up the keyframe behind it
            Msg::Resolved => self.dirty |= self.last_input.elapsed() >= QUIET_INPUT,
            Msg::Shutdown => return false,
        }
        true
    }

    /// Takes one message in: acknowledged, journaled, applied; dropped if
    /// it repeats one taken before.
    fn take(&mut self, r: Record<P>) {
        if self.admit(r) {
            self.last_input = Instant::now();
            (self.idle_due, self.answer_due) = (true, true);
            self.apply(r);
        }
    }

    /// Records `r` as taken and journals it; false for a duplicate.
    pub(super) fn admit(&mut self, r: Record<P>) -> bool {
        if !self.durability.admit(&r) {
            self.counters.duplicates += 1;
            return false;
        }
        self.dirty = true;
        true
    }

    /// Applies a message taken in.
    fn apply(&mut self, r: Record<P>) {
        match r {
            Record::Keyframe(o, k) => match self.engine.add_keyframe_at(k.id, k.guess, k.timestamp_ns) {
                Ok(_) => {
                    self.counters.keyframes += 1;
                    for h in self.held.release(k.id) {
                        self.add_edge(h.origin, h.item, h.since);
                    }
                    for h in self.held_fixes.release(k.id) {
                        self.add_gps(h.origin, h.item, h.since);
                    }
                }
                Err(e) => self.reject(engine_rejection(o, kind::KEYFRAME, [k.id, 0], &e)),
            },
            Record::Edge(o, edge) => self.add_edge(o, edge, Instant::now()),
            Record::Fix(o, fix) => self.add_gps(o, fix, Instant::now()),
            Record::Refused(_) => {}
        }
    }

    /// Adds an edge, or holds it while one of its keyframes is missing.
    pub(super) fn add_edge(&mut self, o: Origin, edge: EdgeInput<P>, since: Instant) {
        match self.engine.add_edge_from(edge, o) {
            Ok(_) => {
                self.counters.edges += 1;
                self.dirty = true;
                self.switches_due |= edge.kind != EdgeKind::Odometry;
            }
            Err(EngineError::Graph(GraphError::UnknownKeyframe(missing))) => {
                let h = Waiting {
                    origin: o,
                    item: edge,
                    since,
                };
                if !self.held.hold(missing, h, self.config.held_edges) {
                    self.reject(Rejection::new(
                        o.frontend,
                        o.sequence,
                        kind::EDGE,
                        RejectionReason::HeldOverflow,
                        [edge.from, edge.to],
                        &format!(
                            "edge {}→{}: {} edges already wait for keyframes (held_edges)",
                            edge.from,
                            edge.to,
                            self.held.len()
                        ),
                    ));
                }
            }
            Err(e) => self.reject(engine_rejection(o, kind::EDGE, [edge.from, edge.to], &e)),
        }
    }

    /// Adds a fix, or holds it while its keyframe is missing (sharing the
    /// `held_edges` cap and timeout).
    pub(super) fn add_gps(&mut self, o: Origin, fix: FixInput, since: Instant) {
        match self.engine.add_gps(fix) {
            Ok(()) => {
                self.counters.fixes += 1;
                self.dirty = true;
            }
            Err(EngineError::FixKeyframe(missing)) => {
                let h = Waiting {
                    origin: o,
                    item: fix,
                    since,
                };
                if !self.held_fixes.hold(missing, h, self.config.held_edges) {
                    self.reject(Rejection::new(
                        o.frontend,
                        o.sequence,
                        kind::GPS,
                        RejectionReason::HeldOverflow,
                        [fix.keyframe, 0],
                        &format!("fix on keyframe {missing}: too many messages wait (held_edges)"),
                    ));
                }
            }
            Err(e) => self.reject(engine_rejection(o, kind::GPS, [fix.keyframe, 0], &e)),
        }
    }

    fn reject(&mut self, r: Rejection) {
        self.counters.rejected += 1;
        if self.recovering {
            // published before the restart
            tracing::debug!(frontend = r.frontend, sequence = r.sequence, "{}", r.text());
            return;
        }
        tracing::warn!(frontend = r.frontend, sequence = r.sequence, reason = ?r.reason(), "{}", r.text());
        if let Err(e) = self.outlet.reject(r) {
            tracing::error!(error = %e, "Cannot publish a rejection.");
        }
    }

    /// Idle work: expire waiting edges; when input has paused, let the
    /// engine re-solve; swap a finished re-solve in.
    fn tick(&mut self) {
        let limit = Duration::from_secs_f64(self.config.held_timeout_s);
        for (missing, h) in self.held.expire(Instant::now(), limit) {
            self.reject(Rejection::new(
                h.origin.frontend,
                h.origin.sequence,
                kind::EDGE,
                RejectionReason::UnknownKeyframe,
                [h.item.from, h.item.to],
                &format!(
                    "edge {}→{}: keyframe {missing} did not arrive within {} s",
                    h.item.from, h.item.to, self.config.held_timeout_s
                ),
            ));
        }
        for (missing, h) in self.held_fixes.expire(Instant::now(), limit) {
            self.reject(Rejection::new(
                h.origin.frontend,
                h.origin.sequence,
                kind::GPS,
                RejectionReason::UnknownKeyframe,
                [missing, 0],
                &format!(
                    "GPS fix: keyframe {missing} did not arrive within {} s",
                    self.config.held_timeout_s
                ),
            ));
        }
        let tick = Duration::from_millis(self.config.ipc.tick_ms);
        if self.quiet_for() >= tick {
            if self.idle_due {
                tracing::debug!(
                    quiet_ms = self.quiet_for().as_millis() as u64,
                    keyframes = self.counters.keyframes,
                    "Input paused; the engine idles."
                );
            }
            self.idle_due = false;
            self.engine.idle();
        }
        // operators (`slamd status`) read the daemon while it idles
        self.publish_status();
        self.durability.sync_if_due();
        if self.engine.resolving() || self.durability.failing() {
            // a finished re-solve is swapped in at the next update; a
            // failed journal commit is tried again
            self.dirty = true;
        }
        // clients waiting for the final map learn that it is settled
        self.dirty |= self.last_header.settling != 0 && !self.settling();
    }

    /// How long input has paused: since the last message, or since the
    /// snapshot that answered it if that went out later (a frontend that
    /// waits for its acknowledgement while the engine works has not
    /// paused; telling the engine it idles then would start the closing
    /// re-solves in the middle of a stream).
    fn quiet_for(&self) -> Duration {
        self.last_input.max(self.last_answer).elapsed()
    }

    /// Whether the input so far still has work under way: it came within
    /// a tick (the engine has not been told it is idle), or the engine
    /// settles it ([`Engine::settling`]).
    fn settling(&self) -> bool {
        self.idle_due || self.engine.settling()
    }

    fn publish_if_due(&mut self) {
        if !self.dirty {
            return;
        }
        if let (Some(min), Some(last)) = (self.min_interval(), self.last_publish) {
            if last.elapsed() < min {
                return;
            }
        }
        // what the snapshot acknowledges is on disk first
        self.durability.commit();
        self.publish_status();
        let t0 = Instant::now();
        let report = self.engine.update();
        let solved = t0.elapsed();
        let covariance = self.newest_covariance();
        let changes = self.engine.take_changes();
        let settling = self.settling();
        if !settling && self.last_header.settling != 0 {
            self.publication.whole_next();
        }
        let snap = self.engine.snapshot();
        let carry = self
            .publication
            .plan(snap.version, changes, snap.georef, Instant::now());
        let header = SnapshotHeader {
            protocol: PROTOCOL_VERSION,
            dimension: P::DIMENSION,
            version: snap.version,
            poses: 0,
            chi2: snap.chi2,
            solved_at_ns: now_ns(),
            keyframes: self.counters.keyframes,
            edges: self.counters.edges,
            rejected: self.counters.rejected,
            held: (self.held.len() + self.held_fixes.len()) as u64,
            resolves: snap.resolves as u64,
            fixes: self.counters.fixes,
            georeferenced: u32::from(snap.georef.is_some()),
            has_origin: u32::from(snap.origin.is_some()),
            origin: snap.origin.map_or([0.0; 3], |o| [o.lat, o.lon, o.height]),
            acks: self.durability.acknowledged(),
            has_covariance: u32::from(covariance.is_some()),
            pending: snap.pending as u32,
            covariance_keyframe: covariance.map_or(0, |c| c.0),
            covariance: covariance.map_or([0.0; INFORMATION_UPPER], |c| c.1),
            instance: self.instance,
            settling: u32::from(settling),
            ..SnapshotHeader::default()
        };
        let georef = snap.georef;
        let out = |(id, p, t): (KeyframeId, P, u64)| wire::pose_out(id, &p, t, georef.as_ref());
        let result: Result<(), TransportError> = match carry {
            Carry::Whole => {
                let poses = snap
                    .poses()
                    .zip(snap.timestamps())
                    .map(|((id, p), t)| out((id, p, t)));
                let sent = self.outlet.publish_whole(header, snap.len(), poses);
                if sent.is_ok() {
                    let joined = (0..snap.keyframes()).map(|k| snap.pose(k).is_some());
                    self.publication.sent_whole(joined);
                }
                sent
            }
            Carry::Changes { base, keyframes } => {
                // only a rebuild takes a keyframe out of the map, and it goes out whole
                let (keyframes, entries): (Vec<usize>, Vec<_>) = (keyframes.into_iter())
                    .filter_map(|k| Some((k, snap.entry(k)?)))
                    .unzip();
                let header = SnapshotHeader { base, ..header };
                let sent = (self.outlet).publish_changes(header, entries.len(), entries.into_iter().map(out));
                if sent.is_ok() {
                    self.publication.sent_changes(&keyframes);
                }
                sent
            }
        };
        self.last_header = SnapshotHeader {
            poses: self.publication.map_size() as u64,
            whole: 1,
            ..header
        };
        if let Err(e) = result {
            self.publication.whole_next();
            tracing::error!(error = %e, "Cannot publish a snapshot.");
        }
        if let Some(t) = self.batch_start.take() {
            self.latency.push(t.elapsed());
        }
        if std::mem::take(&mut self.answer_due) {
            self.last_answer = Instant::now();
        }
        tracing::debug!(
            version = report.version,
            moved = report.moved,
            chi2 = report.chi2,
            solve_us = solved.as_micros() as u64,
            publish_us = (t0.elapsed() - solved).as_micros() as u64,
            "Snapshot published."
        );
        self.switches_due |= report.resolved || report.decided > 0;
        // every loop closure's switch is a list the size of the map: at most
        // every SWITCHES_EVERY, and with the settled map
        let recent = self.last_switches.is_some_and(|t| t.elapsed() < SWITCHES_EVERY);
        if self.switches_due && !(recent && header.settling != 0) {
            self.publish_switches(report.version);
        }
        self.dirty = false;
        self.last_publish = Some(Instant::now());
    }

    /// The newest keyframe's marginal covariance as the header carries it
    /// (its upper triangle), when configured and readable.
    fn newest_covariance(&mut self) -> Option<(KeyframeId, [f64; INFORMATION_UPPER])> {
        if !self.config.snapshot.covariance {
            return None;
        }
        let id = self.engine.snapshot().newest()?;
        let sigma = match self.engine.marginal(id) {
            Ok(s) => s,
            Err(e) => {
                tracing::debug!(error = %e, "No covariance in this snapshot.");
                return None;
            }
        };
        let mut upper = [0.0; INFORMATION_UPPER];
        for (slot, v) in upper.iter_mut().zip(upper_triangle(&sigma)) {
            *slot = v;
        }
        Some((id, upper))
    }

    fn publish_status(&mut self) {
        let (latency_p50_us, latency_p99_us) = self.latency.percentiles();
        let m = DaemonStatus {
            protocol: PROTOCOL_VERSION,
            journal_failing: u32::from(self.durability.failing()),
            instance: self.instance,
            started_at_ns: self.started_at_ns,
            checkpoint_at_ns: self.durability.checkpoint_at_ns(),
            journal_bytes: self.durability.journal_bytes(),
            frontends: self.durability.active(Duration::from_secs(60)) as u64,
            latency_p50_us,
            latency_p99_us,
            snapshot: self.last_header,
            acks: self.durability.acknowledged(),
        };
        if let Err(e) = self.outlet.publish_status(m) {
            tracing::error!(error = %e, "Cannot publish the acknowledgements.");
        }
    }

    /// Publishes the filter's switch of every loop closure.
    fn publish_switches(&mut self, version: u64) {
        self.switches_due = false;
        self.last_switches = Some(Instant::now());
        let (header, switches) = wire::switches_out(&self.engine, version);
        let count = switches.len();
        if let Err(e) = self.outlet.publish_switches(header, count, switches.into_iter()) {
            tracing::error!(error = %e, "Cannot publish the switches.");
        }
    }
}

/// A number for this daemon start, nonzero and different from the last
/// start's: the clock's nanoseconds mixed with the process id.
fn new_instance() -> u64 {
    (now_ns() ^ u64::from(std::process::id()).rotate_left(32)).max(1)
}
