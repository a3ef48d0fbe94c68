//! The outlier filter: wrong loop closures switched off online and in
//! batch, and a wrongly rejected one restored.

use slamd::engine::{EdgeInput, Engine, EngineConfig};
use slamd::eval::ate;
use slamd::geometry::Pose2;
use slamd::graph::{EdgeKind, Information, PoseGraph};
use slamd::outliers::{OutlierConfig, REJECTED_BELOW};
use slamd::solver::{solve_batch, BatchOptions};
use slamd::synthetic::{generate, WorldParams};
use slamd_tests::{dataset, max_pose_error, run_json};
use std::collections::{BTreeSet, HashMap};
use std::process::Command;

/// [`slamd_tests::replay`], then the re-solve that ends a stream.
fn replay(graph: &PoseGraph, config: EngineConfig) -> (Engine, Vec<usize>) {
    let (mut engine, sent) = slamd_tests::replay(graph, config, |_, _| {});
    engine.resolve_now();
    (engine, sent)
}

fn poses(engine: &Engine, n: usize) -> Vec<Pose2> {
    let snap = engine.snapshot();
    (0..n)
        .map(|k| snap.pose(k).expect("every keyframe mapped"))
        .collect()
}

#[test]
fn random_wrong_loop_closures_are_switched_off_online() {
    let world = generate(&WorldParams {
        poses: 600,
        seed: 11,
        ..WorldParams::default()
    });
    let truth: HashMap<u64, Pose2> = (0..world.truth.len() as u64)
        .zip(world.truth.iter().copied())
        .collect();
    let clean = replay(&world.graph, EngineConfig::default()).0;
    let clean_ate = ate(&world.graph, &poses(&clean, 600), &truth).unwrap().rmse;

    // 60 Vertigo-style random loop closures: random ends, small measurement
    let (spoiled, first_injected) =
        slamd_tests::with_random_loop_closures(&world.graph, 60, 12345, 300.0, 0.1);
    let (engine, sent) = replay(&spoiled, EngineConfig::default());
    let switches = engine.switches();
    let switched_off: BTreeSet<usize> = (sent.iter().enumerate())
        .filter(|&(n, _)| switches[n] < REJECTED_BELOW)
        .map(|(_, &e)| e)
        .collect();
    let injected: BTreeSet<usize> = (first_injected..first_injected + 60).collect();
    let missed: Vec<_> = injected.difference(&switched_off).collect();
    assert!(missed.is_empty(), "outliers left on: {missed:?}");
    // a calibrated true loop closure is held wrong about once in a thousand
    // tests at the default Φ; allow 2 of this world's ~150
    let wrongly_off: Vec<_> = switched_off.difference(&injected).collect();
    assert!(
        wrongly_off.len() <= 2,
        "true loop closures switched off: {wrongly_off:?}"
    );
    let filtered_ate = ate(&spoiled, &poses(&engine, 600), &truth).unwrap().rmse;
    assert!(
        filtered_ate <= 1.1 * clean_ate,
        "ATE {filtered_ate} with outliers vs {clean_ate} without"
    );
    // and without the filter the same outliers bend the map
    let mut off = EngineConfig::default();
    off.outliers.enabled = false;
    let (bent, _) = replay(&spoiled, off);
    let bent_ate = ate(&spoiled, &poses(&bent, 600), &truth).unwrap().rmse;
    assert!(bent_ate > 5.0 * clean_ate, "unfiltered ATE {bent_ate}");
}

#[test]
fn a_loop_closure_rejected_on_arrival_is_restored_by_the_re_solve() {
    // a square of 4 × 10 steps whose odometry turns 0.6° too far each step
    let step = Pose2::new(1.0, 0.0, 0.0);
    let corner = Pose2::new(1.0, 0.0, std::f64::consts::FRAC_PI_2);
    let bias = Pose2::new(0.0, 0.0, 0.6f64.to_radians());
    let mut truth = vec![Pose2::IDENTITY];
    for k in 1..=40 {
        let m = if k % 10 == 0 { corner } else { step };
        truth.push(truth[k - 1].compose(&m));
    }
    let config = EngineConfig {
        background: false,
        ..EngineConfig::default()
    };
    let mut engine = Engine::new(config);
    let odometry = Information::identity();
    for k in 0..=40u64 {
        engine.add_keyframe(k, None).unwrap();
        if k > 0 {
            let (i, j) = (k as usize - 1, k as usize);
            let m = truth[i].between(&truth[j]).compose(&bias);
            let e = EdgeInput::new(k - 1, k, m, odometry, EdgeKind::Odometry);
            engine.add_edge(e).unwrap();
        }
        engine.update();
    }
    // the loop closure is exact, but the drifted estimate disagrees with it
    let close = EdgeInput::new(
        0,
        40,
        truth[0].between(&truth[40]),
        Information::identity().scaled(10.0),
        EdgeKind::LoopClosure,
    );
    let e = engine.add_edge(close).unwrap();
    engine.update();
    let on_arrival = engine.switches()[e];
    assert!(on_arrival < REJECTED_BELOW, "switch on arrival {on_arrival}");
    // the re-solve weighs it against the whole map and takes it back
    engine.resolve_now();
    let restored = engine.switches()[e];
    assert!(restored > 0.99, "switch after the re-solve {restored}");
    let p40 = engine.snapshot().pose(40).unwrap();
    assert!(p40.position().norm() < 0.1, "the loop closed: {p40:?}");
}

