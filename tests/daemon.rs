//! The real `slamd` binary as a daemon, talked to through the client over
//! shared memory.

use slamd_client::{
    Config, EdgeInput, EdgeKind, Embedded, EngineConfig, Frontend, Information, MapSnapshot, Pose2, Publish,
    RejectionReason, Snapshots,
};
use slamd_protocol::codec::{edge_out, Origin};
use slamd_protocol::{Edge, PROTOCOL_VERSION};
use slamd_tests::{read, slamd_bin};
use std::collections::HashMap;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// A `slamd run` child on its own namespace.
pub struct Daemon {
    child: Child,
    pub namespace: String,
}

impl Daemon {
    pub fn start(name: &str, env: &[(&str, &str)]) -> Daemon {
        let namespace = format!("slamd-test-{}-{name}", std::process::id());
        Self::serve(&namespace, &[], env)
    }

    /// `slamd run --namespace namespace` with `args`; returns once
    /// frontends can connect.
    pub fn serve(namespace: &str, args: &[&str], env: &[(&str, &str)]) -> Daemon {
        let mut cmd = Command::new(slamd_bin());
        cmd.args(["run", "--namespace", namespace])
            .args(args)
            .env("SLAMD_LOG", "error")
            .stdin(Stdio::null());
        for (k, v) in env {
            cmd.env(k, v);
        }
        let child = cmd.spawn().expect("start slamd run");
        let deadline = Instant::now() + Duration::from_secs(20);
        while Snapshots::open(namespace).is_err() {
            assert!(Instant::now() < deadline, "daemon `{namespace}` did not come up");
            std::thread::sleep(Duration::from_millis(20));
        }
        Daemon {
            child,
            namespace: namespace.into(),
        }
    }

    pub fn config(&self) -> Config {
        Config {
            namespace: self.namespace.clone(),
            ..Config::default()
        }
    }

    pub fn signal(mut self, sig: i32) -> ExitStatus {
        // SAFETY: kill(2) on our own child.
        unsafe { libc::kill(self.child.id() as i32, sig) };
        let status = self.child.wait().expect("wait for the daemon");
        std::mem::forget(self);
        status
    }

    /// The daemon's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    pub fn stop(self) -> ExitStatus {
        self.signal(libc::SIGTERM)
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Waits for a snapshot acknowledging `seq` from `frontend`; returns its
/// poses by id and its header.
fn wait_for_ack(
    s: &mut Snapshots,
    frontend: u32,
    seq: u64,
) -> (HashMap<u64, Pose2>, slamd_protocol::SnapshotHeader) {
    let snap = wait_for_sample(s, frontend, seq);
    let poses = snap
        .poses()
        .iter()
        .map(|p| (p.id, Pose2::new(p.x, p.y, p.theta)))
        .collect();
    (poses, *snap.header())
}

/// Waits for a snapshot acknowledging `seq` from `frontend`.
fn wait_for_sample(s: &mut Snapshots, frontend: u32, seq: u64) -> MapSnapshot {
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        if let Some(snap) = s.wait(Duration::from_millis(200)).expect("snapshot link") {
            if snap.header().ack_of(frontend).is_some_and(|a| a >= seq) {
                return snap.clone();
            }
        }
        assert!(
            Instant::now() < deadline,
            "no snapshot acknowledged {frontend}:{seq}"
        );
    }
}

fn walk(n: usize) -> Vec<Pose2> {
    let mut p = vec![Pose2::IDENTITY];
    for k in 1..n {
        let last = p[k - 1];
        p.push(last.compose(&Pose2::new(1.0, 0.1 * (k % 3) as f64, 0.3)));
    }
    p
}

fn exact(truth: &[Pose2], i: usize, j: usize, kind: EdgeKind) -> EdgeInput {
    EdgeInput::new(
        i as u64,
        j as u64,
        truth[i].between(&truth[j]),
        Information::identity(),
        kind,
    )
}

fn close(got: &HashMap<u64, Pose2>, truth: &[Pose2], tol: f64) {
    assert_eq!(got.len(), truth.len());
    for (k, t) in truth.iter().enumerate() {
        let g = got[&(k as u64)];
        assert!(
            (g.x - t.x).abs() < tol && (g.y - t.y).abs() < tol,
            "keyframe {k}: {g:?} vs {t:?}"
        );
    }
}

