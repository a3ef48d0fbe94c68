//! `slamd eval GRAPH POSES`: χ² and ATE of any pose table on a graph, so a
//! peer's result is scored with exactly slamd's cost and alignment.

use anyhow::Context;
use clap::Args;
use slamd::graph::{EdgeCost, KeyframeId, PoseGraph, RigidMotion};
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
        io::AnyGraph::Planar(graph) => eval(&opts, &graph),
        io::AnyGraph::Spatial(graph) => eval(&opts, &graph),
    }
}

/// What `slamd eval` needs of a pose: its cost, its file and table forms,
/// its ground truth and its alignment.
trait EvalPose: EdgeCost + io::FilePose + io::FromSpatial + io::TruthPose + slamd::eval::Aligned {}

impl<P: EdgeCost + io::FilePose + io::FromSpatial + io::TruthPose + slamd::eval::Aligned> EvalPose for P {}

/// Reads the poses and the ground truth in `graph`'s dimension and scores
/// them.
fn eval<P: EvalPose>(opts: &EvalOpts, graph: &PoseGraph<P>) -> anyhow::Result<()> {
    let table = if let Some(layout) = io::Trajectory::of(&opts.poses) {
        io::read_trajectory(&opts.poses, layout, &crate::solve::keyframe_ids(graph))?
    } else if opts.poses.extension().is_some_and(|e| e == "g2o") {
        vertices(&io::read_graph::<P>(&opts.poses)?)
    } else {
        io::read_pose_table(&opts.poses)?
    };
    let truth = opts
        .ground_truth
        .as_deref()
        .map(io::read_ground_truth)
        .transpose()?;
    score(opts, graph, &table, |poses| {
        truth.as_ref().and_then(|t| slamd::eval::ate(graph, poses, t))
    })
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
