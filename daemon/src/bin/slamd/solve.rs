//! `slamd solve FILE`: the batch pipeline on one graph file, 2-D or 3-D.

use crate::robust::Rejected;
use anyhow::{bail, Context};
use clap::Args;
use slamd::eval::{aligned_onto, ate, Ate};
use slamd::geometry::Pose2;
use slamd::graph::{Pose3, PoseGraph};
use slamd::io::{self, svg};
use slamd::nonlinear::LiePose;
use slamd::outliers::OutlierConfig;
use slamd::solver::{solve_batch, BatchOptions, BatchSolution, Formulation};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct SolveOpts {
    /// Graph file, 2-D or 3-D: g2o (.g2o), TORO or HOG-Man (.graph), iSAM (.txt).
    pub file: PathBuf,
    /// Linear formulation: two-stage, virtual-frame, virtual-frame-pivot, odometry.
    #[arg(long, default_value = "two-stage")]
    pub formulation: Formulation,
    /// Polish with Levenberg–Marquardt after the linear solve.
    #[arg(long)]
    pub polish: bool,
    /// Ground truth: a pose table or a noise-free graph file.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Write the result: `.g2o` as a graph, `.tum` and `.kitti` as evo reads
    /// them (TUM's time is the keyframe id), `.map` as a saved map that
    /// `slamd run --map` continues, anything else as `id x y theta` (in 3-D
    /// `id x y z qx qy qz qw`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Draw the estimate over the ground truth and the initial guess.
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Write every keyframe's marginal covariance at the result: its id,
    /// then the upper triangle row by row over `x y theta` (in 3-D
    /// `x y z rx ry rz`), in the pose's own frame, the first keyframe fixed.
    #[arg(long)]
    pub covariances: Option<PathBuf>,
    /// Drop every loop closure: odometry alone (with --gps: odometry and GPS).
    #[arg(long)]
    pub odometry_only: bool,
    #[command(flatten)]
    pub gps: crate::gps::GpsOpts,
    /// Filter wrong loop closures: the robust polish (implies --polish).
    #[arg(long)]
    pub robust: bool,
    #[command(flatten)]
    pub filter: crate::robust::RobustOpts,
    #[command(flatten)]
    pub input: crate::input::InputOpts,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(opts: SolveOpts) -> anyhow::Result<()> {
    let input = crate::input::Input::read_any(&opts.file, opts.input, opts.json)?;
    let skipped = input.json();
    let mut graph = match input.graph {
        io::AnyGraph::Planar(g) => g,
        io::AnyGraph::Spatial(g) => return run_spatial(&opts, &g, skipped),
    };
    if opts.odometry_only {
        graph = odometry_only(&graph);
    }
    let truth = opts
        .ground_truth
        .as_deref()
        .map(io::read_ground_truth)
        .transpose()?;
    let gps = crate::gps::load(&opts.gps, &graph)?;
    if opts.covariances.is_some() && gps.is_some() {
        anyhow::bail!("--covariances does not take GPS fixes in; leave out --gps");
    }
    let options = BatchOptions {
        formulation: opts.formulation,
        polish: opts.polish,
        gps: gps.as_ref().map(|g| g.input.clone()),
        robust: opts.robust.then(|| opts.filter.apply(OutlierConfig::default())),
        ..Default::default()
    };
    let sol = solve_batch(&graph, &options).with_context(|| format!("solving {}", opts.file.display()))?;
    let ate = truth.as_ref().and_then(|t| ate(&graph, &sol.poses, t));

    if let Some(out) = &opts.out {
        write_result(out, &graph, &sol.poses, sol.switches.as_deref())?;
    }
    let covariance_seconds = opts
        .covariances
        .as_deref()
        .map(|path| crate::covariances::write(path, &graph, &sol.poses, sol.switches.as_deref()))
        .transpose()?;
    if let Some(plot) = &opts.plot {
        let guess = graph.initial_guess()?;
        let truth_poses: Option<Vec<_>> = truth.as_ref().map(|t| {
            graph
                .keyframes()
                .iter()
                .filter_map(|k| t.get(&k.id).copied())
                .collect()
        });
        let aligned_truth = truth_poses.map(|t| slamd::eval::aligned_onto(&t, &sol.poses));
        let layers = plot_layers(&sol.poses, aligned_truth.as_deref(), &guess);
        let title = format!(
            "{} ({}{})",
            file_name(&opts.file),
            opts.formulation,
            if opts.robust {
                " + robust polish"
            } else if opts.polish {
                " + polish"
            } else {
                ""
            }
        );
        svg::write_svg(plot, &title, &layers).map_err(anyhow::Error::msg)?;
    }

    let robust = crate::robust::Rejected::of(&graph, sol.switches.as_deref());
    let enu_rmse = gps
        .as_ref()
        .and_then(|g| crate::gps::enu_rmse(g, sol.georef.as_ref(), &sol.poses));
    if opts.json {
        let extra = serde_json::json!({
            "rho": sol.rho,
            "median_axis_length": sol.median_axis_length,
            "gps_fixes": gps.as_ref().map(|g| g.input.fixes.len()),
            "georeferenced": sol.georef.is_some(),
            "enu_rmse": enu_rmse,
            "covariance_seconds": covariance_seconds.map(|c| c.0),
            "covariance_max_seconds": covariance_seconds.map(|c| c.1),
        });
        println!(
            "{}",
            summary_json(&opts, &graph, &sol, ate, &robust, skipped, extra)
        );
    } else {
        print_head(&opts, &graph, &sol, "");
        if let (Some(rho), Some(m)) = (sol.rho, sol.median_axis_length) {
            println!("scale rho      {rho:.4}  (median virtual axis {m:.4} before scaling; truth 1)");
        }
        print_result(&sol, &robust, ate);
        if let Some(g) = &gps {
            println!(
                "gps            {} fixes, georeferenced: {}",
                g.input.fixes.len(),
                sol.georef.is_some()
            );
        }
        if let Some(e) = enu_rmse {
            println!("enu rmse       {e:.4} m  (georeferenced positions vs the fixes' true ENU)");
        }
        println!("seconds        {:.4}", sol.seconds());
    }
    Ok(())
}

/// A solve's picture: the estimate, the ground truth aligned onto it when
/// given, and the initial guess.
pub fn plot_layers<'a>(
    estimate: &'a [Pose2],
    truth: Option<&'a [Pose2]>,
    guess: &'a [Pose2],
) -> Vec<svg::Layer<'a>> {
    layers(("estimate", estimate), truth, ("initial guess", guess))
}

