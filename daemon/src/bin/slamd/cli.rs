//! The command line: one subcommand per mode, each in its own file.

use clap::{Parser, Subcommand};

/// slamd: a streaming pose-graph SLAM backend.
#[derive(Parser, Debug)]
#[command(name = "slamd", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Run the daemon: serve frontends over shared memory until SIGINT or SIGTERM.
    Run(crate::run::RunOpts),
    /// Solve a whole graph file at once and report χ², ATE and time.
    Solve(crate::solve::SolveOpts),
    /// Run the demo: solve the built-in synthetic world and draw its map.
    Demo(crate::demo::DemoOpts),
    /// Write the built-in synthetic world as a g2o file plus ground truth.
    Synth(crate::synth::SynthOpts),
    /// Stream a graph file in time order and report per-keyframe latency.
    Replay(crate::replay::ReplayOpts),
    /// Score a pose table on a graph: χ² and ATE, as `solve` computes them.
    Eval(crate::eval::EvalOpts),
    /// Write a saved map (a state directory's `map`) as a g2o graph.
    Export(crate::export::ExportOpts),
    /// Show a running daemon's health: map, input, snapshot, latency, journal.
    Status(crate::status::StatusOpts),
    /// Keep every journal record that can be verified after corruption.
    Recover(crate::recover::RecoverOpts),
    /// Watch a running daemon's map live: Foxglove, a page in any browser, an MCAP recording.
    View(crate::view::ViewOpts),
}