#[test]
fn solve_robust_reports_the_injected_edges() {
    let out = std::env::temp_dir().join(format!("slamd-test-outliers-{}.g2o", std::process::id()));
    let side = out.with_extension("g2o.outliers.json");
    let status = Command::new("python3")
        .arg(dataset("../tools/add_outliers.py"))
        .args(["-i", dataset("intel_sesync.g2o").to_str().unwrap()])
        .args([
            "-o",
            out.to_str().unwrap(),
            "--kind",
            "random",
            "--count",
            "50",
            "--seed",
            "3",
        ])
        .stdout(std::process::Stdio::null())
        .status()
        .expect("python3 runs add_outliers.py");
    assert!(status.success());
    let listed: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&side).unwrap()).unwrap();
    let injected: BTreeSet<u64> = (listed["outliers"].as_array().unwrap().iter())
        .map(|o| o["edge_index"].as_u64().unwrap())
        .collect();
    // the kernel alone, then PCM before it
    for extra in [None, Some("--pairwise")] {
        let mut args = vec!["solve", out.to_str().unwrap(), "--robust", "--json"];
        args.extend(extra);
        let r = run_json(&args);
        let rejected: BTreeSet<u64> = (r["rejected_edges"].as_array().unwrap().iter())
            .map(|v| v.as_u64().unwrap())
            .collect();
        let caught = injected.intersection(&rejected).count() as f64;
        let (precision, recall) = (caught / rejected.len() as f64, caught / injected.len() as f64);
        assert!(
            precision >= 0.99 && recall >= 0.99,
            "{extra:?}: precision {precision}, recall {recall}"
        );
    }
    std::fs::remove_file(&out).unwrap();
    std::fs::remove_file(&side).unwrap();
}

#[test]
fn the_daemon_publishes_each_loop_closures_switch() {
    use crate::daemon::Daemon;
    use slamd_client::{Frontend, Snapshots};
    use std::time::{Duration, Instant};
    let daemon = Daemon::start("switches", &[]);
    let mut f = Frontend::connect(&daemon.config()).unwrap();
    let mut snaps = Snapshots::open(&daemon.namespace).unwrap();
    // a corridor walked twice: every second keyframe of the return closes a loop
    let n = 40;
    let truth: Vec<Pose2> = (0..n)
        .map(|k| {
            if k < n / 2 {
                Pose2::new(k as f64, 0.0, 0.0)
            } else {
                Pose2::new((n - 1 - k) as f64, 1.0, std::f64::consts::PI)
            }
        })
        .collect();
    // σ = 0.1 m and 0.1 rad: stiff enough that bending to one wrong edge costs
    let info = Information::identity().scaled(100.0);
    let mut good = Vec::new();
    let mut wrong = 0;
    for k in 0..n {
        f.add_keyframe(k as u64, 0, None).unwrap();
        if k > 0 {
            let m = truth[k - 1].between(&truth[k]);
            f.add_edge(&EdgeInput::new(
                k as u64 - 1,
                k as u64,
                m,
                info,
                EdgeKind::Odometry,
            ))
            .unwrap();
        }
        if k >= n / 2 && k % 2 == 0 {
            let twin = n - 1 - k;
            let m = truth[twin].between(&truth[k]);
            let e = EdgeInput::new(twin as u64, k as u64, m, info, EdgeKind::LoopClosure);
            good.push(f.add_edge(&e).unwrap());
        }
        if k == 30 {
            let e = EdgeInput::new(3, 30, Pose2::new(0.2, -0.3, 0.1), info, EdgeKind::LoopClosure);
            wrong = f.add_edge(&e).unwrap();
        }
        f.flush().unwrap();
    }
    // the re-solve after the stream pauses publishes the final switches
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        assert!(
            Instant::now() < deadline,
            "no switches with the wrong loop closure off"
        );
        let _ = snaps.wait(Duration::from_millis(200)).unwrap();
        let Some(s) = snaps.switches().unwrap() else {
            continue;
        };
        let by_seq: HashMap<u64, f64> = (s.switches().iter())
            .filter(|w| w.frontend == f.id())
            .map(|w| (w.sequence, w.weight))
            .collect();
        if by_seq.len() < good.len() + 1 || by_seq[&wrong] >= REJECTED_BELOW || s.header().pending > 0 {
            continue;
        }
        assert_eq!(s.header().rejected, 1);
        for seq in &good {
            assert!(by_seq[seq] > 0.9, "loop closure {seq}: switch {}", by_seq[seq]);
        }
        break;
    }
    assert!(daemon.stop().success());
}

