//! Synthetic captures for tests and benchmarks: cells in data or event mode on the ports of
//! one box, their packets batched into datagrams the way the box does, with status reports.
//!
//! Everything is built with the format crate's emitters; the generator also returns the
//! truth (every record with its datagram and tick) so a decoder can be checked against it.
//! Signals are random walks, enough to give a realistic mix of data packets and event
//! packets of one to nine channels; scenes that match the papers live in the cell models.

use skinbox_protocol::datagram::{DatagramBody, FLAG_FLUSH_TIMEOUT, MAX_RECORDS};
use skinbox_protocol::status::PortCounter;
use skinbox_protocol::{
    Channel, DataRepr, DatagramRepr, EventRepr, Modality, PortCounters, RecordRepr, StatusRepr,
    TICKS_PER_SECOND,
};

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthConfig {
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
    /// A status datagram after every this many records datagrams (0: none).
    pub status_every: u32,
    /// Sequence number of the first datagram.
    pub first_sequence: u32,
    /// Box tick of the first sample.
    pub start_tick: u64,
    /// Random walk step, times the default (more events per sample, and split samples,
    /// above 1).
    pub walk_scale: i32,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            cells: 64,
            ports: 8,
            sample_rate_hz: 125.0,
            samples_per_cell: 50,
            event_every: 2,
            seed: 1,
            box_id: 1,
            boot_id: 0x5eed_0001,
            status_every: 100,
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

struct Batcher {
    config: SynthConfig,
    capture: SynthCapture,
    pending: Vec<(u64, RecordRepr)>,
    sequence: u32,
    records_datagrams: u32,
    records_sent: u32,
    good: Vec<u32>,
    now: u64,
}

impl Batcher {
    fn push(&mut self, tick: u64, port: u8, packet: [u8; 20]) {
        self.good[usize::from(port)] = self.good[usize::from(port)].wrapping_add(1);
        self.pending.push((
            tick,
            RecordRepr {
                port,
                flags: 0,
                tick_offset: 0,
                cell_packet: packet,
            },
        ));
        self.now = tick;
        if self.pending.len() == MAX_RECORDS {
            self.flush(0);
        }
    }

    fn flush(&mut self, flags: u8) {
        if self.pending.is_empty() {
            return;
        }
        let base = self.pending[0].0;
        let sequence = self.sequence;
        let records: Vec<RecordRepr> = self
            .pending
            .drain(..)
            .map(|(tick, r)| {
                let r = RecordRepr {
                    tick_offset: (tick as i64 - base as i64) as i32,
                    ..r
                };
                self.capture.truth.push(TruthRecord {
                    datagram_sequence: sequence,
                    tick,
                    record: r,
                });
                r
            })
            .collect();
        self.records_sent = self.records_sent.wrapping_add(records.len() as u32);
        self.capture.datagrams.push(DatagramRepr {
            box_id: self.config.box_id,
            port_count: self.config.ports,
            flags,
            sequence,
            base_tick: base,
            body: DatagramBody::Records(records),
        });
        self.sequence = self.sequence.wrapping_add(1);
        self.records_datagrams += 1;
        if self.config.status_every > 0
            && self
                .records_datagrams
                .is_multiple_of(self.config.status_every)
        {
            self.status();
        }
    }

    fn status(&mut self) {
        let ports = self
            .good
            .iter()
            .map(|g| {
                let mut c = PortCounters::default();
                c.set(PortCounter::PacketsGood, *g);
                c
            })
            .collect();
        self.capture.datagrams.push(DatagramRepr {
            box_id: self.config.box_id,
            port_count: self.config.ports,
            flags: 0,
            sequence: self.sequence,
            base_tick: self.now,
            body: DatagramBody::Status(StatusRepr {
                boot_id: self.config.boot_id,
                datagrams_sent: self.records_datagrams,
                records_sent: self.records_sent,
                first_port: 0,
                ports,
            }),
        });
        self.sequence = self.sequence.wrapping_add(1);
    }
}

/// Generates a capture.
pub fn generate(config: &SynthConfig) -> SynthCapture {
    let mut rng = Rng::new(config.seed);
    let ports = config.ports.max(1);
    let mut cells: Vec<CellSim> = (1..=config.cells)
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
        .collect();
    let period_ticks = (TICKS_PER_SECOND as f64 / config.sample_rate_hz) as u64;
    // Cells of one port send back to back: 50 us per 20-byte packet at 4 Mbit/s 8N1.
    let packet_ticks = 6_250;
    let mut b = Batcher {
        config: *config,
        capture: SynthCapture::default(),
        pending: Vec::with_capacity(MAX_RECORDS),
        sequence: config.first_sequence,
        records_datagrams: 0,
        records_sent: 0,
        good: vec![0; usize::from(ports)],
        now: config.start_tick,
    };
    for k in 0..u64::from(config.samples_per_cell) {
        let t0 = config.start_tick + k * period_ticks;
        for (i, cell) in cells.iter_mut().enumerate() {
            for c in Channel::ALL {
                cell.value[c.index()] = step(&mut rng, c, cell.value[c.index()], config.walk_scale);
            }
            let slot = (i / usize::from(ports)) as u64;
            let tick = t0 + slot * packet_ticks % period_ticks.max(1);
            if !cell.event_mode {
                if let Ok(d) = DataRepr::from_raw(cell.id, cell.value) {
                    b.push(tick, cell.port, d.to_bytes());
                    b.capture.data_packets += 1;
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
                b.push(tick, cell.port, first.to_bytes());
                b.capture.event_packets += 1;
                cell.sequence = cell.sequence.wrapping_add(1);
                if let Some(second) = second {
                    b.push(tick + packet_ticks, cell.port, second.to_bytes());
                    b.capture.event_packets += 1;
                    cell.sequence = cell.sequence.wrapping_add(1);
                }
            }
        }
    }
    b.flush(FLAG_FLUSH_TIMEOUT);
    if config.status_every > 0 {
        b.status();
    }
    b.capture
}
