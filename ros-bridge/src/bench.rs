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

/// What one run of [`bench_mcap`] measured.
#[derive(Debug, Clone, serde::Serialize)]
pub struct McapBench {
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
}

/// Decodes `payloads` (received 10 us apart) into an MCAP file at `path`, `rounds` times.
pub fn bench_mcap(payloads: &[Vec<u8>], path: &Path, rounds: u32) -> std::io::Result<McapBench> {
    let mut best = f64::INFINITY;
    let mut wall = 0.0;
    let mut published = Default::default();
    for _ in 0..rounds.max(1) {
        let started = Instant::now();
        let cpu = skinbox_host::thread_cpu_ns();
        let out = McapOutput::create(path)?;
        let timing = Timing::new(125.0, PathModel::bus_model(Positions::Unknown));
        let mut sink = RosSink::new(timing, SinkSettings::default(), vec![Box::new(out)]);
        let mut decoder = Decoder::new(DecoderConfig::default());
        let t0 = Duration::from_secs(1_700_000_000);
        for (i, p) in payloads.iter().enumerate() {
            sink.datagram_received(Some(t0 + Duration::from_micros(10 * i as u64)), None, p);
            decoder.push_datagram(p, &mut sink);
        }
        published = sink.finish()?;
        let s = skinbox_host::thread_cpu_ns().saturating_sub(cpu) as f64 * 1e-9;
        if s < best {
            best = s;
            wall = started.elapsed().as_secs_f64();
        }
    }
    let p: crate::sink::Published = published;
    Ok(McapBench {
        samples: p.samples,
        messages: p.samples_messages + p.status_messages + p.activity_messages,
        file_bytes: std::fs::metadata(path).map_or(0, |m| m.len()),
        rounds: rounds.max(1),
        best_cpu_s: best,
        wall_s: wall,
        samples_per_second: p.samples as f64 / best,
        goal_samples_per_second: 5e6,
    })
}
