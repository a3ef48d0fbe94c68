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
    /// Poses to score: a g2o file with vertices, or one pose per line
    /// (`id x y theta`; in 3-D `id x y z qx qy qz qw`).
    pub poses: PathBuf,
    /// Ground truth: a pose table or a noise-free graph file.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(opts: EvalOpts) -> anyhow::Result<()> {
    let graph = match io::read_any_graph_with(&opts.graph, io::OnInvalid::Refuse)?.0 {
        io::AnyGraph::Planar(g) => g,
        io::AnyGraph::Spatial(g) => return run3(&opts, &g),
    };
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

/// `slamd eval` on a 3-D graph: the poses are a 3-D g2o file's vertices or
/// `id x y z qx qy qz qw` lines.
fn run3(opts: &EvalOpts, graph: &slamd::graph::PoseGraph<slamd::graph::Pose3>) -> anyhow::Result<()> {
    use slamd::graph::Pose3;
    use std::collections::HashMap;
    let table: HashMap<u64, Pose3> = if opts.poses.extension().is_some_and(|e| e == "g2o") {
        let g = io::read_graph3(&opts.poses)?;
        g.keyframes()
            .iter()
            .filter_map(|k| k.guess.map(|p| (k.id, p)))
            .collect()
    } else {
        let text = std::fs::read_to_string(&opts.poses)
            .with_context(|| format!("reading {}", opts.poses.display()))?;
        let mut table = HashMap::new();
        for (n, line) in text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'))
        {
            let bad = || {
                format!(
                    "{}:{}: expected `id x y z qx qy qz qw`",
                    opts.poses.display(),
                    n + 1
                )
            };
            let f: Vec<&str> = line.split_whitespace().collect();
            let id: u64 = f.first().and_then(|t| t.parse().ok()).with_context(bad)?;
            let v: Vec<f64> = f[1..]
                .iter()
                .map(|t| t.parse::<f64>())
                .collect::<Result<_, _>>()
                .ok()
                .with_context(bad)?;
            let pose = <[f64; 7]>::try_from(v)
                .ok()
                .and_then(Pose3::from_xyz_quaternion)
                .with_context(bad)?;
            table.insert(id, pose);
        }
        table
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
    let chi2 = slamd::graph::chi2(graph, &poses);
    let truth = opts
        .ground_truth
        .as_deref()
        .map(io::read_ground_truth3)
        .transpose()?;
    let ate = truth
        .as_ref()
        .and_then(|t| slamd::eval::ate3(graph, &poses, t))
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
