//! Writing results: g2o (vertices plus the graph's edges) and `id x y θ`.

use crate::geometry::Pose2;
use crate::graph::{Pose3, PoseGraph};
use std::io::Write;

/// Writes the graph as g2o with `poses` as its vertices.
pub fn write_g2o(out: &mut impl Write, graph: &PoseGraph, poses: &[Pose2]) -> std::io::Result<()> {
    for (k, p) in graph.keyframes().iter().zip(poses) {
        writeln!(out, "VERTEX_SE2 {} {} {} {}", k.id, p.x, p.y, p.theta)?;
    }
    for e in graph.edges() {
        let m = e.measurement;
        let u = e.information.upper();
        writeln!(
            out,
            "EDGE_SE2 {} {} {} {} {} {} {} {} {} {} {}",
            graph.id_of(e.from),
            graph.id_of(e.to),
            m.x,
            m.y,
            m.theta,
            u[0],
            u[1],
            u[2],
            u[3],
            u[4],
            u[5]
        )?;
    }
    Ok(())
}

/// Writes a 3-D graph as g2o (`VERTEX_SE3:QUAT`, `EDGE_SE3:QUAT`) with
/// `poses` as its vertices.
pub fn write_g2o3(out: &mut impl Write, graph: &PoseGraph<Pose3>, poses: &[Pose3]) -> std::io::Result<()> {
    let join = |v: &[f64]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(" ");
    for (k, p) in graph.keyframes().iter().zip(poses) {
        writeln!(out, "VERTEX_SE3:QUAT {} {}", k.id, join(&p.to_xyz_quaternion()))?;
    }
    for e in graph.edges() {
        writeln!(
            out,
            "EDGE_SE3:QUAT {} {} {} {}",
            graph.id_of(e.from),
            graph.id_of(e.to),
            join(&e.measurement.to_xyz_quaternion()),
            join(&e.information.upper())
        )?;
    }
    Ok(())
}

/// Writes one `id x y θ` line per keyframe.
pub fn write_pose_table(out: &mut impl Write, graph: &PoseGraph, poses: &[Pose2]) -> std::io::Result<()> {
    for (k, p) in graph.keyframes().iter().zip(poses) {
        writeln!(out, "{} {} {} {}", k.id, p.x, p.y, p.theta)?;
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
}
