//! The judge: the outlier filter's decisions, made off the snapshot path
//! and the same on every run.
//!
//! With the filter on, the publishing engine holds every new loop closure
//! *pending* (switch 0, out of its factor) until the judge has decided it.
//! The judge is a second [`Engine`] with the filter on and all its work
//! inline (`background = false`), fed the same ops in the same order and
//! updated at the same points, on a thread of its own. Its switches are
//! therefore a function of the input, its order and the configuration,
//! never of when a background re-solve landed or how loaded the machine
//! is. After each update it sends the switches that changed. The publishing
//! engine takes them in with its next background job (a polish that swaps
//! in when done), or inline ([`Op::Switch`]) at its next update when its
//! re-solves run inline. A judge that falls behind delays decisions, never
//! a snapshot: a robust re-solve it runs inline stalls only the judge.
//!
//! The contract between the two: edge `e` is the same edge on both sides
//! (an op the publishing engine refused is not forwarded), the publishing
//! engine never forwards a switch, and the judge sends no switch of a loop
//! closure it has not connected yet.
//!
//! The judge updates where the input says: before each new keyframe
//! (the previous one's edges are in by then), when the input pauses
//! ([`Engine::idle`]) and at the end of a stream ([`Engine::resolve_now`]).
//! At both it also takes the closing re-solve, once per pause, and at the
//! end of a stream the publishing engine waits for it. On its
//! thread a decision therefore comes one keyframe after its loop closure
//! at the earliest. Inline, the judge also updates at the start of each of
//! the publishing engine's updates, whose caller then decides the points:
//! a stream of keyframes each followed by its edges and an update is
//! judged alike either way.

use super::op::{Op, Polish};
use super::pose::EnginePose;
use super::resolve::Waker;
use super::{Engine, EngineConfig, EngineStats};
use crossbeam::channel::{self, Receiver, Sender};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Switches decided: `(edge, switch)`, later ones overriding earlier ones.
pub(super) type Decisions = Vec<(usize, f64)>;

/// What the publishing engine asks of the judge, in input order.
enum Ask<P: EnginePose> {
    /// An op the publishing engine applied.
    Op(Op<P>),
    /// Update if anything arrived since the last update.
    Update,
    /// The input paused: update and take the closing re-solve, if
    /// anything arrived since the last one.
    Idle,
    /// The end of a stream: update, take the closing re-solve, answer with
    /// the decisions and the judge's map.
    Close(Sender<(Decisions, Vec<P>)>),
}

/// The judge's engine and the switches it has sent.
pub(super) struct Bench<P: EnginePose> {
    engine: Engine<P>,
    /// Ops arrived since its last update.
    fresh: bool,
    /// Ops arrived since its last closing re-solve.
    unsettled: bool,
    /// The switch last sent for each edge (`NaN`: none yet).
    sent: Vec<f64>,
    /// The switchable edges, by index.
    switchable: Vec<usize>,
}

impl<P: EnginePose> Bench<P> {
    /// The judge over `engine`, beside a publishing engine that holds the
    /// switches `published` (`NaN` where pending): the first decisions
    /// send whatever differs, and every pending one.
    fn new(engine: Engine<P>, published: Vec<f64>) -> Self {
        let edges = engine.graph().edges();
        let switchable = (0..published.len())
            .filter(|&e| edges[e].kind.switchable())
            .collect();
        Self {
            engine,
            // a restored judge has yet to send what it made of the map
            fresh: !published.is_empty(),
            unsettled: !published.is_empty(),
            sent: published,
            switchable,
        }
    }

    /// Takes `ask`; returns the decisions of an update it made.
    fn ask(&mut self, ask: Ask<P>) -> Option<Decisions> {
        match ask {
            Ask::Op(op) => {
                let update = matches!(op, Op::Keyframe(_)) && self.fresh;
                let decided = update.then(|| self.update());
                if let Err(e) = self.engine.submit(op) {
                    // the publishing engine applied it: only numbers differ
                    tracing::error!(error = %e, "The judge could not apply an op.");
                }
                (self.fresh, self.unsettled) = (true, true);
                decided
            }
            Ask::Update => self.fresh.then(|| self.update()),
            Ask::Idle => self.unsettled.then(|| self.close()),
            Ask::Close(reply) => {
                let decided = if self.unsettled { self.close() } else { Vec::new() };
                let _ = reply.send((decided, self.engine.state.estimate().to_vec()));
                None
            }
        }
    }

