//! The `slamd` command line, end to end.

use crate::daemon::Daemon;
use slamd_tests::{dataset, run_json, run_slamd, slamd_bin};
use std::io::Write;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

#[test]
fn solve_json_reports_the_required_fields() {
    let file = dataset("intel_sesync.g2o");
    let v = run_json(&["solve", file.to_str().expect("utf-8"), "--polish", "--json"]);
    assert_eq!(v["nodes"], 1728);
    assert_eq!(v["edges"], 2512);
    let chi2 = v["chi2"].as_f64().expect("chi2");
    assert!((chi2 - 45.005).abs() < 0.01, "{chi2}");
    assert!(v["seconds"].as_f64().expect("seconds") > 0.0);
    assert!(v["ate"].is_null(), "no ground truth given");
}

/// The replay's latency and accuracy fields, the optimum at the end, and the engine's counters:
/// every inline re-solve and the closing one count among the re-solves;
/// the trace's per-keyframe work adds up to no more than the total.
#[test]
fn replay_json_reports_the_required_fields_and_the_engines_counters() {
    let file = dataset("intel_sesync.g2o");
    let trace = std::env::temp_dir().join(format!("slamd-trace-{}.txt", std::process::id()));
    let v = run_json(&[
        "replay",
        file.to_str().expect("utf-8"),
        "--embedded",
        "--json",
        "--weighted",
        "--trace",
        trace.to_str().expect("utf-8"),
    ]);
    assert_eq!(v["edges"], 2512);
    let (p50, p99, max) = (&v["p50_us"], &v["p99_us"], &v["max_us"]);
    let (p50, p99, max) = (
        p50.as_f64().expect("p50"),
        p99.as_f64().expect("p99"),
        max.as_f64().expect("max"),
    );
    assert!(0.0 < p50 && p50 <= p99 && p99 <= max, "{p50} {p99} {max}");
    assert!(v["total_s"].as_f64().expect("total_s") > 0.0);
    let chi2 = v["chi2"].as_f64().expect("chi2");
    assert!(chi2 <= 1.001 * 45.005, "{chi2}");
    let count = |key: &str| {
        v["engine"][key]
            .as_u64()
            .unwrap_or_else(|| panic!("engine.{key} in {v}"))
    };
    let resolves = v["resolves"].as_u64().expect("resolves");
    assert!(
        resolves > count("nonlinear_resolves") + count("drift_resolves"),
        "{resolves} re-solves: {v}"
    );
    // how many refreshes land depends on the background thread's share of
    // the machine; that they happen is `incremental::a_stream_refreshes_in_the_background`
    let _ = count("refreshes");
    assert_eq!(count("recoveries"), 0, "no downdate fails on clean data: {v}");
    // the snapshots each edge weighed in: one per keyframe's update from
    // the one that sent it, and the settled map; odometry 0 → 1 comes with
    // keyframe 1 of 1,728
    let weighted: Vec<u64> = (v["weighted_snapshots"].as_array())
        .expect("weighted_snapshots")
        .iter()
        .map(|n| n.as_u64().expect("a count"))
        .collect();
    assert_eq!(weighted.len(), 2512);
    assert_eq!((weighted[0], weighted[1]), (1728, 1727));
    // no loop closure of the clean file ends off, so each weighs in at
    // least the settled map; a pending one weighs in none
    assert!(weighted.iter().all(|&n| (1..=1728).contains(&n)), "{weighted:?}");
    let held = weighted.iter().filter(|&&n| n == 1).count();
    assert!(held < 2512, "{held} edges weighed in only the settled map");
    // one line per keyframe with edges: k, latency, walked, solved, nnz
    let lines = std::fs::read_to_string(&trace).expect("the trace");
    let _ = std::fs::remove_file(&trace);
    let rows: Vec<Vec<f64>> = (lines.lines())
        .map(|l| l.split(' ').map(|f| f.parse().expect("a number")).collect())
        .collect();
    assert_eq!(rows.len(), 1727, "every keyframe after the gauge");
    assert!(
        rows.iter().all(|r| r.len() == 5),
        "{:?}",
        rows.iter().find(|r| r.len() != 5)
    );
    let (walked, solved) = (count("walked_entries"), count("solved_entries"));
    let sum = |c: usize| rows.iter().map(|r| r[c]).sum::<f64>() as u64;
    assert!(0 < sum(2) && sum(2) <= walked, "trace {} vs {walked}", sum(2));
    assert!(0 < sum(3) && sum(3) <= solved, "trace {} vs {solved}", sum(3));
    let nnz = rows.last().expect("rows")[4];
    assert!(
        nnz > 1728.0 * 3.0,
        "the factor holds more than its diagonal: {nnz}"
    );
}

