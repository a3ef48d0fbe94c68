//! [`best_start`]: which starts of a robust polish are polished to the
//! end. Each start is probed for a few iterations; the ones near the lowest
//! cost are finished, lowest first, and the lowest final cost wins.

use super::awake::polish_awake;
use crate::nonlinear::{LevenbergMarquardtParams, LiePose, LmReport, Problem};
use crate::sparse::FactorError;
use std::sync::{Mutex, OnceLock};

/// Iterations each start of [`robust_polish`](super::robust_polish) gets
/// before the pruning.
pub const PROBE_ITERATIONS: usize = 12;

/// A start whose cost after the probe exceeds this multiple of the lowest
/// is not polished further.
pub const PRUNE_RATIO: f64 = 2.0;

/// A start whose cost after [`LOOK_ITERATIONS`] still exceeds this
/// multiple of the lowest cost probed before it ends its probe there: a
/// start bent by many wrong loop closures stays orders of magnitude above
/// the others, while starts a re-solve needs lie within a few percent.
pub const ABANDON_RATIO: f64 = 20.0;

/// A start polished on while another has finished gives up once its cost
/// after a round of [`PROBE_ITERATIONS`] is still past this multiple of
/// the finished one's: on Manhattan + 4000 random wrong loop closures a
/// start at 1.48× the lowest after its probe ran 76 more iterations, 50 s
/// with its wrong loop closures awake, to end at 1.40× (`slamd solve
/// --robust`).
pub const LATE_RATIO: f64 = 1.25;

/// Iterations a start gets before [`ABANDON_RATIO`] is checked. One: a
/// start that trusts many wrong loop closures is far above the others
/// after one already, and each of its iterations costs several times
/// theirs (the outliers fill the factor in).
pub const LOOK_ITERATIONS: usize = 1;

/// Probes every start (`threads` at a time), finishes those within
/// [`PRUNE_RATIO`] of the lowest probe ([`finish_start`], lowest first) and
/// returns the one that ends lowest. Fails when no start could be polished
/// (or none was given).
pub(super) fn best_start<P: LiePose>(
    problem: Problem<'_, P>,
    starts: Vec<Vec<P>>,
    params: LevenbergMarquardtParams,
    threads: usize,
) -> Result<LmReport<P>, FactorError> {
    // a probe of a few iterations first: polished to convergence, a start
    // in a wrong basin (a linear solution bent by a thousand outliers)
    // would run to the iteration cap for nothing
    let probe = LevenbergMarquardtParams {
        max_iterations: params.max_iterations.min(PROBE_ITERATIONS),
        ..params
    };
    let mut error = FactorError::NotPositiveDefinite { step: 0 };
    let mut probed: Vec<LmReport<P>> = Vec::new();
    for r in probe_starts(problem, starts, probe, threads) {
        match r {
            Ok(r) => probed.push(r),
            Err(e) => error = e,
        }
    }
    // the lowest probe goes on first, so the others can be measured
    // against where a finished start ended
    probed.sort_by(|a, b| a.final_chi2.total_cmp(&b.final_chi2));
    let lowest = probed.first().map_or(f64::INFINITY, |r| r.final_chi2);
    let mut best: Option<LmReport<P>> = None;
    for r in probed {
        let r = if r.final_chi2 > PRUNE_RATIO * lowest {
            r
        } else {
            finish_start(problem, r, params, best.as_ref().map(|b| b.final_chi2))
        };
        if best.as_ref().is_none_or(|b| r.final_chi2 < b.final_chi2) {
            best = Some(r);
        }
    }
    best.ok_or(error)
}