/// A square of 4 × 10 exact, certain steps (σ ≈ 3 cm) closed by a loop
/// closure 10 m off, of `kind`: the switch it ends with after the closing re-solve and the
/// last keyframe's distance from the first.
fn square_closed_wrongly(kind: EdgeKind) -> (f64, f64) {
    let step = Pose2::new(1.0, 0.0, 0.0);
    let corner = Pose2::new(1.0, 0.0, std::f64::consts::FRAC_PI_2);
    let mut engine = Engine::new(EngineConfig {
        background: false,
        ..EngineConfig::default()
    });
    for k in 0..=40u64 {
        engine.add_keyframe(k, None).unwrap();
        if k > 0 {
            let m = if k % 10 == 0 { corner } else { step };
            let certain = Information::identity().scaled(1000.0);
            let e = EdgeInput::new(k - 1, k, m, certain, EdgeKind::Odometry);
            engine.add_edge(e).unwrap();
        }
        engine.update();
    }
    let wrong = EdgeInput::new(40, 0, Pose2::new(10.0, 0.0, 0.0), Information::identity(), kind);
    let e = engine.add_edge(wrong).unwrap();
    engine.update();
    engine.resolve_now();
    let p40 = engine.snapshot().pose(40).unwrap();
    (engine.switches()[e], p40.position().norm())
}

#[test]
fn a_trusted_loop_closure_is_never_switched_off() {
    // a candidate 10 m off an exact square is switched off (what is left
    // of its weight, s², moves the square's end by centimetres)
    let (switch, gap) = square_closed_wrongly(EdgeKind::LoopClosure);
    assert!(switch < REJECTED_BELOW, "candidate's switch {switch}");
    assert!(gap < 0.5, "keyframe 40 is {gap} m from keyframe 0");
    // trusted, the same edge keeps its whole weight and pulls the map
    let (switch, gap) = square_closed_wrongly(EdgeKind::TrustedLoopClosure);
    assert_eq!(switch, 1.0);
    assert!(gap > 5.0, "keyframe 40 is {gap} m from keyframe 0");
}

/// A corridor of 20 one-metre steps with loose odometry (unit
/// information) and three loop closures from keyframe 3 to 15 measuring
/// 12, 12.35 and 11.65 m (σ 0.1 m): the switches they end with after the
/// closing re-solve, with PCM on or off. Pairwise, the first agrees with
/// each of the others (d² = 0.35² / 0.02 = 6.1) and those two disagree
/// (d² = 24.5 > 11.34). DCS, the third arriving against a map the other
/// two already hold, switches it partly off, at the value its error
/// gives; PCM holds it out of the clique, at switch 0.
fn corridor_with_three_closures(pairwise: bool) -> [f64; 3] {
    let mut engine = Engine::new(EngineConfig {
        background: false,
        outliers: OutlierConfig {
            pairwise,
            ..OutlierConfig::default()
        },
        ..EngineConfig::default()
    });
    for k in 0..20u64 {
        engine.add_keyframe(k, None).unwrap();
        if k > 0 {
            let step = Pose2::new(1.0, 0.0, 0.0);
            let e = EdgeInput::new(k - 1, k, step, Information::identity(), EdgeKind::Odometry);
            engine.add_edge(e).unwrap();
        }
        engine.update();
    }
    let info = Information::identity().scaled(100.0);
    let ids = [12.0, 12.35, 11.65].map(|x| {
        let e = EdgeInput::new(3, 15, Pose2::new(x, 0.0, 0.0), info, EdgeKind::LoopClosure);
        let e = engine.add_edge(e).unwrap();
        engine.update();
        e
    });
    engine.resolve_now();
    let switches = engine.switches();
    ids.map(|e| switches[e])
}

