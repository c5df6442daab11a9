//! `read` and `samples`: a pcap or pcapng through the decoder into numpy rows. `read`'s
//! records with times are decoded in one thread and timed in a second (timed.rs);
//! `samples` (one row per sample, not per record) are written and timed in one.

use crate::errors::{pcap_error, value_error};
use crate::rows::{as_record_rows, as_sample_rows, RecordElement, SampleElement};
use crate::timed::{time_rows, Datagrams};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PySlice;
use skinbox_host::decoder::DecodedRecord;
use skinbox_host::pcap::{self, PcapError, PcapOptions};
use skinbox_host::rows::{max_records, RecordRow, RowWriter, SampleRow};
use skinbox_host::sample_clock::{PathModel, Positions, HOP_LATENCY_NS, PROCESSING_NS};
use skinbox_host::timing::Timing;
use skinbox_host::{DecoderConfig, RecordSink, Report};
use std::path::PathBuf;
use std::sync::mpsc::{channel, sync_channel, Receiver, SyncSender};
use std::time::Duration;

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

/// The report with the host-time summary, as JSON text; with the CPU time of a timing
/// thread (`host.timing_cpu_s`, beside the decoding thread's `host.cpu_s`) where the rows
/// were timed in one.
pub fn report_json(
    report: &Report,
    timing: Option<&Timing>,
    timing_cpu_s: Option<f64>,
) -> PyResult<String> {
    let mut value = serde_json::to_value(report).map_err(|e| value_error(e.to_string()))?;
    value["host_times"] = serde_json::to_value(timing.map(|t| t.summary()).unwrap_or_default())
        .map_err(|e| value_error(e.to_string()))?;
    if let (Some(cpu_s), Some(host)) = (timing_cpu_s, value["host"].as_object_mut()) {
        host.insert("timing_cpu_s".into(), cpu_s.into());
    }
    Ok(value.to_string())
}

/// What filling an array's rows gave: the decoder's report, the rows written, those that
/// did not fit, and the timing (for its summary).
pub(crate) struct Filled {
    report: Result<Report, PcapError>,
    written: usize,
    beyond: u64,
    timing: Option<Timing>,
    /// The CPU time of a thread of its own that timed the rows, s.
    timing_cpu_s: Option<f64>,
}

/// Fills `rows` from their first with the rows of the capture `bytes`, timed by `timing`
/// (or untimed), in this thread: the rows of a `RowWriter` with the timing.
fn fill_rows<R>(
    bytes: &[u8],
    options: &DecodeOptions,
    timing: Option<Timing>,
    rows: &mut [R],
) -> Filled
where
    for<'a> RowWriter<'a, R>: RecordSink,
{
    let mut writer = RowWriter::new(rows, timing);
    let report = pcap::decode_pcap_with(bytes, &options.pcap(), &mut writer);
    Filled {
        report,
        written: writer.written(),
        beyond: writer.beyond(),
        timing: writer.into_timing(),
        timing_cpu_s: None,
    }
}

/// Rows a part of the array holds that the decoding thread hands to the timing thread:
/// small enough to be in the caches still when the timing reads and completes them.
const TIMED_PART_ROWS: usize = 4096;

/// The decoding thread's sink with times in a second thread: rows without times into the
/// current part of the array, each datagram kept in its place among them; a full part
/// goes with its datagrams to the timing thread.
struct PartSink<'a> {
    writer: RowWriter<'a, RecordRow>,
    /// The array after the current part.
    rest: &'a mut [RecordRow],
    datagrams: Datagrams,
    /// Rows handed over.
    handed: usize,
    to: SyncSender<(&'a mut [RecordRow], Datagrams)>,
    spare: Receiver<Datagrams>,
}

impl<'a> PartSink<'a> {
    /// Hands the rows written and their datagrams to the timing thread, going on in `next`.
    fn hand_over(&mut self, next: &'a mut [RecordRow]) {
        let rows = self.writer.swap_rows(next);
        self.handed += rows.len();
        let datagrams = self.spare.try_recv().unwrap_or_default();
        let datagrams = std::mem::replace(&mut self.datagrams, datagrams);
        // The timing thread takes every part until it is dropped.
        let _ = self.to.send((rows, datagrams));
    }

    #[cold]
    fn next_part(&mut self) {
        let n = TIMED_PART_ROWS.min(self.rest.len());
        let (next, rest) = std::mem::take(&mut self.rest).split_at_mut(n);
        self.rest = rest;
        self.hand_over(next);
    }
}

