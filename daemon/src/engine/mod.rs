//! The incremental engine: keyframes and edges in, a fresh estimate out
//! after every update.
//!
//! [`Engine`] keeps the Gauss–Newton normal equations over the keyframes
//! seen so far, linearised at the last polished map ([`gauss_newton`]): its
//! solution is the published estimate, one Gauss–Newton step from the
//! polish over every edge since. They live in a
//! [`DynamicLdlt`](crate::sparse::dynamic::DynamicLdlt) factor: a new
//! keyframe appends columns, a new edge or a reweight is a low-rank
//! update. Every `resolve_every_edges` edges, or when the factor
//! has filled in past `resolve_fill_ratio`, a re-solve (module `resolve`) runs
//! on another thread: Levenberg–Marquardt polish, a fresh ordering with the
//! newest keyframes last, a refactorisation; it then replays what arrived
//! meanwhile and swaps in without stopping ingestion.
//!
//! The parts: `State` (the model, its Gauss–Newton system and the
//! estimate, and how one [`Op`] applies), `Model` with its per-edge
//! `EdgeState`, `Chi2Cache`, `ArrivalGate` (the switch a new loop
//! closure enters with), `rebuild` (polish and fresh factor), `Schedule`
//! (when a re-solve or refresh is due), `Background` (the job on its
//! thread and the ops it has yet to catch up with), `swap` (how a fresh
//! state replaces the current one) and [`judge`] (the outlier filter's
//! decisions, made by a second engine off the snapshot path).
//!
//! ```
//! use slamd::engine::{EdgeInput, Engine, EngineConfig};
//! use slamd::geometry::Pose2;
//! use slamd::graph::{EdgeKind, Information};
//!
//! let mut engine = Engine::new(EngineConfig::default());
//! let step = Pose2::new(1.0, 0.0, std::f64::consts::FRAC_PI_2);
//! for id in 0..4u64 {
//!     engine.add_keyframe(id, None).unwrap();
//!     if id > 0 {
//!         let edge = EdgeInput::new(id - 1, id, step, Information::identity(), EdgeKind::Odometry);
//!         engine.add_edge(edge).unwrap();
//!     }
//!     engine.update();
//! }
//! // close the square
//! engine.add_edge(EdgeInput::new(3, 0, step, Information::identity(), EdgeKind::LoopClosure)).unwrap();
//! let report = engine.update();
//! let snap = engine.snapshot();
//! assert_eq!(snap.version, report.version);
//! assert_eq!(snap.len(), 4);
//! assert!(snap.chi2 < 1e-12);
//! let p2 = snap.pose(2).unwrap();
//! assert!((p2.x - 1.0).abs() < 1e-9 && (p2.y - 1.0).abs() < 1e-9);
//! ```

mod arrival;
mod background;
mod changed;
mod chi2;
mod config;
mod error;
pub mod gauss_newton;
pub mod judge;
mod marginals;
mod model;
mod op;
pub mod pose;
mod rebuild;
mod report;
mod resolve;
mod restore;
mod schedule;
mod snapshot;
mod state;
mod swap;

pub use changed::Changes;
pub use config::EngineConfig;
pub use error::EngineError;
pub use marginals::upper_triangle;
pub use op::Op;
pub use pose::EnginePose;
pub use report::{EngineStats, FactorWork, UpdateReport};
pub use slamd_types::{EdgeInput, FixInput};
pub use snapshot::Snapshot;

use crate::geometry::Pose2;
use crate::gps::{Geodetic, GpsFix, LocalFrame};
use crate::graph::{KeyframeId, KeyframeInput};
use background::Background;
use judge::Judge;
use op::Polish;
use schedule::Schedule;
use slamd_protocol::codec::Origin;
use state::State;
use std::collections::HashMap;

