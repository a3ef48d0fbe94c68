//! [`PositionPrior`]: an absolute position measurement of one keyframe, and
//! [`Problem`]: the cost the polish minimises.

use crate::geometry::Pose2;
use crate::graph::{chi2_of_edges, Edge};
use faer::c64;
use nalgebra::Matrix2;

/// `p_k ≈ target` in the map frame with information Ω (a GPS fix carried
/// into the map frame by the georeference). Its error `e = p_k − target`
/// has the Jacobian `[I₂ 0]` on `(x, y, θ)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionPrior {
    /// Keyframe index.
    pub keyframe: usize,
    /// Map-frame position.
    pub target: c64,
    /// 2×2 information over (x, y).
    pub information: Matrix2<f64>,
}

impl PositionPrior {
    /// `eᵀ Ω e` at `poses`.
    pub fn chi2(&self, poses: &[Pose2]) -> f64 {
        let e = poses[self.keyframe].position() - self.target;
        let v = nalgebra::Vector2::new(e.re, e.im);
        (v.transpose() * self.information * v)[0]
    }
}

/// What the polish minimises: g2o's SE(2) cost of the edges plus the
/// priors' `eᵀΩe`.
#[derive(Clone, Copy, Debug)]
pub struct Problem<'a> {
    /// Relative-pose edges.
    pub edges: &'a [Edge],
    /// Absolute position priors.
    pub priors: &'a [PositionPrior],
}

impl<'a> Problem<'a> {
    /// Edges only.
    pub fn edges(edges: &'a [Edge]) -> Self {
        Self { edges, priors: &[] }
    }

    /// The total cost at `poses`.
    pub fn chi2(&self, poses: &[Pose2]) -> f64 {
        chi2_of_edges(self.edges, poses) + self.priors.iter().map(|p| p.chi2(poses)).sum::<f64>()
    }
}
