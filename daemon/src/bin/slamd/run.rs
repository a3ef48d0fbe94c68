//! `slamd run`: the daemon.

use clap::Args;
use slamd::config::Config;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct RunOpts {
    /// TOML configuration (SLAMD_* environment variables override it).
    #[arg(long, env = slamd::config::FILE_VARIABLE)]
    pub config: Option<PathBuf>,
    /// Serve this namespace instead of the configured one.
    #[arg(long)]
    pub namespace: Option<String>,
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
    let config = load_config(opts.config.as_deref(), opts.namespace.as_deref())?;
    crate::telemetry::init(&config.log);
    slamd::ipc::serve(&config)?;
    Ok(())
}
