//! Spatial rigid motions: [`Pose3`].
//!
//! A pose is a position `t` (m) and a unit quaternion `q` (Hamilton,
//! `w + xi + yj + zk`), so a point in the keyframe's frame maps to
//! `R(q) p + t` in the map. Frames follow REP-103: x forward, y left,
//! z up.

use nalgebra::{Quaternion, Rotation3, UnitQuaternion, Vector3};

/// How far from unit norm a given quaternion may be (`| |q| − 1 |`) before
/// it is refused rather than normalised: files round to 6–9 digits, a
/// wrong field order or a missing entry is off by far more.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// A rigid motion of space, `T = (R, t)`.
///
/// As an edge measurement `T_ij` it is the pose of keyframe `j` seen from
/// keyframe `i`: `T_ij = T_i⁻¹ T_j`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose3 {
    /// Position (m).
    pub translation: Vector3<f64>,
    /// Orientation.
    pub rotation: UnitQuaternion<f64>,
}

impl Default for Pose3 {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Pose3 {
    /// The identity motion.
    pub const IDENTITY: Pose3 = Pose3 {
        translation: Vector3::new(0.0, 0.0, 0.0),
        rotation: UnitQuaternion::new_unchecked(Quaternion::new(1.0, 0.0, 0.0, 0.0)),
    };

    /// From a position and a unit quaternion.
    pub fn new(translation: Vector3<f64>, rotation: UnitQuaternion<f64>) -> Self {
        Self {
            translation,
            rotation,
        }
    }

    /// From `x y z qx qy qz qw`, as g2o and TUM write it. A quaternion whose
    /// norm is within [`QUATERNION_NORM_TOLERANCE`] of 1 is normalised;
    /// `None` if it is farther or any number is not finite.
    pub fn from_xyz_quaternion(v: [f64; 7]) -> Option<Self> {
        if v.iter().any(|x| !x.is_finite()) {
            return None;
        }
        let q = Quaternion::new(v[6], v[3], v[4], v[5]);
        if (q.norm() - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
            return None;
        }
        Some(Self::new(
            Vector3::new(v[0], v[1], v[2]),
            UnitQuaternion::from_quaternion(q),
        ))
    }

    /// From a position and roll, pitch, yaw (rad): `R = R_z(yaw) R_y(pitch)
    /// R_x(roll)`, the convention of HOG-Man and TORO 3-D files.
    pub fn from_xyz_rpy(v: [f64; 6]) -> Self {
        Self::new(
            Vector3::new(v[0], v[1], v[2]),
            UnitQuaternion::from_euler_angles(v[3], v[4], v[5]),
        )
    }

    /// `x y z qx qy qz qw`, with `qw ≥ 0`.
    pub fn to_xyz_quaternion(&self) -> [f64; 7] {
        let q = self.canonical_quaternion();
        let t = &self.translation;
        [t.x, t.y, t.z, q.i, q.j, q.k, q.w]
    }

    /// The quaternion of the rotation with `w ≥ 0` (`q` and `−q` are the
    /// same rotation).
    pub fn canonical_quaternion(&self) -> Quaternion<f64> {
        let q = *self.rotation.quaternion();
        if q.w < 0.0 {
            -q
        } else {
            q
        }
    }

    /// The rotation matrix `R`.
    pub fn rotation_matrix(&self) -> Rotation3<f64> {
        self.rotation.to_rotation_matrix()
    }

    /// `self ∘ other`: `(R₁R₂, R₁t₂ + t₁)`. The product quaternion is
    /// normalised: without it the rounding of a long chain of compositions
    /// (a map re-anchored through thousands of relative poses) lets the norm
    /// drift away from 1, and every pose composed with it inherits the
    /// drift.
    pub fn compose(&self, other: &Pose3) -> Pose3 {
        Pose3 {
            translation: self.rotation * other.translation + self.translation,
            rotation: UnitQuaternion::new_normalize(self.rotation.into_inner() * other.rotation.into_inner()),
        }
    }

    /// `T⁻¹ = (Rᵀ, −Rᵀt)`.
    pub fn inverse(&self) -> Pose3 {
        let inv = self.rotation.inverse();
        Pose3 {
            translation: -(inv * self.translation),
            rotation: inv,
        }
    }

    /// `self⁻¹ ∘ other`: `other` seen from `self`.
    pub fn between(&self, other: &Pose3) -> Pose3 {
        self.inverse().compose(other)
    }

    /// Whether every number is finite.
    pub fn is_finite(&self) -> bool {
        self.translation.iter().all(|v| v.is_finite()) && self.rotation.coords.iter().all(|v| v.is_finite())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rpy_is_yaw_pitch_roll_about_fixed_axes() {
        let p = Pose3::from_xyz_rpy([0.0, 0.0, 0.0, 0.1, 0.2, 0.3]);
        let expected = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.3)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), 0.2)
            * Rotation3::from_axis_angle(&Vector3::x_axis(), 0.1);
        assert!((p.rotation_matrix().matrix() - expected.matrix()).norm() < 1e-15);
    }

    #[test]
    fn between_undoes_compose() {
        let a = Pose3::from_xyz_rpy([1.0, -2.0, 0.5, 0.3, -0.7, 2.5]);
        let b = Pose3::from_xyz_rpy([-0.4, 3.0, 1.5, -1.1, 0.2, -2.9]);
        let back = a.compose(&a.between(&b));
        assert!((back.translation - b.translation).norm() < 1e-12);
        assert!(back.rotation.angle_to(&b.rotation) < 1e-12);
        let id = a.compose(&a.inverse());
        assert!(id.translation.norm() < 1e-12 && id.rotation.angle() < 1e-12);
    }

    #[test]
    fn quaternions_far_from_unit_are_refused() {
        assert!(Pose3::from_xyz_quaternion([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0000004]).is_some());
        assert!(Pose3::from_xyz_quaternion([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.1]).is_none());
        assert!(Pose3::from_xyz_quaternion([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]).is_none());
        assert!(Pose3::from_xyz_quaternion([f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]).is_none());
        let p = Pose3::from_xyz_quaternion([1.0, 2.0, 3.0, 0.0, 0.0, -0.6, -0.8]).unwrap();
        assert_eq!(p.to_xyz_quaternion(), [1.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8]);
    }
}
