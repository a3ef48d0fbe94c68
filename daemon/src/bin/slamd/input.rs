//! Reading the graph a command works on, strictly or skipping what would
//! be refused (`--skip-invalid`).

use clap::Args;
use slamd::graph::PoseGraph;
use slamd::io::{self, AnyGraph, OnInvalid, ReadError};
use std::path::Path;

/// How many skipped lines a report names.
const NAMED: usize = 5;

#[derive(Args, Debug, Clone, Copy, Default)]
pub struct InputOpts {
    /// Skip what would refuse the file (an edge from a keyframe to itself,
    /// an information that is not positive definite, a repeated vertex, a
    /// malformed line) and report how many lines and the first few.
    #[arg(long)]
    pub skip_invalid: bool,
}

/// A graph and the lines left out of it.
pub struct Input<G = PoseGraph> {
    pub graph: G,
    pub skipped: Vec<ReadError>,
}

/// How `opts` treat a line that would refuse the file.
fn on_invalid(opts: InputOpts) -> OnInvalid {
    if opts.skip_invalid {
        OnInvalid::Skip
    } else {
        OnInvalid::Refuse
    }
}

impl Input<AnyGraph> {
    /// Reads `path`, 2-D or 3-D, as `opts` say; skipped lines are reported
    /// on stderr unless `quiet`.
    pub fn read_any(path: &Path, opts: InputOpts, quiet: bool) -> Result<Self, ReadError> {
        let (graph, skipped) = io::read_any_graph_with(path, on_invalid(opts))?;
        let input = Self { graph, skipped };
        input.report(path, quiet);
        Ok(input)
    }
}

impl<G> Input<G> {
    /// Reports the skipped lines on stderr unless `quiet`.
    fn report(&self, path: &Path, quiet: bool) {
        if !quiet && !self.skipped.is_empty() {
            eprintln!(
                "skipped {} invalid line(s) of {}:",
                self.skipped.len(),
                path.display()
            );
            for line in self.named() {
                eprintln!("  {line}");
            }
        }
    }

    /// The first skipped lines, as `file:line: reason`.
    pub fn named(&self) -> Vec<String> {
        self.skipped.iter().take(NAMED).map(|e| e.to_string()).collect()
    }

    /// The skipped lines for a JSON report: their count and the first few.
    pub fn json(&self) -> serde_json::Value {
        serde_json::json!({ "count": self.skipped.len(), "first": self.named() })
    }
}