/// The incremental pose-graph solver, planar (`Engine`, the default) or
/// spatial (`Engine<Pose3>`, made by [`Engine::create`]).
pub struct Engine<P: EnginePose = Pose2> {
    /// Declared first, so dropped first: a running job is stopped before
    /// the state it would swap in for is freed.
    background: Background<P>,
    state: State<P>,
    config: EngineConfig,
    schedule: Schedule,
    version: u64,
    stats: EngineStats,
    /// The ENU frame: the configured origin, else the first fix's.
    frame: Option<LocalFrame>,
    /// This thread's work on the states it replaced, and the current
    /// state's work when it took over.
    work_done: FactorWork,
    work_base: FactorWork,
    /// Every fix taken, as received (what a saved map keeps).
    fixes: Vec<FixInput>,
    /// With the filter on: the loop closures' judge ([`judge`]).
    judge: Option<Judge<P>>,
    /// Loop closures not yet in the estimate with the judge's switch, with
    /// the keyframes received when each arrived (`None` once decided).
    undecided: HashMap<usize, Option<usize>>,
    /// Keyframes from each decided loop closure's arrival to its first
    /// decision, in the order decided.
    decision_lags: Vec<u32>,
    /// The judge's switches not yet in the estimate: the next background
    /// job takes them in (with re-solves on their thread).
    deferred: HashMap<usize, f64>,
}

impl Engine {
    /// An empty planar engine.
    pub fn new(config: EngineConfig) -> Self {
        Self::create(config)
    }
}

impl<P: EnginePose> Engine<P> {
    /// An empty engine for poses `P`. The outlier filter's default
    /// thresholds move to `P`'s degrees of freedom
    /// ([`OutlierConfig::for_dof`](crate::outliers::OutlierConfig::for_dof));
    /// a planar-only check in 3-D
    /// ([`OutlierConfig::planar_only`](crate::outliers::OutlierConfig::planar_only))
    /// is turned off with a warning. With the filter on, loop closures wait for its
    /// judge ([`judge`]).
    pub fn create(config: EngineConfig) -> Self {
        if !config.outliers.enabled {
            return Self::whole(config);
        }
        let judge = Self::whole(judge::judge_config(&config));
        Self::beside(Self::whole(judge::published_config(&config)), judge)
    }

    /// An engine that applies its own outlier filter, if on.
    fn whole(mut config: EngineConfig) -> Self {
        config.outliers = config.outliers.for_dof(P::DOF);
        if P::DIMENSION != 2 && config.outliers.planar_only() {
            tracing::warn!(
                "The cycle test and PCM (outliers.cycles, outliers.pairwise) are planar; turned off for 3-D graphs."
            );
            config.outliers.cycles = false;
            config.outliers.pairwise = false;
        }
        Self {
            state: State::new(&config),
            background: Background::default(),
            schedule: Schedule::default(),
            version: 0,
            stats: EngineStats::default(),
            frame: config.gps.origin.map(LocalFrame::new),
            work_done: FactorWork::default(),
            work_base: FactorWork::default(),
            fixes: Vec::new(),
            judge: None,
            undecided: HashMap::new(),
            decision_lags: Vec::new(),
            deferred: HashMap::new(),
            config,
        }
    }

    /// The configuration this engine runs with. Beside a judge it is the
    /// publishing engine's, with `outliers.enabled` off: the filter runs in
    /// the judge.
    pub fn config(&self) -> &EngineConfig {
        &self.config
    }

    /// Adds a keyframe; the first one is the gauge. `guess` is a pose in
    /// the map frame; without one, the keyframe's first edge to the map
    /// places it. Returns its index.
    pub fn add_keyframe(&mut self, id: KeyframeId, guess: Option<P>) -> Result<usize, EngineError> {
        self.add_keyframe_at(id, guess, 0)
    }

    /// [`Self::add_keyframe`] with the time the frontend took it (ns on its
    /// clock; 0: none), which snapshots and saved maps carry.
    pub fn add_keyframe_at(
        &mut self,
        id: KeyframeId,
        guess: Option<P>,
        timestamp_ns: u64,
    ) -> Result<usize, EngineError> {
        self.submit(Op::Keyframe(KeyframeInput::new(id, guess, timestamp_ns)))?;
        Ok(self.state.model.graph.len() - 1)
    }

    /// The ENU frame's origin, once known.
    pub fn gps_origin(&self) -> Option<Geodetic> {
        self.frame.map(|f| f.origin)
    }

