//! g2o's SE(3) cost (EdgeSE3): χ² = Σ eᵀ Ω e with `e = [Δt, Δq_xyz]` of
//! `Δ = Z_ij⁻¹ X_i⁻¹ X_j`, the quaternion of `Δ` taken with `w ≥ 0`.
//!
//! The rotational part is the vector of a unit quaternion, so near the
//! optimum it is half the rotation vector of the residual rotation; this is
//! the cost under which g2o's and GTSAM's published optima of the 3-D
//! datasets are reported (Sphere2500: 727.15).

use super::{Edge, EdgeCost, Information6, Pose3};
use nalgebra::{Quaternion, Vector3};

/// The residual motion of an edge, `Δ = Z⁻¹ X_i⁻¹ X_j`, and its quaternion
/// with `w ≥ 0`: what the error and its Jacobians are built from.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Delta3 {
    /// `Δ`.
    pub motion: Pose3,
    /// The quaternion of `Δ`, sign chosen so that `w ≥ 0`.
    pub quaternion: Quaternion<f64>,
}

impl Delta3 {
    /// `Δ` of `edge` at `xi`, `xj`.
    pub fn new(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> Self {
        let motion = edge.measurement.between(&xi.between(xj));
        Self {
            quaternion: motion.canonical_quaternion(),
            motion,
        }
    }

    /// `[Δt, Δq_xyz]`.
    pub fn error(&self) -> [f64; 6] {
        let (t, q) = (&self.motion.translation, &self.quaternion);
        [t.x, t.y, t.z, q.i, q.j, q.k]
    }

    /// The translation of `Δ`.
    pub fn translation(&self) -> &Vector3<f64> {
        &self.motion.translation
    }
}

impl EdgeCost for Pose3 {
    type Error = [f64; 6];
    fn edge_error(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> [f64; 6] {
        Delta3::new(edge, xi, xj).error()
    }
    fn mahalanobis(information: &Information6, e: &[f64; 6]) -> f64 {
        information.mahalanobis(e)
    }
    fn vector(&self) -> [f64; 6] {
        let (t, q) = (&self.translation, self.canonical_quaternion());
        [t.x, t.y, t.z, q.i, q.j, q.k]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{edge_chi2, edge_error, EdgeKind};
    use nalgebra::UnitQuaternion;

    fn edge(z: Pose3, information: Information6) -> Edge<Pose3> {
        Edge {
            from: 0,
            to: 1,
            measurement: z,
            information,
            kind: EdgeKind::Odometry,
        }
    }

    #[test]
    fn error_is_zero_on_a_consistent_edge() {
        let xi = Pose3::from_xyz_rpy([1.0, 2.0, -0.5, 0.3, -0.2, 1.0]);
        let xj = Pose3::from_xyz_rpy([-1.0, 4.0, 0.5, -0.1, 0.4, 2.0]);
        let e = edge_error(&edge(xi.between(&xj), Information6::identity()), &xi, &xj);
        assert!(e.iter().all(|v| v.abs() < 1e-12), "{e:?}");
    }

    #[test]
    fn the_rotation_error_is_the_quaternion_vector_with_non_negative_w() {
        // Δ = rotation by 0.4 rad about z, stored with w < 0: the error must
        // be (0, 0, sin 0.2), not its negative.
        let xi = Pose3::IDENTITY;
        let turn = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.4);
        let flipped = UnitQuaternion::new_unchecked(-turn.into_inner());
        let xj = Pose3::new(Vector3::new(0.0, 0.0, 1.0), flipped);
        let mut u = Information6::identity().upper();
        u[20] = 100.0;
        let e = edge(Pose3::IDENTITY, Information6::from_upper(u).unwrap());
        let err = edge_error(&e, &xi, &xj);
        assert!(
            (err[2] - 1.0).abs() < 1e-15 && (err[5] - 0.2f64.sin()).abs() < 1e-15,
            "{err:?}"
        );
        // χ² = 1 + 100 sin²(0.2)
        let chi2 = edge_chi2(&e, &[xi, xj]);
        assert!((chi2 - (1.0 + 100.0 * 0.2f64.sin().powi(2))).abs() < 1e-12);
    }

    #[test]
    fn the_translation_error_is_in_the_measured_frame() {
        // Z turns 90° about z: a surplus of 1 along the map's x shows up on
        // Δ's −y.
        let z = Pose3::new(
            Vector3::new(1.0, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::FRAC_PI_2),
        );
        let xj = Pose3::new(Vector3::new(2.0, 0.0, 0.0), z.rotation);
        let err = edge_error(&edge(z, Information6::identity()), &Pose3::IDENTITY, &xj);
        assert!(err[0].abs() < 1e-12 && (err[1] + 1.0).abs() < 1e-12, "{err:?}");
    }
}
