//! `slamd eval GRAPH POSES`: χ² and ATE of any pose table on a graph, so a
//! peer's result is scored with exactly slamd's cost and alignment.

use anyhow::Context;
use clap::Args;
use slamd::graph::{EdgeCost, KeyframeId, Pose3, PoseGraph, RigidMotion};
use slamd::io;
use std::collections::HashMap;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct EvalOpts {
    /// Graph file (its edges define the cost).
    pub graph: PathBuf,
    /// Poses to score: a g2o file with vertices, a trajectory (`.tum`:
    /// `t x y z qx qy qz qw` with the keyframe id as `t`; `.kitti`: `[R | t]`
    /// rows in keyframe order), or one pose per line (`id x y theta`; in
    /// 3-D `id x y z qx qy qz qw`).
    pub poses: PathBuf,
    /// Ground truth: a pose table or a noise-free graph file.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(opts: EvalOpts) -> anyhow::Result<()> {
    match io::read_any_graph_with(&opts.graph, io::OnInvalid::Refuse)?.0 {
        io::AnyGraph::Planar(graph) => {
            let table = if let Some(layout) = io::Trajectory::of(&opts.poses) {
                io::read_trajectory(&opts.poses, layout, &crate::solve::keyframe_ids(&graph))?
            } else if opts.poses.extension().is_some_and(|e| e == "g2o") {
                vertices(&io::read_graph::<slamd::geometry::Pose2>(&opts.poses)?)
            } else {
                io::read_pose_table(&opts.poses)?
            };
            let truth = opts
                .ground_truth
                .as_deref()
                .map(io::read_ground_truth)
                .transpose()?;
            score(&opts, &graph, &table, |poses| {
                truth.as_ref().and_then(|t| slamd::eval::ate(&graph, poses, t))
            })
        }
        io::AnyGraph::Spatial(graph) => {
            let table = if let Some(layout) = io::Trajectory::of(&opts.poses) {
                io::read_trajectory(&opts.poses, layout, &crate::solve::keyframe_ids(&graph))?
            } else if opts.poses.extension().is_some_and(|e| e == "g2o") {
                vertices(&io::read_graph::<Pose3>(&opts.poses)?)
            } else {
                read_table3(&opts.poses)?
            };
            let truth = opts
                .ground_truth
                .as_deref()
                .map(io::read_ground_truth)
                .transpose()?;
            score(&opts, &graph, &table, |poses| {
                truth.as_ref().and_then(|t| slamd::eval::ate(&graph, poses, t))
            })
        }
    }
}

/// The vertices of a graph file, by keyframe id.
fn vertices<P: RigidMotion>(graph: &PoseGraph<P>) -> HashMap<KeyframeId, P> {
    graph
        .keyframes()
        .iter()
        .filter_map(|k| k.guess.map(|p| (k.id, p)))
        .collect()
}

/// χ² of the poses in `table` on `graph`, and their ATE, printed.
fn score<P: EdgeCost>(
    opts: &EvalOpts,
    graph: &PoseGraph<P>,
    table: &HashMap<KeyframeId, P>,
    ate: impl Fn(&[P]) -> Option<slamd::eval::Ate>,
) -> anyhow::Result<()> {
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
    let ate = ate(&poses).map(|a| a.rmse);
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

/// `id x y z qx qy qz qw` lines.
fn read_table3(path: &std::path::Path) -> anyhow::Result<HashMap<KeyframeId, Pose3>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    let mut table = HashMap::new();
    for (n, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.starts_with('#'))
    {
        let bad = || format!("{}:{}: expected `id x y z qx qy qz qw`", path.display(), n + 1);
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
    Ok(table)
}