#[test]
fn pairwise_consistency_holds_out_what_disagrees_with_the_clique() {
    let [a, b, c] = corridor_with_three_closures(false);
    assert!(
        a >= REJECTED_BELOW && b >= REJECTED_BELOW,
        "DCS keeps the first two: {a}, {b}"
    );
    assert!(c > 0.0 && c < REJECTED_BELOW, "DCS's switch of the third: {c}");
    let [a, b, c] = corridor_with_three_closures(true);
    assert!(
        a >= REJECTED_BELOW && b >= REJECTED_BELOW,
        "the clique stays: {a}, {b}"
    );
    assert_eq!(c, 0.0, "the third is held out");
}

/// A square loop of 200 one-metre steps whose odometry turns 0.005 rad too
/// far each step, then 60 steps along the first side again, each with an
/// exact loop closure to the keyframe 200 back. Odometry has unit
/// information, loop closures 100 times that.
fn drifted_loop() -> PoseGraph {
    let corner = std::f64::consts::FRAC_PI_2;
    let step = |k: usize| Pose2::new(1.0, 0.0, if k.is_multiple_of(50) { corner } else { 0.0 });
    let mut truth = vec![Pose2::IDENTITY];
    for k in 1..260 {
        let last = *truth.last().unwrap();
        truth.push(last.compose(&step(k)));
    }
    let mut g = PoseGraph::default();
    for id in 0..truth.len() as u64 {
        g.add_keyframe(id, None).unwrap();
    }
    let info = Information::identity();
    for k in 1..truth.len() {
        let z = truth[k - 1].between(&truth[k]);
        let biased = Pose2::new(z.x, z.y, z.theta + 0.005);
        g.add_edge(k as u64 - 1, k as u64, biased, info, EdgeKind::Odometry)
            .unwrap();
    }
    for j in 200..truth.len() {
        let z = truth[j - 200].between(&truth[j]);
        let precise = info.scaled(100.0);
        g.add_edge(j as u64 - 200, j as u64, z, precise, EdgeKind::LoopClosure)
            .unwrap();
    }
    g
}

/// An engine with no scheduled re-solve, inline.
fn unscheduled() -> EngineConfig {
    EngineConfig {
        background: false,
        resolve_every_edges: 0,
        resolve_fill_ratio: 0.0,
        ..EngineConfig::default()
    }
}

/// Replays `g`; the engine, and how many loop closures stand rejected.
fn rejected_closures(g: &PoseGraph, config: EngineConfig) -> (Engine, usize) {
    let (engine, sent) = slamd_tests::replay(g, config, |_, _| {});
    let switches = engine.switches();
    let off = sent
        .iter()
        .enumerate()
        .filter(|&(n, &e)| g.edges()[e].kind == EdgeKind::LoopClosure && switches[n] < REJECTED_BELOW)
        .count();
    (engine, off)
}

#[test]
fn a_drifted_loop_is_taken_back_before_any_scheduled_resolve() {
    let g = drifted_loop();
    // only the drift check may re-solve: no schedule, no nonlinearity check
    let online = |drift_run: usize| {
        let mut config = EngineConfig {
            nonlinear_ratio: 0.0,
            ..unscheduled()
        };
        config.outliers.drift_run = drift_run;
        // the gate that knows the map's uncertainty takes the revisit on
        // arrival (next test); this one is about the drift check alone
        config.outliers.arrival_covariance = false;
        let (engine, off) = rejected_closures(&g, config);
        (off, engine.stats().drift_resolves)
    };
    // without the check the whole revisit stands rejected: the arrival gate
    // cannot tell the first loop closure from a wrong one, and the
    // dead-reckoned keyframes after it drift just the same
    let (off, resolves) = online(0);
    assert_eq!(resolves, 0);
    assert!(
        off >= 55,
        "only {off} of 60 loop closures rejected without the check"
    );
    // with it, the 20th agreeing rejection re-solves and takes them back
    let (off, resolves) = online(20);
    assert!(resolves >= 1, "no drift re-solve");
    assert_eq!(off, 0, "{off} true loop closures still rejected");
}

