//! The MCAP write rate: box datagrams decoded, timed, turned into messages and written to
//! an MCAP file (`skinbox bench mcap`), as `skinbox decode --mcap` does it (the messages and
//! the file on a thread of their own: [`RosSink::pipelined`]) and all on one thread
//! ([`RosSink::new`]).

use crate::mcap_out::McapOutput;
use crate::sink::{Output, RosSink, SinkSettings};
use skinbox_host::decoder::{Decoder, DecoderConfig};
use skinbox_host::sample_clock::{PathModel, Positions};
use skinbox_host::timing::Timing;
use skinbox_host::RecordSink;
use std::path::Path;
use std::time::{Duration, Instant};

/// The fastest and the slowest of the rounds, s.
#[derive(Debug, Clone, Copy, serde::Serialize)]
pub struct Range {
    /// The fastest round.
    pub min: f64,
    /// The slowest round.
    pub max: f64,
}

impl Default for Range {
    fn default() -> Self {
        Range {
            min: f64::INFINITY,
            max: 0.0,
        }
    }
}

impl Range {
    fn add(&mut self, v: f64) {
        self.min = self.min.min(v);
        self.max = self.max.max(v);
    }
}

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
    /// Rounds of each way.
    pub rounds: u32,
    /// The pipelined writer (as `decode --mcap`): wall time of the rounds (create,
    /// decode, time, serialise, write, finish), s.
    pub pipelined_wall_s: Range,
    /// Its CPU time (both threads, user and kernel) of the rounds, s.
    pub pipelined_cpu_s: Range,
    /// The decoding thread's share of it (decode, time, gather the messages), s.
    pub pipelined_decoding_thread_cpu_s: Range,
    /// Samples per second of wall time in its fastest round.
    pub pipelined_samples_per_second: f64,
    /// All on one thread: CPU time of that thread (user and kernel) of the rounds, s.
    pub one_thread_cpu_s: Range,
    /// Its wall time of the rounds, s.
    pub one_thread_wall_s: Range,
    /// Samples per second of CPU time in its fastest round.
    pub one_thread_samples_per_second: f64,
    /// The two recordings (pipelined and one thread) byte for byte the same.
    pub files_identical: bool,
    /// The goal, samples per second of wall time.
    pub goal_samples_per_second: f64,
    /// CPU time of decoding and timing alone (the host's share, no messages) of the
    /// rounds, s.
    pub decode_and_timing_cpu_s: Range,
    /// Samples per second of CPU time of the messages and the file alone: the fastest
    /// one-thread round less the fastest round of decoding and timing.
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

/// `payloads`, received 10 us apart, into `sink`.
fn decode_into(payloads: &[Vec<u8>], sink: &mut impl RecordSink) {
    let mut decoder = Decoder::new(DecoderConfig::default());
    let t0 = Duration::from_secs(1_700_000_000);
    for (i, p) in payloads.iter().enumerate() {
        sink.datagram_received(Some(t0 + Duration::from_micros(10 * i as u64)), None, p);
        decoder.push_datagram(p, sink);
    }
}

/// What one round took, s.
struct Round {
    /// CPU time: the process's (both threads) when pipelined, else this thread's.
    cpu: f64,
    /// This thread's CPU time.
    thread_cpu: f64,
    wall: f64,
    published: crate::sink::Published,
}

/// One round: `payloads` decoded into an MCAP file at `path` with chunks of
/// `chunk_bytes`, pipelined or on this thread.
fn mcap_round(
    payloads: &[Vec<u8>],
    path: &Path,
    chunk_bytes: u64,
    pipelined: bool,
) -> std::io::Result<Round> {
    let cpu_ns = if pipelined {
        skinbox_host::process_cpu_ns
    } else {
        skinbox_host::thread_cpu_ns
    };
    // The last round's file goes first, untimed: truncating 145 MB of page cache in the
    // round would cost its thread ~10-15 ms of kernel time, which a new recording does not.
    match std::fs::remove_file(path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
        _ => {}
    }
    let started = Instant::now();
    let cpu = cpu_ns();
    let thread_cpu = skinbox_host::thread_cpu_ns();
    let out: Vec<Box<dyn Output + Send>> =
        vec![Box::new(McapOutput::create_with_chunks(path, chunk_bytes)?)];
    let mut sink = if pipelined {
        RosSink::pipelined(timing(), SinkSettings::default(), out)?
    } else {
        RosSink::new(timing(), SinkSettings::default(), out)
    };
    decode_into(payloads, &mut sink);
    let published = sink.finish()?;
    Ok(Round {
        cpu: cpu_ns().saturating_sub(cpu) as f64 * 1e-9,
        thread_cpu: skinbox_host::thread_cpu_ns().saturating_sub(thread_cpu) as f64 * 1e-9,
        wall: started.elapsed().as_secs_f64(),
        published,
    })
}

