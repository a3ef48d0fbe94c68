//! [`ArrivalGate`]: the switch a new loop closure between mapped keyframes
//! enters with.
//!
//! A new loop closure enters with DCS's switch at the estimate
//! ([`OutlierConfig::arrival_switch`]). One that would be switched off
//! joins the run of agreeing rejections ([`DriftRun`]), vouched for when
//! `arrival_covariance` is on and its error is within `arrival_phi` of its
//! innovation covariance (the caller measures that: it needs the factor).
//! Two vouched members enter together, switch 1 and the earlier ones
//! restored: the first loop closures of a drifted loop, whose ends the map
//! holds loosely. One alone waits for a second, since a random wrong loop
//! closure between loosely held keyframes can pass the covariance test as
//! well. A run reaching `drift_run` means the map drifted
//! ([`ArrivalGate::take_drifted`]).

use super::pose::EnginePose;
use crate::geometry::Pose2;
use crate::graph::Edge;
use crate::outliers::{DriftRun, OutlierConfig, OFF_BELOW};

/// What the gate decided for a loop closure it would switch off.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// It stays at the switch it arrived with.
    Stays,
    /// It and these earlier members of its run enter with switch 1 (the
    /// list includes it).
    EnterWith(Vec<usize>),
}

/// The filter's settings at arrival, the current run of agreeing
/// rejections, and whether a run said the map drifted.
#[derive(Clone, Debug)]
pub struct ArrivalGate<P: EnginePose = Pose2> {
    outliers: OutlierConfig,
    drift: DriftRun<P>,
    drifted: bool,
}

impl<P: EnginePose> ArrivalGate<P> {
    /// A gate with the filter's settings and no run.
    pub fn new(outliers: OutlierConfig) -> Self {
        Self {
            outliers,
            drift: DriftRun::default(),
            drifted: false,
        }
    }

    /// Whether `edge` gets a switch at all (not odometry; filter on).
    pub fn switchable(&self, edge: &Edge<P>) -> bool {
        self.outliers.switchable(edge)
    }

    /// DCS's switch of `edge` at the estimate's `xi`, `xj`.
    pub fn switch(&self, edge: &Edge<P>, xi: &P, xj: &P) -> f64 {
        self.outliers.arrival_switch(edge, xi, xj)
    }

    /// Whether a loop closure arriving with switch `s` goes to the run
    /// (it would be off, and a run is kept).
    pub fn judges(&self, s: f64) -> bool {
        s < OFF_BELOW && (self.outliers.arrival_covariance || self.outliers.drift_run > 0)
    }

    /// Whether a rejected loop closure may be vouched for by its
    /// innovation covariance.
    pub fn vouches(&self) -> bool {
        self.outliers.arrival_covariance
    }

    /// The gate's Φ.
    pub fn phi(&self) -> f64 {
        self.outliers.arrival_phi
    }

    /// Records that loop closure `e`, `edge`, would be switched off at
    /// the estimate's `xi`, `xj`, `vouched` for or not, and decides.
    pub fn rejected(&mut self, e: usize, vouched: bool, edge: &Edge<P>, xi: &P, xj: &P) -> Verdict {
        let run = self.outliers.drift_run;
        let len = self
            .drift
            .rejected(e, vouched, edge, xi, xj, self.outliers.arrival_phi);
        if vouched && self.drift.vouched() >= 2 {
            return Verdict::EnterWith(self.drift.take_vouched());
        }
        if run > 0 && len >= run {
            self.drifted = true;
            self.drift.clear();
        }
        Verdict::Stays
    }

    /// Whether a run of agreeing rejected loop closures said the map
    /// drifted since the last call.
    pub fn take_drifted(&mut self) -> bool {
        std::mem::take(&mut self.drifted)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn closure(from: usize, to: usize, z: Pose2) -> Edge {
        Edge::unit_loop_closure(from, to, z)
    }

    /// The true map: keyframe `k` at `(k, 0)`. The estimate of keyframe
    /// `j` carries the rigid drift `(2, −1, 0.3 rad)`; the loop closure from
    /// `j − 100` measures the truth. Returns it and the two estimates.
    fn drifted(j: usize) -> (Edge, Pose2, Pose2) {
        let truth = |k: usize| Pose2::new(k as f64, 0.0, 0.0);
        let z = truth(j - 100).between(&truth(j));
        let drift = Pose2::new(2.0, -1.0, 0.3);
        (closure(j - 100, j, z), truth(j - 100), drift.compose(&truth(j)))
    }

    #[test]
    fn a_loop_closure_enters_with_dcs_at_the_estimate() {
        let gate = ArrivalGate::new(OutlierConfig::default());
        let e = closure(0, 5, Pose2::new(5.0, 0.0, 0.0));
        // x_j = (5, d, 0) gives the error (0, d, 0): χ² = d², and
        // s = min(1, 2Φ / (Φ + χ²)) with Φ = 16.27
        let at = |d: f64| gate.switch(&e, &Pose2::IDENTITY, &Pose2::new(5.0, d, 0.0));
        assert_eq!(at(3.0), 1.0);
        assert!((at(10.0) - 32.54 / 116.27).abs() < 1e-12, "{}", at(10.0));
        assert!((at(60.0) - 32.54 / 3616.27).abs() < 1e-12, "{}", at(60.0));
        // below 0.05 the run judges it; 0.28 stays as it is
        assert!(gate.judges(at(60.0)) && !gate.judges(at(10.0)));
    }

    #[test]
    fn two_vouched_members_of_a_run_enter_together_and_one_waits() {
        let mut gate = ArrivalGate::new(OutlierConfig::default());
        let (e, xi, xj) = drifted(100);
        assert_eq!(gate.rejected(7, true, &e, &xi, &xj), Verdict::Stays);
        // an unvouched member between them neither enters nor breaks the run
        let (e, xi, xj) = drifted(101);
        assert_eq!(gate.rejected(8, false, &e, &xi, &xj), Verdict::Stays);
        let (e, xi, xj) = drifted(102);
        assert_eq!(
            gate.rejected(9, true, &e, &xi, &xj),
            Verdict::EnterWith(vec![7, 9])
        );
        // the run ended: a vouched loop closure that disagrees with the drift
        // (its keyframe 5 m off the drifted chain) waits alone
        let (e, xi, xj) = drifted(103);
        let off = Pose2::new(5.0, 0.0, 0.0).compose(&xj);
        assert_eq!(gate.rejected(10, true, &e, &xi, &off), Verdict::Stays);
        let (e, xi, xj) = drifted(104);
        assert_eq!(gate.rejected(11, true, &e, &xi, &xj), Verdict::Stays);
        assert!(!gate.take_drifted());
    }

    #[test]
    fn a_run_of_drift_run_rejections_says_the_map_drifted_once() {
        let config = OutlierConfig {
            drift_run: 5,
            ..OutlierConfig::default()
        };
        let mut gate = ArrivalGate::new(config);
        for n in 0..4 {
            let (e, xi, xj) = drifted(100 + n);
            gate.rejected(n, false, &e, &xi, &xj);
        }
        assert!(!gate.take_drifted());
        let (e, xi, xj) = drifted(104);
        gate.rejected(4, false, &e, &xi, &xj);
        assert!(gate.take_drifted());
        assert!(!gate.take_drifted());
        // the run starts over: four more do not say it again
        for n in 5..9 {
            let (e, xi, xj) = drifted(100 + n);
            gate.rejected(n, false, &e, &xi, &xj);
        }
        assert!(!gate.take_drifted());
    }
}
