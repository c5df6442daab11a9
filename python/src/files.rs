//! `read` and `samples`: a pcap or pcapng through the decoder into numpy rows.

use crate::errors::{pcap_error, value_error};
use crate::rows::{as_record_rows, as_sample_rows, RecordElement, SampleElement};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PySlice;
use skinbox_host::pcap::{self, PcapOptions};
use skinbox_host::rows::{max_records, RecordRow, RowWriter, SampleRow};
use skinbox_host::sample_clock::{PathModel, Positions, HOP_LATENCY_NS, PROCESSING_NS};
use skinbox_host::timing::Timing;
use skinbox_host::{DecoderConfig, RecordSink, Report};
use std::path::PathBuf;

/// How to decode and time a capture (the options of `skinbox decode`).
#[derive(Debug, Clone, Copy)]
pub struct DecodeOptions {
    pub sample_rate_hz: Option<f64>,
    pub udp_port: Option<u16>,
    pub cells_per_bus: Option<u16>,
    pub synced: bool,
}

impl DecodeOptions {
    pub fn check(&self) -> PyResult<()> {
        if let Some(rate) = self.sample_rate_hz {
            if !(rate.is_finite() && rate > 0.0) {
                return Err(value_error(format!(
                    "sample_rate_hz {rate}: must be a positive number"
                )));
            }
        }
        if self.cells_per_bus == Some(0) {
            return Err(value_error("cells_per_bus must be at least 1"));
        }
        Ok(())
    }

    pub(crate) fn pcap(&self) -> PcapOptions {
        PcapOptions {
            decoder: DecoderConfig {
                sample_rate_hz: self.sample_rate_hz,
                ..DecoderConfig::default()
            },
            udp_port: self.udp_port,
        }
    }

    /// The timing of cells sampling at `rate_hz` on the bus model's paths.
    pub fn timing(&self, rate_hz: f64) -> Timing {
        let hops = match self.cells_per_bus {
            Some(n) => Positions::Numbered { cells_per_bus: n },
            None => Positions::Unknown,
        };
        let timing = Timing::new(
            rate_hz,
            PathModel {
                processing_ns: PROCESSING_NS,
                hop_latency_ns: HOP_LATENCY_NS,
                hops,
            },
        );
        if self.synced {
            timing.on_box_grid()
        } else {
            timing
        }
    }
}

/// The report with the host-time summary, as JSON text.
pub fn report_json(report: &Report, timing: Option<&Timing>) -> PyResult<String> {
    let mut value = serde_json::to_value(report).map_err(|e| value_error(e.to_string()))?;
    value["host_times"] = serde_json::to_value(timing.map(|t| t.summary()).unwrap_or_default())
        .map_err(|e| value_error(e.to_string()))?;
    Ok(value.to_string())
}

/// Decodes the capture at `path` into a new array of rows (`rows_of` views its elements as
/// rows), in one pass when the sample times need no learned rate (`times` off, or the
/// rate given: the array is then allocated for the most records the file can hold, and
/// only the rows written are touched and returned), else in two as `skinbox decode`
/// does. Returns the rows and the report as JSON text.
fn decode_into<'py, E, R>(
    py: Python<'py>,
    path: &std::path::Path,
    options: &DecodeOptions,
    times: bool,
    rows_of: fn(&mut [E]) -> &mut [R],
) -> PyResult<(Bound<'py, PyAny>, String)>
where
    E: numpy::Element + Send,
    R: Send,
    for<'a> RowWriter<'a, R>: RecordSink,
{
    options.check()?;
    let bytes = py
        .detach(|| crate::mapped::map_file(path))
        .map_err(pcap_error)?;
    let (rate_hz, exact) = match (times, options.sample_rate_hz) {
        (false, _) => (None, None),
        (true, Some(rate)) => (Some(rate), None),
        (true, None) => {
            let report = py
                .detach(|| pcap::decode_pcap_with(&bytes, &options.pcap(), &mut ()))
                .map_err(pcap_error)?;
            (Some(report.sample_rate_hz), Some(report.records as usize))
        }
    };
    let capacity = exact.unwrap_or_else(|| max_records(bytes.len()));
    // SAFETY: every row handed to Python is written below before the array is returned;
    // the rows past them are cut off (a view) or not copied.
    let array = unsafe { PyArray1::<E>::new(py, [capacity], false) };
    // SAFETY: the array is new and not yet visible to Python: nothing else reads or
    // writes it while the rows are written without the GIL.
    let elements = unsafe { array.as_slice_mut() }.map_err(|e| value_error(e.to_string()))?;
    let (report, written, beyond, timing) = py.detach(|| {
        let mut writer = RowWriter::new(rows_of(elements), rate_hz.map(|r| options.timing(r)));
        let report = pcap::decode_pcap_with(&bytes, &options.pcap(), &mut writer);
        let (written, beyond) = (writer.written(), writer.beyond());
        (report, written, beyond, writer.into_timing())
    });
    let report = report.map_err(pcap_error)?;
    if beyond != 0 || exact.is_some_and(|n| n != written) {
        return Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
            "{} rows decoded, room for {capacity}",
            written as u64 + beyond
        )));
    }
    let json = report_json(&report, timing.as_ref())?;
    let array = array.into_any();
    let rows = if written == capacity {
        array
    } else {
        let view = array.get_item(PySlice::new(py, 0, written as isize, 1))?;
        // A file of small datagrams leaves most of the room unused: keep only the rows.
        if written < capacity / 2 {
            view.call_method0("copy")?
        } else {
            view
        }
    };
    Ok((rows, json))
}

/// Every record of a pcap or pcapng as a record array, and the report as JSON text.
#[pyfunction]
#[pyo3(signature = (path, sample_rate_hz=None, udp_port=None, cells_per_bus=None, synced=false, times=true))]
pub fn read_records<'py>(
    py: Python<'py>,
    path: PathBuf,
    sample_rate_hz: Option<f64>,
    udp_port: Option<u16>,
    cells_per_bus: Option<u16>,
    synced: bool,
    times: bool,
) -> PyResult<(Bound<'py, PyAny>, String)> {
    let options = DecodeOptions {
        sample_rate_hz,
        udp_port,
        cells_per_bus,
        synced,
    };
    decode_into::<RecordElement, RecordRow>(py, &path, &options, times, as_record_rows)
}

/// The full sample after every record of a pcap or pcapng (event to data) as a sample
/// array, and the report as JSON text.
#[pyfunction]
#[pyo3(signature = (path, sample_rate_hz=None, udp_port=None, cells_per_bus=None, synced=false, times=true))]
pub fn read_samples<'py>(
    py: Python<'py>,
    path: PathBuf,
    sample_rate_hz: Option<f64>,
    udp_port: Option<u16>,
    cells_per_bus: Option<u16>,
    synced: bool,
    times: bool,
) -> PyResult<(Bound<'py, PyAny>, String)> {
    let options = DecodeOptions {
        sample_rate_hz,
        udp_port,
        cells_per_bus,
        synced,
    };
    decode_into::<SampleElement, SampleRow>(py, &path, &options, times, as_sample_rows)
}
