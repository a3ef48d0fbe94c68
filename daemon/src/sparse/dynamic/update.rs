//! Rank-k update and downdate: `A ← A + σ Σ_t w_t w_tᴴ`, σ = ±1, k ≤
//! [`MAX_RANK`].
//!
//! Davis and Hager's method C1 on `L D Lᴴ`: walking the elimination-tree
//! path from the first nonzero of the `w_t`, column `j` takes each vector in
//! turn; with `p = w_t[j]` and a running scale `α_t` (starting at σ):
//!
//! ```text
//! d̄_j = d_j + α_t|p|²,   γ = α_t p̄ / d̄_j,   α_t ← α_t d_j / d̄_j,
//! w_t[i] ← w_t[i] − p L_ij,   L_ij ← L_ij + γ w_t[i]    (i below j)
//! ```
//!
//! Their multiple-rank form walks each vector's path from its own first
//! nonzero (`Paths`); where paths reach the same column they join,
//! and each column is stepped once, taking every vector that reaches it in
//! one sweep of its rows. The pattern of a column grows to every row where a
//! vector reaching it is nonzero, so a walk follows the path of the *new*
//! tree; only columns on the paths are touched. Each column's pattern nests
//! in its parent's (the structure of a Cholesky factor), so once a column on
//! a path gains no rows, no column above it can: from there the path just
//! follows parents. (Merging every vector's rows into the first column
//! instead would make one path of them all and fill in what separate paths
//! never touch: 25–33% slower on City10000.)
//!
//! A zero pivot (a variable with no weight yet, as a keyframe has between
//! its appending and its first edge) takes a whole vector: its `α_t`
//! becomes 0 and the rest of the walk does nothing for it.
//!
//! On an augmented factor (`[A b; bᴴ β]`, see `DynamicLdlt::augment`) the
//! vectors carry one more entry, their *tail*, in the augmented row, which
//! is a row of every column and whose pivot is the walk's last column: the
//! forward solve `z = D⁻¹ L⁻¹ b` is updated on the walk's path, where it
//! changes, at the cost of one row per column.

use super::factor::DynamicLdlt;
use super::runs::{dense_enough, extend_run_starts, run_starts};
use super::scratch::MAX_RANK;
use crate::sparse::Scalar;
use std::fmt;

/// A downdate that would leave the matrix not positive definite.
#[derive(Clone, Debug, PartialEq)]
pub struct UpdateError {
    /// The column whose pivot would become ≤ 0.
    pub column: usize,
}

impl fmt::Display for UpdateError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "downdate leaves pivot {} not positive", self.column)
    }
}

impl std::error::Error for UpdateError {}

impl<T: Scalar> DynamicLdlt<T> {
    /// `A ← A + σ Σ_t w_t w_tᴴ` for up to [`MAX_RANK`] sparse vectors, each
    /// given as distinct `(column, value)` pairs. `before(j, self)` runs
    /// just before column `j` changes, so a caller can retire state that
    /// depends on the old column.
    ///
    /// On error (a downdate that loses positive definiteness) the factor is
    /// left inconsistent and must be rebuilt.
    pub fn rank_k_with(
        &mut self,
        ws: &[&[(usize, T)]],
        sigma: f64,
        before: impl FnMut(usize, &Self),
    ) -> Result<(), UpdateError> {
        self.rank_k_augmented(ws, &[], sigma, before)
    }

