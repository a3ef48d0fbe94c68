//! `slamd replay FILE`: stream a dataset in time order, one snapshot per
//! keyframe, and report latency and accuracy.
//!
//! `--embedded` runs the engine in this process. A keyframe's edges arrive
//! together, as a frontend publishes them; its latency runs from their
//! arrival (before the first is applied) to its snapshot being ready.

use crate::solve::file_name;
use anyhow::Context;
use clap::Args;
use slamd::engine::{EdgeInput, Engine, EngineConfig, SnapshotSource};
use slamd::graph::{chi2, PoseGraph};
use slamd::io;
use slamd::solver::{solve_batch, BatchOptions};
use std::path::PathBuf;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct ReplayOpts {
    /// Graph file to stream (edges are sorted by time: max(i, j), min(i, j)).
    pub file: PathBuf,
    /// Run the engine in this process instead of talking to a daemon.
    #[arg(long)]
    pub embedded: bool,
    /// Ground truth for the ATE of the final estimate.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Check this many evenly spaced snapshots against the batch optimum of
    /// their own prefix (slow on big files: one batch solve each).
    #[arg(long, default_value_t = 0)]
    pub check_prefixes: usize,
    /// Re-solve every this many edges (0: only on fill).
    #[arg(long)]
    pub resolve_every: Option<usize>,
    /// Snapshot source between re-solves: linear or gauss-newton.
    #[arg(long, value_parser = parse_source)]
    pub snapshot: Option<SnapshotSource>,
    /// Defer consistent loop closures below this χ² (see EngineConfig).
    #[arg(long)]
    pub defer_chi2: Option<f64>,
    /// Keyframes kept last in a fresh ordering (see EngineConfig).
    #[arg(long)]
    pub recent_last: Option<usize>,
    /// Write one line per keyframe (`k chi2 latency_us moved resolved`).
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Latency percentiles of a run, in microseconds.
pub struct Latency {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl Latency {
    pub fn of(mut samples: Vec<f64>) -> Latency {
        samples.sort_by(f64::total_cmp);
        let at = |q: f64| {
            if samples.is_empty() {
                0.0
            } else {
                samples[((samples.len() - 1) as f64 * q).round() as usize]
            }
        };
        Latency {
            p50: at(0.5),
            p99: at(0.99),
            max: at(1.0),
        }
    }
}

/// Edge indices grouped by the keyframe that makes them available.
pub fn edges_by_keyframe(graph: &PoseGraph) -> Vec<Vec<usize>> {
    let mut groups = vec![Vec::new(); graph.len()];
    for e in graph.time_order() {
        groups[graph.edges()[e].newer()].push(e);
    }
    groups
}

pub fn run(opts: ReplayOpts) -> anyhow::Result<()> {
    anyhow::ensure!(opts.embedded, "only --embedded replay exists so far");
    let graph = io::read_graph(&opts.file)?;
    graph.check_connected()?;
    let truth = opts
        .ground_truth
        .as_deref()
        .map(io::read_ground_truth)
        .transpose()?;
    let mut config = EngineConfig::default();
    if let Some(n) = opts.resolve_every {
        config.resolve_every_edges = n;
    }
    if let Some(r) = opts.recent_last {
        config.recent_last = r;
    }
    if let Some(d) = opts.defer_chi2 {
        config.defer_chi2 = d;
    }
    if let Some(s) = opts.snapshot {
        config.snapshot = s;
    }
    let groups = edges_by_keyframe(&graph);
    let checkpoints: Vec<usize> = (1..=opts.check_prefixes)
        .map(|i| (i * graph.len() / (opts.check_prefixes + 1)).max(1))
        .collect();
    let mut checked = Vec::new();

    let mut engine = Engine::new(config);
    let mut latencies = Vec::with_capacity(graph.len());
    let mut trace = Vec::new();
    let start = Instant::now();
    for (k, group) in groups.iter().enumerate() {
        engine.add_keyframe(graph.id_of(k), None)?;
        let arrival = Instant::now();
        for &e in group {
            let edge = graph.edges()[e];
            engine.add_edge(EdgeInput::new(
                graph.id_of(edge.from),
                graph.id_of(edge.to),
                edge.measurement,
                edge.information,
                edge.kind,
            ))?;
        }
        let report = engine.update();
        let latency = arrival.elapsed().as_secs_f64() * 1e6;
        if !group.is_empty() {
            latencies.push(latency);
        }
        if opts.trace.is_some() {
            trace.push(format!(
                "{k} {} {latency:.1} {} {}",
                report.chi2,
                report.moved,
                u8::from(report.resolved)
            ));
        }
        if checkpoints.contains(&k) {
            let poses: Vec<_> = engine.snapshot().poses().map(|(_, p)| p).collect();
            checked.push((k, report.chi2, poses));
        }
    }
    let stream_seconds = start.elapsed().as_secs_f64();
    if let Some(path) = &opts.trace {
        std::fs::write(path, trace.join("\n") + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    let final_report = engine.resolve_now();
    let total = start.elapsed().as_secs_f64();
    let latency_sum: f64 = latencies.iter().sum::<f64>() * 1e-6;
    let poses: Vec<_> = engine.snapshot().poses().map(|(_, p)| p).collect();
    anyhow::ensure!(
        poses.len() == graph.len(),
        "{} keyframes never joined the map",
        graph.len() - poses.len()
    );
    let final_chi2 = chi2(&graph, &poses);
    let ate = truth
        .as_ref()
        .and_then(|t| slamd::eval::ate(&graph, &poses, t))
        .map(|a| a.rmse);
    let lat = Latency::of(latencies);
    let stats = engine.stats();

    // each checked snapshot against the optimum of its own prefix
    let mut worst_ratio: Option<f64> = None;
    for (k, snap_chi2, snap_poses) in &checked {
        let prefix = graph.prefix(k + 1);
        let best = solve_batch(
            &prefix,
            &BatchOptions {
                polish: true,
                ..Default::default()
            },
        )
        .with_context(|| format!("batch solve of the first {} keyframes", k + 1))?;
        let ratio = chi2(&prefix, snap_poses) / best.chi2.max(f64::MIN_POSITIVE);
        tracing::debug!(k, snap_chi2, optimum = best.chi2, ratio, "Prefix checked.");
        worst_ratio = Some(worst_ratio.map_or(ratio, |w: f64| w.max(ratio)));
    }

    if opts.json {
        let v = serde_json::json!({
            "file": opts.file.display().to_string(),
            "mode": "embedded",
            "keyframes": graph.len(),
            "edges": graph.edges().len(),
            "p50_us": lat.p50,
            "p99_us": lat.p99,
            "max_us": lat.max,
            "total_s": total,
            "resolves": stats.resolves,
            "resolve_seconds": stats.resolve_seconds,
            "stream_seconds": stream_seconds,
            "latency_sum_s": latency_sum,
            "chi2": final_chi2,
            "engine_chi2": final_report.chi2,
            "ate": ate,
            "prefixes_checked": checked.len(),
            "worst_prefix_ratio": worst_ratio,
        });
        println!("{v}");
    } else {
        println!(
            "{} (embedded): {} keyframes, {} edges",
            file_name(&opts.file),
            graph.len(),
            graph.edges().len()
        );
        println!(
            "latency per keyframe  p50 {:.0} µs  p99 {:.0} µs  max {:.0} µs",
            lat.p50, lat.p99, lat.max
        );
        println!(
            "total                 {total:.3} s  ({} re-solves, {:.2} s on the re-solve thread)",
            stats.resolves, stats.resolve_seconds
        );
        println!("final chi2            {final_chi2:.3}");
        if let Some(a) = ate {
            println!("ate                   {a:.4} m");
        }
        if let Some(w) = worst_ratio {
            println!(
                "worst snapshot/prefix-optimum chi2 over {} prefixes: {w:.4}",
                checked.len()
            );
        }
    }
    Ok(())
}

fn parse_source(s: &str) -> Result<SnapshotSource, String> {
    match s {
        "linear" => Ok(SnapshotSource::Linear),
        "gauss-newton" => Ok(SnapshotSource::GaussNewton),
        _ => Err(format!("unknown snapshot source `{s}` (linear, gauss-newton)")),
    }
}
