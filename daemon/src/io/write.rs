//! Writing results: g2o (vertices plus the graph's edges) and pose tables
//! (`id x y θ`; in space `id x y z qx qy qz qw`).

use crate::geometry::Pose2;
use crate::graph::{Edge, KeyframeId, Pose3, PoseGraph, RigidMotion};
use std::io::Write;

/// A pose g2o writes: its vertex and edge lines.
pub trait G2oPose: RigidMotion {
    /// The vertex line of keyframe `id` at this pose.
    fn write_vertex(&self, out: &mut impl Write, id: KeyframeId) -> std::io::Result<()>;
    /// The edge line of `edge`, between keyframes `from` and `to`.
    fn write_edge(
        out: &mut impl Write,
        from: KeyframeId,
        to: KeyframeId,
        edge: &Edge<Self>,
    ) -> std::io::Result<()>;
}

impl G2oPose for Pose2 {
    /// `VERTEX_SE2 id x y θ`.
    fn write_vertex(&self, out: &mut impl Write, id: KeyframeId) -> std::io::Result<()> {
        writeln!(out, "VERTEX_SE2 {} {} {} {}", id, self.x, self.y, self.theta)
    }

    /// `EDGE_SE2 from to x y θ` and Ω's upper triangle.
    fn write_edge(out: &mut impl Write, from: KeyframeId, to: KeyframeId, e: &Edge) -> std::io::Result<()> {
        let m = e.measurement;
        let u = e.information.upper();
        writeln!(
            out,
            "EDGE_SE2 {} {} {} {} {} {} {} {} {} {} {}",
            from, to, m.x, m.y, m.theta, u[0], u[1], u[2], u[3], u[4], u[5]
        )
    }
}

impl G2oPose for Pose3 {
    /// `VERTEX_SE3:QUAT id x y z qx qy qz qw`.
    fn write_vertex(&self, out: &mut impl Write, id: KeyframeId) -> std::io::Result<()> {
        writeln!(out, "VERTEX_SE3:QUAT {} {}", id, join(&self.to_xyz_quaternion()))
    }

    /// `EDGE_SE3:QUAT from to` the measurement and Ω's upper triangle.
    fn write_edge(
        out: &mut impl Write,
        from: KeyframeId,
        to: KeyframeId,
        e: &Edge<Pose3>,
    ) -> std::io::Result<()> {
        writeln!(
            out,
            "EDGE_SE3:QUAT {} {} {} {}",
            from,
            to,
            join(&e.measurement.to_xyz_quaternion()),
            join(&e.information.upper())
        )
    }
}

/// Numbers separated by spaces.
fn join(v: &[f64]) -> String {
    v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" ")
}

/// Writes the graph as g2o (`VERTEX_SE2`/`EDGE_SE2`, or `VERTEX_SE3:QUAT`/
/// `EDGE_SE3:QUAT`) with `poses` as its vertices.
pub fn write_g2o<P: G2oPose>(out: &mut impl Write, graph: &PoseGraph<P>, poses: &[P]) -> std::io::Result<()> {
    for (k, p) in graph.keyframes().iter().zip(poses) {
        p.write_vertex(out, k.id)?;
    }
    for e in graph.edges() {
        P::write_edge(out, graph.id_of(e.from), graph.id_of(e.to), e)?;
    }
    Ok(())
}

/// Writes one line per keyframe: its id and the pose's
/// [`RigidMotion::PARAMS`] numbers (`id x y θ`; in space
/// `id x y z qx qy qz qw`, `qw ≥ 0`), what
/// [`read_pose_table`](super::read_pose_table) reads.
pub fn write_pose_table<P: RigidMotion>(
    out: &mut impl Write,
    graph: &PoseGraph<P>,
    poses: &[P],
) -> std::io::Result<()> {
    let mut params = [0.0; 7];
    let params = &mut params[..P::PARAMS];
    for (k, p) in graph.keyframes().iter().zip(poses) {
        p.write_params(params);
        write!(out, "{}", k.id)?;
        for v in params.iter() {
            write!(out, " {v}")?;
        }
        writeln!(out)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::{parse_graph, Format};
    use std::path::Path;

    #[test]
    fn g2o_round_trips() {
        let text = "VERTEX_SE2 0 0 0 0\nVERTEX_SE2 1 1 0.5 0.25\nEDGE_SE2 0 1 1 0 0.5 2 0.5 0 3 0 4\n";
        let g = parse_graph(Path::new("a.g2o"), text, Format::G2o).unwrap();
        let poses: Vec<Pose2> = g.keyframes().iter().map(|k| k.guess.unwrap()).collect();
        let mut out = Vec::new();
        write_g2o(&mut out, &g, &poses).unwrap();
        assert_eq!(String::from_utf8(out).unwrap(), text);
    }

    #[test]
    fn pose_tables_round_trip_in_both_dimensions() {
        let text = "VERTEX_SE2 3 1 0.5 0.25\nVERTEX_SE2 7 -2 4 -3\n";
        let g = parse_graph(Path::new("a.g2o"), text, Format::G2o).unwrap();
        let poses: Vec<Pose2> = g.keyframes().iter().map(|k| k.guess.unwrap()).collect();
        let mut out = Vec::new();
        write_pose_table(&mut out, &g, &poses).unwrap();
        let table = String::from_utf8(out).unwrap();
        assert_eq!(table, "3 1 0.5 0.25\n7 -2 4 -3\n");

        let mut g3 = PoseGraph::<Pose3>::default();
        g3.add_keyframe(4, None).unwrap();
        // w < 0: the table writes the same rotation with w ≥ 0
        let q = nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(-0.8, 0.0, 0.6, 0.0));
        let pose = Pose3::new(nalgebra::Vector3::new(1.0, 2.0, 3.0), q);
        let mut out = Vec::new();
        write_pose_table(&mut out, &g3, &[pose]).unwrap();
        let table = String::from_utf8(out).unwrap();
        let numbers: Vec<f64> = table.split_whitespace().map(|t| t.parse().unwrap()).collect();
        assert_eq!(numbers[..5], [4.0, 1.0, 2.0, 3.0, 0.0]);
        assert!(
            (numbers[5] + 0.6).abs() < 1e-15 && (numbers[7] - 0.8).abs() < 1e-15,
            "{table}"
        );
        let back = crate::io::poses::parse_pose_table::<Pose3>(Path::new("t.txt"), &table).unwrap();
        assert!(
            back[&4].rotation.angle_to(&pose.rotation) < 1e-15 && back[&4].translation == pose.translation
        );
    }
}
