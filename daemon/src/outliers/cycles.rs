//! Paper A's outlier test: cycle consistency with IQR fences (its §6).
//!
//! Every edge gets a prior outlier probability from its variance. For a
//! loop closure `(i, j)` the test gathers alternative transforms `T_ij`:
//! other direct edges between `i` and `j`, and compositions through one- and
//! two-keyframe detours, preferring paths of low prior. With the edge's own
//! transform among them, each component `(x, y, θ)` gets Tukey's fences
//! `[Q1 − k·IQR, Q3 + k·IQR]`; an edge outside them is rejected. With too
//! few alternatives the test defers instead of guessing.

use crate::geometry::{wrap_angle, Pose2};
use crate::graph::Edge;
use std::collections::HashMap;

/// The test's parameters.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CycleParams {
    /// Translational variance (m²) below which an edge's prior is 0.1.
    pub var_low: f64,
    /// Translational variance (m²) below which it is 0.2 (else 0.3).
    pub var_high: f64,
    /// Fence factor k (Tukey's 1.5).
    pub k: f64,
    /// Alternatives gathered at most, lowest prior first.
    pub max_alternatives: usize,
    /// Fewer alternatives than this: defer.
    pub min_alternatives: usize,
    /// Fences are never narrower than this many of the edge's own σ, so
    /// that exact agreement is not split by round-off.
    pub min_sigmas: f64,
}

impl Default for CycleParams {
    fn default() -> Self {
        Self {
            var_low: 0.01,
            var_high: 0.1,
            k: 1.5,
            max_alternatives: 12,
            min_alternatives: 3,
            min_sigmas: 3.0,
        }
    }
}

/// Paper A's prior outlier probability from an edge's translational
/// variance `tr Σ_xy / 2`: 0.1 below `var_low`, 0.2 below `var_high`, else 0.3.
pub fn prior_probability(variance: f64, p: &CycleParams) -> f64 {
    if variance < p.var_low {
        0.1
    } else if variance < p.var_high {
        0.2
    } else {
        0.3
    }
}

fn variance(e: &Edge) -> f64 {
    let c = e.information.covariance();
    (c[(0, 0)] + c[(1, 1)]) / 2.0
}

/// What the test says about one edge.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    /// Inside the fences.
    Accept,
    /// Outside a fence.
    Reject,
    /// Too few alternatives to judge.
    Defer,
}

/// Tukey's fences of `v` with factor `k`, at least `min_half` wide around
/// the median.
pub fn fences(v: &mut [f64], k: f64, min_half: f64) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let x = p * (v.len() - 1) as f64;
        let (lo, hi) = (x.floor() as usize, x.ceil() as usize);
        v[lo] + (v[hi] - v[lo]) * (x - lo as f64)
    };
    let (q1, q3, med) = (q(0.25), q(0.75), q(0.5));
    let iqr = q3 - q1;
    (
        (q1 - k * iqr).min(med - min_half),
        (q3 + k * iqr).max(med + min_half),
    )
}

/// The graph's edges, indexed for detours.
pub struct CycleCheck<'a> {
    edges: &'a [Edge],
    usable: &'a [bool],
    adjacency: Vec<Vec<usize>>,
    between: HashMap<(usize, usize), Vec<usize>>,
}

impl<'a> CycleCheck<'a> {
    /// Indexes the `usable` edges over `n` keyframes.
    pub fn new(n: usize, edges: &'a [Edge], usable: &'a [bool]) -> Self {
        let mut adjacency = vec![Vec::new(); n];
        let mut between: HashMap<(usize, usize), Vec<usize>> = HashMap::new();
        for (k, e) in edges.iter().enumerate().filter(|(k, _)| usable[*k]) {
            adjacency[e.from].push(k);
            adjacency[e.to].push(k);
            between.entry(key(e.from, e.to)).or_default().push(k);
        }
        Self {
            edges,
            usable,
            adjacency,
            between,
        }
    }

