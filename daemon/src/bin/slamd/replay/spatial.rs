//! `slamd replay FILE` on a 3-D graph: the engine in this process or a
//! daemon serving 3-D graphs, the same stream, latency and prefix checks
//! as in 2-D.

use super::{replay, DaemonSink, EmbeddedSink, ReplayOpts, Report, Sink};
use anyhow::bail;
use slamd::config::Config;
use slamd::engine::Engine;
use slamd::graph::{Pose3, PoseGraph};
use slamd::io;
use slamd::solver::{solve_batch3, BatchOptions};
use std::time::Duration;

pub fn run(
    opts: &ReplayOpts,
    config: &Config,
    graph: PoseGraph<Pose3>,
    skipped: serde_json::Value,
) -> anyhow::Result<()> {
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
    let (mut embedded, mut daemon);
    let sink: &mut dyn Sink<Pose3> = if opts.embedded {
        embedded = EmbeddedSink(Engine::<Pose3>::create(super::engine_config(opts, config)));
        &mut embedded
    } else {
        if opts.rate.is_some_and(|r| r.is_nan() || r <= 0.0) {
            bail!("--rate must be > 0");
        }
        let timeout = Duration::from_secs_f64(opts.timeout);
        daemon = DaemonSink::connect(&config.namespace, config, timeout, opts.rate, 3)?;
        &mut daemon
    };
    let out = replay(&graph, &[], sink, &checkpoints, false, |_| {})?;
    if let Some(path) = &opts.out {
        let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
        match io::Trajectory::of(path) {
            Some(layout) => {
                io::write_trajectory(&mut w, layout, &crate::solve::keyframe_ids(&graph), &out.poses)?
            }
            None => io::write_g2o3(&mut w, &graph, &out.poses)?,
        }
    }
    let ate = truth
        .as_ref()
        .and_then(|t| slamd::eval::ate3(&graph, &out.poses, t))
        .map(|a| a.rmse);
    let (mode, stats) = (sink.mode(), sink.engine_stats());
    let report = Report::of(&graph, out, mode, stats, ate, |prefix| {
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
        report.print(opts, &format!("{mode}, 3-D"), || {});
    }
    Ok(())
}
