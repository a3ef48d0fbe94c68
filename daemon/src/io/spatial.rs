//! 3-D records: g2o's `VERTEX_SE3:QUAT` / `EDGE_SE3:QUAT`, HOG-Man's
//! `VERTEX3` / `EDGE3` (roll, pitch, yaw) and iSAM's `EDGE3` (square-root
//! information).
//!
//! Angles are carried to the error slamd minimises, `[Δt, Δq_xyz]`: an
//! information over roll, pitch and yaw becomes `D Ω D` with
//! `D = diag(1, 1, 1, 2, 2, 2)`, since near the identity the angles are
//! twice the quaternion's vector. iSAM's square root is taken over its
//! fields as written (x y z roll pitch yaw).

use super::{id, numbers, ReadErrorKind, Record};
use crate::graph::{Information6, InformationError, Pose3};
use nalgebra::Matrix6;

/// g2o 3-D.
pub(crate) fn parse_g2o(tokens: &[&str]) -> Result<Record<Pose3>, ReadErrorKind> {
    match tokens[0] {
        "VERTEX_SE3:QUAT" => {
            let (id, v) = vertex::<7>(tokens)?;
            Ok(Record::Vertex(id, quaternion_pose(v, tokens[0])?))
        }
        "EDGE_SE3:QUAT" => {
            let (i, j, v) = edge::<7>(tokens)?;
            let z = quaternion_pose(v[..7].try_into().expect("7 numbers"), tokens[0])?;
            let info = Information6::from_upper(v[7..].try_into().expect("21 numbers"));
            Ok(Record::Edge(i, j, z, information(info, tokens[0])?))
        }
        "FIX" => Ok(Record::Skip),
        tag if tag.contains("SE2") => Err(ReadErrorKind::Malformed(format!(
            "`{tag}`: a 2-D record in a 3-D graph"
        ))),
        tag => Err(ReadErrorKind::Malformed(format!("unknown g2o record `{tag}`"))),
    }
}

/// HOG-Man 3-D.
pub(crate) fn parse_hogman(tokens: &[&str]) -> Result<Record<Pose3>, ReadErrorKind> {
    match tokens[0] {
        "VERTEX3" => {
            let (id, v) = vertex::<6>(tokens)?;
            Ok(Record::Vertex(id, Pose3::from_xyz_rpy(v)))
        }
        "EDGE3" => {
            let (i, j, v) = edge::<6>(tokens)?;
            let z = Pose3::from_xyz_rpy(v[..6].try_into().expect("6 numbers"));
            let rpy = upper(&v[6..]);
            Ok(Record::Edge(
                i,
                j,
                z,
                information(Information6::from_rpy_information(&rpy), tokens[0])?,
            ))
        }
        "FIX" => Ok(Record::Skip),
        tag => Err(ReadErrorKind::Malformed(format!(
            "unknown HOG-Man record `{tag}`"
        ))),
    }
}

/// iSAM 3-D.
pub(crate) fn parse_isam(tokens: &[&str]) -> Result<Record<Pose3>, ReadErrorKind> {
    match tokens[0] {
        "EDGE3" => {
            let (i, j, v) = edge::<6>(tokens)?;
            let z = Pose3::from_xyz_rpy(v[..6].try_into().expect("6 numbers"));
            let r = upper(&v[6..]);
            let rpy = r.transpose() * r;
            Ok(Record::Edge(
                i,
                j,
                z,
                information(Information6::from_rpy_information(&rpy), tokens[0])?,
            ))
        }
        tag => Err(ReadErrorKind::Malformed(format!("unknown iSAM record `{tag}`"))),
    }
}

/// `TAG id` + `N` numbers.
fn vertex<const N: usize>(tokens: &[&str]) -> Result<(u64, [f64; N]), ReadErrorKind> {
    let record = tokens[0];
    if tokens.len() != N + 2 {
        return Err(ReadErrorKind::Malformed(format!(
            "{record} needs {} fields after the tag, found {}",
            N + 1,
            tokens.len() - 1
        )));
    }
    Ok((id(tokens[1], record)?, numbers::<N>(&tokens[2..], record)?))
}

/// `TAG i j` + `N` pose numbers + 21 information numbers.
fn edge<const N: usize>(tokens: &[&str]) -> Result<(u64, u64, Vec<f64>), ReadErrorKind> {
    let record = tokens[0];
    if tokens.len() != N + 24 {
        return Err(ReadErrorKind::Malformed(format!(
            "{record} needs {} fields after the tag, found {}",
            N + 23,
            tokens.len() - 1
        )));
    }
    let (i, j) = (id(tokens[1], record)?, id(tokens[2], record)?);
    let pose = numbers::<N>(&tokens[3..3 + N], record)?;
    let info = numbers::<21>(&tokens[3 + N..], record)?;
    Ok((i, j, pose.iter().chain(&info).copied().collect()))
}

