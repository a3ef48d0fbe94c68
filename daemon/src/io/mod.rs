//! Reading and writing pose graphs: g2o, TORO and iSAM files (and saved
//! maps), pose tables, and SVG pictures.
//!
//! Every reader reports a bad line as a [`ReadError`] naming the file, the
//! line and the reason. A non-finite number or an information matrix that is
//! not positive definite is an error, never a silent NaN. Real files are
//! imperfect: with [`OnInvalid::Skip`] a graph reader leaves such lines out
//! and returns them, and the rest of the file is read as usual.

mod error;
mod g2o;
mod gps_csv;
mod graph_file;
mod isam;
mod poses;
mod spatial;
#[cfg(feature = "svg")]
pub mod svg;
mod toro;
mod trajectory;
mod write;

pub use error::{ReadError, ReadErrorKind};
pub use gps_csv::{read_fixes, FixRecord};
pub use graph_file::{read_any_graph_with, read_graph, read_graph_with, AnyGraph, FilePose};
pub use poses::{read_ground_truth, read_pose_table, TruthPose};
pub use trajectory::{read_trajectory, write_trajectory, write_trajectory_at, FromSpatial, Trajectory};
pub use write::{write_g2o, write_pose_table, G2oPose};

use crate::geometry::Pose2;
use crate::graph::{EdgeKind, GraphError, Information, Keyframe, KeyframeId, Pose3, PoseGraph, RigidMotion};
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
    /// g2o 3-D: `VERTEX_SE3:QUAT id x y z qx qy qz qw`,
    /// `EDGE_SE3:QUAT i j x y z qx qy qz qw` + 21 information entries
    /// (upper triangle, row by row, over x y z qx qy qz).
    G2o3,
    /// HOG-Man 3-D: `VERTEX3 id x y z roll pitch yaw`,
    /// `EDGE3 i j x y z roll pitch yaw` + 21 information entries over
    /// x y z roll pitch yaw.
    HogMan3,
    /// iSAM 3-D: `EDGE3 i j x y z roll pitch yaw` + 21 entries of the
    /// upper-triangular square root of the information, no vertices.
    Isam3,
}

/// Whether a graph is planar or spatial.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Dimension {
    /// SE(2): `(x, y, θ)` poses.
    #[serde(rename = "2d")]
    Planar,
    /// SE(3): position and quaternion.
    #[serde(rename = "3d")]
    Spatial,
}

impl Format {
    /// Whether the format holds planar or spatial graphs.
    pub fn dimension(self) -> Dimension {
        match self {
            Format::G2o | Format::Toro | Format::Isam => Dimension::Planar,
            Format::G2o3 | Format::HogMan3 | Format::Isam3 => Dimension::Spatial,
        }
    }

