//! The two-stage linear initialiser (slamd's default; compare GTSAM's LAGO).
//!
//! Paper A's virtual axes, pinned to unit length (docs/design.md, "Two
//! stages: axes, then positions"). With one complex axis `r_i = e^{iθ_i}`
//! per keyframe:
//!
//! 1. **Axes.** `r_j − e^{iθ_ij} r_i = 0` for every edge, weight `1/σθ²`,
//!    gauge `r_0 = 1`. Solve, then normalise `r_i ← r_i / |r_i|`.
//! 2. **Positions.** `p_j − p_i = r_i t_ij` for every edge, gauge `p_0 = 0`,
//!    weighted by the edge's translation information carried into the map
//!    frame, `W = R Σ_t⁻¹ Rᵀ` with `R` the rotation of `r_i e^{iθ_ij}`
//!    ([`PositionWeights::Anisotropic`], the default). With the scalar
//!    weight `2 / tr Σ_t` ([`PositionWeights::Isotropic`]) the normal matrix
//!    is a weighted graph Laplacian that does not depend on the data: what
//!    the incremental engine keeps. Both agree where Ω_t is isotropic.

use super::planar::PlanarSystem;
use super::system::{LinearSystem, Var};
use crate::geometry::Pose2;
use crate::gps::{Georef, GpsInput};
use crate::graph::{pose_ordering, Edge, PoseGraph};
use crate::sparse::ordering::{amd_of_pairs, expand_blocks};
use crate::sparse::{FactorError, Ordering};
use faer::c64;
use nalgebra::Matrix2;

/// Maps keyframe `k` to its unknown; keyframe 0 is the gauge with `value`.
pub(crate) fn gauge_var(k: usize, value: c64) -> Var {
    if k == 0 {
        Var::Fixed(value)
    } else {
        Var::Free(k - 1)
    }
}

/// Pushes the axis row of one edge: `r_j − e^{iθ_ij} r_i = 0`.
pub fn push_axis_row(system: &mut LinearSystem<c64>, edge: &Edge, weight: f64) {
    let one = c64::new(1.0, 0.0);
    let z = edge.measurement.rotation();
    system.push(
        &[(gauge_var(edge.to, one), one), (gauge_var(edge.from, one), -z)],
        c64::new(0.0, 0.0),
        weight,
    );
}

/// Pushes the position row of one edge: `p_j − p_i = r_i t_ij`.
pub fn push_position_row(system: &mut LinearSystem<f64>, edge: &Edge, axis_i: c64, weight: f64) {
    let zero = c64::new(0.0, 0.0);
    system.push(
        &[
            (gauge_var(edge.to, zero), 1.0),
            (gauge_var(edge.from, zero), -1.0),
        ],
        axis_i * edge.measurement.position(),
        weight,
    );
}

/// Stage 1: the axis equations of every edge.
pub fn axis_system(graph: &PoseGraph) -> LinearSystem<c64> {
    let mut s = LinearSystem::new(graph.len() - 1);
    for e in graph.edges() {
        push_axis_row(&mut s, e, e.information.rotation_weight());
    }
    s
}

/// Solves stage 1 and normalises: `r_i = e^{iθ_i}`, `r_0 = 1`. `order` is
/// the keyframe ordering of [`pose_ordering`].
pub fn solve_axes(graph: &PoseGraph, order: &[usize]) -> Result<Vec<c64>, FactorError> {
    let x = axis_system(graph).solve(&Ordering::Custom(order.to_vec()))?;
    Ok(with_gauge(c64::new(1.0, 0.0), x)
        .into_iter()
        .map(normalise)
        .collect())
}

/// How the position stage weighs an edge's translation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PositionWeights {
    /// The full 2×2 information, rotated into the map frame.
    #[default]
    Anisotropic,
    /// One scalar per edge, `2 / tr Σ_t`: a data-independent Laplacian.
    Isotropic,
}

/// Stage 2 with scalar weights: the Laplacian system.
pub fn position_system(graph: &PoseGraph, axes: &[c64]) -> LinearSystem<f64> {
    let mut s = LinearSystem::new(graph.len() - 1);
    for e in graph.edges() {
        push_position_row(&mut s, e, axes[e.from], e.information.translation_weight());
    }
    s
}

/// The translation information of `edge` in the map frame, given `r_i`.
pub fn map_frame_weight(edge: &Edge, axis_i: c64) -> Matrix2<f64> {
    let c = edge.information.covariance();
    let sigma_t = Matrix2::new(c[(0, 0)], c[(0, 1)], c[(1, 0)], c[(1, 1)]);
    let omega_t = sigma_t.try_inverse().unwrap_or_else(Matrix2::zeros);
    let rot = axis_i * edge.measurement.rotation();
    let r = Matrix2::new(rot.re, -rot.im, rot.im, rot.re);
    r * omega_t * r.transpose()
}

/// Stage 2 with full weights: a planar system over 2×2 blocks.
pub fn planar_position_system(graph: &PoseGraph, axes: &[c64]) -> PlanarSystem {
    let mut s = PlanarSystem::new(graph.len() - 1);
    let (zero, one) = (c64::new(0.0, 0.0), c64::new(1.0, 0.0));
    for e in graph.edges() {
        s.push(
            &[(gauge_var(e.to, zero), one), (gauge_var(e.from, zero), -one)],
            axes[e.from] * e.measurement.position(),
            map_frame_weight(e, axes[e.from]),
        );
    }
    s
}

