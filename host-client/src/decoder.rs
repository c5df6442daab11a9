//! The I/O-free decoder: box datagrams in, decoded records (and full samples) out, with
//! every loss and every piece of bad input counted.
//!
//! Losses it sees, in the order a packet could be lost on its way:
//! - the box's own counters from status datagrams (packet slots overflowing, rejected packets),
//!   as deltas between successive reports, and the record flag `FLAG_LOSS_BEFORE`;
//! - datagram sequence gaps, duplicates and reordering ([`crate::sequence`]);
//! - per-cell event packet sequence gaps (a lost event packet, wherever it was lost);
//! - box resets: the boot id of the status datagrams changes.
//!
//! Everything that follows one box's numbering (sequence numbers, boot ids, status reports,
//! counters, cells' event sequences) is kept per box, keyed by [`BoxKey`]: the box id and,
//! where the shell knows it, the datagram's source address. Two boxes on one capture are
//! two independent streams.
//!
//! A datagram whose header or length is wrong is rejected whole; a record whose port,
//! flags or cell packet is wrong rejects only that record (docs/wire-format.md).

use crate::bad_input::{BadInput, Reason};
use crate::convert::{EventToData, Sample, CELL_IDS};
use crate::other_traffic::{OtherKind, OtherTraffic};
pub use crate::rate::ASSUMED_SAMPLE_RATE_HZ;
use crate::rate::{learn_sample_rate, SampleRateEstimate};
use crate::report::{
    self, ratio, BoxReport, BoxStatusReport, CellReport, CellsDenominator, LossReport,
    PacketSizeAnalysis, Report, CELLS_GIVEN, CELLS_SEEN, SAMPLE_RATE_ASSUMED, SAMPLE_RATE_GIVEN,
    SAMPLE_RATE_LEARNED,
};
use crate::sequence::{SequenceEvent, SequenceTracker};
use serde::Serialize;
use skinbox_protocol::cell_command::CellCommandRepr;
use skinbox_protocol::command::{AckRepr, Command, Request, KIND_ACK, KIND_COMMAND};
use skinbox_protocol::datagram::{has_magic, Datagram, DatagramKind, MAX_PORTS};
use skinbox_protocol::record::FLAG_LOSS_BEFORE;
use skinbox_protocol::status::{PortCounter, StatusRepr};
use skinbox_protocol::{CellFraming, CellRepr, Channel, DatagramRepr, Modality};
use std::collections::BTreeMap;
use std::net::SocketAddr;

/// How many boxes one decoder follows; datagrams of further boxes are counted as bad input
/// (`datagram: too many boxes`) and not decoded.
pub const MAX_BOXES: usize = 64;

/// Which box a datagram came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
pub struct BoxKey {
    /// Box id of the datagram header.
    pub box_id: u16,
    /// Source address of the datagram, where the shell knows it.
    pub source: Option<SocketAddr>,
}

/// Settings of a decoder.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DecoderConfig {
    /// Header and end-of-packet bytes of the cells (a parameter of the box).
    pub framing: CellFraming,
    /// The cells' sample rate, for "packet rate in % of data mode"; `None` (the default):
    /// learned from the stamps ([`crate::rate::learn_sample_rate`]), else
    /// [`ASSUMED_SAMPLE_RATE_HZ`], and the report says which.
    pub sample_rate_hz: Option<f64>,
    /// The skin's cell count, the denominator of every per-cell ratio; `None`: the cells
    /// that sent at least one packet.
    pub cells: Option<u64>,
}

impl Default for DecoderConfig {
    fn default() -> Self {
        DecoderConfig {
            framing: CellFraming::DEFAULT,
            sample_rate_hz: None,
            cells: None,
        }
    }
}

/// One decoded record: a cell packet with its box time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct DecodedRecord {
    /// Box that sent it.
    pub box_id: u16,
    /// Source address of its datagram, where the shell knows it: with `box_id` the box's
    /// identity ([`BoxKey`]).
    pub source: Option<SocketAddr>,
    /// Sequence number of the datagram that carried it.
    pub datagram_sequence: u32,
    /// UART port of the box.
    pub port: u8,
    /// Record flags (`FLAG_LOSS_BEFORE`).
    pub flags: u8,
    /// 64-bit box tick (8 ns) of the packet's first start bit.
    pub tick: u64,
    /// The cell packet.
    pub cell: CellRepr,
    /// Event packets of this cell missing just before this one (0 for data packets).
    pub event_packets_missing_before: u16,
}

impl DecodedRecord {
    /// Box time in seconds.
    pub fn time_s(&self) -> f64 {
        crate::ticks_to_seconds(self.tick)
    }
}

