//! [`PositionPrior`]: an absolute position measurement of one keyframe, and
//! [`Problem`]: the cost the polish minimises, with [`Robust`] switches
//! on loop closures.

use crate::geometry::Pose2;
use crate::graph::{chi2_of_edges, edge_chi2, Edge};
use crate::robust::Kernel;
use faer::c64;
use nalgebra::Matrix2;
use std::sync::atomic::{AtomicBool, Ordering};

/// `p_k ≈ target` in the map frame with information Ω (a GPS fix carried
/// into the map frame by the georeference). Its error `e = p_k − target`
/// has the Jacobian `[I₂ 0]` on `(x, y, θ)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionPrior {
    /// Keyframe index.
    pub keyframe: usize,
    /// Map-frame position.
    pub target: c64,
    /// 2×2 information over (x, y).
    pub information: Matrix2<f64>,
}

impl PositionPrior {
    /// `eᵀ Ω e` at `poses`.
    pub fn chi2(&self, poses: &[Pose2]) -> f64 {
        let e = poses[self.keyframe].position() - self.target;
        let v = nalgebra::Vector2::new(e.re, e.im);
        (v.transpose() * self.information * v)[0]
    }
}

/// Which edges are switchable (loop closures) and how their switch
/// follows their error.
#[derive(Clone, Copy, Debug)]
pub struct Robust<'a> {
    /// The closed-form switch.
    pub kernel: Kernel,
    /// One flag per edge of the problem.
    pub switchable: &'a [bool],
}

/// What the polish minimises: g2o's SE(2) cost of the edges (a robust
/// cost `ρ(χ²)` on switchable ones) plus the priors' `eᵀΩe`.
#[derive(Clone, Copy, Debug)]
pub struct Problem<'a> {
    /// Relative-pose edges.
    pub edges: &'a [Edge],
    /// Absolute position priors.
    pub priors: &'a [PositionPrior],
    /// Switchable edges, if any.
    pub robust: Option<Robust<'a>>,
    /// Asked before every iteration: once set, the polish ends where it
    /// is (a background re-solve nobody waits for any more).
    pub stop: Option<&'a AtomicBool>,
}

impl<'a> Problem<'a> {
    /// Edges only.
    pub fn edges(edges: &'a [Edge]) -> Self {
        Self::new(edges, &[])
    }

    /// Edges and priors, no switches.
    pub fn new(edges: &'a [Edge], priors: &'a [PositionPrior]) -> Self {
        Self {
            edges,
            priors,
            robust: None,
            stop: None,
        }
    }

    /// Whether the polish was asked to stop.
    pub fn stopped(&self) -> bool {
        self.stop.is_some_and(|s| s.load(Ordering::Relaxed))
    }

    /// The total cost at `poses`.
    pub fn chi2(&self, poses: &[Pose2]) -> f64 {
        let priors = self.priors.iter().map(|p| p.chi2(poses)).sum::<f64>();
        let Some(r) = &self.robust else {
            return chi2_of_edges(self.edges, poses) + priors;
        };
        let edges: f64 = (self.edges.iter().zip(r.switchable))
            .map(|(e, &sw)| {
                let (xi, xj) = (&poses[e.from], &poses[e.to]);
                if sw {
                    r.kernel.cost(e, xi, xj)
                } else {
                    edge_chi2(e, poses)
                }
            })
            .sum();
        edges + priors
    }

    /// The IRLS weight `s²` of every edge at `poses` (1 where not
    /// switchable), or `None` without switches.
    pub fn weights(&self, poses: &[Pose2]) -> Option<Vec<f64>> {
        let r = self.robust.as_ref()?;
        Some(
            (self.edges.iter().zip(r.switchable))
                .map(|(e, &sw)| {
                    if sw {
                        r.kernel.switch(e, &poses[e.from], &poses[e.to]).powi(2)
                    } else {
                        1.0
                    }
                })
                .collect(),
        )
    }
}
