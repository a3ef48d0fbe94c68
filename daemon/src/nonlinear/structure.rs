//! [`HessianStructure`]: the sparsity of the Gauss–Newton normal equations
//! `H = Σ Jᵀ Ω J`, worked out once per graph topology, and the assembly of
//! `H` and `g = Σ Jᵀ Ω e` into it.
//!
//! Each keyframe owns a block of `B = DOF` variables (`(x, y, θ)` in the
//! plane, `(u, v)` in space), or none when it is held fixed (the gauge).
//! `block_of[k]` says which; the batch polish uses `k − 1`, the incremental
//! engine the position of `k` in its elimination order. Each edge touches a
//! `2B`-square block of `H`; for every local entry `(a, b)` the structure
//! stores where it lands in the upper-triangular value array, or [`NONE`]
//! when it falls below the diagonal or on a fixed keyframe.

use super::lie::LiePose;
use super::prior::PositionPrior;
use crate::geometry::Pose2;
use crate::graph::Edge;
use crate::sparse::UpperCsc;
use std::marker::PhantomData;

/// No slot: the local entry is not stored, or the keyframe has no block.
pub const NONE: u32 = u32::MAX;

/// The pattern of `H` and where each edge's contributions go.
#[derive(Clone, Debug)]
pub struct HessianStructure<P: LiePose = Pose2> {
    pattern: UpperCsc<f64>,
    block_of: Vec<u32>,
    /// `(2B)²` slots per edge, edge after edge.
    slots: Vec<u32>,
    diagonal: Vec<usize>,
    pose: PhantomData<P>,
}

/// The batch layout: keyframe 0 fixed, keyframe `k` owns block `k − 1`.
pub fn gauge_first_blocks(n: usize) -> Vec<u32> {
    (0..n).map(|k| if k == 0 { NONE } else { k as u32 - 1 }).collect()
}

impl<P: LiePose> HessianStructure<P> {
    /// Variables per keyframe.
    const B: usize = P::DOF;
    /// Local variables per edge.
    const L: usize = 2 * P::DOF;

