//! The Python extension of the skinbox host client (`skinbox._native`): numpy arrays of
//! records and samples from pcap and pcapng files and live captures, box commands and an
//! emulated box. The Python package `skinbox` (python/skinbox) wraps it; docs/python.md
//! describes the API.

mod chunks;
mod control;
mod emulate;
mod errors;
mod files;
mod live;
mod mapped;
mod rows;
mod synthetic;
mod timed;

use pyo3::prelude::*;
use pyo3::types::PyList;
use skinbox_host::rows as host_rows;
use skinbox_protocol::Channel;

/// JSON text as plain Python objects (dicts, lists, numbers, strings).
pub(crate) fn json_to_python(py: Python<'_>, json: &str) -> PyResult<Py<PyAny>> {
    Ok(py
        .import("json")?
        .getattr("loads")?
        .call1((json,))?
        .unbind())
}

#[pymodule]
fn _native(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("RECORD_DTYPE", rows::record_dtype(py)?)?;
    m.add("SAMPLE_DTYPE", rows::sample_dtype(py)?)?;
    m.add(
        "CHANNELS",
        PyList::new(py, Channel::ALL.iter().map(|c| c.name()))?,
    )?;
    m.add(
        "CHANNEL_UNITS",
        PyList::new(py, Channel::ALL.iter().map(|c| c.unit()))?,
    )?;
    m.add(
        "UNITS_PER_LSB",
        PyList::new(py, Channel::ALL.iter().map(|c| c.units_per_lsb()))?,
    )?;
    m.add("KIND_DATA", host_rows::KIND_DATA)?;
    m.add("KIND_EVENT", host_rows::KIND_EVENT)?;
    m.add("HOST_TIME_NONE", host_rows::HOST_TIME_NONE)?;
    m.add(
        "HOST_TIME_RECEIVE_STAMPS",
        host_rows::HOST_TIME_RECEIVE_STAMPS,
    )?;
    m.add("HOST_TIME_EXCHANGES", host_rows::HOST_TIME_EXCHANGES)?;
    m.add("SkinboxError", py.get_type::<errors::SkinboxError>())?;
    m.add(
        "CaptureFileError",
        py.get_type::<errors::CaptureFileError>(),
    )?;
    m.add("BadInputError", py.get_type::<errors::BadInputError>())?;
    m.add("BoxError", py.get_type::<errors::BoxError>())?;
    m.add("BoxRefusedError", py.get_type::<errors::BoxRefusedError>())?;
    m.add("EmulatorError", py.get_type::<errors::EmulatorError>())?;
    m.add("CaptureError", py.get_type::<errors::CaptureError>())?;
    m.add_function(wrap_pyfunction!(files::read_records, m)?)?;
    m.add_function(wrap_pyfunction!(files::read_samples, m)?)?;
    m.add_function(wrap_pyfunction!(synthetic::write_synthetic_capture, m)?)?;
    m.add_function(wrap_pyfunction!(synthetic::write_bench_capture, m)?)?;
    m.add_function(wrap_pyfunction!(synthetic::replay_capture, m)?)?;
    m.add_class::<chunks::Reader>()?;
    m.add_class::<control::BoxHandle>()?;
    m.add_class::<emulate::Emulator>()?;
    m.add_class::<live::Capture>()?;
    Ok(())
}
