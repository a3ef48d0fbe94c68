//! [`State`]: the [`Model`] with its Gauss–Newton system, and how one
//! change applies.
//!
//! The foreground engine and a background re-solve hold a `State` each and
//! apply the same [`Op`]s to it, so the re-solved state can catch up with
//! what arrived while it was being built.

use super::arrival::{ArrivalGate, Verdict};
use super::changed::{Changed, Changes};
use super::chi2::Chi2Cache;
use super::gauss_newton::GaussNewton;
pub use super::model::{EdgeState, FixState, KeyframeState, Model};
pub use super::op::{Op, Polish};
use super::pose::EnginePose;
use super::report::FactorWork;
use super::{EngineConfig, EngineError};
use crate::geometry::Pose2;
use crate::gps::Georef;
use crate::graph::{Edge, EdgeKind, KeyframeId};
use crate::outliers::OFF_BELOW;
use crate::sparse::FactorError;

mod changes;
mod factorise;

/// The model, its Gauss–Newton system, the estimate and its cached χ².
#[derive(Clone, Debug)]
pub struct State<P: EnginePose = Pose2> {
    /// Graph and bookkeeping.
    pub model: Model<P>,
    gn: GaussNewton<P>,
    estimate: Vec<P>,
    chi2: Chi2Cache,
    /// The keyframes the last solve moved (a buffer kept between solves).
    moved: Vec<usize>,
    /// Keyframes whose estimate changed since a snapshot last asked.
    changed: Changed,
    gate: ArrivalGate<P>,
    /// While catching up: the foreground's estimate of each keyframe it
    /// had joined (see [`Self::set_hints`]).
    hint: Vec<Option<P>>,
}

impl<P: EnginePose> State<P> {
    /// The Gauss–Newton system.
    pub(super) fn gauss_newton(&mut self) -> &mut GaussNewton<P> {
        &mut self.gn
    }

    /// An empty state.
    pub fn new(config: &EngineConfig) -> Self {
        Self::assemble(
            config,
            Model::default(),
            GaussNewton::new(P::IDENTITY),
            Vec::new(),
        )
    }

