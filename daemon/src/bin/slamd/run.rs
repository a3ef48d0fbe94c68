//! `slamd run`: the daemon.

use clap::Args;
use slamd::config::Config;
use slamd::geometry::Pose2;
use slamd::graph::Pose3;
use slamd::store::MapFile;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

#[derive(Args, Debug)]
pub struct RunOpts {
    /// TOML configuration (SLAMD_* environment variables override it).
    #[arg(long, env = slamd::config::FILE_VARIABLE)]
    pub config: Option<PathBuf>,
    /// Serve this namespace instead of the configured one.
    #[arg(long)]
    pub namespace: Option<String>,
    /// Keep a journal and checkpoints here and continue what it holds
    /// after a restart (config `state.dir`).
    #[arg(long)]
    pub state: Option<PathBuf>,
    /// Start from this saved map (a state directory's `map` file) and keep
    /// mapping in it.
    #[arg(long)]
    pub map: Option<PathBuf>,
}

/// Loads the configuration, with `namespace` taking precedence.
pub fn load_config(path: Option<&std::path::Path>, namespace: Option<&str>) -> anyhow::Result<Config> {
    let mut config = Config::load(path)?;
    if let Some(ns) = namespace {
        config.namespace = ns.to_string();
        config.validate()?;
    }
    Ok(config)
}

pub fn run(opts: RunOpts) -> anyhow::Result<()> {
    let mut config = load_config(opts.config.as_deref(), opts.namespace.as_deref())?;
    if let Some(dir) = opts.state {
        config.state.dir = Some(dir);
    }
    crate::telemetry::init(&config.log);
    let stop = AtomicBool::new(false);
    let path = opts.map.as_deref();
    if config.dimension == 3 {
        let map = path.map(MapFile::<Pose3>::read).transpose()?;
        slamd::ipc::serve_map(&config, map, &stop)?;
    } else {
        let map = path.map(MapFile::<Pose2>::read).transpose()?;
        slamd::ipc::serve_map(&config, map, &stop)?;
    }
    Ok(())
}