    /// Adds an edge between two known keyframes and returns its index. It
    /// joins the estimate when it links to the gauge's part of the graph.
    pub fn add_edge(&mut self, edge: EdgeInput<P>) -> Result<usize, EngineError> {
        self.add_edge_from(edge, Origin::LOCAL)
    }

    /// [`Self::add_edge`] for a message `origin` sent, which the edge keeps
    /// ([`Self::edge_origin`], saved maps).
    pub fn add_edge_from(&mut self, edge: EdgeInput<P>, origin: Origin) -> Result<usize, EngineError> {
        let held = self.judge.is_some() && edge.kind.switchable();
        self.submit(Op::Edge(edge, origin))?;
        self.schedule.edge_added();
        let e = self.state.model.graph.edges().len() - 1;
        if held {
            self.undecided.insert(e, Some(self.keyframe_count()));
        }
        Ok(e)
    }

    /// Sets an edge's weight (its information is scaled by `scale`; 0
    /// removes it). Odometry cannot be set to 0.
    pub fn set_edge_weight(&mut self, edge: usize, scale: f64) -> Result<(), EngineError> {
        self.state.check_weight(edge, scale)?;
        self.submit(Op::Weight { edge, scale })
    }

    /// Removes an edge's terms (weight 0); a later weight restores it.
    pub fn remove_edge(&mut self, edge: usize) -> Result<(), EngineError> {
        self.set_edge_weight(edge, 0.0)
    }

    fn submit(&mut self, op: Op<P>) -> Result<(), EngineError> {
        match self.state.apply(&op) {
            Ok(()) => {}
            Err(EngineError::Numeric(e)) => {
                // the change is in the model; the factor is not: rebuild it
                tracing::warn!(error = %e, "Downdate failed; refactorising.");
                self.stats.recoveries += 1;
                self.rebuild_inline(Polish::None);
            }
            Err(e) => return Err(e),
        }
        if let Some(judge) = &mut self.judge {
            if !matches!(op, Op::Switch { .. }) {
                judge.forward(&op);
            }
        }
        self.background.record(op);
        Ok(())
    }

    /// Solves for the new estimate, swaps in a finished re-solve, and
    /// starts one when due. Returns what changed.
    pub fn update(&mut self) -> UpdateReport {
        let decided = match &mut self.judge {
            Some(judge) => {
                let decisions = judge.update();
                let decided = decisions.len();
                self.take_decisions(decisions);
                decided
            }
            None => 0,
        };
        let mut resolved = self.poll_background();
        let mut moved = self.solve();
        if self.state.take_drifted() {
            // the loop closures it turned away are true: a re-solve with
            // the start that does not exclude them takes them back, inline
            // (in the background, the next nonlinearity check would
            // abandon it)
            self.stats.drift_resolves += 1;
            tracing::debug!(
                keyframes = self.keyframe_count(),
                "Agreeing loop closures rejected on arrival; re-solving inline."
            );
            moved = self.resolve_inline(Polish::FullInline);
            resolved = true;
        } else if self.beyond(self.config.nonlinear_ratio, 1.0) || self.relinearise(&mut moved) {
            self.stats.nonlinear_resolves += 1;
            tracing::debug!(
                keyframes = self.keyframe_count(),
                chi2 = self.state.chi2(),
                predicted = self.state.predicted_chi2(),
                "Linearisation failed; re-solving inline."
            );
            moved = self.resolve_inline(Polish::Inline);
            resolved = true;
        } else if (self.background.running() || !self.config.background)
            && self.schedule.filled(&self.config, &self.state)
        {
            // no refresh lands while a re-solve holds the background
            // thread (or with none), and the keyframes appended meanwhile
            // fill the factor in
            self.reorder_inline();
        }
        self.background.forward_estimates(&self.state);
        self.version += 1;
        if !self.background.running() {
            if !self.deferred.is_empty() {
                // the judge's decisions enter with a polish, off this thread
                self.start_job(Polish::Inline);
            } else if self.schedule.resolve_due(&self.config, &self.state) {
                self.start_job(Polish::Full);
            } else if self.schedule.refresh_due(&self.config) {
                self.start_job(Polish::None);
            }
        }
        UpdateReport {
            version: self.version,
            moved,
            chi2: self.state.chi2(),
            resolved,
            decided,
        }
    }

