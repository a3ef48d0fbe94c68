//! slamd: a streaming pose-graph SLAM backend.
//!
//! slamd estimates keyframe poses `x_i = (p_i, θ_i)` from relative
//! measurements `T_ij` with information `Ω_ij` by minimising g2o's cost
//!
//! ```text
//! χ²(x) = Σ_edges e_ijᵀ Ω_ij e_ij,   e_ij = t2v(T_ij⁻¹ · x_i⁻¹ · x_j)
//! ```
//!
//! **The math path** (pure data and functions, no threads, no I/O):
//! [`geometry`] (poses, angle wrap) → [`graph`] (keyframes, edges,
//! information, the cost) → [`linear`] (initialisers without a guess: the
//! two-stage formulation and paper A's virtual frames) → [`sparse`] (normal
//! equations and faer's sparse Cholesky) → [`nonlinear`] (the
//! Levenberg–Marquardt polish, its switched edges weighed by a [`robust`]
//! kernel); [`gps`] adds fixes and georeferencing, [`outliers`] switches
//! wrong loop closures off.
//! [`solver`] chains them into a batch solve and
//! [`eval`] measures the result.
//!
//! [`synthetic`] generates a seeded world with known ground truth.
//!
//! **The engine** ([`engine`]) bridges the two: it keeps the normal
//! equations factorised as keyframes and edges stream in, and re-solves in
//! the background.
//!
//! **The plumbing**: [`io`] reads and writes graph files; [`config`]
//! holds every setting; [`wire`] checks messages from frontends; [`ipc`]
//! is the daemon and the frontend's side of shared memory.
//!
//! ```
//! use slamd::geometry::Pose2;
//! use slamd::graph::{EdgeKind, Information, PoseGraph};
//! use slamd::solver::{solve_batch, BatchOptions};
//!
//! // A square driven once around, with a loop closure back to the start.
//! let mut g = PoseGraph::default();
//! for id in 0..4 {
//!     g.add_keyframe(id, None).unwrap();
//! }
//! let step = Pose2::new(1.0, 0.0, std::f64::consts::FRAC_PI_2);
//! for (i, j) in [(0, 1), (1, 2), (2, 3), (3, 0)] {
//!     let kind = EdgeKind::from_ids(i, j);
//!     g.add_edge(i, j, step, Information::identity(), kind).unwrap();
//! }
//! let s = solve_batch(&g, &BatchOptions::default()).unwrap();
//! assert!(s.chi2 < 1e-18);
//! assert!((s.poses[2].x - 1.0).abs() < 1e-9 && (s.poses[2].y - 1.0).abs() < 1e-9);
//! ```

#![deny(missing_docs)]
#![warn(clippy::unwrap_used)]

pub mod affinity;
pub mod config;
pub mod engine;
pub mod eval;
pub mod geometry;
pub mod gps;
pub mod graph;
pub mod io;
pub mod ipc;
pub mod linear;
pub mod nonlinear;
pub mod outliers;
pub mod robust;
pub mod solver;
pub mod sparse;
pub mod store;
pub mod synthetic;
pub mod wire;
