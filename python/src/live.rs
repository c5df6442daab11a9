//! `Capture`: a live capture in its own thread, its records handed over in batches.
//!
//! The receiving thread runs the CLI's capture loop (`skinbox_host::live::run_capture`)
//! with a sink that writes each record's row, without times, into the current batch's
//! buffer and keeps each datagram the timing reads; a full batch (or one older than the
//! batch interval) goes over a channel to the timing thread, which fills in the rows'
//! sample and host times (the sample clocks are most of the cost of a record: in their own
//! thread they leave the receiving one the decoder's share) and hands the batch on; it
//! becomes a numpy array without a copy. The Python side waits for batches without the
//! GIL.

use crate::errors::{value_error, CaptureError};
use crate::files::DecodeOptions;
use crate::rows::RecordElement;
use crate::timed::{time_rows, Datagrams};
use numpy::PyArray1;
use pyo3::prelude::*;
use skinbox_host::decoder::{DecodedRecord, RecordSink};
use skinbox_host::live::{self, CaptureLimits, CaptureStats};
use skinbox_host::pcap::PcapFrameWriter;
use skinbox_host::rows::RecordRow;
use skinbox_host::timing::Timing;
use skinbox_host::{Decoder, DecoderConfig};
use std::cell::RefCell;
use std::net::SocketAddr;
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{channel, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// What the receiving thread tells the consumer.
enum Message {
    /// A batch of rows.
    Batch(Vec<RecordElement>),
    /// Running counts, as JSON.
    Progress(String),
    /// The capture ended: the full report as JSON, or why it failed.
    Done(Result<String, String>),
}

/// A batch on its way to the timing thread: rows without times and the datagrams.
#[derive(Default)]
struct Untimed {
    rows: Vec<RecordElement>,
    datagrams: Datagrams,
}

/// The datagram lists of a timed batch, emptied, for the receiving thread to reuse (memory
/// written before costs less than new memory).
type Spare = Datagrams;

/// What the receiving thread tells the timing thread: as [`Message`], rows untimed.
enum Stage {
    Batch(Untimed),
    Progress(String),
    Done(Result<String, String>),
}

/// Rows of the current batch; full batches go to the timing thread.
struct Batcher {
    batch: Untimed,
    batch_records: usize,
    /// The timing thread times the rows: keep the datagrams for it.
    timed: bool,
    to: Sender<Stage>,
    spare: Receiver<Spare>,
    records: u64,
}

impl Batcher {
    fn flush(&mut self) {
        if self.batch.rows.is_empty() && self.batch.datagrams.is_empty() {
            return;
        }
        let datagrams = self.spare.try_recv().unwrap_or_default();
        let batch = std::mem::replace(
            &mut self.batch,
            Untimed {
                rows: Vec::with_capacity(self.batch_records),
                datagrams,
            },
        );
        // A consumer that went away stops wanting rows: nothing to do about it here.
        let _ = self.to.send(Stage::Batch(batch));
    }
}

/// The timing thread: times each batch (with `timing`) and hands it on; adds the host
/// times' summary to the final report.
fn timing_thread(
    mut timing: Option<Timing>,
    from: Receiver<Stage>,
    to: Sender<Message>,
    spare: Sender<Spare>,
) {
    let mut source = None;
    let cpu = skinbox_host::thread_cpu_ns();
    for stage in from {
        let message = match stage {
            Stage::Batch(mut batch) => {
                if let Some(t) = &mut timing {
                    let rows = crate::rows::as_record_rows(&mut batch.rows);
                    time_rows(t, &mut source, rows, &batch.datagrams);
                }
                // the datagrams' memory back to the receiving thread, to fill again
                batch.datagrams.clear();
                let _ = spare.send(batch.datagrams);
                if batch.rows.is_empty() {
                    continue;
                }
                Message::Batch(batch.rows)
            }
            Stage::Progress(json) => Message::Progress(json),
            Stage::Done(Ok(json)) => {
                let mut report: serde_json::Value = serde_json::from_str(&json).unwrap_or_default();
                if let Some(map) = report.as_object_mut() {
                    let summary = timing.as_ref().map(|t| t.summary()).unwrap_or_default();
                    map.insert(
                        "host_times".into(),
                        serde_json::to_value(summary).unwrap_or_default(),
                    );
                    map.insert(
                        "exchanges_unused".into(),
                        timing.as_ref().map_or(0, |t| t.exchanges_unused()).into(),
                    );
                    // the timing thread's CPU time (the receiving thread's is `capture`'s)
                    let cpu_s = skinbox_host::thread_cpu_ns().saturating_sub(cpu) as f64 * 1e-9;
                    map.insert("timing_cpu_s".into(), cpu_s.into());
                }
                Message::Done(Ok(report.to_string()))
            }
            Stage::Done(Err(e)) => Message::Done(Err(e)),
        };
        if to.send(message).is_err() {
            return;
        }
    }
}

/// The sink of the capture loop; the progress callback shares the batcher.
struct BatchSink(Rc<RefCell<Batcher>>);

impl RecordSink for BatchSink {
    #[inline]
    fn record(&mut self, record: &DecodedRecord) {
        let mut b = self.0.borrow_mut();
        let row = RecordRow::new(record, &skinbox_host::rows::UNTIMED);
        b.batch.rows.push(RecordElement(row));
        b.records += 1;
        if b.batch.rows.len() >= b.batch_records {
            b.flush();
        }
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<SocketAddr>,
        payload: &[u8],
    ) {
        let mut b = self.0.borrow_mut();
        if b.timed {
            let b = &mut b.batch;
            b.datagrams.push(b.rows.len(), receive, source, payload);
        }
    }
}

/// Settings of one capture.
struct Settings {
    listen: SocketAddr,
    claim: Option<String>,
    batch_records: usize,
    batch_interval: Duration,
    recv_buffer: usize,
    exchange: Duration,
    duration: Option<Duration>,
    count: Option<u64>,
    pcap: Option<std::path::PathBuf>,
    options: DecodeOptions,
    times: bool,
}

fn running_json(stats: &CaptureStats, decoder: &Decoder) -> String {
    serde_json::json!({
        "running": true,
        "datagrams": stats.datagrams,
        "records": decoder.records(),
        "datagrams_missing": decoder.datagrams_missing(),
        "bad_input": decoder.bad_input_total(),
        "wall_s": stats.wall_s,
        "cpu_s": stats.cpu_s,
    })
    .to_string()
}

/// The receiving thread: binds (and claims), reports its address, captures until stopped.
fn capture_thread(
    settings: Settings,
    started: std::sync::mpsc::Sender<Result<SocketAddr, String>>,
    to: Sender<Message>,
    stop: Arc<tokio::sync::Notify>,
) {
    let runtime = match tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            let _ = started.send(Err(format!("tokio runtime: {e}")));
            return;
        }
    };
    let rate_hz = settings
        .options
        .sample_rate_hz
        .unwrap_or(skinbox_host::decoder::ASSUMED_SAMPLE_RATE_HZ);
    let timing = settings.times.then(|| settings.options.timing(rate_hz));
    let (stage_to, stage_from) = channel();
    let (spare_to, spare) = channel();
    let timer = match std::thread::Builder::new()
        .name("skinbox-timing".into())
        .spawn(move || timing_thread(timing, stage_from, to, spare_to))
    {
        Ok(t) => t,
        Err(e) => {
            let _ = started.send(Err(format!("the timing thread: {e}")));
            return;
        }
    };
    let to = stage_to;
    let done = to.clone();
    let result = runtime.block_on(async move {
        let (socket, granted) = live::bind_udp(settings.listen, settings.recv_buffer)
            .map_err(|e| format!("binding {}: {e}", settings.listen))?;
        let stop_read_ticks = Arc::new(AtomicBool::new(false));
        let (socket, claimed, read_ticks) = match &settings.claim {
            Some(box_addr) => match live::claim(socket, box_addr) {
                Ok(c) => {
                    let read_ticks = (!settings.exchange.is_zero()).then(|| {
                        live::send_read_ticks(
                            c.sender,
                            c.box_addr,
                            c.exchange.ack.box_id,
                            settings.exchange,
                            stop_read_ticks.clone(),
                        )
                    });
                    (c.socket, Some(c.exchange), read_ticks)
                }
                Err(e) => {
                    let message = format!("claim {e}");
                    let _ = started.send(Err(message.clone()));
                    return Err(message);
                }
            },
            None => (socket, None, None),
        };
        let local = socket.local_addr().map_err(|e| e.to_string())?;
        let _ = started.send(Ok(local));
        let mut recorder = match &settings.pcap {
            Some(path) => Some(
                std::fs::File::create(path)
                    .map_err(|e| format!("{}: {e}", path.display()))
                    .and_then(|f| {
                        PcapFrameWriter::new(std::io::BufWriter::new(f)).map_err(|e| e.to_string())
                    })?,
            ),
            None => None,
        };
        let batcher = Rc::new(RefCell::new(Batcher {
            batch: Untimed {
                rows: Vec::with_capacity(settings.batch_records),
                ..Untimed::default()
            },
            batch_records: settings.batch_records,
            timed: settings.times,
            to: to.clone(),
            spare,
            records: 0,
        }));
        let mut sink = BatchSink(batcher.clone());
        let mut decoder = Decoder::new(DecoderConfig {
            sample_rate_hz: settings.options.sample_rate_hz,
            ..DecoderConfig::default()
        });
        // stream datagrams that arrived while the claim waited for its acknowledgement
        let passed_over = claimed.as_ref().map_or(0, |e| e.passed_over.len() as u64);
        if let Some(e) = &claimed {
            for (from, payload) in &e.passed_over {
                sink.datagram_received(None, Some(*from), payload);
                decoder.push_datagram_from(Some(*from), payload, &mut sink);
            }
        }
        let duration = settings.duration;
        let shutdown = async move {
            match duration {
                Some(d) => {
                    tokio::select! {
                        _ = tokio::time::sleep(d) => {}
                        _ = stop.notified() => {}
                    }
                }
                None => stop.notified().await,
            }
        };
        let progress_to = to.clone();
        let progress_batcher = batcher.clone();
        let stats = live::run_capture(
            &socket,
            &mut decoder,
            &mut sink,
            recorder.as_mut(),
            CaptureLimits {
                max_datagrams: settings.count,
                progress_every: settings.batch_interval,
                ..CaptureLimits::default()
            },
            shutdown,
            &mut |s, d| {
                progress_batcher.borrow_mut().flush();
                let _ = progress_to.send(Stage::Progress(running_json(s, d)));
            },
        )
        .await
        .map_err(|e| e.to_string())?;
        stop_read_ticks.store(true, Ordering::Relaxed);
        let read_ticks_sent = read_ticks.map(|t| t.join().unwrap_or(0));
        if let Some(w) = recorder {
            use std::io::Write;
            w.finish()
                .map_err(|e| e.to_string())?
                .flush()
                .map_err(|e| e.to_string())?;
        }
        batcher.borrow_mut().flush();
        let mut report = decoder.report();
        report.frames.frames = stats.datagrams + passed_over;
        report.frames.udp_payloads = stats.datagrams + passed_over;
        report.frames.capture_span_s = stats.wall_s;
        report.host = Some(skinbox_host::report::HostCost {
            cpu_s: stats.cpu_s,
            wall_s: stats.wall_s,
            cpu_ns_per_packet: stats.cpu_ns_per_record(),
        });
        let b = batcher.borrow();
        let json = serde_json::json!({
            "running": false,
            "capture": stats,
            "recv_buffer_bytes": live::usable_recv_buffer(granted),
            "claim": claimed.as_ref().map(|e| serde_json::json!({
                "result": e.ack.result.name(),
                "attempts": e.attempts,
                "rtt_us": e.rtt_ns as f64 / 1000.0,
                "datagrams_before_capture": passed_over,
                "datagrams_dropped": e.dropped,
            })),
            "rows": b.records,
            "report": report,
            "read_ticks_sent": read_ticks_sent,
        });
        Ok(json.to_string())
    });
    // (the timing thread adds the host times' summary)
    let _ = done.send(Stage::Done(result));
    drop(done);
    let _ = timer.join();
}

