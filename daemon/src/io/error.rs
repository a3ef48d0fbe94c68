//! [`ReadError`]: what went wrong reading a file, and where.

use crate::graph::GraphError;
use std::fmt;
use std::path::{Path, PathBuf};

/// A file that could not be read, with the line at fault when there is one.
#[derive(Debug)]
pub struct ReadError {
    /// The file.
    pub path: PathBuf,
    /// The 1-based line number, when the error belongs to a line.
    pub line: Option<usize>,
    /// What went wrong.
    pub kind: ReadErrorKind,
}

/// The reason behind a [`ReadError`].
#[derive(Debug)]
#[non_exhaustive]
pub enum ReadErrorKind {
    /// The file could not be opened or read.
    Io(std::io::Error),
    /// A line does not follow the format; the text says how.
    Malformed(String),
    /// The line is well formed but breaks the graph (unknown or duplicate id).
    Graph(GraphError),
    /// A saved map that cannot be read; the text names the file.
    Map(String),
}

impl ReadError {
    pub(crate) fn io(path: &Path, e: std::io::Error) -> Self {
        Self {
            path: path.to_owned(),
            line: None,
            kind: ReadErrorKind::Io(e),
        }
    }

    pub(crate) fn at(path: &Path, line: usize, kind: ReadErrorKind) -> Self {
        Self {
            path: path.to_owned(),
            line: Some(line),
            kind,
        }
    }

    pub(crate) fn graph(path: &Path, e: GraphError) -> Self {
        Self {
            path: path.to_owned(),
            line: None,
            kind: ReadErrorKind::Graph(e),
        }
    }
}

impl fmt::Display for ReadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let ReadErrorKind::Map(m) = &self.kind {
            return f.write_str(m);
        }
        write!(f, "{}", self.path.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        match &self.kind {
            ReadErrorKind::Io(e) => write!(f, ": {e}"),
            ReadErrorKind::Malformed(m) => write!(f, ": {m}"),
            ReadErrorKind::Graph(e) => write!(f, ": {e}"),
            ReadErrorKind::Map(_) => Ok(()),
        }
    }
}

/// No `source`: the message already ends with the cause's, and a chain
/// printed whole (`{:#}`) would say it twice.
impl std::error::Error for ReadError {}