#[test]
fn solve_with_ground_truth_reports_ate_and_writes_outputs() {
    let dir = std::env::temp_dir().join(format!("slamd-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("tmp");
    let (out, svg) = (dir.join("ring.g2o"), dir.join("ring.svg"));
    let v = run_json(&[
        "solve",
        dataset("ring.g2o").to_str().expect("utf-8"),
        "--polish",
        "--ground-truth",
        dataset("groundtruth/ring_groundtruth.g2o")
            .to_str()
            .expect("utf-8"),
        "--out",
        out.to_str().expect("utf-8"),
        "--plot",
        svg.to_str().expect("utf-8"),
        "--json",
    ]);
    assert!(v["ate"].as_f64().expect("ate") < 2.0);
    // The written g2o reads back with the same χ².
    let back: slamd::graph::PoseGraph = slamd::io::read_graph(&out).expect("readable");
    let poses: Vec<_> = back
        .keyframes()
        .iter()
        .map(|k| k.guess.expect("vertex"))
        .collect();
    let chi2 = slamd::graph::chi2(&back, &poses);
    assert!((chi2 - v["chi2"].as_f64().expect("chi2")).abs() < 1e-3 * chi2);
    let picture = std::fs::read_to_string(&svg).expect("svg written");
    assert!(
        picture.contains("<svg") && picture.contains("ground truth") && picture.contains("initial guess")
    );
}

#[test]
fn malformed_file_gives_line_and_reason_and_exit_code_2() {
    let path = std::env::temp_dir().join(format!("slamd-bad-{}.g2o", std::process::id()));
    let mut f = std::fs::File::create(&path).expect("tmp");
    writeln!(
        f,
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 inf 0 1"
    )
    .expect("write");
    let (code, _, err) = run_slamd(&["solve", path.to_str().expect("utf-8")]);
    assert_eq!(code, 2);
    assert!(err.contains(":3: EDGE_SE2: non-finite number `inf`"), "{err}");
}

/// An edge to a keyframe the file never declares: the line and the id,
/// said once.
#[test]
fn an_edge_to_an_unknown_keyframe_is_named_once() {
    let path = std::env::temp_dir().join(format!("slamd-unknown-{}.g2o", std::process::id()));
    let text = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 4 1 1 0 0 1 0 0 1 0 1\n";
    std::fs::write(&path, text).expect("write");
    let (code, _, err) = run_slamd(&["solve", path.to_str().expect("utf-8")]);
    let _ = std::fs::remove_file(&path);
    assert_eq!(code, 2);
    assert_eq!(err.matches("unknown keyframe 4").count(), 1, "{err}");
    assert!(err.contains(":4: edge refers to unknown keyframe 4"), "{err}");
}

/// A square with a self-edge, an information that is not positive
/// definite and a repeated vertex: refused as it is, solved with
/// `--skip-invalid` (by `solve` and `replay`), which names what it left out.
#[test]
fn skip_invalid_solves_what_is_left_and_names_the_lines() {
    let path = std::env::temp_dir().join(format!("slamd-skip-{}.g2o", std::process::id()));
    std::fs::write(
        &path,
        "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\nVERTEX_SE2 2 1 1 1.5708\nVERTEX_SE2 3 0 1 3.1416\n\
         VERTEX_SE2 3 5 5 0\n\
         EDGE_SE2 0 1 1 0 1.5708 1 0 0 1 0 1\n\
         EDGE_SE2 1 2 1 0 1.5708 1 0 0 1 0 1\n\
         EDGE_SE2 2 2 0 0 0 1 0 0 1 0 1\n\
         EDGE_SE2 2 3 1 0 1.5708 1 0 0 1 0 1\n\
         EDGE_SE2 3 0 1 0 1.5708 1 0 0 -1 0 1\n\
         EDGE_SE2 3 0 1 0 1.5708 1 0 0 1 0 1\n",
    )
    .expect("write");
    let file = path.to_str().expect("utf-8");
    let (code, _, err) = run_slamd(&["solve", file]);
    assert_eq!(code, 2);
    assert!(
        err.contains(":10: EDGE_SE2: information matrix is not positive definite"),
        "{err}"
    );
    let expected = [
        format!("{file}:5: duplicate keyframe id 3"),
        format!("{file}:8: edge from keyframe 2 to itself"),
        format!("{file}:10: EDGE_SE2: information matrix is not positive definite"),
    ];
    for command in [
        &["solve", file, "--polish"][..],
        &["replay", file, "--embedded"][..],
    ] {
        let mut args = command.to_vec();
        args.extend(["--skip-invalid", "--json"]);
        let v = run_json(&args);
        assert_eq!(v["skipped_lines"]["count"], 3, "{command:?}: {v}");
        assert_eq!(
            v["skipped_lines"]["first"],
            serde_json::json!(expected),
            "{command:?}"
        );
        assert_eq!(v["edges"], 4, "{command:?}");
        // the square closes exactly
        let chi2 = v["chi2"].as_f64().expect("chi2");
        assert!(chi2 < 1e-6, "{command:?}: {chi2}");
    }
    // as text, the count and the lines go to stderr
    let (code, _, err) = run_slamd(&["solve", file, "--skip-invalid"]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("skipped 3 invalid line(s)"), "{err}");
    assert!(err.contains(&expected[1]), "{err}");
}

#[test]
fn disconnected_graph_is_an_error_not_a_nan() {
    let path = std::env::temp_dir().join(format!("slamd-split-{}.g2o", std::process::id()));
    std::fs::write(
        &path,
        "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 3 1 0 0 1 0 0 1 0 1\n",
    )
    .expect("write");
    let (code, _, err) = run_slamd(&["solve", path.to_str().expect("utf-8")]);
    assert_eq!(code, 2);
    assert!(
        err.contains("keyframe 2 has no chain of edges to keyframe 0"),
        "{err}"
    );
}

#[test]
fn a_kernel_parameter_out_of_range_is_refused_by_name() {
    let ring = dataset("ring.g2o");
    let ring = ring.to_str().expect("utf-8");
    for (arg, says) in [
        ("dcs:0", "`dcs:0`: the kernel's parameter 0 must be a number > 0"),
        ("sc:-1", "`sc:-1`: the kernel's parameter -1 must be a number > 0"),
        ("huber", "unknown kernel `huber`"),
    ] {
        let (code, _, err) = run_slamd(&["solve", ring, "--robust", "--kernel", arg]);
        assert_eq!(code, 2, "{arg}: {err}");
        assert!(err.contains(says), "{arg}: {err}");
    }
}

/// A 3-D file is detected and solved; the result written as g2o SE3 is
/// read back by `slamd eval` to the same χ²; the embedded replay streams
/// it to the same optimum, and a 2-D daemon refuses it by name.
#[test]
fn solve_eval_and_replay_read_3d_graphs() {
    let file = dataset("3d/smallgrid3d.g2o");
    let file = file.to_str().expect("utf-8");
    let out = std::env::temp_dir().join(format!("slamd-3d-{}.g2o", std::process::id()));
    let out_s = out.to_str().expect("utf-8");
    let v = run_json(&["solve", file, "--polish", "--json", "--out", out_s]);
    assert_eq!(
        (v["dimension"].as_str(), v["nodes"].as_u64(), v["edges"].as_u64()),
        (Some("3d"), Some(125), Some(297))
    );
    let chi2 = v["chi2"].as_f64().expect("chi2");
    // GTSAM's LM from its chordal initialisation, the edges as written,
    // scores 458.2 under g2o's cost (benches/as_written.py)
    assert!(chi2 <= 458.2 && chi2 > 450.0, "{chi2}");
    let e = run_json(&["eval", file, out_s, "--json"]);
    let _ = std::fs::remove_file(&out);
    let scored = e["chi2"].as_f64().expect("chi2");
    assert!((scored - chi2).abs() < 1e-6 * chi2, "{scored} vs {chi2}");
    let r = run_json(&["replay", file, "--embedded", "--json", "--no-filter"]);
    assert_eq!(r["dimension"].as_str(), Some("3d"));
    let streamed = r["chi2"].as_f64().expect("chi2");
    assert!((streamed - chi2).abs() < 1e-6 * chi2, "{streamed} vs {chi2}");
    // a daemon serving 2-D graphs is named, not fed messages it refuses
    let daemon = Daemon::start("cli-2d", &[]);
    let (code, _, err) = run_slamd(&["replay", file, "--namespace", &daemon.namespace]);
    assert_ne!(code, 0);
    assert!(
        err.contains("serves 2-D graphs and this graph is 3-D; start one with SLAMD_DIMENSION=3"),
        "{err}"
    );
}

/// `--out FILE.tum` and `FILE.kitti` write what `slamd eval` reads back to
/// the χ² the solve printed, in both dimensions, and with the ground truth
/// to the same ATE.
#[test]
fn tum_and_kitti_trajectories_read_back_at_the_same_chi2() {
    let planar = dataset("intel_sesync.g2o");
    let spatial = dataset("3d/smallgrid3d.g2o");
    for file in [planar, spatial] {
        let file = file.to_str().expect("utf-8");
        let solved = run_json(&["solve", file, "--polish", "--json"]);
        let chi2 = solved["chi2"].as_f64().expect("chi2");
        for ext in ["tum", "kitti"] {
            let out = std::env::temp_dir().join(format!("slamd-traj-{}.{ext}", std::process::id()));
            let out_s = out.to_str().expect("utf-8");
            run_json(&["solve", file, "--polish", "--json", "--out", out_s]);
            let lines = std::fs::read_to_string(&out).expect("written").lines().count() as u64;
            assert_eq!(Some(lines), solved["nodes"].as_u64(), "{file} {ext}");
            let scored = run_json(&["eval", file, out_s, "--json"]);
            let _ = std::fs::remove_file(&out);
            let back = scored["chi2"].as_f64().expect("chi2");
            assert!(
                (back - chi2).abs() <= 1e-9 * chi2,
                "{file} {ext}: {back} against {chi2}"
            );
        }
    }
}

/// A second daemon on a namespace a live one serves exits 2 naming it,
/// with nothing else on stderr, and the first one goes on serving.
#[test]
fn a_second_daemon_on_a_served_namespace_names_the_first() {
    let first = Daemon::start("second", &[]);
    let ns = first.namespace.clone();
    // the first publishes its status once its engine thread is up
    let deadline = Instant::now() + Duration::from_secs(20);
    while run_slamd(&["status", "--namespace", &ns]).0 != 0 {
        assert!(Instant::now() < deadline, "no status from `{ns}`");
        std::thread::sleep(Duration::from_millis(50));
    }
    let out = Command::new(slamd_bin())
        .args(["run", "--namespace", &ns])
        .env("SLAMD_LOG", "info")
        .stdin(Stdio::null())
        .output()
        .expect("run a second daemon");
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        format!(
            "slamd: namespace {ns} is already served by slamd (pid {})\n",
            first.pid()
        )
    );
    assert!(out.stdout.is_empty());
    assert_eq!(
        run_slamd(&["status", "--namespace", &ns]).0,
        0,
        "the first daemon stopped serving"
    );
    assert!(first.stop().success());
}
