//! [`Scalar`]: the two fields slamd solves in, `f64` and complex `c64`.

use faer::c64;
use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, Mul, MulAssign, Neg, Sub, SubAssign};

/// A real or complex scalar. Complex systems are Hermitian: the normal
/// matrix of weighted rows `c` is `Σ w c̄ cᵀ`.
pub trait Scalar:
    faer::traits::ComplexField
    + Copy
    + Debug
    + Default
    + PartialEq
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
{
    /// Complex conjugate (identity for reals).
    fn conjugate(self) -> Self;
    /// `|x|²`.
    fn abs2(self) -> f64;
    /// Embeds a real number.
    fn from_real(x: f64) -> Self;
    /// Real part.
    fn real(self) -> f64;
    /// Widens to a complex number.
    fn to_c64(self) -> c64;
    /// Multiplies by a real number.
    fn scale(self, r: f64) -> Self;
    /// One column step of a multiple-rank update over every run of a
    /// column, `runs` = (rows, run starts) (see `sparse::dynamic::runs`);
    /// reals take a vectorised path when the CPU has one.
    #[inline]
    fn rank_runs(w: &mut [&mut [Self]], runs: (&[u32], &[u32]), l: &mut [Self], p: &[Self], g: &[Self]) {
        crate::sparse::dynamic::runs::rank_runs_generic(w, runs, l, p, g)
    }
    /// The same step over a column whose runs are short, row by row at
    /// `rows`; reals take a path with fused multiply-adds when the CPU has
    /// them.
    #[inline]
    fn rank_rows(w: &mut [&mut [Self]], rows: &[u32], l: &mut [Self], p: &[Self], g: &[Self]) {
        crate::sparse::dynamic::runs::rank_rows_generic(w, rows, l, p, g)
    }
    /// `Σ_r x_r conj(L_rj)` over a column, `column` = (rows, values, run
    /// starts): the back-substitution's sum; reals take a path with fused
    /// multiply-adds when the CPU has them.
    #[inline]
    fn dot_runs(x: &[Self], column: (&[u32], &[Self], &[u32])) -> Self {
        crate::sparse::dynamic::runs::gather_dot(x, column)
    }
}

impl Scalar for f64 {
    #[inline]
    fn conjugate(self) -> Self {
        self
    }
    #[inline]
    fn abs2(self) -> f64 {
        self * self
    }
    #[inline]
    fn from_real(x: f64) -> Self {
        x
    }
    #[inline]
    fn real(self) -> f64 {
        self
    }
    #[inline]
    fn to_c64(self) -> c64 {
        c64::new(self, 0.0)
    }
    #[inline]
    fn scale(self, r: f64) -> Self {
        self * r
    }
    #[inline]
    fn rank_runs(w: &mut [&mut [Self]], runs: (&[u32], &[u32]), l: &mut [Self], p: &[Self], g: &[Self]) {
        #[cfg(target_arch = "x86_64")]
        if avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA
            return unsafe { crate::sparse::dynamic::runs::rank_runs_fma(w, runs, l, p, g) };
        }
        crate::sparse::dynamic::runs::rank_runs_generic(w, runs, l, p, g)
    }
    #[inline]
    fn rank_rows(w: &mut [&mut [Self]], rows: &[u32], l: &mut [Self], p: &[Self], g: &[Self]) {
        #[cfg(target_arch = "x86_64")]
        if avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA
            return unsafe { crate::sparse::dynamic::runs::rank_rows_fma(w, rows, l, p, g) };
        }
        crate::sparse::dynamic::runs::rank_rows_generic(w, rows, l, p, g)
    }
    #[inline]
    fn dot_runs(x: &[Self], column: (&[u32], &[Self], &[u32])) -> Self {
        #[cfg(target_arch = "x86_64")]
        if avx2_fma() {
            // SAFETY: the CPU has AVX2 and FMA
            return unsafe { crate::sparse::dynamic::runs::gather_dot_fma(x, column) };
        }
        crate::sparse::dynamic::runs::gather_dot(x, column)
    }
}

impl Scalar for c64 {
    #[inline]
    fn conjugate(self) -> Self {
        self.conj()
    }
    #[inline]
    fn abs2(self) -> f64 {
        self.norm_sqr()
    }
    #[inline]
    fn from_real(x: f64) -> Self {
        c64::new(x, 0.0)
    }
    #[inline]
    fn real(self) -> f64 {
        self.re
    }
    #[inline]
    fn to_c64(self) -> c64 {
        self
    }
    #[inline]
    fn scale(self, r: f64) -> Self {
        self * r
    }
}

/// Whether this CPU has AVX2 and FMA, the fast path of the update
/// kernels and of the back-substitution's sum (`std` caches the answer).
#[cfg(target_arch = "x86_64")]
#[inline]
fn avx2_fma() -> bool {
    std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
}
