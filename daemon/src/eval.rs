//! Accuracy against ground truth: the absolute trajectory error (ATE).
//!
//! ATE is the position RMSE after the rigid motion `(R, t)` that best
//! aligns the estimate to the truth. In the plane, with centred points
//! `e'_k`, `g'_k`: `R = arg Σ g'_k ē'_k` and `t = ḡ − R ē` (Kabsch in
//! complex numbers); in space, Kabsch by the SVD ([`align_spatial`]).

use crate::geometry::Pose2;
use crate::graph::{KeyframeId, Pose3, PoseGraph, RigidMotion};
use faer::c64;
use nalgebra::{Matrix3, Rotation3, Vector3};
use std::collections::HashMap;

/// The ATE of a set of poses and how many keyframes it covered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ate {
    /// Position RMSE after alignment (m).
    pub rmse: f64,
    /// Keyframes present in both the estimate and the truth.
    pub matched: usize,
}

/// The rigid motion `x ↦ R x + t` best aligning `from` onto `to`.
pub fn align_planar(from: &[c64], to: &[c64]) -> (c64, c64) {
    let n = from.len().max(1) as f64;
    let cf: c64 = from.iter().sum::<c64>() / n;
    let ct: c64 = to.iter().sum::<c64>() / n;
    let s: c64 = from.iter().zip(to).map(|(f, t)| (t - ct) * (f - cf).conj()).sum();
    let r = if s.norm() > 0.0 {
        s / s.norm()
    } else {
        c64::new(1.0, 0.0)
    };
    (r, ct - r * cf)
}

/// `moving` carried by the rigid motion that best aligns it onto `fixed`
/// (matched by index): how to draw ground truth over an estimate.
pub fn aligned_onto(moving: &[Pose2], fixed: &[Pose2]) -> Vec<Pose2> {
    let m: Vec<c64> = moving.iter().map(|p| p.position()).collect();
    let f: Vec<c64> = fixed.iter().take(m.len()).map(|p| p.position()).collect();
    let (r, t) = align_planar(&m[..f.len()], &f);
    moving
        .iter()
        .map(|p| Pose2::from_complex(r * p.position() + t, p.theta + r.arg()))
        .collect()
}

/// The rigid motion `x ↦ R x + t` best aligning `from` onto `to` in 3-D
/// (Kabsch: the SVD of the cross-covariance, with a reflection turned
/// into a rotation).
pub fn align_spatial(from: &[Vector3<f64>], to: &[Vector3<f64>]) -> (Rotation3<f64>, Vector3<f64>) {
    let n = from.len().max(1) as f64;
    let cf = from.iter().sum::<Vector3<f64>>() / n;
    let ct = to.iter().sum::<Vector3<f64>>() / n;
    let h: Matrix3<f64> = from
        .iter()
        .zip(to)
        .map(|(f, t)| (t - ct) * (f - cf).transpose())
        .sum();
    let r = crate::linear::chordal::project_to_rotation(&h);
    (r, ct - r * cf)
}

/// A pose whose positions can be aligned rigidly: the plane's Kabsch in
/// complex numbers, space's by the SVD.
pub trait Aligned: RigidMotion {
    /// Keyframes needed to fix the alignment (2 in the plane, 3 in space).
    const MIN_MATCHED: usize;

    /// The position RMSE of `est` after the rigid motion that best aligns
    /// it onto `truth` (matched by index).
    fn aligned_rmse(est: &[Self], truth: &[Self]) -> f64;
}

impl Aligned for Pose2 {
    const MIN_MATCHED: usize = 2;

    fn aligned_rmse(est: &[Pose2], truth: &[Pose2]) -> f64 {
        let est: Vec<c64> = est.iter().map(|p| p.position()).collect();
        let gt: Vec<c64> = truth.iter().map(|p| p.position()).collect();
        let (r, t) = align_planar(&est, &gt);
        let sq: f64 = est.iter().zip(&gt).map(|(e, g)| (r * e + t - g).norm_sqr()).sum();
        (sq / est.len() as f64).sqrt()
    }
}

impl Aligned for Pose3 {
    const MIN_MATCHED: usize = 3;

    fn aligned_rmse(est: &[Pose3], truth: &[Pose3]) -> f64 {
        let est: Vec<Vector3<f64>> = est.iter().map(|p| p.translation).collect();
        let gt: Vec<Vector3<f64>> = truth.iter().map(|p| p.translation).collect();
        let (r, t) = align_spatial(&est, &gt);
        let sq: f64 = est
            .iter()
            .zip(&gt)
            .map(|(e, g)| (r * e + t - g).norm_squared())
            .sum();
        (sq / est.len() as f64).sqrt()
    }
}

/// ATE of `poses` (indexed like `graph`) against truth keyed by keyframe
/// id, after the best rigid alignment. `None` when fewer keyframes match
/// than the alignment needs ([`Aligned::MIN_MATCHED`]).
pub fn ate<P: Aligned>(graph: &PoseGraph<P>, poses: &[P], truth: &HashMap<KeyframeId, P>) -> Option<Ate> {
    let (est, gt): (Vec<P>, Vec<P>) = graph
        .keyframes()
        .iter()
        .zip(poses)
        .filter_map(|(k, p)| truth.get(&k.id).map(|g| (*p, *g)))
        .unzip();
    (est.len() >= P::MIN_MATCHED).then(|| Ate {
        rmse: P::aligned_rmse(&est, &gt),
        matched: est.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rigid_motion_has_zero_ate_and_noise_does_not() {
        let mut g = PoseGraph::default();
        let truth: HashMap<u64, Pose2> = (0..4)
            .map(|i| (i, Pose2::new(i as f64, (i * i) as f64, 0.0)))
            .collect();
        for i in 0..4 {
            g.add_keyframe(i, None).unwrap();
        }
        let m = Pose2::new(3.0, -1.0, 0.8);
        let moved: Vec<Pose2> = (0..4).map(|i| m.compose(&truth[&i])).collect();
        let a = ate(&g, &moved, &truth).unwrap();
        assert!(a.rmse < 1e-12 && a.matched == 4);

        let mut noisy = moved.clone();
        noisy[2].x += 0.4;
        let a = ate(&g, &noisy, &truth).unwrap();
        assert!(a.rmse > 0.1 && a.rmse < 0.4, "{}", a.rmse);
    }

    #[test]
    fn a_rigid_motion_in_space_has_zero_ate() {
        let mut g = PoseGraph::<Pose3>::default();
        let truth: HashMap<u64, Pose3> = (0..5)
            .map(|i| {
                (
                    i,
                    Pose3::from_xyz_rpy([i as f64, (i * i) as f64, (i % 2) as f64, 0.0, 0.0, 0.0]),
                )
            })
            .collect();
        for i in 0..5 {
            g.add_keyframe(i, None).unwrap();
        }
        let m = Pose3::from_xyz_rpy([3.0, -1.0, 2.0, 0.4, -1.2, 2.8]);
        let moved: Vec<Pose3> = (0..5).map(|i| m.compose(&truth[&i])).collect();
        let a = ate(&g, &moved, &truth).unwrap();
        assert!(a.rmse < 1e-12 && a.matched == 5, "{}", a.rmse);
        let mut noisy = moved.clone();
        noisy[2].translation.z += 0.5;
        // one point off by 0.5 among five: the aligned RMSE lies below 0.5/√5
        let a = ate(&g, &noisy, &truth).unwrap();
        assert!(a.rmse > 0.05 && a.rmse < 0.5 / 5f64.sqrt(), "{}", a.rmse);
    }
}
