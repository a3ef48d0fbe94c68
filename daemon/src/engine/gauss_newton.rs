//! [`GaussNewton`]: the normal equations of the SE(2) cost linearised at a
//! fixed point, kept factorised as edges arrive (iSAM's scheme).
//!
//! Between re-solves every edge is linearised at `lin`, the poses of the
//! last polish (a new keyframe: where its first edge puts it). The system
//! `H δ = −g` with `H = Σ s Jᵀ Ω J`, `g = Σ s Jᵀ Ω e` then grows by a rank-3
//! update per edge, and the estimate is `lin + δ`: one Gauss–Newton step
//! from the polished map over everything seen since. A re-solve
//! relinearises by building a new one.
//!
//! The factor is of the augmented matrix `[H −g; −gᵀ χ²(lin)]`
//! ([`AugmentedCholesky`]): with `Ω = L Lᵀ`, an edge is the three vectors
//! `[Lᵀ J | −Lᵀ e]` (rows of `Lᵀ`), so its update carries its gradient and
//! cost, the forward solve rides along the update's walk, and the last
//! pivot is the χ² the linear model predicts.
//!
//! Updates wait in a batch until the solve (or until the batch is full) and
//! go in as one multiple-rank walk: a keyframe's odometry and loop closures
//! climb their own paths of the elimination tree and sweep the part they
//! share once. A downdate goes in at once, so that its failure surfaces
//! where it is asked for.

use crate::geometry::Pose2;
use crate::graph::{Edge, PoseGraph};
use crate::nonlinear::se2::jacobian;
use crate::nonlinear::structure::{HessianStructure, NONE};
use crate::nonlinear::{PositionPrior, Problem};
use crate::sparse::dynamic::{AugmentedCholesky, DynamicLdlt, Marginal, UpdateError, MAX_RANK};
use crate::sparse::FactorError;

/// The linearised system and the estimate it gives.
#[derive(Clone, Debug)]
pub struct GaussNewton {
    /// First of the three columns of each keyframe, or `NONE`.
    column: Vec<u32>,
    /// The keyframe owning each column.
    keyframe_of: Vec<u32>,
    chol: AugmentedCholesky<f64>,
    lin: Vec<Pose2>,
    estimate: Vec<Pose2>,
    changed: Vec<usize>,
    stamp: Vec<u32>,
    epoch: u32,
    /// Update vectors (with their tails) waiting for one walk.
    batch: Vec<(Vec<(usize, f64)>, f64)>,
    marginal: Marginal,
}

