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
//!   re-solving only the affected paths and subtrees.
//!
//! Columns are stored one per `Vec` (rows sorted, strictly below the
//! diagonal), so that fill can grow any column. `L` is unit lower
//! triangular and `D` real positive. A fresh factor comes from faer's
//! simplicial LDLᴴ ([`DynamicLdlt::from_matrix`]).

mod factor;
mod solve;
mod update;

pub use factor::DynamicLdlt;
pub use solve::IncrementalCholesky;
pub use update::{UpdateError, MAX_RANK};

#[cfg(test)]
mod tests;