#[test]
fn two_frontends_interleave_edges() {
    let daemon = Daemon::start("two", &[]);
    let truth = walk(40);
    let mut odometry = Frontend::connect(&daemon.config()).unwrap();
    let mut closures = Frontend::connect(&daemon.config()).unwrap();
    let mut snaps = Snapshots::open(&daemon.namespace).unwrap();
    let mut loops = 0;
    for k in 0..truth.len() {
        odometry.add_keyframe(k as u64, 0, None).unwrap();
        if k > 0 {
            odometry
                .add_edge(&exact(&truth, k - 1, k, EdgeKind::Odometry))
                .unwrap();
        }
        odometry.flush().unwrap();
        if k >= 10 && k % 4 == 0 {
            // the other frontend may outrun the odometry: the daemon holds it
            closures
                .add_edge(&exact(&truth, k - 10, k, EdgeKind::LoopClosure))
                .unwrap();
            closures.flush().unwrap();
            loops += 1;
        }
    }
    let _ = wait_for_ack(&mut snaps, closures.id(), closures.last_sequence());
    let (poses, header) = wait_for_ack(&mut snaps, odometry.id(), odometry.last_sequence());
    assert_eq!(
        (header.keyframes, header.edges, header.rejected),
        (40, 39 + loops, 0)
    );
    close(&poses, &truth, 1e-6);
    assert!(header.chi2 < 1e-9, "{}", header.chi2);
    assert!(snaps.rejections().unwrap().is_empty());
    // the snapshot of fresh input says the daemon still works on it; the
    // last one, once it rests, says the map is settled
    assert_eq!(header.settling, 1);
    // once the daemon is at rest (its settled map out, then no snapshot
    // for a second), a subscriber that comes then and waits gets the
    // latest snapshot within a tick
    let (mut newest, mut settled) = (header.version, false);
    let deadline = Instant::now() + Duration::from_secs(60);
    loop {
        match snaps.wait(Duration::from_secs(1)).unwrap() {
            Some(s) => {
                newest = s.header().version;
                settled = s.header().settling == 0;
            }
            None if settled => break,
            None => assert!(Instant::now() < deadline, "no settled map within 60 s"),
        }
    }
    let mut late = Snapshots::open(&daemon.namespace).unwrap();
    let start = Instant::now();
    let got = late
        .wait(Duration::from_secs(5))
        .unwrap()
        .expect("the latest snapshot");
    assert!(start.elapsed() < Duration::from_secs(2), "{:?}", start.elapsed());
    assert_eq!(got.header().version, newest);
    assert_eq!((got.header().keyframes, got.header().edges), (40, 39 + loops));
    assert_eq!((got.header().settling, got.header().pending), (0, 0));
    assert_eq!(got.poses().len(), 40);
    assert!(daemon.stop().success());
}

/// A 2-D information whose upper triangle `[1, 3, 0, 1, 0, 1]` is not
/// positive definite, as the wire writes it.
fn indefinite() -> [f64; 21] {
    let mut v = [0.0; 21];
    v[..6].copy_from_slice(&[1.0, 3.0, 0.0, 1.0, 0.0, 1.0]);
    v
}

