//! 3-D graphs: noise-free chains, grids and loops are recovered exactly (to
//! 1e-9) by the chordal two-stage initialiser, with and without the polish;
//! the shared 3-D files reach their published optimum.

use proptest::prelude::*;
use slamd::graph::{EdgeKind, Information6, Pose3, PoseGraph};
use slamd::solver::{solve_batch, BatchOptions, Formulation};
use std::f64::consts::PI;

const TOL: f64 = 1e-9;

/// The graph of `truth`'s exact relative poses along `pairs`.
fn noise_free3(truth: &[Pose3], pairs: &[(usize, usize)]) -> PoseGraph<Pose3> {
    let mut g = PoseGraph::<Pose3>::default();
    for k in 0..truth.len() {
        g.add_keyframe(k as u64, None).expect("fresh ids");
    }
    let mut info = Information6::identity().upper();
    info[15] = 4.0; // anisotropic rotation, as real files have
    let info = Information6::from_upper(info).expect("positive definite");
    for &(i, j) in pairs {
        let (a, b) = (i as u64, j as u64);
        g.add_edge(a, b, truth[i].between(&truth[j]), info, EdgeKind::from_ids(a, b))
            .expect("valid edge");
    }
    g
}

/// The largest position or rotation-angle difference of `poses` from
/// `truth` expressed relative to the gauge (keyframe 0).
fn max_error(poses: &[Pose3], truth: &[Pose3]) -> f64 {
    poses
        .iter()
        .zip(truth)
        .map(|(p, t)| {
            let t = truth[0].between(t);
            (p.translation - t.translation)
                .norm()
                .max(p.rotation.angle_to(&t.rotation))
        })
        .fold(0.0, f64::max)
}

fn check(truth: &[Pose3], pairs: &[(usize, usize)]) -> Result<(), TestCaseError> {
    let g = noise_free3(truth, pairs);
    for formulation in [Formulation::TwoStage, Formulation::Odometry] {
        for polish in [false, true] {
            let options = BatchOptions {
                formulation,
                polish,
                ..Default::default()
            };
            let s = solve_batch(&g, &options).map_err(|e| TestCaseError::fail(e.to_string()))?;
            let err = max_error(&s.poses, truth);
            prop_assert!(err < TOL, "{formulation} polish={polish}: error {err:e}");
            prop_assert!(s.chi2 < 1e-12, "{formulation} polish={polish}: chi2 {}", s.chi2);
        }
    }
    Ok(())
}

fn step() -> impl Strategy<Value = [f64; 6]> {
    [-2.0..2.0f64, -2.0..2.0, -2.0..2.0, -PI..PI, -1.5..1.5, -PI..PI]
}

/// A random walk from a random start.
fn walk(start: [f64; 6], steps: &[[f64; 6]]) -> Vec<Pose3> {
    let mut poses = vec![Pose3::from_xyz_rpy(start)];
    for s in steps {
        let last = *poses.last().expect("non-empty");
        poses.push(last.compose(&Pose3::from_xyz_rpy(*s)));
    }
    poses
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    #[test]
    fn chains_with_random_loops(
        start in step(),
        steps in prop::collection::vec(step(), 2..40),
        loops in prop::collection::vec((0usize..1000, 0usize..1000), 0..15),
    ) {
        let truth = walk(start, &steps);
        let n = truth.len();
        let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
        pairs.extend(loops.into_iter().map(|(a, b)| (a % n, b % n)).filter(|(a, b)| a != b));
        check(&truth, &pairs)?;
    }

    /// A grid of storeys: every keyframe linked to its neighbours along x,
    /// y and z, each at its own orientation.
    #[test]
    fn grids(
        w in 2usize..5,
        h in 2usize..5,
        storeys in 1usize..4,
        spacing in 0.5..3.0f64,
        angles in prop::collection::vec([-PI..PI, -1.5..1.5f64, -PI..PI], 64),
    ) {
        let n = w * h * storeys;
        let truth: Vec<Pose3> = (0..n)
            .map(|k| {
                let (x, y, z) = (k % w, (k / w) % h, k / (w * h));
                let [r, p, yaw] = angles[k];
                Pose3::from_xyz_rpy([x as f64 * spacing, y as f64 * spacing, z as f64 * spacing, r, p, yaw])
            })
            .collect();
        let mut pairs = Vec::new();
        for k in 0..n {
            if k % w + 1 < w { pairs.push((k, k + 1)); }
            if (k / w) % h + 1 < h { pairs.push((k, k + w)); }
            if k + w * h < n { pairs.push((k, k + w * h)); }
        }
        check(&truth, &pairs)?;
    }

    /// Loops closed newer-id-first (stored inverted) and back to the start.
    #[test]
    fn newer_first_loops(start in step(), steps in prop::collection::vec(step(), 3..20)) {
        let truth = walk(start, &steps);
        let n = truth.len();
        let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
        pairs.push((n - 1, 0));
        pairs.push((n - 1, n / 2));
        check(&truth, &pairs)?;
    }
}

