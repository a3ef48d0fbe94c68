//! The `slamd` command: run the daemon, solve or replay a graph, demo.

mod cli;
mod demo;
mod eval;
mod replay;
mod solve;
mod synth;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_env("SLAMD_LOG").unwrap_or_else(|_| "warn".into()),
        )
        .with_writer(std::io::stderr)
        .init();
    let result = match cli.command {
        cli::Command::Solve(opts) => solve::run(opts),
        cli::Command::Eval(opts) => eval::run(opts),
        cli::Command::Synth(opts) => synth::run(opts),
        cli::Command::Demo(opts) => demo::run(opts),
        cli::Command::Replay(opts) => replay::run(opts),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("slamd: {e:#}");
            ExitCode::from(2)
        }
    }
}