    fn update(&mut self) -> Decisions {
        self.engine.update();
        self.fresh = false;
        self.decisions()
    }

    /// Updates and takes the closing re-solve.
    fn close(&mut self) -> Decisions {
        self.engine.update();
        self.engine.resolve_now();
        (self.fresh, self.unsettled) = (false, false);
        let decided = self.decisions();
        tracing::debug!(decided = decided.len(), "The judge closed.");
        decided
    }

    /// The switches of connected loop closures that changed since the last
    /// call (every one at the first).
    fn decisions(&mut self) -> Decisions {
        let edges = self.engine.graph().edges();
        let new = edges.iter().enumerate().skip(self.sent.len());
        self.switchable
            .extend(new.filter(|(_, edge)| edge.kind.switchable()).map(|(e, _)| e));
        self.sent.resize(edges.len(), f64::NAN);
        let states = &self.engine.state.model.edges;
        let mut changed = Vec::new();
        for &e in &self.switchable {
            let s = states[e].switch;
            // NaN equals nothing: a first decision is always sent
            if states[e].applied && s != self.sent[e] {
                self.sent[e] = s;
                changed.push((e, s));
            }
        }
        changed
    }
}

/// The outlier filter's judge: inline (the publishing engine's
/// `background` off) or on a thread of its own.
pub(super) enum Judge<P: EnginePose> {
    /// Judging within the publishing engine's calls, with the decisions
    /// not yet taken.
    Inline(Box<Bench<P>>, Decisions),
    /// On its thread.
    Thread(Worker<P>),
}

/// A judge on its thread.
pub(super) struct Worker<P: EnginePose> {
    asks: Sender<Ask<P>>,
    decisions: Receiver<(Decisions, EngineStats)>,
    /// The judge's counters with the last decisions taken.
    stats: EngineStats,
    wake: Arc<Mutex<Option<Waker>>>,
    stop: Arc<AtomicBool>,
    /// Asks sent, and asks the thread has answered (decisions sent).
    asked: u64,
    answered: Arc<AtomicU64>,
}

impl<P: EnginePose> Drop for Worker<P> {
    /// Stops the judge at its next ask (the thread is detached).
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

impl<P: EnginePose> Judge<P> {
    /// A judge over `engine` (built by [`judge_config`]; a restored one
    /// holds the saved map) beside a publishing engine holding the switches
    /// `published` (`NaN`: pending), on its own thread when `threaded`.
    pub fn new(engine: Engine<P>, published: Vec<f64>, threaded: bool) -> Self {
        debug_assert!(!engine.config.background && engine.config.outliers.enabled);
        let bench = Bench::new(engine, published);
        if !threaded {
            return Judge::Inline(Box::new(bench), Vec::new());
        }
        let stats = bench.engine.stats();
        Self::spawn(stats, false, move || Some(bench))
    }

    /// A judge on its own thread whose engine `build` makes there first
    /// (a restore: two whole factorisations of a large map would hold the
    /// publishing engine's first snapshot back). Asks queue meanwhile, and
    /// the judge counts as busy (the map is not settled). If `build` fails
    /// the judge is gone: loop closures stay pending and the error is
    /// logged.
    pub fn restoring(
        build: impl FnOnce() -> Result<Engine<P>, super::EngineError> + Send + 'static,
        published: Vec<f64>,
    ) -> Self {
        Self::spawn(EngineStats::default(), true, move || match build() {
            Ok(engine) => Some(Bench::new(engine, published)),
            Err(e) => {
                tracing::error!(error = %e, "The outlier filter's judge could not restore the map; loop closures stay pending.");
                None
            }
        })
    }

