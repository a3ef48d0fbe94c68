//! Pose tables (`id x y θ` or `x y θ` per line) and ground truth.

use super::{numbers, read_graph, ReadError, ReadErrorKind};
use crate::geometry::Pose2;
use crate::graph::{KeyframeId, Pose3, RigidMotion};
use std::collections::HashMap;
use std::path::Path;

/// Reads a pose table: `id x y θ` per line, or `x y θ` where the id is the
/// line's position among the data lines. `#` starts a comment.
pub fn read_pose_table(path: &Path) -> Result<HashMap<KeyframeId, Pose2>, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReadError::io(path, e))?;
    parse_pose_table(path, &text)
}

pub(crate) fn parse_pose_table(path: &Path, text: &str) -> Result<HashMap<KeyframeId, Pose2>, ReadError> {
    let mut poses = HashMap::new();
    let mut row: KeyframeId = 0;
    for (n, line) in text.lines().enumerate() {
        let content = line.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let tokens: Vec<&str> = content
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
            .collect();
        let at = |kind| ReadError::at(path, n + 1, kind);
        let (id, xyz) = match tokens.len() {
            3 => (row, numbers::<3>(&tokens, "pose").map_err(at)?),
            4 => {
                let id = super::id(tokens[0], "pose").map_err(at)?;
                (id, numbers::<3>(&tokens[1..], "pose").map_err(at)?)
            }
            k => {
                return Err(at(ReadErrorKind::Malformed(format!(
                    "pose line needs `id x y theta` or `x y theta`, found {k} fields"
                ))))
            }
        };
        if poses.insert(id, Pose2::new(xyz[0], xyz[1], xyz[2])).is_some() {
            return Err(at(ReadErrorKind::Malformed(format!("duplicate pose id {id}"))));
        }
        row += 1;
    }
    Ok(poses)
}

/// A pose whose ground truth can be read.
pub trait TruthPose: RigidMotion {
    /// The truth in the file at `path`, keyed by keyframe id.
    fn read_ground_truth(path: &Path) -> Result<HashMap<KeyframeId, Self>, ReadError>;
}

/// Reads ground truth: in the plane a pose table, or a noise-free graph
/// file whose edges are composed along a spanning tree from the first
/// keyframe (odometry first); in space a noise-free 3-D graph file, its
/// vertices where it has any, else its edges composed along a spanning
/// tree.
pub fn read_ground_truth<P: TruthPose>(path: &Path) -> Result<HashMap<KeyframeId, P>, ReadError> {
    P::read_ground_truth(path)
}

impl TruthPose for Pose2 {
    fn read_ground_truth(path: &Path) -> Result<HashMap<KeyframeId, Pose2>, ReadError> {
        let text = std::fs::read_to_string(path).map_err(|e| ReadError::io(path, e))?;
        let first_tag = text
            .lines()
            .map(|l| l.split('#').next().unwrap_or("").trim())
            .find(|l| !l.is_empty())
            .and_then(|l| l.split_whitespace().next())
            .unwrap_or("");
        if first_tag.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) {
            let graph = read_graph(path)?;
            let poses = graph
                .compose_spanning_tree()
                .map_err(|e| ReadError::graph(path, e))?;
            Ok(by_id(&graph, poses))
        } else {
            parse_pose_table(path, &text)
        }
    }
}

impl TruthPose for Pose3 {
    fn read_ground_truth(path: &Path) -> Result<HashMap<KeyframeId, Pose3>, ReadError> {
        let graph = super::read_graph::<Pose3>(path)?;
        let poses = graph.initial_guess().map_err(|e| ReadError::graph(path, e))?;
        Ok(by_id(&graph, poses))
    }
}

/// `poses` (indexed like `graph`'s keyframes) keyed by keyframe id.
fn by_id<P: RigidMotion>(graph: &crate::graph::PoseGraph<P>, poses: Vec<P>) -> HashMap<KeyframeId, P> {
    graph
        .keyframes()
        .iter()
        .zip(poses)
        .map(|(k, p)| (k.id, p))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_both_table_layouts() {
        let p = Path::new("gt.txt");
        let a = parse_pose_table(p, "0 0 0 0\n1 1.5 0 0.1\n").unwrap();
        assert_eq!(a[&1], Pose2::new(1.5, 0.0, 0.1));
        let b = parse_pose_table(p, "# x y t\n0 0 0\n2 0 0\n").unwrap();
        assert_eq!(b[&1], Pose2::new(2.0, 0.0, 0.0));
        let err = parse_pose_table(p, "0 0 0\n1 2\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "gt.txt:2: pose line needs `id x y theta` or `x y theta`, found 2 fields"
        );
    }
}
