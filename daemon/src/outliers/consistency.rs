//! Pairwise consistency of loop closures through the odometry, and the
//! largest set of them that all agree: PCM (Mangelson, Dominic, Eustice and
//! Vasudevan, "Pairwise consistent measurement set maximization", ICRA
//! 2018; the loop-closure front of Kimera-RPGO).
//!
//! **The test.** Two loop closures `a = (i_a, j_a, Z_a)` and
//! `b = (i_b, j_b, Z_b)` close a cycle with the odometry:
//!
//! ```text
//! C = Z_a · O(j_a → j_b) · Z_b⁻¹ · O(i_b → i_a)
//! ```
//!
//! `O` the dead-reckoned motion along the odometry chain. If both are
//! right, `C` is the identity up to noise; they are consistent when
//! `eᵀ Σ_C⁻¹ e ≤ χ²`, `e = (x, y, θ)` of `C` and `Σ_C` its first-order
//! covariance. Each piece is a pose with a right perturbation,
//! `T Exp(ξ)`, `ξ ~ N(0, Σ)`; composing `(T₁, Σ₁)` with `(T₂, Σ₂)` gives
//! `(T₁T₂, Ad(T₂⁻¹) Σ₁ Ad(T₂⁻¹)ᵀ + Σ₂)`, and inverting `(T, Σ)` gives
//! `(T⁻¹, Ad(T) Σ Ad(T)ᵀ)`, with `Ad` the adjoint of SE(2) in `(x, y, θ)`
//! order, `[[R, (y, −x)ᵀ], [0, 1]]`.
//!
//! **The odometry in O(1).** Along a chain with dead reckoning `D_k` and
//! step covariances `Σ_k` (step `k → k+1`), the motion from `a` to `c > a`
//! is `D_a⁻¹ D_c` with covariance `Ad(D_c⁻¹) (P_c − P_a) Ad(D_c⁻¹)ᵀ`,
//! where `P_m = Σ_{k<m} Ad(D_{k+1}) Σ_k Ad(D_{k+1})ᵀ` is a prefix sum in
//! the world frame. Keyframes on different chains have no odometry between
//! them; a pair that needs it is counted consistent (no evidence against).
//!
//! **The set.** Loop closures are the vertices of a graph whose edges join
//! consistent pairs; the kept set is a large clique, grown greedily from
//! each of the vertices of highest degree: each step takes the candidate
//! with the most neighbours among the remaining candidates. The test costs
//! one pass over all pairs, O(m²) for m loop closures.

use crate::geometry::Pose2;
use crate::graph::{Edge, EdgeKind};
use nalgebra::{Matrix3, Vector3};

/// χ² with three degrees of freedom at 99%: the default bound of the test.
pub const CONSISTENT_CHI2: f64 = 11.3449;

/// How many of the highest-degree vertices the clique search starts from.
const CLIQUE_STARTS: usize = 16;

/// A pose with its cosine and sine kept, so chains of compositions need no
/// trigonometry.
#[derive(Clone, Copy, Debug)]
struct Rigid {
    x: f64,
    y: f64,
    c: f64,
    s: f64,
}

impl Rigid {
    const IDENTITY: Rigid = Rigid {
        x: 0.0,
        y: 0.0,
        c: 1.0,
        s: 0.0,
    };

    fn of(p: &Pose2) -> Self {
        let (s, c) = p.theta.sin_cos();
        Self { x: p.x, y: p.y, c, s }
    }

    fn compose(&self, o: &Rigid) -> Rigid {
        Rigid {
            x: self.x + self.c * o.x - self.s * o.y,
            y: self.y + self.s * o.x + self.c * o.y,
            c: self.c * o.c - self.s * o.s,
            s: self.s * o.c + self.c * o.s,
        }
    }

    fn inverse(&self) -> Rigid {
        Rigid {
            x: -(self.c * self.x + self.s * self.y),
            y: self.s * self.x - self.c * self.y,
            c: self.c,
            s: -self.s,
        }
    }

    /// `Ad` in `(x, y, θ)` order: `T Exp(ξ) = Exp(Ad ξ) T`.
    fn adjoint(&self) -> Matrix3<f64> {
        Matrix3::new(self.c, -self.s, self.y, self.s, self.c, -self.x, 0.0, 0.0, 1.0)
    }
}

