//! The report: what the papers report per scene, every loss, the box's counters, bad input
//! and the host's own cost. Serialises to JSON as is.

use crate::BadInput;
use serde::Serialize;
use skinbox_protocol::Modality;
use std::collections::BTreeMap;

/// `part / whole` in percent, 0 when `whole` is 0.
pub fn percent(part: f64, whole: f64) -> f64 {
    if whole > 0.0 {
        100.0 * part / whole
    } else {
        0.0
    }
}

/// `sample_rate_source`: the rate was given (command line, scene).
pub const SAMPLE_RATE_GIVEN: &str = "given";
/// `sample_rate_source`: the rate was learned from the record stamps.
pub const SAMPLE_RATE_LEARNED: &str = "learned from the stamps";
/// `sample_rate_source`: neither given nor learnable (no cell sent twice):
/// [`crate::rate::ASSUMED_SAMPLE_RATE_HZ`] assumed.
pub const SAMPLE_RATE_ASSUMED: &str = "assumed: not given, too few stamps to learn it";
/// `cells_denominator.source`: the skin's cell count was given.
pub const CELLS_GIVEN: &str = "given";
/// `cells_denominator.source`: the cells that sent at least one packet.
pub const CELLS_SEEN: &str = "cells seen";

/// The cell count that per-cell ratios divide by, and where it came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct CellsDenominator {
    /// Cells.
    pub cells: u64,
    /// [`CELLS_GIVEN`] (the skin's cells) or [`CELLS_SEEN`] (cells that sent a packet).
    pub source: &'static str,
}

/// `part / whole`, 0 when `whole` is 0.
pub fn ratio(part: f64, whole: f64) -> f64 {
    if whole > 0.0 {
        part / whole
    } else {
        0.0
    }
}

/// Sizes in bytes of an event packet carrying k = 1..9 events, without a time stamp
/// (the papers' packet-size analysis).
pub const PACKET_SIZE_BYTES: [u32; 9] = [7, 9, 10, 12, 14, 15, 17, 18, 20];
/// The same with a 21-bit time stamp.
pub const PACKET_SIZE_WITH_TIMESTAMP_BYTES: [u32; 9] = [10, 12, 13, 15, 17, 18, 20, 21, 22];
/// Size of today's fixed packet, bytes.
pub const FIXED_PACKET_BYTES: u32 = 20;

/// One packet size of the analysis: packets of at most `k` events.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PacketSizeRow {
    /// Events per packet at most.
    pub k: u32,
    /// Packets needed: `sum_i n(i) * ceil(i / k)` over the fired-together histogram.
    pub packets: u64,
    /// Packet size without a time stamp, bytes.
    pub size_bytes: u32,
    /// Transmission rate against data mode (every cell, every sample, 20 bytes).
    pub ratio: f64,
    /// Packet size with a 21-bit time stamp, bytes.
    pub size_with_timestamp_bytes: u32,
    /// Transmission rate against data mode, with the time stamp.
    pub ratio_with_timestamp: f64,
}

/// The best packet size: fewest bytes against data mode.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PacketSizeBest {
    /// Events per packet.
    pub k: u32,
    /// Its transmission rate ratio.
    pub ratio: f64,
}

/// The papers' packet-size analysis: transmission rate against events per packet,
/// `ratio(k) = n_pkt(k) / (t * f_s * n_cells) * s(k) / 20`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PacketSizeAnalysis {
    /// `t * f_s * n_cells`: the samples of the denominator's cells.
    pub samples: f64,
    /// k = 1..9.
    pub rows: Vec<PacketSizeRow>,
    /// The minimum without a time stamp.
    pub best: Option<PacketSizeBest>,
    /// The minimum with a time stamp.
    pub best_with_timestamp: Option<PacketSizeBest>,
}

