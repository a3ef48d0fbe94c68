//! `slamd.Engine`: the incremental engine in this process.

use crate::convert::{self, ids, pose_rows, PyPose};
use crate::error;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use slamd::engine::{Engine as Core, EngineConfig, EnginePose};
use slamd::geometry::Pose2;
use slamd::graph::Pose3;

/// One engine per dimension (boxed: the two differ in size).
enum Inner {
    Planar(Box<Core<Pose2>>),
    Spatial(Box<Core<Pose3>>),
}

macro_rules! on_engine {
    ($engine:expr, $e:ident, $P:ident => $body:expr) => {
        match $engine {
            Inner::Planar($e) => {
                type $P = Pose2;
                $body
            }
            Inner::Spatial($e) => {
                type $P = Pose3;
                $body
            }
        }
    };
}

/// The incremental pose-graph engine, in this process (no daemon).
///
/// Keyframes, edges and GPS fixes go in as they arrive; `update()` solves
/// for the new estimate (re-solves run on a background thread unless
/// `background=False`), and `snapshot()` reads it. The first keyframe is
/// the gauge. Bad input raises `SlamdError` and changes nothing.
#[pyclass(module = "slamd")]
pub struct Engine {
    inner: Inner,
}

/// The engine's estimate at one moment.
#[pyclass(module = "slamd", frozen, get_all)]
pub struct Snapshot {
    /// Increases with every update.
    pub version: u64,
    /// χ² of the estimate over the applied edges, with their weights.
    pub chi2: f64,
    /// Re-solves completed so far.
    pub resolves: u64,
    /// Keyframes received (joined to the map or not).
    pub keyframes: u64,
    /// Edges received.
    pub edges: u64,
    /// Loop closures held out of the estimate until the outlier filter
    /// decides them.
    pub pending: u64,
    /// From a daemon: whether it still works on the input so far (a
    /// re-solve, the outlier filter); False on the settled map. In
    /// process: whether a re-solve runs or decisions wait.
    pub settling: bool,
    /// The id of each row of `poses` (keyframes joined to the map).
    pub ids: Py<PyArray1<u64>>,
    /// One row per keyframe: `(x, y, theta)` or `(x, y, z, qx, qy, qz, qw)`.
    pub poses: Py<PyArray2<f64>>,
    /// Each row's keyframe timestamp (ns; 0: none given).
    pub timestamps: Py<PyArray1<u64>>,
    /// From a daemon: the keyframe whose covariance `covariance` is (the
    /// newest), else None.
    pub covariance_keyframe: Option<u64>,
    /// From a daemon: that keyframe's marginal covariance, as
    /// `Engine.marginal` gives it; else None.
    pub covariance: Option<Py<PyArray2<f64>>>,
}

#[pymethods]
impl Snapshot {
    fn __len__(&self, py: Python<'_>) -> usize {
        self.ids.bind(py).len().unwrap_or(0)
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!(
            "<slamd.Snapshot version {}: {} poses, chi2={:.6}>",
            self.version,
            self.__len__(py),
            self.chi2
        )
    }
}

fn snapshot<P: EnginePose + PyPose>(py: Python<'_>, e: &Core<P>) -> PyResult<Snapshot> {
    let s = e.snapshot();
    let (id, poses): (Vec<u64>, Vec<P>) = s.poses().unzip();
    Ok(Snapshot {
        version: s.version,
        chi2: s.chi2,
        resolves: s.resolves as u64,
        keyframes: e.graph().len() as u64,
        edges: e.graph().edges().len() as u64,
        pending: s.pending as u64,
        settling: e.settling(),
        ids: ids(py, id).unbind(),
        poses: pose_rows(py, poses.into_iter())?.unbind(),
        timestamps: ids(py, s.timestamps().collect()).unbind(),
        covariance_keyframe: None,
        covariance: None,
    })
}

fn add_keyframe<P: EnginePose + PyPose>(
    e: &mut Core<P>,
    id: u64,
    guess: Option<&Bound<'_, PyAny>>,
    timestamp_ns: u64,
) -> PyResult<usize> {
    let guess = guess.map(convert::pose::<P>).transpose()?;
    e.add_keyframe_at(id, guess, timestamp_ns).map_err(error)
}

fn square<'py>(py: Python<'py>, m: nalgebra::DMatrix<f64>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let n = m.nrows();
    // nalgebra is column-major; a covariance is symmetric, but write rows
    convert::rows(py, n, m.transpose().iter().copied().collect())
}

#[pymethods]
impl Engine {
    /// An empty engine for `dimension` 2 or 3. `background=False` runs
    /// re-solves inline (deterministic); `outlier_filter=False` keeps every
    /// loop closure.
    #[new]
    #[pyo3(signature = (dimension = 2, *, background = true, outlier_filter = true))]
    fn new(dimension: u32, background: bool, outlier_filter: bool) -> PyResult<Self> {
        let mut config = EngineConfig {
            background,
            ..EngineConfig::default()
        };
        config.outliers.enabled = outlier_filter;
        let inner = match dimension {
            2 => Inner::Planar(Box::new(Core::create(config))),
            3 => Inner::Spatial(Box::new(Core::create(config))),
            d => return Err(error(format!("dimension {d}: 2 or 3"))),
        };
        Ok(Self { inner })
    }