/// Where decoded records and samples go.
pub trait RecordSink {
    /// One decoded record, in datagram order.
    fn record(&mut self, record: &DecodedRecord);
    /// Whether [`RecordSink::sample`] should be called (the converter costs time).
    fn wants_samples(&self) -> bool {
        false
    }
    /// The full sample of the record's cell after it.
    fn sample(&mut self, _sample: &Sample) {}
    /// The next datagram, `payload` (not yet checked), from `source` (where known), was
    /// received at `receive` on the host clock (the kernel's receive timestamp, or the
    /// pcap's; `None`: unknown): for sinks that map box time to host time
    /// ([`crate::timing`]). The shells call it before decoding each datagram.
    fn datagram_received(
        &mut self,
        _receive: Option<std::time::Duration>,
        _source: Option<SocketAddr>,
        _payload: &[u8],
    ) {
    }
    /// The decoder is done with the datagram `payload` from `source` (after its records):
    /// what became of it. For sinks that group records by datagram (one message per
    /// datagram) or read status datagrams.
    fn datagram_decoded(
        &mut self,
        _source: Option<SocketAddr>,
        _payload: &[u8],
        _outcome: DatagramOutcome,
    ) {
    }
}

/// A sink that drops everything (for reports only).
impl RecordSink for () {
    fn record(&mut self, _record: &DecodedRecord) {}
}

/// A sink that keeps every record.
impl RecordSink for Vec<DecodedRecord> {
    fn record(&mut self, record: &DecodedRecord) {
        self.push(*record);
    }
}

/// What became of one datagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DatagramOutcome {
    /// A records datagram; its records were decoded (bad ones counted).
    Records {
        /// Records in it.
        records: usize,
    },
    /// A status datagram.
    Status,
    /// A duplicate of a datagram already decoded: skipped.
    Duplicate,
    /// Rejected as bad input.
    Rejected,
    /// A well-formed command acknowledgement (kind 4): counted by result, not a box
    /// datagram ([`crate::control`] reads them).
    Acknowledgement,
    /// A well-formed command to a box (kind 3, in a capture of both directions): counted.
    Command,
    /// Not a skinbox datagram (no magic "SK"): counted as other traffic.
    NotSkinbox,
}

#[derive(Debug, Clone, Copy, Default)]
struct CellCounters {
    port: u8,
    data_packets: u64,
    event_packets: u64,
    channel_events: [u64; Channel::COUNT],
    last_event_sequence: Option<u16>,
    event_sequence_gaps: u64,
    event_packets_missing: u64,
    event_packets_repeated: u64,
    /// Tick of its last packet that began a sample (not a split sample's second).
    last_sample_tick: Option<u64>,
    /// Channels of its last event sample while it may still be split (a second part
    /// with the next sequence number completes it), not yet in the fired-together
    /// histogram; 0: none.
    pending_fired: u8,
}

#[derive(Debug, Clone, Default)]
struct BoxState {
    boot_id: Option<u32>,
    /// Last counters per port since the current boot.
    ports: BTreeMap<u8, [u32; PortCounter::ALL.len()]>,
    datagrams_sent: Option<u32>,
    records_sent: Option<u32>,
    /// The box counter block of the last status datagram that carried one.
    box_counters: Option<skinbox_protocol::BoxCounters>,
}

/// Everything the decoder follows of one box.
#[derive(Debug, Clone)]
struct BoxTrack {
    key: BoxKey,
    /// Port count of its latest datagram.
    port_count: u8,
    sequence: SequenceTracker,
    cells: Vec<CellCounters>,
    converter: Option<EventToData>,
    state: BoxState,
    boot_ids: Vec<u32>,
    box_resets: u64,
    status_datagrams: u64,
    status_reports: u64,
    /// Boot id and base tick of the last status report (one report may span datagrams).
    last_report: Option<(u32, u64)>,
    records_datagrams: u64,
    records: u64,
    min_tick: u64,
    max_tick: u64,
    records_flagged_loss_before: BTreeMap<u8, u64>,
    counter_deltas: BTreeMap<u8, [u64; PortCounter::ALL.len()]>,
    last_counters: BTreeMap<u8, [u32; PortCounter::ALL.len()]>,
    datagrams_sent_delta: u64,
    records_sent_delta: u64,
    /// Event samples by the number of channels that fired in them (index 1..=9), split
    /// samples joined; the cells' pending samples are not in it yet.
    fired_together: [u64; Channel::COUNT + 1],
}

/// How many per-cell tick intervals a decoder keeps for learning the sample rate, over
/// all boxes.
const MAX_INTERVALS: usize = 1 << 18;

