//! [`Deferred`]: loop closures that agree with the estimate wait out of the
//! Gauss–Newton factor until the next re-solve.
//!
//! A loop closure's update walks the elimination tree from its older
//! keyframe to the root: on City10000 about 115,000 stored entries, times
//! three vectors, per loop closure. One that agrees with the current
//! estimate barely moves the mean, so it waits: its χ² still counts in the
//! estimate's, and the next re-solve, on the other core, factorises it with
//! everything else. The budget bounds what waiting can cost a snapshot:
//!
//! ```text
//! Σ_{e waiting} χ²_e ≤ β · χ²(estimate)
//! ```
//!
//! When the estimate moves and the waiting edges' χ² outgrows the budget,
//! the worst of them enter the factor. The budget bounds the waiting
//! edges' own χ², not the snapshot's distance from its prefix's optimum:
//! an edge that enters late corrects keyframes linearised without it, and
//! that Gauss–Newton step costs more (Manhattan reached 1.54× at β = 0.02
//! until a keyframe's first loop closure was made to enter at once).

/// The waiting loop closures and their χ² at the estimate.
#[derive(Clone, Debug, Default)]
pub struct Deferred {
    /// The budget β (0: nothing waits).
    budget: f64,
    /// Whether each edge waits.
    waiting: Vec<bool>,
    /// The waiting edges (may hold edges that since entered; see `waiting`).
    list: Vec<usize>,
    /// `Σ χ²_e` over the waiting edges.
    chi2: f64,
}

impl Deferred {
    /// Nothing waiting, budget `β`.
    pub fn new(budget: f64) -> Self {
        Self {
            budget,
            ..Self::default()
        }
    }

    /// Whether anything may wait (a budget above 0).
    pub fn enabled(&self) -> bool {
        self.budget > 0.0
    }

    /// Whether edge `e` waits.
    pub fn waits(&self, e: usize) -> bool {
        self.waiting.get(e).copied().unwrap_or(false)
    }

    /// Whether an edge of χ² `v` may wait beside the others when the
    /// estimate's χ² is `chi2` (without it).
    pub fn admits(&self, v: f64, chi2: f64) -> bool {
        self.enabled() && self.chi2 + v <= self.budget * (chi2 + v)
    }

    /// Edge `e`, of χ² `v`, waits.
    pub fn push(&mut self, e: usize, v: f64) {
        if self.waiting.len() <= e {
            self.waiting.resize(e + 1, false);
        }
        self.waiting[e] = true;
        self.list.push(e);
        self.chi2 += v;
    }

    /// A waiting edge's χ² changed from `old` to `new`.
    pub fn refresh(&mut self, e: usize, old: f64, new: f64) {
        if self.waits(e) {
            self.chi2 += new - old;
        }
    }

    /// Sets the waiting edges' χ² sum afresh (after a full recount).
    pub fn recount(&mut self, edge_chi2: &[f64]) {
        self.list.retain(|&e| self.waiting[e]);
        self.chi2 = self.list.iter().map(|&e| edge_chi2[e]).sum();
    }

    /// The waiting edge of largest χ² while the waiting edges exceed the
    /// budget at an estimate of χ² `chi2`; it no longer waits.
    pub fn pop_over_budget(&mut self, chi2: f64, edge_chi2: &[f64]) -> Option<usize> {
        if self.chi2 <= self.budget * chi2 {
            return None;
        }
        self.list.retain(|&e| self.waiting[e]);
        let (at, &e) = self
            .list
            .iter()
            .enumerate()
            .max_by(|a, b| edge_chi2[*a.1].total_cmp(&edge_chi2[*b.1]))?;
        self.list.swap_remove(at);
        self.waiting[e] = false;
        self.chi2 -= edge_chi2[e];
        Some(e)
    }

    /// `Σ χ²_e` over the waiting edges.
    pub fn chi2(&self) -> f64 {
        self.chi2
    }

    /// Edges waiting now.
    pub fn len(&self) -> usize {
        self.list.iter().filter(|&&e| self.waiting[e]).count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_budget_caps_the_waiting_chi2() {
        let mut d = Deferred::new(0.1);
        // χ² 100 without the edge: 5 fits (5 ≤ 0.1 · 105), 12 does not
        assert!(d.admits(5.0, 100.0));
        assert!(!d.admits(12.0, 100.0));
        d.push(3, 5.0);
        // 5 + 6 = 11 > 0.1 · 106
        assert!(!d.admits(6.0, 100.0));
        assert!(d.admits(4.0, 100.0));
        assert!(!Deferred::new(0.0).admits(0.0, 100.0));
    }

    #[test]
    fn the_worst_edges_leave_first_until_within_budget() {
        let mut d = Deferred::new(0.1);
        let mut chi2 = vec![0.0; 8];
        for (e, v) in [(1, 2.0), (4, 3.0), (6, 1.0)] {
            chi2[e] = v;
            d.push(e, v);
        }
        assert_eq!(d.len(), 3);
        // the estimate moved: edge 4 now costs 9, total 12 against 0.1 · 50
        d.refresh(4, 3.0, 9.0);
        chi2[4] = 9.0;
        assert_eq!(d.pop_over_budget(50.0, &chi2), Some(4));
        assert!(!d.waits(4));
        // 3 ≤ 5: within budget again
        assert_eq!(d.pop_over_budget(50.0, &chi2), None);
        assert_eq!(d.len(), 2);
        assert!((d.chi2() - 3.0).abs() < 1e-12);
    }
}
