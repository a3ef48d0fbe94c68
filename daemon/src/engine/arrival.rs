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
pub struct ArrivalGate {
    outliers: OutlierConfig,
    drift: DriftRun,
    drifted: bool,
}

impl ArrivalGate {
    /// A gate with the filter's settings and no run.
    pub fn new(outliers: OutlierConfig) -> Self {
        Self {
            outliers,
            drift: DriftRun::default(),
            drifted: false,
        }
    }

    /// Whether `edge` gets a switch at all (not odometry; filter on).
    pub fn switchable(&self, edge: &Edge) -> bool {
        self.outliers.switchable(edge)
    }

    /// DCS's switch of `edge` at the estimate's `xi`, `xj`.
    pub fn switch(&self, edge: &Edge, xi: &Pose2, xj: &Pose2) -> f64 {
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
    pub fn rejected(&mut self, e: usize, vouched: bool, edge: &Edge, xi: &Pose2, xj: &Pose2) -> Verdict {
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
