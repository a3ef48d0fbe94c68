//! [`LevenbergMarquardt`]: the damped polish on g2o's SE(2) and SE(3) costs.
//!
//! Each iteration solves `(H + λ D) δ = −g`, with `H = Σ Jᵀ Ω J`,
//! `g = Σ Jᵀ Ω e` and `D = diag(H)` (Marquardt's scaling), and accepts the
//! step only when χ² drops. The gain ratio `ρ = (χ² − χ²_new) / δᵀ(λDδ − g)`
//! steers λ (Nielsen's rule). Undamped Gauss–Newton can overshoot from a
//! linear initialiser (docs/design.md, "The polish and the cost"), hence
//! the damping.
//!
//! The pattern of `H` and its fill-reducing ordering (AMD on the pose graph,
//! each pose's `DOF` variables kept together) are computed once; each
//! iteration only refills values and refactorises. A step moves each pose
//! by [`LiePose::retract`]: additively in the plane, on the manifold in
//! space.

use super::lie::LiePose;
use super::params::LevenbergMarquardtParams;
use super::prior::Problem;
use super::structure::{gauge_first_blocks, HessianStructure};
use crate::geometry::Pose2;
use crate::graph::pose_ordering;
use crate::sparse::ordering::expand_blocks;
use crate::sparse::{FactorError, Ordering, SparseCholesky, UpperCsc};

/// The damping a rejected step raises λ to at least.
const MIN_LAMBDA: f64 = 1e-12;

/// One trial step.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Iteration {
    /// χ² after the step if accepted, else the unchanged χ².
    pub chi2: f64,
    /// The damping used.
    pub lambda: f64,
    /// Whether χ² dropped and the step was kept.
    pub accepted: bool,
}

/// What the polish did.
#[derive(Clone, Debug)]
pub struct LmReport<P = Pose2> {
    /// The final poses.
    pub poses: Vec<P>,
    /// χ² at the start.
    pub initial_chi2: f64,
    /// χ² at the end.
    pub final_chi2: f64,
    /// Every trial step, in order.
    pub iterations: Vec<Iteration>,
    /// True if a tolerance was met before the iteration cap.
    pub converged: bool,
}

/// Damped Gauss–Newton over the poses of a graph; pose 0 stays fixed.
pub struct LevenbergMarquardt<'a, P: LiePose = Pose2> {
    problem: Problem<'a, P>,
    structure: HessianStructure<P>,
    factor: SparseCholesky<f64>,
    hessian: UpperCsc<f64>,
    damped: UpperCsc<f64>,
    gradient: Vec<f64>,
    poses: Vec<P>,
    chi2: f64,
    lambda: f64,
    nu: f64,
    params: LevenbergMarquardtParams,
    iterations: Vec<Iteration>,
    initial_chi2: f64,
    converged: bool,
}

impl<'a, P: LiePose> LevenbergMarquardt<'a, P> {
    /// Prepares the polish of `problem` from `initial` (one pose per
    /// keyframe).
    pub fn new(
        problem: Problem<'a, P>,
        initial: Vec<P>,
        params: LevenbergMarquardtParams,
    ) -> Result<Self, FactorError> {
        let n = initial.len();
        let structure = HessianStructure::new(gauge_first_blocks(n), n.saturating_sub(1), problem.edges);
        let hessian = structure.pattern().clone();
        let poses = pose_ordering(initial.len(), problem.edges);
        let factor =
            SparseCholesky::analyze_supernodal(&hessian, &Ordering::Custom(expand_blocks(&poses, P::DOF)))?;
        let chi2 = problem.chi2(&initial);
        let mut lm = Self {
            problem,
            damped: hessian.clone(),
            gradient: vec![0.0; structure.dim()],
            structure,
            factor,
            hessian,
            poses: initial,
            chi2,
            lambda: params.initial_lambda,
            nu: 2.0,
            params,
            iterations: Vec::new(),
            initial_chi2: chi2,
            converged: false,
        };
        lm.linearize();
        Ok(lm)
    }

    /// Current χ².
    pub fn chi2(&self) -> f64 {
        self.chi2
    }

    /// Current poses.
    pub fn poses(&self) -> &[P] {
        &self.poses
    }