impl BoxTrack {
    fn new(key: BoxKey) -> Self {
        BoxTrack {
            key,
            port_count: MAX_PORTS,
            sequence: SequenceTracker::new(),
            cells: Vec::new(),
            converter: None,
            state: BoxState::default(),
            boot_ids: Vec::new(),
            box_resets: 0,
            status_datagrams: 0,
            status_reports: 0,
            last_report: None,
            records_datagrams: 0,
            records: 0,
            min_tick: u64::MAX,
            max_tick: 0,
            records_flagged_loss_before: BTreeMap::new(),
            counter_deltas: BTreeMap::new(),
            last_counters: BTreeMap::new(),
            datagrams_sent_delta: 0,
            records_sent_delta: 0,
            fired_together: [0; Channel::COUNT + 1],
        }
    }

    /// Event samples by channels fired (index 1..=9), the pending ones included.
    fn fired_together(&self) -> [u64; Channel::COUNT + 1] {
        let mut h = self.fired_together;
        for c in &self.cells {
            if c.pending_fired > 0 {
                h[usize::from(c.pending_fired).min(Channel::COUNT)] += 1;
            }
        }
        h
    }

    /// Span of this box's record ticks plus one sample period (0 without records).
    fn duration_s(&self, sample_rate_hz: f64) -> f64 {
        if self.records == 0 {
            return 0.0;
        }
        crate::ticks_to_seconds(self.max_tick - self.min_tick) + 1.0 / sample_rate_hz
    }

    /// Takes a status datagram; false when it is a duplicate.
    fn take_status(&mut self, sequence: u32, base_tick: u64, status: &StatusRepr) -> bool {
        if self.state.boot_id != Some(status.boot_id) {
            if self.state.boot_id.is_some() {
                self.box_resets += 1;
                // The box numbers datagrams from its reset on: go on from this status
                // datagram, unless the numbering already restarted just before it.
                let continues = self.sequence.highest().is_some_and(|h| {
                    (1..crate::sequence::WINDOW).contains(&sequence.wrapping_sub(h))
                });
                if continues {
                    self.sequence.push_tagged(sequence, Some(base_tick));
                } else {
                    self.sequence.begin_at(sequence, base_tick);
                }
            } else {
                self.sequence.push_tagged(sequence, Some(base_tick));
            }
            self.boot_ids.push(status.boot_id);
            self.state = BoxState {
                boot_id: Some(status.boot_id),
                ..BoxState::default()
            };
        } else if self.sequence.push_tagged(sequence, Some(base_tick)) == SequenceEvent::Duplicate {
            return false;
        }
        self.status_datagrams += 1;
        // A report with more ports than one datagram holds spans several datagrams of
        // one base tick: it counts once.
        if self.last_report != Some((status.boot_id, base_tick)) {
            self.status_reports += 1;
            self.last_report = Some((status.boot_id, base_tick));
        }
        if let Some(before) = self.state.datagrams_sent {
            self.datagrams_sent_delta += wrapping_delta(status.datagrams_sent, before);
        }
        if let Some(before) = self.state.records_sent {
            self.records_sent_delta += wrapping_delta(status.records_sent, before);
        }
        self.state.datagrams_sent = Some(status.datagrams_sent);
        self.state.records_sent = Some(status.records_sent);
        for (i, counters) in status.ports.iter().enumerate() {
            let port = status.first_port.wrapping_add(i as u8);
            let now = counters.0;
            if let Some(before) = self.state.ports.get(&port) {
                let deltas = self.counter_deltas.entry(port).or_default();
                for c in PortCounter::ALL {
                    deltas[c.index()] += wrapping_delta(now[c.index()], before[c.index()]);
                }
            } else {
                self.counter_deltas.entry(port).or_default();
            }
            self.state.ports.insert(port, now);
            self.last_counters.insert(port, now);
        }
        true
    }

    /// This box's losses.
    fn losses(&self) -> LossReport {
        let mut losses = LossReport::default();
        for c in &self.cells {
            losses.event_sequence_gaps += c.event_sequence_gaps;
            losses.event_packets_missing += c.event_packets_missing;
            losses.event_packets_repeated += c.event_packets_repeated;
        }
        let seq = self.sequence.counts();
        losses.datagrams_missing = seq.missing;
        losses.datagrams_duplicate = seq.duplicate;
        losses.datagrams_reordered = seq.reordered;
        losses.datagram_sequence_gaps = seq.gaps;
        losses.sequence_restarts = seq.restarts;
        losses.box_resets = self.box_resets;
        losses.records_flagged_loss_before = self.records_flagged_loss_before.clone();
        losses.box_packets_lost = self
            .counter_deltas
            .values()
            .map(|d| {
                PortCounter::ALL
                    .iter()
                    .filter(|c| c.is_packet_loss())
                    .map(|c| d[c.index()])
                    .sum::<u64>()
            })
            .sum();
        losses
    }

