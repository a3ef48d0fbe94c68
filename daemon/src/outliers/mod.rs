//! Outlier filtering of loop closures.
//!
//! - [`crate::robust`]'s kernels give the closed-form switches (paper B's
//!   ASC as printed, SC with a fixed Ξ, DCS) and their robust costs; the
//!   polish minimises those costs by reweighting each loop closure with
//!   `s²` at every iteration.
//! - [`cycles`]: paper A's cycle-consistency test with IQR fences.
//! - [`consistency`]: PCM, the largest set of loop closures that agree
//!   pairwise through the odometry.
//!
//! The engine applies both in its background re-solve: edges the cycle test
//! rejects are switched off (and tested again at every re-solve, so later
//! evidence can restore them), the polish reweights the rest, and the final
//! switches go into the fresh factor. Between re-solves a new loop closure
//! enters with the switch its error has under the current estimate.
//! Odometry is never switched.

mod awake;
pub mod consistency;
pub mod cycles;
pub mod drift;
mod robust;
mod starts;

pub use awake::DORMANT_BELOW;
pub use cycles::{CycleCheck, CycleParams, Verdict};
pub use drift::DriftRun;
pub use robust::{robust_polish, Comparison, RobustEdges, RobustSolution};
pub use starts::{ABANDON_RATIO, LATE_RATIO, LOOK_ITERATIONS, PROBE_ITERATIONS, PRUNE_RATIO};

use crate::graph::Edge;
use crate::robust::kernel::dcs;
use crate::robust::Kernel;

/// The `[engine.outliers]` settings. The defaults won the benchmark in
/// `benches/outliers.py` (docs/robustness.md).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OutlierConfig {
    /// Filter at all.
    pub enabled: bool,
    /// The switch of each loop closure.
    pub kernel: Kernel,
    /// A new loop closure enters with DCS's switch at this Φ (default: the
    /// 99.9% quantile of χ² with 3 degrees of freedom). The estimate it is
    /// measured against has not seen it yet and may carry drift, so the
    /// arrival gate is wider than the kernel the re-solve applies.
    pub arrival_phi: f64,
    /// A loop closure the gate would switch off is measured again against
    /// its innovation covariance `Ω⁻¹ + σ² J Σ Jᵀ` (`Σ`: the estimate's
    /// covariance, read off the factor; `σ²`: the estimate's variance
    /// factor χ²/r in [10⁻³, 1]). Once two that agree (see [`drift`]) are
    /// within `arrival_phi` of theirs, they enter with switch 1; until
    /// then the gate's switch stands. The first loop closures of a long
    /// drifted loop are surprising only against `Ω`, not against how
    /// loosely the map holds their ends; a lone random wrong one can be
    /// just as unsurprising where the odometry claims to be loose
    /// (ringCity).
    pub arrival_covariance: bool,
    /// This many agreeing loop closures switched off on arrival in a row
    /// mean the map drifted, not that they are wrong: the engine re-solves
    /// at once (see [`drift`]; 0: never). Twice Vertigo's group of ten.
    pub drift_run: usize,
    /// Every multi-start re-solve, not only the one that ends a stream,
    /// also starts from the two-stage solution without the loop closures
    /// let in on arrival since the last such re-solve. A group of agreeing
    /// wrong ones can enter against a map bent by the ones before it, and
    /// every other start then ends in their basin. Off by default (8–11%
    /// faster on City10000 and Manhattan); on, Intel + 1000 local-grouped
    /// outliers reach precision 1.000 from 0.86.
    pub unadmitted_start: bool,
    /// Before the kernel, keep only the largest set of loop closures that
    /// agree pairwise through the odometry (PCM, see [`consistency`]); the
    /// others are switched off at every re-solve and tested again at the
    /// next. Off by default: it wins where wrong loop closures outnumber
    /// the true ones on a pessimistically weighted graph (Intel + 4000
    /// random: precision 0.99, recall 1.00, from 0.75 and 0.35), but where
    /// the odometry claims more than it holds it turns true loop closures
    /// away (34% of `input_intel_g2o`'s), and it costs O(m²) tests for m
    /// loop closures (docs/robustness.md, "Pairwise consistency").
    pub pairwise: bool,
    /// The bound of the pairwise test on the cycle's `eᵀ Σ⁻¹ e`.
    pub pairwise_chi2: f64,
    /// Run paper A's cycle test before the kernel.
    pub cycles: bool,
    /// Its parameters.
    pub cycle: CycleParams,
}

