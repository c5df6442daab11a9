//! `Reader`: a pcap or pcapng decoded in batches into one reused numpy buffer.
//!
//! A new array costs the first touch of every row (the kernel zeroing its pages, about as
//! much as decoding the record); rows rewritten into memory touched before cost a fraction
//! of it. The decoder (`pcap::decode_pcap_with`) runs in a worker thread whose
//! `RowWriter` (the rows of `read`, from the same code) writes into the reader's buffer
//! only while `__next__` waits for it: each call hands the buffer over, the worker fills it
//! and hands it back (a message each way per batch), so the buffer is never written while
//! Python code runs in the thread that iterates. With times the worker writes the rows
//! without them, a part of the buffer at a time, and a timing thread fills them in
//! (timed.rs) while the worker decodes the next part; the buffer's `Full` and `Done` go to
//! the reader through the timing thread, after the parts before them.

use crate::errors::{pcap_error, value_error, CaptureFileError};
use crate::files::DecodeOptions;
use crate::rows::RecordElement;
use crate::timed::{time_rows, Datagrams};
use numpy::{PyArray1, PyArrayMethods, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PySlice;
use skinbox_host::decoder::{DecodedRecord, RecordSink};
use skinbox_host::pcap::{self, PcapError};
use skinbox_host::rows::{RecordRow, RowWriter};
use skinbox_host::timing::Timing;
use std::sync::mpsc::{channel, sync_channel, Receiver, Sender, SyncSender};
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

/// Rows of the buffer a part holds with times: the worker hands each part, written
/// without times, to the timing thread, which fills in the times while the worker decodes
/// the next (as `read` does, files.rs).
const TIMED_PART_ROWS: usize = 4096;

/// Rows of the reader's buffer written without times, for the timing thread.
struct Part {
    start: *mut RecordRow,
    len: usize,
}

// SAFETY: as `Buffer`: the rows are the buffer's, which the reader keeps alive and reads
// only after the message that follows the part through the timing thread.
unsafe impl Send for Part {}

/// What the worker tells the timing thread.
enum Stage {
    /// Rows to time, with the datagrams before and among them.
    Part(Part, Datagrams),
    /// The buffer holds this many rows: for the reader, once every part before is timed.
    Full(usize),
    /// The file is decoded: the rows since the last `Full`, and the report.
    Done(usize, Box<Result<skinbox_host::Report, PcapError>>),
}

/// The worker's link to the timing thread.
struct ToTimer {
    to: SyncSender<Stage>,
    /// The datagrams of the current part.
    datagrams: Datagrams,
    /// Emptied datagram lists back from the timing thread.
    spare: Receiver<Datagrams>,
}

/// The worker's sink: the rows of the [`RowWriter`] that `read` uses too, written into the
/// buffer while the worker holds it, which it hands back whenever it is full. With times,
/// the rows are written without them, a part at a time, and the timing thread fills them
/// in (`timer`) before the buffer goes back to the reader.
struct ChunkSink {
    /// Holds the current part of the buffer's rows while the worker holds the buffer, else
    /// none: it then only counts the rows (the reader went away).
    writer: RowWriter<'static, RecordRow>,
    buffer: Buffer,
    /// Where in the buffer the writer's part begins.
    part_at: usize,
    /// The worker holds the buffer (a `resume` came and no message went since).
    holding: bool,
    /// The reader went away: rows are dropped, the rest of the file only decoded.
    closed: bool,
    resume: Receiver<()>,
    to: Sender<Message>,
    timer: Option<ToTimer>,
}

impl ChunkSink {
    /// Lends the writer the buffer's rows from `at`: a part with times, else the rest.
    fn lend(&mut self, at: usize) -> &'static mut [RecordRow] {
        let len = match self.timer {
            Some(_) => TIMED_PART_ROWS.min(self.buffer.len - at),
            None => self.buffer.len - at,
        };
        // SAFETY: the worker holds the buffer (see `handoff`), `at + len` is within it, and
        // the rows lent before `at` were taken back from the writer (`swap_rows`).
        let rows = unsafe { std::slice::from_raw_parts_mut(self.buffer.start.add(at), len) };
        self.part_at = at;
        self.writer.swap_rows(rows)
    }

    /// Hands the rows the writer took back to the timing thread (if any), with the
    /// datagrams kept for them.
    fn time(&mut self, rows: &'static mut [RecordRow]) {
        if let Some(t) = &mut self.timer {
            let datagrams = t.spare.try_recv().unwrap_or_default();
            let datagrams = std::mem::replace(&mut t.datagrams, datagrams);
            let part = Part {
                start: rows.as_mut_ptr(),
                len: rows.len(),
            };
            if t.to.send(Stage::Part(part, datagrams)).is_err() {
                self.closed = true;
            }
        }
    }

    /// Takes the buffer from the writer (the worker then no longer holds it), returning the
    /// rows written into it (0 where it held none); their last part goes to be timed.
    fn release(&mut self) -> usize {
        self.holding = false;
        let rows = self.writer.swap_rows(Default::default());
        let written = self.part_at + rows.len();
        self.part_at = 0;
        self.time(rows);
        written
    }

    /// Tells the reader (through the timing thread, with times) what `message` says.
    fn send(&mut self, message: Message) -> bool {
        match (&self.timer, message) {
            (Some(t), Message::Full(n)) => t.to.send(Stage::Full(n)).is_ok(),
            (_, message) => self.to.send(message).is_ok(),
        }
    }

    /// Goes on in the next part of the buffer, or hands a full buffer back (if holding
    /// one) and waits until it is given again.
    #[cold]
    fn handoff(&mut self) {
        if self.holding {
            let end = self.part_at + self.writer.written();
            if self.timer.is_some() && end < self.buffer.len {
                let rows = self.lend(end);
                self.time(rows);
                return;
            }
            let written = self.release();
            if !self.send(Message::Full(written)) {
                self.closed = true;
                return;
            }
        }
        match self.resume.recv() {
            Ok(()) => {
                // the reader sent `resume` and waits for the next message, keeping the
                // buffer alive and reading none of it until then; the rows are taken back
                // from the writer (`release`) before any message is sent.
                self.lend(0);
                self.holding = true;
            }
            Err(_) => self.closed = true,
        }
    }
}

