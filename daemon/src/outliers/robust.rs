//! [`robust_polish`]: the polish that switches wrong loop closures off,
//! shared by the engine's re-solve and `slamd solve --robust`.

use super::OutlierConfig;
use crate::geometry::Pose2;
use crate::graph::Edge;
use crate::nonlinear::{polish, LevenbergMarquardtParams, LiePose, LmReport, Problem, Robust};
use crate::sparse::FactorError;
use std::sync::atomic::AtomicBool;
use std::sync::{Mutex, OnceLock};

/// What the robust polish found.
#[derive(Clone, Debug)]
pub struct RobustSolution<P = Pose2> {
    /// The poses.
    pub poses: Vec<P>,
    /// The switch `s ∈ [0, 1]` of each edge (1 where not switchable, 0 where
    /// it was held out: PCM's or the cycle test's verdict).
    pub switches: Vec<f64>,
    /// The robust cost at `poses`.
    pub cost: f64,
}

/// The edges of a [`robust_polish`] and what it may do with each.
#[derive(Clone, Copy, Debug)]
pub struct RobustEdges<'a, P: LiePose = Pose2> {
    /// The edges.
    pub edges: &'a [Edge<P>],
    /// Whether each edge gets a switch.
    pub switchable: &'a [bool],
    /// Edges held out before the polish, at switch 0 (the verdict of PCM
    /// or of the cycle test, [`super::cycles::rejected`]); a shorter slice
    /// holds out none past its end.
    pub held_out: &'a [bool],
}

/// Iterations each start of [`robust_polish`] gets before the pruning.
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
fn polish_awake<P: LiePose>(
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
                || robust.kernel.switch(e, &poses[e.from], &poses[e.to]) >= DORMANT_BELOW)
        {
            awake[a] = true;
            woke += 1;
        }
    }
    woke
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

