//! [`HessianStructure`]: the sparsity of the Gauss–Newton normal equations
//! `H = Σ Jᵀ Ω J`, worked out once per graph topology.
//!
//! Pose `k ≥ 1` owns the three variables `3(k−1) .. 3(k−1)+3`; pose 0 is the
//! gauge and has none. Each edge touches a 6×6 block of `H`; for every local
//! entry `(a, b)` the structure stores where it lands in the upper-triangular
//! value array, or [`NONE`] when it falls below the diagonal or on the gauge.

use crate::graph::Edge;
use crate::sparse::UpperCsc;

/// No slot: the local entry is not stored.
pub const NONE: u32 = u32::MAX;

/// The pattern of `H` and where each edge's contributions go.
#[derive(Clone, Debug)]
pub struct HessianStructure {
    pattern: UpperCsc<f64>,
    slots: Vec<[u32; 36]>,
    diagonal: Vec<usize>,
}

/// The global variable of local index `a` (0..3 pose i, 3..6 pose j).
#[inline]
pub fn global_var(edge: &Edge, a: usize) -> Option<usize> {
    let pose = if a < 3 { edge.from } else { edge.to };
    (pose > 0).then(|| 3 * (pose - 1) + a % 3)
}

impl HessianStructure {
    /// The structure for `n` poses connected by `edges`.
    pub fn new(n: usize, edges: &[Edge]) -> Self {
        let dim = 3 * n.saturating_sub(1);
        let mut entries: Vec<(usize, usize, f64)> = (0..dim).map(|i| (i, i, 0.0)).collect();
        for e in edges {
            for a in 0..6 {
                for b in 0..6 {
                    if let (Some(ga), Some(gb)) = (global_var(e, a), global_var(e, b)) {
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
                        if let (Some(ga), Some(gb)) = (global_var(e, a), global_var(e, b)) {
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

    /// Slots of edge `k`'s local 6×6 block, row-major.
    pub fn edge_slots(&self, k: usize) -> &[u32; 36] {
        &self.slots[k]
    }

    /// Slots of the diagonal entries.
    pub fn diagonal(&self) -> &[usize] {
        &self.diagonal
    }
}
