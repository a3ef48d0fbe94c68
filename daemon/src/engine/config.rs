//! [`EngineConfig`]: the engine's tuning and its defaults.

use crate::gps::GpsConfig;
use crate::nonlinear::LevenbergMarquardtParams;
use crate::outliers::OutlierConfig;

/// Tuning of the [`Engine`](super::Engine). Each field gives its meaning
/// and default; the measurements behind the defaults are in
/// docs/benchmarks.md, "Engine defaults and why".
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EngineConfig {
    /// Re-solve after this many new edges (0: never on count; fill, GPS,
    /// the drift and nonlinearity checks, idle time (the daemon calls
    /// `Engine::idle`) and the end of a stream still start re-solves). A
    /// re-solve's polish holds the only background thread, so no refresh
    /// lands while it runs. Default 10000.
    pub resolve_every_edges: usize,
    /// Between re-solves, refresh after this many new edges when the
    /// background thread is free: relinearise every edge at the estimate
    /// and refactorise with a fresh ordering, without the polish (one
    /// Gauss–Newton iteration; 0: never). Default 50.
    pub refresh_every_edges: usize,
    /// Re-solve in the background when the factor holds this many times
    /// the entries per column it had when last fresh (fill-in: a map grown
    /// by odometry alone grows its factor in proportion); while a re-solve
    /// runs, or with everything inline (`background` off), refactorise
    /// inline with a fresh ordering instead (0: neither). Default 2.
    pub resolve_fill_ratio: f64,
    /// Run re-solves on a background thread; else inline, blocking.
    /// Default true.
    pub background: bool,
    /// A column whose solution moves by at most this much does not pass the
    /// change to its subtree (iSAM2's wildfire; m and rad). 0 is exact.
    /// Default 1e-4.
    pub wildfire_threshold: f64,
    /// Re-solve at once, inline, when the estimate's true χ² exceeds this
    /// multiple of the χ² its linear model predicts (plus 1): the
    /// linearisation point is too far from the estimate, as after a large
    /// loop closure (0: never). A running re-solve is abandoned. Default
    /// 1.5.
    pub nonlinear_ratio: f64,
    /// Relinearise at once, inline, when the estimate's true χ² exceeds
    /// this multiple of its linear model's (plus 0.01) but not
    /// `nonlinear_ratio`'s: every edge relinearised at the estimate and
    /// refactorised, one Gauss–Newton step, no polish; still past it after
    /// that, the inline re-solve follows (0: never). It bounds how far a
    /// snapshot strays from its prefix's optimum (sampled snapshots within
    /// 1.22× on Manhattan at 1.2, up to 1.36× without). Default 1.2.
    pub relinearise_ratio: f64,
    /// Keyframes kept last in a fresh ordering: the newest keyframe's
    /// odometry then walks a short path, but every loop closure's path
    /// crosses them. Default 8.
    pub recent_last: usize,
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
            polish: LevenbergMarquardtParams::default(),
            outliers: OutlierConfig::default(),
            gps: GpsConfig::default(),
        }
    }
}
