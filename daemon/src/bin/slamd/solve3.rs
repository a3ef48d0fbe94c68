//! `slamd solve FILE` on a 3-D graph: the chordal two-stage initialiser,
//! then optionally the polish on g2o's SE(3) cost.

use crate::solve::{file_name, plot_layers, print_head, print_result, summary_json, SolveOpts};
use anyhow::{bail, Context};
use slamd::eval::{aligned_onto, ate};
use slamd::geometry::Pose2;
use slamd::graph::{Pose3, PoseGraph};
use slamd::io::{self, svg};
use slamd::outliers::OutlierConfig;
use slamd::solver::{solve_batch, BatchOptions};

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
        .map(io::read_ground_truth)
        .transpose()?;
    let options = BatchOptions {
        formulation: opts.formulation,
        polish: opts.polish,
        robust: opts.robust.then(|| opts.filter.apply(OutlierConfig::default())),
        ..Default::default()
    };
    let sol = solve_batch(graph, &options).with_context(|| format!("solving {}", opts.file.display()))?;
    let ate = truth.as_ref().and_then(|t| ate(graph, &sol.poses, t));
    if let Some(out) = &opts.out {
        let file = std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
        let mut w = std::io::BufWriter::new(file);
        if let Some(layout) = io::Trajectory::of(out) {
            io::write_trajectory(&mut w, layout, &crate::solve::keyframe_ids(graph), &sol.poses)?;
        } else if out.extension().is_some_and(|e| e == "g2o") {
            io::write_g2o(&mut w, graph, &sol.poses)?;
        } else {
            for (k, p) in graph.keyframes().iter().zip(&sol.poses) {
                let v = p.to_xyz_quaternion().map(|x| x.to_string()).join(" ");
                std::io::Write::write_all(&mut w, format!("{} {v}\n", k.id).as_bytes())?;
            }
        }
    }
    let covariance_seconds = opts
        .covariances
        .as_deref()
        .map(|path| crate::covariances::write(path, graph, &sol.poses, sol.switches.as_deref()))
        .transpose()?;
    if let Some(plot) = &opts.plot {
        plot_top_view(plot, opts, graph, &sol.poses, truth.as_ref())?;
    }
    let robust = crate::robust::Rejected::of(graph, sol.switches.as_deref());
    if opts.json {
        let extra = serde_json::json!({
            "dimension": "3d",
            "covariance_seconds": covariance_seconds.map(|c| c.0),
            "covariance_max_seconds": covariance_seconds.map(|c| c.1),
        });
        println!(
            "{}",
            summary_json(opts, graph, &sol, ate, &robust, skipped, extra)
        );
    } else {
        print_head(opts, graph, &sol, "  (3-D)");
        print_result(&sol, &robust, ate);
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
    let layers = plot_layers(&estimate, aligned.as_deref(), &guess);
    let title = format!(
        "{} ({}{}, top view)",
        file_name(&opts.file),
        opts.formulation,
        if opts.polish { " + polish" } else { "" }
    );
    svg::write_svg(plot, &title, &layers).map_err(anyhow::Error::msg)
}
