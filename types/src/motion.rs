//! [`RigidMotion`]: what planar and spatial poses have in common, so that
//! edges, graphs and solvers are written once for both dimensions.

use crate::{Information, Information6, Pose2, Pose3};
use std::fmt::Debug;

/// What every information matrix offers, whatever its size.
pub trait InformationMatrix: Copy + PartialEq + Debug + Send + Sync + 'static {
    /// Ω scaled by `s ≥ 0` (a weight or a switch's `s²`).
    fn scaled(&self, s: f64) -> Self;
    /// Whether every entry is 0 (an edge weighted out).
    fn is_zero(&self) -> bool;
}

impl InformationMatrix for Information {
    fn scaled(&self, s: f64) -> Self {
        Information::scaled(self, s)
    }
    fn is_zero(&self) -> bool {
        self.upper() == [0.0; 6]
    }
}

impl InformationMatrix for Information6 {
    fn scaled(&self, s: f64) -> Self {
        Information6::scaled(self, s)
    }
    fn is_zero(&self) -> bool {
        self.upper() == [0.0; 21]
    }
}

/// A rigid motion group, SE(2) or SE(3), with the information matrix of a
/// measurement on it.
pub trait RigidMotion: Copy + PartialEq + Debug + Default + Send + Sync + 'static {
    /// Degrees of freedom: 3 in the plane, 6 in space.
    const DOF: usize;
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
}

impl RigidMotion for Pose2 {
    const DOF: usize = 3;
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
}

impl RigidMotion for Pose3 {
    const DOF: usize = 6;
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
}