/// `A Σ Aᵀ`.
fn sandwich(a: &Matrix3<f64>, s: &Matrix3<f64>) -> Matrix3<f64> {
    a * s * a.transpose()
}

/// A pose with the covariance of its right perturbation.
#[derive(Clone, Copy, Debug)]
struct Uncertain {
    pose: Rigid,
    cov: Matrix3<f64>,
}

impl Uncertain {
    fn then(&self, o: &Uncertain) -> Uncertain {
        Uncertain {
            pose: self.pose.compose(&o.pose),
            cov: sandwich(&o.pose.inverse().adjoint(), &self.cov) + o.cov,
        }
    }

    fn inverse(&self) -> Uncertain {
        Uncertain {
            pose: self.pose.inverse(),
            cov: sandwich(&self.pose.adjoint(), &self.cov),
        }
    }
}

/// Dead reckoning along the odometry chains of a graph, with the prefix
/// sums of the steps' covariances (see the module doc). Grows with the
/// graph: an odometry edge `i → j` extends `i`'s chain when `i` ends it
/// and `j` is still a chain of its own; every other keyframe starts a
/// chain of its own. (Pairs tested while `j` was alone stay as tested.)
#[derive(Clone, Debug, Default)]
struct Chains {
    /// Chain of each keyframe (its first keyframe).
    chain: Vec<usize>,
    /// Position of each keyframe along its chain.
    depth: Vec<u32>,
    /// Whether a keyframe ends its chain (no odometry from it yet).
    tip: Vec<bool>,
    /// `D_k`, the dead-reckoned pose in its chain's frame.
    pose: Vec<Rigid>,
    /// `P_k`.
    prefix: Vec<Matrix3<f64>>,
}

impl Chains {
    /// Takes in `n` keyframes and the odometry among `edges`.
    fn extend(&mut self, n: usize, edges: &[Edge]) {
        if self.chain.len() < n {
            let old = self.chain.len();
            self.chain.extend(old..n);
            self.depth.resize(n, 0);
            self.tip.resize(n, true);
            self.pose.resize(n, Rigid::IDENTITY);
            self.prefix.resize(n, Matrix3::zeros());
        }
        for e in edges {
            let (i, j) = (e.from, e.to);
            let alone = j < n && self.chain[j] == j && self.tip[j];
            if e.kind == EdgeKind::Odometry && i < n && i != j && alone && self.tip[i] && self.chain[i] != j {
                let pose = self.pose[i].compose(&Rigid::of(&e.measurement));
                self.chain[j] = self.chain[i];
                self.depth[j] = self.depth[i] + 1;
                self.prefix[j] = self.prefix[i] + sandwich(&pose.adjoint(), &e.information.covariance());
                self.pose[j] = pose;
                self.tip[i] = false;
            }
        }
    }

    /// The odometry from keyframe `a` to `c`, if they share a chain.
    fn between(&self, a: usize, c: usize) -> Option<Uncertain> {
        if self.chain[a] != self.chain[c] {
            return None;
        }
        let (lo, hi) = if self.depth[a] <= self.depth[c] {
            (a, c)
        } else {
            (c, a)
        };
        let forward = Uncertain {
            pose: self.pose[lo].inverse().compose(&self.pose[hi]),
            cov: sandwich(
                &self.pose[hi].inverse().adjoint(),
                &(self.prefix[hi] - self.prefix[lo]),
            ),
        };
        Some(if lo == a { forward } else { forward.inverse() })
    }
}

/// The consistency graph of a pose graph's loop closures, grown as the
/// pose graph grows, and its clique.
#[derive(Clone, Debug, Default)]
pub struct ConsistencyGraph {
    chains: Chains,
    /// The endpoints of every edge taken in so far. A graph that is not
    /// a prefix or an extension of these starts the consistency graph
    /// afresh; a shorter one (a re-solve behind the foreground) uses it
    /// as it is.
    ends: Vec<(usize, usize)>,
    /// The edge index of each vertex, ascending.
    loops: Vec<usize>,
    measured: Vec<Uncertain>,
    /// Row `v`: bit `u` set when `u` and `v` are consistent (rows grow as
    /// vertices arrive; missing words are zero).
    rows: Vec<Vec<u64>>,
}

