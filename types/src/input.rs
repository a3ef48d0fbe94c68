//! What a frontend hands slamd: keyframe ids, edges and GPS fixes.

use crate::{check_covariance, Geodetic, GpsError, Pose2, RigidMotion};

/// A keyframe's id, chosen by the frontend (unique per map).
pub type KeyframeId = u64;

/// What produced an edge. The outlier filter never switches odometry nor
/// a trusted loop closure; every other edge is a candidate it may switch
/// off.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EdgeKind {
    /// Consecutive keyframes, from the frontend's odometry.
    #[default]
    Odometry,
    /// A place-recognition match between distant keyframes: a candidate
    /// for the outlier filter.
    LoopClosure,
    /// A loop closure the frontend vouches for (verified geometrically, or
    /// set by hand): never switched off.
    TrustedLoopClosure,
    /// Anything else (a prior, a manual constraint).
    Other,
}

impl EdgeKind {
    /// Whether the outlier filter may switch an edge of this kind off:
    /// every kind but odometry and trusted loop closures.
    pub fn switchable(self) -> bool {
        !matches!(self, EdgeKind::Odometry | EdgeKind::TrustedLoopClosure)
    }

    /// The usual reading of a dataset file: keyframes with consecutive ids are
    /// odometry, every other pair a loop closure.
    pub fn from_ids(i: u64, j: u64) -> Self {
        if i.abs_diff(j) == 1 {
            EdgeKind::Odometry
        } else {
            EdgeKind::LoopClosure
        }
    }
}

/// A keyframe as a frontend gives it: its id, an optional guess of its
/// pose and the time it was taken.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeyframeInput<P: RigidMotion = Pose2> {
    /// Its id.
    pub id: KeyframeId,
    /// A guess of its pose in the map frame; `None` lets slamd place it by
    /// its first edge.
    pub guess: Option<P>,
    /// When it was taken (ns; 0: not given).
    pub timestamp_ns: u64,
}

impl<P: RigidMotion> KeyframeInput<P> {
    /// Bundles the fields.
    pub fn new(id: KeyframeId, guess: Option<P>, timestamp_ns: u64) -> Self {
        Self {
            id,
            guess,
            timestamp_ns,
        }
    }
}

/// An edge as a frontend gives it: keyframe ids, `T_ij`, Ω and its kind.
/// `P` is the pose type: [`Pose2`] (the default) or
/// [`Pose3`](crate::Pose3).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EdgeInput<P: RigidMotion = Pose2> {
    /// Keyframe `i`.
    pub from: KeyframeId,
    /// Keyframe `j`.
    pub to: KeyframeId,
    /// `T_ij`: `j` seen from `i`.
    pub measurement: P,
    /// Ω over the edge's error (`(x, y, θ)` in the plane).
    pub information: P::Information,
    /// What produced it.
    pub kind: EdgeKind,
}

impl<P: RigidMotion> EdgeInput<P> {
    /// Bundles the fields.
    pub fn new(
        from: KeyframeId,
        to: KeyframeId,
        measurement: P,
        information: P::Information,
        kind: EdgeKind,
    ) -> Self {
        Self {
            from,
            to,
            measurement,
            information,
            kind,
        }
    }
}

/// A GPS fix as a frontend gives it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixInput {
    /// The keyframe it was taken at.
    pub keyframe: KeyframeId,
    /// Where (WGS84).
    pub position: Geodetic,
    /// Covariance of (east, north) in m², row-major.
    pub covariance: [f64; 4],
    /// Variance of the height (m²): a 3-D map's keyframe is held to the
    /// fix's height with it. `None` leaves the height free (and a 2-D map
    /// ignores it).
    pub height_variance: Option<f64>,
}

impl FixInput {
    /// Checks the covariance ([`check_covariance`]) and the height's
    /// variance, which must be finite and positive when given.
    pub fn check(&self) -> Result<(), GpsError> {
        check_covariance(self.covariance)?;
        match self.height_variance {
            Some(v) if !v.is_finite() => Err(GpsError::NonFinite),
            Some(v) if v <= 0.0 => Err(GpsError::NotPositiveDefinite),
            _ => Ok(()),
        }
    }
}
