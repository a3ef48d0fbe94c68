//! `slamd demo`: the README's first command. Starts a daemon, replays the
//! built-in synthetic world (or `--dataset FILE`) into it over shared
//! memory, prints latency and accuracy, and draws the map. `--3d` does the
//! same with the 3-D building and a daemon serving 3-D graphs.

use crate::replay::{replay, DaemonSink, Latency, ReplayPose};
use crate::solve::file_name;
use crate::solve::top_view;
use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use slamd::config::Config;
use slamd::eval::{aligned_onto, ate, Aligned};
use slamd::geometry::Pose2;
use slamd::graph::{chi2, KeyframeId, Pose3, PoseGraph, RigidMotion};
use slamd::io::{svg, AnyGraph, OnInvalid};
use slamd::synthetic::{generate, generate_building, gps_fixes, GpsParams, WorldParams};
use std::collections::HashMap;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

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
    /// The 3-D world instead: the same drive through a building of
    /// `--storeys` floors, streamed to a daemon serving 3-D graphs (the
    /// picture is its top view).
    #[arg(long = "3d")]
    pub three_d: bool,
    /// Storeys of the 3-D building.
    #[arg(long, default_value_t = 3)]
    pub storeys: usize,
    /// Serve the live view (`slamd view`: Foxglove on port 8765, the page
    /// on 8766) while the world streams in, and keep it up until Ctrl-C.
    #[arg(long)]
    pub view: bool,
    /// Record the live view's channels to this MCAP file.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Also stream GPS fixes of the synthetic world (one every 10
    /// keyframes, σ = 1.5 m), so the map is georeferenced.
    #[arg(long)]
    pub gps: bool,
}

/// What the demo does per dimension.
trait DemoPose: ReplayPose + slamd::graph::EdgeCost + Aligned {
    /// The pose seen from above.
    fn top(&self) -> Pose2;
    /// Its position `(x, y, z)`.
    fn position(&self) -> [f64; 3];
}

impl DemoPose for Pose2 {
    fn top(&self) -> Pose2 {
        *self
    }
    fn position(&self) -> [f64; 3] {
        [self.x, self.y, 0.0]
    }
}

impl DemoPose for Pose3 {
    fn top(&self) -> Pose2 {
        top_view(self)
    }
    fn position(&self) -> [f64; 3] {
        self.translation.into()
    }
}

/// A child `slamd` process (the daemon, the viewer); stopped with
/// SIGTERM when dropped.
struct Daemon(Child);

impl Daemon {
    fn start(namespace: &str, dimension: u32) -> anyhow::Result<Daemon> {
        let child = Self::slamd(&["run", "--namespace", namespace])
            .env("SLAMD_DIMENSION", dimension.to_string())
            .spawn()
            .context("starting the daemon")?;
        Ok(Daemon(child))
    }

    /// `slamd view` of `namespace`: on its default ports with `--view`,
    /// on free ones without a page when it only records.
    fn view(namespace: &str, opts: &DemoOpts) -> anyhow::Result<Option<Daemon>> {
        if !opts.view && opts.record.is_none() {
            return Ok(None);
        }
        let mut args: Vec<std::ffi::OsString> = vec!["view".into(), "--namespace".into(), namespace.into()];
        if !opts.view {
            args.extend(["--port", "0", "--no-page"].map(Into::into));
        }
        if let Some(path) = &opts.record {
            args.extend(["--record".into(), path.into()]);
        }
        let child = Self::slamd(&args).spawn().context("starting the viewer")?;
        Ok(Some(Daemon(child)))
    }

    fn slamd<S: AsRef<std::ffi::OsStr>>(args: &[S]) -> Command {
        let exe = std::env::current_exe().unwrap_or_else(|_| "slamd".into());
        let mut c = Command::new(exe);
        c.args(args)
            .env(
                "SLAMD_LOG",
                std::env::var("SLAMD_LOG").unwrap_or_else(|_| "error".into()),
            )
            .stdin(Stdio::null());
        c
    }

    /// SIGTERM, then the exit status.
    fn stop(mut self) -> anyhow::Result<std::process::ExitStatus> {
        // SAFETY: kill(2) on our own child's pid.
        unsafe { libc::kill(self.0.id() as i32, libc::SIGTERM) };
        let status = self.0.wait()?;
        std::mem::forget(self);
        Ok(status)
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        // SAFETY: as above; the child may already be gone.
        unsafe { libc::kill(self.0.id() as i32, libc::SIGTERM) };
        let _ = self.0.wait();
    }
}

pub fn run(opts: DemoOpts) -> anyhow::Result<()> {
    let params = WorldParams {
        poses: opts.poses,
        seed: opts.seed,
        ..Default::default()
    };
    match (&opts.dataset, opts.three_d) {
        (Some(path), _) => match slamd::io::read_any_graph_with(path, OnInvalid::Refuse)?.0 {
            AnyGraph::Planar(g) => show(&opts, &file_name(path), &g, None),
            AnyGraph::Spatial(g) => show(&opts, &file_name(path), &g, None),
        },
        (None, false) => {
            let w = generate(&params);
            let truth = by_id(&w.graph, w.truth);
            let name = format!("synthetic world (seed {})", opts.seed);
            show(&opts, &name, &w.graph, Some(&truth))
        }
        (None, true) => {
            let w = generate_building(&params, opts.storeys);
            let truth = by_id(&w.graph, w.truth);
            let name = format!(
                "synthetic building, {} storeys (seed {})",
                opts.storeys, opts.seed
            );
            show(&opts, &name, &w.graph, Some(&truth))
        }
    }
}

