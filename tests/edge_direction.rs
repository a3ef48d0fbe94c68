//! An edge means what its writer wrote, whichever keyframe is newer
//! (docs/design.md, "Edge direction").
//!
//! - A loop closure written newer-first, `(i, j, Z, Ω)` with `i > j`, and
//!   the same measurement written older-first, `(j, i, Z⁻¹, Ω')` with
//!   `Ω' = Ad_Z⁻ᵀ Ω Ad_Z⁻¹`, are one noise model to first order: with
//!   residuals of 1e-5 the two maps agree to 1e-9 (they differ by the
//!   square of the residuals), in the batch polish and in the engine.
//!   Kept unrotated, `(j, i, Z⁻¹, Ω)` is another noise model and another map.
//! - Random noisy graphs with anisotropic information and newer-first
//!   edges, 2-D and 3-D: the polished map is a stationary point of g2o's
//!   cost of the edges as written, evaluated here from the poses alone, and
//!   the χ² slamd reports is that cost.

use nalgebra::{Matrix3, Matrix6, SMatrix, SVector, UnitQuaternion, Vector3, Vector6};
use proptest::prelude::*;
use slamd::engine::EngineConfig;
use slamd::geometry::{wrap_angle, Pose2};
use slamd::graph::{EdgeKind, Information, Information6, Pose3, PoseGraph};
use slamd::solver::{solve_batch, BatchOptions};
use slamd_tests::{max_pose_error, replay, walk};
use std::f64::consts::{FRAC_PI_2, PI};

fn polished(g: &PoseGraph) -> Vec<Pose2> {
    let options = BatchOptions {
        polish: true,
        ..Default::default()
    };
    solve_batch(g, &options).expect("connected").poses
}

/// The engine's map after every keyframe streamed and a closing re-solve.
fn streamed(g: &PoseGraph) -> Vec<Pose2> {
    let config = EngineConfig {
        background: false,
        ..EngineConfig::default()
    };
    let (mut engine, _) = replay(g, config, |_, _| {});
    engine.resolve_now();
    engine.snapshot().poses().map(|(_, p)| p).collect()
}

/// `Ad_Z` over g2o's `(x, y, θ)`: `Z Exp(ξ) Z⁻¹ = Exp(Ad_Z ξ)`.
fn adjoint(z: &Pose2) -> Matrix3<f64> {
    let (s, c) = z.theta.sin_cos();
    Matrix3::new(c, -s, z.y, s, c, -z.x, 0.0, 0.0, 1.0)
}

fn information(m: &Matrix3<f64>) -> Information {
    Information::from_matrix(m).expect("SPD")
}

/// Three quarter turns of 2 m, odometry off by about 1e-5, and a loop
/// closure from keyframe 3 back to 0 added by `close`.
fn three_quarters_with(close: impl Fn(&mut PoseGraph)) -> PoseGraph {
    let mut g = PoseGraph::default();
    for id in 0..4 {
        g.add_keyframe(id, None).expect("fresh id");
    }
    let odometry = Information::from_upper([100.0, 0.0, 0.0, 100.0, 0.0, 400.0]).expect("SPD");
    let noise = [(3e-5, -1e-5, 2e-5), (-2e-5, 1e-5, -1e-5), (1e-5, 2e-5, 1e-5)];
    for (k, (dx, dy, dt)) in noise.into_iter().enumerate() {
        let step = Pose2::new(2.0 + dx, dy, FRAC_PI_2 + dt);
        g.add_edge(k as u64, k as u64 + 1, step, odometry, EdgeKind::Odometry)
            .expect("valid edge");
    }
    close(&mut g);
    g
}

/// `T_30`, keyframe 0 seen from keyframe 3 (at (0, 2), turned by −90°):
/// 2 m ahead and turned by 90°, so that "across" and "along" swap between
/// the frames of the two ends; off the odometry by about 1e-5.
fn loop_closure() -> Pose2 {
    Pose2::new(2.0 - 2e-5, 1e-5, FRAC_PI_2 + 3e-5)
}

