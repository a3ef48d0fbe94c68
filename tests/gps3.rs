//! GPS in 3-D: fixes with a height and its variance hold a spatial map in
//! ENU, up included, in process and through a daemon serving 3-D graphs.

use crate::daemon::Daemon;
use faer::c64;
use slamd::engine::{EdgeInput, Engine, FixInput};
use slamd::gps::{Geodetic, LocalFrame};
use slamd::graph::{EdgeKind, Information6, Pose3};
use slamd_client::{Frontend, Snapshots};
use std::time::{Duration, Instant};

fn origin() -> Geodetic {
    Geodetic::new(45.4781, 9.2271, 120.0).expect("valid")
}

/// The map→ENU rotation about up and shift of the truth.
const HEADING: f64 = 0.7;
const SHIFT: [f64; 3] = [120.0, -35.0, 30.0];

/// A ramp that turns and climbs 4 cm a step: `n` keyframes.
fn ramp(n: usize) -> Vec<Pose3> {
    let step = Pose3::from_xyz_rpy([1.0, 0.0, 0.04, 0.0, 0.0, 0.05]);
    let mut truth = vec![Pose3::IDENTITY];
    for k in 1..n {
        truth.push(truth[k - 1].compose(&step));
    }
    truth
}

/// Odometry from the truth, with 2 cm a step of climb it did not make: the
/// map's height drifts 2 m over 100 keyframes.
fn odometry(truth: &[Pose3], k: usize) -> EdgeInput<Pose3> {
    let biased = truth[k - 1]
        .between(&truth[k])
        .compose(&Pose3::from_xyz_rpy([0.0, 0.0, 0.02, 0.0, 0.0, 0.0]));
    EdgeInput::new(
        k as u64 - 1,
        k as u64,
        biased,
        Information6::identity().scaled(400.0),
        EdgeKind::Odometry,
    )
}

/// Keyframe `k`'s true ENU position.
fn enu_of(p: &Pose3) -> [f64; 3] {
    let t = p.translation;
    let en = c64::from_polar(1.0, HEADING) * c64::new(t.x, t.y) + c64::new(SHIFT[0], SHIFT[1]);
    [en.re, en.im, t.z + SHIFT[2]]
}

/// An exact fix of keyframe `k`, its height held with σ 0.1 m or free.
fn fix(truth: &[Pose3], k: usize, height: bool) -> FixInput {
    let [e, n, u] = enu_of(&truth[k]);
    FixInput {
        keyframe: k as u64,
        position: LocalFrame::new(origin()).to_geodetic(e, n, u),
        covariance: [0.01, 0.0, 0.0, 0.01],
        height_variance: height.then_some(0.01),
    }
}

/// Keyframes this close to the gauge (keyframe 0, held at the origin)
/// are left out of the comparisons: the georeference is fitted to the
/// poses and the poses polished to it in turn, and near the gauge, which
/// does not move, the map keeps a bend of the drift's size.
const NEAR_GAUGE: usize = 20;

/// The worst errors of the engine's map away from the gauge: east-north
/// and up in ENU, and the climb since keyframe `NEAR_GAUGE` (what drifts).
fn worst_errors(engine: &Engine<Pose3>, truth: &[Pose3]) -> (f64, f64, f64) {
    let snap = engine.snapshot();
    let g = snap.georef.expect("georeferenced");
    let z0 = snap.pose(NEAR_GAUGE).expect("joined").translation.z;
    let mut worst = (0.0f64, 0.0f64, 0.0f64);
    for (k, t) in truth.iter().enumerate().skip(NEAR_GAUGE) {
        let p = snap.pose(k).expect("joined").translation;
        let en = g.rotation * c64::new(p.x, p.y) + g.translation;
        let want = enu_of(t);
        let climb = (p.z - z0) - (t.translation.z - truth[NEAR_GAUGE].translation.z);
        worst.0 = worst.0.max((en - c64::new(want[0], want[1])).norm());
        worst.1 = worst.1.max((p.z + g.up - want[2]).abs());
        worst.2 = worst.2.max(climb.abs());
    }
    worst
}

#[test]
fn fixes_with_a_height_hold_the_map_up_included() {
    let truth = ramp(100);
    let run = |height: bool| {
        let mut engine = Engine::<Pose3>::create(slamd_tests::gps_engine_config(origin()));
        for k in 0..truth.len() {
            engine.add_keyframe(k as u64, None).unwrap();
            if k > 0 {
                engine.add_edge(odometry(&truth, k)).unwrap();
            }
            if k % 5 == 0 {
                engine.add_gps(fix(&truth, k, height)).unwrap();
            }
            engine.update();
        }
        engine.resolve_now();
        worst_errors(&engine, &truth)
    };
    let (plane, up, climb) = run(true);
    assert!(plane < 0.05, "east-north off by {plane} m");
    assert!(up < 0.05, "up off by {up} m with the heights held");
    assert!(climb < 0.05, "the climb off by {climb} m with the heights held");
    // with the heights free the map keeps the odometry's drift in height:
    // 2 cm a step over 80 steps
    let (plane, _, climb) = run(false);
    assert!(plane < 0.05, "east-north off by {plane} m");
    assert!(
        (climb - 1.6).abs() < 0.1,
        "the climb off by {climb} m with the heights free"
    );
}

#[test]
fn a_3d_daemon_georeferences_with_heights() {
    let truth = ramp(60);
    let daemon = Daemon::start(
        "gps3",
        &[
            ("SLAMD_DIMENSION", "3"),
            ("SLAMD_GPS__ORIGIN", "45.4781,9.2271,120"),
        ],
    );
    let mut snaps = Snapshots::open(&daemon.namespace).unwrap();
    let mut f = Frontend::connect(&daemon.config()).unwrap();
    let mut seq = 0;
    for k in 0..truth.len() {
        seq = f.add_keyframe(k as u64, 0, None).unwrap();
        if k > 0 {
            seq = f.add_edge(&odometry(&truth, k)).unwrap();
        }
        if k % 5 == 0 {
            seq = f.add_gps(&fix(&truth, k, true)).unwrap();
        }
        f.flush().unwrap();
    }
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut worst = f64::INFINITY;
    while Instant::now() < deadline {
        let Some(snap) = snaps.wait(Duration::from_millis(200)).unwrap() else {
            continue;
        };
        let h = snap.header();
        if h.ack_of(f.id()).is_none_or(|a| a < seq) || h.georeferenced == 0 {
            continue;
        }
        assert_eq!((h.dimension, h.fixes, h.rejected), (3, 12, 0));
        worst = (snap.poses().iter())
            .filter(|p| p.id as usize >= NEAR_GAUGE)
            .map(|p| {
                let want = enu_of(&truth[p.id as usize]);
                let d = [p.east - want[0], p.north - want[1], p.up - want[2]];
                d.iter().map(|v| v * v).sum::<f64>().sqrt()
            })
            .fold(0.0, f64::max);
        if worst < 0.05 {
            break;
        }
    }
    assert!(worst < 0.05, "the daemon's ENU poses are {worst} m off");
}
