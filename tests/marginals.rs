//! Marginal covariances against the dense inverse of the information
//! matrix, built here from numerical Jacobians.
//!
//! `H = Σ Jᵀ Ω J`, with `J` the edge error's derivative in each pose's
//! body-frame tangent (`X · Exp(ξ)`, translation then rotation) by a
//! five-point central difference. The gauge keyframe's rows are left out
//! (it is held fixed), and `H⁻¹` is inverted densely. The engine's
//! marginals and joint marginals must equal its blocks, turned into the
//! frame of the estimate they are published with, to 1e-9:
//! - at arbitrary (noisy, unsolved) poses, through a restored map whose
//!   loop closures carry switches in [0.3, 1] (information weighed `s²`),
//!   so that the residuals are not zero and the weights count;
//! - on a noise-free graph streamed keyframe by keyframe, so that the
//!   factor is the one the incremental updates built.

use nalgebra::{DMatrix, UnitQuaternion, Vector3};
use proptest::prelude::*;
use slamd::engine::{Engine, EngineConfig, EngineError, EnginePose};
use slamd::geometry::Pose2;
use slamd::graph::{edge_error, Edge, EdgeKind, Information, Information6, Pose3, PoseGraph};
use slamd::store::MapFile;
use std::f64::consts::PI;

/// What the numerical Hessian needs of a pose type.
trait Numeric: EnginePose + Copy {
    const D: usize;
    /// `self · Exp(ξ)` to first order (the engine's tangent convention).
    fn perturbed(&self, xi: &[f64]) -> Self;
    fn error(edge: &Edge<Self>, xi: &Self, xj: &Self) -> Vec<f64>;
    fn omega(edge: &Edge<Self>) -> DMatrix<f64>;
    /// `T` with `ξ_to = T ξ_from` for one step `δ` of the engine, written in
    /// the body frames of `from` (the linearisation point) and `to` (the
    /// published estimate).
    fn turn(from: &Self, to: &Self) -> DMatrix<f64>;
}

impl Numeric for Pose2 {
    const D: usize = 3;
    fn perturbed(&self, xi: &[f64]) -> Self {
        self.compose(&Pose2::new(xi[0], xi[1], xi[2]))
    }
    fn error(edge: &Edge, xi: &Pose2, xj: &Pose2) -> Vec<f64> {
        edge_error(edge, xi, xj).to_vec()
    }
    fn omega(edge: &Edge) -> DMatrix<f64> {
        DMatrix::from_iterator(3, 3, edge.information.matrix().iter().copied())
    }
    /// The planar step is additive in the map frame, so its covariance is
    /// the estimate's: turn by the heading between the two.
    fn turn(from: &Pose2, to: &Pose2) -> DMatrix<f64> {
        let (s, c) = (from.theta - to.theta).sin_cos();
        DMatrix::from_row_slice(3, 3, &[c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0])
    }
}

impl Numeric for Pose3 {
    const D: usize = 6;
    fn perturbed(&self, xi: &[f64]) -> Self {
        let t = Vector3::new(xi[0], xi[1], xi[2]);
        let r = UnitQuaternion::from_scaled_axis(Vector3::new(xi[3], xi[4], xi[5]));
        self.compose(&Pose3::new(t, r))
    }
    fn error(edge: &Edge<Pose3>, xi: &Pose3, xj: &Pose3) -> Vec<f64> {
        edge_error(edge, xi, xj).to_vec()
    }
    fn omega(edge: &Edge<Pose3>) -> DMatrix<f64> {
        DMatrix::from_iterator(6, 6, edge.information.matrix().iter().copied())
    }
    /// The spatial step is in the linearisation point's frame already.
    fn turn(_: &Pose3, _: &Pose3) -> DMatrix<f64> {
        DMatrix::identity(6, 6)
    }
}

/// `∂e/∂ξ` of `edge` in the tangent of one of its poses, by the
/// five-point stencil.
fn jacobian<P: Numeric>(edge: &Edge<P>, poses: &[P], of: usize) -> DMatrix<f64> {
    let h = 1e-3;
    let mut j = DMatrix::zeros(P::D, P::D);
    for c in 0..P::D {
        let at = |step: f64| {
            let mut xi = vec![0.0; P::D];
            xi[c] = step;
            let mut p = poses.to_vec();
            p[of] = p[of].perturbed(&xi);
            P::error(edge, &p[edge.from], &p[edge.to])
        };
        let (m2, m1, p1, p2) = (at(-2.0 * h), at(-h), at(h), at(2.0 * h));
        for r in 0..P::D {
            j[(r, c)] = (m2[r] - 8.0 * m1[r] + 8.0 * p1[r] - p2[r]) / (12.0 * h);
        }
    }
    j
}

