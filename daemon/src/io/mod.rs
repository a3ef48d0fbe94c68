//! Reading and writing pose graphs: g2o, TORO and iSAM files, pose tables,
//! and SVG pictures.
//!
//! Every reader reports a bad line as a [`ReadError`] naming the file, the
//! line and the reason. A non-finite number or an information matrix that is
//! not positive definite is an error, never a silent NaN.

mod error;
mod g2o;
mod gps_csv;
mod isam;
mod poses;
pub mod svg;
mod toro;
mod write;

pub use error::{ReadError, ReadErrorKind};
pub use gps_csv::{read_fixes, FixRecord};
pub use poses::{read_ground_truth, read_pose_table};
pub use write::{write_g2o, write_pose_table};

use crate::geometry::Pose2;
use crate::graph::{EdgeKind, GraphError, Information, Keyframe, KeyframeId, PoseGraph};
use std::collections::{BTreeSet, HashSet};
use std::path::Path;

/// The graph file formats slamd reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// g2o 2-D: `VERTEX_SE2 id x y θ`, `EDGE_SE2 i j dx dy dθ` + 6 information
    /// entries (upper triangle, row by row).
    G2o,
    /// TORO 2-D: `VERTEX2`, `EDGE2 i j dx dy dθ` + information in the order
    /// xx, xy, yy, θθ, xθ, yθ.
    Toro,
    /// iSAM: `EDGE2` or `ODOMETRY i j dx dy dθ` + the upper-triangular square
    /// root of the information matrix.
    Isam,
}

impl Format {
    /// Guesses the format from the extension, then from the first record.
    pub fn detect(path: &Path, text: &str) -> Format {
        match path.extension().and_then(|e| e.to_str()) {
            Some("g2o") => return Format::G2o,
            Some("graph") => return Format::Toro,
            _ => {}
        }
        let mut has_vertex2 = false;
        for tag in text.lines().filter_map(|l| l.split_whitespace().next()) {
            match tag {
                "VERTEX_SE2" | "EDGE_SE2" => return Format::G2o,
                "ODOMETRY" => return Format::Isam,
                "VERTEX2" => has_vertex2 = true,
                _ => {}
            }
        }
        if has_vertex2 {
            Format::Toro
        } else {
            Format::Isam
        }
    }
}

/// One parsed line of a graph file.
#[derive(Debug, PartialEq)]
pub(crate) enum Record {
    Vertex(KeyframeId, Pose2),
    Edge(KeyframeId, KeyframeId, Pose2, Information),
    Skip,
}

/// Reads a graph file, detecting its format.
pub fn read_graph(path: &Path) -> Result<PoseGraph, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReadError::io(path, e))?;
    let format = Format::detect(path, &text);
    parse_graph(path, &text, format)
}

/// Parses graph text of a known format. `path` only labels errors.
pub fn parse_graph(path: &Path, text: &str, format: Format) -> Result<PoseGraph, ReadError> {
    let parse_line = match format {
        Format::G2o => g2o::parse_line,
        Format::Toro => toro::parse_line,
        Format::Isam => isam::parse_line,
    };
    let mut vertices = Vec::new();
    let mut edges = Vec::new();
    for (n, line) in text.lines().enumerate() {
        let line_no = n + 1;
        let content = line.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let tokens: Vec<&str> = content.split_whitespace().collect();
        match parse_line(&tokens).map_err(|kind| ReadError::at(path, line_no, kind))? {
            Record::Vertex(id, pose) => vertices.push((line_no, id, pose)),
            Record::Edge(i, j, m, info) => edges.push((line_no, i, j, m, info)),
            Record::Skip => {}
        }
    }
    assemble(path, vertices, edges)
}

type VertexLine = (usize, KeyframeId, Pose2);
type EdgeLine = (usize, KeyframeId, KeyframeId, Pose2, Information);

/// Builds the graph. With `VERTEX` lines, an edge to an undeclared keyframe is
/// an error; without any, the keyframes are the edge end points.
fn assemble(path: &Path, vertices: Vec<VertexLine>, edges: Vec<EdgeLine>) -> Result<PoseGraph, ReadError> {
    let keyframes: Vec<Keyframe> = if vertices.is_empty() {
        let ids: BTreeSet<KeyframeId> = edges.iter().flat_map(|e| [e.1, e.2]).collect();
        ids.into_iter().map(|id| Keyframe { id, guess: None }).collect()
    } else {
        let mut seen = HashSet::new();
        for &(line, id, _) in &vertices {
            if !seen.insert(id) {
                return Err(ReadError::at(
                    path,
                    line,
                    ReadErrorKind::Graph(GraphError::DuplicateKeyframe(id)),
                ));
            }
        }
        vertices
            .iter()
            .map(|&(_, id, pose)| Keyframe {
                id,
                guess: Some(pose),
            })
            .collect()
    };
    let mut graph = PoseGraph::with_keyframes(keyframes).map_err(|e| ReadError::graph(path, e))?;
    for (line, i, j, m, info) in edges {
        graph
            .add_edge(i, j, m, info, EdgeKind::from_ids(i, j))
            .map_err(|e| ReadError::at(path, line, ReadErrorKind::Graph(e)))?;
    }
    Ok(graph)
}

/// Parses `n` finite numbers from `tokens`, naming the record on error.
pub(crate) fn numbers<const N: usize>(tokens: &[&str], record: &str) -> Result<[f64; N], ReadErrorKind> {
    if tokens.len() != N {
        return Err(ReadErrorKind::Malformed(format!(
            "{record} needs {N} numbers after the tag, found {}",
            tokens.len()
        )));
    }
    let mut out = [0.0; N];
    for (o, t) in out.iter_mut().zip(tokens) {
        let v: f64 = t
            .parse()
            .map_err(|_| ReadErrorKind::Malformed(format!("{record}: `{t}` is not a number")))?;
        if !v.is_finite() {
            return Err(ReadErrorKind::Malformed(format!(
                "{record}: non-finite number `{t}`"
            )));
        }
        *o = v;
    }
    Ok(out)
}

