//! [`Marginal`]: `Vᵀ A⁻¹ V` for up to `N` sparse vectors, read off the
//! factor.
//!
//! With `A = L D Lᵀ`, `Vᵀ A⁻¹ V = Yᵀ D⁻¹ Y` where `Y = L⁻¹ V`. The pattern
//! of `Y` is the union of the elimination-tree paths from the nonzeros of
//! `V` to the root (the rows of a column are its ancestors), so the forward
//! solve runs over those columns only, in ascending order: the cost of one
//! update's walk, with nothing written to the factor. The engine uses it
//! for the covariance `J Σ Jᵀ` of an edge's predicted error (`Σ = H⁻¹`,
//! `N` = 6) and for the marginal covariance of one or two poses (`V` their
//! unit vectors, `N` = 12).

use super::DynamicLdlt;
use nalgebra::SMatrix;

/// Scratch for [`Marginal::form`], kept between calls (dense per column,
/// zero outside a call), for up to `N` vectors.
#[derive(Clone, Debug)]
pub struct Marginal<const N: usize = 6> {
    y: Vec<[f64; N]>,
    on_path: Vec<bool>,
    path: Vec<usize>,
}

impl<const N: usize> Default for Marginal<N> {
    fn default() -> Self {
        Self {
            y: Vec::new(),
            on_path: Vec::new(),
            path: Vec::new(),
        }
    }
}

impl<const N: usize> Marginal<N> {
    /// `Vᵀ A⁻¹ V`, where `v[r]` lists the nonzeros `(column, value)` of
    /// vector `r` (at most `N`); the result fills the top-left `v.len()`
    /// square. `None` when a pivot on the path is zero while `Y` is not (a
    /// variable with no weight: infinite variance).
    pub fn form(&mut self, factor: &DynamicLdlt<f64>, v: &[&[(usize, f64)]]) -> Option<SMatrix<f64, N, N>> {
        assert!(v.len() <= N, "at most {N} vectors");
        let (n, m) = (factor.len(), v.len());
        if self.y.len() < n {
            self.y.resize(n, [0.0; N]);
            self.on_path.resize(n, false);
        }
        self.path.clear();
        for (r, w) in v.iter().enumerate() {
            for &(c, value) in w.iter() {
                self.y[c][r] += value;
                let mut k = Some(c);
                while let Some(j) = k.filter(|&j| !self.on_path[j]) {
                    self.on_path[j] = true;
                    self.path.push(j);
                    k = factor.parent(j);
                }
            }
        }
        self.path.sort_unstable();
        let mut form = Some(SMatrix::<f64, N, N>::zeros());
        for &j in &self.path {
            let y = self.y[j];
            if y[..m].iter().all(|&v| v == 0.0) {
                continue;
            }
            let d = factor.d(j);
            if d <= 0.0 {
                form = None;
                break;
            }
            if let Some(f) = form.as_mut() {
                for a in 0..m {
                    for b in 0..m {
                        f[(a, b)] += y[a] * y[b] / d;
                    }
                }
            }
            let (rows, vals) = factor.column(j);
            for (&i, &l) in rows.iter().zip(vals) {
                let yi = &mut self.y[i as usize];
                for r in 0..m {
                    yi[r] -= l * y[r];
                }
            }
        }
        // every row written is an ancestor of a path column, so on the path
        for &j in &self.path {
            self.y[j] = [0.0; N];
            self.on_path[j] = false;
        }
        form
    }
}