/// `H⁻¹` over keyframes `1..n` (the gauge's rows left out), dense, each
/// edge's information scaled by `weight[e]`.
fn dense_covariance<P: Numeric>(graph: &PoseGraph<P>, poses: &[P], weight: &[f64]) -> DMatrix<f64> {
    let d = P::D;
    let n = poses.len() - 1;
    let mut h = DMatrix::zeros(d * n, d * n);
    for (edge, w) in graph.edges().iter().zip(weight) {
        let ends = [edge.from, edge.to];
        let js = ends.map(|k| jacobian(edge, poses, k));
        let omega = P::omega(edge) * *w;
        for (a, ka) in ends.iter().enumerate() {
            for (b, kb) in ends.iter().enumerate() {
                if *ka == 0 || *kb == 0 {
                    continue;
                }
                let block = js[a].transpose() * &omega * &js[b];
                let mut view = h.view_mut(((ka - 1) * d, (kb - 1) * d), (d, d));
                view += block;
            }
        }
    }
    h.try_inverse().expect("the graph holds every keyframe")
}

/// Block `(a, b)` of the covariance over all keyframes (zero on the gauge).
fn block(sigma: &DMatrix<f64>, d: usize, a: usize, b: usize) -> DMatrix<f64> {
    if a == 0 || b == 0 {
        return DMatrix::zeros(d, d);
    }
    sigma.view(((a - 1) * d, (b - 1) * d), (d, d)).into_owned()
}

fn assert_close(got: &DMatrix<f64>, want: &DMatrix<f64>, what: &str) -> Result<(), TestCaseError> {
    prop_assert_eq!(got.shape(), want.shape());
    let scale = want.diagonal().iter().fold(1e-12_f64, |m, v| m.max(v.abs()));
    let err = (got - want).amax();
    prop_assert!(
        err <= 1e-9 * scale,
        "{}: off by {:e} (scale {:e})\n{}\n{}",
        what,
        err,
        scale,
        got,
        want
    );
    Ok(())
}

/// Checks every keyframe's marginal and the joint marginals of `pairs`,
/// the engine linearised at `poses` with edge `e`'s information weighed
/// `weight[e]`: `H⁻¹` there, each block turned into the frame of the
/// estimate it is published with.
fn check_engine<P: Numeric>(
    engine: &mut Engine<P>,
    graph: &PoseGraph<P>,
    poses: &[P],
    weight: &[f64],
    pairs: &[(usize, usize)],
) -> Result<(), TestCaseError> {
    let d = P::D;
    let sigma = dense_covariance(graph, poses, weight);
    let estimate: Vec<P> = engine.snapshot().poses().map(|(_, p)| p).collect();
    prop_assert_eq!(estimate.len(), poses.len());
    let turn: Vec<DMatrix<f64>> = poses.iter().zip(&estimate).map(|(l, e)| P::turn(l, e)).collect();
    let want = |x: usize, y: usize| &turn[x] * block(&sigma, d, x, y) * turn[y].transpose();
    for k in 0..poses.len() {
        let got = engine
            .marginal(k as u64)
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        assert_close(&got, &want(k, k), &format!("marginal {k}"))?;
    }
    for &(a, b) in pairs {
        let got = engine
            .joint_marginal(a as u64, b as u64)
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        let mut joint = DMatrix::zeros(2 * d, 2 * d);
        for (r, x) in [a, b].into_iter().enumerate() {
            for (c, y) in [a, b].into_iter().enumerate() {
                joint.view_mut((r * d, c * d), (d, d)).copy_from(&want(x, y));
            }
        }
        let want = joint;
        assert_close(&got, &want, &format!("joint marginal {a}, {b}"))?;
    }
    Ok(())
}

fn config() -> EngineConfig {
    let mut config = EngineConfig {
        background: false,
        ..EngineConfig::default()
    };
    config.outliers.enabled = false;
    config
}

/// A walk of `steps` from the origin, as 2-D poses.
fn walk2(steps: &[[f64; 3]]) -> Vec<Pose2> {
    let mut poses = vec![Pose2::new(0.0, 0.0, 0.0)];
    for s in steps {
        let last = *poses.last().expect("non-empty");
        poses.push(last.compose(&Pose2::new(s[0], s[1], s[2])));
    }
    poses
}

/// A walk of `steps` from the origin, as 3-D poses.
fn walk3(steps: &[[f64; 6]]) -> Vec<Pose3> {
    let mut poses = vec![Pose3::from_xyz_rpy([0.0; 6])];
    for s in steps {
        let last = *poses.last().expect("non-empty");
        poses.push(last.compose(&Pose3::from_xyz_rpy(*s)));
    }
    poses
}