    /// A state over `model` with this Gauss–Newton system and estimate;
    /// the bookkeeping starts fresh and the cached χ² is computed.
    pub(super) fn assemble(
        config: &EngineConfig,
        model: Model<P>,
        gn: GaussNewton<P>,
        estimate: Vec<P>,
    ) -> Self {
        Self {
            chi2: Chi2Cache::new(&model, &estimate),
            model,
            gn,
            estimate,
            moved: Vec::new(),
            changed: Changed::default(),
            gate: ArrivalGate::new(config.outliers),
            hint: Vec::new(),
        }
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
    pub fn replay(&mut self, op: &Op<P>, threshold: f64) -> Result<(), EngineError> {
        if matches!(op, Op::Keyframe(_)) && !self.model.unconnected.is_empty() {
            if self.hint.is_empty() {
                self.solve(threshold)?;
            } else {
                self.join_new()?;
            }
        }
        self.apply(op)
    }

    /// Catching up with a foreground whose estimate is `estimate` over the
    /// keyframes flagged `joined`: a keyframe `k` that joins through
    /// anchor `m` takes the foreground's relative pose `F_m⁻¹ F_k`, so the
    /// new part of the map arrives in the shape the foreground's solves
    /// gave it (its loop closures applied) rather than dead-reckoned.
    pub fn set_hints(&mut self, estimate: &[P], joined: impl IntoIterator<Item = bool>) {
        self.hint = (estimate.iter().zip(joined))
            .map(|(&p, j)| j.then_some(p))
            .collect();
    }

    /// The foreground's estimate of keyframe `k`, forwarded during a
    /// catch-up.
    pub fn hint(&mut self, k: usize, pose: P) {
        if self.hint.len() <= k {
            self.hint.resize(k + 1, None);
        }
        self.hint[k] = Some(pose);
    }

    /// Ends a catch-up: keyframes join dead-reckoned again.
    pub fn clear_hints(&mut self) {
        self.hint = Vec::new();
    }

    /// This state refactorised with a fresh ordering at its linearisation
    /// point (the estimate where none is kept yet), its arrival gate and
    /// hints kept: the same linear system without the fill of keyframes
    /// appended to an older ordering, whose loop closures reach back into
    /// it.
    pub fn reordered(&self, config: &EngineConfig) -> Result<Self, FactorError> {
        let mut lin = self.linearisation().to_vec();
        lin.extend_from_slice(&self.estimate[lin.len()..]);
        let mut fresh = Self::factorise(self.model.clone(), lin, config)?;
        fresh.gate = self.gate.clone();
        fresh.hint = self.hint.clone();
        Ok(fresh)
    }

    /// Connects the edges and fixes received since the last solve, without
    /// solving.
    pub fn join_new(&mut self) -> Result<(), EngineError> {
        let connected = self.connect_new();
        self.apply_fixes().and(connected)
    }

    /// Applies one change. Nothing is stored when it is rejected.
    pub fn apply(&mut self, op: &Op<P>) -> Result<(), EngineError> {
        match op {
            Op::Keyframe(input) => {
                let k = self.model.graph.add_keyframe(input.id, input.guess)?;
                self.model.keyframes.push(KeyframeState {
                    timestamp_ns: input.timestamp_ns,
                    ..KeyframeState::default()
                });
                let gauge = input.guess.unwrap_or(P::IDENTITY);
                self.estimate.push(gauge);
                if k == 0 {
                    // keyframe 0 fixes the gauge where it is
                    self.gn = GaussNewton::new(gauge);
                    self.model.keyframes[0].joined = true;
                    self.changed.mark(0);
                }
                Ok(())
            }
            Op::Edge(input, origin) => {
                let e = self.model.graph.add_edge(
                    input.from,
                    input.to,
                    input.measurement,
                    input.information,
                    input.kind,
                )?;
                let held = self.model.judged && input.kind.switchable();
                let state = if held { EdgeState::HELD } else { EdgeState::NEW };
                self.model.edges.push(EdgeState {
                    origin: *origin,
                    ..state
                });
                self.chi2.push_edge();
                self.model.unconnected.push(e);
                Ok(())
            }
            Op::Gps(fix) => {
                if fix.keyframe >= self.model.graph.len() {
                    return Err(EngineError::FixKeyframe(fix.keyframe as KeyframeId));
                }
                self.model.fixes.push(FixState {
                    fix: *fix,
                    applied: false,
                });
                Ok(())
            }
            Op::Weight { edge, scale } => self.reweight(*edge, *scale),
            Op::Switch { edge, switch } => self.set_switch(*edge, *switch),
        }
    }

    /// Puts the priors of fixes on joined keyframes into the solver, once a
    /// georeference exists (the next re-solve makes one).
    fn apply_fixes(&mut self) -> Result<(), EngineError> {
        if self.model.georef.is_none() {
            return Ok(());
        }
        for f in 0..self.model.fixes.len() {
            let FixState { fix, applied } = self.model.fixes[f];
            if applied || !self.model.joined(fix.keyframe) {
                continue;
            }
            let prior = self.model.prior(f).expect("georeferenced");
            self.model.fixes[f].applied = true;
            self.gn.apply_prior(&prior).map_err(EngineError::Numeric)?;
        }
        Ok(())
    }

    /// Fixes on keyframes in the estimate.
    pub fn usable_fixes(&self) -> usize {
        let m = &self.model;
        m.fixes.iter().filter(|f| m.joined(f.fix.keyframe)).count()
    }

    /// The map→ENU motion, once fitted.
    pub fn georef(&self) -> Option<Georef> {
        self.model.georef
    }

    /// Connects the edges received since the last solve: odometry first, so
    /// that a new keyframe joins through its odometry (the best guess, and a
    /// short update path) and its loop closures find it joined.
    fn connect_new(&mut self) -> Result<(), EngineError> {
        let mut unconnected = std::mem::take(&mut self.model.unconnected);
        let edges = self.model.graph.edges();
        unconnected.sort_by_key(|&e| (edges[e].kind != EdgeKind::Odometry, e));
        let mut result = Ok(());
        for &e in &unconnected {
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
            if self.model.edges[e].applied {
                continue;
            }
            let edge = self.model.graph.edges()[e];
            let (i, j) = (edge.from, edge.to);
            match (self.model.joined(i), self.model.joined(j)) {
                (true, true) => {
                    // a new loop closure between mapped keyframes enters
                    // with the switch its error has now
                    if self.gate.switchable(&edge) {
                        let s = self.arrival_switch(e, &edge)?;
                        self.model.edges[e].switch = s;
                        self.model.edges[e].admitted |= s >= OFF_BELOW;
                    }
                }
                (false, false) => {
                    self.model.wait_for(i, e);
                    self.model.wait_for(j, e);
                    continue;
                }
                (true, false) | (false, true) if self.model.weight(e) == 0.0 => {
                    // an edge switched off, removed or held constrains
                    // nothing: it cannot join a keyframe
                    let k = if self.model.joined(i) { j } else { i };
                    self.model.wait_for(k, e);
                    continue;
                }
                (true, false) | (false, true) => {
                    let (m, k) = if self.model.joined(i) { (i, j) } else { (j, i) };
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
                    self.join(k, guess);
                    queue.extend(self.model.waiting.remove(&k).unwrap_or_default());
                }
            }
            self.model.edges[e].applied = true;
            self.model.keyframes[i].incident.push(e as u32);
            self.model.keyframes[j].incident.push(e as u32);
            let s = self.model.weight(e);
            if s != 0.0 {
                self.contribute(e, s)?;
            }
            self.refresh_edge(e);
        }
        Ok(())
    }

    /// The switch new loop closure `e`, between joined keyframes, enters
    /// with ([`ArrivalGate`]); a run of vouched rejections restores its
    /// earlier members.
    fn arrival_switch(&mut self, e: usize, edge: &Edge<P>) -> Result<f64, EngineError> {
        let (xi, xj) = (self.estimate[edge.from], self.estimate[edge.to]);
        let s = self.gate.switch(edge, &xi, &xj);
        if !self.gate.judges(s) {
            return Ok(s);
        }
        let vouched = self.gate.vouches() && self.within_innovation(edge)?;
        match self.gate.rejected(e, vouched, edge, &xi, &xj) {
            Verdict::Stays => Ok(s),
            Verdict::EnterWith(members) => {
                for m in members {
                    if m != e {
                        self.restore(m)?;
                    }
                    self.model.edges[m].admitted = true;
                }
                Ok(1.0)
            }
        }
    }

    /// Whether loop closure `edge`'s error at the estimate is within
    /// `arrival_phi` of its innovation covariance `Ω⁻¹ + σ² J Σ Jᵀ`
    /// ([`GaussNewton::innovation_chi2`](super::gauss_newton::GaussNewton::innovation_chi2); `σ²`: [`Self::variance_factor`]).
    fn within_innovation(&mut self, edge: &Edge<P>) -> Result<bool, EngineError> {
        let e = P::edge_error(edge, &self.estimate[edge.from], &self.estimate[edge.to]);
        let factor = self.variance_factor();
        let phi = self.gate.phi();
        let innovation = (self.gn)
            .innovation_chi2(edge, &e, factor)
            .map_err(EngineError::Numeric)?;
        Ok(innovation.is_some_and(|chi2| chi2 <= phi))
    }

    /// Switches on loop closure `m`, switched off on arrival: its terms
    /// join the factor at the estimate.
    fn restore(&mut self, m: usize) -> Result<(), EngineError> {
        if !self.model.edges[m].applied || self.model.edges[m].switch >= OFF_BELOW {
            return Ok(());
        }
        self.model.edges[m].switch = 1.0;
        let w = self.model.weight(m);
        if w != 0.0 {
            self.contribute(m, w)?;
        }
        self.refresh_edge(m);
        Ok(())
    }

    /// The a-posteriori variance factor `χ² / r` of the estimate (`r`: the
    /// redundancy, `DOF` per applied edge less `DOF` per keyframe past the
    /// gauge), within [10⁻³, 1] ([`crate::gps::variance_factor`]: 1 while
    /// `r` is below its `MIN_REDUNDANCY`).
    fn variance_factor(&self) -> f64 {
        let m = &self.model;
        let edges = (0..m.edges.len())
            .filter(|&e| m.edges[e].applied && m.weight(e) > 0.0)
            .count();
        let keyframes = m.keyframes.iter().filter(|k| k.joined).count();
        crate::gps::variance_factor(self.chi2.total(), edges, keyframes, P::DOF).clamp(1e-3, 1.0)
    }

    /// Keyframe `k` joins the map at `guess`.
    fn join(&mut self, k: usize, guess: P) {
        self.model.keyframes[k].joined = true;
        self.estimate[k] = guess;
        self.changed.mark(k);
        self.gn.add_keyframe(k, guess);
    }

    /// Adds `delta` times edge `e`'s terms to the Gauss–Newton system.
    fn contribute(&mut self, e: usize, delta: f64) -> Result<(), EngineError> {
        let edge = self.model.graph.edges()[e];
        self.gn.apply_edge(&edge, delta).map_err(EngineError::Numeric)
    }

    /// Recomputes one edge's cached χ² at the current estimate.
    fn refresh_edge(&mut self, e: usize) {
        self.chi2.refresh(&self.model, e, &self.estimate);
    }

    /// Brings the estimate up to date (see [`GaussNewton::solve`](super::gauss_newton::GaussNewton::solve))
    /// and the cached χ² with it. Returns the number of keyframes that
    /// moved.
    pub fn solve(&mut self, threshold: f64) -> Result<usize, EngineError> {
        let connected = self.join_new();
        // the buffer is reused: a fresh one per solve made the allocator
        // consolidate its free lists every keyframe
        let mut changed = std::mem::take(&mut self.moved);
        changed.clear();
        let solved = match self.gn.solve(threshold) {
            Ok(moved) => {
                changed.extend_from_slice(moved);
                Ok(())
            }
            Err(e) => Err(EngineError::Numeric(e)),
        };
        if solved.is_ok() {
            for &k in &changed {
                self.estimate[k] = self.gn.estimate()[k];
                self.changed.mark(k);
            }
            self.chi2.refresh_moved(&self.model, &changed, &self.estimate);
        }
        let moved = changed.len();
        self.moved = changed;
        solved?;
        connected?;
        Ok(moved)
    }

    /// χ² of the estimate over the applied edges, with their weights.
    pub fn chi2(&self) -> f64 {
        self.chi2.total()
    }

    /// Whether a run of agreeing rejected loop closures said the map
    /// drifted since the last call.
    pub fn take_drifted(&mut self) -> bool {
        self.gate.take_drifted()
    }

    /// Replaces the estimate of the joined keyframes `start` covers, for a
    /// rebuild to start from (the factor and the cached χ² are left as
    /// they were: only a rebuild may follow).
    pub fn start_from(&mut self, start: &[P]) {
        self.changed.mark_all();
        let joined = self.model.keyframes.iter().zip(&mut self.estimate);
        for ((kf, x), s) in joined.zip(start) {
            if kf.joined {
                *x = *s;
            }
        }
    }

    /// Which keyframes' estimates changed since the last call.
    pub fn take_changes(&mut self) -> Changes {
        self.changed.take()
    }

    /// Every keyframe's estimate may have changed (this state replaced
    /// another).
    pub(super) fn changed_all(&mut self) {
        self.changed.mark_all();
    }

    /// The estimate of every keyframe slot (meaningful where joined).
    pub fn estimate(&self) -> &[P] {
        &self.estimate
    }

    /// Where the estimate is linearised: the Gauss–Newton system's point.
    /// Indexed like the keyframes, but it may end at the newest joined
    /// one: a newer keyframe no edge has connected yet has no
    /// linearisation point.
    pub fn linearisation(&self) -> &[P] {
        self.gn.linearisation()
    }

    /// χ² the Gauss–Newton model predicts for the current estimate.
    pub fn predicted_chi2(&self) -> f64 {
        self.gn.predicted_chi2()
    }

    /// What the Gauss–Newton factor's update walks and back-substitutions
    /// have swept so far.
    pub fn work(&self) -> FactorWork {
        FactorWork {
            walked: self.gn.factor().walk_stats().entries,
            solved: self.gn.solve_stats().entries,
        }
    }

    /// Stored entries of the factor behind the published estimate.
    pub fn factor_nnz(&self) -> usize {
        self.gn.factor_nnz()
    }

    /// The factor's columns (scalar variables).
    pub fn factor_columns(&self) -> usize {
        self.gn.factor_columns()
    }

    /// A copy of the model, for a rebuild elsewhere.
    pub fn model(&self) -> &Model<P> {
        &self.model
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::engine::EdgeInput;
    use crate::graph::{Information, KeyframeInput};
    use slamd_protocol::codec::Origin;

    /// Keyframe `id`, no guess.
    pub fn keyframe(id: KeyframeId) -> Op {
        Op::Keyframe(KeyframeInput::new(id, None, 0))
    }

    /// Odometry `step` from `from` to `to`, unit information.
    pub fn odometry(from: KeyframeId, to: KeyframeId, step: Pose2) -> Op {
        Op::Edge(
            EdgeInput::new(from, to, step, Information::identity(), EdgeKind::Odometry),
            Origin::LOCAL,
        )
    }

    /// Two poses equal to 1e-12 in every component.
    pub fn close(a: Pose2, b: Pose2) -> bool {
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
        hinted.set_hints(&[Pose2::IDENTITY, f1], [true, true]);
        hinted.hint(2, f1.compose(&relative));
        for state in [&mut plain, &mut hinted] {
            state.replay(&keyframe(2), 0.0).unwrap();
            state.replay(&odometry(1, 2, step), 0.0).unwrap();
            state.join_new().unwrap();
        }
        let anchor = plain.estimate()[1];
        assert!(close(plain.estimate()[2], anchor.compose(&step)));
        assert!(close(hinted.estimate()[1], anchor));
        assert!(close(hinted.estimate()[2], anchor.compose(&relative)));
        // the catch-up over, keyframes join dead-reckoned again
        hinted.clear_hints();
        hinted.replay(&keyframe(3), 0.0).unwrap();
        hinted.replay(&odometry(2, 3, step), 0.0).unwrap();
        hinted.join_new().unwrap();
        let k2 = hinted.estimate()[2];
        assert!(close(hinted.estimate()[3], k2.compose(&step)));
    }
}
