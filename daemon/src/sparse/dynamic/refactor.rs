//! Refactorising in place: new values, the same ordering and pattern (a
//! relinearisation of a system whose structure did not change).

use super::factor::DynamicLdlt;
use crate::sparse::{FactorError, Scalar, UpperCsc};

/// No column in a row's list.
const NIL: u32 = u32::MAX;

impl<T: Scalar> DynamicLdlt<T> {
    /// `A = L D Lᴴ` anew for `a` (upper triangle, already in elimination
    /// order), keeping the elimination order and the stored pattern of `L`:
    /// no ordering, no symbolic analysis, no allocation per column. The
    /// nonzeros of `a`'s lower triangle must lie within the pattern of `L` (true for
    /// the matrix this factor was built from and updated to, since updates
    /// only add fill), else [`FactorError::OutsidePattern`]. Left-looking:
    /// column `j` gathers `A[j.., j]` and subtracts `L[j.., k] d_k
    /// conj(L[j, k])` for every `k < j` with `L[j, k] ≠ 0`, found through
    /// lists of the columns whose next row is `j`. The augmented row is
    /// dropped ([`Self::augment`] again); on error the factor is unusable.
    pub fn refactor(&mut self, a: &UpperCsc<T>) -> Result<(), FactorError> {
        let n = self.len();
        assert_eq!(a.n(), n, "one row and column of `a` per variable");
        self.augmented = None;
        let lower = lower_columns(a);
        // `head[j]`: the first column whose next unused row is `j`;
        // `next[k]`: the column after `k` in its list; `at[k]`: where
        // column `k`'s next unused row sits among its rows
        let (mut head, mut next, mut at) = (vec![NIL; n], vec![NIL; n], vec![0u32; n]);
        // `mark[r] == j` while column `j` is built: row `r` is in its pattern
        let mut mark = vec![usize::MAX; n];
        let mut w = std::mem::take(&mut self.work[0]);
        let result = (|| {
            for j in 0..n {
                mark[j] = j;
                for &r in &self.cols[j].rows {
                    mark[r as usize] = j;
                }
                for &(r, v) in &lower[j] {
                    // an assembled pattern may hold exact zeros (a 3×3
                    // block where the Jacobians do not couple) that no
                    // update made fill for
                    if v == T::default() {
                        continue;
                    }
                    if mark[r] != j {
                        return Err(FactorError::OutsidePattern { step: j });
                    }
                    w[r] += v;
                }
                let mut k = std::mem::replace(&mut head[j], NIL);
                while k != NIL {
                    let kk = k as usize;
                    let after = next[kk];
                    let col = &self.cols[kk];
                    let p = at[kk] as usize;
                    // A[i, j] -= L[i, k] d_k conj(L[j, k]) for the rows
                    // i ≥ j of column k, the first of which is j itself
                    let f = col.vals[p].conjugate().scale(self.d[kk]);
                    for (&r, &l) in col.rows[p..].iter().zip(&col.vals[p..]) {
                        let r = r as usize;
                        if mark[r] != j {
                            return Err(FactorError::OutsidePattern { step: j });
                        }
                        w[r] -= l * f;
                    }
                    at[kk] += 1;
                    if let Some(&r) = col.rows.get(p + 1) {
                        next[kk] = head[r as usize];
                        head[r as usize] = k;
                    }
                    k = after;
                }
                let d = w[j].real();
                w[j] = T::default();
                if !(d > 0.0 && d.is_finite()) {
                    return Err(FactorError::NotPositiveDefinite { step: j });
                }
                self.d[j] = d;
                let col = &mut self.cols[j];
                for (&r, l) in col.rows.iter().zip(col.vals.iter_mut()) {
                    *l = w[r as usize].scale(1.0 / d);
                    w[r as usize] = T::default();
                }
                if let Some(&r) = col.rows.first() {
                    at[j] = 0;
                    next[j] = head[r as usize];
                    head[r as usize] = j as u32;
                }
            }
            Ok(())
        })();
        // the accumulators are zero between calls, also after an error
        w.iter_mut().for_each(|v| *v = T::default());
        self.work[0] = w;
        result
    }
}

/// The lower triangle of the symmetric `a`, by columns: column `j` holds
/// `(i, A[i, j])` for `i ≥ j`, the diagonal included.
fn lower_columns<T: Scalar>(a: &UpperCsc<T>) -> Vec<Vec<(usize, T)>> {
    let mut lower = vec![Vec::new(); a.n()];
    let (ptr, rows, vals) = (a.col_ptr(), a.row_idx(), a.values());
    for c in 0..a.n() {
        for p in ptr[c]..ptr[c + 1] {
            // A[c, r] = conj(A[r, c]) for r ≤ c: row c of lower column r
            lower[rows[p]].push((c, vals[p].conjugate()));
        }
    }
    lower
}