/// Odometry along the walk plus loop closures `loops` (pairs taken modulo
/// the length, self-pairs dropped), measuring `truth` after `noise`.
fn graph_of<P: Numeric>(
    truth: &[P],
    loops: &[(usize, usize)],
    mut measure: impl FnMut(usize, &P) -> (P, P::Information),
) -> (PoseGraph<P>, Vec<(usize, usize)>) {
    let n = truth.len();
    let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
    for &(a, b) in loops {
        let (a, b) = (a % n, b % n);
        if a != b && !pairs.contains(&(a.min(b), a.max(b))) {
            pairs.push((a.min(b), a.max(b)));
        }
    }
    let mut g = PoseGraph::<P>::default();
    for (k, pose) in truth.iter().enumerate() {
        g.add_keyframe(k as u64, Some(*pose)).expect("fresh ids");
    }
    for (e, &(i, j)) in pairs.iter().enumerate() {
        let (z, info) = measure(e, &truth[i].between(&truth[j]));
        let (a, b) = (i as u64, j as u64);
        g.add_edge(a, b, z, info, EdgeKind::from_ids(a, b))
            .expect("valid edge");
    }
    (g, pairs)
}

fn information2(w: [f64; 3]) -> Information {
    let (a, b, c) = (1.0 + 99.0 * w[0], 1.0 + 99.0 * w[1], 10.0 + 990.0 * w[2]);
    Information::from_upper([a, 0.3 * (a * b).sqrt() * (w[2] - 0.5), 0.0, b, 0.1, c])
        .expect("positive definite")
}

fn information3(w: [f64; 3]) -> Information6 {
    let mut u = Information6::identity().upper();
    // diagonal entries of the upper triangle, row by row
    for (r, idx) in [0usize, 6, 11, 15, 18, 20].into_iter().enumerate() {
        u[idx] = if r < 3 {
            1.0 + 99.0 * w[r]
        } else {
            10.0 + 990.0 * w[r - 3]
        };
    }
    u[1] = 0.2 * (u[0] * u[6]).sqrt() * (w[2] - 0.5);
    Information6::from_upper(u).expect("positive definite")
}

/// The map of `graph` at `poses` with each loop closure's switch taken
/// from `switches` (odometry is never switched), and the weight `s²` each
/// edge's information then carries.
fn switched<P: Numeric>(graph: &PoseGraph<P>, poses: &[P], switches: &[f64]) -> (MapFile<P>, Vec<f64>) {
    let mut map = MapFile::solved(graph, poses);
    let mut weight = Vec::new();
    for (e, edge) in map.edges.iter_mut().enumerate() {
        if edge.edge.kind != EdgeKind::Odometry {
            edge.switch = switches[e];
        }
        weight.push(edge.switch * edge.switch);
    }
    (map, weight)
}

/// Streams `graph` keyframe by keyframe with one update each.
fn stream<P: Numeric>(graph: &PoseGraph<P>) -> Engine<P> {
    let mut engine = Engine::<P>::create(config());
    for (k, group) in graph.by_newer().iter().enumerate() {
        engine.add_keyframe(graph.id_of(k), None).expect("a new keyframe");
        for &e in group {
            engine.add_edge(graph.edge_input(e)).expect("a known keyframe");
        }
        engine.update();
    }
    engine
}

fn step2() -> impl Strategy<Value = [f64; 3]> {
    [-2.0..2.0f64, -2.0..2.0, -PI..PI]
}

fn step3() -> impl Strategy<Value = [f64; 6]> {
    [-2.0..2.0f64, -2.0..2.0, -2.0..2.0, -PI..PI, -1.2..1.2, -PI..PI]
}

