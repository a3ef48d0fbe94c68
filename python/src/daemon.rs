//! `slamd.Frontend` and `slamd.Snapshots`: a running daemon, over shared
//! memory.

use crate::convert::{self, ids, rows};
use crate::engine::Snapshot;
use crate::error;
use pyo3::prelude::*;
use slamd::geometry::Pose2;
use slamd::graph::Pose3;
use slamd_protocol::transport::SnapshotLink;
use slamd_protocol::Endpoint;
use std::time::{Duration, Instant};

/// A frontend publishing to the daemon of `namespace` (the daemon's
/// `SLAMD_NAMESPACE`, default "slamd"), in `dimension` 2 or 3 (the
/// daemon's own). Messages are numbered; the daemon acknowledges them in
/// its snapshots, and what it has not acknowledged is sent again when a
/// new daemon instance takes over the namespace.
#[pyclass(module = "slamd", unsendable)]
pub struct Frontend {
    link: Link,
}

/// The connection, typed by the daemon's dimension.
enum Link {
    Planar(slamd_protocol::Frontend<Pose2>),
    Spatial(slamd_protocol::Frontend<Pose3>),
}

/// `$body` with `$l` bound to the connection and `$P` to its pose type,
/// whatever its dimension.
macro_rules! on_link {
    ($link:expr, $l:ident => $body:expr) => {
        match $link {
            Link::Planar($l) => $body,
            Link::Spatial($l) => $body,
        }
    };
    ($link:expr, $l:ident, $P:ident => $body:expr) => {
        match $link {
            Link::Planar($l) => {
                type $P = Pose2;
                $body
            }
            Link::Spatial($l) => {
                type $P = Pose3;
                $body
            }
        }
    };
}

#[pymethods]
impl Frontend {
    #[new]
    #[pyo3(signature = (namespace = "slamd", dimension = 2))]
    fn new(namespace: &str, dimension: u32) -> PyResult<Self> {
        if !(2..=3).contains(&dimension) {
            return Err(error(format!("dimension {dimension}: 2 or 3")));
        }
        let endpoint = Endpoint::new(namespace);
        let link = if dimension == 2 {
            Link::Planar(slamd_protocol::Frontend::connect(endpoint).map_err(error)?)
        } else {
            Link::Spatial(slamd_protocol::Frontend::connect(endpoint).map_err(error)?)
        };
        Ok(Self { link })
    }

    /// This frontend's id in the daemon's acknowledgements.
    #[getter]
    fn id(&self) -> u32 {
        on_link!(&self.link, l => l.id())
    }

    /// The number of the last message sent.
    #[getter]
    fn last_sequence(&self) -> u64 {
        on_link!(&self.link, l => l.last_sequence())
    }

    /// Publishes a keyframe, with an optional initial pose and its time
    /// (ns, the frontend's clock). Returns its message number.
    #[pyo3(signature = (id, guess = None, timestamp_ns = 0))]
    fn add_keyframe(
        &mut self,
        id: u64,
        guess: Option<&Bound<'_, PyAny>>,
        timestamp_ns: u64,
    ) -> PyResult<u64> {
        on_link!(&mut self.link, l, P => {
            let guess = guess.map(convert::pose::<P>).transpose()?;
            l.add_keyframe(id, timestamp_ns, guess).map_err(error)
        })
    }

    /// Publishes an edge, as `Engine.add_edge` takes it. Returns its
    /// message number.
    #[pyo3(signature = (from_id, to_id, measurement, information, kind = None))]
    fn add_edge(
        &mut self,
        from_id: u64,
        to_id: u64,
        measurement: &Bound<'_, PyAny>,
        information: &Bound<'_, PyAny>,
        kind: Option<&str>,
    ) -> PyResult<u64> {
        on_link!(&mut self.link, l, P => {
            let edge = convert::edge::<P>(from_id, to_id, measurement, information, kind)?;
            l.add_edge(&edge).map_err(error)
        })
    }

