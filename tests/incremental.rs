//! The incremental engine against batch solves: its published estimate
//! recovers noise-free graphs exactly, keeps sampled snapshots within 1.3×
//! of their prefix's optimum, and reaches the optimum after a re-solve.

use slamd::engine::{EdgeInput, Engine, EngineConfig, EngineError, FactorWork};
use slamd::geometry::Pose2;
use slamd::graph::{chi2, EdgeKind, GraphError, Information, PoseGraph};
use slamd_tests::{max_pose_error, noise_free, read, replay, walk};

/// χ² of the batch optimum of `g` (two-stage start, polished).
fn optimum(g: &PoseGraph) -> f64 {
    slamd_tests::optimum(g).chi2
}

fn snapshot_poses(engine: &Engine) -> Vec<Pose2> {
    engine.snapshot().poses().map(|(_, p)| p).collect()
}

#[test]
fn noise_free_graph_is_recovered_at_every_step() {
    let truth = walk(&[(1.0, 0.0, 0.5); 40]);
    let mut pairs: Vec<(usize, usize)> = (1..truth.len()).map(|k| (k - 1, k)).collect();
    pairs.extend([(0, 12), (3, 30), (10, 40), (25, 39)]);
    let g = noise_free(&truth, &pairs);
    let config = EngineConfig {
        background: false,
        ..EngineConfig::default()
    };
    replay(&g, config, |k, engine| {
        let err = max_pose_error(&snapshot_poses(engine), &truth[..=k]);
        assert!(err < 1e-9, "keyframe {k}: error {err:e}");
        assert!(engine.snapshot().chi2 < 1e-12);
    });
}

#[test]
fn snapshots_stay_near_their_prefix_optimum_and_the_end_is_optimal() {
    let g = read("manhattanolson3500_g2oversion.g2o").prefix(1500);
    let samples = [199, 399, 599, 799, 999, 1199, 1499];
    let mut checked = Vec::new();
    let config = EngineConfig {
        background: false,
        ..EngineConfig::default()
    };
    let (mut engine, _) = replay(&g, config, |k, engine| {
        if samples.contains(&k) {
            checked.push((k, snapshot_poses(engine)));
        }
    });
    for (k, poses) in checked {
        let prefix = g.prefix(k + 1);
        let best = optimum(&prefix);
        let ratio = chi2(&prefix, &poses) / best;
        assert!(
            ratio <= 1.3,
            "keyframe {k}: snapshot χ² {ratio:.3}× the prefix optimum"
        );
    }
    engine.resolve_now();
    let end = chi2(&g, &snapshot_poses(&engine));
    let best = optimum(&g);
    assert!(end <= 1.001 * best, "after the re-solve: {end} vs {best}");
}

/// The work counters are the foreground's in all: they never fall back
/// when a rebuilt state takes over (its own counters start again), and
/// each keyframe with edges adds to them.
#[test]
fn the_work_counters_add_up_across_rebuilds() {
    let g = read("manhattanolson3500_g2oversion.g2o").prefix(600);
    let config = EngineConfig {
        background: false,
        ..EngineConfig::default()
    };
    let (mut last, mut grew) = (FactorWork::default(), 0);
    let (mut engine, _) = replay(&g, config, |k, engine| {
        let w = engine.stats().work;
        assert!(
            w.walked >= last.walked && w.solved >= last.solved,
            "keyframe {k}: {w:?} after {last:?}"
        );
        grew += usize::from(w.walked > last.walked && w.solved > last.solved);
        last = w;
    });
    let stats = engine.stats();
    assert!(
        stats.resolves + stats.refreshes + stats.relinearisations > 0,
        "the prefix rebuilds its state: {stats:?}"
    );
    assert!(grew >= 590, "{grew} of 599 keyframes added work");
    engine.resolve_now();
    let end = engine.stats().work;
    assert!(
        end.walked >= last.walked && end.solved >= last.solved,
        "{end:?} after {last:?}"
    );
}

#[test]
fn removing_and_restoring_a_loop_closure_round_trips() {
    let g = read("intel_sesync.g2o").prefix(300);
    let config = EngineConfig {
        background: false,
        resolve_every_edges: 0,
        resolve_fill_ratio: 0.0,
        nonlinear_ratio: 0.0,
        wildfire_threshold: 0.0,
        ..EngineConfig::default()
    };
    let (mut engine, _) = replay(&g, config, |_, _| {});
    let before = snapshot_poses(&engine);
    let lc = (0..g.edges().len())
        .find(|&e| engine.graph().edges()[e].kind == EdgeKind::LoopClosure)
        .unwrap();
    engine.remove_edge(lc).unwrap();
    engine.update();
    let removed = snapshot_poses(&engine);
    assert!(
        max_pose_error(&removed, &before) > 1e-6,
        "removing a loop closure must move something"
    );
    engine.set_edge_weight(lc, 1.0).unwrap();
    engine.update();
    let restored = snapshot_poses(&engine);
    assert!(
        max_pose_error(&restored, &before) < 1e-8,
        "{:e}",
        max_pose_error(&restored, &before)
    );
}

