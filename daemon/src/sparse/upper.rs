//! [`UpperCsc`]: the upper triangle of a Hermitian matrix in compressed
//! sparse columns, rows sorted within each column.

use super::Scalar;
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};

/// Upper triangle (diagonal included) of an `n × n` Hermitian matrix.
#[derive(Clone, Debug, Default)]
pub struct UpperCsc<T> {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    values: Vec<T>,
}

impl<T: Scalar> UpperCsc<T> {
    /// Builds the matrix from `(row, col, value)` entries with `row ≤ col`,
    /// summing duplicates. Runs in O(n + entries · log(column length)).
    pub fn from_triplets(n: usize, entries: &[(usize, usize, T)]) -> Self {
        let mut count = vec![0usize; n + 1];
        for &(r, c, _) in entries {
            debug_assert!(
                r <= c && c < n,
                "entry ({r}, {c}) outside the upper triangle of {n}"
            );
            count[c + 1] += 1;
        }
        for c in 0..n {
            count[c + 1] += count[c];
        }
        let mut next = count.clone();
        let mut bucket = vec![(0usize, T::default()); entries.len()];
        for &(r, c, v) in entries {
            bucket[next[c]] = (r, v);
            next[c] += 1;
        }
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::with_capacity(entries.len());
        let mut values = Vec::with_capacity(entries.len());
        col_ptr.push(0);
        for c in 0..n {
            let col = &mut bucket[count[c]..count[c + 1]];
            col.sort_unstable_by_key(|&(r, _)| r);
            let start = row_idx.len();
            for &(r, v) in col.iter() {
                if row_idx.len() > start && row_idx[row_idx.len() - 1] == r {
                    let last = values.len() - 1;
                    values[last] += v;
                } else {
                    row_idx.push(r);
                    values.push(v);
                }
            }
            col_ptr.push(row_idx.len());
        }
        Self {
            n,
            col_ptr,
            row_idx,
            values,
        }
    }

    /// A pattern with zero values from its compressed columns: `col_ptr`
    /// has `n + 1` offsets into `row_idx`, whose rows are sorted within
    /// each column and `≤` its index.
    pub fn from_parts(n: usize, col_ptr: Vec<usize>, row_idx: Vec<usize>) -> Self {
        assert_eq!(col_ptr.len(), n + 1);
        assert_eq!(col_ptr[n], row_idx.len());
        debug_assert!((0..n).all(|c| {
            let rows = &row_idx[col_ptr[c]..col_ptr[c + 1]];
            rows.windows(2).all(|w| w[0] < w[1]) && rows.last().is_none_or(|&r| r <= c)
        }));
        let values = vec![T::default(); row_idx.len()];
        Self {
            n,
            col_ptr,
            row_idx,
            values,
        }
    }

    /// The same pattern with other values; `values` must match [`Self::nnz`].
    pub fn with_values<U: Scalar>(&self, values: Vec<U>) -> UpperCsc<U> {
        assert_eq!(values.len(), self.values.len());
        UpperCsc {
            n: self.n,
            col_ptr: self.col_ptr.clone(),
            row_idx: self.row_idx.clone(),
            values,
        }
    }

    /// Dimension.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Stored entries.
    pub fn nnz(&self) -> usize {
        self.row_idx.len()
    }

    /// Column pointers (length `n + 1`).
    pub fn col_ptr(&self) -> &[usize] {
        &self.col_ptr
    }

    /// Row indices, sorted within each column.
    pub fn row_idx(&self) -> &[usize] {
        &self.row_idx
    }

    /// The stored values.
    pub fn values(&self) -> &[T] {
        &self.values
    }

    /// Mutable values, for refilling the same pattern.
    pub fn values_mut(&mut self) -> &mut [T] {
        &mut self.values
    }

    /// Position of entry `(row, col)`, `row ≤ col`, in [`Self::values`].
    pub fn slot(&self, row: usize, col: usize) -> Option<usize> {
        let range = self.col_ptr[col]..self.col_ptr[col + 1];
        self.row_idx[range.clone()]
            .binary_search(&row)
            .ok()
            .map(|k| range.start + k)
    }

    /// Positions of the diagonal entries (every column must store one).
    pub fn diagonal_slots(&self) -> Vec<usize> {
        (0..self.n)
            .map(|c| {
                let s = self.col_ptr[c + 1] - 1;
                debug_assert!(self.row_idx[s] == c, "column {c} has no diagonal entry");
                s
            })
            .collect()
    }

    /// faer's view of the pattern.
    pub fn symbolic(&self) -> SymbolicSparseColMatRef<'_, usize> {
        SymbolicSparseColMatRef::new_checked(self.n, self.n, &self.col_ptr, None, &self.row_idx)
    }

    /// faer's view of the matrix.
    pub fn as_faer(&self) -> SparseColMatRef<'_, usize, T> {
        SparseColMatRef::new(self.symbolic(), &self.values)
    }

    /// `y = A x` using both triangles (tests and residual checks).
    pub fn mul_vec(&self, x: &[T]) -> Vec<T> {
        let mut y = vec![T::default(); self.n];
        for c in 0..self.n {
            for k in self.col_ptr[c]..self.col_ptr[c + 1] {
                let r = self.row_idx[k];
                let v = self.values[k];
                y[r] += v * x[c];
                if r != c {
                    y[c] += v.conjugate() * x[r];
                }
            }
        }
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sums_duplicates_and_sorts_rows() {
        let a = UpperCsc::from_triplets(
            3,
            &[(1, 2, 1.0), (0, 2, 2.0), (1, 2, 3.0), (0, 0, 5.0), (2, 2, 1.0)],
        );
        assert_eq!(a.col_ptr(), &[0, 1, 1, 4]);
        assert_eq!(a.row_idx(), &[0, 0, 1, 2]);
        assert_eq!(a.values(), &[5.0, 2.0, 4.0, 1.0]);
        assert_eq!(a.slot(1, 2), Some(2));
        assert_eq!(a.slot(1, 1), None);
        assert_eq!(a.mul_vec(&[1.0, 1.0, 1.0]), vec![7.0, 4.0, 7.0]);
    }
}
