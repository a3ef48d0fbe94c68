//! [`robust_polish`]: the polish that switches wrong loop closures off,
//! shared by the engine's re-solve and `slamd solve --robust`.

use super::{CycleCheck, OutlierConfig, Verdict};
use crate::geometry::Pose2;
use crate::graph::Edge;
use crate::nonlinear::{polish, LevenbergMarquardtParams, LmReport, Problem, Robust};
use crate::sparse::FactorError;

/// What the robust polish found.
#[derive(Clone, Debug)]
pub struct RobustSolution {
    /// The poses.
    pub poses: Vec<Pose2>,
    /// The switch `s ∈ [0, 1]` of each edge (1 where not switchable, 0 where
    /// the cycle test rejected it).
    pub switches: Vec<f64>,
    /// The robust cost at `poses`.
    pub cost: f64,
}

/// Paper A's cycle test (when configured) switches off what it rejects;
/// Levenberg–Marquardt then minimises the kernel's robust cost, each
/// switchable edge reweighted by `s²` at every iteration, from every start;
/// the lowest cost wins and gives the switches. Fails when no start could
/// be polished (or none was given).
pub fn robust_polish(
    edges: &[Edge],
    switchable: &[bool],
    starts: Vec<Vec<Pose2>>,
    config: &OutlierConfig,
    params: LevenbergMarquardtParams,
) -> Result<RobustSolution, FactorError> {
    let n = starts.first().map_or(0, Vec::len);
    let mut out = vec![false; edges.len()];
    if config.enabled && config.cycles {
        let usable = vec![true; edges.len()];
        let check = CycleCheck::new(n, edges, &usable);
        for (a, o) in out.iter_mut().enumerate() {
            *o = switchable[a] && check.verdict(a, &config.cycle) == Verdict::Reject;
        }
    }
    let kept: Vec<usize> = (0..edges.len()).filter(|&a| !out[a]).collect();
    let kept_edges: Vec<Edge> = kept.iter().map(|&a| edges[a]).collect();
    let kept_switchable: Vec<bool> = kept.iter().map(|&a| switchable[a]).collect();
    let problem = Problem {
        edges: &kept_edges,
        priors: &[],
        robust: config.enabled.then_some(Robust {
            kernel: config.kernel,
            switchable: &kept_switchable,
        }),
    };
    let mut best: Option<LmReport> = None;
    let mut error = FactorError::NotPositiveDefinite { step: 0 };
    for start in starts {
        match polish(problem, start, params) {
            Ok(r) if best.as_ref().is_none_or(|b| r.final_chi2 < b.final_chi2) => best = Some(r),
            Ok(_) => {}
            Err(e) => error = e,
        }
    }
    let best = best.ok_or(error)?;
    let poses = best.poses;
    let switches = (0..edges.len())
        .map(|a| {
            if out[a] {
                0.0
            } else if switchable[a] && config.enabled {
                let e = &edges[a];
                config.kernel.switch(e, &poses[e.from], &poses[e.to])
            } else {
                1.0
            }
        })
        .collect();
    Ok(RobustSolution {
        poses,
        switches,
        cost: best.final_chi2,
    })
}
