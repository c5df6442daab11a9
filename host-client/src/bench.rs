//! Benchmarks (not tests): decoding speed in memory, and the highest lossless rate of the
//! live path on loopback.

use crate::decoder::{DecodedRecord, Decoder, DecoderConfig, RecordSink};
use crate::live::{self, CaptureLimits, CaptureStats};
use crate::pcap::PcapFrameWriter;
use crate::replay::{self, Pacing, ReplaySummary};
use crate::report::Report;
use serde::Serialize;
use std::collections::BTreeMap;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

/// Result of [`bench_decode`].
#[derive(Debug, Clone, Serialize)]
pub struct DecodeBench {
    /// Cell packets decoded per round.
    pub cell_packets: u64,
    /// Data packets among them.
    pub data_packets: u64,
    /// Event packets among them.
    pub event_packets: u64,
    /// Datagrams per round.
    pub datagrams: u64,
    /// Payload bytes per round.
    pub bytes: u64,
    /// Rounds run.
    pub rounds: u32,
    /// Fastest round, in seconds of thread CPU time.
    pub best_cpu_s: f64,
    /// Cell packets per second of one core, fastest round.
    pub packets_per_second: f64,
    /// CPU time per cell packet, fastest round.
    pub ns_per_packet: f64,
    /// Goal: 10 M cell packets/s on one core (100x the original driver's ~10 us per packet).
    pub goal_packets_per_second: f64,
}

/// A capture to benchmark with: its datagrams as UDP payloads, and the cell packets in it.
#[derive(Debug, Clone, Default)]
pub struct BenchPayloads {
    /// UDP payloads in sending order.
    pub payloads: Vec<Vec<u8>>,
    /// Data packets among their records.
    pub data_packets: u64,
    /// Event packets among their records.
    pub event_packets: u64,
}

impl BenchPayloads {
    /// Cell packets in the capture.
    pub fn cell_packets(&self) -> u64 {
        self.data_packets + self.event_packets
    }
}

/// Decodes an in-memory capture `rounds` times with a fresh decoder each time and reports
/// the fastest round.
pub fn bench_decode(capture: &BenchPayloads, rounds: u32) -> DecodeBench {
    let payloads = &capture.payloads;
    let bytes = payloads.iter().map(|p| p.len() as u64).sum();
    let mut best = f64::INFINITY;
    let mut decoded = 0;
    for _ in 0..rounds.max(1) {
        let mut decoder = Decoder::new(DecoderConfig::default());
        let cpu = crate::thread_cpu_ns();
        for p in payloads {
            decoder.push_datagram(p, &mut ());
        }
        let s = crate::thread_cpu_ns().saturating_sub(cpu) as f64 * 1e-9;
        decoded = decoder.records();
        best = best.min(s);
    }
    DecodeBench {
        cell_packets: decoded,
        data_packets: capture.data_packets,
        event_packets: capture.event_packets,
        datagrams: payloads.len() as u64,
        bytes,
        rounds: rounds.max(1),
        best_cpu_s: best,
        packets_per_second: decoded as f64 / best,
        ns_per_packet: best * 1e9 / decoded.max(1) as f64,
        goal_packets_per_second: 10e6,
    }
}

/// One replay of payloads to a capture on loopback.
#[derive(Debug, Clone)]
pub struct LoopbackRun {
    /// What the sender did.
    pub sent: ReplaySummary,
    /// What the receiver counted.
    pub received: CaptureStats,
    /// Kernel receive buffer granted.
    pub recv_buffer_bytes: usize,
    /// The decoder's report.
    pub report: Report,
    /// Decoded records, when asked to keep them.
    pub records: Vec<DecodedRecord>,
}

struct Keep(Option<Vec<DecodedRecord>>);

impl RecordSink for Keep {
    fn record(&mut self, record: &DecodedRecord) {
        if let Some(v) = self.0.as_mut() {
            v.push(*record);
        }
    }
}

