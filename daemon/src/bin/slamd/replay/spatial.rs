//! `slamd replay FILE` on a 3-D graph: the engine in this process, the
//! same stream, latency and prefix checks as in 2-D.

use super::{replay, EmbeddedSink, ReplayOpts, Report};
use anyhow::bail;
use slamd::config::Config;
use slamd::engine::Engine;
use slamd::graph::{Pose3, PoseGraph};
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
    let ate = truth
        .as_ref()
        .and_then(|t| slamd::eval::ate3(&graph, &out.poses, t))
        .map(|a| a.rmse);
    let stats = sink.0.stats();
    let report = Report::of(&graph, out, "embedded", Some(stats), ate, |prefix| {
        let options = BatchOptions {
            polish: true,
            ..Default::default()
        };
        Ok(solve_batch3(prefix, &options)?.chi2)
    })?;
    if opts.json {
        println!(
            "{}",
            report.json(opts, skipped, serde_json::json!({ "dimension": "3d" }))
        );
    } else {
        report.print(opts, "embedded, 3-D", || {});
    }
    Ok(())
}
