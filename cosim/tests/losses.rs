//! Loss detection: drop, duplicate and reorder datagrams, reset the box; exact counts.

use skinbox_cosim::synthetic::{self, SynthCapture, SyntheticConfig};
use skinbox_host::{DecodedRecord, Decoder, DecoderConfig, Report};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{CellFraming, CellRepr};
use std::collections::HashMap;

fn capture(boot_id: u32, first_sequence: u32) -> SynthCapture {
    synthetic::generate(&SyntheticConfig {
        cells: 60,
        samples_per_cell: 60,
        event_every: 3,
        status_period_ticks: 0,
        boot_id,
        first_sequence,
        ..SyntheticConfig::default()
    })
    .unwrap()
}

fn decode(payloads: &[Vec<u8>]) -> (Report, Vec<DecodedRecord>) {
    let mut d = Decoder::new(DecoderConfig::default());
    let mut records = Vec::new();
    for p in payloads {
        d.push_datagram(p, &mut records);
    }
    (d.report(), records)
}

/// Oracle for per-cell event gaps: from the event packets that arrive, in arrival order,
/// count the sequence numbers skipped between successive packets of each cell.
fn event_gaps(payloads: &[Vec<u8>]) -> (u64, u64) {
    let mut last: HashMap<u16, u16> = HashMap::new();
    let (mut gaps, mut missing) = (0, 0);
    for p in payloads {
        let d = skinbox_protocol::DatagramRepr::parse(p).unwrap();
        let DatagramBody::Records(records) = d.body else {
            continue;
        };
        for r in records {
            if let Ok(CellRepr::Event(e)) = CellRepr::parse(&r.cell_packet, &CellFraming::DEFAULT) {
                if let Some(prev) = last.insert(e.cell_id, e.sequence) {
                    let skipped = e.sequence.wrapping_sub(prev).wrapping_sub(1);
                    if skipped > 0 {
                        gaps += 1;
                        missing += u64::from(skipped);
                    }
                }
            }
        }
    }
    (gaps, missing)
}

#[test]
fn nothing_lost_when_nothing_is_dropped() {
    let c = capture(1, 0);
    let payloads = c.payloads();
    let (r, records) = decode(&payloads);
    assert_eq!(records.len(), c.truth.len());
    let l = &r.losses;
    assert_eq!(
        (
            l.datagrams_missing,
            l.datagrams_duplicate,
            l.datagrams_reordered
        ),
        (0, 0, 0)
    );
    assert_eq!((l.event_sequence_gaps, l.event_packets_missing), (0, 0));
}

/// The decoder's cheap getters (for a progress line) say what its report says.
#[test]
fn the_getters_agree_with_the_report() {
    let c = capture(1, 0);
    let mut payloads = c.payloads();
    payloads.remove(5);
    payloads.remove(9);
    payloads[3].truncate(10);
    let mut d = Decoder::new(DecoderConfig::default());
    for p in &payloads {
        d.push_datagram(p, &mut ());
    }
    let r = d.report();
    assert!(r.losses.datagrams_missing >= 2, "{:?}", r.losses);
    assert_eq!(d.datagrams_missing(), r.losses.datagrams_missing);
    assert_eq!(r.bad_input.total, 1);
    assert_eq!(d.bad_input_total(), r.bad_input.total);
    assert_eq!(d.records(), r.records);
}

#[test]
fn dropped_datagrams_are_counted_exactly() {
    let c = capture(1, 0);
    let all = c.payloads();
    assert!(all.len() > 20, "{}", all.len());
    let dropped = [3usize, 7, 8, 9, 15];
    let kept: Vec<Vec<u8>> = all
        .iter()
        .enumerate()
        .filter(|(i, _)| !dropped.contains(i))
        .map(|(_, p)| p.clone())
        .collect();
    let (r, records) = decode(&kept);
    let l = &r.losses;
    assert_eq!(l.datagrams_missing, 5);
    assert_eq!(l.datagram_sequence_gaps, 3);
    assert_eq!(l.datagrams_duplicate, 0);
    assert_eq!(l.datagrams_reordered, 0);
    let lost_records: usize = dropped
        .iter()
        .map(|i| match &c.datagrams[*i].body {
            DatagramBody::Records(r) => r.len(),
            _ => 0,
        })
        .sum();
    assert_eq!(records.len(), c.truth.len() - lost_records);
    let (gaps, missing) = event_gaps(&kept);
    assert!(missing > 0, "the drops must hit event packets");
    assert_eq!(l.event_sequence_gaps, gaps);
    assert_eq!(l.event_packets_missing, missing);
}

