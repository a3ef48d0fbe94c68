//! [`IncrementalCholesky`]: `x = A⁻¹ b` kept current while `A` and `b`
//! change, re-solving only what the change reaches.
//!
//! With `A = L D Lᴴ`, the solve is `y = L⁻¹ b` (forward), then
//! `x = L⁻ᴴ D⁻¹ y` (backward). Besides `y` and `x` this keeps, for every row
//! `i`, the sum of what the columns to its left contribute to it,
//! `c_i = Σ_{j<i} L_ij y_j`, so that `y_i = b_i − c_i`.
//!
//! - **Forward.** A changed column `j` (an update walked through it) or a
//!   changed `b_j` changes `y` only at `j` and its ancestors in the
//!   elimination tree. Before such a column changes, its old contribution
//!   leaves the `c` of its rows; the forward pass then recomputes `y` on the
//!   ancestor-closed set of touched columns, in order, and adds the new
//!   contributions back. Cost: the touched paths, not the matrix.
//! - **Backward** (iSAM2's wildfire). `x` is recomputed from the roots down,
//!   starting at the touched columns; a column's children are visited only
//!   if its `x` moved by more than the threshold. That is an approximation:
//!   a child also depends on ancestors above its parent. A threshold of 0
//!   visits every subtree under a touched column and gives the exact
//!   solution.
//!
//! `M` is the scalar of the matrix and `V` that of the vectors: the position
//! stage solves a real Laplacian for complex positions.

use super::factor::DynamicLdlt;
use super::runs::{gather_dot, scatter_add};
use super::update::UpdateError;
use crate::sparse::Scalar;
use std::ops::Mul;

/// A dynamic factor with its right-hand side and solution.
#[derive(Clone, Debug)]
pub struct IncrementalCholesky<M, V> {
    factor: DynamicLdlt<M>,
    b: Vec<V>,
    y: Vec<V>,
    c: Vec<V>,
    x: Vec<V>,
    dirty: Vec<bool>,
    dirty_list: Vec<usize>,
    queued: Vec<bool>,
    changed: Vec<usize>,
}

impl<M: Scalar, V: Scalar + Mul<M, Output = V>> IncrementalCholesky<M, V> {
    /// Wraps a factor and a right-hand side (in the factor's order) and
    /// solves.
    pub fn new(factor: DynamicLdlt<M>, b: Vec<V>) -> Self {
        assert_eq!(factor.len(), b.len());
        let n = b.len();
        let mut s = Self {
            factor,
            b,
            y: vec![V::default(); n],
            c: vec![V::default(); n],
            x: vec![V::default(); n],
            dirty: vec![false; n],
            dirty_list: Vec::new(),
            queued: vec![false; n],
            changed: Vec::new(),
        };
        s.solve_full();
        s
    }

    /// An empty system.
    pub fn empty() -> Self {
        Self::new(DynamicLdlt::new(), Vec::new())
    }

    /// The factor.
    pub fn factor(&self) -> &DynamicLdlt<M> {
        &self.factor
    }

    /// The solution of the last solve, in the factor's order.
    pub fn x(&self) -> &[V] {
        &self.x
    }

    /// The right-hand side.
    pub fn b(&self) -> &[V] {
        &self.b
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.b.len()
    }

    /// True with no variables.
    pub fn is_empty(&self) -> bool {
        self.b.is_empty()
    }

    /// Adds a variable as the last column (no coupling, `b = 0`, `x = 0`).
    pub fn append(&mut self) -> usize {
        for v in [&mut self.b, &mut self.y, &mut self.c, &mut self.x] {
            v.push(V::default());
        }
        self.dirty.push(false);
        self.queued.push(false);
        self.factor.append()
    }

    /// `b_k ← b_k + v`.
    pub fn add_rhs(&mut self, k: usize, v: V) {
        self.b[k] += v;
        self.touch(k);
    }

    /// `A ← A + σ w wᴴ`. On error the factor must be rebuilt.
    pub fn rank1(&mut self, w: &[(usize, M)], sigma: f64) -> Result<(), UpdateError> {
        self.rank_k(&[w], sigma)
    }

    /// `A ← A + σ Σ_t w_t w_tᴴ` (at most `MAX_RANK` vectors) in one walk.
    pub fn rank_k(&mut self, ws: &[&[(usize, M)]], sigma: f64) -> Result<(), UpdateError> {
        let (dirty, dirty_list, c, y) = (&mut self.dirty, &mut self.dirty_list, &mut self.c, &self.y);
        self.factor.rank_k_with(ws, sigma, |j, f| {
            if !dirty[j] {
                dirty[j] = true;
                dirty_list.push(j);
                retire(f, j, y, c);
            }
        })
    }