#[test]
fn a_drifted_loop_passes_the_gate_that_knows_the_maps_uncertainty() {
    let g = drifted_loop();
    // no scheduled re-solve and no drift check: what stands is what the
    // arrival gate decided (the nonlinearity check relinearises once the
    // loop has closed, keeping the switches it finds)
    let online = |covariance: bool| {
        let mut config = unscheduled();
        config.outliers.drift_run = 0;
        config.outliers.arrival_covariance = covariance;
        let (engine, off) = rejected_closures(&g, config);
        assert_eq!(engine.stats().drift_resolves, 0);
        let poses: Vec<Pose2> = engine.snapshot().poses().map(|(_, p)| p).collect();
        (off, poses)
    };
    let options = BatchOptions {
        polish: true,
        ..Default::default()
    };
    let best = solve_batch(&g, &options).unwrap();
    // against Ω alone the first loop closure looks as wrong as a false one
    let (off, bent) = online(false);
    assert!(off >= 55, "only {off} of 60 rejected by the plain gate");
    let bent = max_pose_error(&bent, &best.poses);
    assert!(bent > 20.0, "{bent} m from the optimum with the revisit rejected");
    // against Ω⁻¹ + J Σ Jᵀ the loop's two ends are known that loosely
    let (off, closed) = online(true);
    assert_eq!(off, 0, "{off} true loop closures rejected on arrival");
    // and the map closed: the last snapshot is where the optimum is
    let closed = max_pose_error(&closed, &best.poses);
    assert!(closed < 0.5, "{closed} m from the optimum");
}

/// A straight chain of 200 exact one-metre steps whose odometry claims
/// ringCity's information (σ 5 cm, 5° per step), then one keyframe per
/// entry of `wrong`, each closing on the keyframe 200 back with the
/// measurement it would have if keyframe 200 sat at `wrong[n]` (and the
/// keyframes after it moved rigidly with it). Returns the switch of each
/// wrong loop closure after the update of its keyframe, then after the
/// last update.
fn loosely_held_chain(wrong: &[Pose2]) -> Vec<f64> {
    let truth = |k: usize| Pose2::new(k as f64, 0.0, 0.0);
    let odometry = Information::from_upper([400.0, 0.0, 0.0, 400.0, 0.0, 131.312254]).unwrap();
    let closure = Information::from_upper([100.0, 0.0, 0.0, 100.0, 0.0, 131.312254]).unwrap();
    let n = 200 + wrong.len();
    let mut g = PoseGraph::default();
    for id in 0..n as u64 {
        g.add_keyframe(id, None).unwrap();
    }
    for k in 1..n {
        let step = truth(k - 1).between(&truth(k));
        g.add_edge(k as u64 - 1, k as u64, step, odometry, EdgeKind::Odometry)
            .unwrap();
        if k >= 200 {
            let moved = wrong[k - 200].compose(&truth(200).inverse());
            let z = truth(k - 200).between(&moved.compose(&truth(k)));
            g.add_edge(k as u64 - 200, k as u64, z, closure, EdgeKind::LoopClosure)
                .unwrap();
        }
    }
    let mut config = EngineConfig {
        nonlinear_ratio: 0.0,
        ..unscheduled()
    };
    config.outliers.drift_run = 0;
    let mut switches = Vec::new();
    let (engine, _) = slamd_tests::replay(&g, config, |k, engine| {
        if k >= 200 {
            // each keyframe from 200 on brings one loop closure, the newest
            let edges = engine.graph().edges();
            let e = edges.iter().rposition(|e| e.kind == EdgeKind::LoopClosure);
            switches.push(engine.switches()[e.expect("its loop closure")]);
        }
    });
    // and as they stand at the end
    let edges = engine.graph().edges();
    let closures = (0..edges.len()).filter(|&e| edges[e].kind == EdgeKind::LoopClosure);
    let at_end = engine.switches();
    switches.extend(closures.map(|e| at_end[e]));
    switches
}

#[test]
fn a_loop_closure_only_the_maps_uncertainty_excuses_waits_for_a_second() {
    // 60 m sideways and 0.3 rad off at the end of a chain the odometry
    // claims to hold within a radian: against Ω (σ 10 cm) a wrong loop
    // closure, against Ω⁻¹ + J Σ Jᵀ as plausible as a drifted revisit
    let w = Pose2::new(200.0, 60.0, 0.3);
    // alone, it is held off
    let alone = loosely_held_chain(&[w]);
    assert!(
        alone.iter().all(|&s| s < REJECTED_BELOW),
        "a lone one entered: {alone:?}"
    );
    // a second that agrees with it (the same correction of the map) brings
    // both in, as the first loop closures of a drifted loop
    let pair = loosely_held_chain(&[w, w]);
    assert!(pair[0] < REJECTED_BELOW, "the first entered alone: {pair:?}");
    assert_eq!(&pair[1..], &[1.0, 1.0, 1.0], "the agreeing pair: {pair:?}");
    // a second that disagrees leaves both off
    let split = loosely_held_chain(&[w, Pose2::new(200.0, -50.0, -0.2)]);
    assert!(split.iter().all(|&s| s < REJECTED_BELOW), "{split:?}");
}
