//! Helpers shared by slamd's integration tests and benchmarks: where the
//! shared datasets live, noise-free synthetic graphs, feeding a graph to
//! the engine as a frontend would, a handle on the `slamd` binary, and
//! the true loop closures the filter holds off ([`held_off`]).

pub mod held_off;

use slamd::engine::{Engine, EngineConfig};
use slamd::geometry::Pose2;
use slamd::graph::{EdgeKind, Information, PoseGraph};
use slamd::solver::{solve_batch, BatchOptions, BatchSolution};
use std::path::PathBuf;
use std::process::Command;
use std::sync::OnceLock;

/// The environment variable naming the shared datasets folder.
pub const DATASETS_VARIABLE: &str = "SLAMD_DATASETS";

/// The shared datasets: the folder named by `SLAMD_DATASETS`, by default
/// `../shared/datasets` beside the repository. A missing folder fails the
/// caller with a message naming the variable; no test skips for it.
pub fn datasets() -> PathBuf {
    let dir = match std::env::var_os(DATASETS_VARIABLE) {
        Some(dir) => PathBuf::from(dir),
        None => PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/datasets"),
    };
    assert!(
        dir.join("README.md").exists(),
        "no shared datasets at {}: set {DATASETS_VARIABLE} to the folder that holds them \
         (default ../shared/datasets beside the repository)",
        dir.display()
    );
    dir
}

/// One shared dataset file.
pub fn dataset(name: &str) -> PathBuf {
    datasets().join(name)
}

/// Reads a shared dataset.
pub fn read(name: &str) -> PoseGraph {
    slamd::io::read_graph(&dataset(name)).unwrap_or_else(|e| panic!("{e}"))
}

/// The least-squares optimum of `g`: the two-stage solution, polished.
pub fn optimum(g: &PoseGraph) -> BatchSolution {
    let options = BatchOptions {
        polish: true,
        ..Default::default()
    };
    solve_batch(g, &options).expect("a connected graph")
}

/// A graph whose every edge is the exact relative pose between `truth`
/// poses: keyframe ids `0..n`, the pairs given, unit information scaled per
/// edge so that weights differ.
pub fn noise_free(truth: &[Pose2], pairs: &[(usize, usize)]) -> PoseGraph {
    let mut g = PoseGraph::default();
    for id in 0..truth.len() as u64 {
        g.add_keyframe(id, None).expect("fresh id");
    }
    for (k, &(i, j)) in pairs.iter().enumerate() {
        let m = truth[i].between(&truth[j]);
        let w = 1.0 + (k % 7) as f64;
        let info = Information::from_upper([10.0 * w, 1.0, 0.5, 20.0 * w, -0.5, 30.0 * w]).expect("SPD");
        g.add_edge(
            i as u64,
            j as u64,
            m,
            info,
            EdgeKind::from_ids(i as u64, j as u64),
        )
        .expect("valid edge");
    }
    g
}

/// `graph` with `count` Vertigo-style random wrong loop closures appended,
/// drawn from a seeded LCG in a fixed order: both ends uniform over the
/// keyframes (at least 2 apart), the measurement `(u / scale, v / scale,
/// theta)` with `u`, `v` uniform in 0..100, information 42.7·I (Vertigo's
/// default). Returns the spoiled graph and the index of the first.
pub fn with_random_loop_closures(
    graph: &PoseGraph,
    count: usize,
    seed: u64,
    scale: f64,
    theta: f64,
) -> (PoseGraph, usize) {
    let n = graph.len() as u64;
    let mut edges = graph.edges().to_vec();
    let mut rng = seed;
    let mut next = |m: u64| {
        rng = rng
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (rng >> 33) % m
    };
    let first = edges.len();
    while edges.len() < first + count {
        let (a, b) = (next(n) as usize, next(n) as usize);
        if a.abs_diff(b) < 2 {
            continue;
        }
        let m = Pose2::new(next(100) as f64 / scale, next(100) as f64 / scale, theta);
        edges.push(slamd::graph::Edge {
            from: a.min(b),
            to: a.max(b),
            measurement: m,
            information: Information::from_upper([42.7, 0.0, 0.0, 42.7, 0.0, 42.7]).unwrap(),
            kind: EdgeKind::LoopClosure,
        });
    }
    let spoiled = PoseGraph::from_parts(graph.keyframes().to_vec(), edges).unwrap();
    (spoiled, first)
}