/// Decodes `payloads` (received 10 us apart) into an MCAP file at `path` (and, all on one
/// thread, at its name in a directory named as `path` with the extension `one-thread`), `rounds` times for each of `chunk_sizes` (bytes)
/// and each way, the sizes and the ways taking turns within a round so that the machine's
/// changing load falls on each alike; then times decoding and timing alone. One result
/// per chunk size, in their order.
pub fn bench_mcap(
    payloads: &[Vec<u8>],
    path: &Path,
    rounds: u32,
    chunk_sizes: &[u64],
) -> std::io::Result<Vec<McapBench>> {
    // The same file name (the bag metadata names the file), in a directory of its own.
    let one_dir = path.with_extension("one-thread");
    std::fs::create_dir_all(&one_dir)?;
    let one_path = one_dir.join(path.file_name().unwrap_or_default());
    let n = chunk_sizes.len();
    let (mut p_wall, mut p_cpu) = (vec![Range::default(); n], vec![Range::default(); n]);
    let (mut o_wall, mut o_cpu) = (vec![Range::default(); n], vec![Range::default(); n]);
    let mut p_decoding = vec![Range::default(); n];
    let mut host = Range::default();
    let mut published = crate::sink::Published::default();
    let mut file_bytes = vec![0; n];
    let mut identical = vec![true; n];
    for round in 0..rounds.max(1) {
        for (i, chunk) in chunk_sizes.iter().enumerate() {
            let r = mcap_round(payloads, path, *chunk, true)?;
            p_wall[i].add(r.wall);
            p_cpu[i].add(r.cpu);
            p_decoding[i].add(r.thread_cpu);
            published = r.published;
            file_bytes[i] = std::fs::metadata(path).map_or(0, |m| m.len());
            let r = mcap_round(payloads, &one_path, *chunk, false)?;
            o_wall[i].add(r.wall);
            o_cpu[i].add(r.cpu);
            if round == 0 {
                identical[i] = std::fs::read(path)? == std::fs::read(&one_path)?;
            }
        }
        let cpu = skinbox_host::thread_cpu_ns();
        let mut sink = TimingOnly(timing(), 0);
        decode_into(payloads, &mut sink);
        std::hint::black_box(sink.1);
        host.add(skinbox_host::thread_cpu_ns().saturating_sub(cpu) as f64 * 1e-9);
    }
    let _ = std::fs::remove_dir_all(&one_dir);
    let p = published;
    Ok((0..n)
        .map(|i| McapBench {
            chunk_bytes: chunk_sizes[i],
            samples: p.samples,
            messages: p.samples_messages + p.status_messages + p.activity_messages,
            file_bytes: file_bytes[i],
            rounds: rounds.max(1),
            pipelined_wall_s: p_wall[i],
            pipelined_cpu_s: p_cpu[i],
            pipelined_decoding_thread_cpu_s: p_decoding[i],
            pipelined_samples_per_second: p.samples as f64 / p_wall[i].min,
            one_thread_cpu_s: o_cpu[i],
            one_thread_wall_s: o_wall[i],
            one_thread_samples_per_second: p.samples as f64 / o_cpu[i].min,
            files_identical: identical[i],
            goal_samples_per_second: 5e6,
            decode_and_timing_cpu_s: host,
            ros_samples_per_second: p.samples as f64 / (o_cpu[i].min - host.min).max(1e-9),
        })
        .collect())
}