impl Default for OutlierConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            kernel: Kernel::default(),
            arrival_phi: 16.27,
            arrival_covariance: true,
            drift_run: 20,
            unadmitted_start: false,
            pairwise: false,
            pairwise_chi2: consistency::CONSISTENT_CHI2,
            cycles: false,
            cycle: CycleParams::default(),
        }
    }
}

impl OutlierConfig {
    /// Checks the numbers: the kernel's parameter and `arrival_phi` > 0,
    /// the cycle test's variances, fence factor and counts in range.
    pub fn check(&self) -> Result<(), String> {
        self.kernel.check()?;
        let c = &self.cycle;
        let positive = [
            ("arrival_phi", self.arrival_phi),
            ("pairwise_chi2", self.pairwise_chi2),
            ("cycle.var_low", c.var_low),
            ("cycle.var_high", c.var_high),
            ("cycle.k", c.k),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} {v} must be a number > 0"));
            }
        }
        if c.var_high < c.var_low {
            return Err(format!(
                "cycle.var_high {} must be ≥ cycle.var_low {}",
                c.var_high, c.var_low
            ));
        }
        if c.min_alternatives == 0 || c.max_alternatives < c.min_alternatives {
            return Err(format!(
                "cycle.min_alternatives {} must be ≥ 1 and ≤ cycle.max_alternatives {}",
                c.min_alternatives, c.max_alternatives
            ));
        }
        if !(c.min_sigmas.is_finite() && c.min_sigmas >= 0.0) {
            return Err(format!("cycle.min_sigmas {} must be a number ≥ 0", c.min_sigmas));
        }
        Ok(())
    }

    /// The switch a new loop closure enters with, at poses `xi`, `xj`.
    pub fn arrival_switch<P: crate::graph::EdgeCost>(&self, edge: &Edge<P>, xi: &P, xj: &P) -> f64 {
        let e = P::edge_error(edge, xi, xj);
        dcs(P::mahalanobis(&edge.information, &e), self.arrival_phi)
    }

    /// This configuration for edges of `dof` degrees of freedom: the
    /// kernel's Φ and `arrival_phi`, where they are the defaults (set for
    /// three), move to the same quantiles at six (χ²₆(0.999) = 22.458).
    pub fn for_dof(mut self, dof: usize) -> Self {
        if dof == 6 {
            if self.kernel == Kernel::default() {
                self.kernel = Kernel::default_for(6);
            }
            if self.arrival_phi == Self::default().arrival_phi {
                self.arrival_phi = 22.458;
            }
        }
        self
    }

    /// Whether `edge` gets a switch: every edge but odometry and trusted
    /// loop closures, when enabled.
    pub fn switchable<P: crate::graph::RigidMotion>(&self, edge: &Edge<P>) -> bool {
        self.enabled && edge.kind.switchable()
    }

    /// PCM picks the loop closures first: enabled with `pairwise`.
    pub fn pcm(&self) -> bool {
        self.enabled && self.pairwise
    }

    /// Paper A's cycle test runs: enabled with `cycles`.
    pub fn cycle_test(&self) -> bool {
        self.enabled && self.cycles
    }

    /// A planar-only check is on (the cycle test or PCM), which a 3-D
    /// graph refuses.
    pub fn planar_only(&self) -> bool {
        self.pcm() || self.cycle_test()
    }
}

/// A switch below this counts as a rejection (`rejected_edges`): the
/// wire's rule, one constant for the filter and its readers.
pub use slamd_protocol::REJECTED_BELOW;

/// A switch below this is off: the edge weighs `s² < 0.0025` of itself,
/// too little to matter, and keeping it out of the factor saves the fill
/// a wrong long-range edge would cause. The next re-solve still scores it
/// and can switch it back on.
pub const OFF_BELOW: f64 = 0.05;
