//! `slamd demo`: the README's first command. Solves the built-in synthetic
//! world (or `--dataset FILE`), prints accuracy and time, and draws the map.

use crate::solve::file_name;
use clap::Args;
use slamd::eval::ate;
use slamd::graph::{chi2, KeyframeId, PoseGraph};
use slamd::io::svg;
use slamd::solver::{solve_batch, BatchOptions};
use slamd::synthetic::{generate, WorldParams};
use std::collections::HashMap;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct DemoOpts {
    /// Keyframes of the synthetic world.
    #[arg(long, default_value_t = 3000)]
    pub poses: usize,
    /// Seed of the synthetic world.
    #[arg(long, default_value_t = 7)]
    pub seed: u64,
    /// Replay this graph file instead of the synthetic world.
    #[arg(long)]
    pub dataset: Option<PathBuf>,
    /// Where to write the picture.
    #[arg(long, default_value = "slamd-demo.svg")]
    pub out: PathBuf,
}

pub fn run(opts: DemoOpts) -> anyhow::Result<()> {
    let (name, graph, truth): (String, PoseGraph, Option<HashMap<KeyframeId, _>>) = match &opts.dataset {
        Some(path) => (file_name(path), slamd::io::read_graph(path)?, None),
        None => {
            let w = generate(&WorldParams {
                poses: opts.poses,
                seed: opts.seed,
                ..Default::default()
            });
            let truth = w.graph.keyframes().iter().map(|k| k.id).zip(w.truth).collect();
            (
                format!("synthetic world (seed {})", opts.seed),
                w.graph,
                Some(truth),
            )
        }
    };
    let odometry = graph.compose_spanning_tree()?;
    let sol = solve_batch(
        &graph,
        &BatchOptions {
            polish: true,
            ..Default::default()
        },
    )?;
    println!("{name}: {} keyframes, {} edges", graph.len(), graph.edges().len());
    println!("{:<22} {:>14} {:>10}", "estimate", "chi2", "ATE (m)");
    let ate_of = |p: &[slamd::geometry::Pose2]| {
        truth
            .as_ref()
            .and_then(|t| ate(&graph, p, t))
            .map_or("–".to_string(), |a| format!("{:.3}", a.rmse))
    };
    println!(
        "{:<22} {:>14.2} {:>10}",
        "odometry only",
        chi2(&graph, &odometry),
        ate_of(&odometry)
    );
    println!("{:<22} {:>14.2} {:>10}", "two-stage linear", sol.linear_chi2, "");
    println!(
        "{:<22} {:>14.2} {:>10}",
        "slamd (polished)",
        sol.chi2,
        ate_of(&sol.poses)
    );
    println!("solve time {:.1} ms", sol.seconds() * 1e3);
    let truth_poses: Option<Vec<_>> = truth.as_ref().map(|t| {
        slamd::eval::aligned_onto(
            &graph.keyframes().iter().map(|k| t[&k.id]).collect::<Vec<_>>(),
            &sol.poses,
        )
    });
    let mut layers = vec![svg::Layer {
        label: "slamd",
        poses: &sol.poses,
        color: svg::ESTIMATE,
    }];
    if let Some(t) = &truth_poses {
        layers.push(svg::Layer {
            label: "ground truth",
            poses: t,
            color: svg::TRUTH,
        });
    }
    layers.push(svg::Layer {
        label: "odometry only",
        poses: &odometry,
        color: svg::GUESS,
    });
    svg::write_svg(&opts.out, &name, &layers).map_err(anyhow::Error::msg)?;
    println!("map written to {}", opts.out.display());
    Ok(())
}