    /// [`Self::rank_k_with`] on an augmented factor (see
    /// [`DynamicLdlt::augment`]): vector `t` has `tails[t]` as its last
    /// entry (missing tails are 0), so that `b` grows by `σ Σ_t w_t
    /// conj(tail_t)` and `β` by `σ Σ_t |tail_t|²`. The augmented row rides
    /// along the walk as one more row of every column; the walk ends at its
    /// pivot. Without augmentation the tails are ignored.
    pub fn rank_k_augmented(
        &mut self,
        ws: &[&[(usize, T)]],
        tails: &[T],
        sigma: f64,
        mut before: impl FnMut(usize, &Self),
    ) -> Result<(), UpdateError> {
        let k = ws.len();
        assert!(k <= MAX_RANK, "rank {k} above {MAX_RANK}");
        assert!(tails.len() <= k, "more tails than vectors");
        let mut tail = [T::default(); MAX_RANK];
        if self.augmented.is_some() {
            tail[..tails.len()].copy_from_slice(tails);
        }
        // each vector's path starts at its first nonzero, holding its other
        // nonzero rows to merge there; vectors that start together walk as one
        let mut paths = std::mem::take(&mut self.scratch.paths);
        paths.clear();
        for (t, w) in ws.iter().enumerate() {
            let Some(first) = w
                .iter()
                .filter(|&&(_, v)| v != T::default())
                .map(|&(i, _)| i)
                .min()
            else {
                continue;
            };
            let pending = paths.start(first);
            for &(i, v) in w.iter() {
                if v != T::default() {
                    self.scratch.work[t][i] += v;
                    if i != first {
                        pending.push(i as u32);
                    }
                }
            }
        }
        let mut alpha = [sigma; MAX_RANK];
        let mut result = Ok(());
        self.walked.walks += 1;
        let mut extra = std::mem::take(&mut self.scratch.extra);
        // rows the previous column gained in this walk: by the nesting of
        // patterns, the only ones its parent can be missing
        let mut added = std::mem::take(&mut self.scratch.added);
        while let Some(j) = paths.lowest() {
            // the paths that reach column j join here, in the lowest slot
            extra.clear();
            let slot = paths.join_at(j, &mut extra);
            extra.sort_unstable();
            extra.dedup();
            // rows of column j are below j
            let from = extra.partition_point(|&r| r as usize <= j);
            before(j, self);
            let old_parent = self.parent(j);
            self.merge_rows(j, &extra[from..], &mut added);
            let new_parent = self.parent(j);
            if new_parent != old_parent {
                self.reparent(j, old_parent);
            }
            self.walked.columns += 1;
            self.walked.entries += self.cols[j].rows.len() as u64;
            if let Some(p) = new_parent {
                self.prefetch_column(p);
            }
            if let Err(e) = self.eliminate(j, k, &mut alpha, &mut tail, sigma) {
                result = Err(e);
                break;
            }
            // what the parent may be missing: the rows column j gained, or,
            // when a new parent did not nest its old rows, all of them
            let full = new_parent != old_parent && old_parent.is_some();
            let gained = if full { &self.cols[j].rows[..] } else { &added[..] };
            match new_parent {
                Some(p) => paths.advance(slot, p, gained),
                None => paths.end(slot),
            }
        }
        if let (Some(a), Ok(())) = (&mut self.augmented, &result) {
            // the augmented pivot is the last column of every walk
            for (t, a_t) in alpha.iter().enumerate().take(k) {
                a.pivot += a_t * tail[t].abs2();
            }
        }
        self.scratch.extra = extra;
        self.scratch.added = added;
        self.scratch.paths = paths;
        result
    }

    /// The numeric step of all vectors at column `j`: the pivots first, then
    /// one sweep over the column applying every vector in turn per row.
    fn eliminate(
        &mut self,
        j: usize,
        k: usize,
        alpha: &mut [f64; MAX_RANK],
        tail: &mut [T; MAX_RANK],
        sigma: f64,
    ) -> Result<(), UpdateError> {
        let mut ps = [T::default(); MAX_RANK];
        let mut gammas = [T::default(); MAX_RANK];
        let mut live = 0;
        for (t, a) in alpha.iter_mut().enumerate().take(k) {
            let p = std::mem::take(&mut self.scratch.work[t][j]);
            if p == T::default() || *a == 0.0 {
                continue;
            }
            let d = self.d[j];
            let dbar = d + *a * p.abs2();
            if dbar.is_nan() || dbar <= 0.0 || (sigma < 0.0 && dbar <= 1e-14 * d) {
                // leave the accumulator clean before bailing out
                for w in &mut self.scratch.work {
                    for r in &self.cols[j].rows {
                        w[*r as usize] = T::default();
                    }
                    w[j] = T::default();
                }
                return Err(UpdateError { column: j });
            }
            gammas[live] = p.conjugate().scale(*a / dbar);
            ps[live] = p;
            *a *= d / dbar;
            self.d[j] = dbar;
            // remember which vector slot this pivot belongs to
            self.scratch.slots[live] = t as u8;
            live += 1;
        }
        if live == 0 {
            return Ok(());
        }
        if let Some(a) = &mut self.augmented {
            // the augmented row: one more row of column j
            let mut z = a.z[j];
            for i in 0..live {
                let t = self.scratch.slots[i] as usize;
                let wi = tail[t] - ps[i] * z;
                tail[t] = wi;
                z += gammas[i] * wi;
            }
            a.z[j] = z;
        }
        let col = &mut self.cols[j];
        let slots = &self.scratch.slots[..live];
        let mut w: [&mut [T]; MAX_RANK] = Default::default();
        let mut rest = &mut self.scratch.work[..];
        let mut taken = 0;
        // the live slots are increasing: split them off in turn
        for (i, &t) in slots.iter().enumerate() {
            let (head, tail) = std::mem::take(&mut rest).split_at_mut(t as usize - taken + 1);
            w[i] = &mut head[t as usize - taken];
            rest = tail;
            taken = t as usize + 1;
        }
        let w = &mut w[..live];
        if dense_enough(&col.rows, &col.starts) {
            let runs = (&col.rows[..], &col.starts[..]);
            T::rank_runs(w, runs, &mut col.vals, &ps[..live], &gammas[..live]);
            return Ok(());
        }
        // short runs: one pass over the rows, every vector per row
        T::rank_rows(w, &col.rows, &mut col.vals, &ps[..live], &gammas[..live]);
        Ok(())
    }

