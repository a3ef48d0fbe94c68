//! The nonlinear polish: damped least squares on g2o's SE(2) and SE(3)
//! costs, written once over [`LiePose`].
//!
//! - [`lie`]: what a pose type gives the polish (edge systems, the step).
//! - [`se2`], [`se3`]: the error of one edge and its Jacobians.
//! - [`structure`]: the block pattern of the Gauss–Newton normal equations.
//! - [`prior`]: absolute position priors (GPS in the map frame) and the
//!   [`Problem`] that sums both costs.
//! - [`LevenbergMarquardt`] with [`LevenbergMarquardtParams`]: `iterate()`
//!   takes one step, `optimize()` loops to convergence.

mod levenberg_marquardt;
pub mod lie;
mod params;
pub mod prior;
pub mod se2;
pub mod se3;
pub mod structure;

pub use levenberg_marquardt::{polish, Iteration, LevenbergMarquardt, LmReport};
pub use lie::LiePose;
pub use params::LevenbergMarquardtParams;
pub use prior::{PositionPrior, Problem, Robust};
