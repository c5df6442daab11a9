//! `read` and `samples`: a pcap or pcapng through the decoder into numpy rows.

use crate::errors::{pcap_error, value_error};
use crate::rows::{as_record_rows, as_sample_rows, RecordElement, SampleElement};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use skinbox_host::pcap::{self, PcapOptions};
use skinbox_host::rows::RowWriter;
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

    fn pcap(&self) -> PcapOptions {
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
pub fn report_json(report: &Report, timing: &Timing) -> PyResult<String> {
    let mut value = serde_json::to_value(report).map_err(|e| value_error(e.to_string()))?;
    value["host_times"] =
        serde_json::to_value(timing.summary()).map_err(|e| value_error(e.to_string()))?;
    Ok(value.to_string())
}

/// Reads the file and counts its records (the first pass, which also learns the sample
/// rate when it is not given); the rows then fill an array of exactly that length.
fn first_pass(
    path: &std::path::Path,
    options: &DecodeOptions,
) -> Result<(Vec<u8>, usize, f64), pcap::PcapError> {
    let bytes = pcap::read_file(path)?;
    let report = pcap::decode_pcap_with(&bytes, &options.pcap(), &mut ())?;
    Ok((bytes, report.records as usize, report.sample_rate_hz))
}

/// Decodes the rows into `rows`; every row must fit exactly.
fn fill<S: RecordSink>(
    bytes: &[u8],
    options: &DecodeOptions,
    writer: &mut S,
) -> Result<Report, pcap::PcapError> {
    pcap::decode_pcap_with(bytes, &options.pcap(), writer)
}

fn check_filled(written: usize, beyond: u64, expected: usize) -> PyResult<()> {
    if written != expected || beyond != 0 {
        return Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
            "the second pass over the capture gave {} rows, the first {expected}",
            written as u64 + beyond
        )));
    }
    Ok(())
}

/// Every record of a pcap or pcapng as a record array, and the report as JSON text.
#[pyfunction]
#[pyo3(signature = (path, sample_rate_hz=None, udp_port=None, cells_per_bus=None, synced=false))]
pub fn read_records<'py>(
    py: Python<'py>,
    path: PathBuf,
    sample_rate_hz: Option<f64>,
    udp_port: Option<u16>,
    cells_per_bus: Option<u16>,
    synced: bool,
) -> PyResult<(Bound<'py, PyArray1<RecordElement>>, String)> {
    let options = DecodeOptions {
        sample_rate_hz,
        udp_port,
        cells_per_bus,
        synced,
    };
    options.check()?;
    let (bytes, n, rate_hz) = py
        .detach(|| first_pass(&path, &options))
        .map_err(pcap_error)?;
    let array = PyArray1::<RecordElement>::zeros(py, n, false);
    // SAFETY: the array is new and not yet visible to Python: nothing else reads or
    // writes it while the rows are written without the GIL.
    let elements = unsafe { array.as_slice_mut() }.map_err(|e| value_error(e.to_string()))?;
    let (report, written, beyond, timing) = py.detach(|| {
        let mut writer = RowWriter::new(as_record_rows(elements), options.timing(rate_hz));
        let report = fill(&bytes, &options, &mut writer);
        let (written, beyond) = (writer.written(), writer.beyond());
        (report, written, beyond, writer.into_timing())
    });
    let report = report.map_err(pcap_error)?;
    check_filled(written, beyond, n)?;
    Ok((array, report_json(&report, &timing)?))
}

/// The full sample after every record of a pcap or pcapng (event to data) as a sample
/// array, and the report as JSON text.
#[pyfunction]
#[pyo3(signature = (path, sample_rate_hz=None, udp_port=None, cells_per_bus=None, synced=false))]
pub fn read_samples<'py>(
    py: Python<'py>,
    path: PathBuf,
    sample_rate_hz: Option<f64>,
    udp_port: Option<u16>,
    cells_per_bus: Option<u16>,
    synced: bool,
) -> PyResult<(Bound<'py, PyArray1<SampleElement>>, String)> {
    let options = DecodeOptions {
        sample_rate_hz,
        udp_port,
        cells_per_bus,
        synced,
    };
    options.check()?;
    let (bytes, n, rate_hz) = py
        .detach(|| first_pass(&path, &options))
        .map_err(pcap_error)?;
    let array = PyArray1::<SampleElement>::zeros(py, n, false);
    // SAFETY: as in `read_records`.
    let elements = unsafe { array.as_slice_mut() }.map_err(|e| value_error(e.to_string()))?;
    let (report, written, beyond, timing) = py.detach(|| {
        let mut writer = RowWriter::new(as_sample_rows(elements), options.timing(rate_hz));
        let report = fill(&bytes, &options, &mut writer);
        let (written, beyond) = (writer.written(), writer.beyond());
        (report, written, beyond, writer.into_timing())
    });
    let report = report.map_err(pcap_error)?;
    check_filled(written, beyond, n)?;
    Ok((array, report_json(&report, &timing)?))
}