/// A live capture: an iterator of record arrays (the dtype of `read`).
#[pyclass(module = "skinbox")]
pub struct Capture {
    address: SocketAddr,
    messages: Mutex<Receiver<Message>>,
    stop: Arc<tokio::sync::Notify>,
    thread: Mutex<Option<std::thread::JoinHandle<()>>>,
    report: Mutex<Option<String>>,
    error: Mutex<Option<String>>,
}

impl Capture {
    fn lock_err<T>(_: T) -> PyErr {
        CaptureError::new_err("the capture's state is poisoned by a failed thread")
    }

    fn take(&self, message: Message) -> PyResult<Option<Vec<RecordElement>>> {
        match message {
            Message::Batch(rows) => Ok(Some(rows)),
            Message::Progress(json) => {
                *self.report.lock().map_err(Self::lock_err)? = Some(json);
                Ok(None)
            }
            Message::Done(Ok(json)) => {
                *self.report.lock().map_err(Self::lock_err)? = Some(json);
                Ok(None)
            }
            Message::Done(Err(e)) => {
                *self.error.lock().map_err(Self::lock_err)? = Some(e);
                Ok(None)
            }
        }
    }

    fn join(&self, py: Python<'_>) -> PyResult<()> {
        let thread = self.thread.lock().map_err(Self::lock_err)?.take();
        if let Some(t) = thread {
            py.detach(|| t.join())
                .map_err(|_| CaptureError::new_err("the capture thread panicked"))?;
        }
        Ok(())
    }
}

