//! [`LinearSystem`]: weighted linear equations over complex unknowns, solved
//! in the least-squares sense through sparse normal equations.
//!
//! Each row says `Σ_k c_k x_k = y` with weight `w` (an inverse variance).
//! The normal equations are `A x = b` with `A = Σ w c̄ cᵀ` and `b = Σ w c̄ y`.
//! Coefficients are `f64` (a Laplacian: the position stage) or `c64`
//! (similar-triangle rows: axes and virtual frames); unknowns and
//! right-hand sides are always complex planar points.

use crate::sparse::{FactorError, Ordering, Scalar, SparseCholesky, UpperCsc};
use faer::c64;

/// A term's variable: an unknown, or a known value moved to the right side.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Var {
    /// The unknown with this index.
    Free(usize),
    /// A known value (the gauge).
    Fixed(c64),
}

/// Most free terms a row holds (a GPS triangle through paper A's virtual
/// points has six).
pub const MAX_TERMS: usize = 6;

/// One weighted row `Σ_k coefs[k] · x[cols[k]] = rhs` with at most `N`
/// free terms, of weight `W`: an inverse variance here, a 2×2 SPD matrix in
/// [`super::planar`].
#[derive(Clone, Copy, Debug)]
pub(super) struct Row<T, W, const N: usize> {
    pub(super) cols: [usize; N],
    pub(super) coefs: [T; N],
    pub(super) len: usize,
    pub(super) rhs: c64,
    pub(super) weight: W,
}

impl<T: Scalar, W, const N: usize> Row<T, W, N> {
    /// The row `Σ coef·var = rhs` with the fixed variables moved to the
    /// right side, or `None` when no term is free. At most `N` free terms.
    pub(super) fn new(terms: &[(Var, T)], rhs: c64, weight: W) -> Option<Self> {
        let mut row = Row {
            cols: [0; N],
            coefs: [T::default(); N],
            len: 0,
            rhs,
            weight,
        };
        for &(var, coef) in terms {
            match var {
                Var::Free(i) => {
                    row.cols[row.len] = i;
                    row.coefs[row.len] = coef;
                    row.len += 1;
                }
                Var::Fixed(v) => row.rhs -= coef.to_c64() * v,
            }
        }
        (row.len > 0).then_some(row)
    }

    /// The left side `Σ_k c_k x_k` at `x`.
    pub(super) fn lhs(&self, x: &[c64]) -> c64 {
        (0..self.len)
            .map(|k| self.coefs[k].to_c64() * x[self.cols[k]])
            .sum()
    }
}

/// Weighted rows over `n` complex unknowns.
#[derive(Clone, Debug)]
pub struct LinearSystem<T> {
    n: usize,
    rows: Vec<Row<T, f64, MAX_TERMS>>,
}

impl<T: Scalar> LinearSystem<T> {
    /// An empty system over `n` unknowns.
    pub fn new(n: usize) -> Self {
        Self { n, rows: Vec::new() }
    }

    /// Number of unknowns.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Adds `Σ coef·var = rhs` with weight `w`; fixed variables move to the
    /// right side. At most [`MAX_TERMS`] free terms.
    pub fn push(&mut self, terms: &[(Var, T)], rhs: c64, weight: f64) {
        self.rows.extend(Row::new(terms, rhs, weight));
    }

    /// Assembles `A = Σ w c̄ cᵀ` (upper triangle) and `b = Σ w c̄ y`.
    pub fn normal_equations(&self) -> (UpperCsc<T>, Vec<c64>) {
        let mut entries = Vec::with_capacity(self.rows.len() * 6 + self.n);
        debug_assert!(self.rows.iter().all(|r| r.len <= MAX_TERMS));
        let mut b = vec![c64::new(0.0, 0.0); self.n];
        for row in &self.rows {
            for a in 0..row.len {
                let (i, ci) = (row.cols[a], row.coefs[a].conjugate().scale(row.weight));
                b[i] += ci.to_c64() * row.rhs;
                for k in 0..row.len {
                    let j = row.cols[k];
                    if i <= j {
                        entries.push((i, j, ci * row.coefs[k]));
                    }
                }
            }
        }
        (UpperCsc::from_triplets(self.n, &entries), b)
    }