impl RecordSink for PartSink<'_> {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        // a full part with more array after it: on in the next part (else `beyond` counts)
        if self.writer.is_full() && !self.rest.is_empty() {
            self.next_part();
        }
        self.writer.record(record);
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<std::net::SocketAddr>,
        payload: &[u8],
    ) {
        self.datagrams
            .push(self.writer.written(), receive, source, payload);
    }
}

/// As [`fill_rows`] with a timing, the rows' times filled in by a second thread while this
/// one decodes (`timed`): the wall time is about the longer of the two instead of their
/// sum. The rows are the same, bit for bit.
fn fill_records_timed(
    bytes: &[u8],
    options: &DecodeOptions,
    mut timing: Timing,
    rows: &mut [RecordRow],
) -> Filled {
    std::thread::scope(|s| {
        let (to, parts) = sync_channel::<(&mut [RecordRow], Datagrams)>(8);
        let (spare_to, spare) = channel();
        let timer = std::thread::Builder::new()
            .name("skinbox-timing".into())
            .spawn_scoped(s, move || {
                let cpu = skinbox_host::thread_cpu_ns();
                let mut source = None;
                for (rows, mut datagrams) in parts {
                    time_rows(&mut timing, &mut source, rows, &datagrams);
                    datagrams.clear();
                    let _ = spare_to.send(datagrams);
                }
                let cpu_s = skinbox_host::thread_cpu_ns().saturating_sub(cpu) as f64 * 1e-9;
                (timing, cpu_s)
            })
            .expect("a thread for the times");
        let n = TIMED_PART_ROWS.min(rows.len());
        let (first, rest) = rows.split_at_mut(n);
        let mut sink = PartSink {
            writer: RowWriter::new(first, None),
            rest,
            datagrams: Datagrams::default(),
            handed: 0,
            to,
            spare,
        };
        let report = pcap::decode_pcap_with(bytes, &options.pcap(), &mut sink);
        sink.hand_over(&mut []);
        let (written, beyond) = (sink.handed, sink.writer.beyond());
        drop(sink);
        let (timing, timing_cpu_s) = match timer.join() {
            Ok(t) => t,
            Err(panic) => std::panic::resume_unwind(panic),
        };
        Filled {
            report,
            written,
            beyond,
            timing: Some(timing),
            timing_cpu_s: Some(timing_cpu_s),
        }
    })
}

/// Fills record rows: with times, decoding and timing in two threads.
fn fill_records(
    bytes: &[u8],
    options: &DecodeOptions,
    timing: Option<Timing>,
    rows: &mut [RecordRow],
) -> Filled {
    match timing {
        Some(t) => fill_records_timed(bytes, options, t, rows),
        None => fill_rows(bytes, options, None, rows),
    }
}

/// Decodes the capture at `path` into a new array of rows (`rows_of` views its elements as
/// rows, `fill` writes them), in one pass when the sample times need no learned rate
/// (`times` off, or the rate given: the array is then allocated for the most records the
/// file can hold, and only the rows written are touched and returned), else in two as
/// `skinbox decode` does. Returns the rows and the report as JSON text.
fn decode_into<'py, E, R>(
    py: Python<'py>,
    path: &std::path::Path,
    options: &DecodeOptions,
    times: bool,
    rows_of: fn(&mut [E]) -> &mut [R],
    fill: fn(&[u8], &DecodeOptions, Option<Timing>, &mut [R]) -> Filled,
) -> PyResult<(Bound<'py, PyAny>, String)>
where
    E: numpy::Element + Send,
    R: Send,
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
    let filled = py.detach(|| {
        fill(
            &bytes,
            options,
            rate_hz.map(|r| options.timing(r)),
            rows_of(elements),
        )
    });
    let Filled {
        report,
        written,
        beyond,
        timing,
        timing_cpu_s,
    } = filled;
    let report = report.map_err(pcap_error)?;
    if beyond != 0 || exact.is_some_and(|n| n != written) {
        return Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
            "{} rows decoded, room for {capacity}",
            written as u64 + beyond
        )));
    }
    let json = report_json(&report, timing.as_ref(), timing_cpu_s)?;
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
    decode_into::<RecordElement, RecordRow>(
        py,
        &path,
        &options,
        times,
        as_record_rows,
        fill_records,
    )
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
    decode_into::<SampleElement, SampleRow>(py, &path, &options, times, as_sample_rows, fill_rows)
}
