//! Marginal covariances of poses, read off the engine's factor.
//!
//! The Gauss–Newton system keeps `H = Σ s Jᵀ Ω J` (switch weights and GPS
//! priors included) factorised as `L D Lᵀ` at its linearisation point. The
//! Laplace approximation of the posterior is `N(x̂, H⁻¹)`, so the marginal
//! covariance of pose `k` is the `DOF` square of `H⁻¹` on its columns,
//! `Vᵀ H⁻¹ V = Yᵀ D⁻¹ Y` with `Y = L⁻¹ V` for `V` the columns' unit
//! vectors. `Y` is nonzero only on the elimination-tree paths from those
//! columns to the root, so one marginal costs a forward solve over one
//! path: no inverse is formed and nothing in the factor changes. The
//! newest keyframes sit near the root, where the paths are short.
//!
//! Covariances are in the body-frame tangent of GTSAM's `Marginals`: a
//! pose is `X · Exp(ξ)`, `ξ` = translation in the pose's own frame, then
//! the rotation (`(x, y, θ)` in the plane; `(x, y, z, rx, ry, rz)` in
//! space, a rotation vector in rad; GTSAM's Pose3 orders the rotation
//! block first). The gauge keyframe is held fixed, so
//! its covariance is zero and every other one is relative to it.

use super::{Engine, EngineError, EnginePose};
use crate::graph::KeyframeId;
use nalgebra::DMatrix;

/// The upper triangle of a square `sigma`, row by row (the order the
/// snapshot header and `slamd solve --covariances` write a covariance in,
/// g2o's order for information matrices).
pub fn upper_triangle(sigma: &DMatrix<f64>) -> impl Iterator<Item = f64> + '_ {
    let n = sigma.nrows();
    (0..n).flat_map(move |r| (r..n).map(move |c| sigma[(r, c)]))
}

impl<P: EnginePose> Engine<P> {
    /// The marginal covariance of keyframe `id`'s pose, `DOF` square (3 in
    /// the plane, 6 in space), as of the changes applied so far.
    pub fn marginal(&mut self, id: KeyframeId) -> Result<DMatrix<f64>, EngineError> {
        self.covariance(&[id])
    }

    /// The joint covariance of keyframes `a` and `b`, `2·DOF` square: `a`'s
    /// rows first, the cross-covariance off the diagonal.
    pub fn joint_marginal(&mut self, a: KeyframeId, b: KeyframeId) -> Result<DMatrix<f64>, EngineError> {
        self.covariance(&[a, b])
    }

    fn covariance(&mut self, ids: &[KeyframeId]) -> Result<DMatrix<f64>, EngineError> {
        let mut slots = Vec::with_capacity(ids.len());
        for &id in ids {
            let model = &self.state.model;
            let k = (model.graph.index_of(id)).ok_or(EngineError::NoCovariance(id, "no such keyframe"))?;
            if !model.joined(k) {
                return Err(EngineError::NoCovariance(id, "it has no edge to the map yet"));
            }
            slots.push(k);
        }
        match self.state.gauss_newton().covariance(&slots) {
            Ok(Some(sigma)) => Ok(sigma),
            Ok(None) => Err(EngineError::NoCovariance(
                ids[0],
                "the graph leaves a direction of it free (infinite variance)",
            )),
            Err(e) => Err(EngineError::Numeric(e)),
        }
    }
}