    /// What this box's status datagrams said.
    fn box_status(&self) -> BoxStatusReport {
        BoxStatusReport {
            status_reports: self.status_reports,
            status_datagrams: self.status_datagrams,
            boot_ids: self.boot_ids.clone(),
            datagrams_sent_delta: self.datagrams_sent_delta,
            records_sent_delta: self.records_sent_delta,
            last_box_counters: self
                .state
                .box_counters
                .as_ref()
                .map(crate::report::BoxCountersReport::from),
            counter_deltas: self
                .counter_deltas
                .iter()
                .map(|(port, d)| {
                    (
                        *port,
                        PortCounter::ALL
                            .iter()
                            .map(|c| (c.name(), d[c.index()]))
                            .collect(),
                    )
                })
                .collect(),
            last_counters: self
                .last_counters
                .iter()
                .map(|(port, v)| {
                    (
                        *port,
                        PortCounter::ALL
                            .iter()
                            .map(|c| (c.name(), v[c.index()]))
                            .collect(),
                    )
                })
                .collect(),
        }
    }
}

/// The decoder. Feed it UDP payloads with [`Decoder::push_datagram`] (or
/// [`Decoder::push_datagram_from`] where the source address is known).
#[derive(Debug, Clone)]
pub struct Decoder {
    config: DecoderConfig,
    boxes: Vec<BoxTrack>,
    /// Index of the box of the previous datagram (most datagrams come from the same box).
    current: usize,
    bad: BadInput,
    other: OtherTraffic,
    acknowledgements: u64,
    acknowledgements_by_result: BTreeMap<&'static str, u64>,
    commands: u64,
    records: u64,
    /// Per-cell intervals between packets that began a sample, in ticks, of every box
    /// (the first [`MAX_INTERVALS`]).
    intervals: Vec<u64>,
    data_packets: u64,
    event_packets: u64,
    events_per_packet: [u64; 7],
}

impl Default for Decoder {
    fn default() -> Self {
        Self::new(DecoderConfig::default())
    }
}

fn wrapping_delta(now: u32, before: u32) -> u64 {
    u64::from(now.wrapping_sub(before))
}

impl Decoder {
    /// A decoder that has seen nothing.
    pub fn new(config: DecoderConfig) -> Self {
        Decoder {
            config,
            boxes: Vec::new(),
            current: 0,
            bad: BadInput::default(),
            other: OtherTraffic::default(),
            acknowledgements: 0,
            acknowledgements_by_result: BTreeMap::new(),
            commands: 0,
            records: 0,
            intervals: Vec::new(),
            data_packets: 0,
            event_packets: 0,
            events_per_packet: [0; 7],
        }
    }

    /// Command acknowledgements received among the datagrams (not box datagrams).
    pub fn acknowledgements(&self) -> u64 {
        self.acknowledgements
    }

    /// The settings.
    pub fn config(&self) -> &DecoderConfig {
        &self.config
    }

    /// Bad input counted so far; shells add their own (frames, pcap) here.
    pub fn bad_input_mut(&mut self) -> &mut BadInput {
        &mut self.bad
    }

    /// Other traffic counted so far; shells add the frames they passed over here.
    pub fn other_traffic_mut(&mut self) -> &mut OtherTraffic {
        &mut self.other
    }

    /// Other traffic counted so far.
    pub fn other_traffic(&self) -> &OtherTraffic {
        &self.other
    }

    /// Records decoded so far.
    pub fn records(&self) -> u64 {
        self.records
    }

    /// Datagrams missing so far, over every box (the report's `losses.datagrams_missing`,
    /// without building a report).
    pub fn datagrams_missing(&self) -> u64 {
        self.boxes.iter().map(|b| b.sequence.counts().missing).sum()
    }

    /// Bad input counted so far (the report's `bad_input.total`).
    pub fn bad_input_total(&self) -> u64 {
        self.bad.total
    }

    /// Index of the box of `key`, added when new; `None` past [`MAX_BOXES`].
    fn box_index(&mut self, key: BoxKey) -> Option<usize> {
        if self.boxes.get(self.current).is_some_and(|b| b.key == key) {
            return Some(self.current);
        }
        let i = match self.boxes.iter().position(|b| b.key == key) {
            Some(i) => i,
            None if self.boxes.len() < MAX_BOXES => {
                self.boxes.push(BoxTrack::new(key));
                self.boxes.len() - 1
            }
            None => return None,
        };
        self.current = i;
        Some(i)
    }

    /// Takes one UDP payload that should be a box datagram, source unknown.
    pub fn push_datagram<S: RecordSink + ?Sized>(
        &mut self,
        payload: &[u8],
        sink: &mut S,
    ) -> DatagramOutcome {
        self.push_datagram_from(None, payload, sink)
    }