    /// Guesses the format: a 3-D record decides first (`EDGE3` is HOG-Man's
    /// in a `.graph` file or beside `VERTEX3` lines, else iSAM's), then the
    /// extension, then the first 2-D record.
    pub fn detect(path: &Path, text: &str) -> Format {
        let ext = path.extension().and_then(|e| e.to_str());
        let mut edge3 = false;
        for tag in text
            .lines()
            .take(4096)
            .filter_map(|l| l.split_whitespace().next())
        {
            match tag {
                "VERTEX_SE3:QUAT" | "EDGE_SE3:QUAT" => return Format::G2o3,
                "VERTEX3" => return Format::HogMan3,
                "EDGE3" if ext == Some("graph") => return Format::HogMan3,
                "EDGE3" => edge3 = true,
                "VERTEX_SE2" | "EDGE_SE2" | "VERTEX2" | "EDGE2" | "ODOMETRY" => break,
                _ => {}
            }
        }
        if edge3 {
            return Format::Isam3;
        }
        match ext {
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
pub(crate) enum Record<P: RigidMotion = Pose2> {
    Vertex(KeyframeId, P),
    Edge(KeyframeId, KeyframeId, P, P::Information),
    Skip,
}

/// What a graph reader does with a line it would refuse: a malformed line,
/// a non-finite number, an information matrix that is not positive
/// definite, an edge from a keyframe to itself or to an undeclared one, a
/// repeated vertex.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OnInvalid {
    /// The file is refused at the first such line.
    #[default]
    Refuse,
    /// The line is left out and reported; the first of repeated vertices
    /// stays.
    Skip,
}

/// Parses 3-D graph text of a known format. `path` only labels errors.
pub fn parse_graph3_with(
    path: &Path,
    text: &str,
    format: Format,
    on_invalid: OnInvalid,
) -> Result<(PoseGraph<Pose3>, Vec<ReadError>), ReadError> {
    let parse_line = match format {
        Format::G2o3 => spatial::parse_g2o,
        Format::HogMan3 => spatial::parse_hogman,
        Format::Isam3 => spatial::parse_isam,
        Format::G2o | Format::Toro | Format::Isam => {
            return Err(ReadError {
                path: path.to_owned(),
                line: None,
                kind: ReadErrorKind::Malformed("a 2-D pose graph where a 3-D one is needed".into()),
            })
        }
    };
    parse_records(path, text, parse_line, on_invalid)
}

/// Parses graph text of a known format. `path` only labels errors.
pub fn parse_graph(path: &Path, text: &str, format: Format) -> Result<PoseGraph, ReadError> {
    parse_graph_with(path, text, format, OnInvalid::Refuse).map(|(graph, _)| graph)
}

/// [`parse_graph`], leaving out bad lines with [`OnInvalid::Skip`] and
/// returning them.
pub fn parse_graph_with(
    path: &Path,
    text: &str,
    format: Format,
    on_invalid: OnInvalid,
) -> Result<(PoseGraph, Vec<ReadError>), ReadError> {
    let parse_line = match format {
        Format::G2o => g2o::parse_line,
        Format::Toro => toro::parse_line,
        Format::Isam => isam::parse_line,
        Format::G2o3 | Format::HogMan3 | Format::Isam3 => {
            return Err(ReadError {
                path: path.to_owned(),
                line: None,
                kind: ReadErrorKind::Malformed("a 3-D pose graph where a 2-D one is needed".into()),
            })
        }
    };
    parse_records(path, text, parse_line, on_invalid)
}

/// Parses every line with `parse_line` and builds the graph.
fn parse_records<P: RigidMotion>(
    path: &Path,
    text: &str,
    parse_line: fn(&[&str]) -> Result<Record<P>, ReadErrorKind>,
    on_invalid: OnInvalid,
) -> Result<(PoseGraph<P>, Vec<ReadError>), ReadError> {
    let mut bad = Invalid {
        on_invalid,
        skipped: Vec::new(),
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
        match parse_line(&tokens) {
            Ok(Record::Vertex(id, pose)) => vertices.push((line_no, id, pose)),
            Ok(Record::Edge(i, j, m, info)) => edges.push((line_no, i, j, m, info)),
            Ok(Record::Skip) => {}
            Err(kind) => bad.line(ReadError::at(path, line_no, kind))?,
        }
    }
    let graph = assemble(path, vertices, edges, &mut bad)?;
    bad.skipped.sort_by_key(|e| e.line);
    Ok((graph, bad.skipped))
}

/// Bad lines: refused, or collected.
struct Invalid {
    on_invalid: OnInvalid,
    skipped: Vec<ReadError>,
}

impl Invalid {
    /// Refuses the file with `e`, or records the line and goes on.
    fn line(&mut self, e: ReadError) -> Result<(), ReadError> {
        match self.on_invalid {
            OnInvalid::Refuse => Err(e),
            OnInvalid::Skip => {
                self.skipped.push(e);
                Ok(())
            }
        }
    }
}

type VertexLine<P> = (usize, KeyframeId, P);
type EdgeLine<P> = (usize, KeyframeId, KeyframeId, P, <P as RigidMotion>::Information);

/// Builds the graph. With `VERTEX` lines, an edge to an undeclared keyframe is
/// an error; without any, the keyframes are the edge end points.
fn assemble<P: RigidMotion>(
    path: &Path,
    vertices: Vec<VertexLine<P>>,
    edges: Vec<EdgeLine<P>>,
    bad: &mut Invalid,
) -> Result<PoseGraph<P>, ReadError> {
    let keyframes: Vec<Keyframe<P>> = if vertices.is_empty() {
        // a skipped self-edge does not declare its keyframe
        let skips = bad.on_invalid == OnInvalid::Skip;
        let ids: BTreeSet<KeyframeId> = (edges.iter())
            .filter(|e| !(skips && e.1 == e.2))
            .flat_map(|e| [e.1, e.2])
            .collect();
        ids.into_iter().map(|id| Keyframe { id, guess: None }).collect()
    } else {
        let mut seen = HashSet::new();
        let mut kept = Vec::with_capacity(vertices.len());
        for &(line, id, pose) in &vertices {
            if seen.insert(id) {
                kept.push(Keyframe {
                    id,
                    guess: Some(pose),
                });
            } else {
                let e = ReadErrorKind::Graph(GraphError::DuplicateKeyframe(id));
                bad.line(ReadError::at(path, line, e))?;
            }
        }
        kept
    };
    let mut graph = PoseGraph::with_keyframes(keyframes).map_err(|e| ReadError::graph(path, e))?;
    for (line, i, j, m, info) in edges {
        if let Err(e) = graph.add_edge(i, j, m, info, EdgeKind::from_ids(i, j)) {
            bad.line(ReadError::at(path, line, ReadErrorKind::Graph(e)))?;
        }
    }
    Ok(graph)
}

/// Parses `n` finite numbers from `tokens`, naming the record on error.
pub(crate) fn numbers<const N: usize>(tokens: &[&str], record: &str) -> Result<[f64; N], ReadErrorKind> {
    let mut out = [0.0; N];
    numbers_into(tokens, record, &mut out)?;
    Ok(out)
}

/// [`numbers`] into `out`, as many as it holds.
pub(crate) fn numbers_into(tokens: &[&str], record: &str, out: &mut [f64]) -> Result<(), ReadErrorKind> {
    if tokens.len() != out.len() {
        return Err(ReadErrorKind::Malformed(format!(
            "{record} needs {} numbers after the tag, found {}",
            out.len(),
            tokens.len()
        )));
    }
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
    Ok(())
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
        // newer-id-first: kept as written
        let e = g.edges()[1];
        assert_eq!((e.from, e.to), (2, 1));
        assert_eq!(e.measurement, crate::geometry::Pose2::new(1.0, 0.0, 0.0));
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

    /// What `--skip-invalid` leaves out: each line that would be refused,
    /// with its number and reason, in file order; the rest is read.
    #[test]
    fn skipping_leaves_out_exactly_the_lines_that_would_be_refused() {
        let text = "VERTEX_SE2 0 0 0 0\n\
                    VERTEX_SE2 1 1 0 0\n\
                    VERTEX_SE2 1 9 9 9\n\
                    VERTEX_SE2 2 2 0 0\n\
                    EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n\
                    EDGE_SE2 1 1 0 0 0 1 0 0 1 0 1\n\
                    EDGE_SE2 1 2 1 0 0 1 0 0 -1 0 1\n\
                    EDGE_SE2 1 2 1 0 0 1 0 0 1 0 1\n\
                    EDGE_SE2 2 7 1 0 0 1 0 0 1 0 1\n\
                    EDGE_SE2 0 2 2 0 0 1 0 0 1 0\n";
        let refused = parse(text, Format::G2o).unwrap_err();
        // refused at the first line that does not parse (the graph's own
        // checks come after every line parsed)
        assert_eq!(
            refused.to_string(),
            "t.g2o:7: EDGE_SE2: information matrix is not positive definite"
        );
        let (g, skipped) = parse_graph_with(Path::new("t.g2o"), text, Format::G2o, OnInvalid::Skip).unwrap();
        let lines: Vec<String> = skipped.iter().map(|e| e.to_string()).collect();
        assert_eq!(
            lines,
            [
                "t.g2o:3: duplicate keyframe id 1",
                "t.g2o:6: edge from keyframe 1 to itself",
                "t.g2o:7: EDGE_SE2: information matrix is not positive definite",
                "t.g2o:9: edge refers to unknown keyframe 7",
                "t.g2o:10: EDGE_SE2 needs 11 fields after the tag, found 10",
            ]
        );
        // the first of the repeated vertices stays; two good edges remain
        assert_eq!(g.len(), 3);
        assert_eq!(g.keyframes()[1].guess, Some(Pose2::new(1.0, 0.0, 0.0)));
        assert_eq!(g.edges().len(), 2);
        // a clean file skips nothing
        let clean = "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\n";
        let (_, none) = parse_graph_with(Path::new("t.g2o"), clean, Format::G2o, OnInvalid::Skip).unwrap();
        assert!(none.is_empty());
    }

    /// Without vertex lines, a skipped self-edge declares no keyframe.
    #[test]
    fn a_skipped_self_edge_declares_no_keyframe() {
        let text = "EDGE_SE2 0 1 1 0 0 1 0 0 1 0 1\nEDGE_SE2 5 5 0 0 0 1 0 0 1 0 1\n";
        let (g, skipped) = parse_graph_with(Path::new("t.g2o"), text, Format::G2o, OnInvalid::Skip).unwrap();
        assert_eq!(g.len(), 2);
        assert_eq!(skipped.len(), 1);
        assert_eq!(skipped[0].line, Some(2));
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
