//! GPS: fixes in a local metric frame, paper A's similar triangles, and
//! georeferencing.
//!
//! - [`local_frame`]: WGS84 latitude/longitude/height to the local
//!   east-north-up tangent plane at an origin (x east, y north, REP-103).
//! - [`triangles`]: paper A §4.2's equations between fixes: adjacent triples
//!   and seeded wide triangles, each `p_c − p_b = ω (p_a − p_b)` with ω the
//!   complex ratio of the GPS vectors. They fix shape only.
//! - [`georef`]: the map→ENU rigid motion fitted to the GPS-tagged poses,
//!   which turns each fix into an absolute position equation in the map
//!   frame: what corrects drift at its true scale and georeferences the map.

pub mod georef;
pub mod local_frame;
pub mod triangles;

pub use georef::Georef;
pub use local_frame::{Geodetic, LocalFrame};
pub use slamd_types::{check_covariance, GpsError};
pub use triangles::{Triangle, TriangleParams};

use crate::geometry::Pose2;
use crate::graph::{Edge, Pose3};
use crate::nonlinear::{polish, LevenbergMarquardtParams, LiePose, LmReport, PositionPrior, Problem};
use crate::sparse::FactorError;
use faer::c64;
use nalgebra::{Matrix2, Matrix3, Vector3};
use slamd_types::FixInput;

/// The `[gps]` settings.
///
/// ```toml
/// [gps]
/// origin = "45.5138,9.2110"   # LAT,LON[,HEIGHT] of the ENU frame; default: the first fix
/// absolute = true             # georeference: absolute position equations
/// calibrate = true            # weigh fixes by the graph's variance factor
/// [gps.triangles]             # paper A's rules
/// eps = 0.5
/// p_thres = 3.0
/// delta_req = 200
/// f_max = 20000
/// seed = 1
/// ```
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GpsConfig {
    /// Origin of the local ENU frame (default: the first fix).
    pub origin: Option<Geodetic>,
    /// Add absolute position equations (see [`GpsInput::absolute`]).
    pub absolute: bool,
    /// Weigh fixes by the graph's variance factor ([`variance_factor`]).
    pub calibrate: bool,
    /// Paper A's triangle rules.
    pub triangles: TriangleParams,
}

impl Default for GpsConfig {
    fn default() -> Self {
        Self {
            origin: None,
            absolute: true,
            calibrate: true,
            triangles: TriangleParams::default(),
        }
    }
}

/// The fixes of a solve and what to make of them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct GpsInput {
    /// The fixes, any order.
    pub fixes: Vec<GpsFix>,
    /// Paper A's triangle rules.
    pub triangles: TriangleParams,
    /// Also add absolute position equations (georeferencing), beyond the
    /// paper's shape-only triangles.
    pub absolute: bool,
    /// Multiplies every GPS weight: the graph's a-posteriori variance
    /// factor ([`variance_factor`]), so that edges and fixes weigh in the
    /// same units. 1 trusts the edges' information as given.
    pub weight: f64,
    /// Set `weight` from the graph's own χ² before solving.
    pub calibrate: bool,
}

impl GpsInput {
    /// Fixes with the default rules and absolute equations.
    pub fn new(fixes: Vec<GpsFix>) -> Self {
        Self::with_config(fixes, &GpsConfig::default())
    }

    /// Fixes with the rules of `config`.
    pub fn with_config(fixes: Vec<GpsFix>, config: &GpsConfig) -> Self {
        Self {
            fixes,
            triangles: config.triangles,
            absolute: config.absolute,
            weight: 1.0,
            calibrate: config.calibrate,
        }
    }

    /// The fixes in keyframe (time) order.
    pub fn ordered(&self) -> Vec<GpsFix> {
        let mut f = self.fixes.clone();
        f.sort_by_key(|f| f.keyframe);
        f
    }

    /// Paper A's equations: adjacent triples, then wide triangles; the
    /// indices refer to [`Self::ordered`].
    pub fn triangles(&self) -> (Vec<GpsFix>, Vec<Triangle>) {
        let fixes = self.ordered();
        let mut t = triangles::adjacent(&fixes, &self.triangles);
        t.extend(triangles::wide(&fixes, &self.triangles));
        (fixes, t)
    }

