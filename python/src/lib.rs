//! slamd from Python: the `slamd._slamd` extension module, which maturin
//! builds (`pip install ./python`) and `slamd/__init__.py` re-exports.
//!
//! - `graph`: `read`, `Graph`, `solve`, `Solution`: the batch pipeline;
//! - `engine`: `Engine`, `Snapshot`: the incremental engine in-process,
//!   marginals included;
//! - `daemon`: `Frontend`, `Snapshots`: a running daemon over shared
//!   memory.
//!
//! Every Rust error becomes `slamd.SlamdError` with the same message.

use pyo3::prelude::*;

mod convert;
mod daemon;
mod engine;
mod graph;

pyo3::create_exception!(
    slamd,
    SlamdError,
    pyo3::exceptions::PyValueError,
    "An error from slamd (bad input, an unreadable file, a daemon that cannot be reached), with slamd's message."
);

/// `e` as a [`SlamdError`] with its message.
pub(crate) fn error(e: impl std::fmt::Display) -> PyErr {
    SlamdError::new_err(e.to_string())
}

#[pymodule]
fn _slamd(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("SlamdError", m.py().get_type::<SlamdError>())?;
    m.add_function(wrap_pyfunction!(graph::read, m)?)?;
    m.add_function(wrap_pyfunction!(graph::solve, m)?)?;
    m.add_class::<graph::Graph>()?;
    m.add_class::<graph::Solution>()?;
    m.add_class::<engine::Engine>()?;
    m.add_class::<engine::Snapshot>()?;
    m.add_class::<daemon::Frontend>()?;
    m.add_class::<daemon::Snapshots>()?;
    m.add_class::<daemon::Switches>()?;
    Ok(())
}