/// Why a loopback run failed.
#[derive(Debug, thiserror::Error)]
pub enum LoopbackError {
    /// A socket or thread failed.
    #[error("loopback: {0}")]
    Io(#[from] std::io::Error),
    /// The capture failed.
    #[error("loopback capture: {0}")]
    Capture(#[from] live::CaptureError),
}

/// How the receiver of a loopback run receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReceiverOptions {
    /// Datagrams per receive call.
    pub batch: usize,
    /// Wait after draining the socket ([`CaptureLimits::coalesce`]).
    pub coalesce: Duration,
    /// Receive buffer asked for, in bytes.
    pub recv_buffer_bytes: usize,
}

impl Default for ReceiverOptions {
    fn default() -> Self {
        ReceiverOptions {
            batch: live::DEFAULT_BATCH,
            coalesce: live::DEFAULT_COALESCE,
            recv_buffer_bytes: live::DEFAULT_RECV_BUFFER_BYTES,
        }
    }
}

/// Replays `payloads` from 127.0.0.1 with `pacing` to [`live::run_capture`] listening on
/// 127.0.0.1:0 in its own thread and tokio runtime. The capture stops when every payload
/// arrived, or `drain` after the sender finished.
pub fn loopback_run(
    payloads: &[&[u8]],
    pacing: Pacing,
    keep_records: bool,
    drain: Duration,
) -> Result<LoopbackRun, LoopbackError> {
    loopback_run_with(
        payloads,
        pacing,
        keep_records,
        drain,
        ReceiverOptions::default(),
    )
}

/// [`loopback_run`] with the receiver's batch and receive buffer.
pub fn loopback_run_with(
    payloads: &[&[u8]],
    pacing: Pacing,
    keep_records: bool,
    drain: Duration,
    receiver_options: ReceiverOptions,
) -> Result<LoopbackRun, LoopbackError> {
    let expected = payloads.len() as u64;
    let (addr_tx, addr_rx) = std::sync::mpsc::channel::<Result<(SocketAddr, usize), String>>();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let receiver = std::thread::Builder::new()
        .name("skinbox-rx".into())
        .spawn(move || -> Result<_, LoopbackError> {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()?;
            rt.block_on(async move {
                let loopback = SocketAddr::from(([127, 0, 0, 1], 0));
                let (socket, granted) =
                    match live::bind_udp(loopback, receiver_options.recv_buffer_bytes) {
                        Ok(s) => s,
                        Err(e) => {
                            let _ = addr_tx.send(Err(e.to_string()));
                            return Err(e.into());
                        }
                    };
                let _ = addr_tx.send(Ok((socket.local_addr()?, granted)));
                let mut decoder = Decoder::new(DecoderConfig::default());
                let mut sink = Keep(keep_records.then(Vec::new));
                let stats = live::run_capture(
                    &socket,
                    &mut decoder,
                    &mut sink,
                    None::<&mut PcapFrameWriter<std::io::Sink>>,
                    CaptureLimits {
                        max_datagrams: Some(expected),
                        progress_every: Duration::from_secs(3600),
                        batch: receiver_options.batch,
                        coalesce: receiver_options.coalesce,
                    },
                    async {
                        let _ = stop_rx.await;
                    },
                    &mut |_, _| {},
                )
                .await?;
                Ok((stats, decoder.report(), sink.0.unwrap_or_default(), granted))
            })
        })?;
    let (to, _) = addr_rx
        .recv()
        .map_err(|e| std::io::Error::other(e.to_string()))?
        .map_err(std::io::Error::other)?;
    let socket = UdpSocket::bind(SocketAddr::from(([127, 0, 0, 1], 0)))?;
    let stop = AtomicBool::new(false);
    let sent = replay::replay(
        &socket,
        to,
        payloads.iter().map(|p| (Duration::ZERO, *p)),
        pacing,
        &stop,
    );
    // The receiver stops by itself when everything arrived; otherwise after `drain`.
    let deadline = Instant::now() + drain;
    while !receiver.is_finished() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(5));
    }
    let _ = stop_tx.send(());
    let (received, report, records, granted) = receiver
        .join()
        .map_err(|_| std::io::Error::other("capture thread panicked"))??;
    Ok(LoopbackRun {
        sent,
        received,
        recv_buffer_bytes: granted,
        report,
        records,
    })
}