/// `poses`, one per keyframe of `graph`, by keyframe id.
fn by_id<P: DemoPose>(graph: &PoseGraph<P>, poses: Vec<P>) -> HashMap<KeyframeId, P> {
    graph.keyframes().iter().map(|k| k.id).zip(poses).collect()
}

/// Streams `graph` through a daemon of its dimension, prints latency and
/// accuracy against `truth` (if known) and draws the map from above.
fn show<P: DemoPose>(
    opts: &DemoOpts,
    name: &str,
    graph: &PoseGraph<P>,
    truth: Option<&HashMap<KeyframeId, P>>,
) -> anyhow::Result<()> {
    graph.check_connected()?;
    let config = Config::load(None)?;
    let namespace = format!("slamd-demo-{}", std::process::id());
    println!(
        "starting the daemon on namespace `{namespace}` ({}-D)",
        P::DIMENSION
    );
    let daemon = Daemon::start(&namespace, P::DIMENSION)?;
    let viewer = Daemon::view(&namespace, opts)?;
    let mut sink = connect::<P>(&namespace, &config)?;

    println!(
        "{name}: {} keyframes, {} edges, streamed over shared memory",
        graph.len(),
        graph.edges().len()
    );
    let bar = ProgressBar::new(graph.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} keyframes  {per_sec}  eta {eta}")
            .expect("valid template"),
    );
    let fixes = match (opts.gps, truth) {
        (true, Some(t)) => {
            let positions = graph.keyframes().iter().map(|k| (k.id, t[&k.id].position()));
            gps_fixes(positions, &GpsParams::default())
        }
        (true, None) => {
            anyhow::bail!("--gps takes its fixes from the synthetic world's truth: not with --dataset")
        }
        (false, _) => Vec::new(),
    };
    if !fixes.is_empty() {
        println!(
            "with {} GPS fixes (σ = {} m)",
            fixes.len(),
            GpsParams::default().sigma
        );
    }
    let out = replay(graph, &fixes, &mut sink, &[], false, 0, |_| bar.inc(1))?;
    bar.finish_and_clear();
    drop(sink);

    let odometry = graph.compose_spanning_tree()?;
    let lat = Latency::of(out.latencies);
    let ate_of = |p: &[P]| {
        truth
            .and_then(|t| ate(graph, p, t))
            .map_or("–".to_string(), |a| format!("{:.3}", a.rmse))
    };
    println!();
    println!(
        "latency, keyframe published → snapshot received: p50 {:.0} µs, p99 {:.0} µs, max {:.0} µs",
        lat.p50, lat.p99, lat.max
    );
    println!("total {:.2} s, {} re-solves", out.total_s, out.resolves);
    println!("{:<22} {:>14} {:>10}", "estimate", "chi2", "ATE (m)");
    println!(
        "{:<22} {:>14.2} {:>10}",
        "odometry only",
        chi2(graph, &odometry),
        ate_of(&odometry)
    );
    println!(
        "{:<22} {:>14.2} {:>10}",
        "slamd",
        chi2(graph, &out.poses),
        ate_of(&out.poses)
    );

    let top = |poses: &[P]| poses.iter().map(P::top).collect::<Vec<Pose2>>();
    let estimate = top(&out.poses);
    let truth_poses: Option<Vec<Pose2>> = truth.map(|t| {
        let t: Vec<Pose2> = graph.keyframes().iter().map(|k| t[&k.id].top()).collect();
        aligned_onto(&t, &estimate)
    });
    let odometry = top(&odometry);
    let layers = crate::solve::layers(
        ("slamd", &estimate),
        truth_poses.as_deref(),
        ("odometry only", &odometry),
    );
    let title = match P::DIMENSION {
        3 => format!("{name}, top view"),
        _ => name.to_string(),
    };
    svg::write_svg(&opts.out, &title, &layers).map_err(anyhow::Error::msg)?;
    println!("map written to {}", opts.out.display());
    if let Some(viewer) = viewer {
        if opts.view {
            crate::signals::catch();
            println!("the live view stays up until Ctrl-C");
            while !crate::signals::stopped() {
                crate::signals::sleep(Duration::from_secs(1));
            }
        } else {
            // the viewer publishes at most every 100 ms: let it take the
            // last snapshot and switches before it closes the recording
            std::thread::sleep(Duration::from_millis(300));
        }
        let status = viewer.stop()?;
        anyhow::ensure!(status.success(), "the viewer ended with {status}");
    }
    let status = daemon.stop()?;
    println!("daemon stopped ({status})");
    Ok(())
}

/// Connects once the daemon's services exist (it needs a moment to start).
fn connect<P: RigidMotion>(namespace: &str, config: &Config) -> anyhow::Result<DaemonSink<P>> {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        match DaemonSink::connect(namespace, config, Duration::from_secs(10), None) {
            Ok(sink) => return Ok(sink),
            Err(e) if Instant::now() < deadline => {
                tracing::debug!(error = %e, "Daemon not up yet.");
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(e) => return Err(e.context("the daemon did not come up within 10 s")),
        }
    }
}
