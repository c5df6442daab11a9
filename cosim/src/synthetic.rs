//! Synthetic captures for tests and benchmarks: cells in data or event mode on the ports of
//! one box, their packets played on the box's pins and batched into datagrams by the
//! reference model of the box ([`crate::reference`]), status reports included.
//!
//! The cell packets are built with the format crate's emitters; the generator also returns
//! the truth (every record with its datagram and tick) so a decoder can be checked against
//! it, after checking that the box delivered every packet with its true start tick.
//! Signals are random walks, enough to give a realistic mix of data packets and event
//! packets of one to nine channels; scenes that match the papers live in the cell models.
//!
//! Two things a box cannot be asked for are explicit edits of the box's capture: sequence
//! numbers from [`SyntheticConfig::first_sequence`] (a box that has been running a while) and
//! no status datagrams at all ([`SyntheticConfig::status_period_ticks`] 0).

use crate::error::CosimError;
use crate::line::Jitter;
use crate::reference::run_reference;
use crate::run::{SentPacket, SimSpec, PORTS_READY_CYCLE, TICK_ZERO_CYCLE};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::cell::UART_BITS_PER_PACKET;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{
    Channel, DataRepr, DatagramRepr, EventRepr, Modality, RecordRepr, TICKS_PER_SECOND, TICK_NS,
};

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SyntheticConfig {
    /// Number of cells, ids 1..=cells.
    pub cells: u16,
    /// Ports of the box; cell `i` is on port `i % ports`.
    pub ports: u8,
    /// Samples per second of every cell.
    pub sample_rate_hz: f64,
    /// Samples each cell takes.
    pub samples_per_cell: u32,
    /// Every `event_every`-th cell runs in event mode (0: none, 1: all), the rest in data mode.
    pub event_every: u16,
    /// Random seed.
    pub seed: u64,
    /// Box id.
    pub box_id: u16,
    /// Boot id in the status reports.
    pub boot_id: u32,
    /// The box's flush timeout, ticks.
    pub flush_timeout_ticks: u64,
    /// The box's status period, ticks (0: the status datagrams are removed).
    pub status_period_ticks: u64,
    /// Sequence number of the first datagram.
    pub first_sequence: u32,
    /// Box tick of the first sample (packets due before the box's ports are ready wait
    /// for them).
    pub start_tick: u64,
    /// Random walk step, times the default (more events per sample, and split samples,
    /// above 1).
    pub walk_scale: i32,
}

impl Default for SyntheticConfig {
    fn default() -> Self {
        SyntheticConfig {
            cells: 64,
            ports: 8,
            sample_rate_hz: 125.0,
            samples_per_cell: 50,
            event_every: 2,
            seed: 1,
            box_id: 1,
            boot_id: 0x5eed_0001,
            flush_timeout_ticks: 12_500,
            status_period_ticks: 12_500_000,
            first_sequence: 0,
            start_tick: 125_000_000,
            walk_scale: 1,
        }
    }
}

/// A record as generated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TruthRecord {
    /// Sequence number of its datagram.
    pub datagram_sequence: u32,
    /// Its absolute box tick.
    pub tick: u64,
    /// The record.
    pub record: RecordRepr,
}

/// A generated capture.
#[derive(Debug, Clone, Default)]
pub struct SynthCapture {
    /// Datagrams in sending order.
    pub datagrams: Vec<DatagramRepr>,
    /// Every record in sending order.
    pub truth: Vec<TruthRecord>,
    /// Data packets among them.
    pub data_packets: u64,
    /// Event packets among them.
    pub event_packets: u64,
}

impl SynthCapture {
    /// The datagrams as UDP payloads.
    pub fn payloads(&self) -> Vec<Vec<u8>> {
        self.datagrams.iter().map(|d| d.to_bytes()).collect()
    }

    /// Cell packets in the capture.
    pub fn cell_packets(&self) -> usize {
        self.truth.len()
    }
}

