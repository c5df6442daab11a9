//! The decoder's policy for bad records (a bad record rejects only itself, counted by
//! reason), status reports counted per report, `first_tick` as the earliest record, and
//! split samples of exactly two event packets.

use skinbox_host::bad_input::{FormatFault, Reason};
use skinbox_host::{DecodedRecord, Decoder, DecoderConfig};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{
    Channel, DataRepr, DatagramRepr, EventRepr, PortCounters, RecordRepr, StatusRepr,
};

fn record(port: u8, flags: u8, tick_offset: i32, cell_id: u16) -> RecordRepr {
    RecordRepr {
        port,
        flags,
        tick_offset,
        cell_packet: DataRepr {
            cell_id,
            ..DataRepr::default()
        }
        .to_bytes(),
    }
}

fn records_datagram(sequence: u32, base_tick: u64, records: Vec<RecordRepr>) -> Vec<u8> {
    DatagramRepr {
        box_id: 3,
        port_count: 4,
        flags: 0,
        sequence,
        base_tick,
        body: DatagramBody::Records(records),
    }
    .to_bytes()
}

#[test]
fn a_bad_record_rejects_only_itself() {
    let mut bad_end = record(1, 0, 20, 12);
    bad_end.cell_packet[19] = 0x54;
    let mut bad_accel = record(1, 0, 30, 13);
    bad_accel.cell_packet[3..5].copy_from_slice(&512i16.to_be_bytes());
    let payload = records_datagram(
        0,
        1_000,
        vec![
            record(0, 0, 0, 10),
            record(4, 0, 10, 11), // port 4 of a 4-port box
            bad_end,
            bad_accel,
            record(3, 0x02, 40, 14), // undefined flag bit
            record(3, 0x01, 50, 15), // the limits themselves: port 3, flag bit 0
        ],
    );
    let mut decoder = Decoder::new(DecoderConfig::default());
    let mut records: Vec<DecodedRecord> = Vec::new();
    decoder.push_datagram(&payload, &mut records);
    let ids: Vec<u16> = records.iter().map(|r| r.cell.cell_id()).collect();
    assert_eq!(ids, vec![10, 15]);
    let r = decoder.report();
    let bad = &r.bad_input;
    assert_eq!(bad.total, 4, "{bad:?}");
    assert_eq!(bad.get(Reason::Record(FormatFault::BadPort)), 1);
    assert_eq!(bad.get(Reason::Record(FormatFault::BadEndOfPacket)), 1);
    assert_eq!(bad.get(Reason::Record(FormatFault::ValueOutOfRange)), 1);
    assert_eq!(bad.get(Reason::Record(FormatFault::BadFlags)), 1);
    assert!(
        bad.examples
            .iter()
            .any(|e| e.contains("accel_x") && e.contains("512")),
        "{:?}",
        bad.examples
    );
    assert_eq!(r.records_datagrams, 1);
    assert_eq!(r.losses.records_flagged_loss_before.get(&3), Some(&1));
}

#[test]
fn a_bad_header_rejects_the_datagram() {
    let mut payload = records_datagram(0, 1_000, vec![record(0, 0, 0, 10)]);
    payload[6] = 65; // port count
    let mut decoder = Decoder::new(DecoderConfig::default());
    let mut records: Vec<DecodedRecord> = Vec::new();
    decoder.push_datagram(&payload, &mut records);
    payload[6] = 64;
    payload[7] = 0x02; // header flags
    decoder.push_datagram(&payload, &mut records);
    assert!(records.is_empty());
    let bad = decoder.report().bad_input;
    assert_eq!(bad.get(Reason::Datagram(FormatFault::BadPortCount)), 1);
    assert_eq!(bad.get(Reason::Datagram(FormatFault::BadFlags)), 1);
}

fn status_datagram(sequence: u32, base_tick: u64, first_port: u8, ports: usize) -> Vec<u8> {
    DatagramRepr {
        box_id: 3,
        port_count: 64,
        flags: 0,
        sequence,
        base_tick,
        body: DatagramBody::Status(StatusRepr {
            boot_id: 9,
            datagrams_sent: sequence,
            records_sent: 0,
            first_port,
            ports: vec![PortCounters::default(); ports],
        }),
    }
    .to_bytes()
}

#[test]
fn a_report_of_two_datagrams_counts_once() {
    let mut decoder = Decoder::new(DecoderConfig::default());
    // Two reports of a 64-port box, 44 + 20 ports each, at two report times.
    for (i, tick) in [12_500_000u64, 25_000_000].into_iter().enumerate() {
        let seq = 2 * i as u32;
        decoder.push_datagram(&status_datagram(seq, tick, 0, 44), &mut ());
        decoder.push_datagram(&status_datagram(seq + 1, tick, 44, 20), &mut ());
    }
    let r = decoder.report();
    assert_eq!(r.box_status.status_reports, 2);
    assert_eq!(r.box_status.status_datagrams, 4);
    assert_eq!(r.status_datagrams, 4);
    assert_eq!(r.box_status.last_counters.len(), 64);
    assert_eq!(r.losses.datagrams_missing, 0);
}

#[test]
fn first_tick_is_the_earliest_record() {
    let mut decoder = Decoder::new(DecoderConfig::default());
    // The second datagram holds a record that started before every record of the first.
    decoder.push_datagram(
        &records_datagram(0, 10_000, vec![record(0, 0, 0, 1), record(1, 0, 500, 2)]),
        &mut (),
    );
    decoder.push_datagram(
        &records_datagram(1, 11_000, vec![record(2, 0, 0, 3), record(3, 0, -4_000, 4)]),
        &mut (),
    );
    let r = decoder.report();
    assert_eq!(r.first_tick, 7_000);
    assert_eq!(r.last_tick, 11_000);
    assert_eq!(r.boxes[0].first_tick, 7_000);
}

/// A split sample has exactly two packets: a run of second parts with consecutive sequence
/// numbers pairs up (the first with its first part, then two by two), never adding up
/// past one pair, and the last unpaired packet is a pending sample of its own.
#[test]
fn a_run_of_second_parts_pairs_up() {
    let event = |sequence: u16, second_part: bool, channels: usize| RecordRepr {
        port: 0,
        flags: 0,
        tick_offset: i32::from(sequence) * 1_000,
        cell_packet: EventRepr::new(
            5,
            sequence,
            second_part,
            &Channel::ALL[..channels]
                .iter()
                .map(|c| (*c, 0))
                .collect::<Vec<_>>(),
        )
        .unwrap()
        .to_bytes(),
    };
    // A first part of six channels, then 300 second parts of three channels each.
    let packets: Vec<RecordRepr> = std::iter::once(event(0, false, 6))
        .chain((1..=300).map(|s| event(s, true, 3)))
        .collect();
    let mut decoder = Decoder::new(DecoderConfig::default());
    let mut records = Vec::new();
    for (i, chunk) in packets.chunks(20).enumerate() {
        decoder.push_datagram(
            &records_datagram(i as u32, 1_000_000, chunk.to_vec()),
            &mut records,
        );
    }
    assert_eq!(records.len(), 301);
    let r = decoder.report();
    assert_eq!(r.bad_input.total, 0);
    assert_eq!(r.event_packets, 301);
    assert_eq!(r.losses.event_sequence_gaps, 0);
    // (0, 1): 6 + 3 channels; (2, 3) .. (298, 299): 3 + 3; 300 alone: 3.
    let mut expected = vec![0u64; 9];
    expected[9 - 1] = 1;
    expected[6 - 1] = 149;
    expected[3 - 1] = 1;
    assert_eq!(r.fired_together_histogram, expected);
}
