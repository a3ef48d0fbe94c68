//! [`State`]: the [`Model`] with its solvers, and how one change applies.
//!
//! The foreground engine and a background re-solve hold a `State` each and
//! apply the same [`Op`]s to it, so the re-solved state can catch up with
//! what arrived while it was being built.

use super::deferred::Deferred;
use super::gauss_newton::GaussNewton;
use super::linear_stages::LinearStages;
pub use super::model::Model;
pub use super::op::{Op, Polish, SnapshotSource};
use super::{EngineConfig, EngineError};
use crate::geometry::{Pose2, Turns};
use crate::gps::Georef;
use crate::graph::{edge_chi2, edge_error, edge_error_turned, Edge, EdgeKind, KeyframeId};
use crate::outliers::{DriftRun, OutlierConfig, OFF_BELOW};
use crate::sparse::ordering::amd_newest_last;
use crate::sparse::FactorError;
use std::sync::atomic::AtomicBool;

/// Entries of `L` a factor's update walks swept and its back-substitutions
/// read: the work behind a snapshot, measured without a clock.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FactorWork {
    /// Swept by update walks (a column's rows, once per walk).
    pub walked: u64,
    /// Read by back-substitutions.
    pub solved: u64,
}

impl std::ops::Sub for FactorWork {
    type Output = FactorWork;
    fn sub(self, base: FactorWork) -> FactorWork {
        FactorWork {
            walked: self.walked.saturating_sub(base.walked),
            solved: self.solved.saturating_sub(base.solved),
        }
    }
}

impl std::ops::AddAssign for FactorWork {
    fn add_assign(&mut self, more: FactorWork) {
        self.walked += more.walked;
        self.solved += more.solved;
    }
}

/// The model plus the solvers and the cached χ².
#[derive(Clone, Debug)]
pub struct State {
    /// Graph and bookkeeping.
    pub model: Model,
    source: SnapshotSource,
    gn: Option<GaussNewton>,
    linear: Option<LinearStages>,
    /// Per keyframe, the rigid correction from the two-stage pose to the
    /// published one (linear source).
    offset: Vec<Pose2>,
    estimate: Vec<Pose2>,
    edge_chi2: Vec<f64>,
    /// Rotations of the estimate's keyframes and of the edges'
    /// measurements, for the χ² bookkeeping (a moved keyframe meets
    /// several edges; a measurement never changes).
    turns: Turns,
    measured_turns: Turns,
    /// The keyframes the last solve moved (a buffer kept between solves).
    moved: Vec<usize>,
    chi2: f64,
    stamp: Vec<u32>,
    epoch: u32,
    outliers: OutlierConfig,
    /// Loop closures waiting out of the Gauss–Newton factor.
    deferred: Deferred,
    /// The run of agreeing loop closures switched off on arrival.
    drift: DriftRun,
    /// A run reached `drift_run`: the map drifted; re-solve.
    drifted: bool,
    /// While catching up: the foreground's estimate of each keyframe it
    /// had joined (see [`Self::set_hints`]).
    hint: Vec<Option<Pose2>>,
}

impl State {
    /// An empty state publishing from `source`; `linear` keeps the exact
    /// two-stage solution even when it is not the source.
    pub fn new(config: &EngineConfig) -> Self {
        let source = config.snapshot;
        let linear = config.linear_stages || source == SnapshotSource::Linear;
        let gn = (source == SnapshotSource::GaussNewton).then(|| GaussNewton::new(Pose2::IDENTITY));
        Self::assemble(
            config,
            Model::default(),
            gn,
            linear.then(LinearStages::new),
            Vec::new(),
            Vec::new(),
        )
    }

    /// A state over `model` with these solvers, offsets and estimate; the
    /// bookkeeping starts fresh and the cached χ² is computed.
    fn assemble(
        config: &EngineConfig,
        model: Model,
        gn: Option<GaussNewton>,
        linear: Option<LinearStages>,
        offset: Vec<Pose2>,
        estimate: Vec<Pose2>,
    ) -> Self {
        let edges = model.graph.edges().len();
        let mut state = Self {
            stamp: vec![0; edges],
            model,
            source: config.snapshot,
            gn,
            linear,
            offset,
            estimate,
            edge_chi2: vec![0.0; edges],
            turns: Turns::default(),
            measured_turns: Turns::default(),
            moved: Vec::new(),
            chi2: 0.0,
            epoch: 0,
            outliers: config.outliers,
            deferred: Deferred::new(config.defer_budget),
            drift: DriftRun::default(),
            drifted: false,
            hint: Vec::new(),
        };
        state.recompute_chi2();
        state
    }

