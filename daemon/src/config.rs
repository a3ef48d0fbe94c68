//! [`Config`]: every setting of the daemon and its frontends, in one place.
//!
//! Defaults come from one `Default` impl, then a TOML file (`--config`),
//! then `SLAMD_*` environment variables, each overriding the one before:
//! `SLAMD_NAMESPACE=robot7`, `SLAMD_IPC__EDGE_BUFFER=8192`,
//! `SLAMD_ENGINE__RESOLVE_EVERY_EDGES=500` (double underscores separate
//! levels). `slamd run`, `slamd replay` and the client read the same
//! settings, so a daemon and its frontends agree on the namespace.
//!
//! ```toml
//! namespace = "slamd"          # service names live under it
//! log = "info"                 # tracing filter (SLAMD_LOG overrides)
//! held_edges = 100000          # edges kept waiting for their keyframes
//! held_timeout_s = 30.0        # then rejected as naming an unknown keyframe
//!
//! [ipc]
//! max_frontends = 16
//! max_subscribers = 8
//! keyframe_buffer = 1024       # queue lengths on the daemon's side
//! edge_buffer = 4096
//! gps_buffer = 1024
//! initial_poses = 16384        # snapshot size reserved at start (it grows)
//! max_changes = 256            # a snapshot that changed more poses goes out whole
//! change_buffer = 32           # changes a subscriber's queue holds
//! backpressure_ms = 200        # a frontend's send waits this long on a full queue
//! tick_ms = 250                # dead-node cleanup and idle work
//! reconnect_s = 30.0           # a frontend waits this long for a restarted daemon
//! # cpu = 0                    # pin the IPC and engine threads (background work: other CPUs)
//!
//! [snapshot]
//! max_rate_hz = 0.0            # 0: one snapshot per processed batch
//! covariance = true            # the newest keyframe's covariance in each header
//! whole_every_ms = 1000        # the whole map at least this often (late subscribers)
//!
//! [gps]                        # see slamd::gps::GpsConfig
//! # origin = "45.5138,9.2110"  # ENU origin LAT,LON[,HEIGHT]; default: the first fix
//!
//! [state]                      # see slamd::store::StateConfig
//! # dir = "/var/lib/slamd"     # journal and checkpoints; none: in memory only
//! sync = "always"              # fsync the journal per batch: always, interval, never
//! sync_interval_ms = 100
//! checkpoint_interval_s = 60.0
//! checkpoint_journal_mib = 64
//!
//! [engine]                     # see slamd::engine::EngineConfig
//! resolve_every_edges = 10000
//! refresh_every_edges = 50     # relinearise between re-solves when the worker is free
//! relinearise_ratio = 1.2      # χ² past this × its linear model's (+0.01): relinearise inline
//!
//! [engine.outliers]            # see slamd::outliers::OutlierConfig
//! drift_run = 20               # agreeing rejections in a row that mean drift: re-solve
//! arrival_covariance = true    # a loop closure the gate turns away is tried against the map's uncertainty
//! unadmitted_start = false     # every re-solve (not only the closing one) also starts without the loop closures let in on arrival
//! pairwise = false             # PCM: only the largest set of loop closures that agree pairwise through the odometry
//! ```

use crate::engine::EngineConfig;
use crate::gps::GpsConfig;
use crate::store::StateConfig;
use serde::{Deserialize, Serialize};
use slamd_protocol::service::{Qos, DEFAULT_NAMESPACE};
use std::fmt;
use std::path::Path;
use std::time::Duration;

/// The environment variable that names the configuration file (the
/// commands' `--config`).
pub const FILE_VARIABLE: &str = "SLAMD_CONFIG";

/// `SLAMD_*` variables that are not settings: the configuration file, and
/// those of slamd's tests and bench scripts (the datasets' directory, the
/// binary a script runs). Any other `SLAMD_*` variable must name a
/// setting, so a typo is an error, not silently ignored.
pub const NOT_SETTINGS: [&str; 3] = [FILE_VARIABLE, "SLAMD_DATASETS", "SLAMD_BIN"];

/// Why the configuration cannot be used.
#[derive(Debug)]
pub struct ConfigError(String);

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "configuration: {}", self.0)
    }
}

impl std::error::Error for ConfigError {}

