//! `slamd view`: the live view of a running daemon, in a process of its
//! own. It subscribes to the daemon's snapshots, switches and status like
//! any client (the daemon never waits for it: a viewer that stalls only
//! misses snapshots) and serves what it reads three ways:
//!
//! - Foxglove's WebSocket protocol (the `foxglove` SDK), on the channels
//!   of [`Channels`];
//! - an MCAP recording of the same channels (`--record`);
//! - a self-contained page ([`page`]) fed by the same WebSocket.
//!
//! It publishes at most `--rate` frames a second, always the newest
//! snapshot, and again whenever a client subscribes so a late one sees the
//! map at once; the recording takes at most `--record-rate` frames a
//! second, and the last one.

mod page;
mod scene;

use anyhow::Context as _;
use clap::Args;
use foxglove::messages::{LocationFix, LocationFixes, PoseInFrame, PosesInFrame, SceneUpdate};
use foxglove::websocket::{ChannelView, Client, ServerListener};
use foxglove::{
    Channel, Context, McapCompression, McapWriteOptions, McapWriter, RawChannel, WebSocketServer,
};
use scene::Frame;
use slamd_protocol::transport::SnapshotLink;
use slamd_protocol::DaemonStatus;
use std::io::Write as _;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Args, Debug)]
pub struct ViewOpts {
    /// The daemon's namespace (default: the configured one).
    #[arg(long)]
    pub namespace: Option<String>,
    /// Address to serve on.
    #[arg(long, default_value = "127.0.0.1")]
    pub host: String,
    /// Port of the Foxglove WebSocket server (0: any free port).
    #[arg(long, default_value_t = 8765)]
    pub port: u16,
    /// Port of the page (0: any free port).
    #[arg(long, default_value_t = 8766)]
    pub page_port: u16,
    /// Serve no page, only the WebSocket.
    #[arg(long)]
    pub no_page: bool,
    /// Also record every channel to this MCAP file.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Frames published per second at most.
    #[arg(long, default_value_t = 10.0)]
    pub rate: f64,
    /// Frames recorded per second at most: every frame carries the whole
    /// map, so a recording at the live rate grows by megabytes a second
    /// on a large map. The last frame is always recorded.
    #[arg(long, default_value_t = 1.0)]
    pub record_rate: f64,
}

/// The topics, as Foxglove and the page subscribe to them.
pub mod topic {
    /// `foxglove.PosesInFrame`: every keyframe's pose.
    pub const TRAJECTORY: &str = "/slamd/trajectory";
    /// `foxglove.SceneUpdate`: odometry and loop closures by state, and
    /// the newest keyframe's covariance ellipsoid.
    pub const GRAPH: &str = "/slamd/graph";
    /// `foxglove.PoseInFrame`: the newest keyframe.
    pub const NEWEST: &str = "/slamd/newest";
    /// `foxglove.LocationFix`: the newest keyframe on the globe, once GPS
    /// has georeferenced the map.
    pub const LOCATION: &str = "/slamd/location";
    /// `foxglove.LocationFixes`: every keyframe on the globe.
    pub const LOCATIONS: &str = "/slamd/locations";
    /// JSON: the daemon's counters, χ² and latency.
    pub const HEALTH: &str = "/slamd/health";
    /// JSON: the map as the page draws it.
    pub const MAP: &str = "/slamd/map";
}

/// The viewer's channels on one Foxglove context.
struct Channels {
    trajectory: Channel<PosesInFrame>,
    graph: Channel<SceneUpdate>,
    newest: Channel<PoseInFrame>,
    location: Channel<LocationFix>,
    locations: Channel<LocationFixes>,
    health: Arc<RawChannel>,
    map: Arc<RawChannel>,
}

impl Channels {
    fn new(ctx: &Arc<Context>) -> anyhow::Result<Self> {
        let json = |t: &str| ctx.channel_builder(t).message_encoding("json").build_raw();
        Ok(Self {
            trajectory: ctx.channel_builder(topic::TRAJECTORY).build(),
            graph: ctx.channel_builder(topic::GRAPH).build(),
            newest: ctx.channel_builder(topic::NEWEST).build(),
            location: ctx.channel_builder(topic::LOCATION).build(),
            locations: ctx.channel_builder(topic::LOCATIONS).build(),
            health: json(topic::HEALTH)?,
            map: json(topic::MAP)?,
        })
    }

