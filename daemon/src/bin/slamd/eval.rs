//! `slamd eval GRAPH POSES`: χ² and ATE of any pose table on a graph, so a
//! peer's result is scored with exactly slamd's cost and alignment.

use anyhow::Context;
use clap::Args;
use slamd::io;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct EvalOpts {
    /// Graph file (its edges define the cost).
    pub graph: PathBuf,
    /// Poses to score: `id x y theta` per line, or a g2o file with vertices.
    pub poses: PathBuf,
    /// Ground truth: a pose table or a noise-free graph file.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(opts: EvalOpts) -> anyhow::Result<()> {
    let graph = io::read_graph(&opts.graph)?;
    let table = if opts.poses.extension().is_some_and(|e| e == "g2o") {
        let g = io::read_graph(&opts.poses)?;
        g.keyframes()
            .iter()
            .filter_map(|k| k.guess.map(|p| (k.id, p)))
            .collect()
    } else {
        io::read_pose_table(&opts.poses)?
    };
    let poses = graph
        .keyframes()
        .iter()
        .map(|k| {
            table
                .get(&k.id)
                .copied()
                .with_context(|| format!("{}: no pose for keyframe {}", opts.poses.display(), k.id))
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let chi2 = slamd::graph::chi2(&graph, &poses);
    let truth = opts
        .ground_truth
        .as_deref()
        .map(io::read_ground_truth)
        .transpose()?;
    let ate = truth
        .as_ref()
        .and_then(|t| slamd::eval::ate(&graph, &poses, t))
        .map(|a| a.rmse);
    if opts.json {
        println!(
            "{}",
            serde_json::json!({ "nodes": graph.len(), "edges": graph.edges().len(), "chi2": chi2, "ate": ate })
        );
    } else {
        println!("chi2  {chi2:.4}");
        if let Some(a) = ate {
            println!("ate   {a:.4} m");
        }
    }
    Ok(())
}
