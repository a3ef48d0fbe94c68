//! [`GaussNewton`]: the normal equations of the SE(2) or SE(3) cost
//! linearised at a fixed point, kept factorised as edges arrive (iSAM's
//! scheme).
//!
//! Between re-solves every edge is linearised at `lin`, the poses of the
//! last polish (a new keyframe: where its first edge puts it). The system
//! `H δ = −g` with `H = Σ s Jᵀ Ω J`, `g = Σ s Jᵀ Ω e` then grows by a
//! rank-`DOF` update per edge, and the estimate is `lin + δ`: one Gauss–Newton step
//! from the polished map over everything seen since. A re-solve
//! relinearises by building a new one.
//!
//! The factor is of the augmented matrix `[H −g; −gᵀ χ²(lin)]`
//! ([`AugmentedCholesky`]): with `Ω = L Lᵀ`, an edge is the `DOF` vectors
//! `[Lᵀ J | −Lᵀ e]` (rows of `Lᵀ`), so its update carries its gradient and
//! cost, the forward solve rides along the update's walk, and the last
//! pivot is the χ² the linear model predicts.
//!
//! Updates wait in a batch until the solve (or until the batch is full) and
//! go in as one multiple-rank walk: a keyframe's odometry and loop closures
//! climb their own paths of the elimination tree and sweep the part they
//! share once. A downdate goes in at once, so that its failure surfaces
//! where it is asked for.

use super::pose::EnginePose;
use crate::geometry::Pose2;
use crate::graph::{Edge, InformationMatrix, PoseGraph};
use crate::nonlinear::structure::{HessianStructure, NONE};
use crate::nonlinear::{PositionPrior, Problem};
use crate::sparse::dynamic::{AugmentedCholesky, DynamicLdlt, Marginal, UpdateError, MAX_RANK};
use crate::sparse::FactorError;
use nalgebra::DMatrix;

/// The linearised system and the estimate it gives.
#[derive(Clone, Debug)]
pub struct GaussNewton<P: EnginePose = Pose2> {
    /// First of the `DOF` columns of each keyframe, or `NONE`.
    column: Vec<u32>,
    /// The keyframe owning each column.
    keyframe_of: Vec<u32>,
    chol: AugmentedCholesky<f64>,
    lin: Vec<P>,
    estimate: Vec<P>,
    changed: Vec<usize>,
    stamp: Vec<u32>,
    epoch: u32,
    /// Update vectors (with their tails) waiting for one walk.
    batch: Vec<(Vec<(usize, f64)>, f64)>,
    marginal: Marginal,
    /// Scratch for [`Self::covariance`]: two poses of `DOF` ≤ 6.
    pose_marginal: Marginal<12>,
}

impl<P: EnginePose> GaussNewton<P> {
    /// A system holding only the gauge keyframe at `gauge`.
    pub fn new(gauge: P) -> Self {
        Self {
            column: vec![NONE],
            keyframe_of: Vec::new(),
            chol: AugmentedCholesky::empty(),
            lin: vec![gauge],
            estimate: vec![gauge],
            changed: Vec::new(),
            stamp: vec![0],
            epoch: 0,
            batch: Vec::new(),
            marginal: Marginal::default(),
            pose_marginal: Marginal::default(),
        }
    }

