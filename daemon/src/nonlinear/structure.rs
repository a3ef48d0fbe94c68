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
        let pairs = BlockPattern::new(&block_of, blocks, edges);
        let pattern = pairs.scalar_pattern();
        let col_ptr = pattern.col_ptr();
        let slots = edges
            .iter()
            .map(|e| {
                let mut s = [NONE; 36];
                let (bi, bj) = (block_of[e.from], block_of[e.to]);
                let cross =
                    (bi != NONE && bj != NONE && bi != bj).then(|| pairs.position(bi.min(bj), bi.max(bj)));
                for (a, b) in (0..6).flat_map(|a| (0..6).map(move |b| (a, b))) {
                    let (ba, bb) = (if a < 3 { bi } else { bj }, if b < 3 { bi } else { bj });
                    let (ta, tb) = (a % 3, b % 3);
                    if ba == NONE || bb == NONE || (ba, ta) > (bb, tb) {
                        continue;
                    }
                    // row 3·ba + ta of scalar column 3·bb + tb: three rows
                    // per block above it, the diagonal block last
                    let p = cross.filter(|_| ba != bb).unwrap_or_else(|| pairs.diagonal(bb));
                    s[6 * a + b] = (col_ptr[3 * bb as usize + tb] + 3 * p + ta) as u32;
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

/// The block-level pattern of `H`: for each block column, the block rows
/// its edges reach, sorted, the diagonal block last. A block pair is one
/// entry here and nine (six on the diagonal) in the scalar pattern, so
/// working it out at this level is a fraction of the cost of building the
/// scalar pattern from triplets.
struct BlockPattern {
    col_ptr: Vec<usize>,
    rows: Vec<u32>,
}

impl BlockPattern {
    fn new(block_of: &[u32], blocks: usize, edges: &[Edge]) -> Self {
        let pair = |e: &Edge| {
            let (a, b) = (block_of[e.from], block_of[e.to]);
            (a != NONE && b != NONE && a != b).then(|| (a.min(b), a.max(b)))
        };
        // counting sort of the off-diagonal pairs by column
        let mut count = vec![0usize; blocks + 1];
        for (_, c) in edges.iter().filter_map(pair) {
            count[c as usize + 1] += 1;
        }
        for c in 0..blocks {
            count[c + 1] += count[c];
        }
        let mut next = count.clone();
        let mut bucket = vec![0u32; count[blocks]];
        for (r, c) in edges.iter().filter_map(pair) {
            bucket[next[c as usize]] = r;
            next[c as usize] += 1;
        }
        let mut col_ptr = Vec::with_capacity(blocks + 1);
        let mut rows = Vec::with_capacity(bucket.len() + blocks);
        col_ptr.push(0);
        for c in 0..blocks {
            let column = &mut bucket[count[c]..count[c + 1]];
            column.sort_unstable();
            let start = rows.len();
            for &r in column.iter() {
                if rows.len() == start || rows[rows.len() - 1] != r {
                    rows.push(r);
                }
            }
            rows.push(c as u32);
            col_ptr.push(rows.len());
        }
        Self { col_ptr, rows }
    }

    /// Where block row `r` sits in block column `c` (`r ≤ c`, an entry).
    fn position(&self, r: u32, c: u32) -> usize {
        let column = &self.rows[self.col_ptr[c as usize]..self.col_ptr[c as usize + 1]];
        column
            .binary_search(&r)
            .expect("an edge's block pair is in the pattern")
    }

    /// Where the diagonal block sits in block column `c`: last.
    fn diagonal(&self, c: u32) -> usize {
        self.col_ptr[c as usize + 1] - self.col_ptr[c as usize] - 1
    }

    /// The scalar upper pattern: block entry `(r, c)` off the diagonal
    /// gives rows `3r..3r+3` of columns `3c..3c+3`; the diagonal block its
    /// upper triangle.
    fn scalar_pattern(&self) -> UpperCsc<f64> {
        let blocks = self.col_ptr.len() - 1;
        let mut col_ptr = Vec::with_capacity(3 * blocks + 1);
        let mut row_idx = Vec::with_capacity(9 * self.rows.len());
        col_ptr.push(0);
        for c in 0..blocks {
            let above = &self.rows[self.col_ptr[c]..self.col_ptr[c + 1] - 1];
            for t in 0..3 {
                row_idx.extend(
                    above
                        .iter()
                        .flat_map(|&r| (0..3).map(move |u| 3 * r as usize + u)),
                );
                row_idx.extend((0..=t).map(|u| 3 * c + u));
                col_ptr.push(row_idx.len());
            }
        }
        UpperCsc::from_parts(3 * blocks, col_ptr, row_idx)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{EdgeKind, Information};
    use proptest::prelude::*;

    /// The pattern by its definition: every block's upper diagonal block
    /// and each edge's 6×6 block, as triplets.
    fn by_triplets(block_of: &[u32], blocks: usize, edges: &[Edge]) -> UpperCsc<f64> {
        let mut entries = Vec::new();
        for b in 0..3 * blocks {
            for r in 3 * (b / 3)..=b {
                entries.push((r, b, 0.0));
            }
        }
        for e in edges {
            for (a, b) in (0..6).flat_map(|a| (0..6).map(move |b| (a, b))) {
                if let (Some(ga), Some(gb)) = (var_of(block_of, e, a), var_of(block_of, e, b)) {
                    if ga <= gb {
                        entries.push((ga, gb, 0.0));
                    }
                }
            }
        }
        UpperCsc::from_triplets(3 * blocks, &entries)
    }

    proptest! {
        #[test]
        fn the_pattern_and_slots_match_the_triplet_definition(
            n in 2usize..16,
            fixed in prop::collection::vec(any::<bool>(), 16),
            shuffle in any::<u64>(),
            pairs in prop::collection::vec((0usize..16, 0usize..16), 0..40),
        ) {
            // a shuffled block order, some keyframes without a block
            let mut order: Vec<usize> = (0..n).filter(|&k| !fixed[k]).collect();
            let len = order.len();
            for i in (1..len).rev() {
                order.swap(i, (shuffle as usize >> (i % 32)) % (i + 1));
            }
            let mut block_of = vec![NONE; n];
            for (b, &k) in order.iter().enumerate() {
                block_of[k] = b as u32;
            }
            let edges: Vec<Edge> = pairs
                .iter()
                .map(|&(i, j)| Edge {
                    from: i % n,
                    to: j % n,
                    measurement: Pose2::IDENTITY,
                    information: Information::identity(),
                    kind: EdgeKind::LoopClosure,
                })
                .collect();
            let s = HessianStructure::new(block_of.clone(), len, &edges);
            let expected = by_triplets(&block_of, len, &edges);
            prop_assert_eq!(s.pattern().col_ptr(), expected.col_ptr());
            prop_assert_eq!(s.pattern().row_idx(), expected.row_idx());
            for (k, e) in edges.iter().enumerate() {
                for (a, b) in (0..6).flat_map(|a| (0..6).map(move |b| (a, b))) {
                    let slot = match (var_of(&block_of, e, a), var_of(&block_of, e, b)) {
                        (Some(ga), Some(gb)) if ga <= gb => expected.slot(ga, gb).map_or(NONE, |v| v as u32),
                        _ => NONE,
                    };
                    prop_assert_eq!(s.slots[k][6 * a + b], slot, "edge {} local ({}, {})", k, a, b);
                }
            }
            for (c, &d) in s.diagonal().iter().enumerate() {
                prop_assert_eq!(expected.slot(c, c), Some(d));
            }
        }
    }
}
