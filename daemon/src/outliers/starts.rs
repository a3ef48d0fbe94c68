//! [`best_start`]: which starts of a robust polish are polished to the
//! end, and which of them wins. Each start is probed for a few iterations;
//! the ones near the lowest cost are finished, lowest first, and the one
//! of least cost at a given noise level wins ([`lowest_at_scale`]).

use super::awake::polish_awake;
use super::REJECTED_BELOW;
use crate::graph::{edge_chi2, Edge};
use crate::nonlinear::{LevenbergMarquardtParams, LiePose, LmReport, Problem, Robust};
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
/// returns, of those that did not give up, the one of least cost at the
/// variance factor `sigma2` ([`lowest_at_scale`]). Fails when no start
/// could be polished (or none was given).
pub(super) fn best_start<P: LiePose>(
    problem: Problem<'_, P>,
    starts: Vec<Vec<P>>,
    params: LevenbergMarquardtParams,
    threads: usize,
    sigma2: f64,
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
    let mut finished: Vec<LmReport<P>> = Vec::new();
    for r in probed {
        if r.final_chi2 > PRUNE_RATIO * lowest {
            continue;
        }
        let done = finished.iter().map(|f| f.final_chi2).reduce(f64::min);
        let r = finish_start(problem, r, params, done);
        // one that gave up behind a finished start is not compared
        if done.is_none_or(|d| r.final_chi2 <= LATE_RATIO * d) {
            finished.push(r);
        }
    }
    lowest_at_scale(problem, finished, sigma2).ok_or(error)
}

/// The finished start of least robust cost once every edge's `χ²` is
/// divided by `sigma2` (in `(0, 1]`): DCS at `Φ σ̂²`, in units of the
/// noise the accepted set shows. Where the information is pessimistic, a
/// basin bent by many wrong loop closures can cost less than the right one
/// at the stated scale, because the wrong ones pay a saturated cost while
/// the bending of odometry and true loop closures is priced in covariances
/// far larger than their errors (Intel with 4000 random wrong loop
/// closures, seed 1's closing re-solve: 61,921 against 65,133 for the
/// start that ends clean; read at the estimate's `σ̂² = 0.22`, 163,069
/// against 65,875). At `sigma2 = 1` the lowest robust cost wins. The first
/// of equals wins.
fn lowest_at_scale<P: LiePose>(
    problem: Problem<'_, P>,
    finished: Vec<LmReport<P>>,
    sigma2: f64,
) -> Option<LmReport<P>> {
    let robust = problem.robust.filter(|_| sigma2 < 1.0 && finished.len() > 1);
    let cost = |r: &LmReport<P>| match robust {
        Some(k) => scaled_cost(problem.edges, &k, &r.poses, sigma2),
        None => r.final_chi2,
    };
    (finished.into_iter())
        .map(|r| (cost(&r), r))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, r)| r)
}

/// The a-posteriori variance factor `χ² / r` of the edges `poses` accept
/// (odometry and every switch at [`REJECTED_BELOW`] or above; `r` their
/// redundancy), within `[10⁻³, 1]` as the covariance gate's
/// ([`crate::gps::variance_factor`]).
pub(super) fn accepted_variance_factor<P: LiePose>(
    edges: &[Edge<P>],
    robust: &Robust<'_>,
    poses: &[P],
) -> f64 {
    let (mut chi2, mut accepted) = (0.0, 0);
    for (e, &switchable) in edges.iter().zip(robust.switchable) {
        let c = edge_chi2(e, poses);
        if !switchable
            || robust
                .kernel
                .switch(c, || P::asc_scale(e, &poses[e.from], &poses[e.to]))
                >= REJECTED_BELOW
        {
            chi2 += c;
            accepted += 1;
        }
    }
    crate::gps::variance_factor(chi2, accepted, poses.len(), P::DOF).clamp(1e-3, 1.0)
}

