//! Trajectories as evo and the benchmarks' tools read them: TUM (one
//! `t x y z qx qy qz qw` line per keyframe) and KITTI (one line per
//! keyframe: the 3×4 matrix `[R | t]` row by row).
//!
//! A TUM line's time is the keyframe's timestamp in seconds when every
//! keyframe written has one (a saved map keeps them), else the keyframe's
//! id (graph files carry no timestamps); a KITTI line has no key at all, so line `k`
//! is the graph's `k`-th keyframe. A planar pose is written with `z = 0` and the rotation by θ
//! about z, and read back as `(x, y, yaw)`.

use super::{ReadError, ReadErrorKind};
use crate::geometry::Pose2;
use crate::graph::{KeyframeId, Pose3, RigidMotion};
use nalgebra::{Matrix3, Quaternion, Rotation3, UnitQuaternion, Vector3};
use std::collections::HashMap;
use std::io::Write;
use std::path::Path;

/// A trajectory file's layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trajectory {
    /// `t x y z qx qy qz qw`.
    Tum,
    /// `r00 r01 r02 tx r10 r11 r12 ty r20 r21 r22 tz`.
    Kitti,
}

impl Trajectory {
    /// The layout a file's extension names (`.tum`, `.kitti`), if any.
    pub fn of(path: &Path) -> Option<Self> {
        match path.extension()?.to_str()? {
            "tum" => Some(Self::Tum),
            "kitti" => Some(Self::Kitti),
            _ => None,
        }
    }
}

/// A pose read from a spatial one: itself in space, `(x, y, yaw)` in the
/// plane.
pub trait FromSpatial: RigidMotion {
    /// The pose `p` stands for.
    fn from_spatial(p: &Pose3) -> Self;
}

impl FromSpatial for Pose2 {
    fn from_spatial(p: &Pose3) -> Pose2 {
        Pose2::new(p.translation.x, p.translation.y, p.heading())
    }
}

impl FromSpatial for Pose3 {
    fn from_spatial(p: &Pose3) -> Pose3 {
        *p
    }
}

/// Writes `poses` (of the keyframes `ids`, in order) as `layout`.
pub fn write_trajectory<P: RigidMotion>(
    out: &mut impl Write,
    layout: Trajectory,
    ids: &[KeyframeId],
    poses: &[P],
) -> std::io::Result<()> {
    write_trajectory_at(out, layout, ids, &[], poses)
}

/// [`write_trajectory`] with each keyframe's timestamp (ns; 0 or missing:
/// none): a TUM line's time is the timestamp in seconds when every
/// keyframe has one, else every line's time is the keyframe's id (one
/// file never mixes the two clocks).
pub fn write_trajectory_at<P: RigidMotion>(
    out: &mut impl Write,
    layout: Trajectory,
    ids: &[KeyframeId],
    timestamps: &[u64],
    poses: &[P],
) -> std::io::Result<()> {
    let stamped = ids.len() <= timestamps.len() && timestamps[..ids.len()].iter().all(|&t| t != 0);
    for (k, (id, p)) in ids.iter().zip(poses).enumerate() {
        let [x, y, z] = p.position3();
        let [qx, qy, qz, qw] = p.orientation();
        match layout {
            Trajectory::Tum => match if stamped { timestamps[k] } else { 0 } {
                0 => writeln!(out, "{id} {x} {y} {z} {qx} {qy} {qz} {qw}")?,
                t => writeln!(
                    out,
                    "{}.{:09} {x} {y} {z} {qx} {qy} {qz} {qw}",
                    t / 1_000_000_000,
                    t % 1_000_000_000
                )?,
            },
            Trajectory::Kitti => {
                let q = UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz));
                let r = q.to_rotation_matrix();
                let m = r.matrix();
                let t = [x, y, z];
                let row = |i: usize| format!("{} {} {} {}", m[(i, 0)], m[(i, 1)], m[(i, 2)], t[i]);
                writeln!(out, "{} {} {}", row(0), row(1), row(2))?;
            }
        }
    }
    Ok(())
}

/// Reads a trajectory of the keyframes `ids` (a KITTI file's order); TUM
/// times must be keyframe ids. Every line is checked: numbers, a unit
/// quaternion or a rotation matrix, a known keyframe.
pub fn read_trajectory<P: FromSpatial>(
    path: &Path,
    layout: Trajectory,
    ids: &[KeyframeId],
) -> Result<HashMap<KeyframeId, P>, ReadError> {
    let text = std::fs::read_to_string(path).map_err(|e| ReadError::io(path, e))?;
    parse_trajectory(path, &text, layout, ids)
}