impl ConsistencyGraph {
    /// Takes in the edges of `edges` (over `n` keyframes) past the ones
    /// taken in already: odometry extends the chains, and each edge whose
    /// index `candidate` accepts becomes a vertex, tested against every
    /// earlier one at bound `chi2`.
    pub fn update(&mut self, n: usize, edges: &[Edge], candidate: impl Fn(usize) -> bool, chi2: f64) {
        let common = self.ends.len().min(edges.len());
        let agrees = common == 0 || self.ends[common - 1] == (edges[common - 1].from, edges[common - 1].to);
        if !agrees {
            *self = Self::default();
        }
        let seen = self.ends.len();
        if edges.len() <= seen {
            return;
        }
        self.chains.extend(n, &edges[seen..]);
        for (e, edge) in edges.iter().enumerate().skip(seen) {
            if candidate(e) && edge.from < n && edge.to < n {
                self.add(e, edge, edges, chi2);
            }
            self.ends.push((edge.from, edge.to));
        }
    }

    fn add(&mut self, e: usize, eb: &Edge, edges: &[Edge], chi2: f64) {
        let b = self.loops.len();
        let mb = Uncertain {
            pose: Rigid::of(&eb.measurement),
            cov: eb.information.covariance(),
        };
        let back = mb.inverse();
        let mut row = vec![0u64; b / 64 + 1];
        for a in 0..b {
            let ea = &edges[self.loops[a]];
            let consistent = match (
                self.chains.between(ea.to, eb.to),
                self.chains.between(eb.from, ea.from),
            ) {
                (Some(tail), Some(head)) => {
                    mahalanobis(&self.measured[a].then(&tail).then(&back).then(&head)) <= chi2
                }
                _ => true,
            };
            if consistent {
                row[a / 64] |= 1 << (a % 64);
                let other = &mut self.rows[a];
                if other.len() <= b / 64 {
                    other.resize(b / 64 + 1, 0);
                }
                other[b / 64] |= 1 << (b % 64);
            }
        }
        self.loops.push(e);
        self.measured.push(mb);
        self.rows.push(row);
    }

    /// Whether vertices `a` and `b` are consistent.
    fn consistent(&self, a: usize, b: usize) -> bool {
        self.rows[a].get(b / 64).is_some_and(|w| w >> (b % 64) & 1 == 1)
    }

    /// A large clique (see the module doc) among the vertices whose edges
    /// `among` lists (ascending edge indices; others are left out), as
    /// edge indices, ascending.
    pub fn clique(&self, among: &[usize]) -> Vec<usize> {
        let mut mask = vec![0u64; self.loops.len().div_ceil(64)];
        let mut present = Vec::with_capacity(among.len());
        let mut next = 0;
        for &e in among {
            while next < self.loops.len() && self.loops[next] < e {
                next += 1;
            }
            if next < self.loops.len() && self.loops[next] == e {
                mask[next / 64] |= 1 << (next % 64);
                present.push(next);
            }
        }
        let degree: Vec<u32> = present.iter().map(|&v| and_count(&self.rows[v], &mask)).collect();
        let mut order: Vec<usize> = (0..present.len()).collect();
        order.sort_by_key(|&q| (std::cmp::Reverse(degree[q]), q));
        let mut best: Vec<usize> = Vec::new();
        for &q in order.iter().take(CLIQUE_STARTS) {
            // a clique through the vertex has at most degree + 1 vertices
            if (degree[q] as usize) < best.len() {
                break;
            }
            let clique = self.greedy_from(present[q], &present, &mask);
            if clique.len() > best.len() {
                best = clique;
            }
        }
        let mut kept: Vec<usize> = best.into_iter().map(|v| self.loops[v]).collect();
        kept.sort_unstable();
        kept
    }

    /// Which of the edges `ids` (ascending edge indices; `switchable`
    /// alike) PCM holds out: the switchable ones outside the clique among
    /// the switchable ones.
    pub fn held_out(&self, ids: &[usize], switchable: &[bool]) -> Vec<bool> {
        let candidates: Vec<usize> = ids
            .iter()
            .zip(switchable)
            .filter(|(_, &s)| s)
            .map(|(&e, _)| e)
            .collect();
        let kept = self.clique(&candidates);
        ids.iter()
            .zip(switchable)
            .map(|(e, &s)| s && kept.binary_search(e).is_err())
            .collect()
    }

