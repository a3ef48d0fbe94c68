//! The incremental engine: keyframes and edges in, a fresh estimate out
//! after every update.
//!
//! [`Engine`] keeps two incremental systems over the keyframes seen so far:
//!
//! - the Gauss–Newton normal equations linearised at the last polished map
//!   ([`gauss_newton`]): its solution is the published estimate, one
//!   Gauss–Newton step from the polish over every edge since;
//! - optionally, the two-stage linear system ([`linear_stages`]), exact at
//!   every step.
//!
//! Both live in [`DynamicLdlt`](crate::sparse::dynamic::DynamicLdlt)
//! factors: a new keyframe appends columns, a new edge or a reweight is a
//! low-rank update. Every `resolve_every_edges` edges, or when the factor
//! has filled in past `resolve_fill_ratio`, a re-solve (module `resolve`) runs
//! on another thread: Levenberg–Marquardt polish, a fresh ordering with the
//! newest keyframes last, a refactorisation; it then replays what arrived
//! meanwhile and swaps in without stopping ingestion.
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

mod config;
mod deferred;
pub mod gauss_newton;
pub mod linear_stages;
mod model;
mod op;
mod resolve;
mod snapshot;
mod state;

pub use config::EngineConfig;
pub use snapshot::Snapshot;
pub use state::{FactorWork, Op, SnapshotSource};

use crate::geometry::Pose2;
use crate::gps::{covariance, Geodetic, GpsError, GpsFix, LocalFrame};
use crate::graph::{EdgeKind, GraphError, Information, KeyframeId};
use crate::sparse::dynamic::UpdateError;
use faer::c64;
use resolve::Job;
use state::{Polish, State};
use std::fmt;
use std::time::Instant;

/// An edge as a frontend gives it: keyframe ids, `T_ij`, Ω and its kind.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeInput {
    /// Keyframe `i`.
    pub from: KeyframeId,
    /// Keyframe `j`.
    pub to: KeyframeId,
    /// `T_ij`: `j` seen from `i`.
    pub measurement: Pose2,
    /// Ω over `(x, y, θ)`.
    pub information: Information,
    /// What produced it.
    pub kind: EdgeKind,
}

impl EdgeInput {
    /// Bundles the fields.
    pub fn new(
        from: KeyframeId,
        to: KeyframeId,
        measurement: Pose2,
        information: Information,
        kind: EdgeKind,
    ) -> Self {
        Self {
            from,
            to,
            measurement,
            information,
            kind,
        }
    }

    /// Edge `e` of `graph` as a frontend sends it (keyframe ids, not
    /// indices).
    pub fn from_graph(graph: &crate::graph::PoseGraph, e: usize) -> Self {
        let edge = graph.edges()[e];
        Self::new(
            graph.id_of(edge.from),
            graph.id_of(edge.to),
            edge.measurement,
            edge.information,
            edge.kind,
        )
    }
}

/// Why the engine refused a change. A refused change is not stored.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum EngineError {
    /// The graph refused it (duplicate or unknown id, self-edge, NaN).
    Graph(GraphError),
    /// No edge has this index.
    UnknownEdge(usize),
    /// A weight that is negative or not finite.
    InvalidWeight(f64),
    /// Odometry edges are never switched off.
    OdometrySwitch(usize),
    /// A downdate lost positive definiteness; the engine refactorised.
    Numeric(UpdateError),
    /// A GPS fix out of range, non-finite, or with a bad covariance.
    Gps(GpsError),
    /// A GPS fix for a keyframe that has not arrived.
    FixKeyframe(KeyframeId),
}

impl fmt::Display for EngineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EngineError::Graph(e) => e.fmt(f),
            EngineError::UnknownEdge(e) => write!(f, "no edge with index {e}"),
            EngineError::InvalidWeight(w) => write!(f, "edge weight {w} is not a finite number ≥ 0"),
            EngineError::OdometrySwitch(e) => write!(f, "edge {e} is odometry and cannot be switched off"),
            EngineError::Numeric(e) => write!(f, "{e}; refactorised"),
            EngineError::Gps(e) => e.fmt(f),
            EngineError::FixKeyframe(id) => write!(f, "GPS fix for unknown keyframe {id}"),
        }
    }
}

impl std::error::Error for EngineError {}

