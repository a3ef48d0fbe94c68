//! [`EnginePose`]: what the incremental engine needs of a pose type beyond
//! the polish's [`LiePose`], so that one engine serves SE(2) and SE(3).
//!
//! Each item is the same math written for one dimension: the whitened
//! rows of an edge, its innovation test, the linear initialiser a re-solve
//! starts from. What only the plane has so far (the cycle test and PCM,
//! [`OutlierConfig::planar_only`](crate::outliers::OutlierConfig::planar_only))
//! is not asked of the pose type: [`Engine::create`](super::Engine::create)
//! turns it off with a warning in 3-D.

use crate::geometry::{Pose2, Turns};
use crate::gps::GpsPose;
use crate::graph::{edge_error_turned, Edge, Pose3, PoseGraph};
use crate::linear::{chordal, two_stage};
use crate::nonlinear::{se2, se3, LiePose, PositionPrior};
use nalgebra::{Matrix3, Matrix6, SMatrix, Vector2, Vector3, Vector6};
use std::ops::Index;

/// A pose type the engine can run on.
pub trait EnginePose: LiePose + GpsPose + 'static {
    /// `Lᵀ J`, `DOF × 2·DOF`, with `Ω = L Lᵀ`.
    type Rows: Index<(usize, usize), Output = f64>;
    /// `−Lᵀ e`, `DOF` long.
    type Tails: Index<usize, Output = f64>;
    /// `J`, `DOF × 2·DOF`.
    type Jacobian: Index<(usize, usize), Output = f64>;

    /// The edge's whitened rows and tails at `xi`, `xj`: its terms in the
    /// normal equations are `Σ_r [rows_r | tail_r]ᵀ [rows_r | tail_r]`.
    fn whitened(edge: &Edge<Self>, xi: &Self, xj: &Self) -> (Self::Rows, Self::Tails);

    /// The edge's Jacobian at `xi`, `xj`.
    fn jacobian(edge: &Edge<Self>, xi: &Self, xj: &Self) -> Self::Jacobian;

    /// The whitened rows of a position prior at this pose, over the pose's
    /// own `DOF` variables (local column, value), with their tails.
    fn prior_rows(&self, prior: &PositionPrior<Self>) -> Vec<(Vec<(usize, f64)>, f64)>;

    /// `eᵀ S⁻¹ e` with `S = Ω⁻¹ + σ² J Σ Jᵀ`, given `J Σ Jᵀ` in the top-left
    /// `DOF` square of `jsj`; `None` when `S` is not positive definite.
    fn innovation_chi2(
        information: &Self::Information,
        e: &Self::Error,
        jsj: &Matrix6<f64>,
        variance_factor: f64,
    ) -> Option<f64>;

    /// `eᵀ Ω e` of edge `e` at `estimate`, with whatever the caches keep.
    fn cached_chi2(
        turns: &mut Turns,
        measured: &mut Turns,
        e: usize,
        edge: &Edge<Self>,
        estimate: &[Self],
    ) -> f64;

    /// The linear initialiser's solution of `graph` (gauge at the
    /// identity): a re-solve's start that does not depend on the estimate.
    fn linear_solution(graph: &PoseGraph<Self>) -> Option<Vec<Self>>;
}

/// A square root `L` of an information matrix, `Ω = L Lᵀ` (Cholesky; the
/// square roots of the diagonal for one that is not positive definite,
/// which the graph refuses at its door).
fn sqrt_information<const N: usize>(omega: &SMatrix<f64, N, N>) -> SMatrix<f64, N, N>
where
    nalgebra::Const<N>: nalgebra::DimMin<nalgebra::Const<N>, Output = nalgebra::Const<N>>,
{
    omega
        .cholesky()
        .map(|c| c.l())
        .unwrap_or_else(|| SMatrix::from_diagonal(&omega.diagonal().map(|v| v.max(0.0).sqrt())))
}

impl EnginePose for Pose2 {
    type Rows = SMatrix<f64, 3, 6>;
    type Tails = Vector3<f64>;
    type Jacobian = SMatrix<f64, 3, 6>;

    fn whitened(edge: &Edge, xi: &Pose2, xj: &Pose2) -> (Self::Rows, Vector3<f64>) {
        let (j, e) = se2::jacobian(edge, xi, xj);
        let lt = sqrt_information(&edge.information.matrix()).transpose();
        (lt * j, -(lt * e))
    }