    /// `T_ab` through edge `k` (which joins `a` and `b`), with its prior.
    fn step(&self, k: usize, a: usize) -> (usize, Pose2, f64) {
        let e = &self.edges[k];
        let prior = prior_probability(variance(e), &CycleParams::default());
        if e.from == a {
            (e.to, e.measurement, prior)
        } else {
            (e.from, e.measurement.inverse(), prior)
        }
    }

    /// Alternatives to edge `skip` for `T_ij`: `(summed prior, transform)`,
    /// lowest prior first, at most `max`.
    pub fn alternatives(&self, i: usize, j: usize, skip: usize, max: usize) -> Vec<(f64, Pose2)> {
        let mut out = Vec::new();
        let others = |a: usize| self.adjacency[a].iter().copied().filter(move |&k| k != skip);
        for &k in self.between.get(&key(i, j)).into_iter().flatten() {
            if k != skip {
                let (_, t, p) = self.step(k, i);
                out.push((p, t));
            }
        }
        for k1 in others(i) {
            let (m, t1, p1) = self.step(k1, i);
            if m == j {
                continue;
            }
            // one keyframe: i → m → j
            for &k2 in self.between.get(&key(m, j)).into_iter().flatten() {
                if k2 != skip && k2 != k1 {
                    let (_, t2, p2) = self.step(k2, m);
                    out.push((p1 + p2, t1.compose(&t2)));
                }
            }
            // two keyframes: i → m → m2 → j
            for k3 in others(j) {
                let (m2, t3j, p3) = self.step(k3, j);
                if m2 == i || m2 == m {
                    continue;
                }
                for &k2 in self.between.get(&key(m, m2)).into_iter().flatten() {
                    if k2 != skip && k2 != k1 && k2 != k3 {
                        let (_, t2, p2) = self.step(k2, m);
                        out.push((p1 + p2 + p3, t1.compose(&t2).compose(&t3j.inverse())));
                    }
                }
            }
        }
        out.sort_by(|a, b| a.0.total_cmp(&b.0));
        out.truncate(max);
        out
    }

    /// The test of edge `e`.
    pub fn verdict(&self, e: usize, p: &CycleParams) -> Verdict {
        let edge = &self.edges[e];
        debug_assert!(self.usable.len() == self.edges.len());
        let alts = self.alternatives(edge.from, edge.to, e, p.max_alternatives);
        if alts.len() < p.min_alternatives {
            return Verdict::Defer;
        }
        let own = edge.measurement;
        let sigma = edge.information.covariance().map(|v| v.max(0.0).sqrt());
        let comps: [fn(&Pose2, &Pose2) -> f64; 3] = [
            |t, _| t.x,
            |t, _| t.y,
            // angles relative to the edge's own, so that ±π does not split
            |t, own| wrap_angle(t.theta - own.theta),
        ];
        for (c, get) in comps.iter().enumerate() {
            let mut v: Vec<f64> = alts.iter().map(|(_, t)| get(t, &own)).collect();
            let mine = get(&own, &own);
            v.push(mine);
            let (lo, hi) = fences(&mut v, p.k, p.min_sigmas * sigma[(c, c)]);
            if mine < lo || mine > hi {
                return Verdict::Reject;
            }
        }
        Verdict::Accept
    }
}

fn key(a: usize, b: usize) -> (usize, usize) {
    (a.min(b), a.max(b))
}

/// The switchable edges paper A's cycle test rejects when `config` asks
/// for it (over keyframes `0..n`), else none: a held-out mask for
/// [`super::robust_polish`].
pub fn rejected(n: usize, edges: &[Edge], switchable: &[bool], config: &super::OutlierConfig) -> Vec<bool> {
    if !config.cycle_test() {
        return Vec::new();
    }
    let usable = vec![true; edges.len()];
    let check = CycleCheck::new(n, edges, &usable);
    (0..edges.len())
        .map(|a| switchable[a] && check.verdict(a, &config.cycle) == Verdict::Reject)
        .collect()
}