#[test]
fn bad_changes_are_refused_and_leave_nothing_behind() {
    let mut config = EngineConfig {
        resolve_every_edges: 0,
        resolve_fill_ratio: 0.0,
        nonlinear_ratio: 0.0,
        background: false,
        ..EngineConfig::default()
    };
    config.outliers.enabled = false;
    let mut engine = Engine::new(config);
    engine.add_keyframe(10, None).unwrap();
    engine.add_keyframe(11, None).unwrap();
    let info = Information::identity();
    let odo = engine
        .add_edge(EdgeInput::new(
            10,
            11,
            Pose2::new(1.0, 0.0, 0.0),
            info,
            EdgeKind::Odometry,
        ))
        .unwrap();
    assert_eq!(
        engine.add_keyframe(11, None),
        Err(EngineError::Graph(GraphError::DuplicateKeyframe(11)))
    );
    assert_eq!(
        engine.add_edge(EdgeInput::new(
            10,
            99,
            Pose2::IDENTITY,
            info,
            EdgeKind::LoopClosure
        )),
        Err(EngineError::Graph(GraphError::UnknownKeyframe(99)))
    );
    assert_eq!(
        engine.add_edge(EdgeInput::new(
            11,
            11,
            Pose2::IDENTITY,
            info,
            EdgeKind::LoopClosure
        )),
        Err(EngineError::Graph(GraphError::SelfEdge(11)))
    );
    assert_eq!(
        engine.add_edge(EdgeInput::new(
            10,
            11,
            Pose2::new(f64::NAN, 0.0, 0.0),
            info,
            EdgeKind::Other
        )),
        Err(EngineError::Graph(GraphError::NonFinite("edge measurement")))
    );
    assert_eq!(engine.remove_edge(odo), Err(EngineError::OdometrySwitch(odo)));
    assert!(
        matches!(engine.set_edge_weight(odo, f64::NAN), Err(EngineError::InvalidWeight(w)) if w.is_nan())
    );
    assert_eq!(
        engine.set_edge_weight(odo, -1.0),
        Err(EngineError::InvalidWeight(-1.0))
    );
    assert_eq!(engine.set_edge_weight(7, 1.0), Err(EngineError::UnknownEdge(7)));
    let report = engine.update();
    assert_eq!(engine.graph().edges().len(), 1);
    assert_eq!(engine.snapshot().len(), 2);
    assert!(report.chi2 < 1e-20);
    let p = engine.snapshot().pose(1).unwrap();
    assert!((p.x - 1.0).abs() < 1e-12);
}

/// Streams `g` into an engine with `config` (the filter off), starting a
/// background re-solve just before keyframe `at` and then sleeping
/// `pause_ms`; updates after each keyframe below `update_below`. The
/// closing re-solve must then reach the batch optimum to 1e-6.
fn close_after_a_resolve_at(
    g: &PoseGraph,
    mut config: EngineConfig,
    at: usize,
    pause_ms: u64,
    update_below: usize,
) -> Engine {
    config.outliers.enabled = false;
    let mut engine = Engine::new(config);
    for (k, group) in g.by_newer().iter().enumerate() {
        if k == at {
            engine.idle();
            assert!(engine.resolving());
            std::thread::sleep(std::time::Duration::from_millis(pause_ms));
        }
        engine.add_keyframe(g.id_of(k), None).unwrap();
        for &e in group {
            engine.add_edge(g.edge_input(e)).unwrap();
        }
        if k < update_below {
            engine.update();
        }
    }
    engine.resolve_now();
    let best = optimum(g);
    let got = chi2(g, &snapshot_poses(&engine));
    assert!(
        (got - best).abs() <= 1e-6 * best,
        "χ² {got} after the closing re-solve, optimum {best}"
    );
    engine
}

#[test]
fn the_closing_resolve_polishes_what_arrived_after_a_background_resolve() {
    // a background re-solve that has drained its queue before the last
    // keyframes arrive: they reach it only through the foreground's replay
    // at the swap
    let config = EngineConfig {
        resolve_every_edges: 0,
        resolve_fill_ratio: 0.0,
        nonlinear_ratio: 0.0,
        ..EngineConfig::default()
    };
    let g = read("manhattanolson3500_g2oversion.g2o").prefix(600);
    close_after_a_resolve_at(&g, config, 450, 400, 450);
}