/// Solves stage 2: `p_i`, with `p_0 = 0`. Anisotropic weights fall back
/// to the (identical, four times smaller) Laplacian when every edge's
/// translation information is isotropic.
pub fn solve_positions(
    graph: &PoseGraph,
    axes: &[c64],
    weights: PositionWeights,
    order: &[usize],
) -> Result<Vec<c64>, FactorError> {
    let isotropic = graph
        .edges()
        .iter()
        .all(|e| e.information.translation_is_isotropic());
    let x = match weights {
        PositionWeights::Anisotropic if !isotropic => {
            planar_position_system(graph, axes).solve(&Ordering::Custom(expand_blocks(order, 2)))?
        }
        _ => position_system(graph, axes).solve(&Ordering::Custom(order.to_vec()))?,
    };
    Ok(with_gauge(c64::new(0.0, 0.0), x))
}

/// Both stages with GPS: paper A's triangle rows join the position stage,
/// then, if `gps.absolute`, each fix's absolute position equation in the
/// map frame of the georeference fitted to the positions so far (fitted,
/// solved, refitted, solved). Returns the poses and the georeference.
pub fn solve_gps(graph: &PoseGraph, gps: &GpsInput) -> Result<(Vec<Pose2>, Option<Georef>), FactorError> {
    let order = pose_ordering(graph.len(), graph.edges());
    let axes = solve_axes(graph, &order)?;
    let zero = c64::new(0.0, 0.0);
    let mut base = planar_position_system(graph, &axes);
    let (fixes, triangles) = gps.triangles();
    // triangles couple far-apart keyframes: order with them, or fill explodes
    let couplings = triangles.iter().flat_map(|t| {
        let (a, b, c) = (fixes[t.a].keyframe, fixes[t.b].keyframe, fixes[t.c].keyframe);
        [(a, b), (b, c), (a, c)]
    });
    let free = graph
        .edges()
        .iter()
        .map(|e| (e.from, e.to))
        .chain(couplings)
        .filter(|&(i, j)| i > 0 && j > 0)
        .map(|(i, j)| (i - 1, j - 1));
    let position_order = amd_of_pairs(graph.len().saturating_sub(1), free);
    for t in &triangles {
        let (a, b, c) = (fixes[t.a].keyframe, fixes[t.b].keyframe, fixes[t.c].keyframe);
        let one = c64::new(1.0, 0.0);
        base.push(
            &[
                (gauge_var(c, zero), one),
                (gauge_var(b, zero), t.omega - one),
                (gauge_var(a, zero), -t.omega),
            ],
            zero,
            Matrix2::identity() * (gps.weight / t.variance),
        );
    }
    let ordering = Ordering::Custom(expand_blocks(&position_order, 2));
    let mut positions = with_gauge(zero, base.solve(&ordering)?);
    let mut georef = None;
    if gps.absolute {
        for _ in 0..2 {
            let Some(g) = gps.fit(&poses_from(&positions, &axes)) else {
                break;
            };
            let mut system = base.clone();
            for prior in gps.priors::<Pose2>(&g) {
                system.push(
                    &[(gauge_var(prior.keyframe, zero), c64::new(1.0, 0.0))],
                    prior.target,
                    prior.information,
                );
            }
            positions = with_gauge(zero, system.solve(&ordering)?);
            georef = Some(g);
        }
        georef = gps.fit(&poses_from(&positions, &axes)).or(georef);
    }
    Ok((poses_from(&positions, &axes), georef))
}

/// Both stages with the default weights: the poses `(p_i, arg r_i)`.
pub fn solve(graph: &PoseGraph) -> Result<Vec<Pose2>, FactorError> {
    solve_with(graph, PositionWeights::default())
}

/// Both stages with the given position weights.
pub fn solve_with(graph: &PoseGraph, weights: PositionWeights) -> Result<Vec<Pose2>, FactorError> {
    let order = pose_ordering(graph.len(), graph.edges());
    let axes = solve_axes(graph, &order)?;
    let positions = solve_positions(graph, &axes, weights, &order)?;
    Ok(poses_from(&positions, &axes))
}

/// Poses from complex positions and unit axes.
pub fn poses_from(positions: &[c64], axes: &[c64]) -> Vec<Pose2> {
    positions
        .iter()
        .zip(axes)
        .map(|(p, r)| Pose2::from_complex(*p, r.arg()))
        .collect()
}

/// `r / |r|`, or 1 for a zero axis (an unconstrained heading).
pub fn normalise(r: c64) -> c64 {
    let n = r.norm();
    if n > 0.0 && n.is_finite() {
        r / n
    } else {
        c64::new(1.0, 0.0)
    }
}

/// Prepends the gauge value to the solved unknowns.
pub(crate) fn with_gauge(gauge: c64, x: Vec<c64>) -> Vec<c64> {
    std::iter::once(gauge).chain(x).collect()
}
