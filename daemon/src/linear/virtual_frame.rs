//! Paper A as printed: linear SLAM on virtual coordinates.
//!
//! Selectable (`--formulation virtual-frame`), not the default: with only
//! keyframe 0 pinned, least squares shrinks the virtual axes of distant
//! frames, and one global scale cannot undo a shrink that varies across
//! the map (docs/design.md, "Paper A as printed").
//!
//! Every keyframe `k` gets two virtual points `k_x = p_k + e^{iθ_k}` and
//! `k_y = p_k + i·e^{iθ_k}`. An edge `(i, j)` with `T_ij = (t, e^{iθ})` puts
//! `j_x = t + e^{iθ}` and `j_y = t + i·e^{iθ}` in frame `i`, where `i_x = 1`
//! and `i_y = i`, and gives one similar-triangle equation for each of `j_x`
//! and `j_y`:
//!
//! - [`Pivot::Printed`]: `i_y − q = ω (i_x − q)`, `ω = (i − q)/(1 − q)`, with
//!   the paper's degenerate cases `i_x = q` when `|1 − q| < ε` and `i_y = q`
//!   when `|i − q| < ε`;
//! - [`Pivot::AxisX`]: `q = i_x + ω′ (i_y − i_x)`, `ω′ = (q − 1)/(i − 1)`, the
//!   same triangle pivoted on `i_x`; `|i_y − i_x| = √2` so it never degenerates.
//!
//! Then `p_k = (k_y − i·k_x)/(1 − i)`, the closed-form scale ρ
//! ([`super::scale`]) and headings by registration ([`super::rotation`]).

use super::rotation::register;
use super::scale::closed_form_scale;
use super::system::{LinearSystem, Var};
use crate::geometry::Pose2;
use crate::gps::GpsInput;
use crate::graph::PoseGraph;
use crate::sparse::{FactorError, Ordering};
use faer::c64;

/// Which vertex of the triangle the equation is written around.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Pivot {
    /// The paper's form, pivoting on the neighbour's virtual point.
    #[default]
    Printed,
    /// Pivoting on `i_x`: better conditioned, no degenerate case.
    AxisX,
}

/// The result of the literal formulation, with the figures that show its
/// collapse.
#[derive(Clone, Debug)]
pub struct VirtualFrameSolution {
    /// Poses after scaling by ρ and registering headings.
    pub poses: Vec<Pose2>,
    /// The closed-form global scale.
    pub rho: f64,
    /// Median length of the solved virtual axes at ρ = 1 (truth: 1).
    pub median_axis_length: f64,
}

/// Distance below which two points of a triangle count as coincident.
pub const DEGENERATE_EPS: f64 = 1e-9;

const I: c64 = c64 { re: 0.0, im: 1.0 };
const ONE: c64 = c64 { re: 1.0, im: 0.0 };

/// The virtual point `(k_x or k_y)` of keyframe `k` as a variable; keyframe 0
/// is the gauge with `0_x = 1`, `0_y = i`.
fn point(k: usize, y_axis: bool) -> Var {
    match (k, y_axis) {
        (0, false) => Var::Fixed(ONE),
        (0, true) => Var::Fixed(I),
        (k, y) => Var::Free(2 * (k - 1) + y as usize),
    }
}

/// The similar-triangle system of every edge.
pub fn system(graph: &PoseGraph, pivot: Pivot) -> LinearSystem<c64> {
    let mut s = LinearSystem::new(2 * (graph.len() - 1));
    let zero = c64::new(0.0, 0.0);
    for e in graph.edges() {
        let w = e.information.scalar_weight();
        let (t, z) = (e.measurement.position(), e.measurement.rotation());
        let (ix, iy) = (point(e.from, false), point(e.from, true));
        for (q_local, q) in [(t + z, point(e.to, false)), (t + I * z, point(e.to, true))] {
            match pivot {
                Pivot::Printed => {
                    if (ONE - q_local).norm() < DEGENERATE_EPS {
                        s.push(&[(ix, ONE), (q, -ONE)], zero, w);
                    } else if (I - q_local).norm() < DEGENERATE_EPS {
                        s.push(&[(iy, ONE), (q, -ONE)], zero, w);
                    } else {
                        let omega = (I - q_local) / (ONE - q_local);
                        s.push(&[(iy, ONE), (ix, -omega), (q, omega - ONE)], zero, w);
                    }
                }
                Pivot::AxisX => {
                    let omega = (q_local - ONE) / (I - ONE);
                    s.push(&[(q, ONE), (ix, omega - ONE), (iy, -omega)], zero, w);
                }
            }
        }
    }
    s
}

