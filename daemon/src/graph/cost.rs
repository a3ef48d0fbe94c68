//! g2o's SE(2) cost: χ² = Σ eᵀ Ω e with `e = t2v(T_ij⁻¹ T_i⁻¹ T_j)`.
//!
//! Written out: `e_t = R(θ_ij)ᵀ (R_iᵀ (p_j − p_i) − t_ij)` and
//! `e_θ = wrap(θ_j − θ_i − θ_ij)`. This is the figure every table in slamd
//! reports, relative to the optimum of the same file (docs/design.md, "Scoring: χ² and ATE").

use super::{Edge, PoseGraph, RigidMotion};
use crate::geometry::{wrap_angle, Pose2};
use num_complex::Complex64;

/// A pose type whose edges have an error vector and a χ²: g2o's cost in
/// each dimension (SE(2) in this module, SE(3) in `cost3`).
pub trait EdgeCost: RigidMotion {
    /// The error vector, `DOF` numbers.
    type Error: Copy + std::fmt::Debug + AsRef<[f64]>;
    /// The error of `edge` at poses `xi`, `xj`.
    fn edge_error(edge: &Edge<Self>, xi: &Self, xj: &Self) -> Self::Error;
    /// `eᵀ Ω e`.
    fn mahalanobis(information: &Self::Information, e: &Self::Error) -> f64;
    /// The motion's own coordinates in the error's form (`t2v`: `(x, y, θ)`
    /// in the plane, `[t, q_xyz]` with `w ≥ 0` in space), so that the error
    /// of `Z` against `X` is `(Z⁻¹ X).vector()`.
    fn vector(&self) -> Self::Error;
}

impl EdgeCost for Pose2 {
    type Error = [f64; 3];
    fn edge_error(edge: &Edge, xi: &Pose2, xj: &Pose2) -> [f64; 3] {
        edge_error_turned(edge, xi, xi.rotation(), xj, edge.measurement.rotation())
    }
    fn mahalanobis(information: &super::Information, e: &[f64; 3]) -> f64 {
        information.mahalanobis(e)
    }
    fn vector(&self) -> [f64; 3] {
        self.to_array()
    }
}

/// The error vector of one edge at poses `xi`, `xj`: `[e_x, e_y, e_θ]` in
/// the plane, `[Δt, Δq_xyz]` in space.
pub fn edge_error<P: EdgeCost>(edge: &Edge<P>, xi: &P, xj: &P) -> P::Error {
    P::edge_error(edge, xi, xj)
}

/// [`edge_error`] with the rotations `e^{iθ}` of `xi` and of the
/// measurement given (`turn_i`, `turn_m`): a caller that meets a pose on
/// several edges computes its sine and cosine once. The same arithmetic
/// as `T_ij⁻¹ (T_i⁻¹ T_j)` with [`Pose2::between`], so the same result.
pub fn edge_error_turned(
    edge: &Edge,
    xi: &Pose2,
    turn_i: Complex64,
    xj: &Pose2,
    turn_m: Complex64,
) -> [f64; 3] {
    let m = &edge.measurement;
    let p = turn_i.conj() * (xj.position() - xi.position());
    let q = turn_m.conj() * (p - m.position());
    [q.re, q.im, wrap_angle(wrap_angle(xj.theta - xi.theta) - m.theta)]
}

/// `eᵀ Ω e` of one edge at the given poses (indexed like the graph).
pub fn edge_chi2<P: EdgeCost>(edge: &Edge<P>, poses: &[P]) -> f64 {
    let e = P::edge_error(edge, &poses[edge.from], &poses[edge.to]);
    P::mahalanobis(&edge.information, &e)
}

/// The total χ² of a graph at the given poses.
pub fn chi2<P: EdgeCost>(graph: &PoseGraph<P>, poses: &[P]) -> f64 {
    chi2_of_edges(graph.edges(), poses)
}

/// χ² summed over a slice of edges.
pub fn chi2_of_edges<P: EdgeCost>(edges: &[Edge<P>], poses: &[P]) -> f64 {
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

    /// The engine's cached rotations must give what the composition
    /// `T_ij⁻¹ (T_i⁻¹ T_j)` gives, to the last bit.
    #[test]
    fn the_turned_error_is_the_composed_one_bit_for_bit() {
        for k in 0..50 {
            let f = k as f64;
            let (xi, xj) = (
                Pose2::new(3.0 * f.sin(), f.cos(), 0.37 * f - 7.0),
                Pose2::new(-f, 0.5 * f, 2.9 - 0.21 * f),
            );
            let measurement = Pose2::new(0.1 * f, -1.0, 0.13 * f - 3.0);
            let edge = Edge {
                from: 0,
                to: 1,
                measurement,
                information: Information::identity(),
                kind: EdgeKind::Odometry,
            };
            let e = measurement.between(&xi.between(&xj));
            assert_eq!(edge_error(&edge, &xi, &xj), [e.x, e.y, e.theta]);
        }
    }
}