/// The poses of a walk from the origin (the gauge) by relative `steps`
/// `(x, y, θ)`, each in the frame of the pose before.
pub fn walk(steps: &[(f64, f64, f64)]) -> Vec<Pose2> {
    let mut poses = vec![Pose2::IDENTITY];
    for &(x, y, t) in steps {
        let last = *poses.last().expect("non-empty");
        poses.push(last.compose(&Pose2::new(x, y, t)));
    }
    poses
}

/// The largest position or heading difference between two pose lists.
pub fn max_pose_error(a: &[Pose2], b: &[Pose2]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| {
            let dt = slamd::geometry::wrap_angle(p.theta - q.theta).abs();
            (p.x - q.x).abs().max((p.y - q.y).abs()).max(dt)
        })
        .fold(0.0, f64::max)
}

/// A directory path under the system's temporary directory named for the
/// test and this process, removed if a run before left it.
pub fn fresh_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("slamd-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// The `slamd` binary of this workspace, built once per test run.
pub fn slamd_bin() -> PathBuf {
    static BIN: OnceLock<PathBuf> = OnceLock::new();
    BIN.get_or_init(|| {
        let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
        let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
        let status = Command::new(cargo)
            .args(["build", "-q", "-p", "slamd", "--bin", "slamd"])
            .current_dir(&root)
            .status()
            .expect("run cargo build");
        assert!(status.success(), "building the slamd binary failed");
        let target = std::env::var("CARGO_TARGET_DIR")
            .map(PathBuf::from)
            .unwrap_or_else(|_| root.join("target"));
        target.join("debug").join("slamd")
    })
    .clone()
}

/// Runs `slamd` with `args`; returns (exit code, stdout, stderr).
pub fn run_slamd(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(slamd_bin()).args(args).output().expect("run slamd");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Runs `slamd … --json` and parses its one JSON object.
pub fn run_json(args: &[&str]) -> serde_json::Value {
    let (code, out, err) = run_slamd(args);
    assert_eq!(code, 0, "slamd {args:?} failed: {err}");
    serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("not JSON ({e}): {out}"))
}

/// Feeds keyframes `range` of `g` to `engine`, each with its edges to
/// older ones ([`PoseGraph::by_newer`]) and one update.
pub fn feed(engine: &mut Engine, g: &PoseGraph, range: std::ops::Range<usize>) {
    let groups = g.by_newer();
    for k in range {
        engine.add_keyframe(g.id_of(k), None).expect("a new keyframe");
        for &e in &groups[k] {
            engine
                .add_edge(g.edge_input(e))
                .expect("an edge between known keyframes");
        }
        engine.update();
    }
}

/// Feeds `g` keyframe by keyframe, each with its edges
/// ([`PoseGraph::by_newer`]) and one update, then calls `each(k, engine)`.
/// Returns the engine and, per engine edge index, the graph edge it came
/// from.
pub fn replay(
    g: &PoseGraph,
    config: EngineConfig,
    mut each: impl FnMut(usize, &mut Engine),
) -> (Engine, Vec<usize>) {
    let mut engine = Engine::new(config);
    let mut sent = Vec::new();
    for (k, group) in g.by_newer().iter().enumerate() {
        engine.add_keyframe(g.id_of(k), None).expect("a new keyframe");
        for &e in group {
            engine
                .add_edge(g.edge_input(e))
                .expect("an edge between known keyframes");
            sent.push(e);
        }
        engine.update();
        each(k, &mut engine);
    }
    (engine, sent)
}

/// The engine's defaults with the ENU frame at `origin` and re-solves
/// inline, so that a test sees when they happen.
pub fn gps_engine_config(origin: slamd::gps::Geodetic) -> EngineConfig {
    EngineConfig {
        gps: slamd::gps::GpsConfig {
            origin: Some(origin),
            ..Default::default()
        },
        background: false,
        ..EngineConfig::default()
    }
}
