//! g2o's SE(2) cost: χ² = Σ eᵀ Ω e with `e = t2v(T_ij⁻¹ T_i⁻¹ T_j)`.
//!
//! Written out: `e_t = R(θ_ij)ᵀ (R_iᵀ (p_j − p_i) − t_ij)` and
//! `e_θ = wrap(θ_j − θ_i − θ_ij)`. This is the figure every table in slamd
//! reports, relative to the optimum of the same file (ALGORITHM.md §4).

use super::{Edge, PoseGraph};
use crate::geometry::Pose2;

/// The error vector `[e_x, e_y, e_θ]` of one edge at poses `xi`, `xj`.
pub fn edge_error(edge: &Edge, xi: &Pose2, xj: &Pose2) -> [f64; 3] {
    let e = edge.measurement.between(&xi.between(xj));
    [e.x, e.y, e.theta]
}

/// `eᵀ Ω e` of one edge at the given poses (indexed like the graph).
pub fn edge_chi2(edge: &Edge, poses: &[Pose2]) -> f64 {
    let e = edge_error(edge, &poses[edge.from], &poses[edge.to]);
    edge.information.mahalanobis(&e)
}

/// The total χ² of a graph at the given poses.
pub fn chi2(graph: &PoseGraph, poses: &[Pose2]) -> f64 {
    chi2_of_edges(graph.edges(), poses)
}

/// χ² summed over a slice of edges.
pub fn chi2_of_edges(edges: &[Edge], poses: &[Pose2]) -> f64 {
    edges.iter().map(|e| edge_chi2(e, poses)).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{EdgeKind, Information};

    #[test]
    fn error_is_zero_on_a_consistent_edge() {
        let xi = Pose2::new(1.0, 2.0, 0.3);
        let xj = Pose2::new(-1.0, 4.0, 2.0);
        let edge = Edge {
            from: 0,
            to: 1,
            measurement: xi.between(&xj),
            information: Information::identity(),
            kind: EdgeKind::Odometry,
        };
        let e = edge_error(&edge, &xi, &xj);
        assert!(e.iter().all(|v| v.abs() < 1e-12), "{e:?}");
    }

    #[test]
    fn translation_error_is_in_the_measured_frame() {
        // e_t = R(θ_ij)ᵀ (R_iᵀ (p_j − p_i) − t_ij): with θ_ij = π/2 an x offset
        // of the measurement shows up on −y.
        let edge = Edge {
            from: 0,
            to: 1,
            measurement: Pose2::new(1.0, 0.0, std::f64::consts::FRAC_PI_2),
            information: Information::from_upper([4.0, 0.0, 0.0, 1.0, 0.0, 1.0]).unwrap(),
            kind: EdgeKind::Odometry,
        };
        let xi = Pose2::IDENTITY;
        let xj = Pose2::new(2.0, 0.0, std::f64::consts::FRAC_PI_2);
        let e = edge_error(&edge, &xi, &xj);
        assert!((e[0]).abs() < 1e-12 && (e[1] + 1.0).abs() < 1e-12, "{e:?}");
        assert!((edge_chi2(&edge, &[xi, xj]) - 1.0).abs() < 1e-12);
    }
}