    /// Publishes a GPS fix, as `Engine.add_gps` takes it.
    #[pyo3(signature = (keyframe, lat, lon, height = 0.0, covariance = [1.0, 0.0, 0.0, 1.0], height_variance = None))]
    fn add_gps(
        &mut self,
        keyframe: u64,
        lat: f64,
        lon: f64,
        height: f64,
        covariance: [f64; 4],
        height_variance: Option<f64>,
    ) -> PyResult<u64> {
        let fix = convert::fix(keyframe, lat, lon, height, covariance, height_variance)?;
        on_link!(&mut self.link, l => l.add_gps(&fix)).map_err(error)
    }

    /// Wakes the daemon for what was published.
    fn flush(&mut self) -> PyResult<()> {
        on_link!(&mut self.link, l => l.flush()).map_err(error)
    }

    /// Waits until the daemon has acknowledged message `sequence` (default:
    /// the last one sent), for as long as the daemon shows it is alive:
    /// False once `timeout` seconds pass with no status from it (gone, or
    /// never there). A daemon that holds acknowledgements (its journal
    /// cannot be written) is waited for, and why is logged on the `slamd`
    /// logger (warning) at most every 5 s. Ctrl-C interrupts it.
    #[pyo3(signature = (sequence = None, timeout = 10.0))]
    fn wait_acknowledged(&mut self, py: Python<'_>, sequence: Option<u64>, timeout: f64) -> PyResult<bool> {
        let sequence = sequence.unwrap_or(on_link!(&self.link, l => l.last_sequence()));
        let silence = Duration::try_from_secs_f64(timeout).map_err(error)?;
        let logger = py.import("logging")?.call_method1("getLogger", ("slamd",))?;
        let mut failed: Option<PyErr> = None;
        let mut last_look = Instant::now();
        let done = on_link!(&mut self.link, l => l.wait_acknowledged_with(sequence, silence, |w| {
            let said = if w.say {
                logger.call_method1("warning", (w.to_string(),)).map(drop)
            } else {
                Ok(())
            };
            // the waits keep the GIL (the iceoryx2 ports cannot leave
            // their thread): look for Ctrl-C every SLICE
            let checked = if last_look.elapsed() >= SLICE {
                last_look = Instant::now();
                py.check_signals()
            } else {
                Ok(())
            };
            match said.and(checked) {
                Ok(()) => true,
                Err(e) => {
                    failed = Some(e);
                    false
                }
            }
        }))
        .map_err(error)?;
        match failed {
            Some(e) => Err(e),
            None => Ok(done),
        }
    }
}

/// The longest a wait holds the interpreter before it looks for Ctrl-C
/// (the iceoryx2 ports cannot leave their thread, so the waits keep the
/// GIL).
const SLICE: Duration = Duration::from_millis(100);

/// When a wait of `timeout` seconds ends.
fn deadline(timeout: f64) -> PyResult<Instant> {
    Ok(Instant::now() + Duration::try_from_secs_f64(timeout).map_err(error)?)
}

/// The daemon's pose snapshots of `namespace`.
#[pyclass(module = "slamd", unsendable)]
pub struct Snapshots {
    link: SnapshotLink,
}