impl PacketSizeAnalysis {
    /// From the histogram `n(i)` of samples in which i = 1..9 channels fired and the
    /// samples of the cells.
    pub fn new(fired_together: &[u64], samples: f64) -> Self {
        let rows: Vec<PacketSizeRow> = (1..=9u32)
            .map(|k| {
                let packets: u64 = fired_together
                    .iter()
                    .enumerate()
                    .map(|(j, n)| n * u64::from((j as u32 + 1).div_ceil(k)))
                    .sum();
                let s = PACKET_SIZE_BYTES[k as usize - 1];
                let st = PACKET_SIZE_WITH_TIMESTAMP_BYTES[k as usize - 1];
                let r = ratio(packets as f64, samples);
                PacketSizeRow {
                    k,
                    packets,
                    size_bytes: s,
                    ratio: r * f64::from(s) / f64::from(FIXED_PACKET_BYTES),
                    size_with_timestamp_bytes: st,
                    ratio_with_timestamp: r * f64::from(st) / f64::from(FIXED_PACKET_BYTES),
                }
            })
            .collect();
        let best_by = |f: fn(&PacketSizeRow) -> f64| {
            (samples > 0.0)
                .then(|| rows.iter().min_by(|a, b| f(a).total_cmp(&f(b))))
                .flatten()
                .map(|r| PacketSizeBest {
                    k: r.k,
                    ratio: f(r),
                })
        };
        let best = best_by(|r| r.ratio);
        let best_with_timestamp = best_by(|r| r.ratio_with_timestamp);
        PacketSizeAnalysis {
            samples,
            rows,
            best,
            best_with_timestamp,
        }
    }
}

/// One cell's share.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CellReport {
    /// Box the cell is on.
    pub box_id: u16,
    /// Source address of that box's datagrams, where known.
    pub source: Option<std::net::SocketAddr>,
    /// Cell id.
    pub cell_id: u16,
    /// Port of its last record.
    pub port: u8,
    /// Data packets received.
    pub data_packets: u64,
    /// Event packets received.
    pub event_packets: u64,
    /// All its packets against one per sample period.
    pub packet_rate_percent_of_data_mode: f64,
    /// Channel events per second by modality (events of a modality's channels summed).
    pub events_per_second: BTreeMap<Modality, f64>,
    /// Gaps in its event packet sequence.
    pub event_sequence_gaps: u64,
    /// Event packets missing in those gaps.
    pub event_packets_missing: u64,
}

/// Every loss the host can see.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct LossReport {
    /// Datagram sequence numbers never received.
    pub datagrams_missing: u64,
    /// Datagram sequence gaps when they opened (some may have filled later).
    pub datagram_sequence_gaps: u64,
    /// Copies of datagrams already received (skipped).
    pub datagrams_duplicate: u64,
    /// Datagrams that arrived after a later one.
    pub datagrams_reordered: u64,
    /// Times the datagram numbering started again without a status report saying so.
    pub sequence_restarts: u64,
    /// Box resets: the boot id of the status datagrams changed.
    pub box_resets: u64,
    /// Gaps in the cells' event packet sequences.
    pub event_sequence_gaps: u64,
    /// Event packets missing in those gaps.
    pub event_packets_missing: u64,
    /// Event packets whose sequence number was not ahead of the cell's last one.
    pub event_packets_repeated: u64,
    /// Records flagged "packets of this port dropped before", by port.
    pub records_flagged_loss_before: BTreeMap<u8, u64>,
    /// Packets the box itself lost (overflow and rejects), from its counter deltas.
    pub box_packets_lost: u64,
}

impl LossReport {
    /// Adds another box's losses into these.
    pub fn add(&mut self, other: &LossReport) {
        self.datagrams_missing += other.datagrams_missing;
        self.datagram_sequence_gaps += other.datagram_sequence_gaps;
        self.datagrams_duplicate += other.datagrams_duplicate;
        self.datagrams_reordered += other.datagrams_reordered;
        self.sequence_restarts += other.sequence_restarts;
        self.box_resets += other.box_resets;
        self.event_sequence_gaps += other.event_sequence_gaps;
        self.event_packets_missing += other.event_packets_missing;
        self.event_packets_repeated += other.event_packets_repeated;
        for (port, n) in &other.records_flagged_loss_before {
            *self.records_flagged_loss_before.entry(*port).or_insert(0) += n;
        }
        self.box_packets_lost += other.box_packets_lost;
    }
}

/// What the box's status datagrams said.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct BoxStatusReport {
    /// Status reports taken: one per report, however many datagrams it spans.
    pub status_reports: u64,
    /// Status datagrams taken (duplicates skipped).
    pub status_datagrams: u64,
    /// Boot ids seen, in order.
    pub boot_ids: Vec<u32>,
    /// Records datagrams the box sent between its first and last report (per boot, summed).
    pub datagrams_sent_delta: u64,
    /// Records the box sent between its first and last report (per boot, summed).
    pub records_sent_delta: u64,
    /// Per port, each counter's growth (by `PortCounter::name`) between successive reports of one boot, summed.
    pub counter_deltas: BTreeMap<u8, BTreeMap<&'static str, u64>>,
    /// Per port, the counters of the last report (in a total over several boxes: empty).
    pub last_counters: BTreeMap<u8, BTreeMap<&'static str, u32>>,
    /// The box counter block of the last status datagram that carried one (in a total
    /// over several boxes: none).
    pub last_box_counters: Option<BoxCountersReport>,
}