#[test]
fn an_anisotropic_loop_closure_means_the_same_written_either_way() {
    let z = loop_closure();
    let omega = Matrix3::from_diagonal(&Vector3::new(1e4, 1.0, 50.0));
    let newer_first = three_quarters_with(|g| {
        g.add_edge(3, 0, z, information(&omega), EdgeKind::LoopClosure)
            .expect("valid edge");
    });
    let ad_inv = adjoint(&z).try_inverse().expect("invertible");
    let turned = ad_inv.transpose() * omega * ad_inv;
    let older_first = three_quarters_with(|g| {
        g.add_edge(0, 3, z.inverse(), information(&turned), EdgeKind::LoopClosure)
            .expect("valid edge");
    });
    let kept = three_quarters_with(|g| {
        g.add_edge(0, 3, z.inverse(), information(&omega), EdgeKind::LoopClosure)
            .expect("valid edge");
    });
    for (what, solve) in [
        ("batch", polished as fn(&PoseGraph) -> Vec<Pose2>),
        ("engine", streamed),
    ] {
        let (a, b, c) = (solve(&newer_first), solve(&older_first), solve(&kept));
        let same = max_pose_error(&a, &b);
        assert!(
            same < 1e-9,
            "{what}: newer-first and older-first differ by {same:e}"
        );
        let other = max_pose_error(&a, &c);
        assert!(
            other > 1e-7,
            "{what}: Ω kept unrotated moved the map by only {other:e}"
        );
    }
}

/// g2o's 2-D error of `(Z, xi, xj)` as written: `t2v(Z⁻¹ X_i⁻¹ X_j)`.
fn error2(z: &Pose2, xi: &Pose2, xj: &Pose2) -> Vector3<f64> {
    let d = z.inverse().compose(&xi.inverse().compose(xj));
    Vector3::new(d.x, d.y, wrap_angle(d.theta))
}

/// g2o's 3-D error as written: `[Δt, Δq_xyz]` of `Δ = Z⁻¹ X_i⁻¹ X_j`, `w ≥ 0`.
fn error3(z: &Pose3, xi: &Pose3, xj: &Pose3) -> Vector6<f64> {
    let d = z.inverse().compose(&xi.inverse().compose(xj));
    let (t, q) = (d.translation, d.canonical_quaternion());
    Vector6::new(t.x, t.y, t.z, q.i, q.j, q.k)
}

/// An edge as written: `(i, j, Z, Ω)`, over an error of `N` numbers.
type Written<P, const N: usize> = (usize, usize, P, SMatrix<f64, N, N>);

/// `Σ eᵀ Ω e` of `edges` at `poses`, with `error` g2o's error of one edge.
fn cost<P, const N: usize>(
    edges: &[Written<P, N>],
    poses: &[P],
    error: fn(&P, &P, &P) -> SVector<f64, N>,
) -> f64 {
    edges
        .iter()
        .map(|(i, j, z, o)| {
            let e = error(z, &poses[*i], &poses[*j]);
            e.dot(&(o * e))
        })
        .sum()
}

/// The largest central difference of `cost` over one coordinate of one
/// keyframe after the gauge, moved by `bump(pose, coordinate, h)`.
fn gradient<P: Copy>(
    poses: &[P],
    cost: impl Fn(&[P]) -> f64,
    bump: impl Fn(&P, usize, f64) -> P,
    dof: usize,
) -> f64 {
    let h = 1e-6;
    let mut worst = 0.0f64;
    let mut moved = poses.to_vec();
    for k in 1..poses.len() {
        for c in 0..dof {
            moved[k] = bump(&poses[k], c, h);
            let up = cost(&moved);
            moved[k] = bump(&poses[k], c, -h);
            let down = cost(&moved);
            moved[k] = poses[k];
            worst = worst.max(((up - down) / (2.0 * h)).abs());
        }
    }
    worst
}