/// Sphere2500 reaches g2o's published optimum, 727.15, from nothing.
#[test]
fn sphere2500_reaches_the_published_optimum() {
    let g = slamd::io::read_graph::<Pose3>(&slamd_tests::dataset("3d/sphere2500.g2o")).expect("readable");
    let options = BatchOptions {
        polish: true,
        ..Default::default()
    };
    let s = solve_batch(&g, &options).expect("solvable");
    assert!((s.chi2 - 727.15).abs() < 0.01, "chi2 {}", s.chi2);
    assert!(s.linear_chi2 < 2.0 * s.chi2, "linear chi2 {}", s.linear_chi2);
}

/// Keyframes on a `w × h` grid 2 m apart on each of `storeys` floors 3 m
/// apart, keyframe `k` turned `yaw_step · k` about the vertical.
fn building(w: usize, h: usize, storeys: usize, yaw_step: f64) -> Vec<Pose3> {
    (0..w * h * storeys)
        .map(|k| {
            let (x, y, z) = (k % w, (k / w) % h, k / (w * h));
            Pose3::from_xyz_rpy([
                2.0 * x as f64,
                2.0 * y as f64,
                3.0 * z as f64,
                0.0,
                0.0,
                yaw_step * k as f64,
            ])
        })
        .collect()
}

/// The robust polish switches off wrong loop closures in 3-D and keeps
/// the true ones: a noise-free building of three storeys, every keyframe
/// linked to its neighbours along x, y and z, and five wrong loop
/// closures, as confident, each 3 m and 29° off.
#[test]
fn the_robust_polish_switches_off_wrong_loop_closures_in_3d() {
    let (w, h, storeys) = (4, 4, 3);
    let truth = building(w, h, storeys, 0.3);
    let n = truth.len();
    let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
    pairs.extend((0..n - w).map(|k| (k, k + w)));
    pairs.extend((0..n - w * h).map(|k| (k, k + w * h)));
    let mut g = noise_free3(&truth, &pairs);
    for e in g.edges_mut() {
        e.information = e.information.scaled(100.0);
    }
    let wrong = [(2, 40), (7, 30), (12, 45), (20, 33), (5, 25)];
    let off = Pose3::from_xyz_rpy([3.0, 0.0, 0.0, 0.0, 0.0, 0.5]);
    for &(i, j) in &wrong {
        let z = truth[i].between(&truth[j]).compose(&off);
        g.add_edge(
            i as u64,
            j as u64,
            z,
            Information6::identity().scaled(100.0),
            EdgeKind::LoopClosure,
        )
        .expect("valid edge");
    }
    let options = BatchOptions {
        robust: Some(slamd::outliers::OutlierConfig::default()),
        ..Default::default()
    };
    let s = solve_batch(&g, &options).expect("solvable");
    let switches = s.switches.expect("the robust polish gives switches");
    let first_wrong = g.edges().len() - wrong.len();
    for (e, &sw) in switches.iter().enumerate() {
        if e < first_wrong {
            assert!(sw > 0.99, "true edge {e} switched to {sw}");
        } else {
            assert!(sw < slamd::outliers::OFF_BELOW, "wrong edge {e} kept at {sw}");
        }
    }
    // what the wrong edges still pull (s² < 0.0025 of each) bends the map
    // by less than a millimetre
    let err = max_error(&s.poses, &truth);
    assert!(err < 1e-3, "error {err}");
}

