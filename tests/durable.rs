//! A daemon with a state directory: killed mid-stream and restarted, it
//! loses nothing it acknowledged, and a replay through it completes.

use crate::daemon::Daemon;
use slamd::geometry::Pose2;
use slamd::store::MapFile;
use slamd_tests::{dataset, fresh_dir, read, slamd_bin};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

/// Intel streamed at 800 keyframes a second through a daemon that is
/// SIGKILLed twice mid-stream and restarted on the same state directory:
/// the replay completes at the optimum (45.005), and the map the last
/// daemon leaves on SIGTERM holds every keyframe and edge of the file.
#[test]
fn a_stream_survives_two_daemon_kills_and_ends_at_the_optimum() {
    let dir = fresh_dir("durable-kills");
    let dir_arg = dir.to_str().unwrap().to_string();
    let namespace = format!("slamd-test-{}-kills", std::process::id());
    let args = ["--state", dir_arg.as_str()];
    let mut daemon = Daemon::serve(&namespace, &args, &[]);
    let file = dataset("intel_sesync.g2o");
    let replay = Command::new(slamd_bin())
        .args(["replay", file.to_str().unwrap(), "--namespace", &namespace])
        .args(["--json", "--timeout", "60", "--rate", "800"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the replay");
    for _ in 0..2 {
        std::thread::sleep(Duration::from_millis(700));
        daemon.signal(libc::SIGKILL);
        daemon = Daemon::serve(&namespace, &args, &[]);
    }
    let out = replay.wait_with_output().expect("the replay ends");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "replay failed: {stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let chi2 = v["chi2"].as_f64().unwrap();
    assert!((chi2 - 45.005).abs() < 1e-3, "final χ² {chi2}");
    assert!(daemon.stop().success());

    let g = read("intel_sesync.g2o");
    let map = MapFile::<Pose2>::read(&dir.join("map")).expect("a checkpoint on SIGTERM");
    assert_eq!(map.keyframes.len(), g.len());
    assert_eq!(map.edges.len(), g.edges().len());
    // no edge went in twice, though the frontend sent some again
    let mut pairs: Vec<_> = map.edges.iter().map(|e| (e.edge.from, e.edge.to)).collect();
    pairs.sort_unstable();
    pairs.dedup();
    assert_eq!(pairs.len(), g.edges().len());
}

/// `--map` with a state directory that already holds one is refused:
/// which map goes on would be a guess.
#[test]
fn a_second_map_for_a_state_directory_is_refused() {
    let dir = fresh_dir("durable-two-maps");
    std::fs::create_dir_all(&dir).unwrap();
    let mut map = MapFile::default();
    map.keyframes.push(slamd::store::MapKeyframe {
        id: 0,
        guess: None,
        estimate: slamd::geometry::Pose2::IDENTITY,
        lin: slamd::geometry::Pose2::IDENTITY,
        joined: true,
        timestamp_ns: 0,
    });
    std::fs::write(dir.join("map"), map.encode()).unwrap();
    let other = dir.join("other.map");
    std::fs::write(&other, map.encode()).unwrap();
    let (code, _, err) = slamd_tests::run_slamd(&[
        "run",
        "--namespace",
        &format!("slamd-test-{}-two-maps", std::process::id()),
        "--state",
        dir.to_str().unwrap(),
        "--map",
        other.to_str().unwrap(),
    ]);
    assert_eq!(code, 2);
    assert!(err.contains("already holds a map"), "{err}");
}

/// `slamd run --map`'s path: a daemon started from Manhattan saved at
/// keyframe 1,750 takes the rest of the stream from a frontend and, once
/// input pauses, publishes the optimum 146.077.
#[test]
fn a_daemon_continues_a_saved_map_to_the_optimum() {
    use slamd::engine::{Engine, EngineConfig};
    use slamd::ipc::{Frontend, Server, Snapshots};
    let g = read("manhattanolson3500_g2oversion.g2o");
    let groups = g.by_newer();
    let mut engine = Engine::new(EngineConfig::default());
    slamd_tests::feed(&mut engine, &g, 0..1750);
    let bytes = engine.map().encode();
    drop(engine);
    let map = MapFile::<Pose2>::decode(std::path::Path::new("manhattan-1750"), &bytes).unwrap();
    let config = slamd::config::Config {
        namespace: format!("slamd-test-{}-continue", std::process::id()),
        ..slamd::config::Config::default()
    };
    let server = Server::spawn_map(config.clone(), Some(map)).expect("daemon");
    let mut snapshots = Snapshots::open(&config.namespace).unwrap();
    let mut f = Frontend::connect(&config).unwrap();
    for (k, group) in groups.iter().enumerate().skip(1750) {
        f.add_keyframe(g.id_of(k), 0, None).unwrap();
        let mut last = f.last_sequence();
        for &e in group {
            last = f.add_edge(&g.edge_input(e)).unwrap();
        }
        f.flush().unwrap();
        assert!(
            f.wait_acknowledged(last, Duration::from_secs(30)).unwrap(),
            "keyframe {k}"
        );
    }
    // the daemon re-solves once input pauses (the acknowledgement goes
    // out on the status topic just before its snapshot, so the first
    // snapshot read may still be the one before)
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    let (mut keyframes, mut chi2) = (0, f64::NAN);
    while std::time::Instant::now() < deadline {
        if let Some(s) = snapshots.wait(Duration::from_millis(500)).unwrap() {
            (keyframes, chi2) = (s.header().keyframes, s.header().chi2);
            if keyframes == 3500 && (chi2 - 146.077).abs() < 1e-3 {
                break;
            }
        }
    }
    assert_eq!(keyframes, 3500);
    assert!((chi2 - 146.077).abs() < 1e-3, "final χ² {chi2}");
    let counters = server.join().unwrap();
    assert_eq!((counters.keyframes, counters.rejected), (3500, 0));
}

/// A map made from a file: Manhattan's first 1,750 keyframes solved in
/// batch and written as a saved map (`slamd solve --out FILE.map`), served
/// with `slamd run --map --state`, restarted from the state directory,
/// and continued with the rest of the file (`slamd replay --from 1750`):
/// the replay ends at the whole file's optimum, 146.077, with all 3,500
/// keyframes.
#[test]
fn a_solved_map_restarts_from_its_state_directory_and_continues() {
    let dir = fresh_dir("durable-solved-map");
    std::fs::create_dir_all(&dir).unwrap();
    let file = dataset("manhattanolson3500_g2oversion.g2o");
    let prefix = dir.join("prefix.g2o");
    let kept: Vec<String> = std::fs::read_to_string(&file)
        .unwrap()
        .lines()
        .filter(|line| {
            let t: Vec<&str> = line.split_whitespace().collect();
            let below = |i: usize| {
                t.get(i)
                    .and_then(|x| x.parse::<usize>().ok())
                    .is_some_and(|k| k < 1750)
            };
            match t.first() {
                Some(&"VERTEX_SE2") => below(1),
                Some(&"EDGE_SE2") => below(1) && below(2),
                _ => true,
            }
        })
        .map(str::to_string)
        .collect();
    std::fs::write(&prefix, kept.join("\n") + "\n").unwrap();
    let map = dir.join("prefix.map");
    let (p, m) = (prefix.to_str().unwrap(), map.to_str().unwrap());
    let (code, _, err) = slamd_tests::run_slamd(&["solve", p, "--polish", "--out", m]);
    assert_eq!(code, 0, "{err}");
    let saved = MapFile::<Pose2>::read(&map).expect("a saved map");
    assert_eq!(saved.keyframes.len(), 1750);

    let state = dir.join("state");
    let state = state.to_str().unwrap();
    let namespace = format!("slamd-test-{}-solved-map", std::process::id());
    let served = |args: &[&str]| {
        let daemon = Daemon::serve(&namespace, args, &[]);
        // the restored map is out once the status counts its keyframes
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        loop {
            let status =
                slamd_tests::run_json(&["status", "--namespace", &namespace, "--json", "--wait", "5"]);
            if status["keyframes"].as_u64() == Some(1750) {
                break daemon;
            }
            assert!(std::time::Instant::now() < deadline, "{status}");
            std::thread::sleep(Duration::from_millis(50));
        }
    };
    assert!(served(&["--map", m, "--state", state]).stop().success());
    let daemon = served(&["--state", state]);
    let out = Command::new(slamd_bin())
        .args(["replay", file.to_str().unwrap(), "--namespace", &namespace])
        .args(["--from", "1750", "--json", "--timeout", "60"])
        .output()
        .expect("run the replay");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    assert_eq!(v["keyframes"].as_u64(), Some(3500));
    let chi2 = v["chi2"].as_f64().unwrap();
    assert!((chi2 - 146.077).abs() < 1e-3, "final χ² {chi2}");
    // past the file's end there is nothing to continue with
    let (code, _, err) = slamd_tests::run_slamd(&[
        "replay",
        file.to_str().unwrap(),
        "--namespace",
        &namespace,
        "--from",
        "3500",
    ]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--from 3500: the file has 3500 keyframes"), "{err}");
    assert!(daemon.stop().success());
}

/// A tmpfs mounted for a test, unmounted when it goes.
struct Tmpfs(PathBuf);

impl Tmpfs {
    fn mount(dir: &std::path::Path, size: &str) -> Tmpfs {
        std::fs::create_dir_all(dir).unwrap();
        let status = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
            .arg(dir)
            .status()
            .expect("run mount");
        assert!(
            status.success(),
            "mounting a tmpfs at {} needs root",
            dir.display()
        );
        Tmpfs(dir.to_path_buf())
    }

    fn resize(&self, size: &str) {
        let status = Command::new("mount")
            .args(["-o", &format!("remount,size={size}")])
            .arg(&self.0)
            .status()
            .expect("run mount");
        assert!(status.success(), "remounting {}", self.0.display());
    }
}

impl Drop for Tmpfs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(&self.0).status();
    }
}

/// A daemon on namespace `tag` whose state directory sits on a 300 KiB
/// tmpfs, which Manhattan's journal outgrows partway: the tmpfs, the state
/// directory, the namespace and the daemon.
fn daemon_on_a_small_disk(tag: &str) -> (Tmpfs, PathBuf, String, Daemon) {
    let mount = fresh_dir(&format!("durable-{tag}"));
    let tmpfs = Tmpfs::mount(&mount, "300k");
    let state = mount.join("state");
    let namespace = format!("slamd-test-{}-{tag}", std::process::id());
    let daemon = Daemon::serve(&namespace, &["--state", state.to_str().unwrap()], &[]);
    (tmpfs, state, namespace, daemon)
}

/// Grows `tmpfs` to 100 MiB 10 s from now, on a thread of its own.
fn grow_in_ten_seconds(tmpfs: Tmpfs) -> std::thread::JoinHandle<Tmpfs> {
    std::thread::spawn(move || {
        std::thread::sleep(Duration::from_secs(10));
        tmpfs.resize("100m");
        tmpfs
    })
}

/// The state directory on a 300 KiB tmpfs, which Manhattan's journal
/// outgrows partway: the daemon holds its acknowledgements, the replay
/// waits for it (saying why) instead of giving up after its 5 s, and when
/// the tmpfs grows to 100 MiB 10 s later the replay completes at the
/// optimum with every keyframe.
#[test]
fn a_full_disk_holds_the_stream_until_space_returns() {
    let (tmpfs, state, namespace, daemon) = daemon_on_a_small_disk("full-disk");
    let file = dataset("manhattanolson3500_g2oversion.g2o");
    let replay = Command::new(slamd_bin())
        .args(["replay", file.to_str().unwrap(), "--namespace", &namespace])
        .args(["--json", "--timeout", "5"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the replay");
    let grow = grow_in_ten_seconds(tmpfs);
    let out = replay.wait_with_output().expect("the replay ends");
    let _tmpfs = grow.join().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "replay failed: {stderr}");
    assert!(
        stderr.contains("is alive but holds its acknowledgements: its journal cannot be written"),
        "{stderr}"
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("JSON");
    let chi2 = v["chi2"].as_f64().unwrap();
    assert!((chi2 - 146.077).abs() < 1e-3, "final χ² {chi2}");
    assert!(daemon.stop().success());
    let map = MapFile::<Pose2>::read(&state.join("map")).expect("a checkpoint on SIGTERM");
    assert_eq!(map.keyframes.len(), 3500);
}

/// A frontend's wait for an acknowledgement outlasts its silence bound
/// while the daemon is alive but holding: Manhattan published at once to a
/// daemon whose state directory sits on a 300 KiB tmpfs, grown to 100 MiB
/// 10 s later. `wait_acknowledged` with a 3 s bound waits through the
/// hold, told that the daemon holds and asked to say so, and returns once
/// every message is acknowledged; with the daemon stopped, the same call
/// gives up after its bound.
#[test]
fn a_frontend_waits_for_a_daemon_that_holds_its_acknowledgements() {
    use slamd::ipc::{Endpoint, Frontend};
    use std::time::Instant;
    let (tmpfs, _state, namespace, daemon) = daemon_on_a_small_disk("frontend-holds");
    let started = Instant::now();
    let grow = grow_in_ten_seconds(tmpfs);
    let g = read("manhattanolson3500_g2oversion.g2o");
    let mut f = Frontend::connect(Endpoint::new(&namespace)).unwrap();
    for (k, group) in g.by_newer().iter().enumerate() {
        f.add_keyframe(g.id_of(k), 0, None).unwrap();
        for &e in group {
            f.add_edge(&g.edge_input(e)).unwrap();
        }
        f.flush().unwrap();
    }
    let last = f.last_sequence();
    let silence = Duration::from_secs(3);
    let (mut held, mut said) = (false, false);
    let waiting = Instant::now();
    let acknowledged = f
        .wait_acknowledged_with(last, silence, |w| {
            held |= w.holding;
            said |= w.say && w.to_string().contains("its journal cannot be written");
            true
        })
        .unwrap();
    assert!(
        acknowledged,
        "gave up after {:.1} s",
        waiting.elapsed().as_secs_f64()
    );
    assert!(held && said, "held {held}, said {said}");
    assert!(
        waiting.elapsed() > silence && started.elapsed() >= Duration::from_secs(10),
        "the wait outlasted its bound: {:.1} s",
        waiting.elapsed().as_secs_f64()
    );
    assert_eq!(f.unacknowledged(), 0);
    let _tmpfs = grow.join().unwrap();
    assert!(daemon.stop().success());
    assert!(!f.wait_acknowledged(last + 1, Duration::from_secs(1)).unwrap());
    let gone = Instant::now();
    let after = f.add_keyframe(1_000_000, 0, None).unwrap();
    assert!(!f.wait_acknowledged(after, Duration::from_secs(1)).unwrap());
    assert!(gone.elapsed() < Duration::from_secs(5), "{:?}", gone.elapsed());
}
