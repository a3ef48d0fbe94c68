//! [`PlanarSystem`]: weighted equations over planar points with a full 2×2
//! weight per row, solved as a real system of twice the size.
//!
//! A row says `Σ_k c_k p_k = y` with complex `c_k` (a rotation and scale,
//! the 2×2 block `C = [[Re c, −Im c], [Im c, Re c]]`) and an SPD weight `W`.
//! The normal equations are `A_kl = Σ C_kᵀ W C_l`, `b_k = Σ C_kᵀ W y`. This
//! is what the position stage needs when an edge's translation information
//! is anisotropic: a scalar weight cannot express it (on Carlone's Intel a
//! scalar weight gives χ² = 2.2·10⁷, the full weight 221).

use super::system::{Row, Var};
use crate::sparse::{FactorError, Ordering, SparseCholesky, UpperCsc};
use faer::c64;
use nalgebra::{Matrix2, Vector2};

/// Most free terms a planar row holds.
const PLANAR_TERMS: usize = 3;

/// Weighted planar rows over `n` unknown points.
#[derive(Clone, Debug)]
pub struct PlanarSystem {
    n: usize,
    rows: Vec<Row<c64, Matrix2<f64>, PLANAR_TERMS>>,
}

fn block(c: c64) -> Matrix2<f64> {
    Matrix2::new(c.re, -c.im, c.im, c.re)
}

impl PlanarSystem {
    /// An empty system over `n` unknown points.
    pub fn new(n: usize) -> Self {
        Self { n, rows: Vec::new() }
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.rows.len()
    }

    /// True when there are no rows.
    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Adds `Σ c·var = rhs` with weight matrix `weight` (SPD, in the frame
    /// of the residual); fixed variables move to the right side. At most
    /// three free terms.
    pub fn push(&mut self, terms: &[(Var, c64)], rhs: c64, weight: Matrix2<f64>) {
        self.rows.extend(Row::new(terms, rhs, weight));
    }

    /// The real normal equations over `2n` unknowns `[x_0, y_0, x_1, …]`.
    pub fn normal_equations(&self) -> (UpperCsc<f64>, Vec<f64>) {
        let mut entries = Vec::with_capacity(self.rows.len() * 14 + 2 * self.n);
        let mut b = vec![0.0; 2 * self.n];
        for row in &self.rows {
            let y = Vector2::new(row.rhs.re, row.rhs.im);
            for a in 0..row.len {
                let ctw = block(row.coefs[a]).transpose() * row.weight;
                let ba = ctw * y;
                let ia = 2 * row.cols[a];
                b[ia] += ba[0];
                b[ia + 1] += ba[1];
                for k in 0..row.len {
                    let blk = ctw * block(row.coefs[k]);
                    let ik = 2 * row.cols[k];
                    for (r, c) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
                        if ia + r <= ik + c {
                            entries.push((ia + r, ik + c, blk[(r, c)]));
                        }
                    }
                }
            }
        }
        (UpperCsc::from_triplets(2 * self.n, &entries), b)
    }

    /// Least-squares solution; `ordering` is over the `2n` real unknowns.
    pub fn solve(&self, ordering: &Ordering) -> Result<Vec<c64>, FactorError> {
        let (a, b) = self.normal_equations();
        let x = SparseCholesky::new(&a, ordering)?.solve(&b);
        Ok((0..self.n).map(|k| c64::new(x[2 * k], x[2 * k + 1])).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn anisotropic_weight_picks_the_trusted_direction() {
        // Two measurements of one point: (1, 0) trusted in x only and (0, 1)
        // trusted in y only. The weighted solution is (1, 1).
        let mut s = PlanarSystem::new(1);
        let one = c64::new(1.0, 0.0);
        s.push(
            &[(Var::Free(0), one)],
            c64::new(1.0, 0.0),
            Matrix2::new(1e6, 0.0, 0.0, 1.0),
        );
        s.push(
            &[(Var::Free(0), one)],
            c64::new(0.0, 1.0),
            Matrix2::new(1.0, 0.0, 0.0, 1e6),
        );
        let p = s.solve(&Ordering::BlockAmd(2)).unwrap()[0];
        assert!((p - c64::new(1.0, 1.0)).norm() < 1e-5, "{p}");
    }

    #[test]
    fn complex_coefficients_rotate() {
        // i · p = (0, 2) → p = (2, 0)
        let mut s = PlanarSystem::new(1);
        s.push(
            &[(Var::Free(0), c64::new(0.0, 1.0))],
            c64::new(0.0, 2.0),
            Matrix2::identity(),
        );
        let p = s.solve(&Ordering::BlockAmd(2)).unwrap()[0];
        assert!((p - c64::new(2.0, 0.0)).norm() < 1e-12, "{p}");
    }
}