/// A pose from `x y z qx qy qz qw`, refusing a quaternion far from unit.
fn quaternion_pose(v: [f64; 7], record: &str) -> Result<Pose3, ReadErrorKind> {
    Pose3::from_xyz_quaternion(v).ok_or_else(|| {
        let norm = (v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6]).sqrt();
        ReadErrorKind::Malformed(format!("{record}: quaternion norm {norm} is not 1"))
    })
}

/// The symmetric matrix of 21 upper-triangular entries, row by row.
fn upper(v: &[f64]) -> Matrix6<f64> {
    let mut m = Matrix6::zeros();
    let mut k = 0;
    for r in 0..6 {
        for c in r..6 {
            m[(r, c)] = v[k];
            k += 1;
        }
    }
    m
}

fn information(
    info: Result<Information6, InformationError>,
    record: &str,
) -> Result<Information6, ReadErrorKind> {
    info.map_err(|e| ReadErrorKind::Malformed(format!("{record}: {e}")))
}

#[cfg(test)]
mod tests {
    use super::super::{parse_graph3_with, Format, OnInvalid};
    use std::path::Path;

    fn parse(text: &str, format: Format) -> Result<crate::graph::PoseGraph<crate::graph::Pose3>, String> {
        parse_graph3_with(Path::new("t.g2o"), text, format, OnInvalid::Refuse)
            .map(|(g, _)| g)
            .map_err(|e| e.to_string())
    }

    const INFO: &str = "1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 4 0 0 4 0 4";

    #[test]
    fn reads_g2o_hogman_and_isam_records() {
        let g = parse(
            &format!(
                "VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nVERTEX_SE3:QUAT 1 1 0 0 0 0 0 1\n\
                 EDGE_SE3:QUAT 0 1 1 0 0 0 0 0.0998334 0.9950042 {INFO}\n"
            ),
            Format::G2o3,
        )
        .unwrap();
        let e = g.edges()[0];
        assert!((e.measurement.rotation.angle() - 0.2).abs() < 1e-6);
        assert_eq!(e.information.matrix()[(5, 5)], 4.0);
        // HOG-Man: yaw 0.2 and Ω over the angles carried to the quaternion
        let h = parse(
            &format!("VERTEX3 0 0 0 0 0 0 0\nVERTEX3 1 1 0 0 0 0 0\nEDGE3 0 1 1 0 0 0 0 0.2 {INFO}\n"),
            Format::HogMan3,
        )
        .unwrap();
        let e = h.edges()[0];
        assert!((e.measurement.rotation.angle() - 0.2).abs() < 1e-12);
        assert_eq!(
            (e.information.matrix()[(0, 0)], e.information.matrix()[(5, 5)]),
            (1.0, 16.0)
        );
        // iSAM: square roots, squared, then carried over
        let i = parse(&format!("EDGE3 0 1 1 0 0 0 0 0.2 {INFO}\n"), Format::Isam3).unwrap();
        assert_eq!(i.edges()[0].information.matrix()[(5, 5)], 64.0);
        assert_eq!(i.len(), 2);
    }

    #[test]
    fn errors_name_file_line_and_reason() {
        let bad_q = format!("EDGE_SE3:QUAT 0 1 1 0 0 0 0 0.5 0.5 {INFO}\n");
        assert_eq!(
            parse(&bad_q, Format::G2o3).unwrap_err(),
            "t.g2o:1: EDGE_SE3:QUAT: quaternion norm 0.7071067811865476 is not 1"
        );
        let nan = format!("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1\nEDGE_SE3:QUAT 0 1 nan 0 0 0 0 0 1 {INFO}\n");
        assert_eq!(
            parse(&nan, Format::G2o3).unwrap_err(),
            "t.g2o:2: EDGE_SE3:QUAT: non-finite number `nan`"
        );
        let indefinite = "EDGE_SE3:QUAT 0 1 1 0 0 0 0 0 1 1 0 0 0 0 0 1 0 0 0 0 1 0 0 0 1 0 0 1 0 -1\n";
        assert_eq!(
            parse(indefinite, Format::G2o3).unwrap_err(),
            "t.g2o:1: EDGE_SE3:QUAT: information matrix is not positive definite"
        );
        let short = "EDGE3 0 1 1 0 0 0 0 0.2 1 0 0\n";
        assert_eq!(
            parse(short, Format::HogMan3).unwrap_err(),
            "t.g2o:1: EDGE3 needs 29 fields after the tag, found 11"
        );
        let planar = "VERTEX_SE2 0 0 0 0\n";
        assert_eq!(
            parse(planar, Format::G2o3).unwrap_err(),
            "t.g2o:1: `VERTEX_SE2`: a 2-D record in a 3-D graph"
        );
        let self_edge = format!("EDGE_SE3:QUAT 4 4 1 0 0 0 0 0 1 {INFO}\n");
        assert_eq!(
            parse(&self_edge, Format::G2o3).unwrap_err(),
            "t.g2o:1: edge from keyframe 4 to itself"
        );
    }
}