/// splitmix64: small, fast, good enough for test signals.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Rng(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `lo..=hi`.
    pub fn range(&mut self, lo: i32, hi: i32) -> i32 {
        lo + (self.next_u64() % (hi - lo + 1) as u64) as i32
    }
}

struct CellSim {
    id: u16,
    port: u8,
    event_mode: bool,
    value: [i32; Channel::COUNT],
    last_sent: [i32; Channel::COUNT],
    sequence: u16,
}

fn step(rng: &mut Rng, channel: Channel, v: i32, scale: i32) -> i32 {
    let d = match channel.modality() {
        Modality::Acceleration => rng.range(-4, 4),
        Modality::Force => rng.range(-1, 1),
        Modality::Proximity => rng.range(-6, 6),
        Modality::Temperature => {
            if rng.next_u64().is_multiple_of(64) {
                rng.range(-1, 1)
            } else {
                0
            }
        }
    };
    let range = channel.data_range();
    (v + d * scale).clamp(*range.start(), *range.end())
}

/// Generates a capture: the cells' packets through the reference model of a box with
/// `config.ports` ports. Fails when the box cannot be built with that configuration or
/// does not deliver every packet with its true start tick.
pub fn generate(config: &SyntheticConfig) -> Result<SynthCapture, CosimError> {
    let mut rng = Rng::new(config.seed);
    let ports = config.ports.max(1);
    let mut cells = new_cells(config, &mut rng, ports);
    let box_config = synthetic_box(config, ports);
    let mut pins = Pins::new(&box_config, ports);
    let (data_packets, event_packets) = play(config, &mut rng, &mut cells, &mut pins, ports);
    // the box runs until the last packet has left in a datagram and the status report
    // after it has counted it
    let last_ns = pins.free_ns.iter().copied().fold(0.0, f64::max) as u64;
    let drain_ns = (box_config.flush_timeout_ticks + box_config.status_period_ticks) * TICK_NS
        + crate::scene::DRAIN_NS;
    let spec = SimSpec {
        duration_ns: (last_ns + drain_ns).div_ceil(TICK_NS) * TICK_NS,
        config: box_config,
        ports: pins.pins,
        pcap: None,
        vcd: None,
        jitter: Jitter::NONE,
        host_frames: vec![],
    };
    let run = run_reference(&spec)?;
    let r = &run.report;
    if r.dropped > 0 || r.records_corrupted > 0 || r.records_mistimed > 0 {
        return Err(CosimError::BoxOutput(format!(
            "the synthetic capture lost packets: {} of {} not delivered, {} corrupted, {} mistimed",
            r.dropped, r.packets_sent, r.records_corrupted, r.records_mistimed
        )));
    }
    let mut capture = SynthCapture {
        data_packets,
        event_packets,
        ..SynthCapture::default()
    };
    // the box numbers its datagrams from 0, one after the other; the kept ones are numbered
    // on from `first_sequence`
    let kept = run
        .datagrams
        .into_iter()
        .filter(|d| config.status_period_ticks > 0 || matches!(d.body, DatagramBody::Records(_)));
    for (n, mut datagram) in kept.enumerate() {
        datagram.sequence = config.first_sequence.wrapping_add(n as u32);
        if let DatagramBody::Records(records) = &datagram.body {
            capture.truth.extend(records.iter().map(|r| TruthRecord {
                datagram_sequence: datagram.sequence,
                tick: r.tick(datagram.base_tick),
                record: *r,
            }));
        }
        capture.datagrams.push(datagram);
    }
    Ok(capture)
}

/// The cells, ids 1..=cells, with random starting values and event sequence numbers.
fn new_cells(config: &SyntheticConfig, rng: &mut Rng, ports: u8) -> Vec<CellSim> {
    (1..=config.cells)
        .map(|id| {
            let value = [
                rng.range(-8, 8),
                rng.range(-8, 8),
                256 + rng.range(-8, 8),
                rng.range(0, 2),
                rng.range(0, 2),
                rng.range(0, 2),
                rng.range(0, 450),
                rng.range(58, 64),
                0,
            ];
            CellSim {
                id,
                port: (id % u16::from(ports)) as u8,
                event_mode: config.event_every > 0 && id % config.event_every == 0,
                value,
                last_sent: value,
                sequence: rng.next_u64() as u16,
            }
        })
        .collect()
}

