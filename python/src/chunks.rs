//! `Reader`: a pcap or pcapng decoded in batches into one reused numpy buffer.
//!
//! A new array costs the first touch of every row (the kernel zeroing its pages, about as
//! much as decoding the record); rows rewritten into memory touched before cost a fraction
//! of it. The decoder (`pcap::decode_pcap_with`) runs in a worker thread that writes rows
//! into the reader's buffer only while `__next__` waits for it: each call hands the buffer
//! over, the worker fills it and hands it back (a message each way per batch), so the
//! buffer is never written while Python code runs in the thread that iterates.

use crate::errors::{pcap_error, value_error, CaptureFileError};
use crate::files::DecodeOptions;
use crate::rows::RecordElement;
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PySlice;
use skinbox_host::decoder::{DecodedRecord, RecordSink};
use skinbox_host::pcap::{self, PcapError};
use skinbox_host::rows::{RecordRow, UNTIMED};
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

/// The buffer's rows, for the worker: written only between a `resume` received and the
/// next message sent.
struct Rows {
    start: *mut RecordRow,
    len: usize,
}

// SAFETY: the reader keeps the buffer alive while the worker may write it (see `Reader`),
// and hands it over through channels, which order the writes before the reads.
unsafe impl Send for Rows {}

/// The worker's sink: rows into the buffer, handing it back whenever it is full.
struct ChunkSink {
    rows: Rows,
    written: usize,
    /// The worker may write the buffer (a `resume` came and no message went since).
    holding: bool,
    /// The reader went away: rows are dropped, the rest of the file only decoded.
    closed: bool,
    timing: Option<Timing>,
    resume: Receiver<()>,
    to: Sender<Message>,
}

impl ChunkSink {
    /// Hands a full buffer back (if holding one) and waits until it is given again.
    #[cold]
    fn handoff(&mut self) {
        if self.holding {
            self.holding = false;
            if self.to.send(Message::Full(self.written)).is_err() {
                self.closed = true;
                return;
            }
        }
        match self.resume.recv() {
            Ok(()) => {
                self.holding = true;
                self.written = 0;
            }
            Err(_) => self.closed = true,
        }
    }
}

impl RecordSink for ChunkSink {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        let times = match &mut self.timing {
            Some(t) => t.record(record),
            None => UNTIMED,
        };
        if !self.holding || self.written == self.rows.len {
            if self.closed {
                return;
            }
            self.handoff();
            if self.closed {
                return;
            }
        }
        // SAFETY: `written < len` (a buffer given has at least one row), and the worker
        // holds the buffer: the reader waits for the next message and keeps it alive.
        unsafe {
            self.rows
                .start
                .add(self.written)
                .write(RecordRow::new(record, &times))
        };
        self.written += 1;
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<std::net::SocketAddr>,
        payload: &[u8],
    ) {
        if let Some(t) = &mut self.timing {
            t.datagram_received(receive, source, payload);
        }
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
            rows: Rows { start, len: rows },
            written: 0,
            holding: false,
            closed: false,
            timing: rate_hz.map(|r| options.timing(r)),
            resume: resumed,
            to: to.clone(),
        };
        std::thread::Builder::new()
            .name("skinbox-reader".into())
            .spawn(move || {
                let report = pcap::decode_pcap_with(&bytes, &options.pcap(), &mut sink);
                let written = if sink.holding { sink.written } else { 0 };
                let report = report.map(|r| report_json(&r, sink.timing.as_ref()));
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