/// Shared-memory sizes and timings.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct IpcConfig {
    /// Frontends that may publish at once.
    pub max_frontends: usize,
    /// Snapshot subscribers at once.
    pub max_subscribers: usize,
    /// Keyframes the daemon's queue holds.
    pub keyframe_buffer: usize,
    /// Edges the daemon's queue holds.
    pub edge_buffer: usize,
    /// GPS fixes the daemon's queue holds.
    pub gps_buffer: usize,
    /// Poses the snapshot publisher reserves at start.
    pub initial_poses: usize,
    /// Changed poses one snapshot carries at most; one that changed more
    /// goes out whole. Every subscriber's queue of changes costs
    /// `change_buffer` × this × 112 bytes of shared memory.
    pub max_changes: usize,
    /// Snapshots' changes a subscriber's queue holds (and a late
    /// subscriber catches up from): a reader that falls further behind
    /// waits for the next whole map.
    pub change_buffer: usize,
    /// How long a frontend's send retries on a full queue before failing.
    pub backpressure_ms: u64,
    /// Period of dead-node cleanup and idle work.
    pub tick_ms: u64,
    /// How long a frontend waits for a daemon that went away to come back.
    pub reconnect_s: f64,
    /// Pin the daemon's IPC and engine threads to this CPU; re-solves and
    /// the freeing of retired factors then run on the other CPUs. On a
    /// small VM a wake-up across cores costs several times one on the same
    /// core; frontends that share the core answer fastest.
    pub cpu: Option<usize>,
}

impl Default for IpcConfig {
    fn default() -> Self {
        let q = Qos::default();
        Self {
            max_frontends: q.max_frontends,
            max_subscribers: q.max_subscribers,
            keyframe_buffer: q.keyframe_buffer,
            edge_buffer: q.edge_buffer,
            gps_buffer: q.gps_buffer,
            initial_poses: q.initial_poses,
            max_changes: q.max_changes,
            change_buffer: q.change_buffer,
            backpressure_ms: 200,
            tick_ms: 250,
            reconnect_s: 30.0,
            cpu: None,
        }
    }
}

/// How snapshots go out.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SnapshotConfig {
    /// Upper bound on snapshots per second (0: one per processed batch).
    pub max_rate_hz: f64,
    /// Whether each snapshot's header carries the marginal covariance of
    /// its newest keyframe ([`Engine::marginal`](crate::engine::Engine::marginal)).
    pub covariance: bool,
    /// The whole map goes out at least this often (ms), besides whenever
    /// more than `ipc.max_changes` poses changed: a late subscriber, or one
    /// whose queue of changes overflowed, waits at most this long for a
    /// map. Every whole map costs the map's size; the snapshots between
    /// cost what changed.
    pub whole_every_ms: u64,
}

impl Default for SnapshotConfig {
    fn default() -> Self {
        Self {
            max_rate_hz: 0.0,
            covariance: true,
            whole_every_ms: 1000,
        }
    }
}

/// Every setting of slamd.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Config {
    /// Service names live under this namespace.
    pub namespace: String,
    /// The dimension of the graphs the daemon serves: 2 (planar poses
    /// `x, y, θ`) or 3 (spatial poses, position and quaternion). A message
    /// of the other dimension is refused.
    pub dimension: u32,
    /// Log filter (tracing's `EnvFilter` syntax).
    pub log: String,
    /// Edges kept waiting for a keyframe that has not arrived.
    pub held_edges: usize,
    /// Seconds an edge may wait for its keyframe before it is rejected.
    pub held_timeout_s: f64,
    /// Shared memory.
    pub ipc: IpcConfig,
    /// Snapshot publication.
    pub snapshot: SnapshotConfig,
    /// The incremental engine.
    pub engine: EngineConfig,
    /// GPS fixes: ENU origin, weighting, paper A's triangle rules.
    pub gps: GpsConfig,
    /// The state directory: journal and checkpoints.
    pub state: StateConfig,
}

impl Default for Config {
    fn default() -> Self {
        Self {
            namespace: DEFAULT_NAMESPACE.to_string(),
            dimension: 2,
            log: "info".to_string(),
            held_edges: 100_000,
            held_timeout_s: 30.0,
            ipc: IpcConfig::default(),
            snapshot: SnapshotConfig::default(),
            engine: EngineConfig::default(),
            gps: GpsConfig::default(),
            state: StateConfig::default(),
        }
    }
}

impl Config {
    /// The engine's settings, with the `[gps]` section.
    pub fn engine(&self) -> EngineConfig {
        EngineConfig {
            gps: self.gps.clone(),
            ..self.engine.clone()
        }
    }