/// The box the capture comes from.
fn synthetic_box(config: &SyntheticConfig, ports: u8) -> BoxConfig {
    BoxConfig {
        ports: usize::from(ports),
        box_id: config.box_id,
        // the box's boot id counts the reset its run starts with
        boot_seed: config.boot_id.wrapping_sub(1),
        // with no status datagrams asked for, the box reports at its default period and
        // the reports are removed below
        status_period_ticks: match config.status_period_ticks {
            0 => BoxConfig::default().status_period_ticks,
            ticks => ticks,
        },
        flush_timeout_ticks: config.flush_timeout_ticks,
        // the synthetic cells sample on their own clocks, deaf to syncs: the box sends none
        // (a box that did would say so, and the host would time the records on its grid)
        sync_period_ticks: 0,
        ..BoxConfig::default()
    }
}

/// The packets on the box's pins: a port's packets back to back at best, the first when
/// the ports see their pins.
struct Pins {
    free_ns: Vec<f64>,
    pins: Vec<Vec<SentPacket>>,
    bit_ns: f64,
    packet_ns: f64,
}

impl Pins {
    fn new(box_config: &BoxConfig, ports: u8) -> Self {
        let bit_ns = 1e9 / box_config.baud as f64;
        Pins {
            free_ns: vec![(PORTS_READY_CYCLE * TICK_NS) as f64; usize::from(ports)],
            pins: vec![Vec::new(); usize::from(ports)],
            bit_ns,
            packet_ns: UART_BITS_PER_PACKET as f64 * bit_ns,
        }
    }

    /// Sends a packet due at box tick `tick` on `port`.
    fn send(&mut self, tick: u64, port: u8, bytes: [u8; 20]) {
        let free = &mut self.free_ns[usize::from(port)];
        let start_ns = ((tick + TICK_ZERO_CYCLE) * TICK_NS) as f64;
        let start_ns = start_ns.max(*free);
        *free = start_ns + self.packet_ns;
        self.pins[usize::from(port)].push(SentPacket {
            bytes,
            start_ns,
            bit_ns: self.bit_ns,
        });
    }
}

/// Every cell's samples onto the pins; returns the data and event packets sent.
fn play(
    config: &SyntheticConfig,
    rng: &mut Rng,
    cells: &mut [CellSim],
    pins: &mut Pins,
    ports: u8,
) -> (u64, u64) {
    let period_ticks = (TICKS_PER_SECOND as f64 / config.sample_rate_hz) as u64;
    let (mut data_packets, mut event_packets) = (0, 0);
    // Cells of one port send back to back: 50 us per 20-byte packet at 4 Mbit/s 8N1.
    let packet_ticks = 6_250;
    for k in 0..u64::from(config.samples_per_cell) {
        let t0 = config.start_tick + k * period_ticks;
        for (i, cell) in cells.iter_mut().enumerate() {
            for c in Channel::ALL {
                cell.value[c.index()] = step(rng, c, cell.value[c.index()], config.walk_scale);
            }
            let slot = (i / usize::from(ports)) as u64;
            let tick = t0 + slot * packet_ticks % period_ticks.max(1);
            if !cell.event_mode {
                if let Ok(d) = DataRepr::from_raw(cell.id, cell.value) {
                    pins.send(tick, cell.port, d.to_bytes());
                    data_packets += 1;
                }
                continue;
            }
            let events: Vec<(Channel, i32)> = Channel::ALL
                .into_iter()
                .filter(|c| {
                    let i = c.index();
                    (cell.value[i] - cell.last_sent[i]).abs() > i32::from(c.table_i_threshold_raw())
                })
                .map(|c| (c, cell.value[c.index()]))
                .collect();
            if events.is_empty() {
                continue;
            }
            for (c, v) in &events {
                cell.last_sent[c.index()] = *v;
            }
            if let Ok((first, second)) = EventRepr::split(cell.id, cell.sequence, &events) {
                pins.send(tick, cell.port, first.to_bytes());
                event_packets += 1;
                cell.sequence = cell.sequence.wrapping_add(1);
                if let Some(second) = second {
                    pins.send(tick + packet_ticks, cell.port, second.to_bytes());
                    event_packets += 1;
                    cell.sequence = cell.sequence.wrapping_add(1);
                }
            }
        }
    }
    (data_packets, event_packets)
}