/// Parses a keyframe id.
pub(crate) fn id(token: &str, record: &str) -> Result<KeyframeId, ReadErrorKind> {
    token
        .parse()
        .map_err(|_| ReadErrorKind::Malformed(format!("{record}: `{token}` is not a keyframe id")))
}

/// The common shape of an edge record: `TAG i j dx dy dθ` + six numbers.
pub(crate) fn edge_record(
    tokens: &[&str],
    record: &str,
    info: impl Fn([f64; 6]) -> Result<Information, crate::graph::InformationError>,
) -> Result<Record, ReadErrorKind> {
    if tokens.len() != 12 {
        return Err(ReadErrorKind::Malformed(format!(
            "{record} needs 11 fields after the tag, found {}",
            tokens.len().saturating_sub(1)
        )));
    }
    let i = id(tokens[1], record)?;
    let j = id(tokens[2], record)?;
    let [dx, dy, dt, a, b, c, d, e, f] = numbers::<9>(&tokens[3..], record)?;
    let information =
        info([a, b, c, d, e, f]).map_err(|e| ReadErrorKind::Malformed(format!("{record}: {e}")))?;
    Ok(Record::Edge(i, j, Pose2::new(dx, dy, dt), information))
}

/// The common shape of a vertex record: `TAG id x y θ`.
pub(crate) fn vertex_record(tokens: &[&str], record: &str) -> Result<Record, ReadErrorKind> {
    if tokens.len() != 5 {
        return Err(ReadErrorKind::Malformed(format!(
            "{record} needs 4 fields after the tag, found {}",
            tokens.len().saturating_sub(1)
        )));
    }
    let id = id(tokens[1], record)?;
    let [x, y, t] = numbers::<3>(&tokens[2..], record)?;
    Ok(Record::Vertex(id, Pose2::new(x, y, t)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str, format: Format) -> Result<PoseGraph, ReadError> {
        parse_graph(Path::new("t.g2o"), text, format)
    }

    #[test]
    fn detects_formats() {
        assert_eq!(Format::detect(Path::new("a.g2o"), ""), Format::G2o);
        assert_eq!(Format::detect(Path::new("a.graph"), ""), Format::Toro);
        assert_eq!(
            Format::detect(Path::new("a.txt"), "EDGE2 0 1 1 0 0 1 0 0 1 0 1"),
            Format::Isam
        );
        assert_eq!(
            Format::detect(Path::new("a.txt"), "VERTEX2 0 0 0 0\n"),
            Format::Toro
        );
        assert_eq!(
            Format::detect(Path::new("a.txt"), "# c\nEDGE_SE2 0 1"),
            Format::G2o
        );
    }

    #[test]
    fn edges_only_files_take_keyframes_from_edges() {
        let g = parse(
            "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 2 1 1 0 0 1 0 0 1 0 1\n",
            Format::G2o,
        )
        .unwrap();
        assert_eq!(g.len(), 3);
        // newer-id-first: stored inverted
        let e = g.edges()[1];
        assert_eq!((e.from, e.to), (1, 2));
        assert_eq!(e.measurement, crate::geometry::Pose2::new(-1.0, 0.0, 0.0));
    }

    #[test]
    fn errors_name_file_line_and_reason() {
        let text = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0 0\n\nEDGE_SE2 0 1 1 0 nan 1 0 0 1 0 1\n";
        let err = parse(text, Format::G2o).unwrap_err();
        assert_eq!(err.line, Some(4));
        assert_eq!(err.to_string(), "t.g2o:4: EDGE_SE2: non-finite number `nan`");

        let err = parse(
            "VERTEX_SE2 0 0 0 0\nEDGE_SE2 0 5 1 0 0 1 0 0 1 0 1\n",
            Format::G2o,
        )
        .unwrap_err();
        assert_eq!(err.to_string(), "t.g2o:2: edge refers to unknown keyframe 5");

        let err = parse("VERTEX_SE2 0 0 0 0\nVERTEX_SE2 0 1 0 0\n", Format::G2o).unwrap_err();
        assert_eq!(err.to_string(), "t.g2o:2: duplicate keyframe id 0");

        let err = parse("EDGE_SE2 0 1 1 0 0 1 0 0 -1 0 1\n", Format::G2o).unwrap_err();
        assert_eq!(
            err.to_string(),
            "t.g2o:1: EDGE_SE2: information matrix is not positive definite"
        );

        let err = parse("EDGE_SE2 0 1 1 0 0 1 0 0 1 0\n", Format::G2o).unwrap_err();
        assert_eq!(
            err.to_string(),
            "t.g2o:1: EDGE_SE2 needs 11 fields after the tag, found 10"
        );

        let err = parse("EDGE_SE2 0 x 1 0 0 1 0 0 1 0 1\n", Format::G2o).unwrap_err();
        assert_eq!(err.to_string(), "t.g2o:1: EDGE_SE2: `x` is not a keyframe id");

        let err = parse("EDGE_SE2 0 0 1 0 0 1 0 0 1 0 1\n", Format::G2o).unwrap_err();
        assert_eq!(err.to_string(), "t.g2o:1: edge from keyframe 0 to itself");
    }

    #[test]
    fn comments_and_blank_lines_are_skipped() {
        let g = parse(
            "# header\n\nEDGE_SE2 0 1 1 0 0 1 0 0 1 0 1 # trailing\n",
            Format::G2o,
        )
        .unwrap();
        assert_eq!(g.edges().len(), 1);
    }
}