    /// Starts a re-solve now if none is running (call when idle).
    pub fn idle(&mut self) {
        if let Some(judge) = &mut self.judge {
            judge.idle();
        }
        if !self.background.running() && self.schedule.has_new_edges() {
            self.start_job(Polish::Full);
        }
    }

    /// Calls `wake` on the re-solve's thread whenever a background
    /// re-solve has finished, so the caller can [`Self::update`] at once
    /// to swap it in rather than at its next update.
    pub fn wake_on_resolved(&mut self, wake: impl Fn() + Send + Sync + 'static) {
        let wake: resolve::Waker = std::sync::Arc::new(wake);
        if let Some(judge) = &mut self.judge {
            judge.wake_with(wake.clone());
        }
        self.background.wake_with(wake);
    }

    /// True while a re-solve runs on its thread or decisions of the
    /// outlier filter wait to be taken in: an [`Self::update`] then has
    /// news to publish.
    pub fn resolving(&self) -> bool {
        self.background.running()
            || !self.deferred.is_empty()
            || self.judge.as_ref().is_some_and(|j| j.has_decisions())
    }

    /// True while work the input called for is under way: a re-solve, the
    /// outlier filter's judge, or decisions not yet taken in. Once it is
    /// false after the input paused ([`Self::idle`]), the next
    /// [`Self::update`] publishes the settled map.
    pub fn settling(&self) -> bool {
        self.resolving() || self.judge.as_ref().is_some_and(|j| j.busy())
    }

    /// Re-solves inline over everything (abandoning a running re-solve):
    /// the polished estimate of the whole graph. With the filter on, it
    /// first waits for the judge's closing decisions and polishes from the
    /// judge's map (and the two-stage solution), which depend on the input
    /// alone: the same stream ends at the same map on every run.
    pub fn resolve_now(&mut self) -> UpdateReport {
        let (decisions, judged) = self.judge.as_mut().map(|j| j.close()).unwrap_or_default();
        let decided = decisions.len();
        self.take_decisions(decisions);
        let moved = self.resolve_inline_from(Polish::Closing, &judged);
        self.version += 1;
        UpdateReport {
            version: self.version,
            moved,
            chi2: self.state.chi2(),
            resolved: true,
            decided,
        }
    }

    /// Which keyframes' estimates changed since the last call (indices as
    /// [`Snapshot::entry`] takes them): what a snapshot that carries only
    /// changes must carry.
    pub fn take_changes(&mut self) -> Changes {
        self.state.take_changes()
    }