/// A capture of at least `min_packets` cell packets for the host benchmarks (their
/// `BenchPayloads` are its [`SynthCapture::payloads`] and packet counts): 2,000 cells on
/// 32 ports at 125 Hz, half in data mode and half in event mode, through a box with a 1 ms
/// flush timeout, so that nearly every datagram is full (55 records).
pub fn bench_capture(min_packets: usize, seed: u64) -> Result<SynthCapture, CosimError> {
    let mut config = SyntheticConfig {
        cells: 2_000,
        ports: 32,
        samples_per_cell: 400,
        event_every: 2,
        seed,
        flush_timeout_ticks: 125_000,
        ..SyntheticConfig::default()
    };
    loop {
        let capture = generate(&config)?;
        let have = capture.cell_packets().max(1);
        if have >= min_packets {
            return Ok(capture);
        }
        // Packets grow with samples: scale once, with a margin for the random walk.
        let scale = min_packets as f64 / have as f64 * 1.05;
        config.samples_per_cell = (f64::from(config.samples_per_cell) * scale).ceil() as u32;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_protocol::datagram::MAX_RECORDS;

    #[test]
    fn the_truth_is_every_packet_sent_in_the_box_datagrams() {
        let config = SyntheticConfig {
            cells: 16,
            samples_per_cell: 20,
            first_sequence: u32::MAX - 3,
            ..SyntheticConfig::default()
        };
        let c = generate(&config).unwrap();
        // every packet the cells sent, once: the counts kept while sending
        assert_eq!(c.cell_packets() as u64, c.data_packets + c.event_packets);
        // the truth is the datagrams' records, in order, with their datagram's number
        let records: Vec<(u32, RecordRepr)> = c
            .datagrams
            .iter()
            .filter_map(|d| match &d.body {
                DatagramBody::Records(r) => Some((d.sequence, r)),
                DatagramBody::Status(_) => None,
            })
            .inspect(|(_, r)| assert!((1..=MAX_RECORDS).contains(&r.len())))
            .flat_map(|(s, r)| r.iter().map(move |r| (s, *r)))
            .collect();
        let truth: Vec<(u32, RecordRepr)> = c
            .truth
            .iter()
            .map(|t| (t.datagram_sequence, t.record))
            .collect();
        assert_eq!(records, truth);
        // numbered on from first_sequence, wrapping, one after the other
        for (n, d) in c.datagrams.iter().enumerate() {
            assert_eq!(d.sequence, config.first_sequence.wrapping_add(n as u32));
        }
        // the box reports at reset and every period: the first datagram is a status
        assert!(matches!(c.datagrams[0].body, DatagramBody::Status(_)));
        // ticks from the first sample on, in sending order per port
        assert!(c.truth.iter().all(|t| t.tick >= config.start_tick));
        // with no status period asked for, only records datagrams, still numbered densely
        let quiet = generate(&SyntheticConfig {
            status_period_ticks: 0,
            ..config
        })
        .unwrap();
        assert!(quiet
            .datagrams
            .iter()
            .all(|d| matches!(d.body, DatagramBody::Records(_))));
        assert_eq!(quiet.truth.len(), c.truth.len());
    }
}