    /// The map→ENU motion fitted to `poses`, weighting each fix by its
    /// inverse variance: the rotation about up and the (east, north) shift
    /// from the positions' `x, y` ([`Georef::fit`]); in space, the up shift
    /// from the fixes with a held height (their inverse-variance weighted
    /// mean of `up − z`).
    pub fn fit<P: GpsPose>(&self, poses: &[P]) -> Option<Georef> {
        let pairs: Vec<_> = (self.fixes.iter())
            .map(|f| {
                let [x, y, _] = poses[f.keyframe].position3();
                (c64::new(x, y), f.enu, 1.0 / f.variance())
            })
            .collect();
        let mut georef = Georef::fit(&pairs)?;
        if P::DOF == 6 {
            let held = self.fixes.iter().filter(|f| f.up_variance > 0.0);
            let (sum, weight) = held.fold((0.0, 0.0), |(s, w), f| {
                let z = poses[f.keyframe].position3()[2];
                (s + (f.up - z) / f.up_variance, w + 1.0 / f.up_variance)
            });
            if weight > 0.0 {
                georef.up = sum / weight;
            }
        }
        Some(georef)
    }

    /// Each fix as a position prior in the map frame of `georef`.
    pub fn priors<P: GpsPose>(&self, georef: &Georef) -> Vec<PositionPrior<P>> {
        (self.fixes.iter())
            .map(|f| P::gps_prior(f, georef, self.weight))
            .collect()
    }

    /// Georeferences `poses` by alternation, `rounds` times: take the
    /// map→ENU motion `g` ([`Self::fit`] to the poses), polish the poses on
    ///
    /// ```text
    /// Σ_edges e_ijᵀ Ω_ij e_ij + Σ_fixes (p_k − g⁻¹(enu_k))ᵀ Ω_k (p_k − g⁻¹(enu_k))
    /// ```
    ///
    /// (each fix a prior in the map frame, [`Self::priors`]), and refit `g`
    /// to the polished poses.
    ///
    /// `georef` goes in as the `g` of the first round (`None`: fitted to
    /// `poses`) and comes out as the fit to the poses as left. A fit that
    /// fails (fewer than two distinct positions) ends the rounds; when the
    /// first one fails nothing changes. On a polish error, `poses` are
    /// those the failing round started from and `georef` the `g` it used.
    /// Returns the report of the last polish, `None` when no round ran.
    pub fn georeference<P: GpsPose>(
        &self,
        edges: &[Edge<P>],
        poses: &mut Vec<P>,
        georef: &mut Option<Georef>,
        params: LevenbergMarquardtParams,
        rounds: usize,
    ) -> Result<Option<LmReport<P>>, FactorError> {
        let mut last = None;
        for _ in 0..rounds {
            let Some(g) = georef.or_else(|| self.fit(poses)) else {
                break;
            };
            *georef = Some(g);
            let priors = self.priors(&g);
            let report = polish(Problem::new(edges, &priors), poses.clone(), params)?;
            poses.clone_from(&report.poses);
            *georef = self.fit(poses);
            last = Some(report);
        }
        Ok(last)
    }
}

/// Redundancy below which a graph's χ² says too little about its noise.
pub const MIN_REDUNDANCY: usize = 30;

/// The a-posteriori variance factor `σ̂₀² = χ² / r` of a solved pose graph,
/// `r = d(m − n + 1)` its redundancy (m edges, n keyframes, connected, `d`
/// degrees of freedom per edge: 3 in the plane, 6 in space).
///
/// Scaling every edge's information by one factor leaves the graph's
/// optimum unchanged, so datasets are often published with information that
/// is only right up to a factor (City10000's optimum χ² is 512 where a
/// consistent model gives about r = 32,064). A fix with a true σ then weighs
/// wrongly against the edges; multiplying GPS weights by `σ̂₀²` restores the
/// balance (Helmert's variance-component estimate with one group). Returns
/// 1 when `r < MIN_REDUNDANCY` (odometry alone has r = 0), and clamps to
/// `[1e-4, 1e4]`.
pub fn variance_factor(chi2: f64, edges: usize, keyframes: usize, dof: usize) -> f64 {
    let r = dof * (edges + 1).saturating_sub(keyframes);
    if r < MIN_REDUNDANCY || !chi2.is_finite() {
        return 1.0;
    }
    (chi2 / r as f64).clamp(1e-4, 1e4)
}

/// A fix attached to a keyframe, in the local ENU frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GpsFix {
    /// Index of the keyframe in its graph.
    pub keyframe: usize,
    /// East + i·north (m).
    pub enu: c64,
    /// Covariance of (east, north), m².
    pub covariance: Matrix2<f64>,
    /// Up (m).
    pub up: f64,
    /// Variance of `up` (m²); 0 leaves the height free.
    pub up_variance: f64,
}