    /// The judge's thread over the bench `bench` makes, `stats` its
    /// counters until its first decisions; `building` counts making it as
    /// an ask answered once it is made.
    fn spawn(
        stats: EngineStats,
        building: bool,
        bench: impl FnOnce() -> Option<Bench<P>> + Send + 'static,
    ) -> Self {
        let (asks, asked) = channel::unbounded::<Ask<P>>();
        let (decided, decisions) = channel::unbounded();
        let stop = Arc::new(AtomicBool::new(false));
        let wake: Arc<Mutex<Option<Waker>>> = Arc::default();
        let (stopped, waker) = (Arc::clone(&stop), Arc::clone(&wake));
        let answered = Arc::new(AtomicU64::new(0));
        let answers = Arc::clone(&answered);
        std::thread::Builder::new()
            .name("slamd-judge".into())
            .spawn(move || {
                // the daemon's engine thread may hold a reserved core
                crate::affinity::run_in_background();
                let bench = bench();
                if building {
                    answers.fetch_add(1, Ordering::Release);
                }
                let Some(mut bench) = bench else {
                    return;
                };
                for ask in asked {
                    if stopped.load(Ordering::Relaxed) {
                        return;
                    }
                    let decisions = bench.ask(ask).filter(|d| !d.is_empty());
                    let sent = decisions.map(|d| decided.send((d, bench.engine.stats())));
                    answers.fetch_add(1, Ordering::Release);
                    match sent {
                        None => continue,
                        Some(Err(_)) => return,
                        Some(Ok(())) => {}
                    }
                    let wake = waker.lock().map(|w| w.clone()).ok().flatten();
                    if let Some(wake) = wake {
                        wake();
                    }
                }
            })
            .expect("spawn the judge's thread");
        Judge::Thread(Worker {
            asks,
            decisions,
            stats,
            wake,
            stop,
            asked: u64::from(building),
            answered,
        })
    }

    /// Forwards an op the publishing engine applied.
    pub fn forward(&mut self, op: &Op<P>) {
        debug_assert!(!matches!(op, Op::Switch { .. }));
        self.ask(Ask::Op(op.clone()));
    }

    /// The input paused.
    pub fn idle(&mut self) {
        self.ask(Ask::Idle);
    }

    fn ask(&mut self, ask: Ask<P>) {
        match self {
            Judge::Inline(bench, outbox) => outbox.extend(bench.ask(ask).unwrap_or_default()),
            Judge::Thread(w) => {
                w.asked += u64::from(w.asks.send(ask).is_ok());
            }
        }
    }

    /// The publishing engine updates: what the judge has decided since
    /// the last call (inline, after updating at this point).
    pub fn update(&mut self) -> Decisions {
        if let Judge::Inline(..) = self {
            self.ask(Ask::Update);
        }
        self.decisions()
    }

    /// What the judge has decided since the last call.
    fn decisions(&mut self) -> Decisions {
        match self {
            Judge::Inline(_, outbox) => std::mem::take(outbox),
            Judge::Thread(w) => {
                let mut all = Vec::new();
                for (d, stats) in w.decisions.try_iter() {
                    all.extend(d);
                    w.stats = stats;
                }
                all
            }
        }
    }

    /// Whether the judge's thread has asks it has not answered yet.
    pub fn busy(&self) -> bool {
        match self {
            Judge::Inline(..) => false,
            Judge::Thread(w) => w.answered.load(Ordering::Acquire) != w.asked,
        }
    }

    /// Whether decisions wait to be taken.
    pub fn has_decisions(&self) -> bool {
        match self {
            Judge::Inline(_, outbox) => !outbox.is_empty(),
            Judge::Thread(w) => !w.decisions.is_empty(),
        }
    }

    /// The judge's counters as of the decisions taken last.
    pub fn stats(&self) -> EngineStats {
        match self {
            Judge::Inline(bench, _) => bench.engine.stats(),
            Judge::Thread(w) => w.stats,
        }
    }

    /// The end of a stream: waits until the judge has caught up and taken
    /// its closing re-solve; returns every decision not yet taken and the
    /// judge's map (indexed like the keyframes; empty if the judge is gone).
    pub fn close(&mut self) -> (Decisions, Vec<P>) {
        let (reply, answer) = channel::bounded(1);
        self.ask(Ask::Close(reply));
        // on the thread, the decisions sent before the answer are queued
        // before it
        let (last, map) = answer.recv().unwrap_or_default();
        let mut all = self.decisions();
        all.extend(last);
        (all, map)
    }

