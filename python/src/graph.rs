//! `slamd.read`, `slamd.Graph` and `slamd.solve`: the batch pipeline.

use crate::convert::{ids, kind_name, pose_rows, rows, PyPose};
use crate::error;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use slamd::graph::{InformationMatrix, PoseGraph};
use slamd::io::{read_any_graph_with, AnyGraph, OnInvalid};
use slamd::outliers::OutlierConfig;
use slamd::solver::{solve_batch, BatchOptions, BatchSolution, Formulation};
use std::path::PathBuf;

/// A pose graph read from a file: keyframes and edges, 2-D or 3-D.
///
/// Edges are as the file wrote them, whichever keyframe is newer. Poses are rows `(x, y, theta)` in 2-D
/// and `(x, y, z, qx, qy, qz, qw)` in 3-D; information rows the upper
/// triangle in g2o order (6 or 21 numbers).
#[pyclass(module = "slamd", frozen)]
pub struct Graph {
    pub(crate) inner: AnyGraph,
}

fn edge_rows<'py, P: PyPose>(py: Python<'py>, g: &PoseGraph<P>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    pose_rows(py, g.edges().iter().map(|e| e.measurement))
}

fn information_rows<'py, P: PyPose>(
    py: Python<'py>,
    g: &PoseGraph<P>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let width = P::Information::UPPER;
    let mut flat = vec![0.0; width * g.edges().len()];
    for (e, out) in g.edges().iter().zip(flat.chunks_mut(width)) {
        e.information.write_upper(out);
    }
    rows(py, width, flat)
}

fn guesses<'py, P: PyPose>(py: Python<'py>, g: &PoseGraph<P>) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let nan = vec![f64::NAN; P::PARAMS];
    let flat = g
        .keyframes()
        .iter()
        .flat_map(|k| k.guess.map_or_else(|| nan.clone(), |p| p.numbers()))
        .collect();
    rows(py, P::PARAMS, flat)
}

macro_rules! on_graph {
    ($graph:expr, $g:ident => $body:expr) => {
        match $graph {
            AnyGraph::Planar($g) => $body,
            AnyGraph::Spatial($g) => $body,
        }
    };
}

#[pymethods]
impl Graph {
    /// 2 or 3.
    #[getter]
    fn dimension(&self) -> u32 {
        match &self.inner {
            AnyGraph::Planar(_) => 2,
            AnyGraph::Spatial(_) => 3,
        }
    }

    /// Keyframe ids in file order.
    #[getter]
    fn ids<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<u64>> {
        on_graph!(&self.inner, g => ids(py, g.keyframes().iter().map(|k| k.id).collect()))
    }

    /// The file's initial guess per keyframe (rows of NaN where it gave none).
    #[getter]
    fn guess<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        on_graph!(&self.inner, g => guesses(py, g))
    }

    /// Each edge's keyframe ids `(from, to)`, an `E × 2` array.
    #[getter]
    fn edges<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<u64>>> {
        let flat: Vec<u64> = on_graph!(&self.inner, g => g
            .edges()
            .iter()
            .flat_map(|e| [g.id_of(e.from), g.id_of(e.to)])
            .collect());
        let n = flat.len() / 2;
        numpy::PyArrayMethods::reshape(&PyArray1::from_vec(py, flat), [n, 2])
    }

    /// Each edge's measured relative pose `T_ij`, one row per edge.
    #[getter]
    fn measurements<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        on_graph!(&self.inner, g => edge_rows(py, g))
    }

    /// Each edge's information, its upper triangle row by row (g2o order).
    #[getter]
    fn information<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        on_graph!(&self.inner, g => information_rows(py, g))
    }

    /// Each edge's kind: "odometry", "loop_closure", "trusted_loop_closure"
    /// or "other".
    #[getter]
    fn kinds(&self) -> Vec<&'static str> {
        on_graph!(&self.inner, g => g.edges().iter().map(|e| kind_name(e.kind)).collect())
    }

    fn __len__(&self) -> usize {
        on_graph!(&self.inner, g => g.len())
    }

    fn __repr__(&self) -> String {
        on_graph!(&self.inner, g => format!(
            "<slamd.Graph {}-D: {} keyframes, {} edges>",
            self.dimension(),
            g.len(),
            g.edges().len()
        ))
    }
}

/// Reads a graph file, 2-D or 3-D: g2o (`.g2o`), TORO or HOG-Man
/// (`.graph`), iSAM (`.txt`), or a map slamd saved. A malformed line raises
/// `SlamdError` naming the file, the line and the reason; with
/// `skip_invalid=True` edges slamd would refuse (from a keyframe to itself,
/// information not positive definite) are left out instead.
#[pyfunction]
#[pyo3(signature = (path, skip_invalid = false))]
pub fn read(py: Python<'_>, path: PathBuf, skip_invalid: bool) -> PyResult<Graph> {
    let on_invalid = if skip_invalid {
        OnInvalid::Skip
    } else {
        OnInvalid::Refuse
    };
    let (inner, _) = py
        .detach(|| read_any_graph_with(&path, on_invalid))
        .map_err(error)?;
    Ok(Graph { inner })
}

/// A batch solution.
#[pyclass(module = "slamd", frozen, get_all)]
pub struct Solution {
    /// χ² of the poses under g2o's cost (switch weights included with
    /// `robust`).
    pub chi2: f64,
    /// One row per keyframe, in the graph's order.
    pub poses: Py<PyArray2<f64>>,
    /// The keyframe id of each row.
    pub ids: Py<PyArray1<u64>>,
    /// With `robust`: each edge's switch in `[0, 1]` (below 0.5: held wrong).
    pub switches: Option<Py<PyArray1<f64>>>,
    /// Seconds the solve took.
    pub seconds: f64,
}

#[pymethods]
impl Solution {
    fn __repr__(&self) -> String {
        format!("<slamd.Solution chi2={:.6} in {:.3} s>", self.chi2, self.seconds)
    }
}

fn solution<P: PyPose + slamd::nonlinear::LiePose>(
    py: Python<'_>,
    g: &PoseGraph<P>,
    s: BatchSolution<P>,
) -> PyResult<Solution> {
    Ok(Solution {
        chi2: s.chi2,
        poses: pose_rows(py, s.poses.iter().copied())?.unbind(),
        ids: ids(py, g.keyframes().iter().map(|k| k.id).collect()).unbind(),
        switches: s.switches.clone().map(|v| PyArray1::from_vec(py, v).unbind()),
        seconds: s.seconds(),
    })
}

/// Solves `graph` at once: the linear `formulation` ("two-stage",
/// "virtual-frame", "virtual-frame-pivot", "odometry"), then with `polish`
/// Levenberg–Marquardt to convergence; `robust` filters wrong loop
/// closures (and implies the polish). Gauge: the first keyframe at the
/// origin.
#[pyfunction]
#[pyo3(signature = (graph, polish = true, robust = false, formulation = "two-stage"))]
pub fn solve(
    py: Python<'_>,
    graph: &Graph,
    polish: bool,
    robust: bool,
    formulation: &str,
) -> PyResult<Solution> {
    let formulation: Formulation = formulation.parse().map_err(error)?;
    let options = BatchOptions {
        formulation,
        polish,
        robust: robust.then(OutlierConfig::default),
        ..Default::default()
    };
    match &graph.inner {
        AnyGraph::Planar(g) => {
            let s = py.detach(|| solve_batch(g, &options)).map_err(error)?;
            solution(py, g, s)
        }
        AnyGraph::Spatial(g) => {
            let s = py.detach(|| solve_batch(g, &options)).map_err(error)?;
            solution(py, g, s)
        }
    }
}