/// Both held-out masks at once: an edge is held out if either holds it
/// out (a shorter mask holds out none past its end).
pub fn either(a: Vec<bool>, b: Vec<bool>) -> Vec<bool> {
    let (mut long, short) = if a.len() >= b.len() { (a, b) } else { (b, a) };
    for (l, s) in long.iter_mut().zip(short) {
        *l |= s;
    }
    long
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::graph::{EdgeKind, Information};

    #[test]
    fn prior_table_follows_the_variance_thresholds() {
        let p = CycleParams::default();
        assert_eq!(prior_probability(0.001, &p), 0.1);
        assert_eq!(prior_probability(0.05, &p), 0.2);
        assert_eq!(prior_probability(0.5, &p), 0.3);
        let info = Information::from_variances(0.04, 0.06, 0.01).unwrap();
        let e = Edge {
            from: 0,
            to: 1,
            measurement: Pose2::IDENTITY,
            information: info,
            kind: EdgeKind::Odometry,
        };
        assert!((variance(&e) - 0.05).abs() < 1e-12);
    }

    #[test]
    fn iqr_fences_are_tukeys() {
        // quartiles of 1..=9 are 3 and 7: IQR 4, fences −3 and 13
        let mut v: Vec<f64> = (1..=9).rev().map(f64::from).collect();
        assert_eq!(fences(&mut v, 1.5, 0.0), (-3.0, 13.0));
        // identical samples: the minimum half-width keeps a band
        let mut same = vec![2.0; 5];
        assert_eq!(fences(&mut same, 1.5, 0.1), (1.9, 2.1));
    }

    /// Two parallel lanes 0..n and n..2n, a metre apart, with rungs `k → n+k`
    /// (rung `bad` wrong) and diagonals `k → n+k+1`.
    fn ladder(n: usize, bad: Option<usize>) -> Vec<Edge> {
        let info = Information::identity();
        let edge = |from, to, m| Edge {
            from,
            to,
            measurement: m,
            information: info,
            kind: EdgeKind::from_ids(from as u64, to as u64),
        };
        let mut edges = Vec::new();
        for lane in [0, n] {
            for k in 1..n {
                edges.push(edge(lane + k - 1, lane + k, Pose2::new(1.0, 0.0, 0.0)));
            }
        }
        for k in 0..n {
            let m = if Some(k) == bad {
                Pose2::new(4.0, -3.0, 1.0)
            } else {
                Pose2::new(0.0, 1.0, 0.0)
            };
            edges.push(edge(k, n + k, m));
        }
        for k in 0..n - 1 {
            edges.push(edge(k, n + k + 1, Pose2::new(1.0, 1.0, 0.0)));
        }
        edges
    }

    #[test]
    fn a_rung_that_disagrees_with_its_neighbours_is_rejected() {
        let n = 8;
        let edges = ladder(n, Some(4));
        let usable = vec![true; edges.len()];
        let check = CycleCheck::new(2 * n, &edges, &usable);
        let p = CycleParams::default();
        let rung = |k: usize| 2 * (n - 1) + k;
        assert_eq!(check.verdict(rung(4), &p), Verdict::Reject);
        for k in [1, 2, 3, 5, 6] {
            assert_eq!(check.verdict(rung(k), &p), Verdict::Accept, "rung {k}");
        }
        // rung 2's detours avoid the bad rung and all agree
        let alts = check.alternatives(2, n + 2, rung(2), 12);
        assert!(alts.len() >= 4, "{}", alts.len());
        for (_, t) in alts {
            assert!((t.x).abs() < 1e-12 && (t.y - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn too_few_alternatives_defer() {
        // a square 0-1-3-2 has one detour per side
        let edges = &ladder(2, None)[..4];
        let usable = vec![true; 4];
        let check = CycleCheck::new(4, edges, &usable);
        assert_eq!(check.alternatives(0, 2, 2, 12).len(), 1);
        assert_eq!(check.verdict(2, &CycleParams::default()), Verdict::Defer);
    }
}