#[test]
fn duplicates_are_counted_and_skipped() {
    let c = capture(1, 0);
    let mut payloads = c.payloads();
    let copy5 = payloads[5].clone();
    let copy2 = payloads[2].clone();
    payloads.insert(6, copy5.clone());
    payloads.insert(12, copy5);
    payloads.insert(20, copy2);
    let (r, records) = decode(&payloads);
    assert_eq!(r.losses.datagrams_duplicate, 3);
    assert_eq!(r.losses.datagrams_missing, 0);
    assert_eq!(r.losses.event_packets_missing, 0);
    assert_eq!(records.len(), c.truth.len());
}

#[test]
fn reordered_datagrams_are_not_lost() {
    let c = capture(1, 0);
    let mut payloads = c.payloads();
    payloads.swap(4, 5);
    let moved = payloads.remove(10);
    payloads.insert(14, moved); // 10 arrives after 11..=14
    let (r, records) = decode(&payloads);
    let l = &r.losses;
    assert_eq!(l.datagrams_missing, 0);
    assert_eq!(l.datagrams_reordered, 2);
    assert_eq!(l.datagram_sequence_gaps, 2);
    assert_eq!(l.datagrams_duplicate, 0);
    assert_eq!(records.len(), c.truth.len());
}

#[test]
fn sequence_numbers_wrap_without_loss() {
    let c = capture(1, u32::MAX - 5);
    let (r, records) = decode(&c.payloads());
    assert_eq!(r.losses.datagrams_missing, 0);
    assert_eq!(r.losses.sequence_restarts, 0);
    assert_eq!(records.len(), c.truth.len());
}

#[test]
fn box_reset_is_counted_from_the_boot_id() {
    let mut config = SyntheticConfig {
        cells: 20,
        samples_per_cell: 30,
        status_period_ticks: 2_500_000,
        boot_id: 0xaaaa_0001,
        first_sequence: 0,
        ..SyntheticConfig::default()
    };
    let before = synthetic::generate(&config).unwrap();
    // The box restarts: a new boot id, sequence numbers and counters from zero.
    config.boot_id = 0xbbbb_0002;
    config.seed = 2;
    let after = synthetic::generate(&config).unwrap();
    // The new boot's first status comes first (the box reports at reset).
    let mut payloads = before.payloads();
    let mut next = after.payloads();
    let first_status = after
        .datagrams
        .iter()
        .position(|d| matches!(d.body, DatagramBody::Status(_)))
        .unwrap();
    let s = next.remove(first_status);
    payloads.push(s);
    payloads.extend(next);
    let mut d = Decoder::new(DecoderConfig::default());
    let mut records = Vec::new();
    for p in &payloads {
        d.push_datagram(p, &mut records);
    }
    let r = d.report();
    assert_eq!(r.losses.box_resets, 1);
    assert_eq!(r.box_status.boot_ids, vec![0xaaaa_0001, 0xbbbb_0002]);
    // Out of order by design: the status moved ahead of the records it follows.
    assert_eq!(r.losses.datagrams_missing, 0, "{:?}", r.losses);
    assert_eq!(records.len(), before.truth.len() + after.truth.len());
}

#[derive(Default)]
struct Pairs {
    records: Vec<DecodedRecord>,
    samples: Vec<skinbox_host::Sample>,
}

impl skinbox_host::RecordSink for Pairs {
    fn record(&mut self, record: &DecodedRecord) {
        self.records.push(*record);
    }
    fn wants_samples(&self) -> bool {
        true
    }
    fn sample(&mut self, sample: &skinbox_host::Sample) {
        self.samples.push(*sample);
    }
}

