//! What one keyframe costs the incremental Gauss–Newton factor, away from
//! the engine's threads: a fresh factor of a dataset's first `n0`
//! keyframes (linearised at their batch optimum, ordered as a re-solve
//! orders them), then the next keyframes streamed one at a time, each
//! with its edges and one solve. Deterministic work, one thread; prints
//! a table (min of `--runs` runs). `build ms` is the fresh factor itself
//! (ordering, Hessian, factorisation, copy into the dynamic factor): the
//! part of a background refresh before its catch-up.
//!
//! `cargo bench -p slamd-benches --bench incremental_path -- [DATASET] [--runs R] [--append K] [--recent-last L]`

use slamd::engine::gauss_newton::GaussNewton;
use slamd::engine::EngineConfig;
use slamd::geometry::Pose2;
use slamd::graph::{EdgeKind, PoseGraph};
use slamd::solver::{solve_batch, BatchOptions};
use slamd::sparse::ordering::amd_newest_last;
use std::time::Instant;

/// The engine's wildfire threshold.
const THRESHOLD: f64 = 1e-4;

struct Run {
    build_s: f64,
    update_s: f64,
    solve_s: f64,
    nnz0: usize,
    nnz1: usize,
    walks: u64,
    columns: u64,
    entries: u64,
    touched: u64,
    visited: u64,
    read: u64,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).filter(|a| a != "--bench").collect();
    let value = |flag: &str, default: usize| {
        args.iter()
            .position(|a| a == flag)
            .and_then(|k| args.get(k + 1))
            .map_or(default, |v| v.parse().expect("a number"))
    };
    let name = args
        .iter()
        .find(|a| a.ends_with(".g2o") || a.ends_with(".graph"))
        .map_or("city10000.g2o", String::as_str);
    let (runs, append) = (value("--runs", 3), value("--append", 300));
    // keyframes kept last in the fresh ordering
    let recent = value("--recent-last", EngineConfig::default().recent_last);
    let graph = slamd_tests::read(name);
    let groups = graph.by_newer();
    println!("{name}: fresh factor at n0 keyframes, then {append} keyframes streamed (min of {runs} runs)\n");
    println!("| n0 | build ms | update ms | solve ms | per keyframe µs | nnz(L) fresh → after | walks | columns per walk | entries per column | solve: touched / visited columns | entries read |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    let n = graph.len();
    for n0 in [n * 3 / 10, n * 6 / 10, n * 9 / 10] {
        let n1 = (n0 + append).min(n);
        let prefix = graph.prefix(n0);
        let opts = BatchOptions {
            polish: true,
            ..Default::default()
        };
        let lin = solve_batch(&prefix, &opts).expect("prefix solves").poses;
        let all: Vec<Run> = (0..runs)
            .map(|_| stream(&graph, &groups, &lin, (n0, n1), recent))
            .collect();
        let build_s = all.iter().map(|r| r.build_s).fold(f64::INFINITY, f64::min);
        let best = all
            .into_iter()
            .min_by(|a, b| (a.update_s + a.solve_s).total_cmp(&(b.update_s + b.solve_s)))
            .expect("one run");
        println!(
            "| {n0} | {:.1} | {:.1} | {:.1} | {:.0} | {} → {} | {} | {:.0} | {:.0} | {:.0} / {:.0} | {:.0} |",
            1e3 * build_s,
            1e3 * best.update_s,
            1e3 * best.solve_s,
            1e6 * (best.update_s + best.solve_s) / (n1 - n0) as f64,
            best.nnz0,
            best.nnz1,
            best.walks,
            best.columns as f64 / best.walks.max(1) as f64,
            best.entries as f64 / best.columns.max(1) as f64,
            best.touched as f64 / (n1 - n0) as f64,
            best.visited as f64 / (n1 - n0) as f64,
            best.read as f64 / (n1 - n0) as f64,
        );
    }
}

/// Builds the factor of keyframes `0..n0` at `lin` and streams `n0..n1`
/// as the engine does: a keyframe joins through its odometry, then its
/// loop closures enter, then one solve.
fn stream(
    graph: &PoseGraph,
    groups: &[Vec<usize>],
    lin: &[Pose2],
    (n0, n1): (usize, usize),
    recent: usize,
) -> Run {
    let prefix = graph.prefix(n0);
    let edges: Vec<(usize, f64)> = (0..prefix.edges().len()).map(|e| (e, 1.0)).collect();
    let built = Instant::now();
    let pairs = prefix
        .edges()
        .iter()
        .filter(|edge| edge.from > 0 && edge.to > 0)
        .map(|edge| (edge.from - 1, edge.to - 1));
    let order: Vec<usize> = amd_newest_last(n0 - 1, pairs, recent)
        .into_iter()
        .map(|c| c + 1)
        .collect();
    let mut gn = GaussNewton::build(&prefix, &edges, &[], lin.to_vec(), &order).expect("factorises");
    let build_s = built.elapsed().as_secs_f64();
    let nnz0 = gn.factor_nnz();
    let walked0 = gn.factor().walk_stats();
    let solved0 = gn.solve_stats();
    let (mut update_s, mut solve_s) = (0.0, 0.0);
    for (k, group) in groups.iter().enumerate().take(n1).skip(n0) {
        let t = Instant::now();
        let mut group = group.clone();
        group.sort_by_key(|&e| graph.edges()[e].kind != EdgeKind::Odometry);
        for (n, &e) in group.iter().enumerate() {
            let edge = graph.edges()[e];
            if n == 0 {
                // the first edge (odometry) places the new keyframe
                let (m, rel) = if edge.to == k {
                    (edge.from, edge.measurement)
                } else {
                    (edge.to, edge.measurement.inverse())
                };
                let guess = gn.estimate()[m].compose(&rel);
                gn.add_keyframe(k, guess);
            }
            gn.apply_edge(&edge, 1.0).expect("an update never fails");
        }
        // the updates wait in a batch: apply them here, so that the
        // update column times the walks and the solve column the solve
        gn.flush().expect("updates never fail");
        let u = Instant::now();
        gn.solve(THRESHOLD).expect("updates never fail");
        solve_s += u.elapsed().as_secs_f64();
        update_s += (u - t).as_secs_f64();
    }
    let walked = gn.factor().walk_stats();
    let solved = gn.solve_stats();
    Run {
        build_s,
        touched: solved.touched - solved0.touched,
        visited: solved.visited - solved0.visited,
        read: solved.entries - solved0.entries,
        update_s,
        solve_s,
        nnz0,
        nnz1: gn.factor_nnz(),
        walks: walked.walks - walked0.walks,
        columns: walked.columns - walked0.columns,
        entries: walked.entries - walked0.entries,
    }
}
