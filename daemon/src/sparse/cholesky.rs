//! [`SparseCholesky`]: faer's sparse `A = LLᴴ`, analysed once, refactorised
//! as the values change.

use super::ordering::{self, Ordering};
use super::{Scalar, UpperCsc};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::llt::factor::LltError;
use faer::linalg::cholesky::llt::factor::LltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LltRef, SymbolicCholesky, SymmetricOrdering,
};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::SymbolicSparseColMatRef;
use faer::{Conj, MatMut, Par, Side, Spec};
use std::fmt;

/// Why a matrix could not be factorised.
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum FactorError {
    /// A pivot was not positive: the matrix is singular or indefinite (an
    /// unconstrained variable, a disconnected graph, a NaN).
    NotPositiveDefinite {
        /// The elimination step at which it failed.
        step: usize,
    },
    /// The symbolic analysis failed (index overflow).
    Symbolic,
}

impl fmt::Display for FactorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FactorError::NotPositiveDefinite { step } => {
                write!(f, "normal equations are not positive definite (pivot {step})")
            }
            FactorError::Symbolic => f.write_str("symbolic Cholesky analysis failed"),
        }
    }
}

impl std::error::Error for FactorError {}

/// A sparse Cholesky factor whose pattern is fixed after [`Self::analyze`].
pub struct SparseCholesky<T> {
    symbolic: SymbolicCholesky<usize>,
    values: Vec<T>,
    buf: MemBuffer,
    factored: bool,
}

impl<T: Scalar> SparseCholesky<T> {
    /// Computes the ordering and the symbolic factor of `a`'s pattern;
    /// faer picks a simplicial or a supernodal factor.
    pub fn analyze(a: &UpperCsc<T>, ordering: &Ordering) -> Result<Self, FactorError> {
        Self::analyze_with(a, ordering, SupernodalThreshold::AUTO)
    }

    /// [`Self::analyze`] with a supernodal factor whatever faer's estimate:
    /// for Gauss–Newton systems, whose 3×3 pose blocks make supernodes.
    /// faer's estimate picks simplicial for some of them, where the
    /// supernodal factor makes a polish about 1.5× faster.
    pub fn analyze_supernodal(a: &UpperCsc<T>, ordering: &Ordering) -> Result<Self, FactorError> {
        Self::analyze_with(a, ordering, SupernodalThreshold::FORCE_SUPERNODAL)
    }

    fn analyze_with(
        a: &UpperCsc<T>,
        ordering: &Ordering,
        threshold: SupernodalThreshold,
    ) -> Result<Self, FactorError> {
        let perm = match ordering {
            Ordering::Amd => None,
            Ordering::Natural => Some((0..a.n()).collect::<Vec<_>>()),
            Ordering::Custom(p) => Some(p.clone()),
            Ordering::BlockAmd(size) => {
                let (cp, ri) = ordering::block_pattern(a.symbolic(), *size);
                let nb = cp.len() - 1;
                let blocks = SymbolicSparseColMatRef::new_checked(nb, nb, &cp, None, &ri);
                Some(ordering::expand_blocks(&ordering::amd(blocks), *size))
            }
        };
        let inv = perm.as_deref().map(ordering::invert);
        let ord = match (&perm, &inv) {
            (Some(p), Some(i)) => SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(p, i, a.n())),
            _ => SymmetricOrdering::Amd,
        };
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: threshold,
            ..Default::default()
        };
        let symbolic = factorize_symbolic_cholesky(a.symbolic(), Side::Upper, ord, params)
            .map_err(|_| FactorError::Symbolic)?;
        let req = symbolic.factorize_numeric_llt_scratch::<T>(Par::Seq, Spec::default());
        let req = req.or(symbolic.solve_in_place_scratch::<T>(2, Par::Seq));
        Ok(Self {
            values: vec![T::default(); symbolic.len_val()],
            buf: MemBuffer::new(req),
            symbolic,
            factored: false,
        })
    }

    /// Factorises `a`, which must have the pattern given to [`Self::analyze`].
    pub fn factorize(&mut self, a: &UpperCsc<T>) -> Result<(), FactorError> {
        self.factored = false;
        let result = self.symbolic.factorize_numeric_llt(
            &mut self.values,
            a.as_faer(),
            Side::Upper,
            LltRegularization::default(),
            Par::Seq,
            MemStack::new(&mut self.buf),
            Spec::default(),
        );
        match result {
            Ok(_) => {
                self.factored = true;
                Ok(())
            }
            Err(LltError::NonPositivePivot { index }) => {
                Err(FactorError::NotPositiveDefinite { step: index })
            }
        }
    }

    /// Analyses and factorises in one call.
    pub fn new(a: &UpperCsc<T>, ordering: &Ordering) -> Result<Self, FactorError> {
        let mut f = Self::analyze(a, ordering)?;
        f.factorize(a)?;
        Ok(f)
    }

    /// Solves `A X = B` in place for up to two right-hand-side columns.
    ///
    /// # Panics
    /// If called before a successful [`Self::factorize`].
    pub fn solve_in_place(&mut self, rhs: MatMut<'_, T>) {
        assert!(self.factored, "solve before a successful factorisation");
        assert!(rhs.ncols() <= 2);
        LltRef::new(&self.symbolic, &self.values).solve_in_place_with_conj(
            Conj::No,
            rhs,
            Par::Seq,
            MemStack::new(&mut self.buf),
        );
    }

    /// Solves `A x = b`.
    pub fn solve(&mut self, b: &[T]) -> Vec<T> {
        let mut x = faer::Mat::<T>::from_fn(b.len(), 1, |i, _| b[i]);
        self.solve_in_place(x.as_mut());
        (0..b.len()).map(|i| x[(i, 0)]).collect()
    }

    /// Number of stored values of the factor.
    pub fn factor_len(&self) -> usize {
        self.symbolic.len_val()
    }

    /// The symbolic analysis (ordering and pattern of L).
    pub fn symbolic(&self) -> &SymbolicCholesky<usize> {
        &self.symbolic
    }
}

