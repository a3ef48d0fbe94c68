//! `slamd replay FILE` on a 3-D graph: the engine in this process, the
//! same stream, latency and prefix checks as in 2-D.

use super::{replay, EmbeddedSink, Latency, ReplayOpts};
use crate::solve::file_name;
use anyhow::bail;
use slamd::config::Config;
use slamd::engine::Engine;
use slamd::graph::{chi2, Pose3, PoseGraph};
use slamd::io;
use slamd::solver::{solve_batch3, BatchOptions};

pub fn run(
    opts: &ReplayOpts,
    config: &Config,
    graph: PoseGraph<Pose3>,
    skipped: serde_json::Value,
) -> anyhow::Result<()> {
    if !opts.embedded {
        bail!("the daemon serves 2-D graphs; replay a 3-D graph with --embedded");
    }
    if opts.gps.gps.is_some() {
        bail!("--gps is not available for 3-D graphs");
    }
    graph.check_connected()?;
    let truth = opts
        .ground_truth
        .as_deref()
        .map(io::read_ground_truth3)
        .transpose()?;
    let checkpoints: Vec<usize> = (1..=opts.check_prefixes)
        .map(|i| (i * graph.len() / (opts.check_prefixes + 1)).max(1))
        .collect();
    let mut sink = EmbeddedSink(Engine::<Pose3>::create(super::engine_config(opts, config)));
    let out = replay(&graph, &[], &mut sink, &checkpoints, false, |_| {})?;
    if let Some(path) = &opts.out {
        let file = std::fs::File::create(path)?;
        io::write_g2o3(&mut std::io::BufWriter::new(file), &graph, &out.poses)?;
    }
    let final_chi2 = chi2(&graph, &out.poses);
    let ate = truth
        .as_ref()
        .and_then(|t| slamd::eval::ate3(&graph, &out.poses, t))
        .map(|a| a.rmse);
    let ratios = out
        .checked
        .iter()
        .map(|(k, poses)| {
            let prefix = graph.prefix(k + 1);
            let options = BatchOptions {
                polish: true,
                ..Default::default()
            };
            let best = solve_batch3(&prefix, &options)?;
            Ok((k + 1, chi2(&prefix, poses) / best.chi2.max(f64::MIN_POSITIVE)))
        })
        .collect::<anyhow::Result<Vec<(usize, f64)>>>()?;
    let worst_ratio = ratios.iter().map(|&(_, r)| r).reduce(f64::max);
    let robust = crate::robust::Rejected::of(&graph, out.switches.as_deref());
    let lat = Latency::of(out.latencies);
    let stats = sink.0.stats();
    if opts.json {
        let v = serde_json::json!({
            "file": opts.file.display().to_string(),
            "dimension": "3d",
            "skipped_lines": skipped,
            "mode": "embedded",
            "keyframes": graph.len(),
            "edges": graph.edges().len(),
            "p50_us": lat.p50,
            "p99_us": lat.p99,
            "max_us": lat.max,
            "total_s": out.total_s,
            "closing_s": out.closing_s,
            "resolves": out.resolves,
            "engine": {
                "refreshes": stats.refreshes,
                "relinearisations": stats.relinearisations,
                "nonlinear_resolves": stats.nonlinear_resolves,
                "drift_resolves": stats.drift_resolves,
                "recoveries": stats.recoveries,
                "walked_entries": stats.work.walked,
                "solved_entries": stats.work.solved,
            },
            "chi2": final_chi2,
            "ate": ate,
            "prefixes_checked": out.checked.len(),
            "worst_prefix_ratio": worst_ratio,
            "prefix_ratios": ratios,
            "loop_closures": robust.loop_closures,
            "switched_off": robust.rejected.len(),
            "rejected_edges": out.switches.as_ref().map(|_| &robust.rejected),
        });
        println!("{v}");
    } else {
        println!(
            "{} (embedded, 3-D): {} keyframes, {} edges",
            file_name(&opts.file),
            graph.len(),
            graph.edges().len()
        );
        println!(
            "latency per keyframe  p50 {:.0} µs  p99 {:.0} µs  max {:.0} µs",
            lat.p50, lat.p99, lat.max
        );
        println!(
            "total                 {:.3} s  ({} re-solves; closing one {:.3} s)",
            out.total_s, out.resolves, out.closing_s
        );
        println!("final chi2            {final_chi2:.3}");
        if let Some(a) = ate {
            println!("ate                   {a:.4} m");
        }
        println!(
            "loop closures         {} ({} switched off)",
            robust.loop_closures,
            robust.rejected.len()
        );
        if let Some(w) = worst_ratio {
            println!(
                "worst snapshot/prefix-optimum chi2 over {} prefixes: {w:.4}",
                out.checked.len()
            );
        }
    }
    Ok(())
}