    /// Applies one change as a catch-up does: before a new keyframe, the
    /// edges of the ones before it connect, as they did at the
    /// foreground's update, so that its loop closures find them joined and
    /// each walk crosses only the keyframes appended so far (connected all
    /// at once, odometry first, every loop closure walked the whole
    /// appended chain).
    ///
    /// With hints ([`Self::set_hints`]) a keyframe joins where the
    /// foreground put it, loop closures included, and the back-substitution
    /// waits for the next [`Self::solve`]. Without, the keyframe is
    /// dead-reckoned from its anchor, so the edges before it are solved for
    /// first: otherwise its loop closures met hundreds of dead-reckoned
    /// keyframes and entered the factor with large errors.
    pub fn replay(&mut self, op: &Op, threshold: f64) -> Result<(), EngineError> {
        if matches!(op, Op::Keyframe { .. }) && !self.model.pending.is_empty() {
            if self.hint.is_empty() {
                self.solve(threshold)?;
            } else {
                self.join_pending()?;
            }
        }
        self.apply(op)
    }

    /// Catching up with a foreground whose estimate is `estimate` over the
    /// keyframes flagged `joined`: a keyframe `k` that joins through
    /// anchor `m` takes the foreground's relative pose `F_m⁻¹ F_k`, so the
    /// new part of the map arrives in the shape the foreground's solves
    /// gave it (its loop closures applied) rather than dead-reckoned.
    pub fn set_hints(&mut self, estimate: &[Pose2], joined: &[bool]) {
        self.hint = (estimate.iter().zip(joined))
            .map(|(&p, &j)| j.then_some(p))
            .collect();
    }

    /// The foreground's estimate of keyframe `k`, forwarded during a
    /// catch-up.
    pub fn hint(&mut self, k: usize, pose: Pose2) {
        if self.hint.len() <= k {
            self.hint.resize(k + 1, None);
        }
        self.hint[k] = Some(pose);
    }

    /// Ends a catch-up: keyframes join dead-reckoned again.
    pub fn clear_hints(&mut self) {
        self.hint = Vec::new();
    }

    /// Connects the pending edges and fixes without solving.
    pub fn join_pending(&mut self) -> Result<(), EngineError> {
        let connected = self.connect_pending();
        self.apply_fixes().and(connected)
    }

    /// Applies one change. Nothing is stored when it is rejected.
    pub fn apply(&mut self, op: &Op) -> Result<(), EngineError> {
        match op {
            Op::Keyframe { id, guess } => {
                let k = self.model.graph.add_keyframe(*id, *guess)?;
                self.model.joined.push(false);
                self.model.incident.push(Vec::new());
                self.stamp.push(0);
                let gauge = guess.unwrap_or(Pose2::IDENTITY);
                self.estimate.push(gauge);
                // the two-stage solution keeps its gauge at the origin
                self.offset.push(gauge);
                if k == 0 {
                    self.model.joined[0] = true;
                    if let Some(gn) = &mut self.gn {
                        *gn = GaussNewton::new(gauge);
                    }
                }
                Ok(())
            }
            Op::Edge(input) => {
                let e = self.model.graph.add_edge(
                    input.from,
                    input.to,
                    input.measurement,
                    input.information,
                    input.kind,
                )?;
                self.model.scale.push(1.0);
                self.model.switch.push(1.0);
                self.model.admitted.push(false);
                self.model.applied.push(false);
                self.edge_chi2.push(0.0);
                self.model.pending.push(e);
                Ok(())
            }
            Op::Gps(fix) => {
                if fix.keyframe >= self.model.graph.len() {
                    return Err(EngineError::FixKeyframe(fix.keyframe as KeyframeId));
                }
                self.model.fixes.push(*fix);
                self.model.fix_applied.push(false);
                Ok(())
            }
            Op::Weight { edge, scale } => self.reweight(*edge, *scale),
        }
    }

    /// Puts the priors of fixes on joined keyframes into the solver, once a
    /// georeference exists (the next re-solve makes one).
    fn apply_fixes(&mut self) -> Result<(), EngineError> {
        if self.model.georef.is_none() {
            return Ok(());
        }
        let Some(gn) = &mut self.gn else {
            return Ok(());
        };
        for f in 0..self.model.fixes.len() {
            if self.model.fix_applied[f] || !self.model.joined[self.model.fixes[f].keyframe] {
                continue;
            }
            let prior = self.model.prior(f).expect("georeferenced");
            self.model.fix_applied[f] = true;
            gn.apply_prior(&prior).map_err(EngineError::Numeric)?;
        }
        Ok(())
    }

    /// Fixes on keyframes in the estimate.
    pub fn usable_fixes(&self) -> usize {
        let m = &self.model;
        m.fixes.iter().filter(|f| m.joined[f.keyframe]).count()
    }

    /// The map→ENU motion, once fitted.
    pub fn georef(&self) -> Option<Georef> {
        self.model.georef
    }

