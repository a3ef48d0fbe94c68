//! The factor's storage, its construction from faer, and appending.

use super::runs::run_starts;
use super::scratch::WalkScratch;
use crate::sparse::{FactorError, Scalar, UpperCsc};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltError;
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::linalg::{SupernodalThreshold, SymbolicSupernodalParams};
use faer::{Par, Side, Spec};

/// One column of `L` below the diagonal.
#[derive(Clone, Debug, Default)]
pub(crate) struct Column<T> {
    pub(crate) rows: Vec<u32>,
    pub(crate) vals: Vec<T>,
    /// Where each run of consecutive rows starts (see `runs`); kept
    /// with `rows`.
    pub(crate) starts: Vec<u32>,
}

/// A sparse `L D Lᴴ` factor in the elimination order (column `k` is the
/// `k`-th variable eliminated).
#[derive(Clone, Debug, Default)]
pub struct DynamicLdlt<T> {
    pub(crate) cols: Vec<Column<T>>,
    pub(crate) d: Vec<f64>,
    pub(crate) children: Vec<Vec<u32>>,
    /// The update walks' working memory.
    pub(super) scratch: WalkScratch<T>,
    /// What the update walks have cost so far.
    pub(crate) walked: WalkStats,
    /// With a right-hand side, the last row and pivot of the factor of
    /// the augmented matrix (see [`DynamicLdlt::augment`]).
    pub(crate) augmented: Option<Augmented<T>>,
    /// Σ of the columns' row counts: [`Self::nnz`] without a scan (patterns
    /// only grow).
    pub(crate) stored: usize,
}

/// The last row of the factor of `[A b; bᴴ β]` = `[L 0; zᴴ 1]
/// diag(D, δ) [Lᴴ z; 0 1]`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Augmented<T> {
    /// `z = D⁻¹ L⁻¹ b`.
    pub(crate) z: Vec<T>,
    /// `δ = β − bᴴ A⁻¹ b`.
    pub(crate) pivot: f64,
}

/// Work counters of the update walks: columns stepped and the stored
/// entries of `L` they swept (a column's rows, once per walk).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WalkStats {
    /// Walks (calls of a rank-k update).
    pub walks: u64,
    /// Columns stepped.
    pub columns: u64,
    /// Entries of `L` swept.
    pub entries: u64,
}

impl<T: Scalar> DynamicLdlt<T> {
    /// An empty factor (no variables).
    pub fn new() -> Self {
        Self {
            cols: Vec::new(),
            d: Vec::new(),
            children: Vec::new(),
            scratch: WalkScratch::new(0),
            walked: WalkStats::default(),
            augmented: None,
            stored: 0,
        }
    }

    /// Factorises `P A Pᵀ` with faer's LDLᴴ, where `perm[k]` is the
    /// variable of `a` eliminated `k`-th. Column `k` of the result is
    /// variable `perm[k]`. Supernodal (about twice as fast as simplicial
    /// on pose graphs); fundamental supernodes only, so that the columns
    /// keep their exact patterns.
    pub fn from_matrix(a: &UpperCsc<T>, perm: &[usize]) -> Result<Self, FactorError> {
        Self::from_matrix_with(a, perm, SupernodalThreshold::FORCE_SUPERNODAL)
    }