#[test]
fn event_gaps_make_the_converter_mark_channels_stale() {
    let c = capture(1, 0);
    // drop the first datagram from the middle of the capture on that carries an event
    // packet (every event cell has sent before)
    let is_event = |p: &[u8; 20]| {
        matches!(
            CellRepr::parse(p, &CellFraming::DEFAULT),
            Ok(CellRepr::Event(_))
        )
    };
    let dropped = (c.datagrams.len() / 2..c.datagrams.len())
        .find(|&i| match &c.datagrams[i].body {
            DatagramBody::Records(records) => records.iter().any(|r| is_event(&r.cell_packet)),
            DatagramBody::Status(_) => false,
        })
        .expect("a datagram with an event packet");
    let kept: Vec<Vec<u8>> = c
        .payloads()
        .into_iter()
        .enumerate()
        .filter(|(i, _)| *i != dropped)
        .map(|(_, p)| p)
        .collect();
    let mut d = Decoder::new(DecoderConfig::default());
    let mut pairs = Pairs::default();
    for p in &kept {
        d.push_datagram(p, &mut pairs);
    }
    assert_eq!(pairs.records.len(), pairs.samples.len());
    let mut gapped = std::collections::HashSet::new();
    let mut stale_after_gap = 0;
    for (r, s) in pairs.records.iter().zip(&pairs.samples) {
        assert_eq!((r.cell.cell_id(), r.tick), (s.cell_id, s.tick));
        match &r.cell {
            CellRepr::Data(data) => {
                assert_eq!(s.raw, data.raw_values());
                assert!(!s.is_stale());
            }
            CellRepr::Event(e) => {
                for (ch, raw) in e.events() {
                    assert_eq!(s.raw[ch.index()], raw);
                    assert!(!s.stale.contains(ch));
                }
                if r.event_packets_missing_before > 0 {
                    gapped.insert(e.cell_id);
                    let want: skinbox_protocol::ChannelMask = s
                        .known
                        .iter()
                        .filter(|ch| !e.channels.contains(*ch))
                        .collect();
                    assert_eq!(s.stale, want);
                    stale_after_gap += 1;
                } else if !gapped.contains(&e.cell_id) {
                    assert!(!s.is_stale(), "cell {} never had a gap", e.cell_id);
                }
            }
        }
    }
    assert_eq!(stale_after_gap, d.report().losses.event_sequence_gaps);
    assert!(stale_after_gap > 0);
}

#[test]
fn duplicate_status_datagrams_are_skipped() {
    let c = synthetic::generate(&SyntheticConfig {
        cells: 10,
        samples_per_cell: 30,
        status_period_ticks: 2_500_000,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let mut payloads = c.payloads();
    let status_at = c
        .datagrams
        .iter()
        .position(|d| matches!(d.body, DatagramBody::Status(_)))
        .unwrap();
    let copy = payloads[status_at].clone();
    payloads.insert(status_at + 1, copy);
    let statuses = c
        .datagrams
        .iter()
        .filter(|d| matches!(d.body, DatagramBody::Status(_)))
        .count() as u64;
    let (r, _) = decode(&payloads);
    assert_eq!(r.status_datagrams, statuses);
    assert_eq!(r.box_status.status_reports, statuses);
    assert_eq!(r.losses.datagrams_duplicate, 1);
    assert_eq!(r.losses.datagrams_missing, 0);
}

#[test]
fn box_reset_before_its_status_arrives_loses_nothing() {
    let mut config = SyntheticConfig {
        cells: 20,
        samples_per_cell: 30,
        status_period_ticks: 2_500_000,
        boot_id: 0xaaaa_0001,
        ..SyntheticConfig::default()
    };
    let before = synthetic::generate(&config).unwrap();
    config.boot_id = 0xbbbb_0002;
    config.seed = 2;
    config.start_tick = 1_000; // the box's clock starts again too
    let after = synthetic::generate(&config).unwrap();
    // The box reports at reset; this one's reporter is late (an edit of the box's
    // capture): its first report goes after its first three records datagrams, the four
    // numbered in that order. So the new boot's first records datagrams reuse numbers 0..
    // that the old boot used, before the new boot's first status report says so.
    let mut next = after.datagrams.clone();
    assert!(matches!(next[0].body, DatagramBody::Status(_)));
    next[..4].rotate_left(1);
    for (n, d) in next[..4].iter_mut().enumerate() {
        d.sequence = n as u32;
    }
    let mut payloads = before.payloads();
    payloads.extend(next.iter().map(|d| d.to_bytes()));
    let (r, records) = decode(&payloads);
    assert_eq!(records.len(), before.truth.len() + after.truth.len());
    let l = &r.losses;
    assert_eq!(l.box_resets, 1);
    assert_eq!(l.sequence_restarts, 1);
    assert_eq!(l.datagrams_duplicate, 0);
    assert_eq!(l.datagrams_missing, 0);
}
