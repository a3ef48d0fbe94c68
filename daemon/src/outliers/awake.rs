//! [`polish_awake`]: the polish with the dormant edges (wrong loop
//! closures switched almost off) left out of its linear systems, which
//! every start of a robust polish runs.

use crate::graph::Edge;
use crate::nonlinear::{polish, LevenbergMarquardtParams, LiePose, LmReport, Problem, Robust};
use crate::sparse::FactorError;

/// A switchable edge whose switch at the start of a polish is below this
/// sits out its linear systems (it weighs `s² < 10⁻⁶` of itself), unless it
/// wakes by the end: wrong long-range loop closures in the pattern make
/// every factorisation dearer through fill.
/// The polish's cost still counts them, and a dormant edge whose switch
/// has risen past this at the polish's result joins a further round.
pub const DORMANT_BELOW: f64 = 1e-3;

/// Rounds of [`polish_awake`] that may wake dormant edges.
const WAKE_ROUNDS: usize = 3;

/// [`polish`] with the dormant edges (switch below [`DORMANT_BELOW`] at
/// the current poses) left out of the linear systems; repeated while the
/// result wakes any of them. The report's costs are the whole problem's.
/// Falls back to the whole problem if the rest cannot be factorised.
pub(super) fn polish_awake<P: LiePose>(
    problem: Problem<'_, P>,
    start: Vec<P>,
    params: LevenbergMarquardtParams,
) -> Result<LmReport<P>, FactorError> {
    let Some(robust) = problem.robust else {
        return polish(problem, start, params);
    };
    let initial_chi2 = problem.chi2(&start);
    let mut awake = vec![false; problem.edges.len()];
    wake(problem.edges, &robust, &start, &mut awake);
    let mut poses = start;
    let mut iterations = Vec::new();
    for _ in 0..WAKE_ROUNDS {
        if awake.iter().all(|&a| a) {
            break;
        }
        let index: Vec<usize> = (0..awake.len()).filter(|&a| awake[a]).collect();
        let edges: Vec<Edge<P>> = index.iter().map(|&a| problem.edges[a]).collect();
        let switchable: Vec<bool> = index.iter().map(|&a| robust.switchable[a]).collect();
        let sub = Problem {
            edges: &edges,
            priors: problem.priors,
            robust: Some(Robust {
                switchable: &switchable,
                ..robust
            }),
            stop: problem.stop,
        };
        let left = params.max_iterations.saturating_sub(iterations.len());
        let Ok(r) = polish(
            sub,
            poses.clone(),
            LevenbergMarquardtParams {
                max_iterations: left,
                ..params
            },
        ) else {
            break;
        };
        iterations.extend(r.iterations);
        poses = r.poses;
        let converged = r.converged;
        let woke = wake(problem.edges, &robust, &poses, &mut awake);
        if woke == 0 || iterations.len() >= params.max_iterations || problem.stopped() {
            return Ok(LmReport {
                final_chi2: problem.chi2(&poses),
                poses,
                initial_chi2,
                iterations,
                converged,
            });
        }
    }
    // everything awake, or the rest could not be factorised: the whole problem
    let left = params.max_iterations.saturating_sub(iterations.len()).max(1);
    let mut r = polish(
        problem,
        poses,
        LevenbergMarquardtParams {
            max_iterations: left,
            ..params
        },
    )?;
    iterations.extend(r.iterations);
    r.iterations = iterations;
    r.initial_chi2 = initial_chi2;
    Ok(r)
}

/// Wakes the edges that are not switchable or whose switch at `poses` is
/// at least [`DORMANT_BELOW`]; returns how many woke.
fn wake<P: LiePose>(edges: &[Edge<P>], robust: &Robust<'_>, poses: &[P], awake: &mut [bool]) -> usize {
    let mut woke = 0;
    for (a, e) in edges.iter().enumerate() {
        if !awake[a]
            && (!robust.switchable[a]
                || P::kernel_switch(&robust.kernel, e, &poses[e.from], &poses[e.to]) >= DORMANT_BELOW)
        {
            awake[a] = true;
            woke += 1;
        }
    }
    woke
}
