//! `slamd replay FILE` on a 3-D graph: the engine in this process or a
//! daemon serving 3-D graphs, the same stream, latency and prefix checks
//! as in 2-D.

use super::{replay, ReplayOpts};
use anyhow::bail;
use slamd::config::Config;
use slamd::graph::{Pose3, PoseGraph};
use slamd::io;

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
        .map(io::read_ground_truth)
        .transpose()?;
    let checkpoints = super::checkpoints(opts, graph.len());
    let mut sink = super::sink::<Pose3>(opts, config)?;
    let out = replay(&graph, &[], sink.as_mut(), &checkpoints, false, opts.from, |_| {})?;
    if let Some(path) = &opts.out {
        crate::solve::write_result(path, &graph, &out.poses, out.switches.as_deref())?;
    }
    let mode = sink.mode();
    let report = super::report(&graph, out, sink.as_ref(), truth.as_ref())?;
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
