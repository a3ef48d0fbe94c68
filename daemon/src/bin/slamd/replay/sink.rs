//! Where a replay sends its keyframes: [`EmbeddedSink`] (the engine in
//! this process) or [`DaemonSink`] (a running daemon over shared memory).

use super::Step;
use faer::c64;
use slamd::config::Config;
use slamd::engine::{Engine, EnginePose, EngineStats};
use slamd::geometry::Pose2;
use slamd::graph::{KeyframeId, Pose3, RigidMotion};
use slamd::ipc::{Frontend, Snapshots};
use slamd::outliers::REJECTED_BELOW;
use slamd_protocol::SnapshotHeader;
use std::collections::{HashMap, VecDeque};
use std::time::{Duration, Instant};

/// Where a replay sends its keyframes.
pub trait Sink<P: slamd::graph::RigidMotion = Pose2> {
    /// Sends keyframe `k` with its edges and fixes; returns latencies (µs)
    /// of the keyframes whose snapshot arrived meanwhile, with their index.
    fn keyframe(&mut self, k: usize, step: &Step<P>) -> anyhow::Result<Vec<(usize, f64)>>;
    /// Waits for every outstanding snapshot; returns their latencies.
    fn drain(&mut self) -> anyhow::Result<Vec<(usize, f64)>>;
    /// The current estimate, by keyframe id.
    fn poses(&mut self) -> anyhow::Result<HashMap<KeyframeId, P>>;
    /// The final estimate after the re-solve that ends the stream, the
    /// number of re-solves, and when that estimate was ready.
    fn finish(&mut self) -> anyhow::Result<(HashMap<KeyframeId, P>, usize, Instant)>;
    /// The georeferenced (east, north) of each keyframe; empty until GPS
    /// has georeferenced the map.
    fn enu(&mut self) -> anyhow::Result<HashMap<KeyframeId, c64>>;
    /// The outlier filter's switch of each edge in the order sent, when
    /// the sink can tell.
    fn switches(&mut self) -> Option<Vec<f64>>;
    /// "embedded" or "daemon".
    fn mode(&self) -> &'static str;
    /// The engine's counters, when it runs in this process.
    fn engine_stats(&self) -> Option<EngineStats> {
        None
    }

    /// Keyframes from each loop closure's arrival to the outlier filter's
    /// decision on it (the engine's, embedded; else none).
    fn decision_lags(&self) -> Vec<u32> {
        Vec::new()
    }

    /// For each edge in the order sent, how many snapshots it weighed in
    /// with a switch of at least [`REJECTED_BELOW`] (embedded; else none).
    fn weighted_snapshots(&self) -> Option<Vec<u32>> {
        None
    }
}

/// The engine in this process, fed as fast as it takes keyframes or, with
/// a pace `(start, period)`, keyframe `k` at `start + k · period`; the
/// third field, when given, counts each edge's weighted snapshots (see
/// [`Sink::weighted_snapshots`]).
pub struct EmbeddedSink<P: EnginePose = Pose2>(
    pub Engine<P>,
    pub Option<(Instant, Duration)>,
    pub Option<Vec<u32>>,
);

/// What a replay does per dimension: a snapshot's poses read as the
/// dimension's poses.
pub trait ReplayPose: EnginePose {
    /// The georeferenced (east, north) of every keyframe, once georeferenced.
    fn enu(engine: &Engine<Self>) -> HashMap<KeyframeId, c64>;
}

impl ReplayPose for Pose2 {
    fn enu(engine: &Engine) -> HashMap<KeyframeId, c64> {
        let snap = engine.snapshot();
        snap.enu_poses().map(|(id, p)| (id, p.position())).collect()
    }
}

impl ReplayPose for Pose3 {
    fn enu(_: &Engine<Pose3>) -> HashMap<KeyframeId, c64> {
        HashMap::new()
    }
}

impl<P: EnginePose> EmbeddedSink<P> {
    /// Counts the snapshot just published for each edge that weighs in it.
    fn count_weighted(&mut self) {
        let Some(weighted) = &mut self.2 else {
            return;
        };
        weighted.resize(self.0.graph().edges().len(), 0);
        for (e, n) in weighted.iter_mut().enumerate() {
            *n += u32::from(self.0.switch(e).is_some_and(|s| s >= REJECTED_BELOW));
        }
    }
}

impl<P: ReplayPose> Sink<P> for EmbeddedSink<P> {
    fn keyframe(&mut self, k: usize, step: &Step<P>) -> anyhow::Result<Vec<(usize, f64)>> {
        if let Some((start, period)) = self.1 {
            let slot = start + period * k as u32;
            if let Some(left) = slot.checked_duration_since(Instant::now()) {
                std::thread::sleep(left);
            }
        }
        self.0.add_keyframe(step.id, None)?;
        let arrival = Instant::now();
        for e in &step.edges {
            self.0.add_edge(*e)?;
        }
        for f in &step.fixes {
            self.0.add_gps(*f)?;
        }
        self.0.update();
        let latency = arrival.elapsed().as_secs_f64() * 1e6;
        self.count_weighted();
        Ok(if step.edges.is_empty() {
            vec![]
        } else {
            vec![(k, latency)]
        })
    }