/// An estimate, the ground truth aligned onto it when given, and where it
/// started from, each with its label.
pub fn layers<'a>(
    (label, estimate): (&'static str, &'a [Pose2]),
    truth: Option<&'a [Pose2]>,
    (start, guess): (&'static str, &'a [Pose2]),
) -> Vec<svg::Layer<'a>> {
    let mut layers = vec![svg::Layer {
        label,
        poses: estimate,
        color: svg::ESTIMATE,
    }];
    if let Some(t) = truth {
        layers.push(svg::Layer {
            label: "ground truth",
            poses: t,
            color: svg::TRUTH,
        });
    }
    layers.push(svg::Layer {
        label: start,
        poses: guess,
        color: svg::GUESS,
    });
    layers
}

/// The JSON fields every solve reports, `extra` added.
pub fn summary_json<P: LiePose>(
    opts: &SolveOpts,
    graph: &PoseGraph<P>,
    sol: &BatchSolution<P>,
    ate: Option<Ate>,
    robust: &Rejected,
    skipped: serde_json::Value,
    extra: serde_json::Value,
) -> serde_json::Value {
    let mut v = serde_json::json!({
        "file": opts.file.display().to_string(),
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
        "iterations": sol.polish.as_ref().map(|r| r.iterations.len()),
        "robust": opts.robust,
        "loop_closures": robust.loop_closures,
        "rejected_edges": sol.switches.as_ref().map(|_| &robust.rejected),
        "skipped_lines": skipped,
    });
    if let (Some(v), serde_json::Value::Object(extra)) = (v.as_object_mut(), extra) {
        v.extend(extra);
    }
    v
}

/// The text report's first lines: the file, its size, the linear solve
/// and the polish; `label` follows the file name.
pub fn print_head<P: LiePose>(opts: &SolveOpts, graph: &PoseGraph<P>, sol: &BatchSolution<P>, label: &str) {
    println!("file           {}{label}", opts.file.display());
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
}

/// The text report's result lines: χ², the loop closures switched off,
/// the ATE.
pub fn print_result<P: LiePose>(sol: &BatchSolution<P>, robust: &Rejected, ate: Option<Ate>) {
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
}

/// Writes `poses` to `out` by its extension: a trajectory (`.tum`,
/// `.kitti`), g2o (`.g2o`), a saved map (`.map`: what `slamd run --map`
/// continues, every edge at its switch in `switches`, else on), else a
/// pose table.
pub fn write_result<P: io::G2oPose>(
    out: &std::path::Path,
    graph: &PoseGraph<P>,
    poses: &[P],
    switches: Option<&[f64]>,
) -> anyhow::Result<()> {
    if out.extension().is_some_and(|e| e == "map") {
        let mut map = slamd::store::MapFile::solved(graph, poses);
        for (edge, &s) in map.edges.iter_mut().zip(switches.unwrap_or_default()) {
            edge.switch = s;
        }
        return std::fs::write(out, map.encode()).with_context(|| format!("writing {}", out.display()));
    }
    let file = std::fs::File::create(out).with_context(|| format!("creating {}", out.display()))?;
    let mut w = std::io::BufWriter::new(file);
    if let Some(layout) = io::Trajectory::of(out) {
        io::write_trajectory(&mut w, layout, &keyframe_ids(graph), poses)?;
    } else if out.extension().is_some_and(|e| e == "g2o") {
        io::write_g2o(&mut w, graph, poses)?;
    } else {
        io::write_pose_table(&mut w, graph, poses)?;
    }
    Ok(())
}

/// The graph's keyframe ids in order.
pub fn keyframe_ids<P: slamd::graph::RigidMotion>(graph: &PoseGraph<P>) -> Vec<slamd::graph::KeyframeId> {
    graph.keyframes().iter().map(|k| k.id).collect()
}

/// The graph without its loop closures.
pub fn odometry_only(graph: &PoseGraph) -> PoseGraph {
    let edges = graph
        .edges()
        .iter()
        .filter(|e| e.kind == slamd::graph::EdgeKind::Odometry)
        .copied()
        .collect();
    PoseGraph::from_parts(graph.keyframes().to_vec(), edges).expect("same keyframes")
}

pub fn file_name(p: &std::path::Path) -> String {
    p.file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// `slamd solve FILE` on a 3-D graph: the chordal two-stage initialiser,
/// then optionally the polish on g2o's SE(3) cost.
fn run_spatial(opts: &SolveOpts, graph: &PoseGraph<Pose3>, skipped: serde_json::Value) -> anyhow::Result<()> {
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
        write_result(out, graph, &sol.poses, sol.switches.as_deref())?;
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