#[pymethods]
impl Capture {
    /// Listens on `listen` ("ip:port"; port 0 picks one, see `address`) and, with `claim`
    /// (a box's command address), asks that box to stream here first and maps its time by
    /// read-tick exchanges every `exchange_ms`. A batch is handed over when it holds
    /// `batch_records` records or `batch_ms` passed; the capture stops on `close()`, after
    /// `duration_ms` or after `count` datagrams. `times=False` leaves the sample and host
    /// times out of the rows (as `read(times=False)`), which costs most of the receiving
    /// thread's time.
    #[new]
    #[pyo3(signature = (listen="0.0.0.0:54091", claim=None, batch_records=65536, batch_ms=100, sample_rate_hz=None, recv_buffer=live::DEFAULT_RECV_BUFFER_BYTES, exchange_ms=100, duration_ms=None, count=None, pcap=None, cells_per_bus=None, synced=false, times=true))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        listen: &str,
        claim: Option<String>,
        batch_records: usize,
        batch_ms: u64,
        sample_rate_hz: Option<f64>,
        recv_buffer: usize,
        exchange_ms: u64,
        duration_ms: Option<u64>,
        count: Option<u64>,
        pcap: Option<std::path::PathBuf>,
        cells_per_bus: Option<u16>,
        synced: bool,
        times: bool,
    ) -> PyResult<Self> {
        let listen: SocketAddr = listen
            .parse()
            .map_err(|e| value_error(format!("listen {listen}: {e}")))?;
        if batch_records == 0 || batch_ms == 0 {
            return Err(value_error("batch_records and batch_ms must be at least 1"));
        }
        let options = DecodeOptions {
            sample_rate_hz,
            udp_port: None,
            cells_per_bus,
            synced,
        };
        options.check()?;
        let settings = Settings {
            listen,
            claim,
            batch_records,
            batch_interval: Duration::from_millis(batch_ms),
            recv_buffer,
            exchange: Duration::from_millis(exchange_ms),
            duration: duration_ms.map(Duration::from_millis),
            count,
            pcap,
            options,
            times,
        };
        let (started_tx, started_rx) = channel();
        let (to, messages) = channel();
        let stop = Arc::new(tokio::sync::Notify::new());
        let thread = {
            let stop = stop.clone();
            std::thread::Builder::new()
                .name("skinbox-capture".into())
                .spawn(move || capture_thread(settings, started_tx, to, stop))
                .map_err(|e| CaptureError::new_err(e.to_string()))?
        };
        let address = match py.detach(move || started_rx.recv()) {
            Ok(Ok(address)) => address,
            Ok(Err(e)) => {
                let _ = py.detach(|| thread.join());
                return Err(CaptureError::new_err(e));
            }
            Err(_) => {
                let _ = py.detach(|| thread.join());
                return Err(CaptureError::new_err(
                    "the capture thread ended before it started",
                ));
            }
        };
        Ok(Capture {
            address,
            messages: Mutex::new(messages),
            stop,
            thread: Mutex::new(Some(thread)),
            report: Mutex::new(None),
            error: Mutex::new(None),
        })
    }

    /// The address the capture listens on.
    #[getter]
    fn address(&self) -> String {
        self.address.to_string()
    }

    /// The running counts while the capture runs (datagrams, records, datagrams missing,
    /// bad input), the full report (losses, box counters, host times) once it stopped;
    /// None before the first batch interval.
    #[getter]
    fn report(&self, py: Python<'_>) -> PyResult<Option<Py<PyAny>>> {
        let report = self.report.lock().map_err(Self::lock_err)?.clone();
        report.map(|r| crate::json_to_python(py, &r)).transpose()
    }

    fn __iter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    /// The next batch of records; waits without the GIL. Raises KeyboardInterrupt on
    /// Ctrl-C (the capture stops first) and StopIteration once the capture stopped and
    /// every batch was taken.
    fn __next__<'py>(
        &self,
        py: Python<'py>,
    ) -> PyResult<Option<Bound<'py, PyArray1<RecordElement>>>> {
        loop {
            let got = py.detach(|| {
                self.messages
                    .lock()
                    .map(|m| m.recv_timeout(Duration::from_millis(50)))
                    .map_err(|_| ())
            });
            let got = got.map_err(Self::lock_err)?;
            match got {
                Ok(message) => {
                    if let Some(rows) = self.take(message)? {
                        return Ok(Some(PyArray1::from_vec(py, rows)));
                    }
                    // progress reports can come faster than the wait's timeout: Ctrl-C is
                    // looked for after each of them too
                    if let Err(e) = py.check_signals() {
                        self.close(py)?;
                        return Err(e);
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    if let Err(e) = py.check_signals() {
                        self.close(py)?;
                        return Err(e);
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    self.join(py)?;
                    if let Some(e) = self.error.lock().map_err(Self::lock_err)?.take() {
                        return Err(CaptureError::new_err(e));
                    }
                    return Ok(None);
                }
            }
        }
    }

    /// Stops the capture and waits for its thread; the batches not yet taken stay there
    /// for the iterator, and `report` is the full report.
    fn close(&self, py: Python<'_>) -> PyResult<()> {
        self.stop.notify_one();
        self.join(py)?;
        // the final report came with the last message: take every message now, keep the
        // batches for the iterator
        let messages = self.messages.lock().map_err(Self::lock_err)?;
        let mut kept = Vec::new();
        while let Ok(m) = messages.try_recv() {
            match m {
                Message::Batch(rows) => kept.push(rows),
                other => {
                    drop(self.take(other)?);
                }
            }
        }
        drop(messages);
        if !kept.is_empty() {
            // put the batches back in order behind a fresh channel
            let (to, rx) = channel();
            for rows in kept {
                let _ = to.send(Message::Batch(rows));
            }
            *self.messages.lock().map_err(Self::lock_err)? = rx;
        }
        if let Some(e) = self.error.lock().map_err(Self::lock_err)?.clone() {
            return Err(CaptureError::new_err(e));
        }
        Ok(())
    }

    fn __enter__(slf: Py<Self>) -> Py<Self> {
        slf
    }

    #[pyo3(signature = (*_args))]
    fn __exit__(&self, py: Python<'_>, _args: &Bound<'_, pyo3::types::PyTuple>) -> PyResult<bool> {
        self.close(py)?;
        Ok(false)
    }

    fn __repr__(&self) -> String {
        format!("skinbox.Capture(listen='{}')", self.address)
    }
}

impl Drop for Capture {
    fn drop(&mut self) {
        self.stop.notify_one();
    }
}