    fn drain(&mut self) -> anyhow::Result<Vec<(usize, f64)>> {
        Ok(vec![])
    }

    fn poses(&mut self) -> anyhow::Result<HashMap<KeyframeId, P>> {
        Ok(self.0.snapshot().poses().collect())
    }

    fn finish(&mut self) -> anyhow::Result<(HashMap<KeyframeId, P>, usize, Instant)> {
        self.0.resolve_now();
        // the settled map is published too
        self.count_weighted();
        Ok((self.poses()?, self.0.stats().resolves, Instant::now()))
    }

    fn enu(&mut self) -> anyhow::Result<HashMap<KeyframeId, c64>> {
        Ok(P::enu(&self.0))
    }

    fn switches(&mut self) -> Option<Vec<f64>> {
        Some(self.0.switches())
    }

    fn mode(&self) -> &'static str {
        "embedded"
    }

    fn engine_stats(&self) -> Option<EngineStats> {
        Some(self.0.stats())
    }

    fn decision_lags(&self) -> Vec<u32> {
        self.0.decision_lags().to_vec()
    }

    fn weighted_snapshots(&self) -> Option<Vec<u32>> {
        self.2.clone()
    }
}

/// A running daemon, over shared memory.
pub struct DaemonSink<P: RigidMotion> {
    frontend: Frontend<P>,
    snapshots: Snapshots,
    timeout: Duration,
    namespace: String,
    /// (keyframe index, last message number, publish time) awaiting a snapshot
    pending: VecDeque<(usize, u64, Instant)>,
    pace: Option<(Instant, Duration)>,
    /// The daemon's last sign of life: a snapshot or a status.
    heard: Instant,
    /// Whether its last status said its journal cannot be written.
    holding: bool,
    /// When the replay last said why it waits.
    said: Option<Instant>,
}

impl<P: RigidMotion> DaemonSink<P> {
    /// Connects to the daemon serving `namespace`, which must serve graphs
    /// of `P`'s dimension.
    pub fn connect(
        namespace: &str,
        config: &Config,
        timeout: Duration,
        rate: Option<f64>,
    ) -> anyhow::Result<Self> {
        let dimension = P::DIMENSION;
        let endpoint = slamd::ipc::Endpoint {
            namespace: namespace.to_string(),
            ..config.into()
        };
        let frontend = Frontend::connect(endpoint)?;
        let snapshots = Snapshots::open(namespace)?;
        if let Some(d) = served_dimension(&snapshots)? {
            if d != dimension {
                anyhow::bail!(
                    "the daemon serving `{namespace}` serves {d}-D graphs and this graph is {dimension}-D; \
                     start one with SLAMD_DIMENSION={dimension} (or `dimension = {dimension}` in its configuration)"
                );
            }
        }
        Ok(Self {
            frontend,
            snapshots,
            timeout,
            namespace: namespace.to_string(),
            pending: VecDeque::new(),
            pace: rate.map(|hz| (Instant::now(), Duration::from_secs_f64(1.0 / hz))),
            heard: Instant::now(),
            holding: false,
            said: None,
        })
    }

    /// Takes in the snapshots that arrived; returns the latencies they settle.
    /// Looks at the acknowledgements every [`RESTART_POLL`] meanwhile, so
    /// that a restarted daemon gets sent what it lacks.
    fn collect(&mut self, wait: Duration) -> anyhow::Result<Vec<(usize, f64)>> {
        let mut done = Vec::new();
        let deadline = Instant::now() + wait;
        let acked = loop {
            let left = deadline.saturating_duration_since(Instant::now());
            if let Some(s) = self.snapshots.wait(left.min(RESTART_POLL))? {
                self.heard = Instant::now();
                break Some(s.header().ack_of(self.frontend.id()));
            }
            if let Some(status) = self.snapshots.status()? {
                self.heard = Instant::now();
                self.holding = status.journal_failing != 0;
            }
            self.frontend.poll()?;
            if left <= RESTART_POLL {
                break None;
            }
        };
        if let Some(Some(acked)) = acked {
            let now = Instant::now();
            while self.pending.front().is_some_and(|p| p.1 <= acked) {
                let (k, _, t) = self.pending.pop_front().expect("non-empty");
                done.push((k, now.duration_since(t).as_secs_f64() * 1e6));
            }
        }
        Ok(done)
    }

    /// Says, at most every [`SAY_EVERY`], why the replay still waits for a
    /// daemon that is alive.
    fn say_why(&mut self) {
        let waited = self.pending.front().map_or(Duration::ZERO, |p| p.2.elapsed());
        if waited < self.timeout || self.said.is_some_and(|t| t.elapsed() < SAY_EVERY) {
            return;
        }
        self.said = Some(Instant::now());
        let why = if self.holding {
            "holds its acknowledgements: its journal cannot be written (a full disk?)"
        } else {
            "has not acknowledged yet"
        };
        eprintln!(
            "slamd: the daemon serving `{}` is alive but {why}; waiting ({:.0} s so far)",
            self.namespace,
            waited.as_secs_f64()
        );
    }

