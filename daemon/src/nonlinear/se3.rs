//! Linearisation of one SE(3) edge under g2o's error, and the step.
//!
//! A pose moves by `X ⊞ δ = X · (R(q(v)), u)` with `δ = (u, v)` and `q(v)`
//! the unit quaternion whose vector is `v` to first order (the rotation by
//! `2|v|` about `v`). With `Δ = Z⁻¹ X_i⁻¹ X_j = (R_Δ, t_Δ)`, its quaternion
//! `(a_w, a)` (`a_w ≥ 0`) and `Z = (R_z, t_z)`, the error `e = [t_Δ, a]`
//! has, to first order in `δ_j` and `δ_i`,
//!
//! ```text
//! ∂t_Δ/∂u_j = R_Δ          ∂t_Δ/∂v_j = 0
//! ∂a/∂u_j   = 0            ∂a/∂v_j   = a_w I + [a]×
//! ∂t_Δ/∂u_i = −R_zᵀ        ∂t_Δ/∂v_i = 2 [t_Δ]× R_zᵀ + 2 R_zᵀ [t_z]×
//! ∂a/∂u_i   = 0            ∂a/∂v_i   = (−a_w I + [a]×) R_zᵀ
//! ```
//!
//! (`Δ ⊞ δ_j` right-multiplies `Δ`; `δ_i` enters as `Z⁻¹ Exp(δ_i)⁻¹ Z Δ`.)

use crate::graph::{Delta3, Edge, Pose3};
use nalgebra::{Matrix3, Quaternion, SMatrix, SVector, UnitQuaternion, Vector3, Vector6};

/// `J = [A B]` (6×12) of `edge` at `xi`, `xj`, and its error.
pub fn jacobian(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> (SMatrix<f64, 6, 12>, Vector6<f64>) {
    let delta = Delta3::new(edge, xi, xj);
    let q = delta.quaternion;
    let a = q.imag();
    let r_delta = delta.motion.rotation_matrix().into_inner();
    let z = &edge.measurement;
    let rz_t = z.rotation_matrix().into_inner().transpose();
    let t = delta.translation();
    let mut j = SMatrix::<f64, 6, 12>::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&-rz_t);
    j.fixed_view_mut::<3, 3>(0, 3)
        .copy_from(&(2.0 * t.cross_matrix() * rz_t + 2.0 * rz_t * z.translation.cross_matrix()));
    j.fixed_view_mut::<3, 3>(3, 3)
        .copy_from(&((a.cross_matrix() - Matrix3::identity() * q.w) * rz_t));
    j.fixed_view_mut::<3, 3>(0, 6).copy_from(&r_delta);
    j.fixed_view_mut::<3, 3>(3, 9)
        .copy_from(&(Matrix3::identity() * q.w + a.cross_matrix()));
    (j, Vector6::from_column_slice(&delta.error()))
}

/// `(Jᵀ Ω J, Jᵀ Ω e)` of one edge.
pub fn local_system(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> (SMatrix<f64, 12, 12>, SVector<f64, 12>) {
    let (j, e) = jacobian(edge, xi, xj);
    let omega_j = edge.information.matrix() * j;
    (j.transpose() * omega_j, omega_j.transpose() * e)
}

/// `X ⊞ δ = X · (R(q(v)), u)`, `q(v) = (cos|v|, sin|v| v/|v|)`: the
/// rotation by `2|v|` about `v`, whose vector part is `v` to first order,
/// so the step agrees with the Jacobians and stays a unit quaternion for
/// any `v`.
pub fn retract(x: &Pose3, delta: &Vector6<f64>) -> Pose3 {
    let u = Vector3::new(delta[0], delta[1], delta[2]);
    let v = Vector3::new(delta[3], delta[4], delta[5]);
    let angle = v.norm();
    let q = if angle < 1e-12 {
        Quaternion::new(1.0, v.x, v.y, v.z)
    } else {
        let s = angle.sin() / angle;
        Quaternion::new(angle.cos(), s * v.x, s * v.y, s * v.z)
    };
    x.compose(&Pose3::new(u, UnitQuaternion::from_quaternion(q)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{edge_error, EdgeKind, Information6};

    #[test]
    fn jacobians_match_finite_differences() {
        let edge = Edge {
            from: 0,
            to: 1,
            measurement: Pose3::from_xyz_rpy([0.8, -0.3, 0.5, 0.2, -0.4, 0.9]),
            information: Information6::identity(),
            kind: EdgeKind::Odometry,
        };
        let xi = Pose3::from_xyz_rpy([0.2, 0.1, -0.3, 0.7, 0.1, -1.2]);
        // near the edge, then far from it (rotation error near π/2)
        for xj in [
            xi.compose(&edge.measurement)
                .compose(&Pose3::from_xyz_rpy([0.1, -0.2, 0.05, 0.1, 0.2, -0.15])),
            Pose3::from_xyz_rpy([1.1, 0.9, 0.4, -0.5, 0.9, 2.3]),
        ] {
            let (j, e) = jacobian(&edge, &xi, &xj);
            let h = 1e-7;
            for k in 0..6 {
                let mut d = Vector6::zeros();
                d[k] = h;
                let (plus_i, minus_i) = (retract(&xi, &d), retract(&xi, &-d));
                let (plus_j, minus_j) = (retract(&xj, &d), retract(&xj, &-d));
                let fd_i = (Vector6::from(edge_error(&edge, &plus_i, &xj))
                    - Vector6::from(edge_error(&edge, &minus_i, &xj)))
                    / (2.0 * h);
                let fd_j = (Vector6::from(edge_error(&edge, &xi, &plus_j))
                    - Vector6::from(edge_error(&edge, &xi, &minus_j)))
                    / (2.0 * h);
                for r in 0..6 {
                    assert!(
                        (fd_i[r] - j[(r, k)]).abs() < 1e-6,
                        "A[{r},{k}] {} vs {}",
                        fd_i[r],
                        j[(r, k)]
                    );
                    assert!(
                        (fd_j[r] - j[(r, 6 + k)]).abs() < 1e-6,
                        "B[{r},{k}] {} vs {}",
                        fd_j[r],
                        j[(r, 6 + k)]
                    );
                }
            }
            assert_eq!(e, Vector6::from(edge_error(&edge, &xi, &xj)));
        }
    }

    #[test]
    fn the_step_turns_by_twice_the_vector() {
        let x = Pose3::IDENTITY;
        let y = retract(&x, &Vector6::new(1.0, 2.0, 3.0, 0.0, 0.0, 0.3));
        assert_eq!(y.translation, Vector3::new(1.0, 2.0, 3.0));
        assert!((y.rotation.angle() - 0.6).abs() < 1e-15);
        assert!((y.rotation.axis().unwrap().z - 1.0).abs() < 1e-15);
    }
}
