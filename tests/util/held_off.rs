//! True loop closures the outlier filter holds off, and what each costs
//! the graph.
//!
//! A loop closure's Δχ² is the rise of the least-squares optimum's χ² when
//! it joins the graph, `χ²(G) − χ²(G ∖ e)`, each at its own optimum: for a
//! true loop closure it is χ²₃-distributed (to first order), whatever the
//! geometry. Its own χ² at the optimum is not: where the graph holds the
//! two ends loosely it bends to fit, and the residual left on the loop
//! closure is small while the bending costs the rest of the graph.

use crate::optimum;
use slamd::engine::EngineConfig;
use slamd::graph::{edge_chi2, EdgeKind, PoseGraph};
use slamd::outliers::REJECTED_BELOW;
use slamd::synthetic::{generate, World, WorldParams};

/// A loop closure switched off at the end of a stream.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeldOff {
    /// Its index in the graph.
    pub edge: usize,
    /// `χ²(G) − χ²(G ∖ e)` at the least-squares optima.
    pub delta_chi2: f64,
    /// Its own χ² at the least-squares optimum of `G`.
    pub own_chi2: f64,
}

/// `slamd synth`'s world of `poses` keyframes and `seed`, with one more
/// loop closure between keyframes `a` and `b` measured exactly from the
/// ground truth ([`with_exact_closure`]).
pub fn world_with_exact_closure(poses: usize, seed: u64, a: usize, b: usize) -> PoseGraph {
    let world = generate(&WorldParams {
        poses,
        seed,
        ..WorldParams::default()
    });
    with_exact_closure(world, a, b)
}

/// `world`'s graph with one more loop closure between keyframes `a` and
/// `b` (which must differ) measured exactly from its ground truth, with
/// the world's information.
pub fn with_exact_closure(world: World, a: usize, b: usize) -> PoseGraph {
    let mut g = world.graph;
    let info = g.edges()[0].information; // every edge of the world has it
    let (i, j) = (a.min(b), a.max(b));
    let exact = world.truth[i].between(&world.truth[j]);
    g.add_edge(i as u64, j as u64, exact, info, EdgeKind::LoopClosure)
        .expect("an edge between two keyframes of the world");
    g
}

/// The loop closures of `g` switched off after a replay closed by the final
/// re-solve, as graph edge indices. With `config.background` false the
/// replay is deterministic.
pub fn switched_off(g: &PoseGraph, config: EngineConfig) -> Vec<usize> {
    let (mut engine, sent) = crate::replay(g, config, |_, _| {});
    engine.resolve_now();
    let switches = engine.switches();
    (sent.iter().zip(&switches))
        .filter(|&(&e, &s)| g.edges()[e].kind == EdgeKind::LoopClosure && s < REJECTED_BELOW)
        .map(|(&e, _)| e)
        .collect()
}

/// `g` without edge `e`.
pub fn without(g: &PoseGraph, e: usize) -> PoseGraph {
    let mut edges = g.edges().to_vec();
    edges.remove(e);
    PoseGraph::from_parts(g.keyframes().to_vec(), edges).expect("the same keyframes")
}

/// Every loop closure `config`'s filter switches off in `g` (all of them
/// true, in a synthetic world), with what it costs.
pub fn held_off(g: &PoseGraph, config: EngineConfig) -> Vec<HeldOff> {
    let off = switched_off(g, config);
    if off.is_empty() {
        return Vec::new();
    }
    let best = optimum(g);
    off.into_iter()
        .map(|edge| HeldOff {
            edge,
            delta_chi2: best.chi2 - optimum(&without(g, edge)).chi2,
            own_chi2: edge_chi2(&g.edges()[edge], &best.poses),
        })
        .collect()
}
