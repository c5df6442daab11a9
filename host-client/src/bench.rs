//! Benchmarks (not tests): decoding speed in memory, and the highest lossless rate of the
//! live path on loopback.

use crate::decoder::{DecodedRecord, Decoder, DecoderConfig, RecordSink};
use crate::live::{self, CaptureLimits, CaptureStats};
use crate::pcap::PcapFrameWriter;
use crate::replay::{self, Pacing, ReplaySummary};
use crate::report::Report;
use crate::synth::{self, SynthConfig};
use serde::Serialize;
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

/// A capture of at least `min_packets` cell packets, half the cells in data mode and half
/// in event mode, as UDP payloads.
pub fn realistic_payloads(min_packets: usize, seed: u64) -> (Vec<Vec<u8>>, synth::SynthCapture) {
    let mut config = SynthConfig {
        cells: 2_000,
        ports: 32,
        samples_per_cell: 400,
        event_every: 2,
        seed,
        status_every: 800,
        ..SynthConfig::default()
    };
    loop {
        let capture = synth::generate(&config);
        let have = capture.cell_packets().max(1);
        if have >= min_packets {
            return (capture.payloads(), capture);
        }
        // Packets grow with samples: scale once, with a margin for the random walk.
        let scale = min_packets as f64 / have as f64 * 1.05;
        config.samples_per_cell = (f64::from(config.samples_per_cell) * scale).ceil() as u32;
    }
}

/// Decodes an in-memory capture of at least `min_packets` cell packets `rounds` times with
/// a fresh decoder each time and reports the fastest round.
pub fn bench_decode(min_packets: usize, rounds: u32) -> DecodeBench {
    let (payloads, capture) = realistic_payloads(min_packets, 7);
    let bytes = payloads.iter().map(|p| p.len() as u64).sum();
    let mut best = f64::INFINITY;
    let mut decoded = 0;
    for _ in 0..rounds.max(1) {
        let mut decoder = Decoder::new(DecoderConfig::default());
        let cpu = crate::thread_cpu_ns();
        for p in &payloads {
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

/// Replays `payloads` from 127.0.0.1 with `pacing` to [`live::run_capture`] listening on
/// 127.0.0.1:0 in its own thread and tokio runtime. The capture stops when every payload
/// arrived, or `drain` after the sender finished.
pub fn loopback_run(
    payloads: &[&[u8]],
    pacing: Pacing,
    keep_records: bool,
    drain: Duration,
) -> Result<LoopbackRun, LoopbackError> {
    let expected = payloads.len() as u64;
    let (addr_tx, addr_rx) = std::sync::mpsc::channel::<Result<(SocketAddr, usize), String>>();
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let receiver = std::thread::spawn(move || -> Result<_, LoopbackError> {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        rt.block_on(async move {
            let loopback = SocketAddr::from(([127, 0, 0, 1], 0));
            let (socket, granted) = match live::bind_udp(loopback, live::DEFAULT_RECV_BUFFER_BYTES)
            {
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
                },
                async {
                    let _ = stop_rx.await;
                },
                &mut |_, _| {},
            )
            .await?;
            Ok((stats, decoder.report(), sink.0.unwrap_or_default(), granted))
        })
    });
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
    /// Receiver CPU per record, in nanoseconds.
    pub receiver_cpu_ns_per_record: f64,
    /// Nothing lost.
    pub lossless: bool,
}

/// Result of [`bench_live`].
#[derive(Debug, Clone, Serialize)]
pub struct LiveBench {
    /// Receive buffer the kernel granted.
    pub recv_buffer_bytes: usize,
    /// Each rate step.
    pub steps: Vec<LiveStep>,
    /// The highest achieved rate of a lossless step.
    pub max_lossless_records_per_second: f64,
    /// Goal: 4.5 M records/s, a full Gigabit link.
    pub goal_records_per_second: f64,
}

/// Replays full datagrams (55 records) on loopback at rising record rates, `step_s`
/// seconds each, until a step loses datagrams or the rates run out.
pub fn bench_live(rates: &[f64], step_s: f64) -> Result<LiveBench, LoopbackError> {
    let max_rate = rates.iter().cloned().fold(0.0, f64::max);
    let (payloads, capture) = realistic_payloads((max_rate * step_s).ceil() as usize + 1, 11);
    let per_datagram = capture.cell_packets() as f64 / payloads.len().max(1) as f64;
    let mut steps = Vec::new();
    let mut best = 0.0f64;
    let mut granted = 0;
    for &rate in rates {
        let datagrams_per_second = rate / per_datagram;
        let n = ((datagrams_per_second * step_s).ceil() as usize).clamp(1, payloads.len());
        let slice: Vec<&[u8]> = payloads[..n].iter().map(|p| p.as_slice()).collect();
        let run = loopback_run(
            &slice,
            Pacing::Rate {
                datagrams_per_second,
            },
            false,
            Duration::from_millis(500),
        )?;
        granted = run.recv_buffer_bytes;
        let records_sent: u64 = slice
            .iter()
            .filter_map(|p| skinbox_protocol::datagram::Datagram::new_checked(*p).ok())
            .map(|d| d.records().count() as u64)
            .sum();
        let sent_rate = records_sent as f64 / run.sent.wall_s.max(1e-9);
        let lossless = run.received.datagrams == run.sent.datagrams
            && run.sent.datagrams == n as u64
            && run.report.losses.datagrams_missing == 0;
        steps.push(LiveStep {
            target_records_per_second: rate,
            sent_records_per_second: sent_rate,
            datagrams_sent: run.sent.datagrams,
            datagrams_received: run.received.datagrams,
            records_received: run.report.records,
            datagrams_missing: run.report.losses.datagrams_missing,
            receiver_cpu_ns_per_record: run.received.cpu_s * 1e9 / run.report.records.max(1) as f64,
            lossless,
        });
        if !lossless {
            break;
        }
        best = best.max(sent_rate);
    }
    Ok(LiveBench {
        recv_buffer_bytes: granted,
        steps,
        max_lossless_records_per_second: best,
        goal_records_per_second: 4.5e6,
    })
}