    /// A fresh factorisation at `lin` (one pose per keyframe of `graph`):
    /// keyframes `order` (gauge excluded) in elimination order, `edges` with
    /// their scales, and position `priors` (GPS).
    pub fn build(
        graph: &PoseGraph<P>,
        edges: &[(usize, f64)],
        priors: &[PositionPrior<P>],
        lin: Vec<P>,
        order: &[usize],
    ) -> Result<Self, FactorError> {
        let n = graph.len();
        let mut block_of = vec![NONE; n];
        for (b, &k) in order.iter().enumerate() {
            block_of[k] = b as u32;
        }
        let scaled: Vec<Edge<P>> = edges
            .iter()
            .map(|&(e, s)| {
                let mut edge = graph.edges()[e];
                edge.information = edge.information.scaled(s);
                edge
            })
            .collect();
        let structure = HessianStructure::<P>::new(block_of.clone(), order.len(), &scaled);
        let mut h = structure.pattern().clone();
        let mut g = vec![0.0; structure.dim()];
        structure.assemble(&scaled, None, priors, &lin, &mut h, &mut g);
        let identity: Vec<usize> = (0..h.n()).collect();
        let factor = DynamicLdlt::from_matrix(&h, &identity)?;
        let b: Vec<f64> = g.iter().map(|v| -v).collect();
        let lin_chi2 = Problem::new(&scaled, priors).chi2(&lin);
        let chol = AugmentedCholesky::new(factor, &b, lin_chi2);
        let column = block_of
            .iter()
            .map(|&b| if b == NONE { NONE } else { P::DOF as u32 * b })
            .collect();
        let keyframe_of = order
            .iter()
            .flat_map(|&k| std::iter::repeat_n(k as u32, P::DOF))
            .collect();
        let mut gn = Self {
            column,
            keyframe_of,
            chol,
            estimate: lin.clone(),
            lin,
            changed: Vec::new(),
            stamp: vec![0; n],
            epoch: 0,
            batch: Vec::new(),
            marginal: Marginal::default(),
            pose_marginal: Marginal::default(),
        };
        for k in order {
            gn.refresh_estimate(*k);
        }
        Ok(gn)
    }

    /// Keyframe `k` joins at `guess`. Keyframes that have not joined keep
    /// their slot with no columns.
    pub fn add_keyframe(&mut self, k: usize, guess: P) {
        if self.column.len() <= k {
            self.column.resize(k + 1, NONE);
            self.lin.resize(k + 1, P::IDENTITY);
            self.estimate.resize(k + 1, P::IDENTITY);
            self.stamp.resize(k + 1, 0);
        }
        self.lin[k] = guess;
        self.estimate[k] = guess;
        if k == 0 {
            return;
        }
        let c = self.chol.append();
        for _ in 1..P::DOF {
            self.chol.append();
        }
        self.column[k] = c as u32;
        self.keyframe_of.extend(std::iter::repeat_n(k as u32, P::DOF));
    }

    /// Adds `delta` times the edge's terms, linearised at `lin`. An update
    /// (`delta > 0`) waits for the next solve; a downdate is applied now.
    pub fn apply_edge(&mut self, edge: &Edge<P>, delta: f64) -> Result<(), UpdateError> {
        let dof = P::DOF;
        let (ci, cj) = (self.column[edge.from], self.column[edge.to]);
        let col = |a: usize| {
            let c = if a < dof { ci } else { cj };
            (c != NONE).then(|| c as usize + a % dof)
        };
        // Ω = L Lᵀ, so [Jᵀ; −eᵀ] Ω [J −e] = Σ_r [Lᵀ J | −Lᵀ e]_rᵀ [Lᵀ J | −Lᵀ e]_r
        let (rows, tails) = P::whitened(edge, &self.lin[edge.from], &self.lin[edge.to]);
        let root = delta.abs().sqrt();
        let vectors = (0..dof).map(|r| {
            let w = (0..2 * dof)
                .filter_map(|a| col(a).map(|c| (c, rows[(r, a)] * root)))
                .collect();
            (w, tails[r] * root)
        });
        self.apply(vectors, delta.signum())
    }

    /// Adds a position prior linearised at `lin` (error `e = p_k − target`):
    /// a low-rank update on the keyframe's columns
    /// ([`EnginePose::prior_rows`]). On the gauge it only adds to the cost.
    pub fn apply_prior(&mut self, prior: &PositionPrior<P>) -> Result<(), UpdateError> {
        let pose = self.lin[prior.keyframe];
        let c = self.column[prior.keyframe];
        if c == NONE {
            self.chol
                .add_cost(pose.prior_chi2(&prior.target, &prior.information));
            return Ok(());
        }
        let c = c as usize;
        let rows = pose.prior_rows(prior);
        let vectors = rows.into_iter().map(|(w, tail)| {
            let w: Vec<(usize, f64)> = w.into_iter().map(|(a, v)| (c + a, v)).collect();
            (w, tail)
        });
        self.apply(vectors, 1.0)
    }