    /// A clique through `v` within `mask` (`present`: its vertices), grown
    /// from its neighbours: each step takes the candidate with the most
    /// neighbours among the candidates (the lowest vertex on ties) and
    /// keeps the candidates consistent with it, until the candidates left
    /// are a clique themselves.
    fn greedy_from(&self, v: usize, present: &[usize], mask: &[u64]) -> Vec<usize> {
        let mut cand: Vec<usize> = present
            .iter()
            .copied()
            .filter(|&u| self.consistent(v, u))
            .collect();
        let bits: Vec<u64> = mask
            .iter()
            .enumerate()
            .map(|(w, m)| m & self.rows[v].get(w).copied().unwrap_or(0))
            .collect();
        let mut inner: Vec<u32> = vec![0; self.loops.len()];
        for &u in &cand {
            inner[u] = and_count(&self.rows[u], &bits);
        }
        let mut clique = vec![v];
        while let Some(&first) = cand.first() {
            let (mut pick, mut least) = (first, inner[first]);
            for &u in &cand {
                if inner[u] > inner[pick] {
                    pick = u;
                }
                least = least.min(inner[u]);
            }
            if least as usize + 1 == cand.len() {
                clique.extend_from_slice(&cand);
                break;
            }
            clique.push(pick);
            let (dropped, kept): (Vec<usize>, Vec<usize>) = cand
                .iter()
                .partition(|&&w| w == pick || !self.consistent(pick, w));
            for &w in &dropped {
                for &x in &kept {
                    inner[x] -= u32::from(self.consistent(w, x));
                }
            }
            cand = kept;
        }
        clique
    }
}

/// `eᵀ Σ⁻¹ e` of a cycle, `e = (x, y, θ)` with θ wrapped.
fn mahalanobis(cycle: &Uncertain) -> f64 {
    let e = Vector3::new(cycle.pose.x, cycle.pose.y, cycle.pose.s.atan2(cycle.pose.c));
    match cycle.cov.cholesky() {
        Some(l) => e.dot(&l.solve(&e)),
        None => f64::INFINITY,
    }
}

fn and_count(a: &[u64], b: &[u64]) -> u32 {
    a.iter().zip(b).map(|(x, y)| (x & y).count_ones()).sum()
}

#[cfg(test)]
mod tests {
    use super::*;
    use slamd_types::Information;

    fn edge(from: usize, to: usize, z: Pose2, information: f64, kind: EdgeKind) -> Edge {
        let w = information;
        Edge {
            from,
            to,
            measurement: z,
            information: Information::from_upper([w, 0.0, 0.0, w, 0.0, w]).unwrap(),
            kind,
        }
    }

    /// A loop closure with information 10⁴.
    fn closure(from: usize, to: usize, z: Pose2) -> Edge {
        edge(from, to, z, 1e4, EdgeKind::LoopClosure)
    }

    /// What PCM keeps of `candidates` (ascending) in a whole graph.
    fn consistent_set(edges: &[Edge], candidates: &[usize]) -> Vec<usize> {
        let mut graph = ConsistencyGraph::default();
        graph.update(
            80,
            edges,
            |e| candidates.binary_search(&e).is_ok(),
            CONSISTENT_CHI2,
        );
        graph.clique(candidates)
    }