    /// `A ← A + σ w wᴴ`.
    pub fn rank1_with(
        &mut self,
        w: &[(usize, T)],
        sigma: f64,
        before: impl FnMut(usize, &Self),
    ) -> Result<(), UpdateError> {
        self.rank_k_with(&[w], sigma, before)
    }

    /// `A ← A + w wᴴ`.
    pub fn update(&mut self, w: &[(usize, T)]) {
        // an update never fails: every new pivot is ≥ the old one
        let _ = self.rank1_with(w, 1.0, |_, _| {});
    }

    /// `A ← A − w wᴴ`.
    pub fn downdate(&mut self, w: &[(usize, T)]) -> Result<(), UpdateError> {
        self.rank1_with(w, -1.0, |_, _| {})
    }

    /// Grows the pattern of column `j` to `rows(j) ∪ extra` (both sorted),
    /// inserting zeros where new, and records the rows it added in `added`.
    fn merge_rows(&mut self, j: usize, extra: &[u32], added: &mut Vec<u32>) {
        added.clear();
        let col = &mut self.cols[j];
        let last = col.rows.last().copied();
        // the common case: the new rows are the newest variables, past the end
        let tail = extra.partition_point(|&r| last.is_some_and(|l| r <= l));
        if is_subset(&extra[..tail], &col.rows) {
            let old = col.rows.len();
            col.rows.extend_from_slice(&extra[tail..]);
            col.vals.resize(col.rows.len(), T::default());
            added.extend_from_slice(&extra[tail..]);
            extend_run_starts(&col.rows, old, &mut col.starts);
            self.stored += added.len();
            return;
        }
        let (rows, vals) = (&mut self.scratch.rows, &mut self.scratch.vals);
        rows.clear();
        vals.clear();
        let (mut a, mut b) = (0, 0);
        while a < col.rows.len() || b < extra.len() {
            let take_old = b == extra.len() || (a < col.rows.len() && col.rows[a] <= extra[b]);
            if take_old {
                if b < extra.len() && col.rows[a] == extra[b] {
                    b += 1;
                }
                rows.push(col.rows[a]);
                vals.push(col.vals[a]);
                a += 1;
            } else {
                rows.push(extra[b]);
                vals.push(T::default());
                added.push(extra[b]);
                b += 1;
            }
        }
        std::mem::swap(&mut col.rows, rows);
        std::mem::swap(&mut col.vals, vals);
        run_starts(&col.rows, &mut col.starts);
        self.stored += added.len();
    }
}

/// Whether sorted `a` ⊆ sorted `b`: by binary search when `a` is small,
/// else in one pass.
fn is_subset(a: &[u32], b: &[u32]) -> bool {
    if a.len() > b.len() {
        return false;
    }
    if a.len() * 8 < b.len() {
        return a.iter().all(|x| b.binary_search(x).is_ok());
    }
    let mut k = 0;
    for &x in a {
        while k < b.len() && b[k] < x {
            k += 1;
        }
        if k == b.len() || b[k] != x {
            return false;
        }
        k += 1;
    }
    true
}