    /// Takes one UDP payload that should be a box datagram, from `source` (the box is
    /// told by its box id and this address).
    pub fn push_datagram_from<S: RecordSink + ?Sized>(
        &mut self,
        source: Option<SocketAddr>,
        payload: &[u8],
        sink: &mut S,
    ) -> DatagramOutcome {
        let outcome = self.take_datagram(source, payload, sink);
        sink.datagram_decoded(source, payload, outcome);
        outcome
    }

    fn take_datagram<S: RecordSink + ?Sized>(
        &mut self,
        source: Option<SocketAddr>,
        payload: &[u8],
        sink: &mut S,
    ) -> DatagramOutcome {
        if !has_magic(payload) {
            self.other.count(OtherKind::UdpNotSkinbox);
            return DatagramOutcome::NotSkinbox;
        }
        match payload.get(skinbox_protocol::datagram::field::KIND) {
            Some(&KIND_ACK) => return self.take_ack(payload),
            Some(&KIND_COMMAND) => return self.take_command(payload),
            _ => {}
        }
        let d = match Datagram::new_checked(payload) {
            Ok(d) => d,
            Err(e) => {
                self.bad.count_error(Reason::Datagram, &e);
                return DatagramOutcome::Rejected;
            }
        };
        let key = BoxKey {
            box_id: d.box_id(),
            source,
        };
        let Some(index) = self.box_index(key) else {
            self.bad.count(Reason::TooManyBoxes, || {
                format!(
                    "datagram: box {} from {:?}: more than {MAX_BOXES} boxes, not decoded",
                    key.box_id, key.source
                )
            });
            return DatagramOutcome::Rejected;
        };
        self.boxes[index].port_count = d.port_count();
        match d.kind() {
            DatagramKind::Status => {
                // A status datagram is small and rare: parse it whole.
                match DatagramRepr::parse(payload) {
                    Ok(DatagramRepr {
                        sequence,
                        base_tick,
                        body: skinbox_protocol::datagram::DatagramBody::Status(status),
                        ..
                    }) => {
                        // A status body is one unit: a bad box counter block refuses the
                        // datagram whole, as a bad port counter block does, before its
                        // sequence number is taken (docs/wire-format.md).
                        let counters = match d.box_counters() {
                            Ok(c) => c,
                            Err(e) => {
                                self.bad.count_error(Reason::Status, &e);
                                return DatagramOutcome::Rejected;
                            }
                        };
                        if !self.boxes[index].take_status(sequence, base_tick, &status) {
                            return DatagramOutcome::Duplicate;
                        }
                        if let Some(c) = counters {
                            self.boxes[index].state.box_counters = Some(c);
                        }
                        DatagramOutcome::Status
                    }
                    Ok(_) => DatagramOutcome::Rejected,
                    Err(e) => {
                        self.bad.count_error(Reason::Status, &e);
                        DatagramOutcome::Rejected
                    }
                }
            }
            DatagramKind::Records => {
                // The base tick tells a copy from a new datagram of a restarted box.
                let track = &mut self.boxes[index];
                if track
                    .sequence
                    .push_tagged(d.sequence(), Some(d.base_tick()))
                    == SequenceEvent::Duplicate
                {
                    return DatagramOutcome::Duplicate;
                }
                track.records_datagrams += 1;
                let n = self.take_records(index, &d, sink);
                DatagramOutcome::Records { records: n }
            }
        }
    }

    /// An acknowledgement (kind 4), parsed whole by the protocol crate: counted by result,
    /// or refused with its reason.
    fn take_ack(&mut self, payload: &[u8]) -> DatagramOutcome {
        match AckRepr::parse(payload) {
            Ok(ack) => {
                self.acknowledgements += 1;
                *self
                    .acknowledgements_by_result
                    .entry(ack.result.name())
                    .or_insert(0) += 1;
                DatagramOutcome::Acknowledgement
            }
            Err(e) => {
                self.bad.count_error(Reason::Ack, &e);
                DatagramOutcome::Rejected
            }
        }
    }

    /// A command (kind 3), parsed whole: header, arguments against the addressed box's port
    /// count (the most a box has when the box is unknown or any box is addressed), and the
    /// cell command packet of a cell command; or refused with its reason.
    fn take_command(&mut self, payload: &[u8]) -> DatagramOutcome {
        let checked = Command::new_checked(payload).and_then(|c| {
            let port_count = self
                .boxes
                .iter()
                .find(|b| b.key.box_id == c.box_id())
                .map_or(MAX_PORTS, |b| b.port_count);
            match c.request(port_count)? {
                Request::CellCommand { packet, .. } => CellCommandRepr::parse(&packet).map(|_| ()),
                _ => Ok(()),
            }
        });
        match checked {
            Ok(()) => {
                self.commands += 1;
                DatagramOutcome::Command
            }
            Err(e) => {
                self.bad.count_error(Reason::Command, &e);
                DatagramOutcome::Rejected
            }
        }
    }