impl RecordSink for ChunkSink {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        // a buffer given has at least one row: full here means none given yet, or a part
        // to hand on, or the buffer to hand back
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
        match &mut self.timer {
            Some(t) if !self.closed => {
                t.datagrams
                    .push(self.writer.written(), receive, source, payload)
            }
            Some(_) => {}
            None => self.writer.datagram_received(receive, source, payload),
        }
    }
}

/// The timing thread of a reader with times: fills in the times of each part and passes
/// the worker's messages on to the reader once the parts before them are timed.
fn timing_thread(
    mut timing: Timing,
    from: Receiver<Stage>,
    to: Sender<Message>,
    spare: Sender<Datagrams>,
) {
    let mut source = None;
    for stage in from {
        match stage {
            Stage::Part(part, mut datagrams) => {
                // SAFETY: the worker wrote these rows while holding the buffer and sent
                // them here before the `Full` or `Done` that returns the buffer to the
                // reader, which this thread passes on only after timing them; the reader
                // keeps the buffer alive until then.
                let rows = unsafe { std::slice::from_raw_parts_mut(part.start, part.len) };
                time_rows(&mut timing, &mut source, rows, &datagrams);
                datagrams.clear();
                let _ = spare.send(datagrams);
            }
            Stage::Full(n) => {
                let _ = to.send(Message::Full(n));
            }
            Stage::Done(n, report) => {
                let report = (*report).map(|r| report_json(&r, Some(&timing)));
                let _ = to.send(Message::Done(n, report));
            }
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
        let timer = match rate_hz {
            Some(rate) => {
                let (stage_to, stages) = sync_channel(8);
                let (spare_to, spare) = channel();
                let (timing, to) = (options.timing(rate), to.clone());
                std::thread::Builder::new()
                    .name("skinbox-timing".into())
                    .spawn(move || timing_thread(timing, stages, to, spare_to))
                    .map_err(|e| value_error(format!("the reader's timing thread: {e}")))?;
                Some(ToTimer {
                    to: stage_to,
                    datagrams: Datagrams::default(),
                    spare,
                })
            }
            None => None,
        };
        let mut sink = ChunkSink {
            writer: RowWriter::new(Default::default(), None),
            buffer: Buffer { start, len: rows },
            part_at: 0,
            holding: false,
            closed: false,
            resume: resumed,
            to,
            timer,
        };
        std::thread::Builder::new()
            .name("skinbox-reader".into())
            .spawn(move || {
                let report = pcap::decode_pcap_with(&bytes, &options.pcap(), &mut sink);
                let written = sink.release();
                match sink.timer.take() {
                    // the timing thread adds the times' summary
                    Some(t) => {
                        let _ = t.to.send(Stage::Done(written, Box::new(report)));
                    }
                    None => {
                        let report = report.map(|r| report_json(&r, None));
                        let _ = sink.to.send(Message::Done(written, report));
                    }
                }
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