    /// The structure for `edges` with keyframe `k` owning block
    /// `block_of[k]` (or [`NONE`]); `blocks` is the number of blocks.
    pub fn new(block_of: Vec<u32>, blocks: usize, edges: &[Edge<P>]) -> Self {
        let (bs, l) = (Self::B, Self::L);
        let pairs = BlockPattern::new(&block_of, blocks, edges);
        let pattern = pairs.scalar_pattern(bs);
        let col_ptr = pattern.col_ptr();
        let mut slots = vec![NONE; l * l * edges.len()];
        for (e, s) in edges.iter().zip(slots.chunks_exact_mut(l * l)) {
            let (bi, bj) = (block_of[e.from], block_of[e.to]);
            let cross =
                (bi != NONE && bj != NONE && bi != bj).then(|| pairs.position(bi.min(bj), bi.max(bj)));
            for (a, b) in (0..l).flat_map(|a| (0..l).map(move |b| (a, b))) {
                let (ba, bb) = (if a < bs { bi } else { bj }, if b < bs { bi } else { bj });
                let (ta, tb) = (a % bs, b % bs);
                if ba == NONE || bb == NONE || (ba, ta) > (bb, tb) {
                    continue;
                }
                // row B·ba + ta of scalar column B·bb + tb: B rows per
                // block above it, the diagonal block last
                let p = cross.filter(|_| ba != bb).unwrap_or_else(|| pairs.diagonal(bb));
                s[l * a + b] = (col_ptr[bs * bb as usize + tb] + bs * p + ta) as u32;
            }
        }
        let diagonal = pattern.diagonal_slots();
        Self {
            pattern,
            block_of,
            slots,
            diagonal,
            pose: PhantomData,
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

    /// The scalar variable of local index `a` of `edge` (`0..B` pose i,
    /// `B..2B` pose j), if it has one.
    pub fn var(&self, edge: &Edge<P>, a: usize) -> Option<usize> {
        var_of(&self.block_of, Self::B, edge.from, edge.to, a)
    }

    /// Fills `hessian` (same pattern) and `gradient` with `Σ w Jᵀ Ω J` and
    /// `Σ w Jᵀ Ω e` of `edges` (those given to [`Self::new`], weighted by
    /// `weights`, else 1) and of `priors` (which touch only diagonal
    /// blocks, always in the pattern) at `poses`.
    pub fn assemble(
        &self,
        edges: &[Edge<P>],
        weights: Option<&[f64]>,
        priors: &[PositionPrior<P>],
        poses: &[P],
        hessian: &mut UpperCsc<f64>,
        gradient: &mut [f64],
    ) {
        let (bs, l) = (Self::B, Self::L);
        hessian.values_mut().fill(0.0);
        gradient.fill(0.0);
        for p in priors {
            let b = self.block_of[p.keyframe];
            if b == NONE {
                continue;
            }
            let v = bs * b as usize;
            let (h, g) = poses[p.keyframe].prior_system(&p.target, &p.information);
            for r in 0..bs {
                gradient[v + r] += g[r];
                for c in r..bs {
                    if h[(r, c)] != 0.0 {
                        let s = self
                            .pattern
                            .slot(v + r, v + c)
                            .expect("diagonal blocks are in the pattern");
                        hessian.values_mut()[s] += h[(r, c)];
                    }
                }
            }
        }
        let values = hessian.values_mut();
        for ((k, edge), slots) in edges.iter().enumerate().zip(self.slots.chunks_exact(l * l)) {
            let w = weights.map_or(1.0, |w| w[k]);
            if w == 0.0 {
                continue;
            }
            let (mut h, mut g) = P::edge_system(edge, &poses[edge.from], &poses[edge.to]);
            if w != 1.0 {
                h *= w;
                g *= w;
            }
            for a in 0..l {
                if let Some(ga) = self.var(edge, a) {
                    gradient[ga] += g[a];
                }
                for b in 0..l {
                    let s = slots[l * a + b];
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
/// entry here and `B²` in the scalar pattern, so working it out at this
/// level is a fraction of the cost of building the scalar pattern from
/// triplets.
struct BlockPattern {
    col_ptr: Vec<usize>,
    rows: Vec<u32>,
}

impl BlockPattern {
    fn new<P: LiePose>(block_of: &[u32], blocks: usize, edges: &[Edge<P>]) -> Self {
        let pair = |e: &Edge<P>| {
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

    /// The scalar upper pattern with blocks of `bs`: block entry `(r, c)`
    /// off the diagonal gives rows `bs·r..bs·r+bs` of columns
    /// `bs·c..bs·c+bs`; the diagonal block its upper triangle.
    fn scalar_pattern(&self, bs: usize) -> UpperCsc<f64> {
        let blocks = self.col_ptr.len() - 1;
        let mut col_ptr = Vec::with_capacity(bs * blocks + 1);
        let mut row_idx = Vec::with_capacity(bs * bs * self.rows.len());
        col_ptr.push(0);
        for c in 0..blocks {
            let above = &self.rows[self.col_ptr[c]..self.col_ptr[c + 1] - 1];
            for t in 0..bs {
                row_idx.extend(
                    above
                        .iter()
                        .flat_map(|&r| (0..bs).map(move |u| bs * r as usize + u)),
                );
                row_idx.extend((0..=t).map(|u| bs * c + u));
                col_ptr.push(row_idx.len());
            }
        }
        UpperCsc::from_parts(bs * blocks, col_ptr, row_idx)
    }
}

/// The scalar variable of local index `a` of an edge `from → to` with
/// blocks of `bs`.
fn var_of(block_of: &[u32], bs: usize, from: usize, to: usize, a: usize) -> Option<usize> {
    let pose = if a < bs { from } else { to };
    let b = block_of[pose];
    (b != NONE).then(|| bs * b as usize + a % bs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{EdgeKind, Pose3};
    use proptest::prelude::*;

    /// The pattern by its definition: every block's upper diagonal block
    /// and each edge's `2B`-square block, as triplets.
    fn by_triplets(block_of: &[u32], bs: usize, blocks: usize, pairs: &[(usize, usize)]) -> UpperCsc<f64> {
        let mut entries = Vec::new();
        for b in 0..bs * blocks {
            for r in bs * (b / bs)..=b {
                entries.push((r, b, 0.0));
            }
        }
        for &(i, j) in pairs {
            for (a, b) in (0..2 * bs).flat_map(|a| (0..2 * bs).map(move |b| (a, b))) {
                if let (Some(ga), Some(gb)) = (var_of(block_of, bs, i, j, a), var_of(block_of, bs, i, j, b)) {
                    if ga <= gb {
                        entries.push((ga, gb, 0.0));
                    }
                }
            }
        }
        UpperCsc::from_triplets(bs * blocks, &entries)
    }

    /// Builds the structure at pose type `P` and compares it entry by
    /// entry with [`by_triplets`].
    fn check<P: LiePose>(
        block_of: &[u32],
        blocks: usize,
        pairs: &[(usize, usize)],
        information: P::Information,
    ) -> Result<(), TestCaseError> {
        let (bs, l) = (P::DOF, 2 * P::DOF);
        let edges: Vec<Edge<P>> = pairs
            .iter()
            .map(|&(i, j)| Edge {
                from: i,
                to: j,
                measurement: P::IDENTITY,
                information,
                kind: EdgeKind::LoopClosure,
            })
            .collect();
        let s = HessianStructure::<P>::new(block_of.to_vec(), blocks, &edges);
        let expected = by_triplets(block_of, bs, blocks, pairs);
        prop_assert_eq!(s.pattern().col_ptr(), expected.col_ptr());
        prop_assert_eq!(s.pattern().row_idx(), expected.row_idx());
        for (k, &(i, j)) in pairs.iter().enumerate() {
            for (a, b) in (0..l).flat_map(|a| (0..l).map(move |b| (a, b))) {
                let slot = match (var_of(block_of, bs, i, j, a), var_of(block_of, bs, i, j, b)) {
                    (Some(ga), Some(gb)) if ga <= gb => expected.slot(ga, gb).map_or(NONE, |v| v as u32),
                    _ => NONE,
                };
                prop_assert_eq!(
                    s.slots[l * l * k + l * a + b],
                    slot,
                    "edge {} local ({}, {})",
                    k,
                    a,
                    b
                );
            }
        }
        for (c, &d) in s.diagonal().iter().enumerate() {
            prop_assert_eq!(expected.slot(c, c), Some(d));
        }
        Ok(())
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
            let pairs: Vec<(usize, usize)> = pairs.iter().map(|&(i, j)| (i % n, j % n)).collect();
            check::<Pose2>(&block_of, len, &pairs, crate::graph::Information::identity())?;
            check::<Pose3>(&block_of, len, &pairs, crate::graph::Information6::identity())?;
        }
    }
}
