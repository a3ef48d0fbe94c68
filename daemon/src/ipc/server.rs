//! [`serve`]: the daemon's main loop and its two threads.

use super::durable::Start;
use super::engine_loop::{Counters, EngineLoop, Msg};
use crate::config::Config;
use crate::engine::{EngineError, EnginePose};
use crate::graph::Pose3;
use crate::store::{MapFile, StateDir, StoreError};
use crossbeam::channel;
use slamd_protocol::codec as wire;
use slamd_protocol::transport::{Exit, Ingress, Input, Outlet, TransportError, Wake};
use std::fmt;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::Duration;

/// Why the daemon could not serve.
#[derive(Debug)]
pub enum ServeError {
    /// Shared memory could not be set up or used.
    Transport(TransportError),
    /// The engine thread stopped unexpectedly.
    EngineThread(String),
    /// The state directory cannot be used.
    State(StoreError),
    /// The saved map cannot be taken up.
    Restore(EngineError),
    /// `--map` given with a state directory that already holds a map.
    TwoMaps(std::path::PathBuf),
    /// A map of another dimension than the configured one.
    Dimension {
        /// The map's.
        map: u32,
        /// The configuration's.
        configured: u32,
    },
}

impl fmt::Display for ServeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ServeError::Transport(e) => e.fmt(f),
            ServeError::EngineThread(e) => write!(f, "engine thread: {e}"),
            ServeError::State(e) => write!(f, "state directory: {e}"),
            ServeError::Restore(e) => e.fmt(f),
            ServeError::TwoMaps(dir) => write!(
                f,
                "the state directory {} already holds a map; continue it without --map, or give an empty directory",
                dir.display()
            ),
            ServeError::Dimension { map, configured } => write!(
                f,
                "the map is {map}-D, but the daemon is configured for {configured}-D graphs (`dimension`)"
            ),
        }
    }
}

impl std::error::Error for ServeError {}

impl From<TransportError> for ServeError {
    fn from(e: TransportError) -> Self {
        ServeError::Transport(e)
    }
}

/// Serves `config.namespace` until SIGINT or SIGTERM, then returns the
/// counts of what it took in.
///
/// Start-up checks `/dev/shm`, removes what dead slamd processes left, and
/// creates every service; a second daemon on the same namespace, or a
/// stale service of another protocol version, is a clear error here.
pub fn serve(config: &Config) -> Result<Counters, ServeError> {
    serve_until(config, &AtomicBool::new(false))
}

/// [`serve`], also stopping within a tick once `stop` is set. The
/// configuration's `dimension` picks the pose type.
pub fn serve_until(config: &Config, stop: &AtomicBool) -> Result<Counters, ServeError> {
    match config.dimension {
        3 => serve_map::<Pose3>(config, None, stop),
        _ => serve_map::<crate::geometry::Pose2>(config, None, stop),
    }
}

/// [`serve_until`] on poses `P`, continuing `map` (`slamd run --map`) when
/// given. `P` must be of the configured dimension.
///
/// With `state.dir` set, the directory is opened first (locked, its map
/// and journal read, a torn journal tail cut off): a directory that cannot
/// be written, or that holds a map of the other dimension, is an error
/// here. The engine thread takes up the saved map and the journal's tail
/// before the first snapshot.
pub fn serve_map<P: EnginePose>(
    config: &Config,
    map: Option<MapFile<P>>,
    stop: &AtomicBool,
) -> Result<Counters, ServeError> {
    if P::DIMENSION != config.dimension {
        return Err(ServeError::Dimension {
            map: P::DIMENSION,
            configured: config.dimension,
        });
    }
    let start = open_state(config, map)?;
    if let Some(cpu) = config.ipc.cpu {
        if !crate::affinity::reserve_current_thread(cpu) {
            tracing::warn!(cpu, "Cannot pin the IPC thread; running unpinned.");
        }
    }
    let ingress = Ingress::create(&config.namespace, &config.qos())?;
    tracing::info!(
        namespace = %config.namespace,
        shared_memory_mib = config.qos().shared_memory_bytes() >> 20,
        cleaned_dead_nodes = ingress.cleaned_at_start(),
        "slamd serving."
    );
    let (tx, rx) = channel::unbounded::<Msg<P>>();
    let (ready_tx, ready_rx) = channel::bounded::<Result<(), ServeError>>(1);
    let engine_config = config.clone();
    let resolved = tx.clone();
    let engine = std::thread::Builder::new()
        .name("slamd-engine".into())
        .spawn(move || {
            if let Some(cpu) = engine_config.ipc.cpu {
                crate::affinity::reserve_current_thread(cpu);
            }
            // iceoryx2 ports are not Send: the outlet is opened on this thread
            let outlet = match Outlet::open(&engine_config.namespace, &engine_config.qos()) {
                Ok(outlet) => outlet,
                Err(e) => {
                    let _ = ready_tx.send(Err(e.into()));
                    return Counters::default();
                }
            };
            let mut engine_loop = EngineLoop::<P>::new(engine_config, outlet);
            // a finished re-solve is published at once, not at the next tick
            engine_loop.engine.wake_on_resolved(move || {
                let _ = resolved.send(Msg::Resolved);
            });
            match engine_loop.take_up(start) {
                Ok(()) => {
                    let _ = ready_tx.send(Ok(()));
                    engine_loop.run(rx)
                }
                Err(e) => {
                    let _ = ready_tx.send(Err(ServeError::Restore(e)));
                    Counters::default()
                }
            }
        })
        .map_err(|e| ServeError::EngineThread(e.to_string()))?;
    ready_rx
        .recv()
        .map_err(|_| ServeError::EngineThread("stopped during start-up".into()))??;

    let stop_engine = StopEngine(tx.clone());
    let tick = Duration::from_millis(config.ipc.tick_ms);
    let exit = ingress.run(tick, |wake| {
        let msg = match wake {
            Wake::Input(Input::Keyframe(m)) => match wire::keyframe_in::<P>(&m) {
                Ok((o, k)) => Msg::Keyframe(o, k),
                Err(r) => Msg::Rejected(r),
            },
            Wake::Input(Input::Edge(m)) => match wire::edge_in::<P>(&m) {
                Ok((o, e)) => Msg::Edge(o, e),
                Err(r) => Msg::Rejected(r),
            },
            Wake::Input(Input::Gps(m)) => match wire::gps_in(&m) {
                Ok((o, f)) => Msg::Gps(o, f),
                Err(r) => Msg::Rejected(r),
            },
            Wake::Drained => Msg::Drained,
            Wake::Tick if stop.load(Ordering::Relaxed) => return false,
            Wake::Tick => Msg::Tick,
        };
        tx.send(msg).is_ok()
    });
    drop(stop_engine);
    let counters = engine
        .join()
        .map_err(|_| ServeError::EngineThread("panicked".into()))?;
    match exit? {
        Exit::Signal => tracing::info!(?counters, "Signal received; slamd stopped."),
        Exit::Stopped => tracing::info!(?counters, "slamd stopped."),
    }
    Ok(counters)
}