/// The incremental engine on a 3-D stream: a building of three storeys
/// with small, fixed noise, streamed keyframe by keyframe (each with the
/// edges whose newer end it is), ends within 0.1% of the batch optimum of
/// its true edges; a wrong loop closure among them is switched off.
#[test]
fn the_engine_streams_a_3d_graph_to_the_batch_optimum() {
    use slamd::engine::{EdgeInput, Engine, EngineConfig};
    let (w, h, storeys) = (5, 4, 3);
    let truth = building(w, h, storeys, 0.4);
    let n = truth.len();
    let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
    pairs.extend((0..n - w).step_by(2).map(|k| (k, k + w)));
    pairs.extend((0..n - w * h).step_by(3).map(|k| (k, k + w * h)));
    let mut g = noise_free3(&truth, &pairs);
    // a small deterministic disturbance of every measurement
    for (k, e) in g.edges_mut().iter_mut().enumerate() {
        let f = k as f64;
        let d = Pose3::from_xyz_rpy([
            0.01 * (1.3 * f).sin(),
            0.01 * (0.7 * f).cos(),
            0.01 * (2.1 * f).sin(),
            0.005 * (0.9 * f).cos(),
            0.005 * (1.7 * f).sin(),
            0.005 * (0.3 * f).sin(),
        ]);
        e.measurement = e.measurement.compose(&d);
        e.information = e.information.scaled(100.0);
    }
    let wrong = truth[3]
        .between(&truth[50])
        .compose(&Pose3::from_xyz_rpy([2.0, -1.0, 0.5, 0.0, 0.3, 0.2]));
    let info = g.edges()[0].information;
    g.add_edge(3, 50, wrong, info, EdgeKind::LoopClosure)
        .expect("valid edge");
    let mut engine = Engine::<Pose3>::create(EngineConfig::default());
    // the engine numbers edges as they arrive
    let mut arrived = vec![0; g.edges().len()];
    for group in g.by_newer() {
        let k = engine.graph().len();
        engine.add_keyframe(g.id_of(k), None).expect("new keyframe");
        for e in group {
            let edge = g.edges()[e];
            let input = EdgeInput::new(
                g.id_of(edge.from),
                g.id_of(edge.to),
                edge.measurement,
                edge.information,
                edge.kind,
            );
            arrived[e] = engine.add_edge(input).expect("valid edge");
        }
        engine.update();
    }
    engine.resolve_now();
    let snap = engine.snapshot();
    assert_eq!(snap.len(), n);
    let switches: Vec<f64> = arrived.iter().map(|&a| engine.switches()[a]).collect();
    let last = switches.len() - 1;
    assert!(
        switches[last] < slamd::outliers::OFF_BELOW,
        "the wrong loop closure is at {}",
        switches[last]
    );
    assert!(
        switches[..last].iter().all(|&s| s > 0.99),
        "a true edge was switched: {switches:?}"
    );
    // the batch optimum of the true edges
    let mut clean = g.clone();
    let true_edges = clean.edges()[..last].to_vec();
    clean = PoseGraph::from_parts(clean.keyframes().to_vec(), true_edges).expect("same keyframes");
    let best = solve_batch(
        &clean,
        &BatchOptions {
            polish: true,
            ..Default::default()
        },
    )
    .expect("solvable");
    let poses: Vec<Pose3> = (0..n).map(|k| snap.pose(k).expect("joined")).collect();
    let online = slamd::graph::chi2(&clean, &poses);
    assert!(best.chi2 > 0.1, "the noise is felt: {}", best.chi2);
    // the closing polish minimises the robust cost, in which the wrong loop
    // closure still pulls a little (s² ~ 10⁻⁴): within 0.1% of the optimum
    assert!(
        online >= best.chi2 * (1.0 - 1e-9) && online <= 1.001 * best.chi2,
        "online {online} against the batch optimum {}",
        best.chi2
    );
}