/// The box-wide counters and link state of a status datagram (docs/wire-format.md).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoxCountersReport {
    /// The PHY reports the link up.
    pub link_up: bool,
    /// Link speed.
    pub link_speed: skinbox_protocol::box_counters::LinkSpeed,
    /// Each counter by name (`BoxCounter::name`), in wire order.
    pub counters: BTreeMap<&'static str, u32>,
    /// Frames counted in no fate or in several (0 from a consistent box).
    pub unaccounted_frames: u32,
}

impl From<&skinbox_protocol::BoxCounters> for BoxCountersReport {
    fn from(c: &skinbox_protocol::BoxCounters) -> Self {
        BoxCountersReport {
            link_up: c.link_up,
            link_speed: c.link_speed,
            counters: c.named().into_iter().collect(),
            unaccounted_frames: c.unaccounted_frames(),
        }
    }
}

impl BoxStatusReport {
    /// Adds another box's counts into these (`last_counters` is left alone).
    pub fn add(&mut self, other: &BoxStatusReport) {
        self.status_reports += other.status_reports;
        self.status_datagrams += other.status_datagrams;
        self.boot_ids.extend(&other.boot_ids);
        self.datagrams_sent_delta += other.datagrams_sent_delta;
        self.records_sent_delta += other.records_sent_delta;
        for (port, counters) in &other.counter_deltas {
            let sum = self.counter_deltas.entry(*port).or_default();
            for (name, n) in counters {
                *sum.entry(name).or_insert(0) += n;
            }
        }
    }
}

/// One box of a capture: its datagrams, losses and status on their own.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoxReport {
    /// Box id.
    pub box_id: u16,
    /// Source address of its datagrams, where known.
    pub source: Option<std::net::SocketAddr>,
    /// Records datagrams decoded (duplicates skipped).
    pub records_datagrams: u64,
    /// Records with a valid cell packet.
    pub records: u64,
    /// Cells that sent at least one packet.
    pub cells_active: u64,
    /// Box tick of its earliest record.
    pub first_tick: u64,
    /// Box tick of its latest record.
    pub last_tick: u64,
    /// Span of its record ticks plus one sample period, in seconds.
    pub duration_s: f64,
    /// Its losses.
    pub losses: LossReport,
    /// Its status reports.
    pub box_status: BoxStatusReport,
}

/// Frames of a pcap or a live socket, before the box datagram decoder.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct FrameCounts {
    /// Frames (pcap packets or received datagrams).
    pub frames: u64,
    /// Frames whose UDP payload went to the datagram decoder.
    pub udp_payloads: u64,
    /// Time span of the frames by the capture's clock, in seconds.
    pub capture_span_s: f64,
}

/// The host's own cost of decoding.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct HostCost {
    /// CPU time of the decoding thread, in seconds.
    pub cpu_s: f64,
    /// Wall time, in seconds.
    pub wall_s: f64,
    /// CPU time per cell packet, in nanoseconds (the original driver: about 10,000).
    pub cpu_ns_per_packet: f64,
}

