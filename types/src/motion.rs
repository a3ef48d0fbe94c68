//! [`RigidMotion`]: what planar and spatial poses have in common, so that
//! edges, graphs and solvers are written once for both dimensions.

use crate::{Information, Information6, InformationError, Pose2, Pose3};
use std::fmt::Debug;

/// What every information matrix offers, whatever its size.
pub trait InformationMatrix: Copy + PartialEq + Debug + Send + Sync + 'static {
    /// Ω scaled by `s ≥ 0` (a weight or a switch's `s²`).
    fn scaled(&self, s: f64) -> Self;
    /// Whether every entry is 0 (an edge weighted out).
    fn is_zero(&self) -> bool;
    /// Entries of the upper triangle: 6 in the plane, 21 in space.
    const UPPER: usize;
    /// The upper triangle, row by row, into `out[..UPPER]`.
    fn write_upper(&self, out: &mut [f64]);
    /// From `v[..UPPER]`, the upper triangle row by row; checked finite and
    /// positive definite.
    fn from_upper_slice(v: &[f64]) -> Result<Self, InformationError>;
}

/// `v[..N]` as an array (zeros past the end of a short `v`).
fn head<const N: usize>(v: &[f64]) -> [f64; N] {
    let mut a = [0.0; N];
    let n = v.len().min(N);
    a[..n].copy_from_slice(&v[..n]);
    a
}

impl InformationMatrix for Information {
    fn scaled(&self, s: f64) -> Self {
        Information::scaled(self, s)
    }
    fn is_zero(&self) -> bool {
        self.upper() == [0.0; 6]
    }
    const UPPER: usize = 6;
    fn write_upper(&self, out: &mut [f64]) {
        out[..6].copy_from_slice(&self.upper());
    }
    fn from_upper_slice(v: &[f64]) -> Result<Self, InformationError> {
        Information::from_upper(head(v))
    }
}

impl InformationMatrix for Information6 {
    fn scaled(&self, s: f64) -> Self {
        Information6::scaled(self, s)
    }
    fn is_zero(&self) -> bool {
        self.upper() == [0.0; 21]
    }
    const UPPER: usize = 21;
    fn write_upper(&self, out: &mut [f64]) {
        out[..21].copy_from_slice(&self.upper());
    }
    fn from_upper_slice(v: &[f64]) -> Result<Self, InformationError> {
        Information6::from_upper(head(v))
    }
}

/// A rigid motion group, SE(2) or SE(3), with the information matrix of a
/// measurement on it.
pub trait RigidMotion: Copy + PartialEq + Debug + Default + Send + Sync + 'static {
    /// Degrees of freedom: 3 in the plane, 6 in space.
    const DOF: usize;
    /// The dimension of the space: 2 or 3.
    const DIMENSION: u32;
    /// Numbers that write a pose on the wire and on disk: 3 `(x, y, θ)` in
    /// the plane, 7 `(x, y, z, qx, qy, qz, qw)` in space.
    const PARAMS: usize;
    /// The identity.
    const IDENTITY: Self;
    /// Ω over the edge error (`DOF × DOF`).
    type Information: InformationMatrix;
    /// `self ∘ other`.
    fn compose(&self, other: &Self) -> Self;
    /// `self⁻¹`.
    fn inverse(&self) -> Self;
    /// `self⁻¹ ∘ other`.
    fn between(&self, other: &Self) -> Self {
        self.inverse().compose(other)
    }
    /// Whether every number is finite.
    fn is_finite(&self) -> bool;
    /// The position, `z = 0` in the plane.
    fn position3(&self) -> [f64; 3];
    /// The orientation as a unit quaternion `[qx, qy, qz, qw]`, `qw ≥ 0`
    /// (in the plane, the rotation by θ about z).
    fn orientation(&self) -> [f64; 4];
    /// The heading, the rotation about z (rad): θ in the plane, the yaw of
    /// `R = R_z(yaw) R_y(pitch) R_x(roll)` in space.
    fn heading(&self) -> f64;
    /// The pose's [`Self::PARAMS`] numbers into `out[..PARAMS]` (in space
    /// the quaternion with `qw ≥ 0`).
    fn write_params(&self, out: &mut [f64]);
    /// The pose `v[..PARAMS]` writes; `None` when a number is not finite
    /// or, in space, the quaternion is off unit norm by more than
    /// [`QUATERNION_NORM_TOLERANCE`](crate::QUATERNION_NORM_TOLERANCE).
    fn from_params(v: &[f64]) -> Option<Self>;
}

