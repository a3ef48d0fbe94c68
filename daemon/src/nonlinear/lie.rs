//! [`LiePose`]: what the polish needs of a pose type, so that one
//! Levenberg–Marquardt and one Hessian layout serve SE(2) and SE(3).
//!
//! A pose owns `DOF` variables, a local perturbation `δ` around it: the
//! additive `(x, y, θ)` in the plane, `X ⊞ δ = X · (R(q(v)), u)` in space (see
//! [`super::se3`]). Each edge contributes the `2·DOF`-square block
//! `Jᵀ Ω J` and the gradient `Jᵀ Ω e` over the variables of its two poses;
//! a position prior the `DOF`-square block of one pose.

use super::{se2, se3};
use crate::geometry::Pose2;
use crate::graph::{Edge, EdgeCost, Pose3};
use crate::robust::Kernel;
use faer::c64;
use nalgebra::{Matrix2, Matrix3, Matrix6, SMatrix, SVector, Vector2, Vector3, Vector6};
use std::ops::{Index, MulAssign};

/// A pose type the polish can linearise and step.
pub trait LiePose: EdgeCost {
    /// `Jᵀ Ω J` of one edge, `2·DOF` square (pose `i` first).
    type EdgeHessian: Index<(usize, usize), Output = f64> + MulAssign<f64>;
    /// `Jᵀ Ω e` of one edge, `2·DOF` long.
    type EdgeGradient: Index<usize, Output = f64> + MulAssign<f64>;
    /// `DOF` square, over one pose.
    type PoseHessian: Index<(usize, usize), Output = f64>;
    /// `DOF` long, over one pose.
    type PoseGradient: Index<usize, Output = f64>;
    /// A position in the map frame.
    type Position: Copy + std::fmt::Debug + PartialEq + Send + Sync;
    /// The information of a position.
    type PositionInformation: Copy + std::fmt::Debug + PartialEq + Send + Sync;

    /// `(Jᵀ Ω J, Jᵀ Ω e)` of `edge` at `xi`, `xj`.
    fn edge_system(edge: &Edge<Self>, xi: &Self, xj: &Self) -> (Self::EdgeHessian, Self::EdgeGradient);

    /// `self ⊞ δ`, with `delta` of length `DOF`.
    fn retract(&self, delta: &[f64]) -> Self;

    /// `M` with `ξ = M δ` to first order, where `self ⊞ δ = self · Exp(ξ)`:
    /// `ξ` is the translation in the pose's own frame, then the rotation
    /// (rad; a rotation vector in space): GTSAM's tangent, though its Pose3
    /// puts the rotation first. A covariance
    /// `Σ` over `δ` is `M Σ Mᵀ` over `ξ`.
    fn body_tangent(&self) -> Self::PoseHessian;

    /// `(p − target)ᵀ Ω (p − target)` of the pose's position `p`.
    fn prior_chi2(&self, target: &Self::Position, information: &Self::PositionInformation) -> f64;

    /// `(Jᵀ Ω J, Jᵀ Ω e)` of the prior on the pose's position.
    fn prior_system(
        &self,
        target: &Self::Position,
        information: &Self::PositionInformation,
    ) -> (Self::PoseHessian, Self::PoseGradient);

    /// Paper B's `χ′ |Λ|`: the squared Euclidean error of `edge` times the
    /// determinant of its covariance (the adaptive switch's scale).
    fn asc_scale(edge: &Edge<Self>, xi: &Self, xj: &Self) -> f64;

    /// `kernel`'s switch of `edge` at poses `xi`, `xj`.
    fn kernel_switch(kernel: &Kernel, edge: &Edge<Self>, xi: &Self, xj: &Self) -> f64 {
        let chi2 = Self::mahalanobis(&edge.information, &Self::edge_error(edge, xi, xj));
        kernel.switch(chi2, || Self::asc_scale(edge, xi, xj))
    }

    /// `kernel`'s robust cost of `edge` at poses `xi`, `xj`.
    fn kernel_cost(kernel: &Kernel, edge: &Edge<Self>, xi: &Self, xj: &Self) -> f64 {
        let chi2 = Self::mahalanobis(&edge.information, &Self::edge_error(edge, xi, xj));
        kernel.cost(chi2, || Self::asc_scale(edge, xi, xj))
    }
}

impl LiePose for Pose2 {
    type EdgeHessian = Matrix6<f64>;
    type EdgeGradient = Vector6<f64>;
    type PoseHessian = Matrix3<f64>;
    type PoseGradient = Vector3<f64>;
    type Position = c64;
    type PositionInformation = Matrix2<f64>;

    fn edge_system(edge: &Edge, xi: &Pose2, xj: &Pose2) -> (Matrix6<f64>, Vector6<f64>) {
        se2::local_system(edge, xi, xj)
    }