fn loops() -> impl Strategy<Value = Vec<(usize, usize)>> {
    prop::collection::vec((0usize..40, 0usize..40), 1..6)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

    /// Planar graphs with noisy edges, factorised at the noisy walk.
    #[test]
    fn planar_marginals_at_unsolved_poses(
        steps in prop::collection::vec(step2(), 2..10),
        loops in loops(),
        noise in prop::collection::vec(step2(), 60),
        weights in prop::collection::vec([0.0..1.0f64, 0.0..1.0, 0.0..1.0], 60),
        pairs in prop::collection::vec((0usize..12, 0usize..12), 3),
        switches in prop::collection::vec(0.3..1.0f64, 60),
    ) {
        let truth = walk2(&steps);
        let (g, _) = graph_of(&truth, &loops, |e, t| {
            let n = noise[e];
            (t.compose(&Pose2::new(0.05 * n[0], 0.05 * n[1], 0.02 * n[2])), information2(weights[e]))
        });
        let (map, weight) = switched(&g, &truth, &switches);
        let mut engine = Engine::restore(config(), map, false)
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        let n = truth.len();
        let pairs: Vec<_> = pairs.iter().map(|&(a, b)| (a % n, b % n)).collect();
        check_engine(&mut engine, &g, &truth, &weight, &pairs)?;
    }

    /// Spatial graphs with noisy edges, factorised at the noisy walk.
    #[test]
    fn spatial_marginals_at_unsolved_poses(
        steps in prop::collection::vec(step3(), 2..8),
        loops in loops(),
        noise in prop::collection::vec(step3(), 60),
        weights in prop::collection::vec([0.0..1.0f64, 0.0..1.0, 0.0..1.0], 60),
        pairs in prop::collection::vec((0usize..12, 0usize..12), 3),
        switches in prop::collection::vec(0.3..1.0f64, 60),
    ) {
        let truth = walk3(&steps);
        let (g, _) = graph_of(&truth, &loops, |e, t| {
            let n = noise[e].map(|v| 0.02 * v);
            (t.compose(&Pose3::from_xyz_rpy(n)), information3(weights[e]))
        });
        let (map, weight) = switched(&g, &truth, &switches);
        let mut engine = Engine::restore(config(), map, false)
            .map_err(|e| TestCaseError::fail(e.to_string()))?;
        let n = truth.len();
        let pairs: Vec<_> = pairs.iter().map(|&(a, b)| (a % n, b % n)).collect();
        check_engine(&mut engine, &g, &truth, &weight, &pairs)?;
    }

    /// Noise-free planar graphs streamed through the incremental factor.
    #[test]
    fn planar_marginals_of_the_streamed_factor(
        steps in prop::collection::vec(step2(), 2..12),
        loops in loops(),
        weights in prop::collection::vec([0.0..1.0f64, 0.0..1.0, 0.0..1.0], 60),
    ) {
        let truth = walk2(&steps);
        let (g, pairs) = graph_of(&truth, &loops, |e, t| (*t, information2(weights[e])));
        let mut engine = stream(&g);
        let weight = vec![1.0; g.edges().len()];
        check_engine(&mut engine, &g, &truth, &weight, &pairs)?;
    }

    /// Noise-free spatial graphs streamed through the incremental factor.
    #[test]
    fn spatial_marginals_of_the_streamed_factor(
        steps in prop::collection::vec(step3(), 2..10),
        loops in loops(),
        weights in prop::collection::vec([0.0..1.0f64, 0.0..1.0, 0.0..1.0], 60),
    ) {
        let truth = walk3(&steps);
        let (g, pairs) = graph_of(&truth, &loops, |e, t| (*t, information3(weights[e])));
        let mut engine = stream(&g);
        let weight = vec![1.0; g.edges().len()];
        check_engine(&mut engine, &g, &truth, &weight, &pairs)?;
    }
}

#[test]
fn marginals_of_unknown_and_unjoined_keyframes_are_refused() {
    let mut engine = Engine::new(config());
    engine.add_keyframe(0, None).expect("gauge");
    engine.add_keyframe(1, None).expect("fresh id");
    let err = engine.marginal(7).expect_err("unknown");
    assert_eq!(err.to_string(), "no covariance for keyframe 7: no such keyframe");
    let err = engine.marginal(1).expect_err("not joined");
    assert!(matches!(err, EngineError::NoCovariance(1, _)), "{err}");
    assert_eq!(
        err.to_string(),
        "no covariance for keyframe 1: it has no edge to the map yet"
    );
    // the gauge is held fixed
    assert_eq!(engine.marginal(0).expect("the gauge"), DMatrix::zeros(3, 3));
}

/// One odometry edge: keyframe 1's covariance is the edge's, turned into
/// keyframe 1's frame.
#[test]
fn one_edge_gives_its_own_covariance_in_the_body_frame() {
    let mut engine = Engine::new(config());
    engine
        .add_keyframe(0, Some(Pose2::new(0.0, 0.0, 0.0)))
        .expect("gauge");
    engine.add_keyframe(1, None).expect("fresh id");
    let info = Information::from_upper([4.0, 0.0, 0.0, 1.0, 0.0, 25.0]).expect("positive definite");
    let z = Pose2::new(1.0, 0.0, 0.7);
    engine
        .add_edge(slamd::engine::EdgeInput::new(0, 1, z, info, EdgeKind::Odometry))
        .expect("known keyframes");
    engine.update();
    let sigma = engine.marginal(1).expect("joined");
    // e_t = R(θ_z)ᵀ(R0ᵀ(t1 − t0) − t_z): a body step ξ of keyframe 1 moves
    // its position by R1 ξ_t = R(0.7) ξ_t, so e_t = ξ_t and Σ = Ω⁻¹,
    // not turned by the heading (in the map frame it would be).
    let want = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(vec![0.25, 1.0, 0.04]));
    assert!((&sigma - &want).amax() < 1e-12, "{sigma}");
}