    fn take_records<S: RecordSink + ?Sized>(
        &mut self,
        index: usize,
        d: &Datagram<&[u8]>,
        sink: &mut S,
    ) -> usize {
        let base = d.base_tick();
        let box_id = d.box_id();
        let port_count = d.port_count();
        let datagram_sequence = d.sequence();
        let framing = self.config.framing;
        let wants_samples = sink.wants_samples();
        let track = &mut self.boxes[index];
        let source = track.key.source;
        if wants_samples && track.converter.is_none() {
            track.converter = Some(EventToData::new());
        }
        let mut n = 0;
        for r in d.records() {
            n += 1;
            // A bad record rejects only itself: its port and flags, then its cell packet.
            if let Err(e) = r.check(port_count) {
                self.bad.count_error(Reason::Record, &e);
                continue;
            }
            let cell = match CellRepr::parse(r.cell_packet(), &framing) {
                Ok(cell) => cell,
                Err(e) => {
                    self.bad.count_error(Reason::Record, &e);
                    continue;
                }
            };
            let tick = base.wrapping_add_signed(i64::from(r.tick_offset()));
            let port = r.port();
            let flags = r.flags();
            if flags & FLAG_LOSS_BEFORE != 0 {
                *track.records_flagged_loss_before.entry(port).or_insert(0) += 1;
            }
            self.records += 1;
            track.records += 1;
            track.min_tick = track.min_tick.min(tick);
            track.max_tick = track.max_tick.max(tick);
            // The table grows to the highest cell id seen (ids are 14 bits).
            let cell_index = usize::from(cell.cell_id()) % CELL_IDS;
            if cell_index >= track.cells.len() {
                track.cells.resize(cell_index + 1, CellCounters::default());
            }
            let c = &mut track.cells[cell_index];
            c.port = port;
            let begins_sample = match &cell {
                CellRepr::Data(_) => true,
                CellRepr::Event(e) => !e.second_part,
            };
            if begins_sample {
                if let Some(last) = c.last_sample_tick {
                    if self.intervals.len() < MAX_INTERVALS {
                        self.intervals.push(tick.abs_diff(last));
                    }
                }
                c.last_sample_tick = Some(tick);
            }
            let mut missing_before = 0u16;
            match &cell {
                CellRepr::Data(_) => {
                    c.data_packets += 1;
                    self.data_packets += 1;
                }
                CellRepr::Event(e) => {
                    c.event_packets += 1;
                    self.event_packets += 1;
                    let mut bits = e.channels.bits();
                    self.events_per_packet[bits.count_ones() as usize] += 1;
                    while bits != 0 {
                        let i = bits.trailing_zeros() as usize;
                        c.channel_events[i] += 1;
                        bits &= bits - 1;
                    }
                    // A split sample's second packet follows its first with the next
                    // sequence number; anything else begins a sample. A split sample has
                    // exactly two packets: the second completes it at once.
                    let fired = e.channels.len() as u8;
                    let joins = e.second_part
                        && c.pending_fired > 0
                        && c.last_event_sequence == Some(e.sequence.wrapping_sub(1));
                    if joins {
                        let together = usize::from(c.pending_fired) + usize::from(fired);
                        track.fired_together[together.min(Channel::COUNT)] += 1;
                        c.pending_fired = 0;
                    } else {
                        if c.pending_fired > 0 {
                            track.fired_together
                                [usize::from(c.pending_fired).min(Channel::COUNT)] += 1;
                        }
                        c.pending_fired = fired;
                    }
                    if let Some(last) = c.last_event_sequence {
                        let ahead = e.sequence.wrapping_sub(last);
                        if ahead == 0 || ahead >= 1 << 15 {
                            // A repeat or an older packet: a duplicated or reordered datagram.
                            c.event_packets_repeated += 1;
                        } else if ahead > 1 {
                            missing_before = ahead - 1;
                            c.event_sequence_gaps += 1;
                            c.event_packets_missing += u64::from(missing_before);
                        }
                    }
                    if c.last_event_sequence
                        .is_none_or(|last| e.sequence.wrapping_sub(last) < 1 << 15)
                    {
                        c.last_event_sequence = Some(e.sequence);
                    }
                }
            }
            let record = DecodedRecord {
                box_id,
                source,
                datagram_sequence,
                port,
                flags,
                tick,
                cell,
                event_packets_missing_before: missing_before,
            };
            sink.record(&record);
            if wants_samples {
                if let Some(conv) = track.converter.as_mut() {
                    let mut sample = conv.push(tick, &cell, missing_before > 0);
                    sample.box_id = box_id;
                    sample.source = source;
                    sink.sample(&sample);
                }
            }
        }
        n
    }