    /// Checks a reweight without applying it.
    pub fn check_weight(&self, edge: usize, scale: f64) -> Result<(), EngineError> {
        let e = self
            .model
            .graph
            .edges()
            .get(edge)
            .ok_or(EngineError::UnknownEdge(edge))?;
        if !scale.is_finite() || scale < 0.0 {
            return Err(EngineError::InvalidWeight(scale));
        }
        if e.kind == EdgeKind::Odometry && scale == 0.0 {
            return Err(EngineError::OdometrySwitch(edge));
        }
        Ok(())
    }

    fn reweight(&mut self, e: usize, scale: f64) -> Result<(), EngineError> {
        self.check_weight(e, scale)?;
        let before = self.model.weight(e);
        self.model.scale[e] = scale;
        let delta = self.model.weight(e) - before;
        if self.model.applied[e] {
            if delta != 0.0 {
                self.contribute(e, delta)?;
                self.refresh_edge(e);
            }
            Ok(())
        } else if scale > 0.0 && !self.model.pending.contains(&e) {
            self.connect(e)
        } else {
            Ok(())
        }
    }

    /// Connects the edges received since the last solve: odometry first, so
    /// that a new keyframe joins through its odometry (the best guess, and a
    /// short update path) and its loop closures find it joined.
    fn connect_pending(&mut self) -> Result<(), EngineError> {
        let mut pending = std::mem::take(&mut self.model.pending);
        let edges = self.model.graph.edges();
        pending.sort_by_key(|&e| (edges[e].kind != EdgeKind::Odometry, e));
        let mut result = Ok(());
        for &e in &pending {
            // keep going: one failure must not strand the other edges
            if let Err(err) = self.connect(e) {
                result = Err(err);
            }
        }
        result
    }

    /// Applies edge `e` if it links to the joined part, joining its other
    /// end (and whatever waited for that) as needed; else it waits.
    fn connect(&mut self, e: usize) -> Result<(), EngineError> {
        let mut queue = vec![e];
        while let Some(e) = queue.pop() {
            if self.model.applied[e] {
                continue;
            }
            let edge = self.model.graph.edges()[e];
            let (i, j) = (edge.from, edge.to);
            let mut wait = false;
            match (self.model.joined[i], self.model.joined[j]) {
                (true, true) => {
                    // a new loop closure between mapped keyframes enters
                    // with the switch its error has now
                    if self.outliers.switchable(&edge) {
                        let s = self.arrival_switch(e, &edge)?;
                        self.model.switch[e] = s;
                        self.model.admitted[e] |= s >= OFF_BELOW;
                    }
                    wait = self.may_wait(e);
                }
                (false, false) => {
                    for k in [i, j] {
                        let list = self.model.waiting.entry(k).or_default();
                        if !list.contains(&e) {
                            list.push(e);
                        }
                    }
                    continue;
                }
                (true, false) | (false, true) if self.model.scale[e] == 0.0 => {
                    // a switched-off edge constrains nothing: it cannot join a keyframe
                    let k = if self.model.joined[i] { j } else { i };
                    let list = self.model.waiting.entry(k).or_default();
                    if !list.contains(&e) {
                        list.push(e);
                    }
                    continue;
                }
                (true, false) | (false, true) => {
                    let (m, k) = if self.model.joined[i] { (i, j) } else { (j, i) };
                    let rel = if m == i {
                        edge.measurement
                    } else {
                        edge.measurement.inverse()
                    };
                    let hinted = match (self.hint.get(k), self.hint.get(m)) {
                        (Some(&Some(hk)), Some(&Some(hm))) => {
                            Some(self.estimate[m].compose(&hm.inverse().compose(&hk)))
                        }
                        _ => None,
                    };
                    let guess = (hinted.or(self.model.graph.keyframes()[k].guess))
                        .unwrap_or_else(|| self.estimate[m].compose(&rel));
                    self.join(k, m, guess);
                    queue.extend(self.model.waiting.remove(&k).unwrap_or_default());
                }
            }
            self.model.applied[e] = true;
            self.model.incident[i].push(e as u32);
            self.model.incident[j].push(e as u32);
            let s = self.model.weight(e);
            if wait {
                // its χ² joins the budget in refresh_edge
                self.deferred.push(e, 0.0);
            }
            if s != 0.0 {
                self.contribute(e, s)?;
            }
            self.refresh_edge(e);
        }
        Ok(())
    }

