//! Sparse symmetric matrices and their Cholesky factors.
//!
//! - [`UpperCsc`]: a Hermitian matrix stored as its upper triangle, column by
//!   column, the layout faer's Cholesky reads.
//! - [`ordering`]: fill-reducing orderings (AMD through faer, expanded to
//!   blocks for the 3-variable poses of Gauss–Newton).
//! - [`SparseCholesky`]: faer's sparse LLᴴ with the symbolic analysis done
//!   once and reused while only the values change.
//! - [`dynamic`]: a factor that grows and changes in place (append,
//!   rank-1 update and downdate) with an incrementally maintained solve.

mod cholesky;
pub mod dynamic;
pub mod ordering;
mod scalar;
mod upper;

pub use cholesky::{FactorError, SparseCholesky};
pub use ordering::Ordering;
pub use scalar::Scalar;
pub use upper::UpperCsc;