    /// Defaults, overridden by `file` (TOML) if given, then by `SLAMD_*`
    /// environment variables; validated.
    pub fn load(file: Option<&Path>) -> Result<Config, ConfigError> {
        Self::load_with_env(file, std::env::vars())
    }

    /// [`Self::load`] with the environment given. `SLAMD_CONFIG` names the
    /// file (the command line reads it); it and the rest of
    /// [`NOT_SETTINGS`] are not settings.
    fn load_with_env(
        file: Option<&Path>,
        env: impl IntoIterator<Item = (String, String)>,
    ) -> Result<Config, ConfigError> {
        let env: config::Map<String, String> = env
            .into_iter()
            .filter(|(k, _)| !NOT_SETTINGS.contains(&k.as_str()))
            .collect();
        let err = |e: config::ConfigError| ConfigError(e.to_string());
        let mut builder =
            config::Config::builder().add_source(config::Config::try_from(&Config::default()).map_err(err)?);
        if let Some(path) = file {
            if !path.exists() {
                return Err(ConfigError(format!("{} does not exist", path.display())));
            }
            builder = builder.add_source(config::File::from(path).format(config::FileFormat::Toml));
        }
        builder = builder.add_source(
            config::Environment::with_prefix("SLAMD")
                .prefix_separator("_")
                .separator("__")
                .try_parsing(true)
                .source(Some(env)),
        );
        let c: Config = builder.build().map_err(err)?.try_deserialize().map_err(err)?;
        c.validate()?;
        Ok(c)
    }

    /// Checks values that parse but make no sense.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError(m));
        if self.namespace.is_empty()
            || self.namespace.len() > 200
            || self.namespace.contains(char::is_whitespace)
        {
            return bad(format!(
                "namespace `{}` must be 1-200 characters without spaces",
                self.namespace
            ));
        }
        if !(2..=3).contains(&self.dimension) {
            return bad(format!("dimension {} must be 2 or 3", self.dimension));
        }
        let i = &self.ipc;
        for (name, v) in [
            ("ipc.max_frontends", i.max_frontends),
            ("ipc.max_subscribers", i.max_subscribers),
            ("ipc.keyframe_buffer", i.keyframe_buffer),
            ("ipc.edge_buffer", i.edge_buffer),
            ("ipc.gps_buffer", i.gps_buffer),
            ("ipc.initial_poses", i.initial_poses),
            ("ipc.max_changes", i.max_changes),
            ("ipc.change_buffer", i.change_buffer),
        ] {
            if v == 0 {
                return bad(format!("{name} must be at least 1"));
            }
        }
        if i.tick_ms == 0 {
            return bad("ipc.tick_ms must be at least 1".into());
        }
        if !(i.reconnect_s.is_finite() && i.reconnect_s >= 0.0) {
            return bad(format!("ipc.reconnect_s {} must be a number ≥ 0", i.reconnect_s));
        }
        if !self.snapshot.max_rate_hz.is_finite() || self.snapshot.max_rate_hz < 0.0 {
            return bad(format!(
                "snapshot.max_rate_hz {} must be a number ≥ 0",
                self.snapshot.max_rate_hz
            ));
        }
        if self.held_timeout_s.is_nan() || self.held_timeout_s <= 0.0 {
            return bad(format!("held_timeout_s {} must be > 0", self.held_timeout_s));
        }
        let e = &self.engine;
        for (name, v) in [
            ("engine.resolve_fill_ratio", e.resolve_fill_ratio),
            ("engine.wildfire_threshold", e.wildfire_threshold),
            ("engine.nonlinear_ratio", e.nonlinear_ratio),
            ("engine.relinearise_ratio", e.relinearise_ratio),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(format!("{name} {v} must be a number ≥ 0"));
            }
        }
        if let Err(m) = e.outliers.check() {
            return bad(format!("engine.outliers: {m}"));
        }
        let st = &self.state;
        if !(st.checkpoint_interval_s.is_finite() && st.checkpoint_interval_s > 0.0) {
            return bad(format!(
                "state.checkpoint_interval_s {} must be > 0",
                st.checkpoint_interval_s
            ));
        }
        Ok(())
    }

    /// The service sizes for the transport.
    pub fn qos(&self) -> Qos {
        let i = &self.ipc;
        Qos {
            max_frontends: i.max_frontends,
            max_subscribers: i.max_subscribers,
            keyframe_buffer: i.keyframe_buffer,
            edge_buffer: i.edge_buffer,
            gps_buffer: i.gps_buffer,
            initial_poses: i.initial_poses,
            max_changes: i.max_changes,
            change_buffer: i.change_buffer,
            ..Qos::default()
        }
    }

    /// The frontend's send timeout on a full queue.
    pub fn backpressure(&self) -> Duration {
        Duration::from_millis(self.ipc.backpressure_ms)
    }
}