    /// Calls `wake` on the judge's thread whenever it has sent decisions.
    pub fn wake_with(&mut self, wake: Waker) {
        if let Judge::Thread(w) = self {
            if let Ok(mut slot) = w.wake.lock() {
                *slot = Some(wake);
            }
        }
    }
}

/// The publishing engine's side of the judge.
impl<P: EnginePose> Engine<P> {
    /// `engine` publishing with `judge` deciding its loop closures.
    pub(super) fn beside(mut engine: Self, judge: Self) -> Self {
        let threaded = engine.config.background;
        let published = engine.judged_switches();
        engine.judge = Some(Judge::new(judge, published, threaded));
        engine
    }

    /// `engine` publishing with a judge that `build` restores on its own
    /// thread ([`Judge::restoring`]).
    pub(super) fn beside_restoring(
        mut engine: Self,
        build: impl FnOnce() -> Result<Self, super::EngineError> + Send + 'static,
    ) -> Self {
        let published = engine.judged_switches();
        engine.judge = Some(Judge::restoring(build, published));
        engine
    }

    /// Marks the model judged; returns the switches it publishes (`NaN`:
    /// pending), which the judge's first decisions are measured against.
    fn judged_switches(&mut self) -> Vec<f64> {
        self.state.model.judged = true;
        (self.state.model.edges.iter().enumerate())
            .map(|(e, s)| if self.is_pending(e) { f64::NAN } else { s.switch })
            .collect()
    }

    /// Takes the judge's decisions: each loop closure's switch as it
    /// decided. Many at once are set in the model and the factor is
    /// rebuilt.
    pub(super) fn take_decisions(&mut self, decisions: Decisions) {
        let keyframes = self.keyframe_count();
        for &(edge, _) in &decisions {
            // a re-solve is due for them as for new edges
            self.schedule.edge_added();
            if let Some(arrived) = self.undecided.get_mut(&edge).and_then(Option::take) {
                self.decision_lags.push((keyframes - arrived) as u32);
            }
        }
        if self.config.background {
            // taken in by the next background job, so that no snapshot waits
            // for the polish they may call for; one that changes nothing
            // (a pending loop closure held off) is in already
            for (edge, switch) in decisions {
                let now = self.state.model.edges.get(edge).map(|s| s.switch);
                if now == Some(switch) {
                    self.deferred.remove(&edge);
                    self.undecided.remove(&edge);
                } else {
                    self.deferred.insert(edge, switch);
                }
            }
            return;
        }
        for (edge, _) in &decisions {
            self.undecided.remove(edge);
        }
        if decisions.len() <= BULK_DECISIONS {
            for (edge, switch) in decisions {
                if let Err(e) = self.submit(Op::Switch { edge, switch }) {
                    tracing::error!(error = %e, edge, "Cannot take the judge's decision.");
                }
            }
            return;
        }
        // the edges' terms join the factor with the rebuild
        self.solve();
        if let Err(e) = self.state.set_switches_for_rebuild(&decisions) {
            tracing::error!(error = %e, "Cannot take a decision of the judge.");
        }
        for (edge, switch) in decisions {
            self.background.record(Op::Switch { edge, switch });
        }
        self.rebuild_inline(Polish::None);
    }

    /// Whether loop closure `edge` awaits the judge's decision (held out
    /// of the estimate meanwhile).
    pub fn is_pending(&self, edge: usize) -> bool {
        self.undecided.contains_key(&edge)
    }

    /// Keyframes from each decided loop closure's arrival to the judge's
    /// first decision on it, in the order decided (empty with the filter
    /// off).
    pub fn decision_lags(&self) -> &[u32] {
        &self.decision_lags
    }
}

/// More of the judge's decisions than this at once are taken by
/// refactorising rather than by one update each.
const BULK_DECISIONS: usize = 32;

/// The configuration of the judge of an engine configured `config`: the
/// same (the filter on), with everything inline.
pub(super) fn judge_config(config: &EngineConfig) -> EngineConfig {
    EngineConfig {
        background: false,
        ..config.clone()
    }
}

/// The configuration of the publishing engine beside a judge: the same,
/// with the filter's work left to the judge.
pub(super) fn published_config(config: &EngineConfig) -> EngineConfig {
    let mut published = config.clone();
    published.outliers.enabled = false;
    published
}
