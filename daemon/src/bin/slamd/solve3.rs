//! `slamd solve FILE` on a 3-D graph: the chordal two-stage initialiser,
//! then optionally the polish on g2o's SE(3) cost.

use crate::solve::{file_name, SolveOpts};
use anyhow::{bail, Context};
use slamd::eval::{aligned_onto, ate3};
use slamd::geometry::Pose2;
use slamd::graph::{Pose3, PoseGraph};
use slamd::io::{self, svg};
use slamd::outliers::OutlierConfig;
use slamd::solver::{solve_batch3, BatchOptions};

pub fn run(opts: &SolveOpts, graph: &PoseGraph<Pose3>, skipped: serde_json::Value) -> anyhow::Result<()> {
    if opts.gps.gps.is_some() {
        bail!("--gps is not available for 3-D graphs");
    }
    if opts.odometry_only {
        bail!("--odometry-only is not available for 3-D graphs");
    }
    let truth = opts
        .ground_truth
        .as_deref()
        .map(io::read_ground_truth3)
        .transpose()?;
    let options = BatchOptions {
        formulation: opts.formulation,
        polish: opts.polish,
        robust: opts.robust.then(|| opts.filter.apply(OutlierConfig::default())),
        ..Default::default()
    };
    let sol = solve_batch3(graph, &options).with_context(|| format!("solving {}", opts.file.display()))?;
    let ate = truth.as_ref().and_then(|t| ate3(graph, &sol.poses, t));
    if let Some(out) = &opts.out {
        let file = std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
        let mut w = std::io::BufWriter::new(file);
        if out.extension().is_some_and(|e| e == "g2o") {
            io::write_g2o3(&mut w, graph, &sol.poses)?;
        } else {
            for (k, p) in graph.keyframes().iter().zip(&sol.poses) {
                let v = p.to_xyz_quaternion().map(|x| x.to_string()).join(" ");
                std::io::Write::write_all(&mut w, format!("{} {v}\n", k.id).as_bytes())?;
            }
        }
    }
    if let Some(plot) = &opts.plot {
        plot_top_view(plot, opts, graph, &sol.poses, truth.as_ref())?;
    }
    let iterations = sol.polish.as_ref().map(|r| r.iterations.len());
    let robust = crate::robust::Rejected::of(graph, sol.switches.as_deref());
    if opts.json {
        let v = serde_json::json!({
            "file": opts.file.display().to_string(),
            "dimension": "3d",
            "formulation": opts.formulation.name(),
            "polish": opts.polish,
            "nodes": graph.len(),
            "edges": graph.edges().len(),
            "chi2": sol.chi2,
            "linear_chi2": sol.linear_chi2,
            "ate": ate.map(|a| a.rmse),
            "seconds": sol.seconds(),
            "linear_seconds": sol.linear_seconds,
            "polish_seconds": sol.polish_seconds,
            "iterations": iterations,
            "robust": opts.robust,
            "loop_closures": robust.loop_closures,
            "rejected_edges": sol.switches.as_ref().map(|_| &robust.rejected),
            "skipped_lines": skipped,
        });
        println!("{v}");
    } else {
        println!("file           {}  (3-D)", opts.file.display());
        println!("keyframes      {}", graph.len());
        println!("edges          {}", graph.edges().len());
        println!("formulation    {}", opts.formulation);
        println!(
            "linear chi2    {:.3}  ({:.1} ms)",
            sol.linear_chi2,
            sol.linear_seconds * 1e3
        );
        if let Some(r) = &sol.polish {
            println!(
                "polish         {} iterations, converged: {}  ({:.1} ms)",
                r.iterations.len(),
                r.converged,
                sol.polish_seconds * 1e3
            );
        }
        println!("chi2           {:.3}", sol.chi2);
        if sol.switches.is_some() {
            println!(
                "loop closures  {} ({} switched off)",
                robust.loop_closures,
                robust.rejected.len()
            );
        }
        if let Some(a) = ate {
            println!("ate            {:.4} m  over {} keyframes", a.rmse, a.matched);
        }
        println!("seconds        {:.4}", sol.seconds());
    }
    Ok(())
}

/// The top view of a 3-D pose: its position's `x, y` and its yaw.
pub fn top_view(p: &Pose3) -> Pose2 {
    let (_, _, yaw) = p.rotation.euler_angles();
    Pose2::new(p.translation.x, p.translation.y, yaw)
}

/// Draws the estimate, the aligned ground truth and the initial guess from
/// above.
fn plot_top_view(
    plot: &std::path::Path,
    opts: &SolveOpts,
    graph: &PoseGraph<Pose3>,
    poses: &[Pose3],
    truth: Option<&std::collections::HashMap<u64, Pose3>>,
) -> anyhow::Result<()> {
    let estimate: Vec<Pose2> = poses.iter().map(top_view).collect();
    let guess: Vec<Pose2> = graph.initial_guess()?.iter().map(top_view).collect();
    let aligned = truth.map(|t| {
        let t: Vec<Pose2> = graph
            .keyframes()
            .iter()
            .filter_map(|k| t.get(&k.id).map(top_view))
            .collect();
        aligned_onto(&t, &estimate)
    });
    let mut layers = vec![svg::Layer {
        label: "estimate",
        poses: &estimate,
        color: svg::ESTIMATE,
    }];
    if let Some(t) = &aligned {
        layers.push(svg::Layer {
            label: "ground truth",
            poses: t,
            color: svg::TRUTH,
        });
    }
    layers.push(svg::Layer {
        label: "initial guess",
        poses: &guess,
        color: svg::GUESS,
    });
    let title = format!(
        "{} ({}{}, top view)",
        file_name(&opts.file),
        opts.formulation,
        if opts.polish { " + polish" } else { "" }
    );
    svg::write_svg(plot, &title, &layers).map_err(anyhow::Error::msg)
}