    /// Whether loop closure `e`, between joined keyframes, may wait out of
    /// the Gauss–Newton factor: its newer keyframe is already pulled by a
    /// loop closure in the factor, and its χ² at the estimate fits the
    /// budget. Odometry always enters (its update path is short), and so
    /// does a keyframe's first loop closure: with all of them waiting, the
    /// keyframes after it joined dead-reckoned, and the Gauss–Newton step
    /// that came when they entered was far from its linearisation point
    /// (Manhattan snapshots 1.54× their prefix's optimum at a 2% budget).
    fn may_wait(&self, e: usize) -> bool {
        let edges = self.model.graph.edges();
        let edge = &edges[e];
        if !self.deferred.enabled() || self.gn.is_none() || edge.kind == EdgeKind::Odometry {
            return false;
        }
        let newer = edge.from.max(edge.to);
        let pulled = self.model.incident[newer].iter().any(|&f| {
            let f = f as usize;
            edges[f].kind != EdgeKind::Odometry && self.model.weight(f) > 0.0 && !self.deferred.waits(f)
        });
        let s = self.model.weight(e);
        pulled
            && s > 0.0
            && self
                .deferred
                .admits(s * edge_chi2(edge, &self.estimate), self.chi2)
    }

    /// The switch new loop closure `e`, between joined keyframes, enters
    /// with: DCS's at the estimate ([`OutlierConfig::arrival_switch`]).
    /// One that turns away joins the run of agreeing rejections
    /// ([`DriftRun`]), vouched for when `arrival_covariance` is on and its
    /// error is within `arrival_phi` of its innovation covariance. Two
    /// vouched members enter together (switch 1, the earlier ones
    /// restored): the first loop closures of a drifted loop, whose ends the
    /// map holds loosely. One alone waits for a second: a random wrong loop
    /// closure between loosely held keyframes passes the covariance test
    /// as well (ringCity's odometry claims 5° per step; 31 of 1000 random
    /// ones passed it and bent the map 30 m). A run reaching `drift_run`
    /// means the map drifted ([`Self::take_drifted`]).
    fn arrival_switch(&mut self, e: usize, edge: &Edge) -> Result<f64, EngineError> {
        let (i, j) = (edge.from, edge.to);
        let s = self
            .outliers
            .arrival_switch(edge, &self.estimate[i], &self.estimate[j]);
        let (covariance, run) = (self.outliers.arrival_covariance, self.outliers.drift_run);
        if s >= OFF_BELOW || (!covariance && run == 0) {
            return Ok(s);
        }
        let vouched = covariance && self.within_innovation(edge)?;
        let (xi, xj) = (&self.estimate[i], &self.estimate[j]);
        let phi = self.outliers.arrival_phi;
        let len = self.drift.rejected(e, vouched, edge, xi, xj, phi);
        if vouched && self.drift.vouched() >= 2 {
            for m in self.drift.take_vouched() {
                if m != e {
                    self.restore(m)?;
                }
                self.model.admitted[m] = true;
            }
            return Ok(1.0);
        }
        if run > 0 && len >= run {
            self.drifted = true;
            self.drift.clear();
        }
        Ok(s)
    }

    /// Whether loop closure `edge`'s error at the estimate is within
    /// `arrival_phi` of its innovation covariance `Ω⁻¹ + σ² J Σ Jᵀ`
    /// ([`GaussNewton::innovation_chi2`]; `σ²`: [`Self::variance_factor`]).
    fn within_innovation(&mut self, edge: &Edge) -> Result<bool, EngineError> {
        let e = edge_error(edge, &self.estimate[edge.from], &self.estimate[edge.to]);
        let factor = self.variance_factor();
        let Some(gn) = &mut self.gn else {
            return Ok(false);
        };
        let innovation = gn
            .innovation_chi2(edge, &e, factor)
            .map_err(EngineError::Numeric)?;
        Ok(innovation.is_some_and(|chi2| chi2 <= self.outliers.arrival_phi))
    }

    /// Switches on loop closure `m`, switched off on arrival: its terms
    /// join the solvers at the estimate.
    fn restore(&mut self, m: usize) -> Result<(), EngineError> {
        if !self.model.applied[m] || self.model.switch[m] >= OFF_BELOW {
            return Ok(());
        }
        self.model.switch[m] = 1.0;
        let w = self.model.weight(m);
        if w != 0.0 {
            self.contribute(m, w)?;
        }
        self.refresh_edge(m);
        Ok(())
    }

    /// The a-posteriori variance factor `χ² / r` of the estimate (`r`: the
    /// redundancy, three per applied edge less three per keyframe past the
    /// gauge), within [10⁻³, 1]; 1 while `r < 30`.
    fn variance_factor(&self) -> f64 {
        let m = &self.model;
        let edges = (0..m.applied.len())
            .filter(|&e| m.applied[e] && m.weight(e) > 0.0)
            .count();
        let keyframes = m.joined.iter().filter(|&&j| j).count();
        let r = 3 * edges as i64 - 3 * (keyframes as i64 - 1);
        if r < 30 {
            1.0
        } else {
            (self.chi2 / r as f64).clamp(1e-3, 1.0)
        }
    }