    fn retract(&self, d: &[f64]) -> Pose2 {
        Pose2::new(self.x + d[0], self.y + d[1], self.theta + d[2])
    }

    /// `δ` moves the position in the map frame: `ξ_t = Rᵀ δ_t`, `ξ_θ = δ_θ`.
    fn body_tangent(&self) -> Matrix3<f64> {
        let (s, c) = self.theta.sin_cos();
        Matrix3::new(c, s, 0.0, -s, c, 0.0, 0.0, 0.0, 1.0)
    }

    fn prior_chi2(&self, target: &c64, information: &Matrix2<f64>) -> f64 {
        let e = self.position() - target;
        let v = Vector2::new(e.re, e.im);
        (v.transpose() * information * v)[0]
    }

    /// `J = [I₂ 0]` on `(x, y, θ)`.
    fn prior_system(&self, target: &c64, information: &Matrix2<f64>) -> (Matrix3<f64>, Vector3<f64>) {
        let e = self.position() - target;
        let g = information * Vector2::new(e.re, e.im);
        let mut h = Matrix3::zeros();
        h.fixed_view_mut::<2, 2>(0, 0).copy_from(information);
        (h, Vector3::new(g[0], g[1], 0.0))
    }

    fn asc_scale(edge: &Edge, xi: &Pose2, xj: &Pose2) -> f64 {
        let e = crate::graph::edge_error(edge, xi, xj);
        let euclid = e[0] * e[0] + e[1] * e[1] + e[2] * e[2];
        euclid * edge.information.covariance().determinant()
    }
}

impl LiePose for Pose3 {
    type EdgeHessian = SMatrix<f64, 12, 12>;
    type EdgeGradient = SVector<f64, 12>;
    type PoseHessian = Matrix6<f64>;
    type PoseGradient = Vector6<f64>;
    type Position = Vector3<f64>;
    type PositionInformation = Matrix3<f64>;

    fn edge_system(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> (Self::EdgeHessian, Self::EdgeGradient) {
        se3::local_system(edge, xi, xj)
    }

    fn retract(&self, d: &[f64]) -> Pose3 {
        se3::retract(self, &Vector6::from_column_slice(d))
    }

    /// `⊞` already moves the position in the pose's frame (`ξ_t = u`); its
    /// rotation part `v` is half the rotation vector (`ξ_r = 2v`).
    fn body_tangent(&self) -> Matrix6<f64> {
        Matrix6::from_diagonal(&Vector6::new(1.0, 1.0, 1.0, 2.0, 2.0, 2.0))
    }

    fn prior_chi2(&self, target: &Vector3<f64>, information: &Matrix3<f64>) -> f64 {
        let e = self.translation - target;
        e.dot(&(information * e))
    }

    /// `p ⊞ δ` moves the position by `R u`, so `J = [R 0]`.
    fn prior_system(
        &self,
        target: &Vector3<f64>,
        information: &Matrix3<f64>,
    ) -> (Matrix6<f64>, Vector6<f64>) {
        let r = self.rotation.to_rotation_matrix().into_inner();
        let e = self.translation - target;
        let mut h = Matrix6::zeros();
        h.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(r.transpose() * information * r));
        let g = r.transpose() * (information * e);
        (h, Vector6::new(g.x, g.y, g.z, 0.0, 0.0, 0.0))
    }

    fn asc_scale(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> f64 {
        let e = crate::graph::edge_error(edge, xi, xj);
        let euclid: f64 = e.iter().map(|v| v * v).sum();
        euclid * edge.information.covariance().determinant()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{EdgeKind, Information};

    #[test]
    fn a_kernel_scores_an_edge_by_its_chi2_and_asc_by_its_scale() {
        // error (0, 2, 0) under Ω = diag(1, 2, 4): χ² = 2·4 = 8; paper B's
        // χ′ = 4 and |Λ| = det diag(1, 1/2, 1/4) = 1/8
        let edge = Edge {
            from: 0,
            to: 1,
            measurement: Pose2::new(1.0, 0.0, 0.0),
            information: Information::from_upper([1.0, 0.0, 0.0, 2.0, 0.0, 4.0]).unwrap(),
            kind: EdgeKind::LoopClosure,
        };
        let (a, b) = (Pose2::IDENTITY, Pose2::new(1.0, 2.0, 0.0));
        let dcs = Kernel::Dcs { phi: 1.0 };
        assert!((Pose2::kernel_switch(&dcs, &edge, &a, &b) - 2.0 / 9.0).abs() < 1e-15);
        assert!((Pose2::kernel_cost(&dcs, &edge, &a, &b) - 23.0 / 9.0).abs() < 1e-15);
        // s = 1/(8·4/8 + 1) = 1/5
        assert!((Pose2::kernel_switch(&Kernel::Asc, &edge, &a, &b) - 0.2).abs() < 1e-15);
    }
}