impl GpsFix {
    /// `fix`'s position, the whole fix checked as the wire checks it
    /// ([`FixInput::check`]).
    pub fn checked_position(fix: &FixInput) -> Result<Geodetic, GpsError> {
        let p = fix.position;
        let position = Geodetic::new(p.lat, p.lon, p.height)?;
        fix.check()?;
        Ok(position)
    }

    /// `fix`, at `position` ([`Self::checked_position`]), taken at keyframe
    /// index `keyframe`, in `frame`'s ENU.
    pub fn at(fix: &FixInput, position: &Geodetic, keyframe: usize, frame: &LocalFrame) -> GpsFix {
        let (e, n, u) = frame.to_enu(position);
        let c = fix.covariance;
        GpsFix {
            keyframe,
            enu: c64::new(e, n),
            covariance: Matrix2::new(c[0], c[1], c[2], c[3]),
            up: u,
            up_variance: fix.height_variance.unwrap_or(0.0),
        }
    }

    /// Mean variance per axis, `tr Σ / 2` (the σ² of paper A's equations).
    pub fn variance(&self) -> f64 {
        self.covariance.trace() / 2.0
    }

    /// The absolute position equation `p_k ≈ R⁻¹(enu − t)` in the map frame
    /// of `georef`, its information `weight · (R⁻¹ Σ R)⁻¹`.
    pub fn prior(&self, georef: &Georef, weight: f64) -> PositionPrior {
        PositionPrior {
            keyframe: self.keyframe,
            target: georef.to_map(self.enu),
            information: georef
                .covariance_to_map(&self.covariance)
                .try_inverse()
                .unwrap_or_else(Matrix2::zeros)
                * weight,
        }
    }
}

/// A pose a GPS fix can hold: the fix as a prior on its position.
pub trait GpsPose: LiePose {
    /// `fix` as a prior on its keyframe's position in the map frame of
    /// `georef`, its information times `weight`.
    fn gps_prior(fix: &GpsFix, georef: &Georef, weight: f64) -> PositionPrior<Self>;
}

impl GpsPose for Pose2 {
    fn gps_prior(fix: &GpsFix, georef: &Georef, weight: f64) -> PositionPrior {
        fix.prior(georef, weight)
    }
}

impl GpsPose for Pose3 {
    /// `p_k ≈ (R⁻¹(en − t), up − u₀)`, Ω block-diagonal: the plane's
    /// `(Rᵀ Σ R)⁻¹` and `1 / σ²_up` (0 when the height is free).
    fn gps_prior(fix: &GpsFix, georef: &Georef, weight: f64) -> PositionPrior<Pose3> {
        let plane = fix.prior(georef, 1.0);
        let mut information = Matrix3::zeros();
        information
            .fixed_view_mut::<2, 2>(0, 0)
            .copy_from(&plane.information);
        if fix.up_variance > 0.0 {
            information[(2, 2)] = 1.0 / fix.up_variance;
        }
        PositionPrior {
            keyframe: fix.keyframe,
            target: Vector3::new(plane.target.re, plane.target.im, fix.up - georef.up),
            information: information * weight,
        }
    }
}

/// Checks a 2×2 covariance (row-major): finite, symmetric, positive
/// definite ([`check_covariance`]).
pub fn covariance(c: [f64; 4]) -> Result<Matrix2<f64>, GpsError> {
    check_covariance(c)?;
    Ok(Matrix2::new(c[0], c[1], c[2], c[3]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn variance_factor_is_chi2_over_redundancy() {
        // 100 keyframes, 120 edges: r = 3 · 21 = 63
        assert!((variance_factor(6.3, 120, 100, 3) - 0.1).abs() < 1e-15);
        assert!((variance_factor(12.6, 120, 100, 6) - 0.1).abs() < 1e-15);
        // a chain has no redundancy: trust the information
        assert_eq!(variance_factor(5.0, 99, 100, 3), 1.0);
        assert_eq!(variance_factor(0.0, 120, 100, 3), 1e-4);
        assert_eq!(variance_factor(f64::NAN, 120, 100, 3), 1.0);
    }

    /// The checks themselves are tested with `check_covariance`; the
    /// wrapper gives the matrix, row-major, or the check's refusal.
    #[test]
    fn covariances_are_checked() {
        assert_eq!(
            covariance([1.0, 0.25, 0.25, 2.0]),
            Ok(Matrix2::new(1.0, 0.25, 0.25, 2.0))
        );
        assert_eq!(covariance([1.0, 0.0, 0.0, f64::NAN]), Err(GpsError::NonFinite));
        assert_eq!(
            covariance([-1.0, 0.0, 0.0, 1.0]),
            Err(GpsError::NotPositiveDefinite)
        );
    }
}