    fn jacobian(edge: &Edge, xi: &Pose2, xj: &Pose2) -> Self::Jacobian {
        se2::jacobian(edge, xi, xj).0
    }

    /// `e = p − target`, `J = [I₂ 0]`: two rows on `x, y`.
    fn prior_rows(&self, prior: &PositionPrior) -> Vec<(Vec<(usize, f64)>, f64)> {
        let p = self.position() - prior.target;
        let e = Vector2::new(p.re, p.im);
        let lt = sqrt_information(&prior.information).transpose();
        let tails = -(lt * e);
        (0..2)
            .map(|r| (vec![(0, lt[(r, 0)]), (1, lt[(r, 1)])], tails[r]))
            .collect()
    }

    fn innovation_chi2(
        information: &super::super::graph::Information,
        e: &[f64; 3],
        jsj: &Matrix6<f64>,
        variance_factor: f64,
    ) -> Option<f64> {
        let jsj: Matrix3<f64> = jsj.fixed_view::<3, 3>(0, 0).into_owned();
        let s = information
            .matrix()
            .try_inverse()
            .map(|cov| cov + variance_factor * jsj);
        let e = Vector3::from(*e);
        s.and_then(|s| s.cholesky()).map(|c| e.dot(&c.solve(&e)))
    }

    /// The rotations of the keyframe and of the measurement from the
    /// caches: the sines and cosines dominate the bookkeeping otherwise.
    fn cached_chi2(
        turns: &mut Turns,
        measured: &mut Turns,
        e: usize,
        edge: &Edge,
        estimate: &[Pose2],
    ) -> f64 {
        let (xi, xj) = (&estimate[edge.from], &estimate[edge.to]);
        let turn_i = turns.get(edge.from, xi.theta);
        let turn_m = measured.get(e, edge.measurement.theta);
        edge.information
            .mahalanobis(&edge_error_turned(edge, xi, turn_i, xj, turn_m))
    }

    fn linear_solution(graph: &PoseGraph) -> Option<Vec<Pose2>> {
        two_stage::solve(graph).ok()
    }
}

impl EnginePose for Pose3 {
    type Rows = SMatrix<f64, 6, 12>;
    type Tails = Vector6<f64>;
    type Jacobian = SMatrix<f64, 6, 12>;

    fn whitened(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> (Self::Rows, Vector6<f64>) {
        let (j, e) = se3::jacobian(edge, xi, xj);
        let lt = sqrt_information(edge.information.matrix()).transpose();
        (lt * j, -(lt * e))
    }

    fn jacobian(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> Self::Jacobian {
        se3::jacobian(edge, xi, xj).0
    }

    /// `e = p − target`, `J = [R 0]` on `(u, v)`: three rows on `u`. Ω
    /// may be singular (a fix that leaves the height free): `L = V √Λ`
    /// from its eigen-decomposition, a zero row for a free direction.
    fn prior_rows(&self, prior: &PositionPrior<Pose3>) -> Vec<(Vec<(usize, f64)>, f64)> {
        let e = self.translation - prior.target;
        let eigen = prior.information.symmetric_eigen();
        let root = eigen.eigenvalues.map(|v| v.max(0.0).sqrt());
        let lt = (eigen.eigenvectors * Matrix3::from_diagonal(&root)).transpose();
        let rows = lt * self.rotation.to_rotation_matrix().into_inner();
        let tails = -(lt * e);
        (0..3)
            .map(|r| ((0..3).map(|c| (c, rows[(r, c)])).collect(), tails[r]))
            .collect()
    }

    fn innovation_chi2(
        information: &crate::graph::Information6,
        e: &[f64; 6],
        jsj: &Matrix6<f64>,
        variance_factor: f64,
    ) -> Option<f64> {
        let s = information.covariance() + variance_factor * jsj;
        let e = Vector6::from(*e);
        s.cholesky().map(|c| e.dot(&c.solve(&e)))
    }

    fn cached_chi2(_: &mut Turns, _: &mut Turns, _: usize, edge: &Edge<Pose3>, estimate: &[Pose3]) -> f64 {
        crate::graph::edge_chi2(edge, estimate)
    }

    fn linear_solution(graph: &PoseGraph<Pose3>) -> Option<Vec<Pose3>> {
        chordal::solve(graph).ok()
    }
}