    fn no_answer(&self) -> anyhow::Error {
        anyhow::anyhow!(
            "the daemon serving `{}` did not answer within {:.1} s (is `slamd run` alive?)",
            self.namespace,
            self.timeout.as_secs_f64()
        )
    }
}

/// The dimension the daemon behind `snapshots` serves, from its status
/// (waited for briefly; `None` if none came).
fn served_dimension(snapshots: &Snapshots) -> anyhow::Result<Option<u32>> {
    let deadline = Instant::now() + Duration::from_millis(500);
    loop {
        if let Some(status) = snapshots.status()? {
            return Ok(Some(status.snapshot.dimension));
        }
        if Instant::now() > deadline {
            return Ok(None);
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

impl<P: ReplayPose> Sink<P> for DaemonSink<P> {
    fn keyframe(&mut self, k: usize, step: &Step<P>) -> anyhow::Result<Vec<(usize, f64)>> {
        let mut done = Vec::new();
        if let Some((start, period)) = self.pace {
            // paced: take in snapshots until this keyframe's slot
            let slot = start + period * k as u32;
            while let Some(left) = slot.checked_duration_since(Instant::now()) {
                done.extend(self.collect(left)?);
            }
        }
        let arrival = Instant::now();
        let mut last = self.frontend.add_keyframe(step.id, 0, None)?;
        for e in &step.edges {
            last = self.frontend.add_edge(e)?;
        }
        for f in &step.fixes {
            last = self.frontend.add_gps(f)?;
        }
        self.frontend.flush()?;
        if !step.edges.is_empty() {
            self.pending.push_back((k, last, arrival));
        }
        if self.pace.is_none() {
            done.extend(Sink::<P>::drain(self)?);
        }
        Ok(done)
    }

    /// Waits for the snapshots that acknowledge every keyframe sent, as long
    /// as the daemon shows it is alive: it gives up only after `timeout`
    /// with neither a snapshot nor a status from it.
    fn drain(&mut self) -> anyhow::Result<Vec<(usize, f64)>> {
        let mut done = Vec::new();
        self.heard = Instant::now();
        while !self.pending.is_empty() {
            let left = (self.heard + self.timeout).saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(self.no_answer());
            }
            done.extend(self.collect(left.min(SAY_EVERY))?);
            self.say_why();
        }
        Ok(done)
    }

    fn poses(&mut self) -> anyhow::Result<HashMap<KeyframeId, P>> {
        let s = self.snapshots.current().ok_or_else(|| self.no_answer())?;
        (s.poses().iter())
            .map(|p| {
                let pose = p
                    .pose::<P>()
                    .ok_or_else(|| anyhow::anyhow!("keyframe {}: {p:?} is not a pose", p.id));
                Ok((p.id, pose?))
            })
            .collect()
    }

    fn finish(&mut self) -> anyhow::Result<(HashMap<KeyframeId, P>, usize, Instant)> {
        Sink::<P>::drain(self)?;
        // the daemon re-solves once input pauses, and its filter's judge
        // decides the loop closures still pending: take snapshots until one
        // says the map is settled, for as long as the daemon shows it is
        // alive (while other frontends' input keeps it busy, for a while)
        let mut ready = Instant::now();
        let deadline = ready + self.timeout.max(Duration::from_secs(30));
        let input = |h: &SnapshotHeader| (h.keyframes, h.edges, h.fixes);
        let ours = self.snapshots.current().map(|s| input(s.header()));
        loop {
            if self.snapshots.wait(RESTART_POLL)?.is_some() {
                (ready, self.heard) = (Instant::now(), Instant::now());
            }
            let h = self.snapshots.current().map(|s| *s.header());
            if h.is_some_and(|h| h.settling == 0 && h.pending == 0) {
                break;
            }
            if Instant::now() > deadline && h.map(|h| input(&h)) != ours {
                break;
            }
            if self.snapshots.status()?.is_some() {
                self.heard = Instant::now();
            }
            if self.heard.elapsed() > self.timeout {
                return Err(self.no_answer());
            }
        }
        let resolves = (self.snapshots.current()).map_or(0, |s| s.header().resolves as usize);
        Ok((self.poses()?, resolves, ready))
    }

    fn enu(&mut self) -> anyhow::Result<HashMap<KeyframeId, c64>> {
        let s = self.snapshots.current().ok_or_else(|| self.no_answer())?;
        if s.header().georeferenced == 0 {
            return Ok(HashMap::new());
        }
        Ok(s.poses()
            .iter()
            .map(|p| (p.id, c64::new(p.east, p.north)))
            .collect())
    }

    fn switches(&mut self) -> Option<Vec<f64>> {
        None
    }

    fn mode(&self) -> &'static str {
        "daemon"
    }
}

/// How often a replay waiting for a snapshot checks whether the daemon
/// restarted.
const RESTART_POLL: Duration = Duration::from_millis(50);

/// A replay waiting for a daemon that is alive says why at most this often.
const SAY_EVERY: Duration = Duration::from_secs(5);