impl GaussNewton {
    /// A system holding only the gauge keyframe at `gauge`.
    pub fn new(gauge: Pose2) -> Self {
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
        }
    }

    /// A fresh factorisation at `lin` (one pose per keyframe of `graph`):
    /// keyframes `order` (gauge excluded) in elimination order, `edges` with
    /// their scales, and position `priors` (GPS).
    pub fn build(
        graph: &PoseGraph,
        edges: &[(usize, f64)],
        priors: &[PositionPrior],
        lin: Vec<Pose2>,
        order: &[usize],
    ) -> Result<Self, FactorError> {
        let n = graph.len();
        let mut block_of = vec![NONE; n];
        for (b, &k) in order.iter().enumerate() {
            block_of[k] = b as u32;
        }
        let scaled: Vec<Edge> = edges
            .iter()
            .map(|&(e, s)| {
                let mut edge = graph.edges()[e];
                edge.information = edge.information.scaled(s);
                edge
            })
            .collect();
        let structure = HessianStructure::new(block_of.clone(), order.len(), &scaled);
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
            .map(|&b| if b == NONE { NONE } else { 3 * b })
            .collect();
        let keyframe_of = order.iter().flat_map(|&k| [k as u32; 3]).collect();
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
        };
        for k in order {
            gn.refresh_estimate(*k);
        }
        Ok(gn)
    }

    /// Keyframe `k` joins at `guess`. Keyframes that have not joined keep
    /// their slot with no columns.
    pub fn add_keyframe(&mut self, k: usize, guess: Pose2) {
        if self.column.len() <= k {
            self.column.resize(k + 1, NONE);
            self.lin.resize(k + 1, Pose2::IDENTITY);
            self.estimate.resize(k + 1, Pose2::IDENTITY);
            self.stamp.resize(k + 1, 0);
        }
        self.lin[k] = guess;
        self.estimate[k] = guess;
        if k == 0 {
            return;
        }
        let c = self.chol.append();
        self.chol.append();
        self.chol.append();
        self.column[k] = c as u32;
        self.keyframe_of.extend([k as u32; 3]);
    }

    /// Adds `delta` times the edge's terms, linearised at `lin`. An update
    /// (`delta > 0`) waits for the next solve; a downdate is applied now.
    pub fn apply_edge(&mut self, edge: &Edge, delta: f64) -> Result<(), UpdateError> {
        let (j, e) = jacobian(edge, &self.lin[edge.from], &self.lin[edge.to]);
        let cols: [Option<usize>; 6] = std::array::from_fn(|a| {
            let k = if a < 3 { edge.from } else { edge.to };
            let c = self.column[k];
            (c != NONE).then(|| c as usize + a % 3)
        });
        // Ω = L Lᵀ, so [Jᵀ; −eᵀ] Ω [J −e] = Σ_r [Lᵀ J | −Lᵀ e]_rᵀ [Lᵀ J | −Lᵀ e]_r
        let lt = sqrt_information(&edge.information.matrix()).transpose();
        let (rows, tails) = (lt * j, -(lt * e));
        let root = delta.abs().sqrt();
        let vectors = (0..3).map(|r| {
            let w = cols
                .iter()
                .enumerate()
                .filter_map(|(a, c)| c.map(|c| (c, rows[(r, a)] * root)))
                .collect();
            (w, tails[r] * root)
        });
        self.apply(vectors, delta.signum())
    }

    /// Adds a position prior linearised at `lin`: error `e = p_k − target`,
    /// Jacobian `[I₂ 0]`, so a rank-2 update on the keyframe's `x, y`
    /// columns. On the gauge it only adds to the cost.
    pub fn apply_prior(&mut self, prior: &PositionPrior) -> Result<(), UpdateError> {
        let p = self.lin[prior.keyframe].position() - prior.target;
        let e = nalgebra::Vector2::new(p.re, p.im);
        let omega = prior.information;
        let c = self.column[prior.keyframe];
        if c == NONE {
            self.chol.add_cost((e.transpose() * omega * e)[0]);
            return Ok(());
        }
        let c = c as usize;
        // Ω = L Lᵀ: rows of Lᵀ, tails −Lᵀ e
        let lt = sqrt_information(&omega).transpose();
        let tails = -(lt * e);
        let vectors = (0..2).map(|r| (vec![(c, lt[(r, 0)]), (c + 1, lt[(r, 1)])], tails[r]));
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
        edge: &Edge,
        e: &[f64; 3],
        variance_factor: f64,
    ) -> Result<Option<f64>, UpdateError> {
        self.flush()?;
        let (j, _) = jacobian(edge, &self.lin[edge.from], &self.lin[edge.to]);
        let mut v: [Vec<(usize, f64)>; 3] = Default::default();
        for (a, k) in [edge.from, edge.from, edge.from, edge.to, edge.to, edge.to]
            .into_iter()
            .enumerate()
        {
            let c = self.column[k];
            if c == NONE {
                // the gauge is fixed; any other keyframe must be in
                if k != 0 {
                    return Ok(None);
                }
                continue;
            }
            for (r, w) in v.iter_mut().enumerate() {
                w.push((c as usize + a % 3, j[(r, a)]));
            }
        }
        let Some(jsj) = self.marginal.form(self.chol.factor(), [&v[0], &v[1], &v[2]]) else {
            return Ok(None);
        };
        let s = edge
            .information
            .matrix()
            .try_inverse()
            .map(|cov| cov + variance_factor * jsj);
        let e = nalgebra::Vector3::from(*e);
        Ok(s.and_then(|s| s.cholesky()).map(|c| e.dot(&c.solve(&e))))
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
        let x = &self.chol.x()[c as usize..c as usize + 3];
        let l = self.lin[k];
        self.estimate[k] = Pose2::new(l.x + x[0], l.y + x[1], l.theta + x[2]);
    }

    /// The χ² the linear model predicts at its solution:
    /// `χ²(lin) + 2gᵀδ + δᵀHδ = χ²(lin) − gᵀH⁻¹g`, the augmented factor's
    /// last pivot. Far below the true χ² of the estimate means the
    /// linearisation failed.
    pub fn predicted_chi2(&self) -> f64 {
        self.chol.residual()
    }

    /// The linearisation point `lin` of every keyframe slot.
    pub fn linearisation(&self) -> &[Pose2] {
        &self.lin
    }

    /// The current estimate of every keyframe slot.
    pub fn estimate(&self) -> &[Pose2] {
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
}

/// A square root `L` of an information matrix, `Ω = L Lᵀ` (Cholesky; the
/// square roots of the diagonal for one that is not positive definite,
/// which the graph refuses at its door).
fn sqrt_information<const N: usize>(omega: &nalgebra::SMatrix<f64, N, N>) -> nalgebra::SMatrix<f64, N, N>
where
    nalgebra::Const<N>: nalgebra::DimMin<nalgebra::Const<N>, Output = nalgebra::Const<N>>,
{
    omega
        .cholesky()
        .map(|c| c.l())
        .unwrap_or_else(|| nalgebra::SMatrix::from_diagonal(&omega.diagonal().map(|v| v.max(0.0).sqrt())))
}