    /// [`Self::from_matrix`] with faer's choice between simplicial and
    /// supernodal set by `threshold` (tests force each).
    pub(crate) fn from_matrix_with(
        a: &UpperCsc<T>,
        perm: &[usize],
        threshold: SupernodalThreshold,
    ) -> Result<Self, FactorError> {
        let n = a.n();
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: threshold,
            supernodal_params: SymbolicSupernodalParams { relax: None },
            ..Default::default()
        };
        // the engine assembles its systems already in elimination order;
        // faer then skips permuting a copy of `a` in both analyses
        let inv;
        let order = if perm.iter().enumerate().all(|(k, &i)| k == i) {
            SymmetricOrdering::Identity
        } else {
            inv = crate::sparse::ordering::invert(perm);
            SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(perm, &inv, n))
        };
        let symbolic = factorize_symbolic_cholesky(a.symbolic(), Side::Upper, order, params)
            .map_err(|_| FactorError::Symbolic)?;
        let mut values = vec![T::default(); symbolic.len_val()];
        let req = symbolic.factorize_numeric_ldlt_scratch::<T>(Par::Seq, Spec::default());
        let mut buf = MemBuffer::new(req);
        symbolic
            .factorize_numeric_ldlt(
                &mut values,
                a.as_faer(),
                Side::Upper,
                LdltRegularization::default(),
                Par::Seq,
                MemStack::new(&mut buf),
                Spec::default(),
            )
            .map_err(|e| match e {
                LdltError::ZeroPivot { index } => FactorError::NotPositiveDefinite { step: index },
            })?;
        let mut f = Self::new();
        match symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(s) => {
                let (col_ptr, row_idx) = (s.col_ptr(), s.row_idx());
                for k in 0..n {
                    let (start, end) = (col_ptr[k], col_ptr[k + 1]);
                    // faer stores D_k as the first (diagonal) entry of column k
                    f.push_column(
                        k,
                        values[start].real(),
                        row_idx[start + 1..end].iter().map(|&r| r as u32).collect(),
                        values[start + 1..end].to_vec(),
                    )?;
                }
            }
            SymbolicCholeskyRaw::Supernodal(s) => {
                // supernode `s`: columns `begin..end`, a dense column-major
                // block whose rows are its own columns (D on the diagonal, L
                // below), then its pattern. Below the diagonal, column `c`
                // holds the rows `begin + c + 1..end` (one run) and then the
                // pattern, whose run starts are found once per supernode
                let (rows_at, vals_at, row_idx) = (s.col_ptr_for_row_idx(), s.col_ptr_for_val(), s.row_idx());
                let (mut pattern, mut pattern_starts) = (Vec::new(), Vec::new());
                f.cols.reserve(n);
                f.d.reserve(n);
                for (sn, (&begin, &end)) in s.supernode_begin().iter().zip(s.supernode_end()).enumerate() {
                    pattern.clear();
                    pattern.extend(row_idx[rows_at[sn]..rows_at[sn + 1]].iter().map(|&r| r as u32));
                    run_starts(&pattern, &mut pattern_starts);
                    let width = end - begin;
                    let height = width + pattern.len();
                    let block = &values[vals_at[sn]..vals_at[sn + 1]];
                    for c in 0..width {
                        let col = &block[c * height..(c + 1) * height];
                        let inner = width - c - 1;
                        let mut rows = Vec::with_capacity(inner + pattern.len());
                        rows.extend((begin + c + 1..end).map(|r| r as u32));
                        rows.extend_from_slice(&pattern);
                        // the pattern's first run continues the inner one
                        // when it starts at row `end`
                        let joined = inner > 0 && pattern.first() == Some(&(end as u32));
                        let mut starts = Vec::with_capacity(pattern_starts.len() + 1);
                        if inner > 0 {
                            starts.push(0);
                        }
                        let skip = usize::from(joined);
                        starts.extend(pattern_starts[skip..].iter().map(|&p| p + inner as u32));
                        debug_assert_eq!(starts, {
                            let mut check = Vec::new();
                            run_starts(&rows, &mut check);
                            check
                        });
                        f.push_column_with_starts(
                            begin + c,
                            col[c].real(),
                            rows,
                            col[c + 1..].to_vec(),
                            starts,
                        )?;
                    }
                }
            }
        }
        f.scratch = WalkScratch::new(n);
        f.rebuild_children();
        Ok(f)
    }

    /// Appends column `k` of a fresh factor, refusing a pivot that is not
    /// positive.
    fn push_column(&mut self, k: usize, d: f64, rows: Vec<u32>, vals: Vec<T>) -> Result<(), FactorError> {
        let mut starts = Vec::new();
        run_starts(&rows, &mut starts);
        self.push_column_with_starts(k, d, rows, vals, starts)
    }

    /// [`Self::push_column`] with the run starts of `rows` known.
    fn push_column_with_starts(
        &mut self,
        k: usize,
        d: f64,
        rows: Vec<u32>,
        vals: Vec<T>,
        starts: Vec<u32>,
    ) -> Result<(), FactorError> {
        if d.is_nan() || d <= 0.0 {
            return Err(FactorError::NotPositiveDefinite { step: k });
        }
        self.d.push(d);
        self.stored += rows.len();
        self.cols.push(Column { rows, vals, starts });
        Ok(())
    }

    /// Adds a variable as the last column, uncoupled, with `D = 0` until an
    /// update gives it weight. Returns its column.
    pub fn append(&mut self) -> usize {
        if let Some(a) = &mut self.augmented {
            a.z.push(T::default());
        }
        self.cols.push(Column::default());
        self.d.push(0.0);
        self.children.push(Vec::new());
        self.scratch.append();
        self.cols.len() - 1
    }

    /// Number of variables.
    pub fn len(&self) -> usize {
        self.cols.len()
    }

    /// Augments the factor with a right-hand side: it becomes the factor of
    /// `[A b; bᴴ β]`, whose last row `z = D⁻¹ L⁻¹ b` (a forward solve) and
    /// last pivot `δ = β − bᴴ A⁻¹ b` every later update keeps current, so
    /// that `x = A⁻¹ b = L⁻ᴴ z` needs only a back-substitution. A variable
    /// with a zero pivot gets `z = 0`.
    pub fn augment(&mut self, b: &[T], beta: f64) {
        assert_eq!(b.len(), self.len(), "one right-hand side entry per variable");
        let mut y = b.to_vec();
        let mut delta = beta;
        for j in 0..self.len() {
            let yj = y[j];
            let col = &self.cols[j];
            for (&r, &l) in col.rows.iter().zip(&col.vals) {
                y[r as usize] -= l * yj;
            }
            let d = self.d[j];
            y[j] = if d > 0.0 {
                delta -= yj.abs2() / d;
                yj.scale(1.0 / d)
            } else {
                T::default()
            };
        }
        self.augmented = Some(Augmented { z: y, pivot: delta });
    }

    /// `z = D⁻¹ L⁻¹ b`, the augmented row (empty before [`Self::augment`]).
    pub fn augmented_row(&self) -> &[T] {
        self.augmented.as_ref().map_or(&[], |a| &a.z)
    }

    /// `δ = β − bᴴ A⁻¹ b`, the augmented factor's last pivot: for least
    /// squares with `A = JᴴJ`, `b = −Jᴴr` and `β = rᴴr`, the cost the
    /// linear model predicts at its solution (0 before [`Self::augment`]).
    pub fn augmented_pivot(&self) -> f64 {
        self.augmented.as_ref().map_or(0.0, |a| a.pivot)
    }

    /// `β ← β + v`: a change of the cost alone, which moves `δ` by `v`.
    pub fn add_to_augmented_pivot(&mut self, v: f64) {
        if let Some(a) = &mut self.augmented {
            a.pivot += v;
        }
    }

    /// Asks the CPU to fetch the start of column `k` into cache: a walk
    /// touches each column of its path once, each in its own allocation,
    /// and waiting for those first lines cost more than sweeping them.
    #[inline]
    pub(crate) fn prefetch_column(&self, k: usize) {
        let c = &self.cols[k];
        prefetch(c.rows.as_ptr());
        prefetch(c.starts.as_ptr());
        prefetch(c.vals.as_ptr());
    }

    /// What the update walks on this factor have cost so far.
    pub fn walk_stats(&self) -> WalkStats {
        self.walked
    }

    /// True with no variables.
    pub fn is_empty(&self) -> bool {
        self.cols.is_empty()
    }

    /// Stored entries of `L` below the diagonal, in O(1).
    pub fn nnz(&self) -> usize {
        debug_assert_eq!(self.stored, self.cols.iter().map(|c| c.rows.len()).sum::<usize>());
        self.stored
    }

    /// `D_k`.
    pub fn d(&self, k: usize) -> f64 {
        self.d[k]
    }

    /// The parent of column `k` in the elimination tree: its first
    /// off-diagonal row.
    pub fn parent(&self, k: usize) -> Option<usize> {
        self.cols[k].rows.first().map(|&r| r as usize)
    }

    /// Children of column `k` in the elimination tree (unordered).
    pub fn children(&self, k: usize) -> &[u32] {
        &self.children[k]
    }

    /// Rows and values of column `k` of `L` below the diagonal.
    pub fn column(&self, k: usize) -> (&[u32], &[T]) {
        (&self.cols[k].rows, &self.cols[k].vals)
    }

    /// Column `k` with where its runs of consecutive rows start.
    pub(crate) fn column_runs(&self, k: usize) -> (&[u32], &[T], &[u32]) {
        let c = &self.cols[k];
        (&c.rows, &c.vals, &c.starts)
    }

    pub(crate) fn rebuild_children(&mut self) {
        // sized first: one allocation per column with children
        let mut count = vec![0u32; self.cols.len()];
        for k in 0..self.cols.len() {
            if let Some(p) = self.parent(k) {
                count[p] += 1;
            }
        }
        self.children = count.iter().map(|&c| Vec::with_capacity(c as usize)).collect();
        for k in 0..self.cols.len() {
            if let Some(p) = self.parent(k) {
                self.children[p].push(k as u32);
            }
        }
    }

    /// Moves column `k` from the children of `old` to those of its parent.
    pub(crate) fn reparent(&mut self, k: usize, old: Option<usize>) {
        let new = self.parent(k);
        if new == old {
            return;
        }
        if let Some(o) = old {
            let list = &mut self.children[o];
            if let Some(pos) = list.iter().position(|&c| c as usize == k) {
                list.swap_remove(pos);
            }
        }
        if let Some(p) = new {
            self.children[p].push(k as u32);
        }
    }

    /// `L D Lᴴ` as a dense row-major matrix (tests and small checks).
    pub fn to_dense(&self) -> Vec<Vec<T>> {
        let n = self.len();
        // column k of L, dense
        let l: Vec<Vec<T>> = (0..n)
            .map(|k| {
                let mut col = vec![T::default(); n];
                col[k] = T::from_real(1.0);
                for (&r, &v) in self.cols[k].rows.iter().zip(&self.cols[k].vals) {
                    col[r as usize] = v;
                }
                col
            })
            .collect();
        (0..n)
            .map(|i| {
                (0..n)
                    .map(|j| {
                        l.iter()
                            .zip(&self.d)
                            .take(i.min(j) + 1)
                            .fold(T::default(), |s, (lk, &dk)| {
                                s + lk[i] * lk[j].conjugate().scale(dk)
                            })
                    })
                    .collect()
            })
            .collect()
    }
}

/// A hint to bring the cache line at `p` in (no effect off x86-64).
#[inline(always)]
fn prefetch<P>(p: *const P) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is a hint; it never faults, whatever the address.
    unsafe {
        std::arch::x86_64::_mm_prefetch(p.cast::<i8>(), std::arch::x86_64::_MM_HINT_T0);
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}
