//! GPS fixes: georeferenced poses from exact fixes, online and in batch,
//! and refusals of bad fixes.

use crate::daemon::Daemon;
use faer::c64;
use slamd::engine::{EdgeInput, Engine, EngineConfig, EngineError, FixInput};
use slamd::geometry::Pose2;
use slamd::gps::{Geodetic, GpsError, LocalFrame};
use slamd::graph::{EdgeKind, Information};
use slamd_client::{Frontend, Publish, RejectionReason, Snapshots};
use slamd_tests::{dataset, run_json};
use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

const ORIGIN: &str = "45.5138,9.2110";

fn origin() -> Geodetic {
    Geodetic::parse(ORIGIN).unwrap()
}

/// `../shared/tools/synth_gps.py` on a ground truth, into a temporary CSV.
fn synth_gps(truth: &str, sigma: f64, heading: f64) -> PathBuf {
    let out = std::env::temp_dir().join(format!(
        "slamd-test-gps-{}-{}-{sigma}.csv",
        std::process::id(),
        truth.replace('/', "_")
    ));
    let tool = dataset("../tools/synth_gps.py");
    let status = Command::new("python3")
        .arg(&tool)
        .arg(dataset(truth))
        .args(["--every", "20", "--sigma", &sigma.to_string()])
        .args([
            "--heading",
            &heading.to_string(),
            "--origin",
            ORIGIN,
            "--seed",
            "4",
        ])
        .arg("--out")
        .arg(&out)
        .stdout(std::process::Stdio::null())
        .status()
        .expect("python3 runs synth_gps.py");
    assert!(status.success(), "synth_gps.py failed");
    out
}

#[test]
fn exact_fixes_on_an_exact_graph_give_the_true_enu_positions() {
    // the iSAM ground-truth file is Manhattan's graph with noise-free edges
    let truth = "groundtruth/manhattanolson3500_groundtruth_isam.txt";
    let fixes = synth_gps(truth, 0.0, 37.0);
    let graph = dataset(truth);
    let (g, f) = (graph.to_str().unwrap(), fixes.to_str().unwrap());
    let batch = run_json(&[
        "solve",
        g,
        "--gps",
        f,
        "--gps-origin",
        ORIGIN,
        "--polish",
        "--json",
    ]);
    assert_eq!(batch["gps_fixes"], 175);
    assert_eq!(batch["georeferenced"], true);
    let rmse = batch["enu_rmse"].as_f64().unwrap();
    assert!(rmse <= 1e-4, "batch ENU RMSE {rmse} m");
    let online = run_json(&[
        "replay",
        g,
        "--embedded",
        "--gps",
        f,
        "--gps-origin",
        ORIGIN,
        "--json",
    ]);
    let rmse = online["enu_rmse"].as_f64().unwrap();
    assert!(rmse <= 1e-4, "online ENU RMSE {rmse} m");
    std::fs::remove_file(fixes).unwrap();
}

#[test]
fn gps_pulls_drifting_odometry_back_in_batch() {
    let truth = "groundtruth/manhattanolson3500_groundtruth_isam.txt";
    let fixes = synth_gps(truth, 1.0, 0.0);
    let graph = dataset("manhattanolson3500_g2oversion.g2o");
    let gt = dataset(truth);
    let (g, f, t) = (
        graph.to_str().unwrap(),
        fixes.to_str().unwrap(),
        gt.to_str().unwrap(),
    );
    let base = [
        "solve",
        g,
        "--odometry-only",
        "--ground-truth",
        t,
        "--polish",
        "--json",
    ];
    let drift = run_json(&base)["ate"].as_f64().unwrap();
    let mut with = base.to_vec();
    with.extend(["--gps", f, "--gps-origin", ORIGIN]);
    let fixed = run_json(&with)["ate"].as_f64().unwrap();
    assert!(drift > 10.0, "odometry alone drifts: ATE {drift} m");
    assert!(fixed < 3.0, "GPS every 20th keyframe at 1 m: ATE {fixed} m");
    std::fs::remove_file(fixes).unwrap();
}

/// A lawnmower walk with loop closures between its lanes.
fn lanes(n: usize) -> (Vec<Pose2>, Vec<(usize, usize)>) {
    let mut truth = vec![Pose2::IDENTITY];
    for k in 1..n {
        let turn = if k % 10 == 0 {
            std::f64::consts::PI / 2.0
        } else {
            0.0
        };
        let last = truth[k - 1];
        truth.push(last.compose(&Pose2::new(2.0, 0.0, turn)));
    }
    let mut pairs: Vec<(usize, usize)> = (1..n).map(|k| (k - 1, k)).collect();
    pairs.extend((25..n).step_by(7).map(|k| (k - 20, k)));
    (truth, pairs)
}

fn edge(truth: &[Pose2], i: usize, j: usize) -> EdgeInput {
    EdgeInput::new(
        i as u64,
        j as u64,
        truth[i].between(&truth[j]),
        Information::identity(),
        EdgeKind::from_ids(i as u64, j as u64),
    )
}

/// Map → ENU: 40° and a shift; each pose's exact fix.
fn enu_of(p: &Pose2) -> c64 {
    c64::from_polar(1.0, 40f64.to_radians()) * p.position() + c64::new(120.0, -35.0)
}