    /// Keyframe `k` joins through an edge from `anchor`, at `guess`.
    fn join(&mut self, k: usize, anchor: usize, guess: Pose2) {
        self.model.joined[k] = true;
        self.estimate[k] = guess;
        // a new keyframe carries its anchor's correction: the new part of
        // the map is the two-stage solution's, moved rigidly
        self.offset[k] = self.offset[anchor];
        if let Some(gn) = &mut self.gn {
            gn.add_keyframe(k, guess);
        }
        if let Some(l) = &mut self.linear {
            l.add_keyframe(k);
        }
    }

    /// Adds `delta` times edge `e`'s terms to every solver it is in.
    fn contribute(&mut self, e: usize, delta: f64) -> Result<(), EngineError> {
        self.contribute_gn(e, delta)?;
        let edge = self.model.graph.edges()[e];
        if let Some(l) = &mut self.linear {
            l.apply_edge(e, &edge, delta).map_err(EngineError::Numeric)?;
        }
        Ok(())
    }

    /// Adds `delta` times edge `e`'s terms to the Gauss–Newton factor,
    /// unless it waits.
    fn contribute_gn(&mut self, e: usize, delta: f64) -> Result<(), EngineError> {
        let edge = self.model.graph.edges()[e];
        if let Some(gn) = self.gn.as_mut().filter(|_| !self.deferred.waits(e)) {
            gn.apply_edge(&edge, delta).map_err(EngineError::Numeric)?;
        }
        Ok(())
    }

    /// Recomputes one edge's cached χ² at the current estimate.
    fn refresh_edge(&mut self, e: usize) {
        let edge = &self.model.graph.edges()[e];
        let v = self.model.weight(e)
            * turned_chi2(&mut self.turns, &mut self.measured_turns, e, edge, &self.estimate);
        self.chi2 += v - self.edge_chi2[e];
        self.deferred.refresh(e, self.edge_chi2[e], v);
        self.edge_chi2[e] = v;
    }

    /// Brings the estimate up to date (see [`GaussNewton::solve`]) and the
    /// cached χ² with it. Returns the number of keyframes that moved.
    pub fn solve(&mut self, threshold: f64) -> Result<usize, EngineError> {
        let connected = self.join_pending();
        let mut moved = self.solve_factor(threshold)?;
        connected?;
        // the estimate moved: waiting loop closures over budget enter, and
        // the solve that follows moves it again; each round takes one in
        // at least, so this ends
        loop {
            let mut entered = false;
            while let Some(e) = self.deferred.pop_over_budget(self.chi2, &self.edge_chi2) {
                self.contribute_gn(e, self.model.weight(e))?;
                entered = true;
            }
            if !entered {
                return Ok(moved);
            }
            moved = moved.max(self.solve_factor(threshold)?);
        }
    }

    /// Solves the source's factor and refreshes the estimate and its χ².
    /// Returns the number of keyframes that moved.
    fn solve_factor(&mut self, threshold: f64) -> Result<usize, EngineError> {
        // the buffer is reused: a fresh one per solve made glibc
        // consolidate its free lists every keyframe
        let mut changed = std::mem::take(&mut self.moved);
        changed.clear();
        match self.source {
            SnapshotSource::GaussNewton => {
                let gn = self.gn.as_mut().expect("Gauss–Newton source");
                changed.extend_from_slice(gn.solve(threshold).map_err(EngineError::Numeric)?);
                for &k in &changed {
                    self.estimate[k] = gn.estimate()[k];
                }
            }
            SnapshotSource::Linear => {
                let l = self.linear.as_mut().expect("linear source");
                changed.extend_from_slice(l.solve(&self.model.graph, threshold));
                for &k in &changed {
                    self.estimate[k] = self.offset[k].compose(&l.pose(k));
                }
            }
        }
        if changed.len() * 4 > self.model.graph.len() {
            self.recompute_chi2();
        } else {
            self.epoch = self.epoch.wrapping_add(1);
            for &k in &changed {
                for i in 0..self.model.incident[k].len() {
                    let e = self.model.incident[k][i] as usize;
                    if self.stamp_edge(e) {
                        self.refresh_edge(e);
                    }
                }
            }
        }
        let moved = changed.len();
        self.moved = changed;
        Ok(moved)
    }

    fn stamp_edge(&mut self, e: usize) -> bool {
        if self.stamp.len() < self.edge_chi2.len() {
            self.stamp.resize(self.edge_chi2.len(), 0);
        }
        let fresh = self.stamp[e] != self.epoch;
        self.stamp[e] = self.epoch;
        fresh
    }

    /// Recomputes every cached χ² (kills round-off drift of the running sum).
    pub fn recompute_chi2(&mut self) {
        let est = &self.estimate;
        for (e, edge) in self.model.graph.edges().iter().enumerate() {
            self.edge_chi2[e] = if self.model.applied[e] {
                self.model.weight(e) * turned_chi2(&mut self.turns, &mut self.measured_turns, e, edge, est)
            } else {
                0.0
            };
        }
        self.chi2 = self.edge_chi2.iter().sum();
        self.deferred.recount(&self.edge_chi2);
    }

