//! Robust kernels: a loss `ρ(χ²)` on an edge's squared Mahalanobis error
//! `χ² = eᵀ Ω e`, and its iteratively reweighted least-squares weight
//! `w = dρ/dχ²`.
//!
//! Minimising `Σ ρ(χ²_e)` by Gauss–Newton steps on `Σ w_e χ²_e`, with each
//! `w_e` taken at the current poses, is IRLS. The kernels here are the
//! closed-form switches of switchable constraints, whose weight is the
//! square of the switch: `w = s²` ([`Kernel::switch`], [`Kernel::cost`]).
//! They take the χ² alone, so they sit below the solver: the polish asks
//! them through [`LiePose::kernel_switch`](crate::nonlinear::LiePose::kernel_switch).
//! The nonlinear polish weighs switchable edges by them; [`crate::outliers`]
//! decides which edges are switchable and drives the polish.

pub mod kernel;

pub use kernel::{Kernel, DEFAULT_PHI, DEFAULT_PHI_6DOF};