impl RigidMotion for Pose2 {
    const DOF: usize = 3;
    const DIMENSION: u32 = 2;
    const PARAMS: usize = 3;
    const IDENTITY: Self = Pose2::IDENTITY;
    type Information = Information;
    fn compose(&self, other: &Self) -> Self {
        Pose2::compose(self, other)
    }
    fn inverse(&self) -> Self {
        Pose2::inverse(self)
    }
    fn between(&self, other: &Self) -> Self {
        Pose2::between(self, other)
    }
    fn is_finite(&self) -> bool {
        Pose2::is_finite(self)
    }
    fn position3(&self) -> [f64; 3] {
        [self.x, self.y, 0.0]
    }
    fn orientation(&self) -> [f64; 4] {
        // θ ∈ (−π, π], so cos(θ/2) ≥ 0
        let (s, c) = (0.5 * self.theta).sin_cos();
        [0.0, 0.0, s, c]
    }
    fn heading(&self) -> f64 {
        self.theta
    }
    fn write_params(&self, out: &mut [f64]) {
        out[..3].copy_from_slice(&self.to_array());
    }
    fn from_params(v: &[f64]) -> Option<Self> {
        let [x, y, theta] = head(v);
        Some(Pose2::new(x, y, theta)).filter(Pose2::is_finite)
    }
}

impl RigidMotion for Pose3 {
    const DOF: usize = 6;
    const DIMENSION: u32 = 3;
    const PARAMS: usize = 7;
    const IDENTITY: Self = Pose3::IDENTITY;
    type Information = Information6;
    fn compose(&self, other: &Self) -> Self {
        Pose3::compose(self, other)
    }
    fn inverse(&self) -> Self {
        Pose3::inverse(self)
    }
    fn between(&self, other: &Self) -> Self {
        Pose3::between(self, other)
    }
    fn is_finite(&self) -> bool {
        Pose3::is_finite(self)
    }
    fn position3(&self) -> [f64; 3] {
        let t = &self.translation;
        [t.x, t.y, t.z]
    }
    fn orientation(&self) -> [f64; 4] {
        let q = self.canonical_quaternion();
        [q.i, q.j, q.k, q.w]
    }
    fn heading(&self) -> f64 {
        self.rotation.euler_angles().2
    }
    fn write_params(&self, out: &mut [f64]) {
        out[..7].copy_from_slice(&self.to_xyz_quaternion());
    }
    fn from_params(v: &[f64]) -> Option<Self> {
        Pose3::from_xyz_quaternion(head(v))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_round_trip_and_bad_ones_are_refused() {
        let mut buf = [0.0; 7];
        let p = Pose2::new(1.0, -2.0, 0.5);
        p.write_params(&mut buf);
        assert_eq!(Pose2::from_params(&buf), Some(p));
        assert_eq!(Pose2::from_params(&[f64::NAN, 0.0, 0.0]), None);
        let q = Pose3::from_xyz_rpy([1.0, 2.0, 3.0, 0.1, -0.2, 0.3]);
        q.write_params(&mut buf);
        let back = Pose3::from_params(&buf).unwrap();
        assert!((back.translation - q.translation).norm() < 1e-15);
        assert!(back.rotation.angle_to(&q.rotation) < 1e-12);
        assert_eq!(Pose3::from_params(&[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]), None);
    }

    #[test]
    fn orientation_and_heading_agree_across_dimensions() {
        for theta in [-3.0, -0.4, 0.0, 1.2, std::f64::consts::PI] {
            let p = Pose2::new(1.0, 2.0, theta);
            let q = Pose3::from_xyz_rpy([1.0, 2.0, 0.0, 0.0, 0.0, theta]);
            let (a, b) = (p.orientation(), q.orientation());
            for k in 0..4 {
                assert!((a[k] - b[k]).abs() < 1e-15, "θ {theta}: {a:?} against {b:?}");
            }
            assert_eq!(p.heading(), theta);
            assert!((q.heading() - theta).abs() < 1e-12 || (q.heading() + theta).abs() < 1e-12);
        }
        let q = Pose3::from_xyz_rpy([0.0, 0.0, 0.0, 0.3, -0.2, 0.7]);
        assert!((q.heading() - 0.7).abs() < 1e-12);
    }

    #[test]
    fn information_slices_round_trip() {
        let mut buf = [0.0; 21];
        let i = Information6::identity().scaled(3.0);
        i.write_upper(&mut buf);
        assert_eq!(Information6::from_upper_slice(&buf), Ok(i));
        let j = Information::identity();
        j.write_upper(&mut buf);
        assert_eq!(Information::from_upper_slice(&buf), Ok(j));
        assert_eq!(
            Information::from_upper_slice(&[1.0, 5.0, 0.0, 1.0, 0.0, 1.0]),
            Err(InformationError::NotPositiveDefinite)
        );
    }
}