    /// χ² of the estimate over the applied edges, with their weights.
    pub fn chi2(&self) -> f64 {
        self.chi2
    }

    /// χ² of the estimate over the edges in the factor: what the
    /// Gauss–Newton model predicts (the waiting loop closures left out).
    pub fn factor_chi2(&self) -> f64 {
        self.chi2 - self.deferred.chi2()
    }

    /// Whether a run of agreeing rejected loop closures said the map
    /// drifted since the last call.
    pub fn take_drifted(&mut self) -> bool {
        std::mem::take(&mut self.drifted)
    }

    /// Loop closures waiting out of the factor now, and their χ².
    pub fn deferred(&self) -> (usize, f64) {
        (self.deferred.len(), self.deferred.chi2())
    }

    /// The estimate of every keyframe slot (meaningful where joined).
    pub fn estimate(&self) -> &[Pose2] {
        &self.estimate
    }

    /// χ² the Gauss–Newton model predicts for the current estimate, when
    /// that is the source.
    pub fn predicted_chi2(&self) -> Option<f64> {
        self.gn.as_ref().map(|g| g.predicted_chi2())
    }

    /// What the Gauss–Newton factor's update walks and back-substitutions
    /// have swept so far (zero without one).
    pub fn work(&self) -> FactorWork {
        self.gn.as_ref().map_or(FactorWork::default(), |g| FactorWork {
            walked: g.factor().walk_stats().entries,
            solved: g.solve_stats().entries,
        })
    }

    /// Stored entries of the factor behind the published estimate.
    pub fn factor_nnz(&self) -> usize {
        match (&self.gn, &self.linear) {
            (Some(gn), _) => gn.factor_nnz(),
            (None, Some(l)) => l.factor_nnz(),
            (None, None) => 0,
        }
    }

    /// The exact two-stage solution, when kept.
    pub fn linear_solution(&mut self) -> Option<Vec<Pose2>> {
        let graph = &self.model.graph;
        self.linear.as_mut().map(|l| l.solve_exact(graph))
    }

    /// A fresh state from `model`: polished from `start` as `polish` says,
    /// re-ordered with the newest `recent_last` keyframes last,
    /// refactorised.
    pub fn rebuild(
        mut model: Model,
        start: &[Pose2],
        polish: Polish,
        config: &EngineConfig,
    ) -> Result<State, FactorError> {
        let lin = Self::polish_model(&mut model, start, polish, config, &AtomicBool::new(false));
        Self::factorise(model, lin, config)
    }

    /// The first half of [`Self::rebuild`]: unjoins what no weighted edge
    /// holds and polishes `model` from `start` as `polish` says, setting
    /// its switches and georeference; returns the linearisation point of
    /// every keyframe. Once `stop` is set the polish ends where it is and
    /// the georeference is left as it was.
    pub fn polish_model(
        model: &mut Model,
        start: &[Pose2],
        polish: Polish,
        config: &EngineConfig,
        stop: &AtomicBool,
    ) -> Vec<Pose2> {
        model.unjoin_unconstrained();
        let n = model.graph.len();
        let mut lin = start.to_vec();
        lin.resize(n, Pose2::IDENTITY);
        if polish != Polish::None {
            let (joined, compact) = model.compact_joined();
            let started = std::time::Instant::now();
            let mut poses = model.robust_polish(config, &compact, &joined, &lin, polish, stop);
            tracing::debug!(seconds = started.elapsed().as_secs_f64(), ?polish, "Polished.");
            if !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let (edges, _) = model.compact_edges(&compact, Model::weight);
                model.georeference(&config.gps, &edges, &compact, &mut poses, &config.polish);
            }
            for (c, &k) in joined.iter().enumerate() {
                lin[k] = poses[c];
            }
        }
        lin
    }

    /// The second half of [`Self::rebuild`]: the fresh factor of `model`
    /// linearised at `lin`.
    pub fn factorise(mut model: Model, lin: Vec<Pose2>, config: &EngineConfig) -> Result<State, FactorError> {
        let (recent, source, linear) = (config.recent_last, config.snapshot, config.linear_stages);
        let n = model.graph.len();
        let (joined, compact) = model.compact_joined();
        let active: Vec<(usize, f64)> = (0..model.graph.edges().len())
            .filter(|&e| model.applied[e] && model.weight(e) > 0.0)
            .map(|e| (e, model.weight(e)))
            .collect();
        // every fix on a joined keyframe enters the fresh factor
        let mut priors = Vec::new();
        for f in 0..model.fixes.len() {
            let on = model.joined[model.fixes[f].keyframe];
            let prior = if on { model.prior(f) } else { None };
            model.fix_applied[f] = prior.is_some();
            priors.extend(prior);
        }
        // elimination order over joined keyframes except the gauge
        let pairs = active.iter().filter_map(|&(e, _)| {
            let edge = &model.graph.edges()[e];
            let (a, b) = (compact[edge.from], compact[edge.to]);
            (a > 0 && b > 0).then(|| (a - 1, b - 1))
        });
        let perm = amd_newest_last(joined.len().saturating_sub(1), pairs, recent);
        let order: Vec<usize> = perm.iter().map(|&c| joined[c + 1]).collect();
        let gn = match source {
            SnapshotSource::GaussNewton => Some(GaussNewton::build(
                &model.graph,
                &active,
                &priors,
                lin.clone(),
                &order,
            )?),
            SnapshotSource::Linear => None,
        };
        let linear = if linear || source == SnapshotSource::Linear {
            Some(LinearStages::build(&model.graph, &active, &order)?)
        } else {
            None
        };
        // the correction from each two-stage pose to its polished pose
        let offset: Vec<Pose2> = (0..n)
            .map(|k| match &linear {
                Some(l) if model.joined[k] => lin[k].compose(&l.pose(k).inverse()),
                _ => lin[0],
            })
            .collect();
        let estimate = match &gn {
            Some(g) => g.estimate().to_vec(),
            None => lin,
        };
        Ok(State::assemble(config, model, gn, linear, offset, estimate))
    }

    /// A copy of the model, for a rebuild elsewhere.
    pub fn model(&self) -> &Model {
        &self.model
    }
}