impl From<GraphError> for EngineError {
    fn from(e: GraphError) -> Self {
        EngineError::Graph(e)
    }
}

/// A GPS fix as a frontend gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixInput {
    /// The keyframe it was taken at.
    pub keyframe: KeyframeId,
    /// Where (WGS84).
    pub position: Geodetic,
    /// Covariance of (east, north) in m², row-major.
    pub covariance: [f64; 4],
}

/// What an [`Engine::update`] did.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpdateReport {
    /// The snapshot version it produced.
    pub version: u64,
    /// Keyframes whose estimate moved.
    pub moved: usize,
    /// χ² of the new estimate.
    pub chi2: f64,
    /// True when a finished re-solve was swapped in.
    pub resolved: bool,
}

/// Counters of the engine's work.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct EngineStats {
    /// Re-solves swapped in.
    pub resolves: usize,
    /// Refreshes swapped in.
    pub refreshes: usize,
    /// Seconds spent in re-solves (on their thread).
    pub resolve_seconds: f64,
    /// Refactorisations forced by a failed downdate.
    pub recoveries: usize,
    /// Inline relinearisations (`relinearise_ratio`).
    pub relinearisations: usize,
    /// Inline re-solves forced by the nonlinearity check.
    pub nonlinear_resolves: usize,
    /// Inline re-solves forced by a run of agreeing loop closures switched
    /// off on arrival ([`DriftRun`](crate::outliers::DriftRun)).
    pub drift_resolves: usize,
    /// Entries of the Gauss–Newton factor now.
    pub factor_nnz: usize,
    /// Loop closures waiting out of the factor now.
    pub deferred: usize,
    /// Their χ² at the estimate (at most `defer_budget` times the
    /// estimate's).
    pub deferred_chi2: f64,
    /// What the updates and solves on this thread have swept of the
    /// Gauss–Newton factors so far (a re-solve's catch-up on its own
    /// thread not counted).
    pub work: FactorWork,
}

/// The incremental pose-graph solver.
pub struct Engine {
    state: State,
    config: EngineConfig,
    job: Option<Job>,
    log: Vec<(u64, Op)>,
    seq: u64,
    edges_since_resolve: usize,
    edges_since_refresh: usize,
    /// Keyframes below this index are known to the running re-solve's
    /// hints (handed over, or forwarded after an update).
    hinted: usize,
    nnz_after_resolve: usize,
    version: u64,
    stats: EngineStats,
    /// The ENU frame: the configured origin, else the first fix's.
    frame: Option<LocalFrame>,
    /// Fixes in the estimate at the last re-solve.
    fixes_at_resolve: usize,
    /// This thread's work on the states it replaced, and the current
    /// state's work when it took over.
    work_done: FactorWork,
    work_base: FactorWork,
}

