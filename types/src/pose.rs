//! Planar rigid motions: [`Pose2`] and angle wrapping.
//!
//! A pose is `(x, y, θ)`: the position of a keyframe in the map and its
//! heading. A rotation is the unit complex number `e^{iθ}`, so a planar
//! point `z = x + iy` rotates as `e^{iθ} z`.

use num_complex::Complex64;
use std::f64::consts::PI;

/// Wraps an angle into `(-π, π]`.
pub fn wrap_angle(a: f64) -> f64 {
    let mut r = a.rem_euclid(2.0 * PI);
    if r > PI {
        r -= 2.0 * PI;
    }
    r
}

/// A rigid motion of the plane, `T = (R(θ), t)`.
///
/// As an edge measurement `T_ij` it is the pose of keyframe `j` seen from
/// keyframe `i`: `T_ij = T_i⁻¹ T_j`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Pose2 {
    /// x coordinate (m).
    pub x: f64,
    /// y coordinate (m).
    pub y: f64,
    /// heading (rad), not necessarily wrapped.
    pub theta: f64,
}

impl Pose2 {
    /// The identity motion.
    pub const IDENTITY: Pose2 = Pose2 {
        x: 0.0,
        y: 0.0,
        theta: 0.0,
    };

    /// Builds a pose from its coordinates.
    pub const fn new(x: f64, y: f64, theta: f64) -> Self {
        Self { x, y, theta }
    }

    /// The position as a complex number `x + iy`.
    pub fn position(&self) -> Complex64 {
        Complex64::new(self.x, self.y)
    }

    /// The rotation as the unit complex number `e^{iθ}`.
    pub fn rotation(&self) -> Complex64 {
        Complex64::from_polar(1.0, self.theta)
    }

    /// Builds a pose from a complex position and a heading.
    pub fn from_complex(p: Complex64, theta: f64) -> Self {
        Self::new(p.re, p.im, theta)
    }

    /// Composition `self ∘ other`: `other` expressed in the frame of `self`.
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let p = self.position() + self.rotation() * other.position();
        Pose2::from_complex(p, wrap_angle(self.theta + other.theta))
    }

    /// The inverse motion `T⁻¹ = (R⁻¹, −R⁻¹ t)`.
    pub fn inverse(&self) -> Pose2 {
        let p = -(self.rotation().conj() * self.position());
        Pose2::from_complex(p, wrap_angle(-self.theta))
    }

    /// The relative motion `self⁻¹ ∘ other`: `other` seen from `self`.
    pub fn between(&self, other: &Pose2) -> Pose2 {
        let p = self.rotation().conj() * (other.position() - self.position());
        Pose2::from_complex(p, wrap_angle(other.theta - self.theta))
    }

    /// True when all three coordinates are finite.
    pub fn is_finite(&self) -> bool {
        self.x.is_finite() && self.y.is_finite() && self.theta.is_finite()
    }

    /// The coordinates as an array `[x, y, θ]`.
    pub fn to_array(&self) -> [f64; 3] {
        [self.x, self.y, self.theta]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: &Pose2, b: &Pose2) -> bool {
        (a.x - b.x).abs() < 1e-12 && (a.y - b.y).abs() < 1e-12 && wrap_angle(a.theta - b.theta).abs() < 1e-12
    }

    #[test]
    fn wrap_angle_lands_in_half_open_interval() {
        assert_eq!(wrap_angle(PI), PI);
        assert_eq!(wrap_angle(-PI), PI);
        assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-15);
        assert!((wrap_angle(-7.0) - (-7.0 + 2.0 * PI)).abs() < 1e-15);
    }

    #[test]
    fn compose_between_and_inverse_agree() {
        let a = Pose2::new(1.0, -2.0, 0.7);
        let b = Pose2::new(-3.0, 0.5, -2.9);
        let ab = a.between(&b);
        assert!(close(&a.compose(&ab), &b));
        assert!(close(&a.compose(&a.inverse()), &Pose2::IDENTITY));
        assert!(close(&ab.inverse(), &b.between(&a)));
    }

    #[test]
    fn compose_rotates_the_offset() {
        let a = Pose2::new(1.0, 0.0, PI / 2.0);
        let c = a.compose(&Pose2::new(2.0, 0.0, 0.0));
        assert!(close(&c, &Pose2::new(1.0, 2.0, PI / 2.0)));
    }
}