    /// Logs `frame` on every map channel someone listens to, at the time
    /// it was solved (the health goes by [`Self::publish_health`]).
    fn publish(&self, frame: &Frame) {
        let t = frame.header.solved_at_ns;
        if self.trajectory.has_sinks() {
            self.trajectory.log_with_time(&frame.trajectory(), t);
        }
        let loops = (self.graph.has_sinks() || self.map.has_sinks()).then(|| frame.loop_closures());
        let loops = loops.as_deref().unwrap_or_default();
        if self.graph.has_sinks() {
            self.graph.log_with_time(&frame.graph(loops), t);
        }
        if let Some(p) = frame.newest_pose().filter(|_| self.newest.has_sinks()) {
            self.newest.log_with_time(&p, t);
        }
        if self.location.has_sinks() || self.locations.has_sinks() {
            if let Some((all, newest)) = frame.locations() {
                self.location.log_with_time(&newest, t);
                self.locations.log_with_time(&all, t);
            }
        }
        if self.map.has_sinks() {
            self.map.log_with_meta(&frame.page_map(loops), at(t));
        }
    }

    /// Logs the daemon's health: its counters from the newer of `frame`
    /// and its status (a status is read once a tick, so it can lag the
    /// frame it goes with), its latency and journal from the status.
    fn publish_health(&self, frame: &Frame, status: Option<&DaemonStatus>) {
        if self.health.has_sinks() {
            let header = match status {
                Some(s) if s.snapshot.version > frame.header.version => &s.snapshot,
                _ => &frame.header,
            };
            let t = header.solved_at_ns;
            let v = scene::health(header, status);
            self.health.log_with_meta(v.to_string().as_bytes(), at(t));
        }
    }
}

fn at(t: u64) -> foxglove::PartialMetadata {
    foxglove::PartialMetadata { log_time: Some(t) }
}

/// Raised when a client subscribes: the loop then publishes the newest
/// frame again.
struct OnSubscribe(Arc<AtomicBool>);

impl ServerListener for OnSubscribe {
    fn on_subscribe(&self, _client: Client, _channel: ChannelView) {
        self.0.store(true, Ordering::Release);
    }
}

/// How often the viewer tells that it is still waiting for a daemon.
const SAY_EVERY: Duration = Duration::from_secs(5);

pub fn run(opts: ViewOpts) -> anyhow::Result<()> {
    for (flag, rate) in [("--rate", opts.rate), ("--record-rate", opts.record_rate)] {
        anyhow::ensure!(
            rate.is_finite() && rate > 0.0,
            "{flag} must be a positive number of frames per second"
        );
    }
    let config = crate::run::load_config(None, opts.namespace.as_deref())?;
    let namespace = config.namespace.clone();
    crate::signals::catch();
    let ctx = Context::new();
    let mut live = Sink::new(&ctx, opts.rate)?;
    let resend = Arc::new(AtomicBool::new(false));
    let server = WebSocketServer::new()
        .name(format!("slamd {namespace}"))
        .bind(opts.host.clone(), opts.port)
        .context(&ctx)
        .listener(Arc::new(OnSubscribe(resend.clone())))
        .start_blocking()
        .with_context(|| format!("serving the Foxglove WebSocket on {}:{}", opts.host, opts.port))?;
    let ws_port = server.port();
    println!("foxglove: ws://{}:{ws_port}", opts.host);
    if !opts.no_page {
        let port = page::serve(&opts.host, opts.page_port, ws_port)
            .with_context(|| format!("serving the page on {}:{}", opts.host, opts.page_port))?;
        println!("page: http://{}:{port}/", opts.host);
    }
    // the recording has a context and channels of its own, published at
    // its own rate; the context lives as long as the recording
    let record_ctx = Context::new();
    let writer = match &opts.record {
        Some(path) => {
            let options = McapWriteOptions::default().compression(Some(McapCompression::Lz4));
            let w = McapWriter::with_options(options)
                .context(&record_ctx)
                .create_new_buffered_file(path)
                .with_context(|| format!("recording to {}", path.display()))?;
            println!("recording: {}", path.display());
            Some(w)
        }
        None => None,
    };
    let mut recorder = match writer {
        Some(_) => Some(Sink::new(&record_ctx, opts.record_rate)?),
        None => None,
    };
    let _ = std::io::stdout().flush();

    let served = serve(&namespace, &mut live, recorder.as_mut(), &resend);
    if let Some(w) = writer {
        w.close().context("closing the recording")?;
    }
    server.stop().wait_blocking();
    served?;
    match recorder {
        Some(r) => println!("frames: {}, recorded: {}", live.frames, r.frames),
        None => println!("frames: {}", live.frames),
    }
    Ok(())
}

