//! Reading the graph a command works on, strictly or skipping what would
//! be refused (`--skip-invalid`).

use clap::Args;
use slamd::graph::PoseGraph;
use slamd::io::{self, OnInvalid, ReadError};
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
pub struct Input {
    pub graph: PoseGraph,
    pub skipped: Vec<ReadError>,
}

impl Input {
    /// Reads `path` as `opts` say; skipped lines are reported on stderr
    /// unless `quiet`.
    pub fn read(path: &Path, opts: InputOpts, quiet: bool) -> Result<Self, ReadError> {
        let on_invalid = if opts.skip_invalid {
            OnInvalid::Skip
        } else {
            OnInvalid::Refuse
        };
        let (graph, skipped) = io::read_graph_with(path, on_invalid)?;
        let input = Self { graph, skipped };
        if !quiet && !input.skipped.is_empty() {
            eprintln!(
                "skipped {} invalid line(s) of {}:",
                input.skipped.len(),
                path.display()
            );
            for line in input.named() {
                eprintln!("  {line}");
            }
        }
        Ok(input)
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