/// One rate step of [`bench_live`].
#[derive(Debug, Clone, Serialize)]
pub struct LiveStep {
    /// Datagrams per receive call of the receiver.
    pub batch: usize,
    /// The receiver's wait after draining the socket, in microseconds.
    pub coalesce_us: u64,
    /// Receive buffer the kernel granted (as Linux reports it: twice the usable size).
    pub recv_buffer_bytes: usize,
    /// Records per second asked for.
    pub target_records_per_second: f64,
    /// Records per second the sender achieved.
    pub sent_records_per_second: f64,
    /// Datagrams sent.
    pub datagrams_sent: u64,
    /// Datagrams received.
    pub datagrams_received: u64,
    /// Records decoded.
    pub records_received: u64,
    /// Datagrams the decoder found missing.
    pub datagrams_missing: u64,
    /// Receive calls that returned datagrams.
    pub receive_calls: u64,
    /// Receiver CPU (receiving and decoding) per datagram, in nanoseconds.
    pub receiver_cpu_ns_per_datagram: f64,
    /// Receiver CPU (receiving and decoding) per record, in nanoseconds.
    pub receiver_cpu_ns_per_record: f64,
    /// Nothing lost.
    pub lossless: bool,
}

/// What [`bench_live`] runs.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveBenchConfig {
    /// Record rates to try, rising; a receiver stops rising at its first loss.
    pub rates: Vec<f64>,
    /// Seconds per step.
    pub step_s: f64,
    /// Receivers to compare, as datagrams per receive call (1: one call per datagram) and
    /// wait after draining (0: wake for every datagram).
    pub receivers: Vec<(usize, Duration)>,
    /// Receive buffer for the rate steps, in bytes.
    pub recv_buffer_bytes: usize,
    /// Receive buffers to try, rising, at `buffer_rate` with the last receiver: the
    /// smallest lossless one is reported. Empty: no sweep.
    pub recv_buffers: Vec<usize>,
    /// Record rate of the buffer sweep.
    pub buffer_rate: f64,
}

impl LiveBenchConfig {
    /// Cell packets the capture of [`bench_live`] needs: one step at the highest rate.
    pub fn packets_needed(&self) -> usize {
        let max_rate = self
            .rates
            .iter()
            .chain([&self.buffer_rate])
            .cloned()
            .fold(0.0, f64::max);
        (max_rate * self.step_s).ceil() as usize + 1
    }
}

impl Default for LiveBenchConfig {
    fn default() -> Self {
        LiveBenchConfig {
            rates: vec![500e3, 1e6, 2e6, 3e6, 4.5e6, 6e6, 7e6, 8e6],
            step_s: 1.0,
            receivers: vec![(1, Duration::ZERO), (live::DEFAULT_BATCH, Duration::ZERO)],
            recv_buffer_bytes: live::DEFAULT_RECV_BUFFER_BYTES,
            recv_buffers: Vec::new(),
            buffer_rate: 4.5e6,
        }
    }
}

/// Result of [`bench_live`].
#[derive(Debug, Clone, Serialize)]
pub struct LiveBench {
    /// Receive buffer asked for in the rate steps.
    pub recv_buffer_asked_bytes: usize,
    /// Each rate step of each receiver.
    pub steps: Vec<LiveStep>,
    /// Per receiver (`batch/coalesce_us`): the highest achieved rate of a lossless step.
    pub max_lossless_records_per_second: BTreeMap<String, f64>,
    /// The buffer sweep's steps (batch and rate fixed).
    pub buffer_steps: Vec<LiveStep>,
    /// The smallest receive buffer asked for that stayed lossless in the sweep.
    pub smallest_lossless_recv_buffer_bytes: Option<usize>,
    /// Goal: 4.5 M records/s, a full Gigabit link.
    pub goal_records_per_second: f64,
    /// Goal: receiver CPU per record, in nanoseconds.
    pub goal_cpu_ns_per_record: f64,
}

/// Datagrams the bench's sender sends back to back before it sleeps: at 82,000
/// datagrams/s a burst every 0.4 ms, 47 KB, far less than any receive buffer tried.
pub const SENDER_BURST: usize = 32;

