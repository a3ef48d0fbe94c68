//! [`HessianStructure`]: the sparsity of the Gauss–Newton normal equations
//! `H = Σ Jᵀ Ω J`, worked out once per graph topology, and the assembly of
//! `H` and `g = Σ Jᵀ Ω e` into it.
//!
//! Each keyframe owns a block of three variables `(x, y, θ)`, or none when
//! it is held fixed (the gauge). `block_of[k]` says which; the batch polish
//! uses `k − 1`, the incremental engine the position of `k` in its
//! elimination order. Each edge touches a 6×6 block of `H`; for every local
//! entry `(a, b)` the structure stores where it lands in the
//! upper-triangular value array, or [`NONE`] when it falls below the
//! diagonal or on a fixed keyframe.

use super::prior::PositionPrior;
use super::se2::linearize;
use crate::geometry::Pose2;
use crate::graph::Edge;
use crate::sparse::UpperCsc;
use nalgebra::{Matrix3x6, Matrix6, Vector6};

/// No slot: the local entry is not stored, or the keyframe has no block.
pub const NONE: u32 = u32::MAX;

/// The pattern of `H` and where each edge's contributions go.
#[derive(Clone, Debug)]
pub struct HessianStructure {
    pattern: UpperCsc<f64>,
    block_of: Vec<u32>,
    slots: Vec<[u32; 36]>,
    diagonal: Vec<usize>,
}

/// The batch layout: keyframe 0 fixed, keyframe `k` owns block `k − 1`.
pub fn gauge_first_blocks(n: usize) -> Vec<u32> {
    (0..n).map(|k| if k == 0 { NONE } else { k as u32 - 1 }).collect()
}

impl HessianStructure {
    /// The structure for `edges` with keyframe `k` owning block
    /// `block_of[k]` (or [`NONE`]); `blocks` is the number of blocks.
    pub fn new(block_of: Vec<u32>, blocks: usize, edges: &[Edge]) -> Self {
        let dim = 3 * blocks;
        let var = |e: &Edge, a: usize| var_of(&block_of, e, a);
        let mut entries: Vec<(usize, usize, f64)> = (0..dim).map(|i| (i, i, 0.0)).collect();
        for e in edges {
            for a in 0..6 {
                for b in 0..6 {
                    if let (Some(ga), Some(gb)) = (var(e, a), var(e, b)) {
                        if ga <= gb {
                            entries.push((ga, gb, 0.0));
                        }
                    }
                }
            }
        }
        let pattern = UpperCsc::from_triplets(dim, &entries);
        let slots = edges
            .iter()
            .map(|e| {
                let mut s = [NONE; 36];
                for a in 0..6 {
                    for b in 0..6 {
                        if let (Some(ga), Some(gb)) = (var(e, a), var(e, b)) {
                            if ga <= gb {
                                s[6 * a + b] = pattern.slot(ga, gb).map_or(NONE, |v| v as u32);
                            }
                        }
                    }
                }
                s
            })
            .collect();
        let diagonal = pattern.diagonal_slots();
        Self {
            pattern,
            block_of,
            slots,
            diagonal,
        }
    }

    /// Number of scalar variables.
    pub fn dim(&self) -> usize {
        self.pattern.n()
    }

    /// The pattern (values are zero).
    pub fn pattern(&self) -> &UpperCsc<f64> {
        &self.pattern
    }

    /// Slots of the diagonal entries.
    pub fn diagonal(&self) -> &[usize] {
        &self.diagonal
    }

    /// The scalar variable of local index `a` of `edge` (0..3 pose i,
    /// 3..6 pose j), if it has one.
    pub fn var(&self, edge: &Edge, a: usize) -> Option<usize> {
        var_of(&self.block_of, edge, a)
    }

    /// Fills `hessian` (same pattern) and `gradient` with `Σ w Jᵀ Ω J` and
    /// `Σ w Jᵀ Ω e` of `edges` (those given to [`Self::new`], weighted by
    /// `weights`, else 1) and of `priors` (which touch only diagonal
    /// blocks, always in the pattern) at `poses`.
    pub fn assemble(
        &self,
        edges: &[Edge],
        weights: Option<&[f64]>,
        priors: &[PositionPrior],
        poses: &[Pose2],
        hessian: &mut UpperCsc<f64>,
        gradient: &mut [f64],
    ) {
        hessian.values_mut().fill(0.0);
        gradient.fill(0.0);
        for p in priors {
            let b = self.block_of[p.keyframe];
            if b == NONE {
                continue;
            }
            let v = 3 * b as usize;
            let e = poses[p.keyframe].position() - p.target;
            let g = p.information * nalgebra::Vector2::new(e.re, e.im);
            gradient[v] += g[0];
            gradient[v + 1] += g[1];
            for (r, c) in [(0, 0), (0, 1), (1, 1)] {
                let s = self
                    .pattern
                    .slot(v + r, v + c)
                    .expect("diagonal blocks are in the pattern");
                hessian.values_mut()[s] += p.information[(r, c)];
            }
        }
        let values = hessian.values_mut();
        for (k, edge) in edges.iter().enumerate() {
            let w = weights.map_or(1.0, |w| w[k]);
            if w == 0.0 {
                continue;
            }
            let (mut h, mut g) = local_system(edge, &poses[edge.from], &poses[edge.to]);
            if w != 1.0 {
                h *= w;
                g *= w;
            }
            let slots = &self.slots[k];
            for a in 0..6 {
                if let Some(ga) = self.var(edge, a) {
                    gradient[ga] += g[a];
                }
                for b in 0..6 {
                    let s = slots[6 * a + b];
                    if s != NONE {
                        values[s as usize] += h[(a, b)];
                    }
                }
            }
        }
    }
}

fn var_of(block_of: &[u32], edge: &Edge, a: usize) -> Option<usize> {
    let pose = if a < 3 { edge.from } else { edge.to };
    let b = block_of[pose];
    (b != NONE).then(|| 3 * b as usize + a % 3)
}

/// The edge's Jacobian `J = [A B]` (3×6) at the given poses, with its error.
pub fn jacobian(edge: &Edge, xi: &Pose2, xj: &Pose2) -> (Matrix3x6<f64>, nalgebra::Vector3<f64>) {
    let lin = linearize(edge, xi, xj);
    let mut j = Matrix3x6::zeros();
    j.fixed_view_mut::<3, 3>(0, 0).copy_from(&lin.a);
    j.fixed_view_mut::<3, 3>(0, 3).copy_from(&lin.b);
    (j, lin.error)
}

/// `(Jᵀ Ω J, Jᵀ Ω e)` of one edge.
pub fn local_system(edge: &Edge, xi: &Pose2, xj: &Pose2) -> (Matrix6<f64>, Vector6<f64>) {
    let (j, e) = jacobian(edge, xi, xj);
    let omega_j = edge.information.matrix() * j;
    (j.transpose() * omega_j, omega_j.transpose() * e)
}