    /// True once a tolerance has been met.
    pub fn converged(&self) -> bool {
        self.converged
    }

    /// Refills `H` and `g` at the current poses.
    fn linearize(&mut self) {
        let p = &self.problem;
        let weights = p.weights(&self.poses);
        self.structure.assemble(
            p.edges,
            weights.as_deref(),
            p.priors,
            &self.poses,
            &mut self.hessian,
            &mut self.gradient,
        );
    }

    /// One trial step: solve the damped system, keep the step if χ² drops.
    pub fn iterate(&mut self) -> Result<Iteration, FactorError> {
        let diag = self.structure.diagonal();
        self.damped.values_mut().copy_from_slice(self.hessian.values());
        let max_diag = diag.iter().map(|&s| self.hessian.values()[s]).fold(0.0, f64::max);
        let mut d = Vec::with_capacity(diag.len());
        for &s in diag {
            let v = self.hessian.values()[s].max(1e-9 * max_diag).max(1e-12);
            d.push(v);
            self.damped.values_mut()[s] += self.lambda * v;
        }
        if let Err(e) = self.factor.factorize(&self.damped) {
            // Indefinite only through round-off: more damping cures it.
            if self.lambda > 1e12 {
                return Err(e);
            }
            self.reject();
            return Ok(self.record(self.chi2, false));
        }
        let rhs: Vec<f64> = self.gradient.iter().map(|g| -g).collect();
        let delta = self.factor.solve(&rhs);
        let candidate: Vec<P> = self
            .poses
            .iter()
            .enumerate()
            .map(|(k, p)| match k {
                0 => *p,
                _ => p.retract(&delta[P::DOF * (k - 1)..P::DOF * k]),
            })
            .collect();
        let new_chi2 = self.problem.chi2(&candidate);
        let predicted: f64 = (0..delta.len())
            .map(|i| delta[i] * (self.lambda * d[i] * delta[i] - self.gradient[i]))
            .sum();
        let max_step = delta.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if new_chi2.is_finite() && new_chi2 < self.chi2 {
            let rho = (self.chi2 - new_chi2) / predicted.max(f64::MIN_POSITIVE);
            let decrease = self.chi2 - new_chi2;
            self.converged = decrease < self.params.relative_error_tol * self.chi2
                || new_chi2 < self.params.absolute_error_tol
                || max_step < self.params.step_tol;
            self.poses = candidate;
            self.chi2 = new_chi2;
            self.lambda *= (1.0 - (2.0 * rho - 1.0).powi(3)).max(1.0 / 3.0);
            self.nu = 2.0;
            self.linearize();
            Ok(self.record(new_chi2, true))
        } else {
            self.converged = max_step < self.params.step_tol;
            self.reject();
            Ok(self.record(self.chi2, false))
        }
    }

    /// Raises the damping after a failed step (doubling the growth rate).
    fn reject(&mut self) {
        self.lambda = (self.lambda * self.nu).max(MIN_LAMBDA);
        self.nu *= 2.0;
    }

    fn record(&mut self, chi2: f64, accepted: bool) -> Iteration {
        let it = Iteration {
            chi2,
            lambda: self.lambda,
            accepted,
        };
        self.iterations.push(it);
        tracing::debug!(chi2, lambda = self.lambda, accepted, "LM iteration.");
        it
    }

    /// Iterates until converged, the iteration cap, or the problem's stop.
    pub fn optimize(mut self) -> Result<LmReport<P>, FactorError> {
        while !self.converged && self.iterations.len() < self.params.max_iterations && !self.problem.stopped()
        {
            self.iterate()?;
        }
        Ok(LmReport {
            initial_chi2: self.initial_chi2,
            final_chi2: self.chi2,
            converged: self.converged,
            iterations: self.iterations,
            poses: self.poses,
        })
    }
}

/// Polishes `initial` on `problem` to convergence.
pub fn polish<P: LiePose>(
    problem: Problem<'_, P>,
    initial: Vec<P>,
    params: LevenbergMarquardtParams,
) -> Result<LmReport<P>, FactorError> {
    LevenbergMarquardt::new(problem, initial, params)?.optimize()
}