fn daemon_snapshot(py: Python<'_>, s: &slamd_protocol::MapSnapshot) -> PyResult<Snapshot> {
    let h = s.header();
    let poses = s.poses();
    let (width, flat): (usize, Vec<f64>) = if h.dimension == 3 {
        (
            7,
            poses
                .iter()
                .flat_map(|p| [p.x, p.y, p.z, p.qx, p.qy, p.qz, p.qw])
                .collect(),
        )
    } else {
        (3, poses.iter().flat_map(|p| [p.x, p.y, p.theta]).collect())
    };
    let covariance = if h.has_covariance != 0 {
        let dof = if width == 7 { 6 } else { 3 };
        let mut sigma = vec![0.0; dof * dof];
        let mut i = 0;
        for r in 0..dof {
            for c in r..dof {
                sigma[r * dof + c] = h.covariance[i];
                sigma[c * dof + r] = h.covariance[i];
                i += 1;
            }
        }
        Some(rows(py, dof, sigma)?.unbind())
    } else {
        None
    };
    Ok(Snapshot {
        version: h.version,
        chi2: h.chi2,
        resolves: h.resolves,
        keyframes: h.keyframes,
        edges: h.edges,
        pending: u64::from(h.pending),
        settling: h.settling != 0,
        ids: ids(py, poses.iter().map(|p| p.id).collect()).unbind(),
        poses: rows(py, width, flat)?.unbind(),
        timestamps: ids(py, poses.iter().map(|p| p.timestamp_ns).collect()).unbind(),
        covariance_keyframe: (h.has_covariance != 0).then_some(h.covariance_keyframe),
        covariance,
    })
}

/// The outlier filter's state of every loop closure, as the daemon last
/// published it (it does when one arrives or is decided).
#[pyclass(module = "slamd", frozen, get_all)]
pub struct Switches {
    /// The snapshot version these weights belong to.
    pub version: u64,
    /// One row `(from, to)` of keyframe ids per loop closure, in arrival
    /// order.
    pub edges: Py<numpy::PyArray2<u64>>,
    /// Each one's switch `s ∈ [0, 1]` (its information counts `s²` times).
    pub weights: Py<numpy::PyArray1<f64>>,
    /// Each one's state: `"kept"`, `"off"` (decided wrong: weight below
    /// 0.5) or `"pending"` (not decided, held out of the estimate).
    pub states: Vec<&'static str>,
}

fn daemon_switches(py: Python<'_>, s: &slamd_protocol::transport::SwitchesSample) -> PyResult<Switches> {
    use numpy::{PyArray1, PyArrayMethods};
    let all = s.switches();
    let edges =
        PyArray1::from_vec(py, all.iter().flat_map(|w| [w.from, w.to]).collect()).reshape([all.len(), 2])?;
    Ok(Switches {
        version: s.header().version,
        edges: edges.unbind(),
        weights: PyArray1::from_vec(py, all.iter().map(|w| w.weight).collect()).unbind(),
        states: all.iter().map(|w| w.state().name()).collect(),
    })
}

#[pymethods]
impl Snapshots {
    /// The newest loop-closure switches delivered since the last call, or
    /// None (never blocks; a new `Snapshots` gets the last ones published).
    fn switches(&self, py: Python<'_>) -> PyResult<Option<Switches>> {
        match self.link.switches().map_err(error)? {
            Some(s) => daemon_switches(py, &s).map(Some),
            None => Ok(None),
        }
    }

    #[new]
    #[pyo3(signature = (namespace = "slamd"))]
    fn new(namespace: &str) -> PyResult<Self> {
        Ok(Self {
            link: SnapshotLink::open(namespace).map_err(error)?,
        })
    }

    /// The newest snapshot delivered since the last call, or None.
    fn latest(&mut self, py: Python<'_>) -> PyResult<Option<Snapshot>> {
        match self.link.latest().map_err(error)? {
            Some(s) => daemon_snapshot(py, s).map(Some),
            None => Ok(None),
        }
    }

    /// Waits up to `timeout` seconds for a snapshot newer than the last one
    /// taken; None on timeout. Ctrl-C interrupts it.
    #[pyo3(signature = (timeout = 5.0))]
    fn wait(&mut self, py: Python<'_>, timeout: f64) -> PyResult<Option<Snapshot>> {
        let deadline = deadline(timeout)?;
        loop {
            let slice = deadline.saturating_duration_since(Instant::now()).min(SLICE);
            if let Some(s) = self.link.wait(slice).map_err(error)? {
                return daemon_snapshot(py, s).map(Some);
            }
            py.check_signals()?;
            if Instant::now() >= deadline {
                return Ok(None);
            }
        }
    }
}