/// One set of channels and how often it gets a frame.
struct Sink {
    channels: Channels,
    period: Duration,
    last: Option<Instant>,
    /// A frame came that this sink has not published.
    behind: bool,
    frames: u64,
}

impl Sink {
    fn new(ctx: &Arc<Context>, rate: f64) -> anyhow::Result<Self> {
        let period = Duration::try_from_secs_f64(1.0 / rate)
            .map_err(|_| anyhow::anyhow!("{rate:e} frames a second is no rate a viewer can keep"))?;
        Ok(Self {
            channels: Channels::new(ctx)?,
            period,
            last: None,
            behind: false,
            frames: 0,
        })
    }

    /// Publishes `frame` if one came since the last and the period has
    /// passed (or, with `now`, at once); whether it did.
    fn publish(&mut self, frame: &Frame, now: bool) -> bool {
        let due = now || self.last.is_none_or(|t| t.elapsed() >= self.period);
        if !(self.behind && due && frame.header.version > 0) {
            return false;
        }
        self.channels.publish(frame);
        self.frames += 1;
        self.last = Some(Instant::now());
        self.behind = false;
        true
    }

    /// How long until this sink may publish again.
    fn rest(&self) -> Duration {
        self.last
            .map_or(Duration::ZERO, |t| self.period.saturating_sub(t.elapsed()))
    }
}

/// Reads the daemon on `namespace` and publishes what it reads, until
/// SIGINT or SIGTERM; then publishes what came since the last frame. A
/// daemon silent for [`SILENT`] is looked for anew (a restarted daemon
/// serves new services). The recording, if any, gets every
/// `record`-period's newest frame, and the last one.
fn serve(
    namespace: &str,
    live: &mut Sink,
    mut record: Option<&mut Sink>,
    resend: &AtomicBool,
) -> anyhow::Result<()> {
    let mut frame = Frame::default();
    let mut status = None;
    while let Some(mut link) = connect(namespace) {
        tracing::info!(namespace, "Viewing.");
        let mut heard = Instant::now();
        loop {
            let stopping = crate::signals::stopped();
            // a new client sees the map at once
            live.behind |= resend.swap(false, Ordering::AcqRel);
            let mut changed = false;
            if let Some(s) = link.wait(if stopping {
                Duration::ZERO
            } else {
                live.period.min(LOOK)
            })? {
                frame.header = *s.header();
                frame.poses.clear();
                frame.poses.extend_from_slice(s.poses());
                changed = true;
            }
            if let Some(s) = link.switches()? {
                frame.loops.clear();
                frame.loops.extend_from_slice(s.switches());
                changed = true;
            }
            if let Some(s) = link.status()? {
                status = Some(s);
                heard = Instant::now();
                live.channels.publish_health(&frame, status.as_ref());
            }
            // the live view's health goes with every status read, the
            // recording's with its frames
            live.behind |= changed;
            live.publish(&frame, stopping);
            if let Some(r) = record.as_deref_mut() {
                r.behind |= changed;
                if r.publish(&frame, stopping) {
                    r.channels.publish_health(&frame, status.as_ref());
                }
            }
            if stopping {
                return Ok(());
            }
            if heard.elapsed() > SILENT {
                eprintln!("slamd view: the daemon on `{namespace}` fell silent; looking for it again");
                break;
            }
            // at most one live frame per period: sleep out its rest
            crate::signals::sleep(live.rest());
        }
    }
    Ok(())
}

/// A daemon publishes its status on every tick (250 ms by default); one
/// not heard for this long is gone.
const SILENT: Duration = Duration::from_secs(3);

/// How long one wait for a snapshot lasts at most.
const LOOK: Duration = Duration::from_millis(100);

/// Opens the daemon's outputs, waiting for a daemon to serve `namespace`
/// and saying so every [`SAY_EVERY`]; `None` if stopped first.
fn connect(namespace: &str) -> Option<SnapshotLink> {
    let started = Instant::now();
    let mut said = Instant::now();
    loop {
        match SnapshotLink::open(namespace) {
            Ok(link) => return Some(link),
            Err(e) => {
                if said.elapsed() >= SAY_EVERY {
                    eprintln!(
                        "slamd view: waiting {:.0} s for a daemon on namespace `{namespace}` ({e})",
                        started.elapsed().as_secs_f64()
                    );
                    said = Instant::now();
                }
            }
        }
        crate::signals::sleep(Duration::from_millis(200));
        if crate::signals::stopped() {
            return None;
        }
    }
}