/// The worst snapshot-to-prefix-optimum χ² ratio over every 25th of
/// Manhattan's first 1,400 keyframes, replayed inline with
/// `relinearise_ratio`, and how many relinearisations it made.
fn worst_ratio_on_manhattan(relinearise_ratio: f64) -> (f64, usize) {
    let g = read("manhattanolson3500_g2oversion.g2o").prefix(1400);
    let config = EngineConfig {
        background: false,
        relinearise_ratio,
        ..EngineConfig::default()
    };
    let mut checked = Vec::new();
    let (engine, _) = replay(&g, config, |k, engine| {
        if k % 25 == 24 {
            checked.push((k, snapshot_poses(engine)));
        }
    });
    let worst = checked
        .into_iter()
        .map(|(k, poses)| {
            let prefix = g.prefix(k + 1);
            chi2(&prefix, &poses) / optimum(&prefix)
        })
        .fold(0.0, f64::max);
    (worst, engine.stats().relinearisations)
}

#[test]
fn relinearising_a_stale_linear_model_keeps_snapshots_near_the_optimum() {
    // the Gauss–Newton step from a stale linearisation lands up to 40%
    // above the optimum while its own model predicts within 1.5× (keyframe
    // 574: 1.40); relinearising past 1.2× brings every sample within 1.3×
    let (stale, none) = worst_ratio_on_manhattan(0.0);
    let (fresh, relinearisations) = worst_ratio_on_manhattan(1.2);
    assert_eq!(none, 0);
    assert!(relinearisations > 0);
    assert!(fresh <= 1.3, "worst snapshot {fresh:.3}× its prefix optimum");
    assert!(fresh < stale, "{fresh:.3} relinearised against {stale:.3}");
}

#[test]
fn a_factor_refactorised_while_a_resolve_runs_still_reaches_the_optimum() {
    // any growth while the re-solve runs calls for a fresh ordering, and
    // a multi-start re-solve of 2,000 keyframes outlasts the foreground's
    // next keyframes
    let config = EngineConfig {
        resolve_every_edges: 0,
        refresh_every_edges: 0,
        resolve_fill_ratio: 1.01,
        ..EngineConfig::default()
    };
    let g = read("city10000.g2o").prefix(2600);
    let engine = close_after_a_resolve_at(&g, config, 2000, 0, usize::MAX);
    assert!(
        engine.stats().reorders > 0,
        "no refactorisation while the re-solve ran"
    );
}

/// The first keyframe fixes the gauge at its guess: it is published there
/// before any edge and after, and the keyframe after it one odometry step
/// away.
#[test]
fn the_first_keyframe_stays_at_its_guess() {
    let mut engine = Engine::new(EngineConfig {
        background: false,
        ..EngineConfig::default()
    });
    let start = Pose2::new(5.0, -3.0, 0.5);
    let step = Pose2::new(1.0, 0.0, 0.2);
    engine.add_keyframe(7, Some(start)).unwrap();
    engine.update();
    assert_eq!(engine.snapshot().poses().collect::<Vec<_>>(), vec![(7, start)]);
    engine.add_keyframe(8, None).unwrap();
    let odometry = EdgeInput::new(7, 8, step, Information::identity(), EdgeKind::Odometry);
    engine.add_edge(odometry).unwrap();
    engine.update();
    let poses: Vec<_> = engine.snapshot().poses().collect();
    assert_eq!(poses.len(), 2);
    assert_eq!(poses[0], (7, start));
    assert_eq!(poses[1].0, 8);
    let error = max_pose_error(&[poses[1].1], &[start.compose(&step)]);
    assert!(error < 1e-12, "{error:e}");
}

/// Between re-solves the background thread relinearises and
/// refactorises (a refresh, every `refresh_every_edges` new edges while
/// it is free). Intel streamed with the stream waiting for each
/// background job to swap in, so that machine load cannot starve one:
/// refreshes swap in, and the stream still ends at the optimum.
#[test]
fn a_stream_refreshes_in_the_background() {
    let g = read("intel_sesync.g2o");
    let mut config = EngineConfig::default();
    config.outliers.enabled = false;
    let (mut engine, _) = replay(&g, config, |_, engine| {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        while engine.resolving() {
            assert!(
                std::time::Instant::now() < deadline,
                "a background job never swapped in"
            );
            std::thread::sleep(std::time::Duration::from_millis(1));
            engine.update();
        }
    });
    let stats = engine.stats();
    assert!(
        stats.refreshes >= 10,
        "{} refreshes over {} edges",
        stats.refreshes,
        g.edges().len()
    );
    let chi2 = engine.resolve_now().chi2;
    assert!((chi2 - 45.005).abs() < 1e-3, "final χ² {chi2}");
}