    /// `eᵀ S⁻¹ e` for an edge whose error at the estimate is `e`, with the
    /// innovation covariance `S = Ω⁻¹ + σ² J Σ Jᵀ`: `Σ = H⁻¹` is the
    /// estimate's covariance in this linearisation, `J` the edge's
    /// Jacobian and `σ²` = `variance_factor` the scale the graph's weights
    /// are off by, so `S` says how well the map knows the relative pose the
    /// edge measures (iSAM's data-association test). Applies the waiting
    /// updates first. `None` when a keyframe has no columns or no weight.
    pub fn innovation_chi2(
        &mut self,
        edge: &Edge<P>,
        e: &P::Error,
        variance_factor: f64,
    ) -> Result<Option<f64>, UpdateError> {
        self.flush()?;
        let dof = P::DOF;
        let j = P::jacobian(edge, &self.lin[edge.from], &self.lin[edge.to]);
        let mut v: Vec<Vec<(usize, f64)>> = vec![Vec::new(); dof];
        for a in 0..2 * dof {
            let k = if a < dof { edge.from } else { edge.to };
            let c = self.column[k];
            if c == NONE {
                // the gauge is fixed; any other keyframe must be in
                if k != 0 {
                    return Ok(None);
                }
                continue;
            }
            for (r, w) in v.iter_mut().enumerate() {
                w.push((c as usize + a % dof, j[(r, a)]));
            }
        }
        let slices: Vec<&[(usize, f64)]> = v.iter().map(|w| &w[..]).collect();
        let Some(jsj) = self.marginal.form(self.chol.factor(), &slices) else {
            return Ok(None);
        };
        Ok(P::innovation_chi2(&edge.information, e, &jsj, variance_factor))
    }

    /// The joint covariance `M Σ Mᵀ` of one or two `keyframes`, `DOF`
    /// rows each in their order: `Σ = H⁻¹` restricted to their columns
    /// (`Vᵀ H⁻¹ V` with `V` the columns' unit vectors, read off the
    /// elimination-tree paths by [`Marginal`], no inverse formed), in the
    /// body-frame tangent `M` ([`LiePose::body_tangent`](crate::nonlinear::LiePose::body_tangent))
    /// of the estimate, the pose it is published with (in the plane `δ` is
    /// additive, so `Σ` is the estimate's covariance; in space `M` does not
    /// depend on the pose and the frame is `lin`'s, a Gauss–Newton step
    /// away). The gauge has zero rows (it is held fixed). Applies the
    /// waiting updates first. `None` when a keyframe has no columns or no
    /// weight (an infinite variance).
    pub fn covariance(&mut self, keyframes: &[usize]) -> Result<Option<DMatrix<f64>>, UpdateError> {
        assert!(keyframes.len() <= 2, "one or two keyframes");
        self.flush()?;
        let dof = P::DOF;
        let mut vectors = Vec::new();
        let mut slot = Vec::new();
        for (b, &k) in keyframes.iter().enumerate() {
            match self.column.get(k) {
                Some(&c) if c != NONE => {
                    for a in 0..dof {
                        vectors.push([(c as usize + a, 1.0)]);
                        slot.push(b * dof + a);
                    }
                }
                _ if k == 0 => {}
                _ => return Ok(None),
            }
        }
        let m = dof * keyframes.len();
        let mut sigma = DMatrix::zeros(m, m);
        if !vectors.is_empty() {
            let slices: Vec<&[(usize, f64)]> = vectors.iter().map(|v| &v[..]).collect();
            let factor = self.chol.factor();
            // one pose fits the narrower scratch, whose rows are half as long
            let form = if slices.len() <= 6 {
                self.marginal
                    .form(factor, &slices)
                    .map(|f| f.resize_generic(nalgebra::Const::<12>, nalgebra::Const::<12>, 0.0))
            } else {
                self.pose_marginal.form(factor, &slices)
            };
            let Some(form) = form else {
                return Ok(None);
            };
            for (r, &a) in slot.iter().enumerate() {
                for (s, &b) in slot.iter().enumerate() {
                    sigma[(a, b)] = form[(r, s)];
                }
            }
        }
        let mut tangent = DMatrix::zeros(m, m);
        for (b, &k) in keyframes.iter().enumerate() {
            let t = self.estimate[k].body_tangent();
            for r in 0..dof {
                for s in 0..dof {
                    tangent[(b * dof + r, b * dof + s)] = t[(r, s)];
                }
            }
        }
        Ok(Some(&tangent * sigma * tangent.transpose()))
    }

