//! The `slamd` command: run the daemon, solve or replay a graph, demo.

mod cli;
mod covariances;
mod demo;
mod eval;
mod export;
mod gps;
mod input;
mod recover;
mod replay;
mod robust;
mod run;
mod signals;
mod solve;
mod status;
mod synth;
mod telemetry;
mod view;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    if !matches!(cli.command, cli::Command::Run(_)) {
        telemetry::init(&std::env::var("SLAMD_LOG").unwrap_or_else(|_| "warn".into()));
    }
    let result = match cli.command {
        cli::Command::Solve(opts) => solve::run(opts),
        cli::Command::Eval(opts) => eval::run(opts),
        cli::Command::Export(opts) => export::run(opts),
        cli::Command::Status(opts) => status::run(opts),
        cli::Command::Synth(opts) => synth::run(opts),
        cli::Command::Demo(opts) => demo::run(opts),
        cli::Command::Replay(opts) => replay::run(opts),
        cli::Command::Run(opts) => run::run(opts),
        cli::Command::Recover(opts) => recover::run(opts),
        cli::Command::View(opts) => view::run(opts),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("slamd: {e:#}");
            ExitCode::from(2)
        }
    }
}
