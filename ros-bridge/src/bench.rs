//! The MCAP write rate: box datagrams decoded, timed, turned into messages and written to
//! an MCAP file (`skinbox bench mcap`).

use crate::mcap_out::McapOutput;
use crate::sink::{RosSink, SinkSettings};
use skinbox_host::decoder::{Decoder, DecoderConfig};
use skinbox_host::sample_clock::{PathModel, Positions};
use skinbox_host::timing::Timing;
use skinbox_host::RecordSink;
use std::path::Path;
use std::time::{Duration, Instant};

/// What one run of [`bench_mcap`] measured, for one chunk size.
#[derive(Debug, Clone, serde::Serialize)]
pub struct McapBench {
    /// The recording's chunk size, bytes.
    pub chunk_bytes: u64,
    /// Cell samples written per round.
    pub samples: u64,
    /// Messages written per round.
    pub messages: u64,
    /// Bytes of the file.
    pub file_bytes: u64,
    /// Rounds; the fastest counts.
    pub rounds: u32,
    /// CPU time of the fastest round (decode, time, serialise, write, finish; this
    /// thread, user and kernel), s: the machine's other load does not count.
    pub best_cpu_s: f64,
    /// Wall time of that round, s.
    pub wall_s: f64,
    /// Samples per second of CPU time in the fastest round.
    pub samples_per_second: f64,
    /// The goal.
    pub goal_samples_per_second: f64,
    /// CPU time of the fastest round of decoding and timing alone (the host's share, no
    /// messages), s.
    pub decode_and_timing_cpu_s: f64,
    /// Samples per second of CPU time of the messages and the file alone: the fastest
    /// round less decoding and timing.
    pub ros_samples_per_second: f64,
}

/// Times every record, as [`RosSink`] does, and nothing else.
struct TimingOnly(Timing, u64);

impl RecordSink for TimingOnly {
    fn record(&mut self, record: &skinbox_host::DecodedRecord) {
        let t = self.0.record(record);
        self.1 = self.1.wrapping_add(t.sample_box_ns as u64);
    }

    fn datagram_received(
        &mut self,
        receive: Option<Duration>,
        source: Option<std::net::SocketAddr>,
        payload: &[u8],
    ) {
        self.0.datagram_received(receive, source, payload);
    }
}

fn timing() -> Timing {
    Timing::new(125.0, PathModel::bus_model(Positions::Unknown))
}

/// One round: `payloads` (received 10 us apart) decoded into an MCAP file at `path` with
/// chunks of `chunk_bytes`; its CPU and wall time, s, and what was published.
fn mcap_round(
    payloads: &[Vec<u8>],
    path: &Path,
    chunk_bytes: u64,
) -> std::io::Result<(f64, f64, crate::sink::Published)> {
    let started = Instant::now();
    let cpu = skinbox_host::thread_cpu_ns();
    let out = McapOutput::create_with_chunks(path, chunk_bytes)?;
    let mut sink = RosSink::new(timing(), SinkSettings::default(), vec![Box::new(out)]);
    let mut decoder = Decoder::new(DecoderConfig::default());
    let t0 = Duration::from_secs(1_700_000_000);
    for (i, p) in payloads.iter().enumerate() {
        sink.datagram_received(Some(t0 + Duration::from_micros(10 * i as u64)), None, p);
        decoder.push_datagram(p, &mut sink);
    }
    let published = sink.finish()?;
    let s = skinbox_host::thread_cpu_ns().saturating_sub(cpu) as f64 * 1e-9;
    Ok((s, started.elapsed().as_secs_f64(), published))
}

/// Decodes `payloads` (received 10 us apart) into an MCAP file at `path`, `rounds` times
/// for each of `chunk_sizes` (bytes; the sizes taking turns within a round, so the
/// machine's changing load falls on each alike), then times decoding and timing alone.
/// One result per chunk size, in their order.
pub fn bench_mcap(
    payloads: &[Vec<u8>],
    path: &Path,
    rounds: u32,
    chunk_sizes: &[u64],
) -> std::io::Result<Vec<McapBench>> {
    let mut best = vec![(f64::INFINITY, 0.0); chunk_sizes.len()];
    let mut published = crate::sink::Published::default();
    let mut file_bytes = vec![0; chunk_sizes.len()];
    for _ in 0..rounds.max(1) {
        for (i, chunk) in chunk_sizes.iter().enumerate() {
            let (cpu, wall, p) = mcap_round(payloads, path, *chunk)?;
            published = p;
            file_bytes[i] = std::fs::metadata(path).map_or(0, |m| m.len());
            if cpu < best[i].0 {
                best[i] = (cpu, wall);
            }
        }
    }
    let mut host = f64::INFINITY;
    for _ in 0..rounds.max(1) {
        let cpu = skinbox_host::thread_cpu_ns();
        let mut sink = TimingOnly(timing(), 0);
        let mut decoder = Decoder::new(DecoderConfig::default());
        let t0 = Duration::from_secs(1_700_000_000);
        for (i, p) in payloads.iter().enumerate() {
            sink.datagram_received(Some(t0 + Duration::from_micros(10 * i as u64)), None, p);
            decoder.push_datagram(p, &mut sink);
        }
        std::hint::black_box(sink.1);
        host = host.min(skinbox_host::thread_cpu_ns().saturating_sub(cpu) as f64 * 1e-9);
    }
    let p = published;
    Ok(chunk_sizes
        .iter()
        .zip(best)
        .zip(file_bytes)
        .map(|((chunk, (best, wall)), file_bytes)| McapBench {
            chunk_bytes: *chunk,
            samples: p.samples,
            messages: p.samples_messages + p.status_messages + p.activity_messages,
            file_bytes,
            rounds: rounds.max(1),
            best_cpu_s: best,
            wall_s: wall,
            samples_per_second: p.samples as f64 / best,
            goal_samples_per_second: 5e6,
            decode_and_timing_cpu_s: host,
            ros_samples_per_second: p.samples as f64 / (best - host).max(1e-9),
        })
        .collect())
}