#[test]
fn hostile_stream_gets_clean_rejections_while_valid_data_flows() {
    let daemon = Daemon::start(
        "hostile",
        &[("SLAMD_HELD_TIMEOUT_S", "0.3"), ("SLAMD_IPC__TICK_MS", "50")],
    );
    let truth = walk(12);
    let mut f = Frontend::connect(&daemon.config()).unwrap();
    let mut snaps = Snapshots::open(&daemon.namespace).unwrap();
    let mut expected: Vec<(RejectionReason, u64)> = Vec::new();
    let good = |k: usize| exact(&truth, k - 1, k, EdgeKind::Odometry);
    // a loop closure as the codec encodes it; the frontend numbers it
    let raw = |k: usize| {
        let e = exact(&truth, k - 1, k, EdgeKind::LoopClosure);
        edge_out(
            &e,
            Origin {
                frontend: 0,
                sequence: 0,
            },
        )
    };
    for k in 0..truth.len() {
        f.add_keyframe(k as u64, 0, None).unwrap();
        if k > 0 {
            f.add_edge(&good(k)).unwrap();
        }
        let bad = match k {
            2 => Some((
                RejectionReason::NonFinite,
                Edge {
                    measurement: [f64::NAN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                    ..raw(k)
                },
            )),
            3 => Some((
                RejectionReason::NotPositiveDefinite,
                Edge {
                    information: indefinite(),
                    ..raw(k)
                },
            )),
            4 => Some((RejectionReason::BadKind, Edge { kind: 77, ..raw(k) })),
            5 => Some((
                RejectionReason::ProtocolVersion,
                Edge {
                    protocol: PROTOCOL_VERSION + 1,
                    ..raw(k)
                },
            )),
            6 => Some((
                RejectionReason::SelfEdge,
                Edge {
                    to: 6,
                    from: 6,
                    ..raw(k)
                },
            )),
            7 => Some((RejectionReason::UnknownKeyframe, Edge { to: 999, ..raw(k) })),
            8 => Some((
                RejectionReason::NonFinite,
                Edge {
                    information: [f64::INFINITY; 21],
                    ..raw(k)
                },
            )),
            9 => Some((
                RejectionReason::Dimension,
                Edge {
                    dimension: 3,
                    ..raw(k)
                },
            )),
            _ => None,
        };
        if let Some((reason, msg)) = bad {
            let seq = f.send_raw_edge(msg).unwrap();
            expected.push((reason, seq));
        }
        if k == 9 {
            let seq = f.add_keyframe(3, 0, None).unwrap(); // duplicate
            expected.push((RejectionReason::DuplicateKeyframe, seq));
        }
        f.flush().unwrap();
    }
    let (poses, header) = wait_for_ack(&mut snaps, f.id(), f.last_sequence());
    close(&poses, &truth, 1e-6);
    // the held edge to keyframe 999 is rejected once its wait runs out
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut got = Vec::new();
    while got.len() < expected.len() && Instant::now() < deadline {
        got.extend(snaps.rejections().unwrap());
        std::thread::sleep(Duration::from_millis(50));
    }
    let mut got: Vec<(RejectionReason, u64)> = got.iter().map(|r| (r.reason(), r.sequence)).collect();
    got.sort_by_key(|g| g.1);
    expected.sort_by_key(|e| e.1);
    assert_eq!(got, expected);
    assert!(header.rejected >= 7, "{header:?}");
    // and the daemon still takes valid input afterwards
    f.add_keyframe(100, 0, None).unwrap();
    let seq = f
        .add_edge(&EdgeInput::new(
            11,
            100,
            Pose2::new(1.0, 0.0, 0.0),
            Information::identity(),
            EdgeKind::Odometry,
        ))
        .unwrap();
    f.flush().unwrap();
    let (poses, header) = wait_for_ack(&mut snaps, f.id(), seq);
    assert_eq!(poses.len(), 13);
    assert_eq!(header.rejected, 9);
    assert!(daemon.stop().success());
}

#[test]
fn a_killed_frontend_is_survived_and_a_new_one_continues() {
    let daemon = Daemon::start("killed", &[("SLAMD_IPC__TICK_MS", "50")]);
    let dir = std::env::temp_dir().join(format!("slamd-killed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let world = dir.join("world.g2o");
    let out = Command::new(slamd_bin())
        .args([
            "synth",
            "--poses",
            "3000",
            "--out",
            world.to_str().unwrap(),
            "--truth",
            dir.join("t.txt").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(out.status.success());
    let mut replayer = Command::new(slamd_bin())
        .args([
            "replay",
            world.to_str().unwrap(),
            "--namespace",
            &daemon.namespace,
            "--rate",
            "500",
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut snaps = Snapshots::open(&daemon.namespace).unwrap();
    // let it get some way, then kill it without a chance to clean up
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        let snap = snaps.wait(Duration::from_millis(200)).unwrap();
        if snap.is_some_and(|s| s.header().keyframes >= 200) {
            break;
        }
        assert!(Instant::now() < deadline, "the replay frontend made no progress");
    }
    replayer.kill().unwrap();
    replayer.wait().unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let _ = snaps.wait(Duration::from_secs(1)).unwrap();
    let latest = snaps.current().expect("a snapshot");
    let last = latest.poses().iter().map(|p| p.id).max().unwrap();
    // a new frontend continues the map from the last keyframe
    let mut f = Frontend::connect(&daemon.config()).unwrap();
    let mut seq = 0;
    for k in last + 1..last + 20 {
        f.add_keyframe(k, 0, None).unwrap();
        seq = f
            .add_edge(&EdgeInput::new(
                k - 1,
                k,
                Pose2::new(1.0, 0.0, 0.0),
                Information::identity(),
                EdgeKind::Odometry,
            ))
            .unwrap();
        f.flush().unwrap();
    }
    let (poses, header) = wait_for_ack(&mut snaps, f.id(), seq);
    assert!(poses.contains_key(&(last + 19)), "new keyframes missing");
    assert_eq!(header.rejected, 0);
    assert!(daemon.stop().success());
}

#[test]
fn daemon_snapshots_equal_the_embedded_engine() {
    // deterministic engine on both sides: inline re-solves, no idle work
    let env = [
        ("SLAMD_ENGINE__BACKGROUND", "false"),
        ("SLAMD_IPC__TICK_MS", "600000"),
    ];
    let daemon = Daemon::start("equal", &env);
    let graph = read("intel_sesync.g2o").prefix(400);
    let groups = graph.by_newer();
    let mut f = Frontend::connect(&daemon.config()).unwrap();
    let mut snaps = Snapshots::open(&daemon.namespace).unwrap();
    let config = Config {
        engine: EngineConfig {
            background: false,
            ..EngineConfig::default()
        },
        ..Config::default()
    };
    let mut embedded: Embedded = Embedded::new(&config);
    let stamp = |k: usize| 1_700_000_000_000_000_000 + 100_000_000 * k as u64;
    let mut last = None;
    for (k, group) in groups.iter().enumerate() {
        // every other keyframe carries its time
        let t = if k.is_multiple_of(2) { stamp(k) } else { 0 };
        for side in [&mut f as &mut dyn Publish, &mut embedded as &mut dyn Publish] {
            side.add_keyframe(graph.id_of(k), t, None).unwrap();
            for &e in group {
                side.add_edge(&graph.edge_input(e)).unwrap();
            }
            side.flush().unwrap();
        }
        // lockstep: one batch, one update per keyframe on both sides
        last = Some(wait_for_sample(&mut snaps, f.id(), f.last_sequence()));
    }
    let last = last.expect("a snapshot");
    let snap = embedded.snapshot();
    assert_eq!(last.poses().len(), snap.len());
    let from_daemon: HashMap<u64, &slamd_client::Pose> = last.poses().iter().map(|p| (p.id, p)).collect();
    for ((id, p), t) in snap.poses().zip(snap.timestamps()) {
        let d = from_daemon[&id];
        assert!(
            (d.x - p.x).abs() < 1e-12 && (d.y - p.y).abs() < 1e-12 && (d.theta - p.theta).abs() < 1e-12,
            "keyframe {id}: daemon {d:?} vs embedded {p:?}"
        );
        let k = graph.index_of(id).unwrap();
        assert_eq!(
            (d.timestamp_ns, t),
            if k.is_multiple_of(2) {
                (stamp(k), stamp(k))
            } else {
                (0, 0)
            }
        );
    }
    // the header carries the newest keyframe's covariance, as the engine
    // gives it
    let h = last.header();
    let newest = graph.id_of(graph.len() - 1);
    assert_eq!((h.has_covariance, h.covariance_keyframe), (1, newest));
    let sigma = embedded.engine().marginal(newest).unwrap();
    let mut i = 0;
    for r in 0..3 {
        for c in r..3 {
            let scale = sigma[(r, r)].max(sigma[(c, c)]);
            assert!(
                (h.covariance[i] - sigma[(r, c)]).abs() <= 1e-9 * scale,
                "{r},{c}: {} vs {}",
                h.covariance[i],
                sigma[(r, c)]
            );
            i += 1;
        }
    }
    assert!(h.covariance[0] > 0.0 && h.covariance[6..].iter().all(|&v| v == 0.0));
    drop(last);
    assert!(
        daemon.signal(libc::SIGINT).success(),
        "SIGINT must stop the daemon cleanly too"
    );
}

#[test]
fn replay_without_a_daemon_says_so_quickly() {
    let start = Instant::now();
    let out = Command::new(slamd_bin())
        .args([
            "replay",
            slamd_tests::dataset("ring.g2o").to_str().unwrap(),
            "--namespace",
            "slamd-test-nobody-home",
        ])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("no slamd daemon serves namespace `slamd-test-nobody-home`"),
        "{err}"
    );
    assert!(start.elapsed() < Duration::from_secs(5));
}

#[test]
fn a_daemon_that_cannot_fit_its_pools_refuses_to_start() {
    let out = Command::new(slamd_bin())
        .args([
            "run",
            "--namespace",
            &format!("slamd-test-{}-huge", std::process::id()),
        ])
        .env("SLAMD_IPC__INITIAL_POSES", "100000000000")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/dev/shm has") && err.contains("enlarge /dev/shm"),
        "{err}"
    );
}

#[test]
fn a_replay_through_the_daemon_ends_at_the_optimum() {
    // The daemon's closing re-solves (input paused) must cover every edge:
    // the replay waits until the daemon is quiet and reports that estimate.
    let daemon = Daemon::start("closing", &[]);
    let file = slamd_tests::dataset("intel_sesync.g2o");
    let v = slamd_tests::run_json(&[
        "replay",
        file.to_str().unwrap(),
        "--namespace",
        &daemon.namespace,
        "--json",
    ]);
    let best = slamd_tests::run_json(&["solve", file.to_str().unwrap(), "--polish", "--json"]);
    let (got, best) = (v["chi2"].as_f64().unwrap(), best["chi2"].as_f64().unwrap());
    assert_eq!(v["mode"], "daemon");
    assert!(
        (got - best).abs() <= 1e-3 * best,
        "χ² {got} through the daemon, optimum {best}"
    );
    daemon.stop();
}

/// `slamd status --json` reads a running daemon's map, input and journal
/// from what it publishes; with no daemon it says so and exits 2.
#[test]
fn status_shows_a_running_daemon() {
    let dir = std::env::temp_dir().join(format!("slamd-status-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let daemon = Daemon::start("status", &[("SLAMD_STATE__DIR", dir.to_str().unwrap())]);
    let config = daemon.config();
    let mut snapshots = Snapshots::open(&config.namespace).unwrap();
    let mut f = Frontend::connect(&config).unwrap();
    let truth = walk(3);
    for k in 0..3 {
        f.add_keyframe(k, 0, None).unwrap();
    }
    f.add_edge(&exact(&truth, 0, 1, EdgeKind::Odometry)).unwrap();
    let last = f.add_edge(&exact(&truth, 1, 2, EdgeKind::Odometry)).unwrap();
    f.flush().unwrap();
    wait_for_ack(&mut snapshots, f.id(), last);
    let v = slamd_tests::run_json(&["status", "--namespace", &daemon.namespace, "--json"]);
    assert_eq!(v["keyframes"], 3);
    assert_eq!(v["edges"], 2);
    assert_eq!(v["rejected"], 0);
    assert_eq!(v["frontends_last_minute"], 1);
    assert_eq!(v["acknowledged"][0]["through"], last);
    // the journal holds five records past its 24-byte head
    assert!(v["journal_bytes"].as_u64().unwrap() > 24, "{v}");
    assert!(v["latency_p99_us"].as_f64().unwrap() > 0.0, "{v}");
    daemon.stop();
    let (code, _, err) =
        slamd_tests::run_slamd(&["status", "--namespace", "slamd-test-nobody", "--wait", "0.2"]);
    assert_eq!(code, 2);
    assert!(err.contains("no slamd daemon publishes"), "{err}");
}