/// `eᵀ Ω e` of edge `e` at `estimate`, the rotations from the caches (the
/// χ² bookkeeping evaluates every edge of each keyframe that moved; the
/// sines and cosines were 70% of it).
fn turned_chi2(turns: &mut Turns, measured: &mut Turns, e: usize, edge: &Edge, estimate: &[Pose2]) -> f64 {
    let (xi, xj) = (&estimate[edge.from], &estimate[edge.to]);
    let turn_i = turns.get(edge.from, xi.theta);
    let turn_m = measured.get(e, edge.measurement.theta);
    edge.information
        .mahalanobis(&edge_error_turned(edge, xi, turn_i, xj, turn_m))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::EdgeInput;
    use crate::graph::Information;

    fn keyframe(id: KeyframeId) -> Op {
        Op::Keyframe { id, guess: None }
    }

    fn odometry(from: KeyframeId, to: KeyframeId, step: Pose2) -> Op {
        Op::Edge(EdgeInput::new(
            from,
            to,
            step,
            Information::identity(),
            EdgeKind::Odometry,
        ))
    }

    fn close(a: Pose2, b: Pose2) -> bool {
        (a.x - b.x).abs() < 1e-12 && (a.y - b.y).abs() < 1e-12 && (a.theta - b.theta).abs() < 1e-12
    }

    /// A caught-up keyframe joins at its anchor moved by the foreground's
    /// relative pose `F_m⁻¹ F_k`; without a hint, dead-reckoned.
    #[test]
    fn a_hinted_keyframe_joins_where_the_foreground_put_it() {
        let step = Pose2::new(1.0, 0.0, 0.0);
        let mut plain = State::new(&EngineConfig::default());
        for op in [keyframe(0), keyframe(1), odometry(0, 1, step)] {
            plain.replay(&op, 0.0).unwrap();
        }
        plain.solve(0.0).unwrap();
        let mut hinted = plain.clone();
        // the foreground's map sits elsewhere, and its solves bent keyframe
        // 2 away from the odometry
        let f1 = Pose2::new(5.0, -2.0, 0.7);
        let relative = Pose2::new(0.5, 0.2, 0.1);
        hinted.set_hints(&[Pose2::IDENTITY, f1], &[true, true]);
        hinted.hint(2, f1.compose(&relative));
        for state in [&mut plain, &mut hinted] {
            state.replay(&keyframe(2), 0.0).unwrap();
            state.replay(&odometry(1, 2, step), 0.0).unwrap();
            state.join_pending().unwrap();
        }
        let anchor = plain.estimate()[1];
        assert!(close(plain.estimate()[2], anchor.compose(&step)));
        assert!(close(hinted.estimate()[1], anchor));
        assert!(close(hinted.estimate()[2], anchor.compose(&relative)));
        // the catch-up over, keyframes join dead-reckoned again
        hinted.clear_hints();
        hinted.replay(&keyframe(3), 0.0).unwrap();
        hinted.replay(&odometry(2, 3, step), 0.0).unwrap();
        hinted.join_pending().unwrap();
        let k2 = hinted.estimate()[2];
        assert!(close(hinted.estimate()[3], k2.compose(&step)));
    }

    /// Six keyframes 1 m apart along x, then two loop closures from 0 to
    /// 5 (edges 5 and 6): one `x` metres long (let in on arrival when near
    /// 5) and one far off (turned away); solved.
    fn line_closed(config: &EngineConfig, x: f64) -> State {
        let step = Pose2::new(1.0, 0.0, 0.0);
        let mut state = State::new(config);
        for k in 0..6 {
            state.replay(&keyframe(k), 0.0).unwrap();
            if k > 0 {
                state.replay(&odometry(k - 1, k, step), 0.0).unwrap();
            }
        }
        for z in [Pose2::new(x, 0.0, 0.0), Pose2::new(-40.0, 30.0, 2.0)] {
            let closure = EdgeInput::new(0, 5, z, Information::identity(), EdgeKind::LoopClosure);
            state.replay(&Op::Edge(closure), 0.0).unwrap();
        }
        state.solve(0.0).unwrap();
        state
    }

    /// A loop closure let in on arrival is marked until a multi-start
    /// re-solve has judged it (the closing one gets a start without the
    /// marked ones); one turned away on arrival is not marked.
    #[test]
    fn loop_closures_let_in_on_arrival_are_marked_until_a_full_resolve() {
        let config = EngineConfig::default();
        let state = line_closed(&config, 5.0);
        let (agreeing, wrong) = (5, 6);
        assert!(state.model.switch[agreeing] >= OFF_BELOW && state.model.admitted[agreeing]);
        assert!(state.model.switch[wrong] < OFF_BELOW && !state.model.admitted[wrong]);
        // a relinearisation is no judgement; a multi-start re-solve is
        let estimate = state.estimate().to_vec();
        let relinearised = State::rebuild(state.model.clone(), &estimate, Polish::None, &config).unwrap();
        assert!(relinearised.model.admitted[agreeing]);
        let resolved = State::rebuild(state.model.clone(), &estimate, Polish::Full, &config).unwrap();
        assert!(!resolved.model.admitted.iter().any(|&a| a));
    }

    /// The start without the loop closures let in on arrival: the closing
    /// re-solve's always, every multi-start re-solve's with
    /// `unadmitted_start`, the inline polish's never.
    #[test]
    fn the_start_without_admitted_loop_closures_goes_where_configured() {
        let config = EngineConfig::default();
        // the loop closure let in pulls keyframe 5 by 0.3 m
        let state = line_closed(&config, 5.3);
        assert!(state.model.admitted[5] && !state.model.admitted[6]);
        let (joined, compact) = state.model.compact_joined();
        let (_, ids) = state.model.compact_edges(&compact, |m, e| m.scale[e]);
        let initial: Vec<Pose2> = joined.iter().map(|&k| state.estimate()[k]).collect();
        let starts = |config: &EngineConfig, polish| {
            state
                .model
                .starts(config, &compact, &joined, &initial, &ids, polish)
        };
        let always = EngineConfig {
            outliers: OutlierConfig {
                unadmitted_start: true,
                ..config.outliers
            },
            ..config.clone()
        };
        // the estimate, the two-stage solution under the switches, under none
        assert_eq!(starts(&config, Polish::Full).len(), 3);
        assert_eq!(starts(&config, Polish::Inline).len(), 1);
        assert_eq!(starts(&always, Polish::Inline).len(), 1);
        for (config, polish) in [(&config, Polish::Closing), (&always, Polish::Full)] {
            let s = starts(config, polish);
            assert_eq!(s.len(), 4);
            // under the switches keyframe 5 is pulled toward 5.3; without
            // the loop closure let in, odometry alone puts it at 5
            assert!(s[1][5].x > 5.1, "{:?}", s[1][5]);
            assert!((s[3][5].x - 5.0).abs() < 1e-9, "{:?}", s[3][5]);
        }
    }

    /// The start under no switches rescues loop closures held wrong; a
    /// scheduled re-solve takes it only while one is (below 0.5), the
    /// closing one whenever a switch is below 1.
    #[test]
    fn a_scheduled_resolve_takes_the_rescue_start_only_while_one_is_held_wrong() {
        let config = EngineConfig::default();
        let mut state = line_closed(&config, 5.0);
        let wrong = 6;
        let mut counts = |switch: f64| {
            state.model.switch[wrong] = switch;
            let (joined, compact) = state.model.compact_joined();
            let (_, ids) = state.model.compact_edges(&compact, |m, e| m.scale[e]);
            let initial: Vec<Pose2> = joined.iter().map(|&k| state.estimate()[k]).collect();
            let starts = |polish| {
                state
                    .model
                    .starts(&config, &compact, &joined, &initial, &ids, polish)
                    .len()
            };
            (starts(Polish::Full), starts(Polish::FullInline))
        };
        // held wrong: the estimate, under the switches, under none
        assert_eq!(counts(0.3), (3, 3));
        // only down-weighted: the scheduled re-solve skips the rescue
        assert_eq!(counts(0.7), (2, 3));
        // every switch at 1: neither takes it
        assert_eq!(counts(1.0), (2, 2));
    }
}
