//! Property tests: every sequence of appends, updates and downdates keeps
//! `L D Lᴴ = A`, and the incremental solve matches a dense solve. Shared
//! here: random SPD starts and the dense comparison.

mod augmented;
mod solves;
mod updates;

use crate::sparse::{Scalar, UpperCsc};
use faer::c64;
use nalgebra::DMatrix;

trait FromParts: Scalar {
    fn from_parts(re: f64, im: f64) -> Self;
}
impl FromParts for f64 {
    fn from_parts(re: f64, _: f64) -> Self {
        re
    }
}
impl FromParts for c64 {
    fn from_parts(re: f64, im: f64) -> Self {
        c64::new(re, im)
    }
}

fn to_c(v: &[Vec<impl Scalar>]) -> DMatrix<c64> {
    DMatrix::from_fn(v.len(), v.len(), |i, j| v[i][j].to_c64())
}

/// A random sparse SPD start: diagonal plus a few rank-1 terms.
fn start<M: FromParts>(n: usize, seed: &[(usize, usize, f64, f64)]) -> (UpperCsc<M>, DMatrix<c64>) {
    let mut dense = DMatrix::<c64>::from_diagonal_element(n, n, c64::new(1.0, 0.0));
    for &(i, j, a, b) in seed {
        let (i, j) = (i % n, j % n);
        if i != j {
            let v = M::from_parts(a, b).to_c64();
            // A += e_i e_iᴴ + e_j e_jᴴ + v e_i e_jᴴ + conj(v) e_j e_iᴴ, kept PD by the diagonal
            dense[(i, i)] += c64::new(v.norm(), 0.0);
            dense[(j, j)] += c64::new(v.norm(), 0.0);
            dense[(i, j)] += v;
            dense[(j, i)] += v.conj();
        }
    }
    let mut entries = Vec::new();
    for c in 0..n {
        for r in 0..=c {
            let v = dense[(r, c)];
            if v.norm() > 0.0 {
                entries.push((r, c, M::from_parts(v.re, v.im)));
            }
        }
    }
    (UpperCsc::from_triplets(n, &entries), dense)
}

fn close(a: &DMatrix<c64>, b: &DMatrix<c64>, tol: f64) -> bool {
    let scale = a.iter().map(|v| v.norm()).fold(1.0, f64::max);
    a.iter().zip(b.iter()).all(|(x, y)| (x - y).norm() <= tol * scale)
}