/// An information matrix with eigenvalues `scales` on axes turned by `turn`.
fn anisotropic2(scales: [f64; 3], turn: f64) -> Matrix3<f64> {
    let r = nalgebra::Rotation2::new(turn).into_inner();
    let mut m = Matrix3::from_diagonal(&Vector3::from(scales));
    let t = r * m.fixed_view::<2, 2>(0, 0) * r.transpose();
    m.fixed_view_mut::<2, 2>(0, 0).copy_from(&t);
    m
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// 2-D: the polished map of a noisy graph with newer-first loop
    /// closures and anisotropic information is where the as-written cost
    /// has no slope, and slamd's χ² is that cost.
    #[test]
    fn newer_first_edges_reach_the_as_written_optimum_2d(
        steps in prop::collection::vec((-2.0..2.0f64, -2.0..2.0f64, -PI..PI), 3..16),
        loops in prop::collection::vec((0usize..100, 0usize..100, 0.0..PI, 0.0..4.0f64), 1..6),
        noise in prop::collection::vec(-0.05..0.05f64, 3 * 24),
    ) {
        let truth = walk(&steps);
        let n = truth.len();
        let mut pairs: Vec<(usize, usize, Matrix3<f64>)> =
            (1..n).map(|k| (k - 1, k, anisotropic2([50.0, 50.0, 200.0], 0.0))).collect();
        for &(a, b, turn, spread) in &loops {
            let (a, b) = (a % n, b % n);
            if a.abs_diff(b) > 1 {
                // newer-first, tight across and loose along a turned axis
                let scale = 10f64.powf(spread);
                pairs.push((a.max(b), a.min(b), anisotropic2([scale, 1.0, 20.0], turn)));
            }
        }
        let mut g = PoseGraph::default();
        for id in 0..n as u64 {
            g.add_keyframe(id, None).expect("fresh id");
        }
        let mut written = Vec::new();
        for (k, (i, j, omega)) in pairs.into_iter().enumerate() {
            let exact = truth[i].between(&truth[j]);
            let at = |r: usize| noise[(3 * k + r) % noise.len()];
            let z = Pose2::new(exact.x + at(0), exact.y + at(1), exact.theta + at(2));
            g.add_edge(i as u64, j as u64, z, information(&omega), EdgeKind::from_ids(i as u64, j as u64))
                .expect("valid edge");
            written.push((i, j, z, omega));
        }
        let options = BatchOptions { polish: true, ..Default::default() };
        let s = solve_batch(&g, &options).expect("connected");
        let chi2 = cost(&written, &s.poses, error2);
        prop_assert!((s.chi2 - chi2).abs() <= 1e-9 * (1.0 + chi2), "slamd χ² {} vs as written {chi2}", s.chi2);
        let bump = |p: &Pose2, c: usize, h: f64| {
            let mut v = p.to_array();
            v[c] += h;
            Pose2::new(v[0], v[1], v[2])
        };
        let slope = gradient(&s.poses, |p| cost(&written, p, error2), bump, 3);
        prop_assert!(slope < 1e-4 * (1.0 + chi2), "slope {slope:e} at χ² {chi2}");
    }

    /// 3-D: the same, with g2o's quaternion error.
    #[test]
    fn newer_first_edges_reach_the_as_written_optimum_3d(
        steps in prop::collection::vec([-1.5..1.5f64, -1.5..1.5, -1.5..1.5, -0.8..0.8, -0.8..0.8, -PI..PI], 3..12),
        loops in prop::collection::vec((0usize..100, 0usize..100, 0.0..3.0f64), 1..5),
        noise in prop::collection::vec(-0.03..0.03f64, 6 * 20),
    ) {
        let mut truth = vec![Pose3::IDENTITY];
        for s in &steps {
            let last = *truth.last().expect("non-empty");
            truth.push(last.compose(&Pose3::from_xyz_rpy(*s)));
        }
        let n = truth.len();
        let odometry = Matrix6::from_diagonal(&Vector6::new(50.0, 50.0, 50.0, 400.0, 400.0, 400.0));
        let mut pairs: Vec<(usize, usize, Matrix6<f64>)> = (1..n).map(|k| (k - 1, k, odometry)).collect();
        for &(a, b, spread) in &loops {
            let (a, b) = (a % n, b % n);
            if a.abs_diff(b) > 1 {
                let scale = 10f64.powf(spread);
                let info = Matrix6::from_diagonal(&Vector6::new(scale, 1.0, 5.0, 100.0, 30.0, 300.0));
                pairs.push((a.max(b), a.min(b), info));
            }
        }
        let mut g = PoseGraph::<Pose3>::default();
        for id in 0..n as u64 {
            g.add_keyframe(id, None).expect("fresh id");
        }
        let mut written = Vec::new();
        for (k, (i, j, omega)) in pairs.into_iter().enumerate() {
            let at = |r: usize| noise[(6 * k + r) % noise.len()];
            let wobble = Pose3::from_xyz_rpy([at(0), at(1), at(2), at(3), at(4), at(5)]);
            let z = truth[i].between(&truth[j]).compose(&wobble);
            g.add_edge(i as u64, j as u64, z, Information6::from_matrix(&omega).expect("SPD"), EdgeKind::from_ids(i as u64, j as u64))
                .expect("valid edge");
            written.push((i, j, z, omega));
        }
        let options = BatchOptions { polish: true, ..Default::default() };
        let s = solve_batch(&g, &options).expect("connected");
        let chi2 = cost(&written, &s.poses, error3);
        prop_assert!((s.chi2 - chi2).abs() <= 1e-9 * (1.0 + chi2), "slamd χ² {} vs as written {chi2}", s.chi2);
        let bump = |p: &Pose3, c: usize, h: f64| {
            let mut t = p.translation;
            let mut r = p.rotation;
            if c < 3 {
                t[c] += h;
            } else {
                let mut axis = Vector3::zeros();
                axis[c - 3] = h;
                r = UnitQuaternion::from_scaled_axis(axis) * r;
            }
            Pose3::new(t, r)
        };
        let slope = gradient(&s.poses, |p| cost(&written, p, error3), bump, 6);
        prop_assert!(slope < 1e-4 * (1.0 + chi2), "slope {slope:e} at χ² {chi2}");
    }
}
