//! Poses, information matrices and edge kinds between Python values and
//! slamd's types.
//!
//! A planar pose is `(x, y, θ)`; a spatial one `(x, y, z, qx, qy, qz, qw)`
//! (a unit quaternion, REP-103 axes). An information matrix is either its
//! upper triangle row by row in g2o order (6 numbers over `x y θ`, 21 over
//! `x y z qx qy qz`) or the full square matrix.

use crate::error;
use numpy::{PyArray1, PyArray2, PyArrayMethods};
use pyo3::prelude::*;
use slamd::engine::{EdgeInput, FixInput};
use slamd::geometry::Pose2;
use slamd::gps::Geodetic;
use slamd::graph::{EdgeKind, InformationMatrix, Pose3, RigidMotion};

/// What the bindings need of a pose type beyond [`RigidMotion`].
pub trait PyPose: RigidMotion {
    /// The pose from its Python numbers.
    fn from_numbers(v: &[f64]) -> PyResult<Self>;
    /// The pose's numbers, `PARAMS` of them.
    fn numbers(&self) -> Vec<f64>;
}

impl PyPose for Pose2 {
    fn from_numbers(v: &[f64]) -> PyResult<Self> {
        match v {
            &[x, y, theta] => Ok(Pose2::new(x, y, theta)),
            _ => Err(error(format!(
                "a planar pose is (x, y, theta); got {} numbers",
                v.len()
            ))),
        }
    }
    fn numbers(&self) -> Vec<f64> {
        vec![self.x, self.y, self.theta]
    }
}

impl PyPose for Pose3 {
    fn from_numbers(v: &[f64]) -> PyResult<Self> {
        let a: [f64; 7] = v.try_into().map_err(|_| {
            error(format!(
                "a spatial pose is (x, y, z, qx, qy, qz, qw); got {} numbers",
                v.len()
            ))
        })?;
        Pose3::from_xyz_quaternion(a)
            .ok_or_else(|| error("a spatial pose needs finite numbers and a quaternion of unit norm"))
    }
    fn numbers(&self) -> Vec<f64> {
        self.to_xyz_quaternion().to_vec()
    }
}

/// The numbers of a pose given as any sequence of floats.
pub fn pose<P: PyPose>(value: &Bound<'_, PyAny>) -> PyResult<P> {
    let v: Vec<f64> = value.extract()?;
    P::from_numbers(&v)
}

/// An information matrix from its upper triangle or the square matrix.
pub fn information<P: RigidMotion>(value: &Bound<'_, PyAny>) -> PyResult<P::Information> {
    let dof = if P::DIMENSION == 2 { 3 } else { 6 };
    let upper: Vec<f64> = match value.extract::<Vec<f64>>() {
        Ok(flat) => flat,
        Err(_) => {
            let rows: Vec<Vec<f64>> = value
                .extract()
                .map_err(|_| error("information: a sequence of numbers or a square matrix"))?;
            if rows.len() != dof || rows.iter().any(|r| r.len() != dof) {
                return Err(error(format!("information: a {dof}x{dof} matrix is needed")));
            }
            (0..dof).flat_map(|r| rows[r][r..].to_vec()).collect()
        }
    };
    if upper.len() != P::Information::UPPER {
        return Err(error(format!(
            "information: {} upper-triangle numbers are needed; got {}",
            P::Information::UPPER,
            upper.len()
        )));
    }
    P::Information::from_upper_slice(&upper).map_err(error)
}

/// An edge from its Python values (see [`pose`], [`information`], [`kind`]).
pub fn edge<P: PyPose>(
    from: u64,
    to: u64,
    measurement: &Bound<'_, PyAny>,
    information: &Bound<'_, PyAny>,
    kind_name: Option<&str>,
) -> PyResult<EdgeInput<P>> {
    Ok(EdgeInput::new(
        from,
        to,
        pose::<P>(measurement)?,
        self::information::<P>(information)?,
        kind(kind_name, from, to)?,
    ))
}

/// A GPS fix: WGS84 degrees and height (m), the (east, north) covariance
/// (m², row major) and the height's variance (None: free).
pub fn fix(
    keyframe: u64,
    lat: f64,
    lon: f64,
    height: f64,
    covariance: [f64; 4],
    height_variance: Option<f64>,
) -> PyResult<FixInput> {
    Ok(FixInput {
        keyframe,
        position: Geodetic::new(lat, lon, height).map_err(error)?,
        covariance,
        height_variance,
    })
}

/// The default kind of an edge: odometry between consecutive ids, else a
/// loop closure (the usual reading of a dataset).
pub fn kind(name: Option<&str>, from: u64, to: u64) -> PyResult<EdgeKind> {
    Ok(match name {
        None => EdgeKind::from_ids(from, to),
        Some("odometry") => EdgeKind::Odometry,
        Some("loop_closure") => EdgeKind::LoopClosure,
        Some("trusted_loop_closure") => EdgeKind::TrustedLoopClosure,
        Some("other") => EdgeKind::Other,
        Some(k) => {
            return Err(error(format!(
                "edge kind {k:?}: one of odometry, loop_closure, trusted_loop_closure, other"
            )))
        }
    })
}

/// The Python name of an edge kind.
pub fn kind_name(kind: EdgeKind) -> &'static str {
    match kind {
        EdgeKind::Odometry => "odometry",
        EdgeKind::LoopClosure => "loop_closure",
        EdgeKind::TrustedLoopClosure => "trusted_loop_closure",
        EdgeKind::Other => "other",
    }
}

/// Rows of numbers as an `n × width` array.
pub fn rows<'py>(py: Python<'py>, width: usize, flat: Vec<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let n = flat.len() / width.max(1);
    PyArray1::from_vec(py, flat).reshape([n, width])
}

/// Poses as an `n × PARAMS` array.
pub fn pose_rows<'py, P: PyPose>(
    py: Python<'py>,
    poses: impl Iterator<Item = P>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    rows(py, P::PARAMS, poses.flat_map(|p| p.numbers()).collect())
}

/// Unsigned ids as an array.
pub fn ids<'py>(py: Python<'py>, ids: Vec<u64>) -> Bound<'py, PyArray1<u64>> {
    PyArray1::from_vec(py, ids)
}