    /// 2 or 3.
    #[getter]
    fn dimension(&self) -> u32 {
        match self.inner {
            Inner::Planar(_) => 2,
            Inner::Spatial(_) => 3,
        }
    }

    /// Adds a keyframe (the first is the gauge), with an optional initial
    /// pose in the map frame (without one its first edge places it) and
    /// the time it was taken (ns; 0: none), which snapshots carry.
    /// Returns its index.
    #[pyo3(signature = (id, guess = None, timestamp_ns = 0))]
    fn add_keyframe(
        &mut self,
        id: u64,
        guess: Option<&Bound<'_, PyAny>>,
        timestamp_ns: u64,
    ) -> PyResult<usize> {
        on_engine!(&mut self.inner, e, P => add_keyframe::<P>(e, id, guess, timestamp_ns))
    }

    /// Adds an edge `T_ij` from keyframe `from_id` to `to_id` with its
    /// information (upper triangle in g2o order, or the square matrix).
    /// `kind`: "odometry", "loop_closure", "trusted_loop_closure" or
    /// "other"; by default odometry between consecutive ids, else a loop
    /// closure. Returns its index.
    #[pyo3(signature = (from_id, to_id, measurement, information, kind = None))]
    fn add_edge(
        &mut self,
        from_id: u64,
        to_id: u64,
        measurement: &Bound<'_, PyAny>,
        information: &Bound<'_, PyAny>,
        kind: Option<&str>,
    ) -> PyResult<usize> {
        on_engine!(&mut self.inner, e, P => {
            let edge = convert::edge::<P>(from_id, to_id, measurement, information, kind)?;
            e.add_edge(edge).map_err(error)
        })
    }

    /// Adds a GPS fix (WGS84 degrees, height in m) taken at a known
    /// keyframe, with the covariance of (east, north) in m² (2×2, row
    /// major) and, in 3-D, the height's variance (None leaves it free).
    #[pyo3(signature = (keyframe, lat, lon, height = 0.0, covariance = [1.0, 0.0, 0.0, 1.0], height_variance = None))]
    fn add_gps(
        &mut self,
        keyframe: u64,
        lat: f64,
        lon: f64,
        height: f64,
        covariance: [f64; 4],
        height_variance: Option<f64>,
    ) -> PyResult<()> {
        let fix = convert::fix(keyframe, lat, lon, height, covariance, height_variance)?;
        on_engine!(&mut self.inner, e, _P => e.add_gps(fix).map_err(error))
    }

    /// Solves for the new estimate (and swaps in a finished re-solve).
    /// Returns the number of keyframes that moved.
    fn update(&mut self, py: Python<'_>) -> usize {
        on_engine!(&mut self.inner, e, _P => py.detach(|| e.update().moved))
    }

    /// Re-solves everything now, inline: the polished estimate.
    fn resolve_now(&mut self, py: Python<'_>) {
        on_engine!(&mut self.inner, e, _P => {
            py.detach(|| e.resolve_now());
        })
    }

    /// The current estimate.
    fn snapshot(&self, py: Python<'_>) -> PyResult<Snapshot> {
        on_engine!(&self.inner, e, P => snapshot::<P>(py, e))
    }

    /// Each edge's switch in `[0, 1]`, by edge index: the outlier filter's
    /// weight (information counts `s²`; below 0.5 it is held wrong).
    fn switches<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        on_engine!(&self.inner, e, _P => PyArray1::from_vec(py, e.switches()))
    }

    /// Scales an edge's information by `weight` (0 removes it; odometry
    /// cannot be removed).
    fn set_edge_weight(&mut self, edge: usize, weight: f64) -> PyResult<()> {
        on_engine!(&mut self.inner, e, _P => e.set_edge_weight(edge, weight).map_err(error))
    }

    /// The marginal covariance of keyframe `id`, 3×3 over `(x, y, theta)`
    /// or 6×6 over `(x, y, z, rx, ry, rz)`, in the pose's own frame (GTSAM's
    /// `Marginals`, though its Pose3 puts the rotation first), the gauge
    /// held fixed.
    fn marginal<'py>(&mut self, py: Python<'py>, id: u64) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let m = on_engine!(&mut self.inner, e, _P => e.marginal(id)).map_err(error)?;
        square(py, m)
    }

    /// The joint covariance of keyframes `a` and `b`, `a`'s rows first.
    fn joint_marginal<'py>(
        &mut self,
        py: Python<'py>,
        a: u64,
        b: u64,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let m = on_engine!(&mut self.inner, e, _P => e.joint_marginal(a, b)).map_err(error)?;
        square(py, m)
    }

    fn __repr__(&self) -> String {
        on_engine!(&self.inner, e, _P => format!(
            "<slamd.Engine {}-D: {} keyframes, {} edges>",
            self.dimension(),
            e.graph().len(),
            e.graph().edges().len()
        ))
    }
}