pub(crate) fn parse_trajectory<P: FromSpatial>(
    path: &Path,
    text: &str,
    layout: Trajectory,
    ids: &[KeyframeId],
) -> Result<HashMap<KeyframeId, P>, ReadError> {
    let known: std::collections::HashSet<KeyframeId> = ids.iter().copied().collect();
    let mut poses = HashMap::new();
    let mut row = 0;
    for (n, line) in text.lines().enumerate() {
        let content = line.trim();
        if content.is_empty() || content.starts_with('#') {
            continue;
        }
        let bad = |why: String| ReadError::at(path, n + 1, ReadErrorKind::Malformed(why));
        let tokens: Vec<&str> = content.split_whitespace().collect();
        let (id, pose) = match layout {
            Trajectory::Tum => {
                let v =
                    super::numbers::<8>(&tokens, "TUM pose").map_err(|k| ReadError::at(path, n + 1, k))?;
                let id = v[0] as KeyframeId;
                if v[0] < 0.0 || id as f64 != v[0] {
                    return Err(bad(format!(
                        "time {} is not a keyframe id (a graph's trajectory is keyed by id)",
                        tokens[0]
                    )));
                }
                let pose = Pose3::from_xyz_quaternion([v[1], v[2], v[3], v[4], v[5], v[6], v[7]])
                    .ok_or_else(|| bad("not finite, or the quaternion is not of unit norm".into()))?;
                (id, pose)
            }
            Trajectory::Kitti => {
                let v =
                    super::numbers::<12>(&tokens, "KITTI pose").map_err(|k| ReadError::at(path, n + 1, k))?;
                let id = *ids.get(row).ok_or_else(|| {
                    bad(format!(
                        "line {} of poses, the graph has {} keyframes",
                        row + 1,
                        ids.len()
                    ))
                })?;
                row += 1;
                let m = Matrix3::new(v[0], v[1], v[2], v[4], v[5], v[6], v[8], v[9], v[10]);
                if v.iter().any(|x| !x.is_finite()) || (m.transpose() * m - Matrix3::identity()).norm() > 1e-6
                {
                    return Err(bad("not finite, or not a rotation matrix".into()));
                }
                let r = UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(m));
                (id, Pose3::new(Vector3::new(v[3], v[7], v[11]), r))
            }
        };
        if !known.contains(&id) {
            return Err(bad(format!("keyframe {id} is not in the graph")));
        }
        if poses.insert(id, P::from_spatial(&pose)).is_some() {
            return Err(bad(format!("keyframe {id} appears twice")));
        }
    }
    Ok(poses)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip<P: FromSpatial>(layout: Trajectory, poses: &[P]) -> HashMap<KeyframeId, P> {
        let ids: Vec<KeyframeId> = (0..poses.len() as u64).map(|k| 10 + k).collect();
        let mut out = Vec::new();
        write_trajectory(&mut out, layout, &ids, poses).unwrap();
        let text = String::from_utf8(out).unwrap();
        parse_trajectory(Path::new("t"), &text, layout, &ids).unwrap()
    }

    #[test]
    fn tum_lines_carry_timestamps_when_every_keyframe_has_one() {
        let poses = [Pose2::new(1.0, 0.0, 0.0), Pose2::new(2.0, 0.0, 0.0)];
        let times = |stamps: &[u64]| {
            let mut out = Vec::new();
            write_trajectory_at(&mut out, Trajectory::Tum, &[7, 8], stamps, &poses).unwrap();
            let text = String::from_utf8(out).unwrap();
            text.lines()
                .map(|l| l.split(' ').next().unwrap().to_string())
                .collect::<Vec<_>>()
        };
        assert_eq!(
            times(&[1_700_000_000_000_000_042, 1_700_000_001_500_000_000]),
            ["1700000000.000000042", "1700000001.500000000"]
        );
        // one keyframe without a time: every line keyed by its id
        assert_eq!(times(&[1_700_000_000_000_000_042, 0]), ["7", "8"]);
    }

    #[test]
    fn both_layouts_round_trip_in_both_dimensions() {
        let planar = [Pose2::new(1.0, -2.0, 0.3), Pose2::new(0.5, 4.0, -2.9)];
        let spatial = [
            Pose3::from_xyz_rpy([1.0, 2.0, 3.0, 0.1, -0.2, 0.3]),
            Pose3::from_xyz_rpy([-1.0, 0.5, 2.0, 0.0, 0.4, -2.5]),
        ];
        for layout in [Trajectory::Tum, Trajectory::Kitti] {
            let back = round_trip(layout, &planar);
            for (k, p) in planar.iter().enumerate() {
                let b = back[&(10 + k as u64)];
                assert!(
                    (b.x - p.x).abs() < 1e-12 && (b.y - p.y).abs() < 1e-12,
                    "{layout:?}"
                );
                assert!(
                    (b.theta - p.theta).abs() < 1e-12,
                    "{layout:?}: {} against {}",
                    b.theta,
                    p.theta
                );
            }
            let back = round_trip(layout, &spatial);
            for (k, p) in spatial.iter().enumerate() {
                let b = back[&(10 + k as u64)];
                assert!((b.translation - p.translation).norm() < 1e-12, "{layout:?}");
                assert!(b.rotation.angle_to(&p.rotation) < 1e-12, "{layout:?}");
            }
        }
    }

    #[test]
    fn bad_lines_are_refused_with_their_line() {
        let ids = [0, 1];
        let parse = |layout, text| parse_trajectory::<Pose3>(Path::new("t"), text, layout, &ids).unwrap_err();
        let err = parse(Trajectory::Tum, "0 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 0 1\n");
        assert_eq!(err.line, Some(2));
        assert!(err.to_string().contains("is not a keyframe id"), "{err}");
        let err = parse(Trajectory::Tum, "0 0 0 0 0 0 0 2\n");
        assert!(err.to_string().contains("unit norm"), "{err}");
        let err = parse(Trajectory::Tum, "7 0 0 0 0 0 0 1\n");
        assert!(
            err.to_string().contains("keyframe 7 is not in the graph"),
            "{err}"
        );
        let three = "1 0 0 0 0 1 0 0 0 0 1 0\n".repeat(3);
        let err = parse(Trajectory::Kitti, three.as_str());
        assert_eq!(err.line, Some(3));
        let err = parse(Trajectory::Kitti, "2 0 0 0 0 1 0 0 0 0 1 0\n");
        assert!(err.to_string().contains("not a rotation matrix"), "{err}");
    }
}
