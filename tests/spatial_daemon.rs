//! A 3-D daemon over shared memory: a building streamed through `slamd run`
//! with `dimension = 3`, its map kept across a restart, and messages of
//! the other dimension refused.

use crate::daemon::Daemon;
use slamd::graph::{EdgeKind, Pose3};
use slamd::solver::{solve_batch, BatchOptions};
use slamd::synthetic::{generate_building, WorldParams};
use slamd_client::{Frontend, Pose2, RejectionReason, SnapshotHeader, Snapshots};
use slamd_tests::slamd_bin;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Waits for a snapshot that acknowledges `seq` of `frontend` and
/// satisfies `done`; returns its poses (indexed by id) and header.
fn wait_until(
    s: &mut Snapshots,
    frontend: u32,
    seq: u64,
    done: impl Fn(&[Option<Pose3>], &SnapshotHeader) -> bool,
) -> (Vec<Option<Pose3>>, SnapshotHeader) {
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut last = None;
    while Instant::now() < deadline {
        let Some(snap) = s.wait(Duration::from_millis(200)).expect("snapshot link") else {
            continue;
        };
        let h = *snap.header();
        last = Some(h);
        if h.ack_of(frontend).is_none_or(|a| a < seq) {
            continue;
        }
        let mut poses = vec![None; snap.poses().len()];
        for p in snap.poses() {
            poses[p.id as usize] = Some(p.pose::<Pose3>().expect("a unit quaternion"));
        }
        if done(&poses, &h) {
            return (poses, h);
        }
    }
    panic!("no snapshot acknowledged {frontend}:{seq} and passed; the last: {last:?}");
}

#[test]
fn a_building_streams_through_a_3d_daemon_and_survives_a_restart() {
    let world = generate_building(
        &WorldParams {
            poses: 300,
            seed: 7,
            ..WorldParams::default()
        },
        2,
    );
    let g = &world.graph;
    let n = g.len();
    let loops = g.edges().iter().filter(|e| e.kind != EdgeKind::Odometry).count();
    assert!(loops >= 5, "the world closes loops: {loops}");
    let best = solve_batch(
        g,
        &BatchOptions {
            polish: true,
            ..Default::default()
        },
    )
    .expect("solvable");
    assert!(best.chi2 > 1.0, "the noise is felt: {}", best.chi2);

    let dir = std::env::temp_dir().join(format!("slamd-spatial-daemon-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let dir_arg = dir.to_str().unwrap().to_string();
    let namespace = format!("slamd-test-{}-spatial", std::process::id());
    let args = ["--state", dir_arg.as_str()];
    let env = [("SLAMD_DIMENSION", "3")];
    let daemon = Daemon::serve(&namespace, &args, &env);
    let mut snaps = Snapshots::open(&namespace).unwrap();
    let mut f = Frontend::connect(&daemon.config()).unwrap();
    // as a frontend that waits for each keyframe's snapshot: one keyframe
    // per batch, whatever the machine's load (a burst arrives in batches
    // whose sizes the load decides, and the filter may then hold true
    // loop closures off)
    let mut seq = 0;
    for (k, group) in g.by_newer().into_iter().enumerate() {
        seq = f.add_keyframe(g.id_of(k), 0, None).unwrap();
        for e in group {
            seq = f.add_edge(&g.edge_input(e)).unwrap();
        }
        f.flush().unwrap();
        wait_until(&mut snaps, f.id(), seq, |_, _| true);
    }
    // at rest the daemon re-solves in the background to the optimum of
    // every edge (the header's χ² leaves out what the filter holds off)
    let chi2_all = |poses: &[Option<Pose3>]| {
        let poses: Option<Vec<Pose3>> = poses.iter().copied().collect();
        poses.map_or(f64::INFINITY, |p| slamd::graph::chi2(g, &p))
    };
    // (the snapshots on the way there, as the filter's decisions come in,
    // may already be within 0.1% in χ² but not in the poses)
    let at_optimum = |poses: &[Option<Pose3>]| {
        poses.iter().zip(&best.poses).all(|(p, b)| {
            p.is_some_and(|p| {
                (p.translation - b.translation).norm() < 1e-3 && p.rotation.angle_to(&b.rotation) < 1e-4
            })
        })
    };
    let (poses, header) = wait_until(&mut snaps, f.id(), seq, |p, h| {
        h.keyframes == n as u64 && chi2_all(p) <= 1.001 * best.chi2 && at_optimum(p)
    });
    assert_eq!((header.dimension, header.poses), (3, n as u64));
    assert_eq!((header.edges, header.rejected), (g.edges().len() as u64, 0));
    assert!(
        (header.chi2 - chi2_all(&poses)).abs() <= 1e-6 * best.chi2,
        "{}",
        header.chi2
    );
    assert_eq!(header.pending, 0);

    // a 2-D keyframe, from a planar frontend, is refused with the reason,
    // the map untouched
    let mut planar: Frontend<Pose2> = Frontend::connect(&daemon.config()).unwrap();
    let wrong = planar.add_keyframe(9999, 0, None).unwrap();
    planar.flush().unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let rejection = loop {
        let found = snaps
            .rejections()
            .unwrap()
            .into_iter()
            .find(|r| r.sequence == wrong);
        if let Some(r) = found {
            break r;
        }
        assert!(Instant::now() < deadline, "no rejection of the 2-D keyframe");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(rejection.reason(), RejectionReason::Dimension);
    assert_eq!(
        rejection.text(),
        "keyframe 9999 is 2-D; this daemon serves 3-D graphs (its `dimension` setting)"
    );
    let (_, after) = wait_until(&mut snaps, planar.id(), wrong, |_, _| true);
    assert_eq!((after.keyframes, after.rejected), (n as u64, 1));
    let chi2 = after.chi2;
    let id = f.id();
    drop((f, planar));
    assert!(daemon.stop().success());

    // a new start on the same directory publishes the same map
    let daemon = Daemon::serve(&namespace, &args, &env);
    let mut snaps = Snapshots::open(&namespace).unwrap();
    // (it acknowledges what the last start had taken)
    let (restored, h) = wait_until(&mut snaps, id, seq, |_, h| h.keyframes == n as u64);
    assert_eq!(
        (h.dimension, h.poses, h.edges),
        (3, n as u64, g.edges().len() as u64)
    );
    assert!(
        (h.chi2 - chi2).abs() <= 1e-9 * chi2,
        "restored χ² {} against {chi2}",
        h.chi2
    );
    for (k, (a, b)) in restored.iter().zip(&poses).enumerate() {
        let (a, b) = (a.expect("restored"), b.expect("published"));
        assert!((a.translation - b.translation).norm() < 1e-6, "keyframe {k}");
    }
    assert!(daemon.stop().success());

    // a 2-D daemon refuses the directory rather than misread or cut it
    let mut child = Command::new(slamd_bin())
        .args([
            "run",
            "--namespace",
            &format!("{namespace}-2d"),
            "--state",
            &dir_arg,
        ])
        .env("SLAMD_LOG", "error")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start slamd run");
    let deadline = Instant::now() + Duration::from_secs(20);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > deadline {
            let _ = child.kill();
            panic!("a 2-D daemon served a 3-D state directory");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("a 3-D map where a 2-D one is expected"),
        "{stderr}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}