    /// Marks `k` for the next forward pass, retiring its contribution.
    fn touch(&mut self, k: usize) {
        if !self.dirty[k] {
            self.dirty[k] = true;
            self.dirty_list.push(k);
            retire(&self.factor, k, &self.y, &mut self.c);
        }
    }

    /// Brings `x` up to date. Columns whose `x` moved by at most `threshold`
    /// do not pass the change on to their subtrees; with 0 every subtree
    /// under a touched column is recomputed (exact). Returns the columns
    /// whose `x` changed.
    pub fn solve(&mut self, threshold: f64) -> &[usize] {
        // the touched set, closed under ancestors in the current tree
        let mut k = 0;
        while k < self.dirty_list.len() {
            if let Some(p) = self.factor.parent(self.dirty_list[k]) {
                self.touch(p);
            }
            k += 1;
        }
        self.dirty_list.sort_unstable();
        for &i in &self.dirty_list {
            let yi = self.b[i] - self.c[i];
            self.y[i] = yi;
            scatter_add(&mut self.c, self.factor.column_runs(i), yi);
        }
        for &i in &self.dirty_list {
            self.dirty[i] = false;
        }
        let (factor, y) = (&self.factor, &self.y);
        wildfire(
            factor,
            &self.dirty_list,
            threshold,
            (&mut self.x, &mut self.queued, &mut self.changed),
            |j, x| back_substitute(factor, y, x, j),
        );
        self.dirty_list.clear();
        &self.changed
    }

    /// Recomputes `y`, `c` and `x` from scratch.
    pub fn solve_full(&mut self) {
        let n = self.len();
        self.c.iter_mut().for_each(|v| *v = V::default());
        for i in 0..n {
            let yi = self.b[i] - self.c[i];
            self.y[i] = yi;
            let (rows, vals) = self.factor.column(i);
            for (&r, &l) in rows.iter().zip(vals) {
                self.c[r as usize] += yi * l;
            }
        }
        for j in (0..n).rev() {
            self.x[j] = back_substitute(&self.factor, &self.y, &self.x, j);
        }
        for &i in &self.dirty_list {
            self.dirty[i] = false;
        }
        self.dirty_list.clear();
    }
}

/// Removes column `j`'s part `L_rj y_j` from the `c` of its rows.
fn retire<M: Scalar, V: Scalar + Mul<M, Output = V>>(f: &DynamicLdlt<M>, j: usize, y: &[V], c: &mut [V]) {
    scatter_add(c, f.column_runs(j), -y[j]);
}

/// `x_j = y_j / d_j − Σ_i conj(L_ij) x_i`; an unconstrained variable (`d_j =
/// 0`) stays at 0.
fn back_substitute<M: Scalar, V: Scalar + Mul<M, Output = V>>(
    factor: &DynamicLdlt<M>,
    y: &[V],
    x: &[V],
    j: usize,
) -> V {
    let d = factor.d(j);
    if d <= 0.0 {
        return V::default();
    }
    y[j].scale(1.0 / d) - gather_dot(x, factor.column_runs(j))
}

/// iSAM2's wildfire: recomputes `x_j = back_substitute(j, x)` from the
/// roots down, starting at the columns `from` (closed under ancestors), and
/// visits a column's children only when its `x` moved by more than
/// `threshold` (with 0, every subtree under `from`: exact). `queued` is
/// all false on entry and on return; `changed` gets the columns whose `x`
/// changed.
///
/// Every row of a column is one of its ancestors, so a column is ready
/// once its parent is done: the walk goes depth first from the roots of
/// `from`, each column pushed by its parent alone (no priority queue).
pub(super) fn wildfire<M: Scalar, V: Scalar>(
    factor: &DynamicLdlt<M>,
    from: &[usize],
    threshold: f64,
    (x, queued, changed): (&mut [V], &mut [bool], &mut Vec<usize>),
    mut back_substitute: impl FnMut(usize, &[V]) -> V,
) {
    // `queued`: touched and not yet recomputed
    for &j in from {
        queued[j] = true;
    }
    let mut stack: Vec<usize> = from
        .iter()
        .copied()
        .filter(|&j| factor.parent(j).is_none())
        .collect();
    changed.clear();
    let tau2 = threshold * threshold;
    while let Some(j) = stack.pop() {
        queued[j] = false;
        let new = back_substitute(j, x);
        let delta = (new - x[j]).abs2();
        if delta > 0.0 {
            changed.push(j);
        }
        x[j] = new;
        let spread = delta > tau2 || threshold == 0.0;
        for &ch in factor.children(j) {
            let ch = ch as usize;
            if spread || queued[ch] {
                stack.push(ch);
            }
        }
    }
    debug_assert!(
        from.iter().all(|&j| !queued[j]),
        "`from` is closed under ancestors"
    );
}