    /// The current estimate.
    pub fn snapshot(&self) -> Snapshot<'_, P> {
        let m = &self.state.model;
        Snapshot {
            version: self.version,
            chi2: self.state.chi2(),
            resolves: self.stats.resolves,
            keyframes: m.graph.keyframes(),
            states: &m.keyframes,
            poses: self.state.estimate(),
            georef: self.state.georef(),
            origin: self.gps_origin(),
            pending: self.undecided.len(),
        }
    }

    /// The graph as the engine holds it (keyframes in arrival order).
    pub fn graph(&self) -> &crate::graph::PoseGraph<P> {
        &self.state.model.graph
    }

    /// Current weight of each edge (as set by [`Self::set_edge_weight`]).
    pub fn edge_weights(&self) -> Vec<f64> {
        self.state.model.edges.iter().map(|s| s.scale).collect()
    }

    /// The outlier filter's switch `s ∈ [0, 1]` of each edge, by index:
    /// 1 for odometry, below [`REJECTED_BELOW`](crate::outliers::REJECTED_BELOW)
    /// for a loop closure the filter holds wrong. The edge's information
    /// counts `s²` times.
    pub fn switches(&self) -> Vec<f64> {
        self.state.model.edges.iter().map(|s| s.switch).collect()
    }

    /// The switch of edge `e` (see [`Self::switches`]); `None` past the
    /// last edge.
    pub fn switch(&self, e: usize) -> Option<f64> {
        self.state.model.edges.get(e).map(|s| s.switch)
    }

    /// Who sent edge `e` ([`Origin::LOCAL`] for one added without an
    /// origin, or past the end).
    pub fn edge_origin(&self, e: usize) -> Origin {
        self.state.model.edges.get(e).map_or(Origin::LOCAL, |s| s.origin)
    }

    /// Work counters.
    pub fn stats(&self) -> EngineStats {
        let mut work = self.work_done;
        work += self.state.work() - self.work_base;
        let drift_resolves = match &self.judge {
            Some(judge) => judge.stats().drift_resolves,
            None => self.stats.drift_resolves,
        };
        EngineStats {
            factor_nnz: self.state.factor_nnz(),
            work,
            drift_resolves,
            pending: self.undecided.len(),
            ..self.stats
        }
    }

    /// The state's solve; a failed downdate on the way means a rebuild.
    fn solve(&mut self) -> usize {
        match self.state.solve(self.config.wildfire_threshold) {
            Ok(moved) => moved,
            Err(e) => {
                tracing::warn!(error = %e, "Update failed; refactorising.");
                self.stats.recoveries += 1;
                self.rebuild_inline(Polish::None);
                self.state.solve(self.config.wildfire_threshold).unwrap_or(0)
            }
        }
    }

    /// Whether the estimate's χ² is above `ratio` times its linear
    /// model's plus `slack` (never for a ratio of 0).
    fn beyond(&self, ratio: f64, slack: f64) -> bool {
        off_model(&self.state, ratio, slack)
    }

    /// Past `relinearise_ratio`: relinearises inline (a running
    /// background re-solve goes on and swaps in later), counting what the
    /// solve moved into `moved`. Returns whether the estimate is still
    /// past it, which calls for the inline re-solve.
    fn relinearise(&mut self, moved: &mut usize) -> bool {
        if !self.beyond(self.config.relinearise_ratio, RELINEARISE_SLACK) {
            return false;
        }
        self.stats.relinearisations += 1;
        tracing::debug!(
            keyframes = self.keyframe_count(),
            chi2 = self.state.chi2(),
            predicted = self.state.predicted_chi2(),
            "Linear model off; relinearising inline."
        );
        self.rebuild_inline(Polish::None);
        *moved = (*moved).max(self.solve());
        self.beyond(self.config.relinearise_ratio, RELINEARISE_SLACK)
    }
}

/// GPS.
impl<P: EnginePose> Engine<P> {
    /// Adds a GPS fix to a known keyframe (the daemon holds fixes that
    /// overtake their keyframe, as it holds edges). The first fix sets the
    /// ENU origin unless the configuration names one. Fixes enter the
    /// estimate as absolute position priors once a re-solve has
    /// georeferenced the map; one starts as soon as two fixes are in, and
    /// again whenever their number has doubled. In 3-D a fix with a
    /// height variance also holds the keyframe's height.
    pub fn add_gps(&mut self, fix: FixInput) -> Result<(), EngineError> {
        let position = GpsFix::checked_position(&fix).map_err(EngineError::Gps)?;
        let k =
            (self.state.model.graph.index_of(fix.keyframe)).ok_or(EngineError::FixKeyframe(fix.keyframe))?;
        let frame = *self.frame.get_or_insert(LocalFrame::new(position));
        self.submit(Op::Gps(GpsFix::at(&fix, &position, k, &frame)))?;
        self.fixes.push(fix);
        Ok(())
    }
}

impl<P: EnginePose> Engine<P> {
    /// Keyframes received so far (for the debug log).
    fn keyframe_count(&self) -> usize {
        self.state.model.graph.keyframes().len()
    }
}

/// Whether `state`'s χ² is above `ratio` times its linear model's plus
/// `slack` (never for a ratio of 0).
fn off_model<P: EnginePose>(state: &State<P>, ratio: f64, slack: f64) -> bool {
    ratio > 0.0 && state.chi2() > ratio * state.predicted_chi2().max(0.0) + slack
}

/// The χ² a relinearisation must gain at least: below it, a gap between
/// the estimate and its linear model is rounding (a noise-free graph sits
/// at χ² ~1e-20). The nonlinearity check's re-solve, dearer, waits for a
/// gap of 1; a slack of 1 here would let early snapshots (χ² of a few
/// units) stray to 1.4–1.9× their prefix's optimum.
const RELINEARISE_SLACK: f64 = 0.01;