/// The edges `input` holds out (the verdict of PCM,
/// [`super::consistency`], or of paper A's cycle test) are switched off;
/// Levenberg–Marquardt then minimises the kernel's robust cost, each
/// switchable edge reweighted by `s²` at every iteration (edges dormant at a
/// start sit out until they wake: [`DORMANT_BELOW`]), from every start
/// for [`PROBE_ITERATIONS`] (a start far above the ones before it, for
/// [`LOOK_ITERATIONS`]: [`ABANDON_RATIO`]), then to convergence unless its
/// cost is past [`PRUNE_RATIO`] times the lowest; the lowest final cost
/// gives the switches. The starts are probed `threads` at a time, with
/// the same outcome. Once `stop` is set, every polish ends where it is.
/// Fails when no start could be polished (or none was given).
pub fn robust_polish<P: LiePose>(
    input: RobustEdges<'_, P>,
    starts: Vec<Vec<P>>,
    config: &OutlierConfig,
    params: LevenbergMarquardtParams,
    threads: usize,
    stop: Option<&AtomicBool>,
) -> Result<RobustSolution<P>, FactorError> {
    let RobustEdges {
        edges,
        switchable,
        held_out,
    } = input;
    let mut out = vec![false; edges.len()];
    for (o, &h) in out.iter_mut().zip(held_out) {
        *o |= h;
    }
    let kept: Vec<usize> = (0..edges.len()).filter(|&a| !out[a]).collect();
    let kept_edges: Vec<Edge<P>> = kept.iter().map(|&a| edges[a]).collect();
    let kept_switchable: Vec<bool> = kept.iter().map(|&a| switchable[a]).collect();
    let problem = Problem {
        edges: &kept_edges,
        priors: &[],
        robust: config.enabled.then_some(Robust {
            kernel: config.kernel,
            switchable: &kept_switchable,
        }),
        stop,
    };
    // every start gets a probe of a few iterations; those within
    // `PRUNE_RATIO` of the lowest cost go on to convergence (a start in a
    // wrong basin, such as a linear solution bent by a thousand outliers,
    // would run to the iteration cap for nothing)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{EdgeKind, Information};

    /// A square of 8 poses, odometry turning 0.02 rad short at every
    /// corner, one loop closure from the truth: the closure bends the map.
    fn square() -> Vec<Edge> {
        let truth: Vec<Pose2> = (0..8)
            .map(|k| {
                let side = k / 2;
                let along = (k % 2) as f64;
                let theta = side as f64 * std::f64::consts::FRAC_PI_2;
                let corner = [(0.0, 0.0), (2.0, 0.0), (2.0, 2.0), (0.0, 2.0)][side];
                Pose2::new(
                    corner.0 + along * theta.cos(),
                    corner.1 + along * theta.sin(),
                    theta,
                )
            })
            .collect();
        let info = Information::identity().scaled(100.0);
        let mut edges: Vec<Edge> = (0..7)
            .map(|k| {
                let mut z = truth[k].inverse().compose(&truth[k + 1]);
                if k % 2 == 1 {
                    z = Pose2::new(z.x, z.y, z.theta - 0.02);
                }
                Edge {
                    from: k,
                    to: k + 1,
                    measurement: z,
                    information: info,
                    kind: EdgeKind::Odometry,
                }
            })
            .collect();
        edges.push(Edge {
            from: 7,
            to: 0,
            measurement: truth[7].inverse().compose(&truth[0]),
            information: info,
            kind: EdgeKind::LoopClosure,
        });
        edges
    }

    #[test]
    fn a_closure_dormant_at_the_start_wakes_and_shapes_the_result() {
        let edges = square();
        let switchable: Vec<bool> = edges.iter().map(|e| e.kind == EdgeKind::LoopClosure).collect();
        // odometry composed, then the last pose thrown 30 m off: the closure
        // starts with χ² ≈ 9·10⁴, a switch ≈ 10⁻⁴ (dormant)
        let mut start = square_start(&edges);
        start[7] = Pose2::new(start[7].x + 30.0, start[7].y, start[7].theta);
        let config = OutlierConfig::default();
        let (closure, robust) = (
            &edges[7],
            Robust {
                kernel: config.kernel,
                switchable: &switchable,
            },
        );
        assert!(config.kernel.switch(closure, &start[7], &start[0]) < DORMANT_BELOW);
        let params = LevenbergMarquardtParams::default();
        let got = robust_polish(
            RobustEdges {
                edges: &edges,
                switchable: &switchable,
                held_out: &[],
            },
            vec![start.clone()],
            &config,
            params,
            1,
            None,
        )
        .unwrap();
        // the reference: every edge in every linear system
        let problem = Problem {
            edges: &edges,
            priors: &[],
            robust: Some(robust),
            stop: None,
        };
        let want = polish(problem, start, params).unwrap();
        assert!(got.switches[7] > 0.99, "switch {}", got.switches[7]);
        for (g, w) in got.poses.iter().zip(&want.poses) {
            assert!(
                (g.x - w.x).abs() < 1e-6 && (g.y - w.y).abs() < 1e-6,
                "{g:?} vs {w:?}"
            );
        }
        // and the closure moved the map off plain odometry
        let odometry_end = edges[..7]
            .iter()
            .fold(Pose2::IDENTITY, |p, e| p.compose(&e.measurement));
        assert!((got.poses[7].theta - odometry_end.theta).abs() > 1e-3);
    }

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

    #[test]
    fn a_stopped_polish_ends_where_it_is() {
        let edges = square();
        let switchable: Vec<bool> = edges.iter().map(|e| e.kind == EdgeKind::LoopClosure).collect();
        let start = square_start(&edges);
        let (config, params) = (OutlierConfig::default(), LevenbergMarquardtParams::default());
        let stop = AtomicBool::new(true);
        let polish = || {
            let starts = vec![start.clone()];
            robust_polish(
                RobustEdges {
                    edges: &edges,
                    switchable: &switchable,
                    held_out: &[],
                },
                starts,
                &config,
                params,
                1,
                Some(&stop),
            )
            .unwrap()
        };
        let stopped = polish();
        assert_eq!(stopped.poses, start);
        // not stopped, the same call moves the map
        stop.store(false, std::sync::atomic::Ordering::Relaxed);
        let done = polish();
        assert!((done.poses[7].theta - start[7].theta).abs() > 1e-3);
        assert!(done.cost < stopped.cost, "{} vs {}", done.cost, stopped.cost);
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

    /// Odometry composed from the origin.
    fn square_start(edges: &[Edge]) -> Vec<Pose2> {
        let mut start = vec![Pose2::IDENTITY];
        for e in &edges[..7] {
            let next = start.last().unwrap().compose(&e.measurement);
            start.push(next);
        }
        start
    }
}
