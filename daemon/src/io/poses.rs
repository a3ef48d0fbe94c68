//! Pose tables (`id x y θ` or `x y θ` per line in the plane,
//! `id x y z qx qy qz qw` or without the id in space) and ground truth.

use super::{numbers_into, read_graph, ReadError, ReadErrorKind};
use crate::geometry::Pose2;
use crate::graph::{KeyframeId, Pose3, RigidMotion};
use std::collections::HashMap;
use std::path::Path;

/// Reads a pose table: per line an id and the pose's
/// [`RigidMotion::PARAMS`] numbers (`id x y θ`; in space
/// `id x y z qx qy qz qw`), or the numbers alone where the id is the line's
/// position among the data lines. `#` starts a comment; commas separate
/// like spaces.
pub fn read_pose_table<P: RigidMotion>(path: &Path) -> Result<HashMap<KeyframeId, P>, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReadError::io(path, e))?;
    parse_pose_table(path, &text)
}

pub(crate) fn parse_pose_table<P: RigidMotion>(
    path: &Path,
    text: &str,
) -> Result<HashMap<KeyframeId, P>, ReadError> {
    let layout = if P::DIMENSION == 2 {
        "`id x y theta` or `x y theta`"
    } else {
        "`id x y z qx qy qz qw` or `x y z qx qy qz qw`"
    };
    let mut poses = HashMap::new();
    let mut row: KeyframeId = 0;
    let mut params = [0.0; 7];
    let params = &mut params[..P::PARAMS];
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
        let id = match tokens.len().checked_sub(P::PARAMS) {
            Some(0) => row,
            Some(1) => super::id(tokens[0], "pose").map_err(at)?,
            _ => {
                return Err(at(ReadErrorKind::Malformed(format!(
                    "pose line needs {layout}, found {} fields",
                    tokens.len()
                ))))
            }
        };
        numbers_into(&tokens[tokens.len() - P::PARAMS..], "pose", params).map_err(at)?;
        let pose = P::from_params(params).ok_or_else(|| {
            at(ReadErrorKind::Malformed(
                "pose: its quaternion is not of unit norm".into(),
            ))
        })?;
        if poses.insert(id, pose).is_some() {
            return Err(at(ReadErrorKind::Malformed(format!("duplicate pose id {id}"))));
        }
        row += 1;
    }
    Ok(poses)
}

/// A pose whose ground truth can be read from a noise-free graph file.
pub trait TruthPose: RigidMotion {
    /// The poses the noise-free graph file at `path` gives, keyed by
    /// keyframe id.
    fn truth_from_graph(path: &Path) -> Result<HashMap<KeyframeId, Self>, ReadError>;
}

/// Reads ground truth, in the plane and in space alike: a pose table
/// ([`read_pose_table`]'s layouts), or a noise-free graph file (its first
/// record starts with a tag): in the plane its edges composed along a
/// spanning tree from the first keyframe (odometry first); in space its
/// vertices where it has any, else its edges composed along a spanning
/// tree.
pub fn read_ground_truth<P: TruthPose>(path: &Path) -> Result<HashMap<KeyframeId, P>, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReadError::io(path, e))?;
    let first_tag = text
        .lines()
        .map(|l| l.split('#').next().unwrap_or("").trim())
        .find(|l| !l.is_empty())
        .and_then(|l| l.split_whitespace().next())
        .unwrap_or("");
    if first_tag.chars().next().is_some_and(|c| c.is_ascii_alphabetic()) {
        P::truth_from_graph(path)
    } else {
        parse_pose_table(path, &text)
    }
}

impl TruthPose for Pose2 {
    fn truth_from_graph(path: &Path) -> Result<HashMap<KeyframeId, Pose2>, ReadError> {
        let graph = read_graph(path)?;
        let poses = graph
            .compose_spanning_tree()
            .map_err(|e| ReadError::graph(path, e))?;
        Ok(by_id(&graph, poses))
    }
}

impl TruthPose for Pose3 {
    fn truth_from_graph(path: &Path) -> Result<HashMap<KeyframeId, Pose3>, ReadError> {
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
        let a = parse_pose_table::<Pose2>(p, "0 0 0 0\n1 1.5 0 0.1\n").unwrap();
        assert_eq!(a[&1], Pose2::new(1.5, 0.0, 0.1));
        let b = parse_pose_table::<Pose2>(p, "# x y t\n0 0 0\n2 0 0\n").unwrap();
        assert_eq!(b[&1], Pose2::new(2.0, 0.0, 0.0));
        let err = parse_pose_table::<Pose2>(p, "0 0 0\n1 2\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "gt.txt:2: pose line needs `id x y theta` or `x y theta`, found 2 fields"
        );
    }

    #[test]
    fn spatial_ground_truth_may_be_a_pose_table() {
        let path = std::env::temp_dir().join(format!("slamd-truth3-{}.txt", std::process::id()));
        std::fs::write(
            &path,
            "# id x y z qx qy qz qw\n0 0 0 0 0 0 0 1\n7 1 2 3 0 0 1 0\n",
        )
        .unwrap();
        let truth = read_ground_truth::<Pose3>(&path);
        std::fs::remove_file(&path).unwrap();
        let truth = truth.unwrap();
        assert_eq!(truth.len(), 2);
        assert_eq!(truth[&7].translation.as_slice(), &[1.0, 2.0, 3.0]);
        // a half turn about z: the quaternion (0, 0, 1, 0)
        let q = truth[&7].rotation;
        assert!((q.k - 1.0).abs() < 1e-15 && q.w.abs() < 1e-15, "{q:?}");
    }

    #[test]
    fn reads_spatial_tables_and_refuses_a_quaternion_off_unit_norm() {
        let p = Path::new("est.txt");
        let t = parse_pose_table::<Pose3>(p, "4 1 2 3 0 0 0.6 0.8\n").unwrap();
        let q = t[&4].rotation;
        assert_eq!(t[&4].translation.as_slice(), &[1.0, 2.0, 3.0]);
        assert!((q.k - 0.6).abs() < 1e-15 && (q.w - 0.8).abs() < 1e-15, "{q:?}");
        let err = parse_pose_table::<Pose3>(p, "0 0 0 0 0 0 0.5\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "est.txt:1: pose: its quaternion is not of unit norm"
        );
        let err = parse_pose_table::<Pose3>(p, "0 0 0 0\n").unwrap_err();
        assert_eq!(
            err.to_string(),
            "est.txt:1: pose line needs `id x y z qx qy qz qw` or `x y z qx qy qz qw`, found 4 fields"
        );
    }
}