    /// Duration the records span, plus one sample period: N samples per cell at the
    /// sample rate make exactly N / rate seconds, so data mode reads 100 %. With several
    /// boxes (each its own clock), the longest box's.
    fn duration_at(&self, rate: f64) -> f64 {
        self.boxes
            .iter()
            .map(|b| b.duration_s(rate))
            .fold(0.0, f64::max)
    }

    /// The sample rate the rates are relative to, where it came from, and what the stamps
    /// say about it: the configured rate, else the learned one, else
    /// [`ASSUMED_SAMPLE_RATE_HZ`].
    pub fn sample_rate(&self) -> (f64, &'static str, Option<SampleRateEstimate>) {
        let learned = learn_sample_rate(self.intervals.iter().copied());
        match (self.config.sample_rate_hz, learned) {
            (Some(rate), _) => (rate, SAMPLE_RATE_GIVEN, learned),
            (None, Some(e)) => (e.rate_hz, SAMPLE_RATE_LEARNED, learned),
            (None, None) => (ASSUMED_SAMPLE_RATE_HZ, SAMPLE_RATE_ASSUMED, None),
        }
    }

    /// Everything so far, as the papers report it: totals over every box, and each box
    /// on its own in `boxes`.
    pub fn report(&self) -> Report {
        let (rate, sample_rate_source, sample_rate_learned) = self.sample_rate();
        let duration_s = self.duration_at(rate);
        let per_s = |n: u64| {
            if duration_s > 0.0 {
                n as f64 / duration_s
            } else {
                0.0
            }
        };
        let mut cells = Vec::new();
        let mut modality_events: BTreeMap<Modality, u64> =
            Modality::ALL.iter().map(|m| (*m, 0)).collect();
        let mut losses = LossReport::default();
        let mut box_status = BoxStatusReport::default();
        let mut boxes = Vec::new();
        let mut expected_all = 0.0;
        for b in &self.boxes {
            let box_duration = b.duration_s(rate);
            let expected_per_cell = rate * box_duration;
            let box_per_s = |n: u64| {
                if box_duration > 0.0 {
                    n as f64 / box_duration
                } else {
                    0.0
                }
            };
            let mut box_cells = 0u64;
            for (id, c) in b.cells.iter().enumerate() {
                let packets = c.data_packets + c.event_packets;
                if packets == 0 {
                    continue;
                }
                box_cells += 1;
                let mut by_modality: BTreeMap<Modality, u64> =
                    Modality::ALL.iter().map(|m| (*m, 0)).collect();
                for ch in Channel::ALL {
                    *by_modality.entry(ch.modality()).or_insert(0) += c.channel_events[ch.index()];
                }
                for (m, n) in &by_modality {
                    *modality_events.entry(*m).or_insert(0) += n;
                }
                cells.push(CellReport {
                    box_id: b.key.box_id,
                    source: b.key.source,
                    cell_id: id as u16,
                    port: c.port,
                    data_packets: c.data_packets,
                    event_packets: c.event_packets,
                    packet_rate_percent_of_data_mode: report::percent(
                        packets as f64,
                        expected_per_cell,
                    ),
                    events_per_second: by_modality
                        .iter()
                        .map(|(m, n)| (*m, box_per_s(*n)))
                        .collect(),
                    event_sequence_gaps: c.event_sequence_gaps,
                    event_packets_missing: c.event_packets_missing,
                });
            }
            expected_all += expected_per_cell * box_cells as f64;
            let box_losses = b.losses();
            losses.add(&box_losses);
            let status = b.box_status();
            box_status.add(&status);
            boxes.push(BoxReport {
                box_id: b.key.box_id,
                source: b.key.source,
                records_datagrams: b.records_datagrams,
                records: b.records,
                cells_active: box_cells,
                first_tick: if b.records > 0 { b.min_tick } else { 0 },
                last_tick: b.max_tick,
                duration_s: box_duration,
                losses: box_losses,
                box_status: status,
            });
        }
        // Counters by port mean something only for one box.
        if let [only] = boxes.as_slice() {
            box_status.last_counters = only.box_status.last_counters.clone();
            box_status.last_box_counters = only.box_status.last_box_counters.clone();
        }
        let cells_active = cells.len() as u64;
        let cells_denominator = match self.config.cells {
            Some(n) => {
                // Every cell of the skin over the whole span.
                expected_all = rate * duration_s * n as f64;
                CellsDenominator {
                    cells: n,
                    source: CELLS_GIVEN,
                }
            }
            None => CellsDenominator {
                cells: cells_active,
                source: CELLS_SEEN,
            },
        };
        let denominator = cells_denominator.cells;
        let per_cell_s = |n: u64| {
            if denominator == 0 || duration_s <= 0.0 {
                0.0
            } else {
                n as f64 / denominator as f64 / duration_s
            }
        };
        let samples = rate * duration_s * denominator as f64;
        let mut fired_together = [0u64; Channel::COUNT + 1];
        let mut channel_events = [0u64; Channel::COUNT];
        for b in &self.boxes {
            for (i, n) in b.fired_together().iter().enumerate() {
                fired_together[i] += n;
            }
            for c in &b.cells {
                for (i, n) in c.channel_events.iter().enumerate() {
                    channel_events[i] += n;
                }
            }
        }
        let fired_together_histogram = fired_together[1..].to_vec();
        let with_records = self.boxes.iter().filter(|b| b.records > 0);
        let first_tick = with_records.clone().map(|b| b.min_tick).min().unwrap_or(0);
        let last_tick = with_records.map(|b| b.max_tick).max().unwrap_or(0);
        let mut box_ids: Vec<u16> = Vec::new();
        for b in &self.boxes {
            if !box_ids.contains(&b.key.box_id) {
                box_ids.push(b.key.box_id);
            }
        }
        Report {
            sample_rate_hz: rate,
            sample_rate_source,
            sample_rate_learned,
            cells_denominator,
            box_ids,
            records_datagrams: boxes.iter().map(|b| b.records_datagrams).sum(),
            status_datagrams: box_status.status_datagrams,
            acknowledgements: self.acknowledgements,
            acknowledgements_by_result: self.acknowledgements_by_result.clone(),
            commands: self.commands,
            records: self.records,
            data_packets: self.data_packets,
            event_packets: self.event_packets,
            first_tick,
            last_tick,
            first_time_s: crate::ticks_to_seconds(first_tick),
            last_time_s: crate::ticks_to_seconds(last_tick),
            duration_s,
            cells_active,
            packets_per_second: per_s(self.records),
            packets_per_cell_per_second: per_cell_s(self.records),
            packet_rate_percent_of_data_mode: report::percent(self.records as f64, expected_all),
            event_packet_rate_percent_of_data_mode: report::percent(
                self.event_packets as f64,
                expected_all,
            ),
            events_per_cell_per_second: modality_events
                .iter()
                .map(|(m, n)| (*m, per_cell_s(*n)))
                .collect(),
            events_per_packet_histogram: self.events_per_packet[1..].to_vec(),
            cells_active_ratio: ratio(cells_active as f64, denominator as f64),
            samples_of_the_cells: samples,
            channel_event_ratio: Channel::ALL
                .iter()
                .map(|c| (c.name(), ratio(channel_events[c.index()] as f64, samples)))
                .collect(),
            packet_sizes: PacketSizeAnalysis::new(&fired_together_histogram, samples),
            fired_together_histogram,
            losses,
            box_status,
            boxes,
            bad_input: self.bad.clone(),
            other_traffic: self.other.clone(),
            frames: Default::default(),
            host: None,
            cells,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_protocol::datagram::{DatagramBody, MAX_RECORDS};
    use skinbox_protocol::{DataRepr, RecordRepr, TICKS_PER_SECOND};

    /// The intervals kept for learning the rate are capped over all boxes, not per box.
    #[test]
    fn the_intervals_are_capped_over_all_boxes() {
        // One cell per box in data mode at 125 Hz.
        let period = TICKS_PER_SECOND / 125;
        let per_box = MAX_INTERVALS * 3 / 5;
        let mut d = Decoder::new(DecoderConfig {
            sample_rate_hz: None,
            ..DecoderConfig::default()
        });
        for box_id in [1, 2] {
            let mut sent = 0usize;
            let mut sequence = 0;
            while sent < per_box {
                let n = MAX_RECORDS.min(per_box - sent);
                let records = (0..n)
                    .map(|k| RecordRepr {
                        port: 0,
                        flags: 0,
                        tick_offset: (k as u64 * period) as i32,
                        cell_packet: DataRepr {
                            cell_id: 1,
                            ..DataRepr::default()
                        }
                        .to_bytes(),
                    })
                    .collect();
                let payload = DatagramRepr {
                    box_id,
                    port_count: 1,
                    flags: 0,
                    sequence,
                    base_tick: sent as u64 * period,
                    body: DatagramBody::Records(records),
                }
                .to_bytes();
                d.push_datagram(&payload, &mut ());
                sent += n;
                sequence += 1;
            }
        }
        assert_eq!(d.records(), 2 * per_box as u64);
        assert_eq!(d.intervals.len(), MAX_INTERVALS);
        let r = d.report();
        assert_eq!(r.sample_rate_source, SAMPLE_RATE_LEARNED);
        assert_eq!(r.sample_rate_hz, 125.0);
        assert_eq!(
            r.sample_rate_learned.unwrap().intervals,
            MAX_INTERVALS as u64
        );
    }
}
