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

/// Iterations each start of [`robust_polish`] gets before the pruning.
pub const PROBE_ITERATIONS: usize = 12;

/// A start whose cost after the probe exceeds this multiple of the lowest
/// is not polished further.
pub const PRUNE_RATIO: f64 = 2.0;

/// Paper A's cycle test (when configured) switches off what it rejects;
/// Levenberg–Marquardt then minimises the kernel's robust cost, each
/// switchable edge reweighted by `s²` at every iteration, from every start
/// for [`PROBE_ITERATIONS`], then to convergence unless its cost is past
/// [`PRUNE_RATIO`] times the lowest; the lowest final cost gives the
/// switches. Fails when no start could be polished (or none was given).
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
    // every start gets a probe of a few iterations; those within
    // `PRUNE_RATIO` of the lowest cost go on to convergence (a start in a
    // wrong basin, such as a linear solution bent by a thousand outliers,
    // ran to the cap of 100 iterations on City10000 for nothing: 24 s)
    let probe = LevenbergMarquardtParams {
        max_iterations: params.max_iterations.min(PROBE_ITERATIONS),
        ..params
    };
    let mut error = FactorError::NotPositiveDefinite { step: 0 };
    let mut probed = Vec::new();
    for start in starts {
        match polish(problem, start, probe) {
            Ok(r) => probed.push(r),
            Err(e) => error = e,
        }
    }
    let lowest = probed.iter().map(|r| r.final_chi2).fold(f64::INFINITY, f64::min);
    let mut best: Option<LmReport> = None;
    for r in probed {
        let spent = r.iterations.len() >= params.max_iterations;
        let r = if r.converged || spent || r.final_chi2 > PRUNE_RATIO * lowest {
            r
        } else {
            let rest = LevenbergMarquardtParams {
                max_iterations: params.max_iterations.saturating_sub(r.iterations.len()),
                ..params
            };
            match polish(problem, r.poses.clone(), rest) {
                Ok(done) => done,
                Err(_) => r,
            }
        };
        if best.as_ref().is_none_or(|b| r.final_chi2 < b.final_chi2) {
            best = Some(r);
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
