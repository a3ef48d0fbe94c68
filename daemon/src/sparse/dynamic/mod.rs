//! [`DynamicLdlt`]: a sparse `A = L D Lᴴ` that changes shape and values in
//! place, for the incremental engine.
//!
//! faer 0.24 factorises from scratch only; this module adds what an online
//! solver needs:
//! - [`DynamicLdlt::append`] adds a variable as the last column;
//! - [`update`](DynamicLdlt::rank_k_with) applies `A ← A ± w wᴴ` by Davis and
//!   Hager's row modification, touching only the elimination-tree path of
//!   `w` and growing the pattern along it;
//! - [`IncrementalCholesky`] keeps `x = A⁻¹ b` current after such changes,
//!   re-solving only the affected paths and subtrees;
//! - [`AugmentedCholesky`] does the same on the factor of `[A b; bᴴ β]`,
//!   where the updates carry the right-hand side and the forward solve rides
//!   along their walks (the Gauss–Newton system, whose `b` changes only with
//!   its updates);
//! - [`Marginal`] reads `Vᵀ A⁻¹ V` for a pose's sparse vectors off the paths
//!   of their columns (an edge's predicted-error covariance).
//!
//! Columns are stored one per `Vec` (rows sorted, strictly below the
//! diagonal), so that fill can grow any column, with where their runs of
//! consecutive rows start: near the root the columns are nearly dense, and
//! the inner loops run over those runs as slices (module `runs`). `L` is
//! unit lower triangular and `D` real positive. A fresh factor comes from
//! faer's LDLᴴ, simplicial or supernodal ([`DynamicLdlt::from_matrix`]).

mod augmented;
mod factor;
mod marginal;
pub(crate) mod runs;
mod scratch;
mod solve;
mod update;

pub use augmented::{AugmentedCholesky, SolveStats};
pub use factor::{DynamicLdlt, WalkStats};
pub use marginal::Marginal;
pub use scratch::MAX_RANK;
pub use solve::IncrementalCholesky;
pub use update::UpdateError;

#[cfg(test)]
mod tests;
