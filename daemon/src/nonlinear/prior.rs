//! [`PositionPrior`]: an absolute position measurement of one keyframe, and
//! [`Problem`]: the cost the polish minimises, with [`Robust`] switches
//! on loop closures.

use super::lie::LiePose;
use crate::geometry::Pose2;
use crate::graph::{chi2_of_edges, edge_chi2, Edge};
use crate::robust::Kernel;
use std::sync::atomic::{AtomicBool, Ordering};

/// `p_k ≈ target` in the map frame with information Ω (a GPS fix carried
/// into the map frame by the georeference), `e = p_k − target`. In the
/// plane the target is `x + iy` and Ω is 2×2; in space both are 3-D.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PositionPrior<P: LiePose = Pose2> {
    /// Keyframe index.
    pub keyframe: usize,
    /// Map-frame position.
    pub target: P::Position,
    /// Information over the position.
    pub information: P::PositionInformation,
}

impl<P: LiePose> PositionPrior<P> {
    /// `eᵀ Ω e` at `poses`.
    pub fn chi2(&self, poses: &[P]) -> f64 {
        poses[self.keyframe].prior_chi2(&self.target, &self.information)
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

/// What the polish minimises: g2o's SE(2) or SE(3) cost of the edges (a robust
/// cost `ρ(χ²)` on switchable ones) plus the priors' `eᵀΩe`.
#[derive(Clone, Copy, Debug)]
pub struct Problem<'a, P: LiePose = Pose2> {
    /// Relative-pose edges.
    pub edges: &'a [Edge<P>],
    /// Absolute position priors.
    pub priors: &'a [PositionPrior<P>],
    /// Switchable edges, if any.
    pub robust: Option<Robust<'a>>,
    /// Asked before every iteration: once set, the polish ends where it
    /// is (a background re-solve nobody waits for any more).
    pub stop: Option<&'a AtomicBool>,
}

impl<'a, P: LiePose> Problem<'a, P> {
    /// Edges only.
    pub fn edges(edges: &'a [Edge<P>]) -> Self {
        Self::new(edges, &[])
    }

    /// Edges and priors, no switches.
    pub fn new(edges: &'a [Edge<P>], priors: &'a [PositionPrior<P>]) -> Self {
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
    pub fn chi2(&self, poses: &[P]) -> f64 {
        let priors = self.priors.iter().map(|p| p.chi2(poses)).sum::<f64>();
        let Some(r) = &self.robust else {
            return chi2_of_edges(self.edges, poses) + priors;
        };
        let edges: f64 = (self.edges.iter().zip(r.switchable))
            .map(|(e, &sw)| {
                let (xi, xj) = (&poses[e.from], &poses[e.to]);
                if sw {
                    P::kernel_cost(&r.kernel, e, xi, xj)
                } else {
                    edge_chi2(e, poses)
                }
            })
            .sum();
        edges + priors
    }

    /// The IRLS weight `s²` of every edge at `poses` (1 where not
    /// switchable), or `None` without switches.
    pub fn weights(&self, poses: &[P]) -> Option<Vec<f64>> {
        let r = self.robust.as_ref()?;
        Some(
            (self.edges.iter().zip(r.switchable))
                .map(|(e, &sw)| {
                    if sw {
                        P::kernel_switch(&r.kernel, e, &poses[e.from], &poses[e.to]).powi(2)
                    } else {
                        1.0
                    }
                })
                .collect(),
        )
    }
}