    /// Two laps of a circle of radius 10 m, 40 keyframes a lap, with exact
    /// odometry (information 10⁴): keyframe `k` and `k + 40` coincide.
    fn two_laps() -> (Vec<Pose2>, Vec<Edge>) {
        let truth: Vec<Pose2> = (0..80)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 40.0;
                Pose2::new(10.0 * a.cos(), 10.0 * a.sin(), a + std::f64::consts::FRAC_PI_2)
            })
            .collect();
        let edges = (1..80)
            .map(|k| edge(k - 1, k, truth[k - 1].between(&truth[k]), 1e4, EdgeKind::Odometry))
            .collect();
        (truth, edges)
    }

    #[test]
    fn two_loop_closures_between_the_same_keyframes_agree_within_the_bound() {
        // a = b + (δ, 0, 0) at σ² = 0.01 each: d² = δ² / 0.02 (hand-computed
        // in the doc of the test's bound: Ad(Z_b) leaves x alone)
        let (_, mut edges) = two_laps();
        let z = Pose2::new(5.0, 0.0, 0.0);
        edges.push(edge(3, 50, z, 100.0, EdgeKind::LoopClosure));
        for (delta, agree) in [(0.3, true), (0.6, false)] {
            let mut all = edges.clone();
            all.push(edge(
                3,
                50,
                Pose2::new(5.0 + delta, 0.0, 0.0),
                100.0,
                EdgeKind::LoopClosure,
            ));
            let mut graph = ConsistencyGraph::default();
            graph.update(80, &all, |e| e >= 79, CONSISTENT_CHI2);
            // d² = 4.5 and 18 against the bound 11.34
            assert_eq!(graph.consistent(0, 1), agree, "δ = {delta}");
            assert_eq!(graph.consistent(1, 0), agree);
        }
    }

    #[test]
    fn the_true_loop_closures_outnumber_a_group_that_agrees_only_with_itself() {
        let (truth, mut edges) = two_laps();
        let first = edges.len();
        // 40 true loop closures k → k + 40 (the same place) ...
        for k in 0..40 {
            edges.push(closure(k, k + 40, truth[k].between(&truth[k + 40])));
        }
        // ... a group of 10 wrong ones claiming k and k + 45 coincide (they
        // agree with each other: the circle is symmetric) ...
        for k in 0..10 {
            edges.push(closure(k, k + 45, Pose2::IDENTITY));
        }
        // ... and 5 lone wrong ones
        for (i, j) in [(2, 33), (7, 61), (12, 70), (20, 44), (30, 75)] {
            edges.push(closure(i, j, Pose2::new(0.5, -0.2, 0.1)));
        }
        let candidates: Vec<usize> = (first..edges.len()).collect();
        let kept = consistent_set(&edges, &candidates);
        assert_eq!(kept, (first..first + 40).collect::<Vec<_>>());
    }

    #[test]
    fn a_graph_grown_in_steps_keeps_what_a_whole_one_keeps() {
        let (truth, mut edges) = two_laps();
        let first = edges.len();
        for k in (0..40).step_by(3) {
            edges.push(closure(k, k + 40, truth[k].between(&truth[k + 40])));
            if k < 20 {
                edges.push(closure(k, k + 43, Pose2::IDENTITY));
            }
        }
        let candidates: Vec<usize> = (first..edges.len()).collect();
        let whole = consistent_set(&edges, &candidates);
        assert_eq!(whole.len(), 14);
        assert!(whole.iter().all(|&e| edges[e].to == edges[e].from + 40));
        let mut grown = ConsistencyGraph::default();
        for end in [first + 5, first + 6, edges.len()] {
            grown.update(80, &edges[..end], |e| e >= first, CONSISTENT_CHI2);
        }
        assert_eq!(grown.clique(&candidates), whole);
        // a graph that does not extend the one taken in starts afresh
        let other: Vec<Edge> = edges[..first + 2].iter().rev().copied().collect();
        grown.update(80, &other, |e| e < 2, CONSISTENT_CHI2);
        assert_eq!(grown.loops, vec![0, 1]);
    }

    #[test]
    fn keyframes_on_different_chains_give_no_evidence_against() {
        // two chains (no odometry 39 → 40): every pair that needs the
        // odometry between them counts as consistent
        let (truth, edges) = two_laps();
        let mut edges: Vec<Edge> = edges.into_iter().filter(|e| e.to != 40).collect();
        let first = edges.len();
        let off = Pose2::new(3.0, 0.0, 0.0);
        edges.push(closure(5, 45, truth[5].between(&truth[45])));
        edges.push(closure(49, 9, truth[49].between(&truth[9]).compose(&off)));
        edges.push(closure(2, 9, truth[2].between(&truth[9])));
        edges.push(closure(3, 10, truth[3].between(&truth[10]).compose(&off)));
        let mut graph = ConsistencyGraph::default();
        graph.update(80, &edges, |e| e >= first, CONSISTENT_CHI2);
        assert!(graph.consistent(0, 1), "across the chains: no evidence");
        assert!(!graph.consistent(2, 3), "within one chain: 3 m apart");
    }
}
