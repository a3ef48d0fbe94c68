//! The `slamd` command: run the daemon, solve or replay a graph, demo.

mod cli;
mod demo;
mod eval;
mod solve;
mod synth;

use clap::Parser;
use std::process::ExitCode;

fn main() -> ExitCode {
    let cli = cli::Cli::parse();
    let result = match cli.command {
        cli::Command::Solve(opts) => solve::run(opts),
        cli::Command::Eval(opts) => eval::run(opts),
        cli::Command::Synth(opts) => synth::run(opts),
        cli::Command::Demo(opts) => demo::run(opts),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("slamd: {e:#}");
            ExitCode::from(2)
        }
    }
}