/// Adds paper A's GPS triangles, each through the positions
/// `p_k = (k_y − i·k_x)/(1 − i)` of its keyframes' virtual points.
pub fn push_gps(s: &mut LinearSystem<c64>, gps: &GpsInput) {
    let (alpha, beta) = (ONE / (ONE - I), -I / (ONE - I));
    let (fixes, triangles) = gps.triangles();
    for t in &triangles {
        let mut terms = Vec::with_capacity(6);
        for (k, coef) in [
            (fixes[t.c].keyframe, ONE),
            (fixes[t.b].keyframe, t.omega - ONE),
            (fixes[t.a].keyframe, -t.omega),
        ] {
            terms.push((point(k, true), coef * alpha));
            terms.push((point(k, false), coef * beta));
        }
        s.push(&terms, c64::new(0.0, 0.0), gps.weight / t.variance);
    }
}

/// Solves paper A's formulation end to end.
pub fn solve(graph: &PoseGraph, pivot: Pivot) -> Result<VirtualFrameSolution, FactorError> {
    solve_with(graph, pivot, None)
}

/// Solves paper A's formulation, with its GPS triangles if given.
pub fn solve_with(
    graph: &PoseGraph,
    pivot: Pivot,
    gps: Option<&GpsInput>,
) -> Result<VirtualFrameSolution, FactorError> {
    let mut sys = system(graph, pivot);
    if let Some(gps) = gps {
        push_gps(&mut sys, gps);
    }
    let x = sys.solve(&Ordering::Amd)?;
    let virt = |k: usize, y: bool| match point(k, y) {
        Var::Fixed(v) => v,
        Var::Free(i) => x[i],
    };
    let n = graph.len();
    let mut kx: Vec<c64> = (0..n).map(|k| virt(k, false)).collect();
    let mut ky: Vec<c64> = (0..n).map(|k| virt(k, true)).collect();
    let mut p: Vec<c64> = (0..n).map(|k| (ky[k] - I * kx[k]) / (ONE - I)).collect();

    let mut lengths: Vec<f64> = (0..n).map(|k| (kx[k] - p[k]).norm()).collect();
    lengths.sort_by(f64::total_cmp);
    let median_axis_length = lengths[n / 2];

    let axes = (0..n).flat_map(|k| [((kx[k] - p[k]).norm_sqr(), 1.0), ((ky[k] - p[k]).norm_sqr(), 1.0)]);
    let edges = graph.edges().iter().map(|e| {
        (
            (p[e.from] - p[e.to]).norm_sqr(),
            e.measurement.position().norm_sqr(),
        )
    });
    let rho = closed_form_scale(axes.chain(edges));
    for v in kx.iter_mut().chain(ky.iter_mut()).chain(p.iter_mut()) {
        *v *= rho;
    }

    let adjacency = graph.adjacency();
    let poses = (0..n)
        .map(|k| {
            let own = [(ONE, kx[k] - p[k]), (I, ky[k] - p[k])];
            let neighbours = adjacency[k].iter().map(|&(m, ei)| {
                let e = &graph.edges()[ei];
                let local = if e.from == k {
                    e.measurement.position()
                } else {
                    e.measurement.inverse().position()
                };
                (local, p[m] - p[k])
            });
            Pose2::from_complex(p[k], register(own.into_iter().chain(neighbours)))
        })
        .collect();
    Ok(VirtualFrameSolution {
        poses,
        rho,
        median_axis_length,
    })
}
