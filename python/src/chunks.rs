//! `Reader`: a pcap or pcapng decoded in batches into one reused numpy buffer.
//!
//! A new array costs the first touch of every row (the kernel zeroing its pages, about as
//! much as decoding the record); rows rewritten into memory touched before cost a fraction
//! of it. The decoder (`pcap::decode_pcap_with`) runs in a worker thread whose
//! `RowWriter` (the rows of `read`, from the same code) writes into the reader's buffer
//! only while `__next__` waits for it: each call hands the buffer over, the worker fills it
//! and hands it back (a message each way per batch), so the buffer is never written while
//! Python code runs in the thread that iterates.

use crate::errors::{pcap_error, value_error, CaptureFileError};
use crate::files::DecodeOptions;
use crate::rows::RecordElement;
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PySlice;
use skinbox_host::decoder::{DecodedRecord, RecordSink};
use skinbox_host::pcap::{self, PcapError};
use skinbox_host::rows::{RecordRow, RowWriter};
use skinbox_host::timing::Timing;
use std::sync::mpsc::{channel, Receiver, Sender};
use std::sync::Mutex;
use std::time::Duration;

/// What the worker tells the reader.
enum Message {
    /// The buffer holds this many rows (it is full) and is the reader's again.
    Full(usize),
    /// The file is decoded: the rows written since the last `Full` (the buffer is the
    /// reader's again), and the report as JSON text or the reason it failed.
    Done(usize, Result<String, PcapError>),
}

/// The reader's buffer, for the worker: lent to its writer only between a `resume`
/// received and the next message sent.
struct Buffer {
    start: *mut RecordRow,
    len: usize,
}

// SAFETY: the reader keeps the buffer alive while the worker may write it (see `Reader`),
// and hands it over through channels, which order the writes before the reads.
unsafe impl Send for Buffer {}

/// The worker's sink: the rows of the [`RowWriter`] that `read` uses too, written into the
/// buffer while the worker holds it, which it hands back whenever it is full.
struct ChunkSink {
    /// Holds the buffer's rows while the worker holds the buffer, else none: it then only
    /// counts the rows (the reader went away), their times still estimated for the report.
    writer: RowWriter<'static, RecordRow>,
    buffer: Buffer,
    /// The worker holds the buffer (a `resume` came and no message went since).
    holding: bool,
    /// The reader went away: rows are dropped, the rest of the file only decoded.
    closed: bool,
    resume: Receiver<()>,
    to: Sender<Message>,
}

impl ChunkSink {
    /// Takes the buffer from the writer (the worker then no longer holds it), returning the
    /// rows written into it (0 where it held none).
    fn release(&mut self) -> usize {
        self.holding = false;
        self.writer.retarget(Default::default())
    }

    /// Hands a full buffer back (if holding one) and waits until it is given again.
    #[cold]
    fn handoff(&mut self) {
        if self.holding {
            let written = self.release();
            if self.to.send(Message::Full(written)).is_err() {
                self.closed = true;
                return;
            }
        }
        match self.resume.recv() {
            Ok(()) => {
                // SAFETY: the reader sent `resume` and waits for the next message, keeping
                // the buffer alive and reading none of it until then; the slice is
                // released (`release`) before any message is sent.
                let rows =
                    unsafe { std::slice::from_raw_parts_mut(self.buffer.start, self.buffer.len) };
                self.writer.retarget(rows);
                self.holding = true;
            }
            Err(_) => self.closed = true,
        }
    }
}

impl RecordSink for ChunkSink {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        // a buffer given has at least one row: full here means none given yet, or it needs
        // handing back
        if self.writer.is_full() && !self.closed {
            self.handoff();
        }
        self.writer.record(record);
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<std::net::SocketAddr>,
        payload: &[u8],
    ) {
        self.writer.datagram_received(receive, source, payload);
    }
}

/// The channels of a reader whose worker has not ended.
struct Running {
    resume: Sender<()>,
    messages: Receiver<Message>,
}

/// State behind the reader's lock.
enum State {
    Running(Running),
    /// The file is decoded; the report as JSON text.
    Ended(String),
    /// The worker failed (or its reason was raised already).
    Failed(Option<PyErr>),
}

/// A pcap or pcapng decoded in batches of at most `rows` records into one buffer: each
/// batch is a view of the buffer, overwritten by the next.
///
/// Safety of the buffer: the worker writes it only between a `resume` the reader sends in
/// `__next__` and the message `__next__` then waits for (holding the lock, so no other
/// `__next__` runs meanwhile), and the reader holds the array (`buffer`) for as long as it
/// lives; a dropped reader drops `resume`, after which the worker writes nothing.
#[pyclass(module = "skinbox._native")]
pub struct Reader {
    buffer: Py<PyArray1<RecordElement>>,
    state: Mutex<State>,
}

/// The report with the host-time summary, as JSON text.
fn report_json(report: &skinbox_host::Report, timing: Option<&Timing>) -> String {
    let mut value = serde_json::to_value(report).unwrap_or_default();
    if let Ok(times) = serde_json::to_value(timing.map(|t| t.summary()).unwrap_or_default()) {
        value["host_times"] = times;
    }
    value.to_string()
}