/// Probes one start for `probe.max_iterations`, or only
/// [`LOOK_ITERATIONS`] when its cost is then still past [`ABANDON_RATIO`]
/// times `lowest()` (the lowest cost probed before it; `None`: the first
/// start). `lowest` is asked only at that check, so a start can be probed
/// while the ones before it still run.
fn probe_start<P: LiePose>(
    problem: Problem<'_, P>,
    start: Vec<P>,
    probe: LevenbergMarquardtParams,
    lowest: Option<&dyn Fn() -> f64>,
) -> Result<LmReport<P>, FactorError> {
    let Some(lowest) = lowest.filter(|_| probe.max_iterations > LOOK_ITERATIONS) else {
        return polish_awake(problem, start, probe);
    };
    let look = LevenbergMarquardtParams {
        max_iterations: LOOK_ITERATIONS,
        ..probe
    };
    let first = polish_awake(problem, start, look)?;
    if first.converged || problem.stopped() || first.final_chi2 > ABANDON_RATIO * lowest() {
        return Ok(first);
    }
    let rest = LevenbergMarquardtParams {
        max_iterations: probe.max_iterations - first.iterations.len(),
        ..probe
    };
    match polish_awake(problem, first.poses.clone(), rest) {
        Ok(mut r) => {
            let mut iterations = first.iterations;
            iterations.extend(r.iterations);
            r.iterations = iterations;
            r.initial_chi2 = first.initial_chi2;
            Ok(r)
        }
        Err(_) => Ok(first),
    }
}

/// Polishes a probed start to convergence, [`PROBE_ITERATIONS`] at a
/// time; once a start has finished at `finished`, one still past
/// [`LATE_RATIO`] times that after a round gives up there.
fn finish_start<P: LiePose>(
    problem: Problem<'_, P>,
    mut r: LmReport<P>,
    params: LevenbergMarquardtParams,
    finished: Option<f64>,
) -> LmReport<P> {
    loop {
        let spent = r.iterations.len() >= params.max_iterations;
        let behind = finished.is_some_and(|f| r.final_chi2 > LATE_RATIO * f);
        if r.converged || spent || behind || problem.stopped() {
            return r;
        }
        let left = params.max_iterations - r.iterations.len();
        let round = LevenbergMarquardtParams {
            max_iterations: if finished.is_some() {
                left.min(PROBE_ITERATIONS)
            } else {
                left
            },
            ..params
        };
        match polish_awake(problem, r.poses.clone(), round) {
            Ok(mut next) => {
                let mut iterations = std::mem::take(&mut r.iterations);
                iterations.extend(next.iterations);
                next.iterations = iterations;
                next.initial_chi2 = r.initial_chi2;
                r = next;
            }
            Err(_) => return r,
        }
    }
}

/// [`probe_start`] on every start, `threads` at a time; start `i`'s look
/// check waits for the probes of the starts before it, so the outcome is
/// the same as one at a time.
fn probe_starts<P: LiePose>(
    problem: Problem<'_, P>,
    starts: Vec<Vec<P>>,
    probe: LevenbergMarquardtParams,
    threads: usize,
) -> Vec<Result<LmReport<P>, FactorError>> {
    let n = starts.len();
    // the cost each probe ended at (infinite when it failed)
    let costs: Vec<OnceLock<f64>> = (0..n).map(|_| OnceLock::new()).collect();
    let lowest_before = |i: usize| (0..i).map(|j| *costs[j].wait()).fold(f64::INFINITY, f64::min);
    let run = |i: usize, start: Vec<P>| {
        // a probe that panics still lets the ones waiting on it go on
        let _unblock = Unblock(&costs[i]);
        let lowest = || lowest_before(i);
        let r = probe_start(
            problem,
            start,
            probe,
            (i > 0).then_some(&lowest as &dyn Fn() -> f64),
        );
        let _ = costs[i].set(r.as_ref().map_or(f64::INFINITY, |r| r.final_chi2));
        r
    };
    if threads <= 1 || n <= 1 {
        return starts.into_iter().enumerate().map(|(i, s)| run(i, s)).collect();
    }
    // starts are taken in order, so a probe only waits on ones under way
    let queue = Mutex::new(starts.into_iter().enumerate());
    let results = Mutex::new((0..n).map(|_| None).collect::<Vec<_>>());
    std::thread::scope(|scope| {
        for _ in 0..threads.min(n) {
            scope.spawn(|| loop {
                let Some((i, start)) = queue.lock().expect("no panics under the lock").next() else {
                    break;
                };
                let r = run(i, start);
                results.lock().expect("no panics under the lock")[i] = Some(r);
            });
        }
    });
    let results = results.into_inner().expect("the probes ended");
    results
        .into_iter()
        .map(|r| r.expect("every start probed"))
        .collect()
}

/// Sets a probe's cost to infinity when it ends without one (a panic),
/// so that the probes waiting on it do not wait forever.
struct Unblock<'a>(&'a OnceLock<f64>);