/// The whole report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    /// Sample rate the rates are relative to.
    pub sample_rate_hz: f64,
    /// Where `sample_rate_hz` came from: [`SAMPLE_RATE_GIVEN`], [`SAMPLE_RATE_LEARNED`] or
    /// [`SAMPLE_RATE_ASSUMED`].
    pub sample_rate_source: &'static str,
    /// What the stamps say about the sample rate (also when it was given).
    pub sample_rate_learned: Option<crate::rate::SampleRateEstimate>,
    /// The cells every per-cell ratio divides by.
    pub cells_denominator: CellsDenominator,
    /// Box ids seen.
    pub box_ids: Vec<u16>,
    /// Records datagrams decoded (duplicates skipped).
    pub records_datagrams: u64,
    /// Status datagrams decoded.
    pub status_datagrams: u64,
    /// Well-formed command acknowledgements among the datagrams (kind 4; not box
    /// datagrams).
    pub acknowledgements: u64,
    /// Those acknowledgements by result (`ok`, `replay`, ...).
    pub acknowledgements_by_result: BTreeMap<&'static str, u64>,
    /// Well-formed commands to a box among the datagrams (kind 3; not box datagrams).
    pub commands: u64,
    /// Records with a valid cell packet.
    pub records: u64,
    /// Cell data packets.
    pub data_packets: u64,
    /// Cell event packets.
    pub event_packets: u64,
    /// Box tick of the earliest record (whatever the capture order).
    pub first_tick: u64,
    /// Box tick of the latest record.
    pub last_tick: u64,
    /// Box time of the earliest record, in seconds.
    pub first_time_s: f64,
    /// Box time of the latest record, in seconds.
    pub last_time_s: f64,
    /// Span of the record ticks plus one sample period, in seconds.
    pub duration_s: f64,
    /// Cells that sent at least one packet.
    pub cells_active: u64,
    /// Cell packets per second of box time.
    pub packets_per_second: f64,
    /// Cell packets per cell of `cells_denominator` per second.
    pub packets_per_cell_per_second: f64,
    /// All packets against every cell of `cells_denominator` sending every sample.
    pub packet_rate_percent_of_data_mode: f64,
    /// Event packets against every cell of `cells_denominator` sending every sample (2nd
    /// paper, Fig. 8).
    pub event_packet_rate_percent_of_data_mode: f64,
    /// Channel events per cell of `cells_denominator` per second, by modality (2nd paper,
    /// Fig. 8).
    pub events_per_cell_per_second: BTreeMap<Modality, f64>,
    /// Event packets carrying 1, 2, ... 6 channels.
    pub events_per_packet_histogram: Vec<u64>,
    /// Cells that sent a packet against `cells_denominator`.
    pub cells_active_ratio: f64,
    /// `duration_s * sample_rate_hz * cells_denominator.cells`: the samples the ratios
    /// below divide by.
    pub samples_of_the_cells: f64,
    /// Per channel, its events against `samples_of_the_cells`.
    pub channel_event_ratio: BTreeMap<&'static str, f64>,
    /// Event samples in which 1, 2, ... 9 channels fired (a split sample's two packets
    /// joined).
    pub fired_together_histogram: Vec<u64>,
    /// Transmission rate against events per packet, with and without a time stamp.
    pub packet_sizes: PacketSizeAnalysis,
    /// Every loss, summed over the boxes.
    pub losses: LossReport,
    /// The boxes' own counters, summed.
    pub box_status: BoxStatusReport,
    /// Each box (box id and source address) on its own, in order of its first datagram.
    pub boxes: Vec<BoxReport>,
    /// Rejected input by reason: malformed skinbox datagrams (and their frames), only.
    pub bad_input: BadInput,
    /// Frames and datagrams that are not the box's (ARP, IPv6, TCP, other UDP, ...), by
    /// kind: not bad input.
    pub other_traffic: crate::other_traffic::OtherTraffic,
    /// Frames before the datagram decoder.
    pub frames: FrameCounts,
    /// The host's cost, when the shell measured it.
    pub host: Option<HostCost>,
    /// Per cell.
    pub cells: Vec<CellReport>,
}

impl Report {
    /// The sample rate, where it came from and what the stamps say, in one line.
    pub fn sample_rate_line(&self) -> String {
        let mut line = format!("{} Hz, {}", self.sample_rate_hz, self.sample_rate_source);
        if let Some(e) = &self.sample_rate_learned {
            let near = match e.standard_hz {
                Some(std) => format!("{std} Hz"),
                None => "the nearest standard rate".to_string(),
            };
            line += &format!(
                " (stamps: {:.2} Hz, {:+.2} % from {near}, {} of {} per-cell intervals fitted)",
                e.estimated_hz, e.off_nearest_standard_percent, e.intervals_fitted, e.intervals
            );
        }
        line
    }

