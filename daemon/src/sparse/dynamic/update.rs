//! Rank-1 update and downdate: `A ← A + σ w wᴴ`, σ = ±1.
//!
//! Davis and Hager's method C1 on `L D Lᴴ`: walking the elimination-tree
//! path from the first nonzero of `w`, column `j` with `p = w_j` becomes
//!
//! ```text
//! d̄_j = d_j + σ|p|²,   γ = σ p̄ / d̄_j,   σ ← σ d_j / d̄_j,
//! w_i ← w_i − p L_ij,   L_ij ← L_ij + γ w_i    (i below j)
//! ```
//!
//! and the pattern of column `j` grows to include every row where `w` is
//! nonzero, so the walk follows the path of the *new* tree. Only columns on
//! that path are touched.

use super::factor::DynamicLdlt;
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
    /// `A ← A + σ w wᴴ` for a sparse `w` given as distinct `(column, value)`
    /// pairs. `before(j, self)` runs just before column `j` changes, so a
    /// caller can retire state that depends on the old column.
    ///
    /// On error (a downdate that loses positive definiteness) the factor is
    /// left inconsistent and must be rebuilt.
    pub fn rank1_with(
        &mut self,
        w: &[(usize, T)],
        sigma: f64,
        mut before: impl FnMut(usize, &Self),
    ) -> Result<(), UpdateError> {
        let mut carry = std::mem::take(&mut self.carry);
        carry.clear();
        for &(i, v) in w {
            if v != T::default() {
                self.work[i] += v;
                carry.push(i as u32);
            }
        }
        carry.sort_unstable();
        carry.dedup();
        let mut alpha = sigma;
        let mut result = Ok(());
        let mut next = carry.first().map(|&j| j as usize);
        let mut start = 1;
        while let Some(j) = next {
            before(j, self);
            let old_parent = self.parent(j);
            self.merge_pattern(j, &carry[start..]);
            self.reparent(j, old_parent);

            let p = self.work[j];
            self.work[j] = T::default();
            let col = &mut self.cols[j];
            if p != T::default() {
                let d = self.d[j];
                let dbar = d + alpha * p.abs2();
                if dbar.is_nan() || dbar <= 0.0 || (sigma < 0.0 && dbar <= 1e-14 * d) {
                    result = Err(UpdateError { column: j });
                    // clear the accumulator before bailing out
                    for &r in &col.rows {
                        self.work[r as usize] = T::default();
                    }
                    break;
                }
                let gamma = p.conjugate().scale(alpha / dbar);
                alpha *= d / dbar;
                self.d[j] = dbar;
                for (&r, l) in col.rows.iter().zip(col.vals.iter_mut()) {
                    let wi = &mut self.work[r as usize];
                    *wi -= p * *l;
                    *l += gamma * *wi;
                }
            }
            // the nonzeros of w now sit exactly on the new pattern of column j
            carry.clear();
            carry.extend_from_slice(&self.cols[j].rows);
            start = 1;
            next = carry.first().map(|&r| r as usize);
        }
        self.carry = carry;
        result
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
    /// inserting zeros where new.
    fn merge_pattern(&mut self, j: usize, extra: &[u32]) {
        let col = &mut self.cols[j];
        if extra.iter().all(|r| col.rows.binary_search(r).is_ok()) {
            return;
        }
        let (rows, vals) = (&mut self.scratch_rows, &mut self.scratch_vals);
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
                b += 1;
            }
        }
        std::mem::swap(&mut col.rows, rows);
        std::mem::swap(&mut col.vals, vals);
    }
}
