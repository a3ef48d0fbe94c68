//! `slamd status`: a running daemon's health in one screen, from what it
//! publishes (it never talks to the daemon, so it never blocks it).

use clap::Args;
use slamd::ipc::Snapshots;
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

#[derive(Args, Debug)]
pub struct StatusOpts {
    /// TOML configuration (for the namespace).
    #[arg(long, env = slamd::config::FILE_VARIABLE)]
    pub config: Option<PathBuf>,
    /// Namespace of the daemon (overrides the configuration).
    #[arg(long)]
    pub namespace: Option<String>,
    /// Seconds to wait for a daemon that publishes.
    #[arg(long, default_value_t = 2.0)]
    pub wait: f64,
    /// Print one JSON object instead of the screen.
    #[arg(long)]
    pub json: bool,
}

pub fn run(opts: StatusOpts) -> anyhow::Result<()> {
    let config = crate::run::load_config(opts.config.as_deref(), opts.namespace.as_deref())?;
    let ns = config.namespace.as_str();
    let deadline = Instant::now() + Duration::from_secs_f64(opts.wait.max(0.0));
    loop {
        if let Ok(link) = Snapshots::open(ns) {
            // the daemon publishes its status on every tick
            let until = Instant::now() + Duration::from_millis(600);
            while Instant::now() < until {
                if let Some(status) = link.status()? {
                    return show(ns, &status, opts.json);
                }
                std::thread::sleep(Duration::from_millis(10));
            }
        }
        if Instant::now() >= deadline {
            anyhow::bail!(
                "no slamd daemon publishes on namespace `{ns}` (waited {:.1} s)",
                opts.wait
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Prints `status` as a screen or as JSON.
fn show(ns: &str, status: &slamd_protocol::DaemonStatus, json: bool) -> anyhow::Result<()> {
    let h = status.snapshot;
    let now = now_ns();
    let age = |ns: u64| (ns > 0).then(|| now.saturating_sub(ns) as f64 / 1e9);
    let acks: Vec<_> = (status.acks.iter())
        .filter(|a| a.frontend != 0)
        .map(|a| serde_json::json!({"frontend": a.frontend, "through": a.sequence}))
        .collect();
    let v = serde_json::json!({
        "namespace": ns,
        "dimension": h.dimension,
        "uptime_s": age(status.started_at_ns),
        "keyframes": h.keyframes,
        "edges": h.edges,
        "fixes": h.fixes,
        "rejected": h.rejected,
        "held": h.held,
        "resolves": h.resolves,
        "chi2": h.chi2,
        "georeferenced": h.georeferenced != 0,
        "snapshot_version": h.version,
        "snapshot_age_s": age(h.solved_at_ns),
        "frontends_last_minute": status.frontends,
        "latency_p50_us": status.latency_p50_us,
        "latency_p99_us": status.latency_p99_us,
        "journal_bytes": status.journal_bytes,
        "journal_failing": status.journal_failing != 0,
        "since_checkpoint_s": age(status.checkpoint_at_ns),
        "acknowledged": acks,
    });
    if json {
        println!("{v}");
        return Ok(());
    }
    let s = |k: &str| v[k].as_f64().map_or("-".into(), |x| format!("{x:.1}"));
    println!("slamd on `{ns}` ({}-D): up {} s", h.dimension, s("uptime_s"));
    println!(
        "  map        {} keyframes, {} edges, {} fixes; χ² {:.3}{}",
        h.keyframes,
        h.edges,
        h.fixes,
        h.chi2,
        if h.georeferenced != 0 {
            ", georeferenced"
        } else {
            ""
        }
    );
    println!(
        "  input      {} rejected, {} held; {} frontends in the last minute",
        h.rejected, h.held, status.frontends
    );
    println!(
        "  snapshot   version {}, {} s old; {} re-solves",
        h.version,
        s("snapshot_age_s"),
        h.resolves
    );
    println!(
        "  latency    p50 {:.0} µs, p99 {:.0} µs (last minute)",
        status.latency_p50_us, status.latency_p99_us
    );
    if status.journal_bytes > 0 || status.checkpoint_at_ns > 0 {
        let checkpoint = match v["since_checkpoint_s"].as_f64() {
            Some(t) => format!("last checkpoint {t:.1} s ago"),
            None => "no checkpoint yet".into(),
        };
        println!(
            "  journal    {} bytes{}; {checkpoint}",
            status.journal_bytes,
            if status.journal_failing != 0 {
                ", WRITES FAILING"
            } else {
                ""
            },
        );
    } else {
        println!("  journal    none (no state directory)");
    }
    for a in status.acks.iter().filter(|a| a.frontend != 0) {
        println!("  frontend   {} acknowledged through {}", a.frontend, a.sequence);
    }
    Ok(())
}

fn now_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}