#[pymethods]
impl Reader {
    /// Reads the file at `path` (raising as `read` does for one that cannot be read) and,
    /// for sample times without `sample_rate_hz`, learns the rate in a first pass; then
    /// decodes in a worker as the batches are taken.
    #[new]
    #[pyo3(signature = (path, rows=65536, sample_rate_hz=None, udp_port=None, cells_per_bus=None, synced=false, times=true))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        path: std::path::PathBuf,
        rows: usize,
        sample_rate_hz: Option<f64>,
        udp_port: Option<u16>,
        cells_per_bus: Option<u16>,
        synced: bool,
        times: bool,
    ) -> PyResult<Self> {
        if rows == 0 {
            return Err(value_error("rows must be at least 1"));
        }
        let options = DecodeOptions {
            sample_rate_hz,
            udp_port,
            cells_per_bus,
            synced,
        };
        options.check()?;
        let bytes = py
            .detach(|| crate::mapped::map_file(&path))
            .map_err(pcap_error)?;
        let rate_hz = match (times, sample_rate_hz) {
            (false, _) => None,
            (true, Some(rate)) => Some(rate),
            (true, None) => Some(
                py.detach(|| pcap::decode_pcap_with(&bytes, &options.pcap(), &mut ()))
                    .map_err(pcap_error)?
                    .sample_rate_hz,
            ),
        };
        let buffer = PyArray1::<RecordElement>::zeros(py, [rows], false);
        let start = buffer.data().cast::<RecordRow>();
        let (resume, resumed) = channel();
        let (to, messages) = channel();
        let mut sink = ChunkSink {
            writer: RowWriter::new(Default::default(), rate_hz.map(|r| options.timing(r))),
            buffer: Buffer { start, len: rows },
            holding: false,
            closed: false,
            resume: resumed,
            to: to.clone(),
        };
        std::thread::Builder::new()
            .name("skinbox-reader".into())
            .spawn(move || {
                let report = pcap::decode_pcap_with(&bytes, &options.pcap(), &mut sink);
                let written = sink.release();
                let report = report.map(|r| report_json(&r, sink.writer.timing()));
                let _ = to.send(Message::Done(written, report));
            })
            .map_err(|e| value_error(format!("the reader's thread: {e}")))?;
        Ok(Reader {
            buffer: buffer.unbind(),
            state: Mutex::new(State::Running(Running { resume, messages })),
        })
    }

    /// The number of rows a batch holds at most.
    #[getter]
    fn rows(&self, py: Python<'_>) -> usize {
        self.buffer.bind(py).len()
    }

    /// The report (as `read`'s, JSON text) once every batch was taken, else None.
    #[getter]
    fn report_json(&self) -> PyResult<Option<String>> {
        let state = self.lock()?;
        Ok(match &*state {
            State::Ended(json) => Some(json.clone()),
            _ => None,
        })
    }

    fn __iter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    /// The next batch: a view of the first rows of the buffer, valid until the next call
    /// (which overwrites them). None (StopIteration) after the last.
    fn __next__<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        let mut state = self.lock()?;
        let State::Running(running) = &mut *state else {
            return match &mut *state {
                State::Failed(error) => match error.take() {
                    Some(e) => Err(e),
                    None => Ok(None),
                },
                _ => Ok(None),
            };
        };
        let message = py.detach(move || {
            // A worker that ended without wanting the buffer has sent its last message.
            let _ = running.resume.send(());
            running.messages.recv()
        });
        let written = match message {
            Ok(Message::Full(n)) => n,
            Ok(Message::Done(n, Ok(json))) => {
                *state = State::Ended(json);
                n
            }
            Ok(Message::Done(_, Err(e))) => {
                *state = State::Failed(None);
                return Err(pcap_error(e));
            }
            Err(_) => {
                *state = State::Failed(None);
                return Err(CaptureFileError::new_err("the reader's thread failed"));
            }
        };
        if written == 0 {
            return Ok(None);
        }
        let view = self
            .buffer
            .bind(py)
            .get_item(PySlice::new(py, 0, written as isize, 1))?;
        Ok(Some(view))
    }

    fn __repr__(&self, py: Python<'_>) -> String {
        format!("skinbox.Reader(rows={})", self.rows(py))
    }
}

impl Reader {
    /// The state, or an error while another thread takes a batch: waiting for the lock
    /// with the GIL held would deadlock with that thread, which takes the GIL back after
    /// waiting for its batch without it.
    fn lock(&self) -> PyResult<std::sync::MutexGuard<'_, State>> {
        self.state.try_lock().map_err(|e| match e {
            std::sync::TryLockError::WouldBlock => pyo3::exceptions::PyRuntimeError::new_err(
                "the reader is taking a batch in another thread",
            ),
            std::sync::TryLockError::Poisoned(_) => {
                CaptureFileError::new_err("the reader's state is poisoned")
            }
        })
    }
}
