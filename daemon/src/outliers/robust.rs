//! [`robust_polish`]: the polish that switches wrong loop closures off,
//! shared by the engine's re-solve and `slamd solve --robust`.

use super::starts::{accepted_variance_factor, best_start};
use super::OutlierConfig;
use crate::geometry::Pose2;
use crate::graph::Edge;
use crate::nonlinear::{LevenbergMarquardtParams, LiePose, Problem, Robust};
use crate::sparse::FactorError;
use std::sync::atomic::AtomicBool;

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

/// The noise level at which [`robust_polish`] compares its finished starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Comparison {
    /// At the stated information: the lowest robust cost wins (a batch
    /// solve, whose first start is only a guess).
    Stated,
    /// At the a-posteriori variance factor `σ̂²` of the edges the first
    /// start accepts (odometry and every switch at
    /// [`REJECTED_BELOW`](super::REJECTED_BELOW) or above, within
    /// `[10⁻³, 1]`): the engine's re-solves, whose first start is the
    /// current estimate, so that the noise level the accepted set shows
    /// prices every start alike.
    AtFirstStart,
}

/// The edges `input` holds out (the verdict of PCM,
/// [`super::consistency`], or of paper A's cycle test) are switched off;
/// Levenberg–Marquardt then minimises the kernel's robust cost, each
/// switchable edge reweighted by `s²` at every iteration (edges dormant at a
/// start sit out until they wake: [`DORMANT_BELOW`](super::DORMANT_BELOW)), from every start
/// for [`PROBE_ITERATIONS`](super::PROBE_ITERATIONS) (a start far above the
/// ones before it, for [`LOOK_ITERATIONS`](super::LOOK_ITERATIONS):
/// [`ABANDON_RATIO`](super::ABANDON_RATIO)), then to convergence unless its
/// cost is past [`PRUNE_RATIO`](super::PRUNE_RATIO) times the lowest (lowest
/// first, giving up past [`LATE_RATIO`](super::LATE_RATIO) times a finished
/// one); of the finished ones, the least robust cost at the noise level
/// `compare` names gives the switches. The starts are probed `threads` at
/// a time, with the same outcome. Once `stop` is set, every polish ends
/// where it is. Fails when no start could be polished (or none was given).
pub fn robust_polish<P: LiePose>(
    input: RobustEdges<'_, P>,
    starts: Vec<Vec<P>>,
    config: &OutlierConfig,
    params: LevenbergMarquardtParams,
    threads: usize,
    stop: Option<&AtomicBool>,
    compare: Comparison,
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
    // one start has nothing to be compared with
    let sigma2 = match (compare, problem.robust, starts.as_slice()) {
        (Comparison::AtFirstStart, Some(robust), [first, _, ..]) => {
            accepted_variance_factor(problem.edges, &robust, first)
        }
        _ => 1.0,
    };
    let best = best_start(problem, starts, params, threads, sigma2)?;
    let poses = best.poses;
    let switches = (0..edges.len())
        .map(|a| {
            if out[a] {
                0.0
            } else if switchable[a] && config.enabled {
                let e = &edges[a];
                P::kernel_switch(&config.kernel, e, &poses[e.from], &poses[e.to])
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
pub(super) mod tests {
    use super::*;
    use crate::graph::{EdgeKind, Information};
    use crate::nonlinear::polish;
    use crate::outliers::DORMANT_BELOW;

    /// A square of 8 poses, odometry turning 0.02 rad short at every
    /// corner, one loop closure from the truth: the closure bends the map.
    pub fn square() -> Vec<Edge> {
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
        assert!(Pose2::kernel_switch(&config.kernel, closure, &start[7], &start[0]) < DORMANT_BELOW);
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
            Comparison::Stated,
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
                Comparison::Stated,
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

    /// Odometry composed from the origin.
    pub fn square_start(edges: &[Edge]) -> Vec<Pose2> {
        let mut start = vec![Pose2::IDENTITY];
        for e in &edges[..7] {
            let next = start.last().unwrap().compose(&e.measurement);
            start.push(next);
        }
        start
    }
}