/// The robust cost at `poses` with every `χ²` divided by `sigma2`: the
/// kernel's `ρ(χ²/σ²)` on switchable edges, `χ²/σ²` on the others.
fn scaled_cost<P: LiePose>(edges: &[Edge<P>], robust: &Robust<'_>, poses: &[P], sigma2: f64) -> f64 {
    let mut cost = 0.0;
    for (e, &switchable) in edges.iter().zip(robust.switchable) {
        let c = edge_chi2(e, poses) / sigma2;
        cost += if switchable {
            robust
                .kernel
                .cost(c, || P::asc_scale(e, &poses[e.from], &poses[e.to]))
        } else {
            c
        };
    }
    cost
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
    use crate::graph::{Edge, EdgeCost, EdgeKind, Information};
    use crate::nonlinear::polish;
    use crate::outliers::robust::tests::{square, square_start};
    use crate::outliers::{robust_polish, Comparison, OutlierConfig, RobustEdges, RobustSolution};

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

    /// A straight drive of 41 poses whose information claims σ = 0.1 (m,
    /// rad) where every measurement is exact; 15 true loop closures across
    /// the middle, and 18 wrong ones that agree with one another on the
    /// drive turned by 0.5 rad at pose 20. Returns the edges, the truth and
    /// the bent drive.
    fn bent_drive() -> (Vec<Edge>, Vec<Pose2>, Vec<Pose2>) {
        let truth: Vec<Pose2> = (0..41).map(|k| Pose2::new(k as f64, 0.0, 0.0)).collect();
        let turn = Pose2::new(0.0, 0.0, 0.5);
        let bent: Vec<Pose2> = (truth.iter())
            .map(|p| match p.x > 20.0 {
                true => truth[20].compose(&turn).compose(&truth[20].inverse().compose(p)),
                false => *p,
            })
            .collect();
        let edge = |from: usize, to: usize, poses: &[Pose2], kind| Edge {
            from,
            to,
            measurement: poses[from].inverse().compose(&poses[to]),
            information: Information::identity().scaled(100.0),
            kind,
        };
        let mut edges: Vec<Edge> = (0..40)
            .map(|k| edge(k, k + 1, &truth, EdgeKind::Odometry))
            .collect();
        edges.extend((0..15).map(|i| edge(i, 40 - i % 8, &truth, EdgeKind::LoopClosure)));
        edges.extend((0..18).map(|k| edge(k % 10, 30 + (7 * k) % 11, &bent, EdgeKind::LoopClosure)));
        (edges, truth, bent)
    }

    #[test]
    fn starts_are_compared_at_the_noise_level_the_first_start_shows() {
        let (edges, truth, bent) = bent_drive();
        let switchable: Vec<bool> = edges.iter().map(|e| e.kind == EdgeKind::LoopClosure).collect();
        let config = OutlierConfig::default();
        let params = LevenbergMarquardtParams::default();
        let solve = |starts: Vec<Vec<Pose2>>, compare| {
            let input = RobustEdges {
                edges: &edges,
                switchable: &switchable,
                held_out: &[],
            };
            robust_polish(input, starts, &config, params, 1, None, compare).unwrap()
        };
        let right = solve(vec![truth.clone()], Comparison::Stated);
        let wrong = solve(vec![bent.clone()], Comparison::Stated);
        // at the stated information the bent drive costs less: the wrong
        // loop closures outnumber the true ones, and the turn is cheap
        assert!(wrong.cost < right.cost, "{} against {}", wrong.cost, right.cost);
        let off = |s: &[f64]| {
            let count = |r: std::ops::Range<usize>| r.filter(|&e| s[e] < REJECTED_BELOW).count();
            (count(40..55), count(55..73))
        };
        assert_eq!(off(&right.switches), (0, 18));
        assert_eq!(off(&wrong.switches), (15, 0));
        // the bent drive accepts odometry and the 18 wrong loop closures:
        // the turn's χ² = 100 (2 − 2 cos 0.5 + 0.25) over 3 (58 − 40)
        // redundant terms
        let robust = Robust {
            kernel: config.kernel,
            switchable: &switchable,
        };
        let turn = 100.0 * (2.0 - 2.0 * 0.5f64.cos() + 0.25);
        let at_bent = accepted_variance_factor(&edges, &robust, &bent);
        assert!((at_bent - turn / 54.0).abs() < 1e-12, "{at_bent}");
        // polished, the straight drive's accepted set shows a noise level
        // far below the bent one's
        let sigma2 = accepted_variance_factor(&edges, &robust, &right.poses);
        let bent_sigma2 = accepted_variance_factor(&edges, &robust, &wrong.poses);
        assert!(sigma2 < 0.1 * bent_sigma2, "σ̂² {sigma2} against {bent_sigma2}");
        let scaled = |p: &[Pose2]| scaled_cost(&edges, &robust, p, sigma2);
        assert!(scaled(&right.poses) < scaled(&wrong.poses));
        let same = |got: &RobustSolution<Pose2>, want: &RobustSolution<Pose2>| {
            assert_eq!(off(&got.switches), off(&want.switches));
            for (g, w) in got.poses.iter().zip(&want.poses) {
                assert!(
                    (g.x - w.x).abs() + (g.y - w.y).abs() < 1e-9,
                    "{g:?} against {w:?}"
                );
            }
        };
        // from the straight drive, read at its noise level, the bent start
        // loses; at the stated information it wins
        let both = vec![truth.clone(), bent.clone()];
        same(&solve(both.clone(), Comparison::AtFirstStart), &right);
        same(&solve(both, Comparison::Stated), &wrong);
        // from the bent drive its own noise level is near the stated one,
        // and the bent start stays
        same(&solve(vec![bent, truth], Comparison::AtFirstStart), &wrong);
    }

    #[test]
    fn the_scaled_cost_divides_each_chi2_before_the_kernel() {
        let (edges, _, bent) = bent_drive();
        let switchable: Vec<bool> = edges.iter().map(|e| e.kind == EdgeKind::LoopClosure).collect();
        let kernel = OutlierConfig::default().kernel;
        let robust = Robust {
            kernel,
            switchable: &switchable,
        };
        // at the bent drive: the odometry's one turn (χ² = 100 (2 − 2 cos
        // 0.5 + 0.25)), 15 true loop closures off, the wrong ones exact
        let chi2: Vec<f64> = (edges.iter())
            .map(|e| Pose2::mahalanobis(&e.information, &Pose2::edge_error(e, &bent[e.from], &bent[e.to])))
            .collect();
        let turn: f64 = chi2[..40].iter().sum();
        assert!(
            (turn - 100.0 * (2.0 - 2.0 * 0.5f64.cos() + 0.25)).abs() < 1e-10,
            "{turn}"
        );
        for sigma2 in [1.0, 0.1, 0.01] {
            let want: f64 = turn / sigma2
                + chi2[40..]
                    .iter()
                    .map(|c| kernel.cost(c / sigma2, || 0.0))
                    .sum::<f64>();
            let got = scaled_cost(&edges, &robust, &bent, sigma2);
            assert!((got - want).abs() < 1e-9 * want, "{got} against {want}");
        }
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
