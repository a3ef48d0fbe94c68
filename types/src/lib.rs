//! The types a frontend and slamd share: planar and spatial poses, information
//! matrices, edge kinds, keyframe ids and GPS positions.
//!
//! This crate is small on purpose: a frontend that only publishes to a
//! daemon links it and `slamd-protocol`, not the solver.
//!
//! ```
//! use slamd_types::{EdgeInput, EdgeKind, Information, Pose2};
//!
//! let step = Pose2::new(1.0, 0.0, std::f64::consts::FRAC_PI_2);
//! let edge = EdgeInput::new(0, 1, step, Information::identity(), EdgeKind::Odometry);
//! let back = step.compose(&step.inverse());
//! assert!(back.x.abs() < 1e-12 && back.theta.abs() < 1e-12);
//! assert_eq!(edge.kind, EdgeKind::from_ids(0, 1));
//! ```

#![deny(missing_docs)]

mod gps;
mod information;
mod information6;
mod input;
mod motion;
mod pose;
mod pose3;

pub use gps::{check_covariance, Geodetic, GpsError};
pub use information::{Information, InformationError};
pub use information6::Information6;
pub use input::{EdgeInput, EdgeKind, FixInput, KeyframeId, KeyframeInput};
pub use motion::{InformationMatrix, RigidMotion};
pub use pose::{wrap_angle, Pose2};
pub use pose3::{Pose3, QUATERNION_NORM_TOLERANCE};
