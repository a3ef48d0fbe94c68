//! `slamd replay FILE`: stream a dataset in time order, one snapshot per
//! keyframe, and report latency and accuracy.
//!
//! A keyframe's edges arrive together, as a frontend publishes them; its
//! latency runs from their arrival to the snapshot that contains them.
//! `--embedded` runs the engine in this process (arrival: before the first
//! edge is applied; snapshot: after the update). Otherwise the edges travel
//! to a running daemon over shared memory (arrival: before the first is
//! published; snapshot: received with an acknowledgement of the last).

use anyhow::{bail, Context};
use clap::Args;
use faer::c64;
use slamd::config::Config;
use slamd::engine::{EdgeInput, Engine, EngineConfig, FactorWork, FixInput};
use slamd::eval::Aligned;
use slamd::geometry::Pose2;
use slamd::graph::{KeyframeId, PoseGraph, RigidMotion};
use slamd::io;
use slamd::solver::{solve_batch, BatchOptions, BatchPose};
use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

mod report;
mod sink;
mod spatial;
use report::Report;
pub use sink::{DaemonSink, EmbeddedSink, ReplayPose, Sink};

#[derive(Args, Debug)]
pub struct ReplayOpts {
    /// Graph file to stream (edges are sorted by time: max(i, j), min(i, j)).
    pub file: PathBuf,
    /// Run the engine in this process instead of talking to a daemon.
    #[arg(long)]
    pub embedded: bool,
    /// Send at most this many keyframes per second (default: into the
    /// daemon, each keyframe waits for its snapshot; embedded, as fast as
    /// the engine takes them).
    #[arg(long)]
    pub rate: Option<f64>,
    /// Ground truth for the ATE of the final estimate.
    #[arg(long)]
    pub ground_truth: Option<PathBuf>,
    /// Check this many evenly spaced snapshots against the batch optimum of
    /// their own prefix (slow on big files: one batch solve each).
    #[arg(long, default_value_t = 0)]
    pub check_prefixes: usize,
    /// TOML configuration (namespace, and the engine for --embedded).
    #[arg(long, env = slamd::config::FILE_VARIABLE)]
    pub config: Option<PathBuf>,
    /// Namespace of the daemon (overrides the configuration).
    #[arg(long)]
    pub namespace: Option<String>,
    /// Seconds to wait for the daemon's answer before giving up.
    #[arg(long, default_value_t = 5.0)]
    pub timeout: f64,
    #[command(flatten)]
    pub gps: crate::gps::GpsOpts,
    #[command(flatten)]
    pub robust: crate::robust::RobustOpts,
    /// Turn the outlier filter off (--embedded).
    #[arg(long)]
    pub no_filter: bool,
    /// Start at the keyframe of this index (0-based, in time order), with
    /// the edges whose newer end it is: the daemon already holds the ones
    /// before (`slamd run --map` of the file's first keyframes).
    #[arg(long, default_value_t = 0)]
    pub from: usize,
    /// Write the result: `.g2o` as a graph, `.tum` and `.kitti` as evo reads
    /// them (TUM's time is the keyframe id), `.map` as a saved map that
    /// `slamd run --map` continues, anything else as `id x y theta` (in 3-D
    /// `id x y z qx qy qz qw`).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Write one line per keyframe: `k latency_us`, and with `--embedded`
    /// the entries of the factor its update walks swept and its
    /// back-substitutions read, and the factor's entries after it.
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// Count, per edge, the snapshots it weighs in with a switch of at
    /// least 0.5 (`weighted_snapshots` in the JSON; --embedded): how long
    /// a wrong loop closure stays in the published estimate. It reads
    /// every switch after each keyframe's update, outside the latency.
    #[arg(long)]
    pub weighted: bool,
    #[command(flatten)]
    pub input: crate::input::InputOpts,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// Latency percentiles of a run, in microseconds.
pub struct Latency {
    pub p50: f64,
    pub p99: f64,
    pub max: f64,
}

impl Latency {
    pub fn of(mut samples: Vec<f64>) -> Latency {
        samples.sort_by(f64::total_cmp);
        let at = |q: f64| {
            if samples.is_empty() {
                0.0
            } else {
                samples[((samples.len() - 1) as f64 * q).round() as usize]
            }
        };
        Latency {
            p50: at(0.5),
            p99: at(0.99),
            max: at(1.0),
        }
    }
}

/// One keyframe of a replay, with what arrives with it.
pub struct Step<P: RigidMotion = Pose2> {
    pub id: KeyframeId,
    /// The edges whose newer end it is.
    pub edges: Vec<EdgeInput<P>>,
    /// Their indices in the graph (file order).
    pub file_index: Vec<usize>,
    /// The GPS fixes taken at it.
    pub fixes: Vec<FixInput>,
}

/// A graph's keyframes in order, each with the edges that it makes
/// available (its newer end) and its fixes, as engine inputs.
pub fn stream<P: RigidMotion>(graph: &PoseGraph<P>, fixes: &[FixInput]) -> Vec<Step<P>> {
    let mut by_id: HashMap<KeyframeId, Vec<FixInput>> = HashMap::new();
    for f in fixes {
        by_id.entry(f.keyframe).or_default().push(*f);
    }
    let index = graph.by_newer();
    let groups: Vec<Vec<EdgeInput<P>>> = index
        .iter()
        .map(|g| g.iter().map(|&e| graph.edge_input(e)).collect())
        .collect();
    groups
        .into_iter()
        .enumerate()
        .zip(index)
        .map(|((k, edges), file_index)| {
            let id = graph.id_of(k);
            Step {
                id,
                edges,
                file_index,
                fixes: by_id.remove(&id).unwrap_or_default(),
            }
        })
        .collect()
}

/// What a replay measured.
pub struct Outcome<P = Pose2> {
    pub latencies: Vec<f64>,
    /// Georeferenced (east, north) of the final estimate, by keyframe id.
    pub enu: HashMap<KeyframeId, c64>,
    pub trace: Vec<(usize, f64)>,
    /// When asked for, per keyframe (by index): the engine's work on it
    /// and the factor's entries after it (embedded only, else empty).
    pub work: Vec<(FactorWork, usize)>,
    pub total_s: f64,
    /// Of `total_s`, the seconds from the last keyframe's snapshot to the
    /// closing estimate (the re-solve that ends the stream).
    pub closing_s: f64,
    pub resolves: usize,
    pub poses: Vec<P>,
    pub checked: Vec<(usize, Vec<P>)>,
    /// The final switch of each edge, in file order (embedded only).
    pub switches: Option<Vec<f64>>,
    /// Keyframes from each loop closure's arrival to the outlier filter's
    /// decision on it (embedded only).
    pub decision_lags: Vec<f64>,
    /// How many snapshots each edge weighed in with a switch of at least
    /// 0.5, in file order (embedded only).
    pub weighted: Option<Vec<u32>>,
}

/// Streams `graph` into `sink`; `progress` is told of each keyframe.
pub fn replay<P: RigidMotion>(
    graph: &PoseGraph<P>,
    fixes: &[FixInput],
    sink: &mut dyn Sink<P>,
    checkpoints: &[usize],
    record_work: bool,
    from: usize,
    mut progress: impl FnMut(usize),
) -> anyhow::Result<Outcome<P>> {
    let mut latencies = Vec::with_capacity(graph.len());
    let mut work = Vec::new();
    let mut before = FactorWork::default();
    let mut checked = Vec::new();
    let mut steps = stream(graph, fixes);
    if from > 0 && from >= steps.len() {
        bail!(
            "--from {from}: the file has {} keyframes, so nothing is left to send",
            steps.len()
        );
    }
    steps.drain(..from);
    let sent: Vec<usize> = steps.iter().flat_map(|s| s.file_index.iter().copied()).collect();
    let start = Instant::now();
    for (k, step) in (from..).zip(&steps) {
        latencies.extend(sink.keyframe(k, step)?);
        // counting the factor's entries walks its columns: only on request
        if let Some(stats) = record_work.then(|| sink.engine_stats()).flatten() {
            work.push((stats.work - before, stats.factor_nnz));
            before = stats.work;
        }
        if checkpoints.contains(&k) {
            latencies.extend(sink.drain()?);
            let by_id = sink.poses()?;
            let poses = graph.keyframes()[..=k]
                .iter()
                .map(|kf| by_id.get(&kf.id).copied())
                .collect::<Option<Vec<_>>>();
            checked.push((k, poses.context("a snapshot lacks keyframes it should hold")?));
        }
        progress(k);
    }
    latencies.extend(sink.drain()?);
    let closing = Instant::now();
    let (by_id, resolves, ready) = sink.finish()?;
    let total_s = ready.duration_since(start).as_secs_f64();
    let closing_s = ready.duration_since(closing).as_secs_f64();
    let enu = sink.enu()?;
    let edges = graph.edges().len();
    let switches = (sink.switches()).map(|sw| in_file_order(&sent, edges, &sw, 1.0));
    let weighted = (sink.weighted_snapshots()).map(|w| in_file_order(&sent, edges, &w, 0));
    let poses = graph
        .keyframes()
        .iter()
        .map(|k| by_id.get(&k.id).copied())
        .collect::<Option<Vec<_>>>()
        .with_context(|| {
            format!(
                "{} keyframes are missing from the final snapshot",
                graph.len() - by_id.len()
            )
        })?;
    latencies.sort_by_key(|&(k, _)| k);
    Ok(Outcome {
        enu,
        switches,
        trace: latencies.clone(),
        work,
        latencies: latencies.into_iter().map(|(_, l)| l).collect(),
        total_s,
        closing_s,
        resolves,
        poses,
        checked,
        decision_lags: sink.decision_lags().into_iter().map(f64::from).collect(),
        weighted,
    })
}

/// Values of the edges in the order `sent` (file indices) rearranged in
/// file order, `fill` where an edge was not sent.
fn in_file_order<T: Copy>(sent: &[usize], edges: usize, values: &[T], fill: T) -> Vec<T> {
    let mut by_file = vec![fill; edges];
    for (&e, &v) in sent.iter().zip(values) {
        by_file[e] = v;
    }
    by_file
}

pub fn run(opts: ReplayOpts) -> anyhow::Result<()> {
    let config = crate::run::load_config(opts.config.as_deref(), opts.namespace.as_deref())?;
    let input = crate::input::Input::read_any(&opts.file, opts.input, opts.json)?;
    let skipped = input.json();
    let graph = match input.graph {
        io::AnyGraph::Planar(g) => g,
        io::AnyGraph::Spatial(g) => return spatial::run(&opts, &config, g, skipped),
    };
    graph.check_connected()?;
    let truth = opts
        .ground_truth
        .as_deref()
        .map(io::read_ground_truth)
        .transpose()?;
    let checkpoints = checkpoints(&opts, graph.len());
    let mut sink = sink::<Pose2>(&opts, &config)?;
    let gps = crate::gps::load(&opts.gps, &graph)?;
    let fixes = gps.as_ref().map_or(&[][..], |g| &g.wire[..]);
    let out = replay(
        &graph,
        fixes,
        sink.as_mut(),
        &checkpoints,
        opts.trace.is_some(),
        opts.from,
        |_| {},
    )?;
    let enu_rmse = gps.as_ref().and_then(|g| {
        let enu: HashMap<usize, c64> = (out.enu.iter())
            .filter_map(|(id, p)| Some((graph.index_of(*id)?, *p)))
            .collect();
        crate::gps::rmse(&g.truth, |k| enu.get(&k).copied())
    });
    if let Some(path) = &opts.trace {
        let lines: Vec<String> = (out.trace.iter())
            .map(|(k, l)| match out.work.get(*k) {
                Some((w, nnz)) => format!("{k} {l:.1} {} {} {nnz}", w.walked, w.solved),
                None => format!("{k} {l:.1}"),
            })
            .collect();
        std::fs::write(path, lines.join("\n") + "\n")
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if let Some(path) = &opts.out {
        crate::solve::write_result(path, &graph, &out.poses, out.switches.as_deref())?;
    }
    let georeferenced = !out.enu.is_empty();
    let report = report(&graph, out, sink.as_ref(), truth.as_ref())?;
    if opts.json {
        let extra = serde_json::json!({
            "gps_fixes": fixes.len(),
            "georeferenced": georeferenced,
            "enu_rmse": enu_rmse,
        });
        println!("{}", report.json(&opts, skipped, extra));
    } else {
        report.print(&opts, sink.mode(), || {
            if let Some(e) = enu_rmse {
                println!("enu rmse              {e:.4} m  ({} fixes)", fixes.len());
            }
        });
    }
    Ok(())
}

/// The report of a replay into `sink`: the final poses' ATE against
/// `truth`, the sampled prefixes against their polished batch optimum.
fn report<P: ReplayPose + BatchPose + Aligned>(
    graph: &PoseGraph<P>,
    out: Outcome<P>,
    sink: &dyn Sink<P>,
    truth: Option<&HashMap<KeyframeId, P>>,
) -> anyhow::Result<Report> {
    let ate = truth
        .and_then(|t| slamd::eval::ate(graph, &out.poses, t))
        .map(|a| a.rmse);
    Report::of(graph, out, sink.mode(), sink.engine_stats(), ate, |prefix| {
        let options = BatchOptions {
            polish: true,
            ..Default::default()
        };
        Ok(solve_batch(prefix, &options)?.chi2)
    })
}

/// The keyframe counts after which `--check-prefixes` samples a snapshot.
fn checkpoints(opts: &ReplayOpts, keyframes: usize) -> Vec<usize> {
    (1..=opts.check_prefixes)
        .map(|i| (i * keyframes / (opts.check_prefixes + 1)).max(1))
        .collect()
}

/// Where the replay of poses `P` goes: the engine in this process
/// (`--embedded`) or the daemon of the configured namespace, which must
/// serve `P`'s dimension.
fn sink<P: ReplayPose>(opts: &ReplayOpts, config: &Config) -> anyhow::Result<Box<dyn Sink<P>>> {
    if opts.rate.is_some_and(|r| r.is_nan() || r <= 0.0) {
        bail!("--rate must be > 0");
    }
    if opts.from > 0 && opts.embedded {
        bail!("--from continues a daemon's map (`slamd run --map`); it does not take --embedded");
    }
    if opts.embedded {
        let engine = Engine::<P>::create(engine_config(opts, config));
        let pace = opts
            .rate
            .map(|hz| (Instant::now(), Duration::from_secs_f64(1.0 / hz)));
        return Ok(Box::new(EmbeddedSink(engine, pace, opts.weighted.then(Vec::new))));
    }
    let timeout = Duration::from_secs_f64(opts.timeout);
    let daemon = DaemonSink::<P>::connect(&config.namespace, config, timeout, opts.rate)?;
    Ok(Box::new(daemon))
}

pub fn engine_config(opts: &ReplayOpts, config: &Config) -> EngineConfig {
    let mut c = config.engine();
    if let Some(o) = opts.gps.gps_origin {
        c.gps.origin = Some(o);
    }
    c.gps.absolute = !opts.gps.gps_paper_only;
    c.outliers = opts.robust.apply(c.outliers);
    c.outliers.enabled &= !opts.no_filter;
    c
}