/// Tells the engine thread to stop when dropped, also when the IPC loop
/// unwinds: the engine's re-solve waker holds a sender of its channel, so
/// the channel never closes by itself.
struct StopEngine<P: EnginePose>(channel::Sender<Msg<P>>);

impl<P: EnginePose> Drop for StopEngine<P> {
    fn drop(&mut self) {
        let _ = self.0.send(Msg::Shutdown);
    }
}

/// Opens the state directory, if one is configured, and decides which map
/// the daemon continues.
fn open_state<P: EnginePose>(config: &Config, map: Option<MapFile<P>>) -> Result<Start<P>, ServeError> {
    let Some(dir) = &config.state.dir else {
        return Ok(Start {
            store: None,
            map,
            tail: Vec::new(),
            cut: None,
        });
    };
    let (store, recovered) = StateDir::open(dir, &config.state).map_err(ServeError::State)?;
    let saved = recovered.map.is_some() || !recovered.tail.is_empty();
    if map.is_some() && saved {
        return Err(ServeError::TwoMaps(dir.clone()));
    }
    Ok(Start {
        store: Some(store),
        map: recovered.map.or(map),
        tail: recovered.tail,
        cut: recovered.cut,
    })
}

/// A daemon on a thread of this process: for examples, tests and
/// applications that want the shared-memory interface without a separate
/// process.
pub struct Server {
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<Result<Counters, ServeError>>>,
}

impl Server {
    /// Serves `config.namespace` on a new thread, in the configured
    /// dimension; returns once frontends can connect (or with the start-up
    /// error).
    pub fn spawn(config: Config) -> Result<Server, ServeError> {
        match config.dimension {
            3 => Self::spawn_map::<Pose3>(config, None),
            _ => Self::spawn_map::<crate::geometry::Pose2>(config, None),
        }
    }

    /// [`Self::spawn`] on poses `P` (of the configured dimension),
    /// continuing `map` when given.
    pub fn spawn_map<P: EnginePose>(config: Config, map: Option<MapFile<P>>) -> Result<Server, ServeError> {
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let namespace = config.namespace.clone();
        let thread = std::thread::Builder::new()
            .name("slamd-server".into())
            .spawn(move || serve_map(&config, map, &flag))
            .map_err(|e| ServeError::EngineThread(e.to_string()))?;
        let server = Server {
            stop,
            thread: Some(thread),
        };
        // up when its services can be opened
        let deadline = std::time::Instant::now() + Duration::from_secs(10);
        loop {
            if slamd_protocol::transport::SnapshotLink::open(&namespace).is_ok() {
                return Ok(server);
            }
            if server.thread.as_ref().is_some_and(|t| t.is_finished()) || std::time::Instant::now() > deadline
            {
                return Err(server
                    .join()
                    .err()
                    .unwrap_or(ServeError::EngineThread("did not start".into())));
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Stops serving and returns what it took in.
    pub fn join(mut self) -> Result<Counters, ServeError> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take() {
            Some(t) => t
                .join()
                .map_err(|_| ServeError::EngineThread("panicked".into()))?,
            None => Ok(Counters::default()),
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}
