//! `slamd demo`: the README's first command. Starts a daemon, replays the
//! built-in synthetic world (or `--dataset FILE`) into it over shared
//! memory, prints latency and accuracy, and draws the map.

use crate::replay::{replay, DaemonSink, Latency};
use crate::solve::file_name;
use anyhow::Context;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use slamd::config::Config;
use slamd::eval::{aligned_onto, ate};
use slamd::graph::{chi2, KeyframeId, PoseGraph};
use slamd::io::svg;
use slamd::synthetic::{generate, WorldParams};
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
}

/// The daemon child process; stopped with SIGTERM when dropped.
struct Daemon(Child);

impl Daemon {
    fn start(namespace: &str) -> anyhow::Result<Daemon> {
        let exe = std::env::current_exe().context("locating the slamd binary")?;
        let child = Command::new(exe)
            .args(["run", "--namespace", namespace])
            .env(
                "SLAMD_LOG",
                std::env::var("SLAMD_LOG").unwrap_or_else(|_| "error".into()),
            )
            .stdin(Stdio::null())
            .spawn()
            .context("starting the daemon")?;
        Ok(Daemon(child))
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
    graph.check_connected()?;
    let config = Config::load(None)?;
    let namespace = format!("slamd-demo-{}", std::process::id());
    println!("starting the daemon on namespace `{namespace}`");
    let daemon = Daemon::start(&namespace)?;
    let mut sink = connect(&namespace, &config)?;

    println!(
        "{name}: {} keyframes, {} edges, streamed over shared memory",
        graph.len(),
        graph.edges().len()
    );
    let bar = ProgressBar::new(graph.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} keyframes  {per_sec}  eta {eta}")
            .expect("valid template"),
    );
    let out = replay(&graph, &[], &mut sink, &[], false, |_| bar.inc(1))?;
    bar.finish_and_clear();
    drop(sink);
    let status = daemon.stop()?;

    let odometry = graph.compose_spanning_tree()?;
    let lat = Latency::of(out.latencies);
    let ate_of = |p: &[slamd::geometry::Pose2]| {
        truth
            .as_ref()
            .and_then(|t| ate(&graph, p, t))
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
        chi2(&graph, &odometry),
        ate_of(&odometry)
    );
    println!(
        "{:<22} {:>14.2} {:>10}",
        "slamd",
        chi2(&graph, &out.poses),
        ate_of(&out.poses)
    );

    let truth_poses: Option<Vec<_>> = truth.as_ref().map(|t| {
        aligned_onto(
            &graph.keyframes().iter().map(|k| t[&k.id]).collect::<Vec<_>>(),
            &out.poses,
        )
    });
    let mut layers = vec![svg::Layer {
        label: "slamd",
        poses: &out.poses,
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
    println!("map written to {}; daemon stopped ({status})", opts.out.display());
    Ok(())
}

/// Connects once the daemon's services exist (it needs a moment to start).
fn connect(namespace: &str, config: &Config) -> anyhow::Result<DaemonSink> {
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