    /// `Σ w c̄ (y − cᵀx)`: the normal-equation residual computed from the
    /// rows, not from the assembled `A` (see [`Self::solve`]).
    fn row_residual(&self, x: &[c64]) -> Vec<c64> {
        let mut g = vec![c64::new(0.0, 0.0); self.n];
        for r in &self.rows {
            let res = (r.rhs - r.lhs(x)) * r.weight;
            for k in 0..r.len {
                g[r.cols[k]] += r.coefs[k].conjugate().to_c64() * res;
            }
        }
        g
    }

    /// The weighted sum of squared residuals `Σ w |cᵀx − y|²` at `x`.
    pub fn cost(&self, x: &[c64]) -> f64 {
        self.rows
            .iter()
            .map(|r| r.weight * (r.lhs(x) - r.rhs).norm_sqr())
            .sum()
    }
}

impl LinearSystem<c64> {
    /// Least-squares solution by sparse Cholesky of the normal equations,
    /// corrected once with the residual of the rows (Björck's corrected
    /// semi-normal equations): forming `A = Σ w c̄ cᵀ` squares the
    /// conditioning, and paper A's triangles near a pole of ω are badly
    /// conditioned; the correction brings the error back to that of the rows.
    pub fn solve(&self, ordering: &Ordering) -> Result<Vec<c64>, FactorError> {
        let (a, b) = self.normal_equations();
        let mut f = SparseCholesky::new(&a, ordering)?;
        let mut x = f.solve(&b);
        let correction = f.solve(&self.row_residual(&x));
        for (xi, d) in x.iter_mut().zip(correction) {
            *xi += d;
        }
        Ok(x)
    }
}

impl LinearSystem<f64> {
    /// Least-squares solution; the real normal matrix is factorised once and
    /// solved for the real and imaginary parts together, then corrected as
    /// in the complex case.
    pub fn solve(&self, ordering: &Ordering) -> Result<Vec<c64>, FactorError> {
        let (a, b) = self.normal_equations();
        let mut f = SparseCholesky::new(&a, ordering)?;
        let mut x = f.solve_complex(&b);
        let correction = f.solve_complex(&self.row_residual(&x));
        for (xi, d) in x.iter_mut().zip(correction) {
            *xi += d;
        }
        Ok(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn least_squares_of_an_overdetermined_system() {
        // x0 = 1, x1 - x0 = 1, x1 = 3 (weight 2): normal equations give
        // [2 -1; -1 3] x = [0, 7] → x = (7/5, 14/5).
        let mut s = LinearSystem::<f64>::new(2);
        let one = c64::new(1.0, 0.0);
        s.push(&[(Var::Free(0), 1.0)], one, 1.0);
        s.push(&[(Var::Free(1), 1.0), (Var::Free(0), -1.0)], one, 1.0);
        s.push(&[(Var::Free(1), 1.0)], c64::new(3.0, 0.0), 2.0);
        let x = s.solve(&Ordering::Amd).unwrap();
        assert!((x[0] - c64::new(7.0 / 5.0, 0.0)).norm() < 1e-12, "{x:?}");
        assert!((x[1] - c64::new(14.0 / 5.0, 0.0)).norm() < 1e-12, "{x:?}");
    }

    #[test]
    fn fixed_terms_move_to_the_right_side() {
        let mut s = LinearSystem::<c64>::new(1);
        let z = c64::from_polar(1.0, 0.3);
        s.push(
            &[
                (Var::Free(0), c64::new(1.0, 0.0)),
                (Var::Fixed(c64::new(2.0, 0.0)), -z),
            ],
            c64::new(0.0, 0.0),
            1.0,
        );
        let x = s.solve(&Ordering::Amd).unwrap();
        assert!((x[0] - 2.0 * z).norm() < 1e-12);
    }
}