/// One step: `datagrams` payloads at `rate` records/s to a receiver.
fn live_step(
    payloads: &[Vec<u8>],
    per_datagram: f64,
    rate: f64,
    step_s: f64,
    receiver: ReceiverOptions,
) -> Result<LiveStep, LoopbackError> {
    let datagrams_per_second = rate / per_datagram;
    let n = ((datagrams_per_second * step_s).ceil() as usize).clamp(1, payloads.len());
    let slice: Vec<&[u8]> = payloads[..n].iter().map(|p| p.as_slice()).collect();
    let run = loopback_run_with(
        &slice,
        Pacing::Bursts {
            datagrams_per_second,
            burst: SENDER_BURST,
        },
        false,
        Duration::from_millis(500),
        receiver,
    )?;
    let records_sent: u64 = slice
        .iter()
        .filter_map(|p| skinbox_protocol::datagram::Datagram::new_checked(*p).ok())
        .map(|d| d.records().count() as u64)
        .sum();
    let lossless = run.received.datagrams == run.sent.datagrams
        && run.sent.datagrams == n as u64
        && run.report.losses.datagrams_missing == 0;
    Ok(LiveStep {
        batch: receiver.batch,
        coalesce_us: receiver.coalesce.as_micros() as u64,
        recv_buffer_bytes: run.recv_buffer_bytes,
        target_records_per_second: rate,
        sent_records_per_second: records_sent as f64 / run.sent.wall_s.max(1e-9),
        datagrams_sent: run.sent.datagrams,
        datagrams_received: run.received.datagrams,
        records_received: run.report.records,
        datagrams_missing: run.report.losses.datagrams_missing,
        receive_calls: run.received.receive_calls,
        receiver_cpu_ns_per_datagram: run.received.cpu_ns_per_datagram(),
        receiver_cpu_ns_per_record: run.received.cpu_ns_per_record(),
        lossless,
    })
}

/// Replays the datagrams of `capture` (nearly all full: 55 records) on loopback at rising
/// record rates, `step_s` seconds each, in bursts of [`SENDER_BURST`], to each receiver in
/// turn, until a step loses datagrams or the rates run out; then, if asked, the receive
/// buffer sweep.
///
/// `capture` holds at least [`LiveBenchConfig::packets_needed`] cell packets.
pub fn bench_live(
    config: &LiveBenchConfig,
    capture: &BenchPayloads,
) -> Result<LiveBench, LoopbackError> {
    let payloads = &capture.payloads;
    let per_datagram = capture.cell_packets() as f64 / payloads.len().max(1) as f64;
    let mut steps = Vec::new();
    let mut best = BTreeMap::new();
    for &(batch, coalesce) in &config.receivers {
        let receiver = ReceiverOptions {
            batch,
            coalesce,
            recv_buffer_bytes: config.recv_buffer_bytes,
        };
        let name = format!("{batch}/{}", coalesce.as_micros());
        best.insert(name.clone(), 0.0f64);
        for &rate in &config.rates {
            let step = live_step(payloads, per_datagram, rate, config.step_s, receiver)?;
            let lossless = step.lossless;
            if lossless {
                let b = best.entry(name.clone()).or_insert(0.0);
                *b = b.max(step.sent_records_per_second);
            }
            steps.push(step);
            if !lossless {
                break;
            }
        }
    }
    let mut buffer_steps = Vec::new();
    let mut smallest = None;
    let (batch, coalesce) = config
        .receivers
        .last()
        .copied()
        .unwrap_or((live::DEFAULT_BATCH, live::DEFAULT_COALESCE));
    for &bytes in &config.recv_buffers {
        let receiver = ReceiverOptions {
            batch,
            coalesce,
            recv_buffer_bytes: bytes,
        };
        let step = live_step(
            payloads,
            per_datagram,
            config.buffer_rate,
            config.step_s,
            receiver,
        )?;
        if step.lossless && smallest.is_none() {
            smallest = Some(bytes);
        }
        buffer_steps.push(step);
    }
    Ok(LiveBench {
        recv_buffer_asked_bytes: config.recv_buffer_bytes,
        steps,
        max_lossless_records_per_second: best,
        buffer_steps,
        smallest_lossless_recv_buffer_bytes: smallest,
        goal_records_per_second: 4.5e6,
        goal_cpu_ns_per_record: 50.0,
    })
}
