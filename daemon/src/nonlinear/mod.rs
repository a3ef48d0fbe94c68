//! The nonlinear polish: damped least squares on the SE(2) cost.
//!
//! - [`se2`]: the error of one edge and its Jacobians.
//! - [`structure`]: the block pattern of the Gauss–Newton normal equations.
//! - [`prior`]: absolute position priors (GPS in the map frame) and the
//!   [`Problem`] that sums both costs.
//! - [`LevenbergMarquardt`] with [`LevenbergMarquardtParams`]: `iterate()`
//!   takes one step, `optimize()` loops to convergence.

mod levenberg_marquardt;
mod params;
pub mod prior;
pub mod se2;
pub mod structure;

pub use levenberg_marquardt::{polish, Iteration, LevenbergMarquardt, LmReport};
pub use params::LevenbergMarquardtParams;
pub use prior::{PositionPrior, Problem, Robust};
