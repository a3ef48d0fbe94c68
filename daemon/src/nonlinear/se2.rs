//! Linearisation of one SE(2) edge under g2o's error.
//!
//! With `M = R(−(θ_i + θ_ij))` and `Δ = p_j − p_i`, the error is
//! `e_t = M Δ − R(θ_ij)ᵀ t_ij`, `e_θ = wrap(θ_j − θ_i − θ_ij)`, and its
//! Jacobians over `(x, y, θ)` of each pose are
//!
//! ```text
//! A = ∂e/∂x_i = [ −M   −J M Δ ]      B = ∂e/∂x_j = [ M  0 ]
//!               [  0     −1   ]                    [ 0  1 ]
//! ```
//! with `J` the rotation by +90°.

use crate::geometry::Pose2;
use crate::graph::{edge_error, Edge};
use nalgebra::{Matrix3, Matrix3x6, Matrix6, Vector3, Vector6};

/// The error of an edge and its Jacobians with respect to both poses.
#[derive(Clone, Copy, Debug)]
pub struct LinearizedEdge {
    /// `e` at the linearisation point.
    pub error: Vector3<f64>,
    /// `∂e/∂x_i`.
    pub a: Matrix3<f64>,
    /// `∂e/∂x_j`.
    pub b: Matrix3<f64>,
}

/// Linearises `edge` at poses `xi`, `xj`.
pub fn linearize(edge: &Edge, xi: &Pose2, xj: &Pose2) -> LinearizedEdge {
    let e = edge_error(edge, xi, xj);
    let (s, c) = (-(xi.theta + edge.measurement.theta)).sin_cos();
    let (dx, dy) = (xj.x - xi.x, xj.y - xi.y);
    // M Δ
    let (mx, my) = (c * dx - s * dy, s * dx + c * dy);
    let a = Matrix3::new(-c, s, my, -s, -c, -mx, 0.0, 0.0, -1.0);
    let b = Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0);
    LinearizedEdge {
        error: Vector3::new(e[0], e[1], e[2]),
        a,
        b,
    }
}

/// The edge's Jacobian `J = [A B]` (3×6) at the given poses, with its error.
pub fn jacobian(edge: &Edge, xi: &Pose2, xj: &Pose2) -> (Matrix3x6<f64>, nalgebra::Vector3<f64>) {
    let lin = linearize(edge, xi, xj);
    let mut j = Matrix3x6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&lin.a);
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&lin.b);
    (j, lin.error)
}

/// `(Jᵀ Ω J, Jᵀ Ω e)` of one edge.
pub fn local_system(edge: &Edge, xi: &Pose2, xj: &Pose2) -> (Matrix6<f64>, Vector6<f64>) {
    let (j, e) = jacobian(edge, xi, xj);
    let omega_j = edge.information.matrix() * j;
    (j.transpose() * omega_j, omega_j.transpose() * e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{EdgeKind, Information};

    #[test]
    fn jacobians_match_finite_differences() {
        let edge = Edge {
            from: 0,
            to: 1,
            measurement: Pose2::new(0.8, -0.3, 0.4),
            information: Information::identity(),
            kind: EdgeKind::Odometry,
        };
        let xi = Pose2::new(0.2, 0.1, 0.7);
        let xj = Pose2::new(1.1, 0.9, 1.3);
        let lin = linearize(&edge, &xi, &xj);
        let h = 1e-6;
        for k in 0..3 {
            let mut d = [0.0; 3];
            d[k] = h;
            let bump = |p: &Pose2| Pose2::new(p.x + d[0], p.y + d[1], p.theta + d[2]);
            let ei = edge_error(&edge, &bump(&xi), &xj);
            let ej = edge_error(&edge, &xi, &bump(&xj));
            for r in 0..3 {
                let fd_i = (ei[r] - lin.error[r]) / h;
                let fd_j = (ej[r] - lin.error[r]) / h;
                assert!(
                    (fd_i - lin.a[(r, k)]).abs() < 1e-5,
                    "A[{r},{k}] {fd_i} vs {}",
                    lin.a[(r, k)]
                );
                assert!(
                    (fd_j - lin.b[(r, k)]).abs() < 1e-5,
                    "B[{r},{k}] {fd_j} vs {}",
                    lin.b[(r, k)]
                );
            }
        }
    }
}
