//! Reading a whole graph file: its format and dimension detected, a saved
//! map read too, into a graph of a known dimension ([`read_graph`]) or of
//! either ([`read_any_graph_with`]).

use super::{parse_graph3_with, parse_graph_with, Dimension, Format, OnInvalid, ReadError, ReadErrorKind};
use crate::geometry::Pose2;
use crate::graph::{Pose3, PoseGraph, RigidMotion};
use crate::store::MapFile;
use std::path::Path;

/// Reads a graph file of dimension `P` (a [`Pose2`] or [`Pose3`] graph),
/// detecting its format; refuses it with the first line that does not
/// parse, else the first that breaks the graph, and a file of the other
/// dimension.
pub fn read_graph<P: FilePose>(path: &Path) -> Result<PoseGraph<P>, ReadError> {
    let (any, _) = read_any_graph_with(path, OnInvalid::Refuse)?;
    P::of(any).map_err(|other| ReadError {
        path: path.to_owned(),
        line: None,
        kind: ReadErrorKind::Malformed(format!(
            "a {}-D pose graph where a {}-D one is needed",
            other.dimension(),
            P::DIMENSION
        )),
    })
}

/// A pose type whose graphs files hold: [`read_graph`] reads them.
pub trait FilePose: RigidMotion {
    /// The graph `any` holds when it is of this dimension, else `any`.
    fn of(any: AnyGraph) -> Result<PoseGraph<Self>, AnyGraph>;
}

impl FilePose for Pose2 {
    fn of(any: AnyGraph) -> Result<PoseGraph<Self>, AnyGraph> {
        match any {
            AnyGraph::Planar(g) => Ok(g),
            other => Err(other),
        }
    }
}

impl FilePose for Pose3 {
    fn of(any: AnyGraph) -> Result<PoseGraph<Self>, AnyGraph> {
        match any {
            AnyGraph::Spatial(g) => Ok(g),
            other => Err(other),
        }
    }
}

/// Reads a graph file, detecting its format. Returns the graph and, with
/// [`OnInvalid::Skip`], the lines left out, in file order. A file that
/// cannot be read is an error either way.
///
/// A saved map (`slamd run --state`'s `map` file) is read too: its
/// keyframes at their saved estimate and all its edges.
pub fn read_graph_with(path: &Path, on_invalid: OnInvalid) -> Result<(PoseGraph, Vec<ReadError>), ReadError> {
    let bytes = std::fs::read(path).map_err(|e| ReadError::io(path, e))?;
    if MapFile::sniff(&bytes) {
        let map = MapFile::decode(path, &bytes).map_err(|e| ReadError {
            path: path.to_owned(),
            line: None,
            kind: ReadErrorKind::Map(e.to_string()),
        })?;
        let graph = map.graph().map_err(|e| ReadError::graph(path, e))?;
        return Ok((graph, Vec::new()));
    }
    let text = String::from_utf8(bytes)
        .map_err(|e| ReadError::io(path, std::io::Error::new(std::io::ErrorKind::InvalidData, e)))?;
    let format = Format::detect(path, &text);
    if format.dimension() == Dimension::Spatial {
        return Err(ReadError {
            path: path.to_owned(),
            line: None,
            kind: ReadErrorKind::Malformed(
                "a 3-D pose graph; this command works on 2-D graphs (`slamd solve`, `slamd eval` and `slamd replay --embedded` read both)".into(),
            ),
        });
    }
    parse_graph_with(path, &text, format, on_invalid)
}

/// A pose graph of either dimension, as read from a file.
#[derive(Clone, Debug)]
pub enum AnyGraph {
    /// A 2-D graph.
    Planar(PoseGraph),
    /// A 3-D graph.
    Spatial(PoseGraph<Pose3>),
}

impl AnyGraph {
    /// 2 or 3.
    pub fn dimension(&self) -> u32 {
        match self {
            AnyGraph::Planar(_) => 2,
            AnyGraph::Spatial(_) => 3,
        }
    }
}

/// Reads a graph file of either dimension, detecting its format; with
/// [`OnInvalid::Skip`] returns the lines left out.
pub fn read_any_graph_with(
    path: &Path,
    on_invalid: OnInvalid,
) -> Result<(AnyGraph, Vec<ReadError>), ReadError> {
    let bytes = std::fs::read(path).map_err(|e| ReadError::io(path, e))?;
    if MapFile::sniff(&bytes) {
        let map_error = |e: crate::store::StoreError| ReadError {
            path: path.to_owned(),
            line: None,
            kind: ReadErrorKind::Map(e.to_string()),
        };
        return match MapFile::<Pose2>::decode(path, &bytes) {
            Ok(map) => map.graph().map(AnyGraph::Planar),
            Err(crate::store::StoreError::Dimension { .. }) => {
                let map = MapFile::<Pose3>::decode(path, &bytes).map_err(map_error)?;
                map.graph().map(AnyGraph::Spatial)
            }
            Err(e) => return Err(map_error(e)),
        }
        .map(|g| (g, Vec::new()))
        .map_err(|e| ReadError::graph(path, e));
    }
    let text = String::from_utf8(bytes)
        .map_err(|e| ReadError::io(path, std::io::Error::new(std::io::ErrorKind::InvalidData, e)))?;
    let format = Format::detect(path, &text);
    match format.dimension() {
        Dimension::Planar => {
            parse_graph_with(path, &text, format, on_invalid).map(|(g, s)| (AnyGraph::Planar(g), s))
        }
        Dimension::Spatial => {
            parse_graph3_with(path, &text, format, on_invalid).map(|(g, s)| (AnyGraph::Spatial(g), s))
        }
    }
}