fn fix(k: usize, truth: &[Pose2]) -> FixInput {
    let e = enu_of(&truth[k]);
    FixInput {
        keyframe: k as u64,
        position: LocalFrame::new(origin()).to_geodetic(e.re, e.im, 0.0),
        covariance: [1e-8, 0.0, 0.0, 1e-8],
        height_variance: None,
    }
}

#[test]
fn the_engine_georeferences_online() {
    let (truth, pairs) = lanes(120);
    let mut engine = Engine::new(slamd_tests::gps_engine_config(origin()));
    let mut georeferenced_at = None;
    for k in 0..truth.len() {
        engine.add_keyframe(k as u64, None).unwrap();
        for &(i, j) in pairs.iter().filter(|p| p.1 == k) {
            engine.add_edge(edge(&truth, i, j)).unwrap();
        }
        if k % 9 == 3 {
            engine.add_gps(fix(k, &truth)).unwrap();
        }
        engine.update();
        if georeferenced_at.is_none() && engine.snapshot().georef.is_some() {
            georeferenced_at = Some(k);
        }
    }
    engine.resolve_now();
    let at = georeferenced_at.expect("two fixes georeference the map");
    assert_eq!(at, 12, "the second fix (keyframe 12) georeferences the map");
    let snap = engine.snapshot();
    assert_eq!(snap.origin, Some(origin()));
    let mut count = 0;
    for (id, p) in snap.enu_poses() {
        let want = enu_of(&truth[id as usize]);
        let err = (p.position() - want).norm();
        assert!(err < 1e-4, "keyframe {id}: ENU off by {err} m");
        let heading = (p.theta - truth[id as usize].theta - 40f64.to_radians())
            .sin()
            .abs();
        assert!(heading < 1e-6, "keyframe {id}: heading off");
        count += 1;
    }
    assert_eq!(count, truth.len());
}

#[test]
fn the_engine_refuses_bad_fixes_and_keeps_going() {
    let (truth, _) = lanes(3);
    let mut engine = Engine::new(EngineConfig::default());
    for k in 0..3 {
        engine.add_keyframe(k as u64, None).unwrap();
    }
    let good = fix(1, &truth);
    let with = |f: &dyn Fn(&mut FixInput)| {
        let mut x = good;
        f(&mut x);
        x
    };
    let cases = [
        (
            with(&|f| f.position.lat = 91.0),
            EngineError::Gps(GpsError::OutOfRange),
        ),
        (
            with(&|f| f.position.lon = f64::NAN),
            EngineError::Gps(GpsError::NonFinite),
        ),
        (
            with(&|f| f.covariance = [1.0, 2.0, 2.0, 1.0]),
            EngineError::Gps(GpsError::NotPositiveDefinite),
        ),
        (with(&|f| f.keyframe = 77), EngineError::FixKeyframe(77)),
    ];
    for (bad, want) in cases {
        assert_eq!(engine.add_gps(bad), Err(want.clone()));
        assert!(!want.to_string().is_empty());
    }
    // nothing was stored: the first good fix still sets the origin
    assert_eq!(engine.gps_origin(), None);
    engine.add_gps(good).unwrap();
    assert_eq!(engine.gps_origin(), Some(good.position));
}

#[test]
fn the_daemon_holds_early_fixes_rejects_bad_ones_and_publishes_enu() {
    let daemon = Daemon::start("gps", &[("SLAMD_GPS__ORIGIN", ORIGIN)]);
    let (truth, pairs) = lanes(60);
    let mut f = Frontend::connect(&daemon.config()).unwrap();
    let mut snaps = Snapshots::open(&daemon.namespace).unwrap();
    // fixes overtake their keyframes: the daemon holds them
    for k in (3..60).step_by(9) {
        Publish::add_gps(&mut f, &fix(k, &truth)).unwrap();
    }
    let bad = FixInput {
        position: Geodetic {
            lat: 95.0,
            ..fix(3, &truth).position
        },
        ..fix(3, &truth)
    };
    let bad_seq = f.add_gps(&bad).unwrap();
    for k in 0..truth.len() {
        f.add_keyframe(k as u64, 0, None).unwrap();
        for &(i, j) in pairs.iter().filter(|p| p.1 == k) {
            f.add_edge(&edge(&truth, i, j)).unwrap();
        }
        f.flush().unwrap();
    }
    // the daemon re-solves when input pauses; wait for an exact ENU map
    let deadline = Instant::now() + Duration::from_secs(30);
    let worst = loop {
        assert!(Instant::now() < deadline, "no georeferenced snapshot");
        let Some(s) = snaps.wait(Duration::from_millis(200)).unwrap() else {
            continue;
        };
        let h = *s.header();
        if h.georeferenced == 0 || h.ack_of(f.id()) < Some(f.last_sequence()) {
            continue;
        }
        assert_eq!((h.fixes, h.held, h.has_origin), (7, 0, 1));
        assert!((h.origin[0] - 45.5138).abs() < 1e-12 && (h.origin[1] - 9.2110).abs() < 1e-12);
        let worst = (s.poses().iter())
            .map(|p| (c64::new(p.east, p.north) - enu_of(&truth[p.id as usize])).norm())
            .fold(0.0, f64::max);
        if worst < 1e-4 {
            break worst;
        }
    };
    assert!(worst < 1e-4);
    let rejections = snaps.rejections().unwrap();
    assert_eq!(rejections.len(), 1, "{rejections:?}");
    assert_eq!(
        (rejections[0].reason(), rejections[0].sequence),
        (RejectionReason::OutOfRange, bad_seq)
    );
    assert!(daemon.stop().success());
}
