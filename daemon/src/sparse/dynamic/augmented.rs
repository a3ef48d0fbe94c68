//! [`AugmentedCholesky`]: `x = A⁻¹ b` kept current on an augmented factor.
//!
//! The factor of `[A b; bᴴ β]` carries `z = D⁻¹ L⁻¹ b` in its last row
//! ([`DynamicLdlt::augment`]), and every update walk keeps `z` current on
//! its own path, so there is no separate forward pass: the right-hand side
//! changes only through the updates' tails. What is left is the
//! back-substitution `x = L⁻ᴴ z`, recomputed from the roots down starting
//! at the columns the walks touched (iSAM2's wildfire): a column whose `x`
//! moved by at most the threshold does not pass the change on to its
//! subtree. That is an approximation, since a child also depends on
//! ancestors above its parent; a threshold of 0 visits every subtree under
//! a touched column and is exact.
//!
//! The augmented pivot `δ = β − bᴴ A⁻¹ b` is the least-squares cost at the
//! solution, kept by the same walks.

use super::factor::DynamicLdlt;
use super::solve::wildfire;
use super::update::UpdateError;
use crate::sparse::Scalar;

/// An augmented dynamic factor and the solution it gives.
#[derive(Clone, Debug)]
pub struct AugmentedCholesky<T> {
    factor: DynamicLdlt<T>,
    x: Vec<T>,
    touched: Vec<bool>,
    touched_list: Vec<usize>,
    queued: Vec<bool>,
    changed: Vec<usize>,
    solved: SolveStats,
}

/// Work counters of the incremental solves.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SolveStats {
    /// Solves.
    pub solves: u64,
    /// Columns the walks touched, back-substituted because they changed.
    pub touched: u64,
    /// Columns back-substituted in all (touched, and reached by the
    /// wildfire below them).
    pub visited: u64,
    /// Entries of `L` those back-substitutions read.
    pub entries: u64,
}

impl<T: Scalar> AugmentedCholesky<T> {
    /// Augments `factor` (of `A`) with `b` and `β`, and solves.
    pub fn new(mut factor: DynamicLdlt<T>, b: &[T], beta: f64) -> Self {
        factor.augment(b, beta);
        let n = factor.len();
        let mut s = Self {
            factor,
            x: vec![T::default(); n],
            touched: vec![false; n],
            touched_list: Vec::new(),
            queued: vec![false; n],
            changed: Vec::new(),
            solved: SolveStats::default(),
        };
        s.solve_full();
        s
    }

    /// An empty system (no variables, `β = 0`).
    pub fn empty() -> Self {
        Self::new(DynamicLdlt::new(), &[], 0.0)
    }

    /// The factor.
    pub fn factor(&self) -> &DynamicLdlt<T> {
        &self.factor
    }

    /// The solution of the last solve, in the factor's order.
    pub fn x(&self) -> &[T] {
        &self.x
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// What the incremental solves have cost so far.
    pub fn solve_stats(&self) -> SolveStats {
        self.solved
    }

    /// True with no variables.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// `δ = β − bᴴ A⁻¹ b`: for least squares, the cost the linear model
    /// predicts at its solution.
    pub fn residual(&self) -> f64 {
        self.factor.augmented_pivot()
    }

    /// Adds a variable as the last column (no coupling, `b = 0`, `x = 0`).
    pub fn append(&mut self) -> usize {
        self.x.push(T::default());
        self.touched.push(false);
        self.queued.push(false);
        self.factor.append()
    }

    /// `β ← β + v`, with `A` and `b` unchanged.
    pub fn add_cost(&mut self, v: f64) {
        self.factor.add_to_augmented_pivot(v);
    }

    /// `[A b; bᴴ β] ← [A b; bᴴ β] + σ Σ_t [w_t; tail_t][w_t; tail_t]ᴴ` in
    /// one walk (at most `MAX_RANK` vectors). On error the factor must be
    /// rebuilt.
    pub fn rank_k(&mut self, ws: &[&[(usize, T)]], tails: &[T], sigma: f64) -> Result<(), UpdateError> {
        let (touched, list) = (&mut self.touched, &mut self.touched_list);
        self.factor.rank_k_augmented(ws, tails, sigma, |j, _| {
            if !touched[j] {
                touched[j] = true;
                list.push(j);
            }
        })
    }

    /// Brings `x` up to date. Columns whose `x` moved by at most `threshold`
    /// do not pass the change on to their subtrees; with 0 every subtree
    /// under a touched column is recomputed (exact). Returns the columns
    /// whose `x` changed.
    pub fn solve(&mut self, threshold: f64) -> &[usize] {
        // the touched set, closed under ancestors in the current tree
        let mut k = 0;
        while k < self.touched_list.len() {
            if let Some(p) = self.factor.parent(self.touched_list[k]) {
                if !self.touched[p] {
                    self.touched[p] = true;
                    self.touched_list.push(p);
                }
            }
            k += 1;
        }
        self.solved.solves += 1;
        self.solved.touched += self.touched_list.len() as u64;
        for &j in &self.touched_list {
            self.touched[j] = false;
        }
        let (factor, solved) = (&self.factor, &mut self.solved);
        wildfire(
            factor,
            &self.touched_list,
            threshold,
            (&mut self.x, &mut self.queued, &mut self.changed),
            |j, x| {
                solved.visited += 1;
                solved.entries += factor.column(j).0.len() as u64;
                back_substitute(factor, x, j)
            },
        );
        self.touched_list.clear();
        &self.changed
    }

    /// Recomputes `x` from `z` everywhere.
    pub fn solve_full(&mut self) {
        for j in (0..self.len()).rev() {
            self.x[j] = back_substitute(&self.factor, &self.x, j);
        }
        for &j in &self.touched_list {
            self.touched[j] = false;
        }
        self.touched_list.clear();
    }
}

/// `x_j = z_j − Σ_i conj(L_ij) x_i`; an unconstrained variable (`d_j = 0`)
/// stays at 0.
fn back_substitute<T: Scalar>(factor: &DynamicLdlt<T>, x: &[T], j: usize) -> T {
    if factor.d(j) <= 0.0 {
        return T::default();
    }
    factor.augmented_row()[j] - T::dot_runs(x, factor.column_runs(j))
}