    /// Batches update vectors (`sigma > 0`), or applies a downdate now
    /// after the batch.
    fn apply(
        &mut self,
        vectors: impl ExactSizeIterator<Item = (Vec<(usize, f64)>, f64)>,
        sigma: f64,
    ) -> Result<(), UpdateError> {
        if sigma == 0.0 {
            return Ok(());
        }
        if sigma < 0.0 || self.batch.len() + vectors.len() > MAX_RANK {
            self.flush()?;
        }
        self.batch.extend(vectors);
        if sigma < 0.0 {
            return self.walk(-1.0);
        }
        Ok(())
    }

    /// Applies the waiting updates in one walk.
    pub fn flush(&mut self) -> Result<(), UpdateError> {
        if self.batch.is_empty() {
            return Ok(());
        }
        self.walk(1.0)
    }

    fn walk(&mut self, sigma: f64) -> Result<(), UpdateError> {
        let ws: Vec<&[(usize, f64)]> = self.batch.iter().map(|(w, _)| &w[..]).collect();
        let tails: Vec<f64> = self.batch.iter().map(|&(_, t)| t).collect();
        let result = self.chol.rank_k(&ws, &tails, sigma);
        self.batch.clear();
        result
    }

    /// Applies the waiting updates and solves for δ; columns whose change
    /// stays within `threshold` do not pass it to their subtrees. Returns
    /// the keyframes whose estimate moved.
    pub fn solve(&mut self, threshold: f64) -> Result<&[usize], UpdateError> {
        self.flush()?;
        self.epoch = self.epoch.wrapping_add(1);
        self.changed.clear();
        for &c in self.chol.solve(threshold) {
            let k = self.keyframe_of[c] as usize;
            if self.stamp[k] != self.epoch {
                self.stamp[k] = self.epoch;
                self.changed.push(k);
            }
        }
        for i in 0..self.changed.len() {
            self.refresh_estimate(self.changed[i]);
        }
        Ok(&self.changed)
    }

    fn refresh_estimate(&mut self, k: usize) {
        let c = self.column[k];
        if c == NONE {
            return;
        }
        let x = &self.chol.x()[c as usize..c as usize + P::DOF];
        self.estimate[k] = self.lin[k].retract(x);
    }

    /// The χ² the linear model predicts at its solution:
    /// `χ²(lin) + 2gᵀδ + δᵀHδ = χ²(lin) − gᵀH⁻¹g`, the augmented factor's
    /// last pivot. Far below the true χ² of the estimate means the
    /// linearisation failed.
    pub fn predicted_chi2(&self) -> f64 {
        self.chol.residual()
    }

    /// The linearisation point `lin` of every keyframe slot.
    pub fn linearisation(&self) -> &[P] {
        &self.lin
    }

    /// The current estimate of every keyframe slot.
    pub fn estimate(&self) -> &[P] {
        &self.estimate
    }

    /// The factor.
    pub fn factor(&self) -> &crate::sparse::dynamic::DynamicLdlt<f64> {
        self.chol.factor()
    }

    /// What the incremental solves have cost so far.
    pub fn solve_stats(&self) -> crate::sparse::dynamic::SolveStats {
        self.chol.solve_stats()
    }

    /// Stored entries of the factor.
    pub fn factor_nnz(&self) -> usize {
        self.chol.factor().nnz()
    }

    /// The factor's columns (scalar variables).
    pub fn factor_columns(&self) -> usize {
        self.chol.factor().len()
    }
}