impl From<&Config> for slamd_protocol::Endpoint {
    fn from(c: &Config) -> Self {
        slamd_protocol::Endpoint {
            namespace: c.namespace.clone(),
            backpressure: c.backpressure(),
            reconnect: Duration::from_secs_f64(c.ipc.reconnect_s),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `SLAMD_CONFIG` names the file (`--config`); it is not a setting
    /// named `config`, nor are the datasets' directory and the binary the
    /// bench scripts read.
    #[test]
    fn the_file_variable_is_not_a_setting() {
        let env = [
            (FILE_VARIABLE.to_string(), "/nowhere/slamd.toml".to_string()),
            ("SLAMD_DATASETS".to_string(), "/data".to_string()),
            ("SLAMD_BIN".to_string(), "/opt/slamd".to_string()),
            ("SLAMD_ENGINE__RESOLVE_EVERY_EDGES".to_string(), "7".to_string()),
        ];
        let c = Config::load_with_env(None, env).unwrap();
        assert_eq!(c.engine.resolve_every_edges, 7);
        let unknown = [("SLAMD_NO_SUCH_SETTING".to_string(), "1".to_string())];
        let e = Config::load_with_env(None, unknown).unwrap_err().to_string();
        assert!(e.contains("no_such_setting"), "{e}");
    }

    /// An `[engine]` key that does not exist (a typo, or one that was
    /// removed) is refused by name, as in every other section.
    #[test]
    fn an_unknown_engine_key_is_refused_by_name() {
        let unknown = [("SLAMD_ENGINE__DEFER_BUDGET".to_string(), "0.1".to_string())];
        let e = Config::load_with_env(None, unknown).unwrap_err().to_string();
        assert!(e.contains("defer_budget"), "{e}");
    }

    #[test]
    fn file_then_environment_override_defaults() {
        let dir = std::env::temp_dir().join(format!("slamd-config-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("slamd.toml");
        std::fs::write(
            &path,
            "namespace = \"from-file\"\n[ipc]\nedge_buffer = 77\n[engine]\nresolve_every_edges = 5\n",
        )
        .unwrap();
        let c = Config::load(Some(&path)).unwrap();
        assert_eq!(c.namespace, "from-file");
        assert_eq!(c.ipc.edge_buffer, 77);
        assert_eq!(c.engine.resolve_every_edges, 5);
        assert_eq!(c.ipc.gps_buffer, IpcConfig::default().gps_buffer);
    }

    #[test]
    fn bad_values_are_named() {
        let c = Config {
            ipc: IpcConfig {
                edge_buffer: 0,
                ..Default::default()
            },
            ..Default::default()
        };
        assert_eq!(
            c.validate().unwrap_err().to_string(),
            "configuration: ipc.edge_buffer must be at least 1"
        );
        let mut c = Config::default();
        c.engine.outliers.kernel = crate::robust::Kernel::Dcs { phi: 0.0 };
        assert_eq!(
            c.validate().unwrap_err().to_string(),
            "configuration: engine.outliers: the kernel's parameter 0 must be a number > 0"
        );
        c.engine.outliers.kernel = crate::robust::Kernel::Sc { xi: f64::NAN };
        assert!(c
            .validate()
            .unwrap_err()
            .to_string()
            .contains("NaN must be a number > 0"));
        c.engine.outliers = Default::default();
        c.engine.outliers.cycle.var_high = c.engine.outliers.cycle.var_low / 2.0;
        assert!(c.validate().unwrap_err().to_string().contains("cycle.var_high"));
        c.engine.outliers = Default::default();
        c.engine.wildfire_threshold = -1.0;
        assert_eq!(
            c.validate().unwrap_err().to_string(),
            "configuration: engine.wildfire_threshold -1 must be a number ≥ 0"
        );
        assert!(Config::default().validate().is_ok());
        let dir = std::env::temp_dir().join(format!("slamd-config-bad-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("bad.toml");
        std::fs::write(&path, "nmespace = \"typo\"\n").unwrap();
        let e = Config::load(Some(&path)).unwrap_err().to_string();
        assert!(e.contains("nmespace"), "{e}");
    }
}