    /// A few lines for a person.
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{} records in {} datagrams (+{} status) over {:.3} s box time: {} data, {} event packets",
            self.records,
            self.records_datagrams,
            self.status_datagrams,
            self.duration_s,
            self.data_packets,
            self.event_packets
        );
        let _ = writeln!(s, "sample rate: {}", self.sample_rate_line());
        let d = &self.cells_denominator;
        let per = format!("{} cells ({})", d.cells, d.source);
        let _ = writeln!(
            s,
            "{} cells active; over {per} at {} Hz: packet rate {:.2} % of data mode (events {:.2} %), \
             {:.2} packets per cell per second; {:.0} packets/s in all",
            self.cells_active,
            self.sample_rate_hz,
            self.packet_rate_percent_of_data_mode,
            self.event_packet_rate_percent_of_data_mode,
            self.packets_per_cell_per_second,
            self.packets_per_second
        );
        let rates: Vec<String> = self
            .events_per_cell_per_second
            .iter()
            .map(|(m, r)| format!("{} {:.2}", m.name(), r))
            .collect();
        let _ = writeln!(
            s,
            "events per cell per second (over {per}): {}",
            rates.join(", ")
        );
        let _ = writeln!(
            s,
            "events per packet (1..6): {:?}",
            self.events_per_packet_histogram
        );
        let _ = writeln!(
            s,
            "active cells: {} of {per} = {:.4}",
            self.cells_active, self.cells_active_ratio
        );
        let ratios: Vec<String> = self
            .channel_event_ratio
            .iter()
            .map(|(c, r)| format!("{c} {r:.4}"))
            .collect();
        let _ = writeln!(
            s,
            "channel events per sample (over {:.0} samples of {per}): {}",
            self.samples_of_the_cells,
            ratios.join(", ")
        );
        let _ = writeln!(
            s,
            "channels fired in one sample (1..9): {:?}",
            self.fired_together_histogram
        );
        let p = &self.packet_sizes;
        let row = |f: fn(&PacketSizeRow) -> f64| {
            p.rows
                .iter()
                .map(|r| format!("{:.4}", f(r)))
                .collect::<Vec<_>>()
                .join(" ")
        };
        let best = |b: &Option<PacketSizeBest>| match b {
            Some(b) => format!("best k = {} at {:.4}", b.k, b.ratio),
            None => "no samples".to_string(),
        };
        let _ = writeln!(
            s,
            "transmission rate against data mode (over {:.0} samples of {per}) for k = 1..9 events per packet:",
            p.samples
        );
        let _ = writeln!(
            s,
            "  without time stamp: {}; {}",
            row(|r| r.ratio),
            best(&p.best)
        );
        let _ = writeln!(
            s,
            "  with 21-bit time stamp: {}; {}",
            row(|r| r.ratio_with_timestamp),
            best(&p.best_with_timestamp)
        );
        let l = &self.losses;
        let _ = writeln!(
            s,
            "losses: {} datagrams missing ({} gaps), {} duplicate, {} reordered, {} restarts, \
             {} box resets; {} event packets missing in {} gaps; box lost {} packets",
            l.datagrams_missing,
            l.datagram_sequence_gaps,
            l.datagrams_duplicate,
            l.datagrams_reordered,
            l.sequence_restarts,
            l.box_resets,
            l.event_packets_missing,
            l.event_sequence_gaps,
            l.box_packets_lost
        );
        let _ = writeln!(
            s,
            "box status: {} reports, boot ids {:x?}, {} datagrams and {} records sent between reports",
            self.box_status.status_reports,
            self.box_status.boot_ids,
            self.box_status.datagrams_sent_delta,
            self.box_status.records_sent_delta
        );
        if let Some(c) = &self.box_status.last_box_counters {
            let nonzero: Vec<String> = c
                .counters
                .iter()
                .filter(|(_, v)| **v != 0)
                .map(|(k, v)| format!("{k}={v}"))
                .collect();
            let _ = writeln!(
                s,
                "box counters: link {} ({:?}), {}{}",
                if c.link_up { "up" } else { "down" },
                c.link_speed,
                if nonzero.is_empty() {
                    "no frames received".to_string()
                } else {
                    nonzero.join(" ")
                },
                if c.unaccounted_frames != 0 {
                    format!(", {} frames unaccounted", c.unaccounted_frames)
                } else {
                    String::new()
                }
            );
        }
        if self.boxes.len() > 1 {
            for b in &self.boxes {
                let l = &b.losses;
                let _ = writeln!(
                    s,
                    "box {}{}: {} records in {} datagrams, {} status reports; {} datagrams missing, \
                     {} duplicate, {} reordered, {} restarts, {} box resets",
                    b.box_id,
                    b.source.map(|a| format!(" from {a}")).unwrap_or_default(),
                    b.records,
                    b.records_datagrams,
                    b.box_status.status_reports,
                    l.datagrams_missing,
                    l.datagrams_duplicate,
                    l.datagrams_reordered,
                    l.sequence_restarts,
                    l.box_resets
                );
            }
        }
        if self.commands > 0 || self.acknowledgements > 0 {
            let results: Vec<String> = self
                .acknowledgements_by_result
                .iter()
                .map(|(r, n)| format!("{r} {n}"))
                .collect();
            let _ = writeln!(
                s,
                "commands: {}; acknowledgements: {}{}",
                self.commands,
                self.acknowledgements,
                if results.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", results.join(", "))
                }
            );
        }
        let _ = writeln!(s, "bad input: {}", self.bad_input);
        let _ = writeln!(s, "other traffic: {}", self.other_traffic);
        if let Some(h) = &self.host {
            let _ = writeln!(
                s,
                "host: {:.3} s CPU, {:.1} ns CPU per packet",
                h.cpu_s, h.cpu_ns_per_packet
            );
        }
        s
    }
}