impl Engine {
    /// An empty engine.
    pub fn new(config: EngineConfig) -> Self {
        Self {
            state: State::new(&config),
            job: None,
            log: Vec::new(),
            seq: 0,
            edges_since_resolve: 0,
            edges_since_refresh: 0,
            hinted: 0,
            nnz_after_resolve: 0,
            version: 0,
            stats: EngineStats::default(),
            frame: config.gps.origin.map(LocalFrame::new),
            fixes_at_resolve: 0,
            work_done: FactorWork::default(),
            work_base: FactorWork::default(),
            config,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &EngineConfig {
        &self.config
    }

    /// Adds a keyframe; the first one is the gauge. `guess` is a pose in
    /// the map frame; without one, the keyframe's first edge to the map
    /// places it. Returns its index.
    pub fn add_keyframe(&mut self, id: KeyframeId, guess: Option<Pose2>) -> Result<usize, EngineError> {
        self.submit(Op::Keyframe { id, guess })?;
        Ok(self.state.model.graph.len() - 1)
    }

    /// Adds a GPS fix to a known keyframe (the daemon holds fixes that
    /// overtake their keyframe, as it holds edges). The first fix sets the
    /// ENU origin unless the configuration names one. Fixes enter the
    /// estimate as absolute position priors once a re-solve has
    /// georeferenced the map; one starts as soon as two fixes are in, and
    /// again whenever their number has doubled.
    pub fn add_gps(&mut self, fix: FixInput) -> Result<(), EngineError> {
        let p = fix.position;
        let position = Geodetic::new(p.lat, p.lon, p.height).map_err(EngineError::Gps)?;
        let cov = covariance(fix.covariance).map_err(EngineError::Gps)?;
        let k =
            (self.state.model.graph.index_of(fix.keyframe)).ok_or(EngineError::FixKeyframe(fix.keyframe))?;
        let frame = *self.frame.get_or_insert(LocalFrame::new(position));
        let (e, n, _) = frame.to_enu(&position);
        self.submit(Op::Gps(GpsFix {
            keyframe: k,
            enu: c64::new(e, n),
            covariance: cov,
        }))
    }

    /// The ENU frame's origin, once known.
    pub fn gps_origin(&self) -> Option<Geodetic> {
        self.frame.map(|f| f.origin)
    }

    /// Adds an edge between two known keyframes and returns its index. It
    /// joins the estimate when it links to the gauge's part of the graph.
    pub fn add_edge(&mut self, edge: EdgeInput) -> Result<usize, EngineError> {
        self.submit(Op::Edge(edge))?;
        self.edges_since_resolve += 1;
        self.edges_since_refresh += 1;
        Ok(self.state.model.graph.edges().len() - 1)
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

    fn submit(&mut self, op: Op) -> Result<(), EngineError> {
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
        if let Some(job) = &self.job {
            job.forward(self.seq, op.clone());
            self.log.push((self.seq, op));
        }
        self.seq += 1;
        Ok(())
    }

    /// Solves for the new estimate, swaps in a finished re-solve, and
    /// starts one when due. Returns what changed.
    pub fn update(&mut self) -> UpdateReport {
        let mut resolved = self.poll_job();
        let mut moved = self.solve();
        if self.state.take_drifted() {
            // the loop closures it turned away are true: a re-solve with
            // the start that does not exclude them takes them back. Inline:
            // started in the background, it was abandoned by the next
            // nonlinearity check, or waited for there up to 104 s (W10000),
            // and City10000's run went on
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
        }
        self.forward_estimates();
        self.version += 1;
        if self.resolve_due() {
            self.start_job(Polish::Full);
        } else if self.refresh_due() {
            self.start_job(Polish::None);
        }
        UpdateReport {
            version: self.version,
            moved,
            chi2: self.state.chi2(),
            resolved,
        }
    }

    /// Starts a re-solve now if none is running (call when idle).
    pub fn idle(&mut self) {
        if self.job.is_none() && self.edges_since_resolve > 0 {
            self.start_job(Polish::Full);
        }
    }

    /// True while a re-solve runs on its thread.
    pub fn resolving(&self) -> bool {
        self.job.is_some()
    }

    /// Re-solves inline over everything (abandoning a running re-solve):
    /// the polished estimate of the whole graph.
    pub fn resolve_now(&mut self) -> UpdateReport {
        let moved = self.resolve_inline(Polish::Closing);
        self.version += 1;
        UpdateReport {
            version: self.version,
            moved,
            chi2: self.state.chi2(),
            resolved: true,
        }
    }

    /// The current estimate.
    pub fn snapshot(&self) -> Snapshot<'_> {
        let m = &self.state.model;
        Snapshot {
            version: self.version,
            chi2: self.state.chi2(),
            resolves: self.stats.resolves,
            keyframes: m.graph.keyframes(),
            joined: &m.joined,
            poses: self.state.estimate(),
            georef: self.state.georef(),
            origin: self.gps_origin(),
        }
    }

    /// The exact two-stage linear solution of everything so far (needs
    /// `linear_stages`), indexed like the keyframes.
    pub fn linear_solution(&mut self) -> Option<Vec<Pose2>> {
        self.state.linear_solution()
    }

    /// The graph as the engine holds it (keyframes in arrival order).
    pub fn graph(&self) -> &crate::graph::PoseGraph {
        &self.state.model.graph
    }

    /// Current weight of each edge (as set by [`Self::set_edge_weight`]).
    pub fn edge_weights(&self) -> &[f64] {
        &self.state.model.scale
    }

    /// The outlier filter's switch `s ∈ [0, 1]` of each edge, by index:
    /// 1 for odometry, below [`REJECTED_BELOW`](crate::outliers::REJECTED_BELOW)
    /// for a loop closure the filter holds wrong. The edge's information
    /// counts `s²` times.
    pub fn switches(&self) -> &[f64] {
        &self.state.model.switch
    }

    /// Work counters.
    pub fn stats(&self) -> EngineStats {
        let (deferred, deferred_chi2) = self.state.deferred();
        let mut work = self.work_done;
        work += self.state.work() - self.work_base;
        EngineStats {
            factor_nnz: self.state.factor_nnz(),
            deferred,
            deferred_chi2,
            work,
            ..self.stats
        }
    }

    /// A full re-solve here. A running background re-solve is abandoned:
    /// this one covers everything it does, and more. Swapping the older
    /// one in afterwards would leave the newest edges unpolished with no
    /// re-solve due (the demo ended at χ² 6,900-8,700 instead of 2,374);
    /// waiting for it cost a keyframe 15-22 s on City10000 with 1000
    /// outliers, and the closing re-solve, when it waited, 0.4 s of
    /// City10000's 0.76. A cheaper relinearisation for the
    /// nonlinearity check, a few robust iterations with the switches held,
    /// left 8-20 true loop closures of the test world off in 3-15% of runs.
    fn resolve_inline(&mut self, polish: Polish) -> usize {
        if let Some(job) = self.job.take() {
            job.abandon();
            self.log.clear();
        }
        // what the swapped-in state replayed is pending, and a rebuild
        // polishes only connected edges: connect them first (else the
        // keyframes that arrived during the last background re-solve, 200
        // of Manhattan's, missed the polish that ends a stream)
        self.solve();
        self.rebuild_inline(polish);
        self.stats.resolves += 1;
        self.solve()
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
        match self.state.predicted_chi2() {
            Some(predicted) => ratio > 0.0 && self.state.factor_chi2() > ratio * predicted.max(0.0) + slack,
            None => false,
        }
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

    fn resolve_due(&self) -> bool {
        if self.job.is_some() {
            return false;
        }
        let c = &self.config;
        let by_count = c.resolve_every_edges > 0 && self.edges_since_resolve >= c.resolve_every_edges;
        let by_fill = c.resolve_fill_ratio > 0.0
            && self.nnz_after_resolve > 0
            && self.state.factor_nnz() as f64 > c.resolve_fill_ratio * self.nnz_after_resolve as f64;
        // georeference as soon as two fixes are in, and again whenever
        // their number has doubled; the count of fixes on joined keyframes
        // is a scan, so it waits until all fixes together could pass
        let due = |fixes: usize| fixes >= 2 && fixes >= 2 * self.fixes_at_resolve.max(1);
        let by_gps = due(self.state.model.fixes.len()) && due(self.state.usable_fixes());
        by_count || by_fill || by_gps
    }

    /// Whether a refresh is due: the background thread is free and enough
    /// edges arrived since the last one.
    fn refresh_due(&self) -> bool {
        let every = self.config.refresh_every_edges;
        self.config.background && self.job.is_none() && every > 0 && self.edges_since_refresh >= every
    }

    /// Forwards the estimates of the keyframes added since the last call
    /// (those that joined) to the running re-solve, as catch-up hints.
    fn forward_estimates(&mut self) {
        let Some(job) = &self.job else {
            return;
        };
        let (model, estimate) = (&self.state.model, self.state.estimate());
        let n = model.graph.len();
        for k in (self.hinted..n).filter(|&k| model.joined[k]) {
            job.hint(k, estimate[k]);
        }
        self.hinted = n;
    }

    /// Starts a re-solve ([`Polish::Full`]) or a refresh ([`Polish::None`]).
    fn start_job(&mut self, polish: Polish) {
        self.edges_since_refresh = 0;
        if polish != Polish::None {
            self.edges_since_resolve = 0;
            self.fixes_at_resolve = self.state.usable_fixes();
        }
        let model = self.state.model().clone();
        let estimate = self.state.estimate().to_vec();
        if self.config.background {
            self.log.clear();
            self.hinted = self.state.model.graph.len();
            self.job = Some(Job::spawn(model, estimate, self.config.clone(), polish));
        } else {
            let (_tx, rx) = crossbeam::channel::unbounded();
            let never = std::sync::atomic::AtomicBool::new(false);
            if let Some(outcome) = resolve::run(model, &estimate, &self.config, polish, &rx, &never) {
                self.swap_in(outcome);
            }
        }
    }

    fn poll_job(&mut self) -> bool {
        let Some(job) = &mut self.job else {
            return false;
        };
        match job.try_finish() {
            Some(outcome) => {
                self.job = None;
                self.swap_in(outcome)
            }
            None => false,
        }
    }

    /// Replays what the re-solve missed and makes its state current.
    fn swap_in(&mut self, outcome: resolve::Outcome) -> bool {
        let log = std::mem::take(&mut self.log);
        let Ok(mut state) = outcome.state else {
            tracing::warn!("Re-solve failed; keeping the current factor.");
            return false;
        };
        // the ops it missed join where this state's solves put them
        let base = state.work();
        state.set_hints(self.state.estimate(), &self.state.model.joined);
        let (caught_up, mut replayed) = (Instant::now(), 0);
        for (seq, op) in log {
            if outcome.last_seq.is_none_or(|last| seq > last) {
                replayed += 1;
                if let Err(e) = state.replay(&op, self.config.wildfire_threshold) {
                    tracing::warn!(error = %e, seq, ?op, "Re-solve cannot replay an op; discarded.");
                    return false;
                }
            }
        }
        if let Err(e) = state.join_pending() {
            tracing::warn!(error = %e, "Re-solve cannot connect the replayed edges; discarded.");
            return false;
        }
        let catch_up_seconds = caught_up.elapsed().as_secs_f64();
        state.clear_hints();
        self.replace_state(state, base);
        self.after_resolve();
        if outcome.polish == Polish::None {
            self.stats.refreshes += 1;
        } else {
            self.stats.resolves += 1;
            self.stats.resolve_seconds += outcome.seconds;
        }
        tracing::debug!(
            keyframes = self.keyframe_count(),
            seconds = outcome.seconds,
            replayed,
            catch_up_seconds,
            chi2 = self.state.chi2(),
            "Re-solve swapped in."
        );
        true
    }

    /// Rebuilds the state here, polished as `polish` says. Only a polish
    /// restarts the re-solve schedule and the fill baseline; a
    /// relinearisation or a recovery ([`Polish::None`]) leaves them.
    fn rebuild_inline(&mut self, polish: Polish) {
        let (model, start) = (self.state.model().clone(), self.state.estimate());
        match State::rebuild(model, start, polish, &self.config) {
            Ok(state) => {
                let base = state.work();
                self.replace_state(state, base);
                if polish != Polish::None {
                    self.after_resolve();
                    self.edges_since_resolve = 0;
                    self.fixes_at_resolve = self.state.usable_fixes();
                }
            }
            Err(e) => tracing::error!(error = %e, "Refactorisation failed; the estimate is stale."),
        }
    }
}

impl Engine {
    /// Makes `state` current; its work counters stood at `base` when this
    /// thread's work on it began.
    fn replace_state(&mut self, state: State, base: FactorWork) {
        self.work_done += self.state.work() - self.work_base;
        self.work_base = base;
        retire(std::mem::replace(&mut self.state, state));
    }

    /// Keyframes received so far (for the debug log).
    fn keyframe_count(&self) -> usize {
        self.state.model.graph.keyframes().len()
    }

    /// Records the fresh factor's size.
    fn after_resolve(&mut self) {
        self.nnz_after_resolve = self.state.factor_nnz();
    }
}

/// The χ² a relinearisation must gain at least: below it, a gap between
/// the estimate and its linear model is rounding (a noise-free graph sits
/// at χ² ~1e-20). The nonlinearity check's re-solve, dearer, waits for a
/// gap of 1. With a slack of 1 here, early Manhattan snapshots (χ² of a
/// few units) reached 1.4-1.9× their prefix's optimum; with this one,
/// every sampled one of four runs stayed within 1.22× (City10000 1.15×;
/// see `EngineConfig::relinearise_ratio`).
const RELINEARISE_SLACK: f64 = 0.01;

/// Drops a replaced state on a thread of its own: freeing a factor's
/// tens of thousands of columns took 4% of the foreground's time on
/// City10000.
fn retire(old: State) {
    // without a thread (resource limits) the closure, and the state with
    // it, is dropped here
    let _ = std::thread::Builder::new()
        .name("slamd-retire".into())
        .spawn(move || {
            // spawned by the engine thread, it would share a pinned core
            crate::affinity::run_in_background();
            drop(old)
        });
}

impl Drop for Engine {
    fn drop(&mut self) {
        if let Some(job) = self.job.take() {
            job.stop();
        }
    }
}