impl Drop for Unblock<'_> {
    fn drop(&mut self) {
        let _ = self.0.set(f64::INFINITY);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Pose2;
    use crate::graph::Edge;
    use crate::nonlinear::polish;
    use crate::outliers::robust::tests::{square, square_start};

    #[test]
    fn a_start_far_above_the_lowest_gets_only_a_look() {
        let edges = square();
        let problem = least_squares(&edges);
        let start = far_start();
        let probe = LevenbergMarquardtParams {
            max_iterations: PROBE_ITERATIONS,
            ..LevenbergMarquardtParams::default()
        };
        let alone = probe_start(problem, start.clone(), probe, None).unwrap();
        assert!(
            alone.iterations.len() > LOOK_ITERATIONS,
            "{} iterations",
            alone.iterations.len()
        );
        let after_look = polish(
            problem,
            start.clone(),
            LevenbergMarquardtParams {
                max_iterations: LOOK_ITERATIONS,
                ..probe
            },
        )
        .unwrap()
        .final_chi2;
        // an earlier start 100× below the look's cost: abandoned after it
        let lowest = after_look / (5.0 * ABANDON_RATIO);
        let cut = probe_start(problem, start.clone(), probe, Some(&|| lowest)).unwrap();
        assert_eq!(cut.iterations.len(), LOOK_ITERATIONS);
        assert_eq!(cut.final_chi2, after_look);
        // one just below the look's cost: the probe goes on
        let kept = probe_start(problem, start.clone(), probe, Some(&|| after_look / 2.0)).unwrap();
        assert!(kept.iterations.len() > LOOK_ITERATIONS);
        assert!(kept.final_chi2 < after_look);
        // probed two at a time, the far start still sees the near one's
        // cost at its look, and each start ends as it does alone
        let near = square_start(&edges);
        let starts = vec![near.clone(), start.clone(), near];
        let one = probe_starts(problem, starts.clone(), probe, 1);
        let two = probe_starts(problem, starts, probe, 2);
        assert_eq!(one[1].as_ref().unwrap().iterations.len(), LOOK_ITERATIONS);
        for (a, b) in one.iter().zip(&two) {
            let (a, b) = (a.as_ref().unwrap(), b.as_ref().unwrap());
            assert_eq!(a.iterations.len(), b.iterations.len());
            assert_eq!(a.final_chi2, b.final_chi2);
            assert_eq!(a.poses, b.poses);
        }
    }

    #[test]
    fn a_start_behind_a_finished_one_gives_up() {
        let edges = square();
        let problem = least_squares(&edges);
        let start = far_start();
        let params = LevenbergMarquardtParams::default();
        let probe = LevenbergMarquardtParams {
            max_iterations: 2,
            ..params
        };
        let probed = polish(problem, start, probe).unwrap();
        assert!(!probed.converged);
        let cost = probed.final_chi2;
        // first to finish: polished to convergence
        let alone = finish_start(problem, probed.clone(), params, None);
        assert!(alone.converged && alone.final_chi2 < cost, "{}", alone.final_chi2);
        // past LATE_RATIO times a finished start's cost: it stops there
        let behind = finish_start(problem, probed.clone(), params, Some(cost / (2.0 * LATE_RATIO)));
        assert_eq!(behind.iterations.len(), probed.iterations.len());
        assert_eq!(behind.final_chi2, cost);
        // within it: rounds go on until it converges (the probe's
        // iterations kept in the report)
        let within = finish_start(problem, probed.clone(), params, Some(cost));
        assert!(within.converged, "{} iterations", within.iterations.len());
        assert!(within.iterations.len() > probed.iterations.len() + 1);
        assert!((within.final_chi2 - alone.final_chi2).abs() < 1e-9);
        assert_eq!(within.initial_chi2, probed.initial_chi2);
    }

    /// The plain least-squares problem over `edges`.
    fn least_squares(edges: &[Edge]) -> Problem<'_, Pose2> {
        Problem {
            edges,
            priors: &[],
            robust: None,
            stop: None,
        }
    }

    /// Every pose of the square thrown off, turned and shuffled: far from
    /// any basin.
    fn far_start() -> Vec<Pose2> {
        (0..8)
            .map(|k| Pose2::new(10.0 * ((k * 5) % 8) as f64, -3.0 * k as f64, 1.3 * k as f64))
            .collect()
    }
}
