//! [`EngineConfig`]: the engine's tuning, with the defaults the replay
//! benchmarks chose.

use super::SnapshotSource;
use crate::gps::GpsConfig;
use crate::nonlinear::LevenbergMarquardtParams;
use crate::outliers::OutlierConfig;

/// Tuning of the [`Engine`](super::Engine). The defaults are what the replay benchmarks
/// measured best on City10000 and Manhattan.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct EngineConfig {
    /// Re-solve after this many new edges (0: never on count; fill, GPS,
    /// the drift and nonlinearity checks, idle time (the daemon calls
    /// `Engine::idle`) and the end of a stream still start re-solves). A
    /// re-solve's polish holds the only background thread, so no refresh
    /// lands while it runs (0.25-0.65 s late in City10000, hundreds of
    /// keyframes appended meanwhile). Every 3000 edges against every
    /// 10000, replays alternated (README, "Re-solve cadence"): W10000
    /// 23.9-44.3 s against 16.8-20.2 s, City10000 4.21-4.61 against
    /// 4.40-4.43 s, the same final χ², worst sampled snapshots and outlier
    /// precision and recall within their run-to-run spread.
    pub resolve_every_edges: usize,
    /// Between re-solves, refresh after this many new edges when the
    /// background thread is free: relinearise every edge at the estimate
    /// and refactorise with a fresh ordering, without the polish (one
    /// Gauss–Newton iteration; 0: never).
    pub refresh_every_edges: usize,
    /// Re-solve when the factor holds this many times the entries it had
    /// after the last re-solve (0: never on fill).
    pub resolve_fill_ratio: f64,
    /// Run re-solves on a background thread; else inline, blocking.
    pub background: bool,
    /// A column whose solution moves by at most this much does not pass the
    /// change to its subtree (iSAM2's wildfire; m and rad). 0 is exact.
    pub wildfire_threshold: f64,
    /// Re-solve at once, inline, when the estimate's true χ² exceeds this
    /// multiple of the χ² its linear model predicts (plus 1): the
    /// linearisation point is too far from the estimate, as after a large
    /// loop closure (0: never). A running re-solve is abandoned.
    pub nonlinear_ratio: f64,
    /// Relinearise at once, inline, when the estimate's true χ² exceeds
    /// this multiple of its linear model's (plus 0.01) but not
    /// `nonlinear_ratio`'s: every edge relinearised at the estimate and
    /// refactorised, one Gauss–Newton step, no polish; still past it after
    /// that, the inline re-solve follows (0: never). A step from a stale
    /// linearisation can land 40% above the optimum while its model
    /// predicts within 1.5× (Manhattan keyframe 574, replayed inline). At
    /// 1.2, 40 sampled snapshots per replay: Manhattan worst 1.16-1.22×
    /// its prefix's optimum over four runs (1.24-1.36× over four without),
    /// City10000 1.15× (1.36×), for about 10% of Manhattan's replay time.
    pub relinearise_ratio: f64,
    /// Keyframes kept last in a fresh ordering: the newest keyframe's
    /// odometry then walks a short path, but every loop closure's path
    /// crosses them. Update entries walked per City10000 keyframe, 100
    /// streamed after a fresh factor at 3,000 / 6,000 / 9,000
    /// (`incremental_path` bench, deterministic): 32 → 21 / 71 / 160 K,
    /// 16 → 18 / 58 / 213 K, 8 → 16 / 60 / 109 K, 4 → 15 / 57 / 139 K,
    /// 0 → 14 / 48 / 137 K. Replays (8 runs each, alternated): City10000
    /// mean 15.2 s at 32, 13.3 at 8, 13.2 at 0; Manhattan the same within
    /// noise, but its p99 reached 4.4-5.6 ms in three of eight runs at 0
    /// (2.3-3.9 ms at 32, 2.9-3.4 at 8).
    pub recent_last: usize,
    /// A loop closure that agrees with the estimate waits out of the
    /// Gauss–Newton factor for the next re-solve while the waiting ones'
    /// χ² stays within this fraction of the estimate's (their cost still
    /// counts; past it, the worst enter). A keyframe's first loop closure
    /// always enters. 0 (the default): every edge enters at once; 0.05 made
    /// City10000 about 15% faster, and Manhattan's worst sampled snapshot
    /// 1.31-1.54× its prefix's optimum against 1.30-1.39× (README).
    pub defer_budget: f64,
    /// What the published estimate is between re-solves.
    pub snapshot: SnapshotSource,
    /// Keep the exact two-stage linear solution even when it is not the
    /// snapshot source.
    pub linear_stages: bool,
    /// The polish of each re-solve.
    pub polish: LevenbergMarquardtParams,
    /// The outlier filter of loop closures.
    pub outliers: OutlierConfig,
    /// GPS: the ENU origin and how fixes weigh (the configuration's `[gps]`
    /// section; see [`Config::engine`](crate::config::Config::engine)).
    #[serde(skip)]
    pub gps: GpsConfig,
}

impl Default for EngineConfig {
    fn default() -> Self {
        Self {
            resolve_every_edges: 10000,
            refresh_every_edges: 50,
            resolve_fill_ratio: 2.0,
            background: true,
            wildfire_threshold: 1e-4,
            nonlinear_ratio: 1.5,
            relinearise_ratio: 1.2,
            recent_last: 8,
            defer_budget: 0.0,
            snapshot: SnapshotSource::default(),
            linear_stages: false,
            polish: LevenbergMarquardtParams::default(),
            outliers: OutlierConfig::default(),
            gps: GpsConfig::default(),
        }
    }
}