impl SparseCholesky<f64> {
    /// Solves the real system for a complex right-hand side, as two real
    /// columns: the position stage's real Laplacian with complex positions.
    pub fn solve_complex(&mut self, b: &[faer::c64]) -> Vec<faer::c64> {
        let mut x = faer::Mat::<f64>::from_fn(b.len(), 2, |i, j| if j == 0 { b[i].re } else { b[i].im });
        self.solve_in_place(x.as_mut());
        (0..b.len())
            .map(|i| faer::c64::new(x[(i, 0)], x[(i, 1)]))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::c64;

    fn tridiagonal<T: Scalar>(n: usize, off: T) -> UpperCsc<T> {
        let mut e = Vec::new();
        for i in 0..n {
            e.push((i, i, T::from_real(4.0)));
            if i + 1 < n {
                e.push((i, i + 1, off));
            }
        }
        UpperCsc::from_triplets(n, &e)
    }

    #[test]
    fn solves_real_and_complex_systems_with_every_ordering() {
        for ord in [
            Ordering::Amd,
            Ordering::Natural,
            Ordering::BlockAmd(2),
            Ordering::Custom(vec![3, 1, 0, 2, 5, 4]),
        ] {
            let a = tridiagonal(6, c64::new(1.0, -0.5));
            let x: Vec<c64> = (0..6).map(|i| c64::new(i as f64, 1.0 - i as f64)).collect();
            let b = a.mul_vec(&x);
            let got = SparseCholesky::new(&a, &ord).unwrap().solve(&b);
            for (g, w) in got.iter().zip(&x) {
                assert!((g - w).norm() < 1e-12, "{ord:?}: {g} vs {w}");
            }
            let r = tridiagonal(6, -1.0);
            let xr: Vec<c64> = (0..6).map(|i| c64::new(1.0, i as f64)).collect();
            let br: Vec<c64> = {
                let re = r.mul_vec(&xr.iter().map(|v| v.re).collect::<Vec<_>>());
                let im = r.mul_vec(&xr.iter().map(|v| v.im).collect::<Vec<_>>());
                re.into_iter().zip(im).map(|(a, b)| c64::new(a, b)).collect()
            };
            let got = SparseCholesky::new(&r, &ord).unwrap().solve_complex(&br);
            for (g, w) in got.iter().zip(&xr) {
                assert!((g - w).norm() < 1e-12);
            }
        }
    }

    /// A chain of 3×3 blocks (a pose graph's shape) factorised supernodal
    /// solves as the default does.
    #[test]
    fn the_supernodal_factor_solves_a_block_chain() {
        let n = 3 * 40;
        let mut e = Vec::new();
        for i in 0..n {
            e.push((i, i, 6.0 + (i % 5) as f64));
            for j in i + 1..n.min(i / 3 * 3 + 6) {
                e.push((i, j, -0.5 + 0.01 * (i + j) as f64));
            }
        }
        let a = UpperCsc::from_triplets(n, &e);
        let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let b = a.mul_vec(&x);
        let mut f = SparseCholesky::analyze_supernodal(&a, &Ordering::Amd).unwrap();
        let raw = f.symbolic().raw();
        assert!(matches!(
            raw,
            faer::sparse::linalg::cholesky::SymbolicCholeskyRaw::Supernodal(_)
        ));
        f.factorize(&a).unwrap();
        for (g, w) in f.solve(&b).iter().zip(&x) {
            assert!((g - w).abs() < 1e-12, "{g} vs {w}");
        }
    }

    #[test]
    fn reports_a_singular_matrix() {
        let a = UpperCsc::from_triplets(2, &[(0, 0, 1.0), (0, 1, 1.0), (1, 1, 1.0)]);
        assert!(matches!(
            SparseCholesky::new(&a, &Ordering::Natural),
            Err(FactorError::NotPositiveDefinite { .. })
        ));
    }
}
