//! Linear formulations: poses from linear least squares, no initial guess.
//!
//! - [`two_stage`]: axes, then positions (the default initialiser).
//! - [`chordal`]: the same two stages in 3-D: chordal rotations, then
//!   positions.
//! - [`virtual_frame`]: paper A as printed, kept to measure its collapse.
//! - [`scale`], [`rotation`]: paper A's closed-form scale and 2-D registration.
//! - [`system`]: weighted complex rows and their normal equations.
//! - [`planar`]: planar rows with full 2×2 weights.

pub mod chordal;
pub mod planar;
pub mod rotation;
pub mod scale;
pub mod system;
pub mod two_stage;
pub mod virtual_frame;

pub use system::{LinearSystem, Var, MAX_TERMS};
pub use virtual_frame::Pivot;
