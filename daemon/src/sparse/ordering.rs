//! Fill-reducing orderings.
//!
//! The ordering decides the cost of everything downstream: Manhattan's
//! position system fills 4.4M entries in chronological order and 85k with
//! AMD. A permutation here is `perm[k] = i`: original variable `i` is
//! eliminated `k`-th.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::amd;
use faer::sparse::SymbolicSparseColMatRef;

/// Which elimination order a factorisation uses.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Ordering {
    /// Approximate minimum degree on the matrix pattern.
    #[default]
    Amd,
    /// AMD computed on the block pattern, each block expanded to `size`
    /// consecutive variables (3 for an SE(2) pose).
    BlockAmd(usize),
    /// The given permutation, `perm[k] = i`.
    Custom(Vec<usize>),
    /// No reordering.
    Natural,
}

/// AMD on a symmetric pattern given by its upper (or full) triangle.
pub fn amd(pattern: SymbolicSparseColMatRef<'_, usize>) -> Vec<usize> {
    let n = pattern.nrows();
    let mut perm = vec![0usize; n];
    let mut inv = vec![0usize; n];
    let nnz = pattern.compute_nnz();
    let mut buf = MemBuffer::new(amd::order_maybe_unsorted_scratch::<usize>(n, nnz));
    let ok = amd::order_maybe_unsorted(
        &mut perm,
        &mut inv,
        pattern,
        amd::Control::default(),
        MemStack::new(&mut buf),
    );
    match ok {
        Ok(_) => perm,
        // AMD only fails on index overflow; the natural order is always valid.
        Err(_) => (0..n).collect(),
    }
}

/// AMD on the graph with `n` vertices and the given edges (self-loops and
/// repeats allowed): the ordering of a normal matrix whose pattern is that
/// graph, without assembling it.
pub fn amd_of_pairs(n: usize, pairs: impl Iterator<Item = (usize, usize)>) -> Vec<usize> {
    let mut adj: Vec<Vec<usize>> = vec![Vec::new(); n];
    for (i, j) in pairs {
        if i != j {
            adj[i.max(j)].push(i.min(j));
        }
    }
    let mut col_ptr = Vec::with_capacity(n + 1);
    let mut row_idx = Vec::new();
    col_ptr.push(0);
    for (c, rows) in adj.iter_mut().enumerate() {
        rows.sort_unstable();
        rows.dedup();
        row_idx.extend_from_slice(rows);
        row_idx.push(c);
        col_ptr.push(row_idx.len());
    }
    amd(SymbolicSparseColMatRef::new_checked(
        n, n, &col_ptr, None, &row_idx,
    ))
}

/// AMD on the first `n − recent` vertices, then the last `recent` in
/// their given order. New edges attach to recent keyframes; keeping those
/// at the root of the elimination tree keeps update paths short. (faer has
/// no constrained AMD; this is the cheap form of GTSAM's
/// `ColamdConstrainedLast`.)
pub fn amd_newest_last(n: usize, pairs: impl Iterator<Item = (usize, usize)>, recent: usize) -> Vec<usize> {
    let old = n.saturating_sub(recent);
    let mut perm = amd_of_pairs(old, pairs.filter(|&(i, j)| i < old && j < old));
    perm.extend(old..n);
    perm
}

/// Expands a block permutation to scalars: block `b` becomes variables
/// `size·b .. size·b + size`, kept together and in order.
pub fn expand_blocks(block_perm: &[usize], size: usize) -> Vec<usize> {
    block_perm
        .iter()
        .flat_map(|&b| (0..size).map(move |c| size * b + c))
        .collect()
}

/// The inverse permutation: `inv[perm[k]] = k`.
pub fn invert(perm: &[usize]) -> Vec<usize> {
    let mut inv = vec![0usize; perm.len()];
    for (k, &i) in perm.iter().enumerate() {
        inv[i] = k;
    }
    inv
}

/// Block pattern of a scalar pattern whose variables come in blocks of
/// `size`: one entry per block pair that holds any scalar entry. Returned as
/// CSC arrays of the upper triangle.
pub fn block_pattern(pattern: SymbolicSparseColMatRef<'_, usize>, size: usize) -> (Vec<usize>, Vec<usize>) {
    let nb = pattern.nrows() / size;
    let mut col_ptr = vec![0usize];
    let mut row_idx = Vec::new();
    let mut mark = vec![usize::MAX; nb];
    for bc in 0..nb {
        for c in size * bc..size * bc + size {
            for &r in pattern.row_idx_of_col_raw(c) {
                let br = r / size;
                if br <= bc && mark[br] != bc {
                    mark[br] = bc;
                    row_idx.push(br);
                }
            }
        }
        let start = col_ptr[bc];
        row_idx[start..].sort_unstable();
        col_ptr.push(row_idx.len());
    }
    (col_ptr, row_idx)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expands_and_inverts() {
        let p = expand_blocks(&[1, 0], 3);
        assert_eq!(p, vec![3, 4, 5, 0, 1, 2]);
        assert_eq!(invert(&p), vec![3, 4, 5, 0, 1, 2]);
        assert_eq!(invert(&[2, 0, 1]), vec![1, 2, 0]);
    }

    #[test]
    fn amd_orders_an_arrow_matrix_hub_last() {
        // Variable 0 couples to every other: eliminating it first fills the
        // whole matrix, so AMD must put it last.
        let n = 6;
        let mut col_ptr = vec![0];
        let mut row_idx = vec![];
        for c in 0..n {
            if c > 0 {
                row_idx.push(0);
            }
            row_idx.push(c);
            col_ptr.push(row_idx.len());
        }
        let s = SymbolicSparseColMatRef::new_checked(n, n, &col_ptr, None, &row_idx);
        let perm = amd(s);
        assert_eq!(perm[n - 1], 0, "{perm:?}");
        let mut sorted = perm.clone();
        sorted.sort();
        assert_eq!(sorted, (0..n).collect::<Vec<_>>());
    }
}
