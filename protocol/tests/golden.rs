//! Golden byte arrays written by hand from docs/wire-format.md, checked against the views,
//! the parsers and the emitters (into poisoned buffers, so a forgotten field shows).

use skinbox_protocol::datagram::{DatagramBody, FLAG_FLUSH_TIMEOUT};
use skinbox_protocol::record::FLAG_LOSS_BEFORE;
use skinbox_protocol::status::PortCounter;
use skinbox_protocol::*;

/// Cell 0x0123: accel (3, -2, 256), force (1, 1024, 0), proximity 450, temperature 61, 0.
const DATA: [u8; 20] = [
    0xA1, 0x01, 0x23, 0x00, 0x03, 0xFF, 0xFE, 0x01, 0x00, 0x00, 0x01, 0x04, 0x00, 0x00, 0x00, 0x01,
    0xC2, 0x3D, 0x00, 0x55,
];
/// Cell 0x0042, one event: force 2 = 7, sequence 0x1234.
const EVENT_1: [u8; 20] = [
    0xA2, 0x00, 0x42, 0x00, 0x10, 0x00, 0x07, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x12, 0x34, 0x55,
];
/// Cell 0x3FFE, six events: accel x -6, accel z 262, force 1 3, proximity 2048,
/// temperature 1 62, temperature 2 1; sequence 0xFFFF.
const EVENT_6: [u8; 20] = [
    0xA2, 0x3F, 0xFE, 0x01, 0xCD, 0xFF, 0xFA, 0x01, 0x06, 0x00, 0x03, 0x08, 0x00, 0x00, 0x3E, 0x00,
    0x01, 0xFF, 0xFF, 0x55,
];
/// Cell 5, all nine channels fired with values 1..9, first sequence 0xFFFF: split in two.
const EVENT_9_FIRST: [u8; 20] = [
    0xA2, 0x00, 0x05, 0x00, 0x3F, 0x00, 0x01, 0x00, 0x02, 0x00, 0x03, 0x00, 0x04, 0x00, 0x05, 0x00,
    0x06, 0xFF, 0xFF, 0x55,
];
const EVENT_9_SECOND: [u8; 20] = [
    0xA2, 0x00, 0x05, 0x81, 0xC0, 0x00, 0x07, 0x00, 0x08, 0x00, 0x09, 0, 0, 0, 0, 0, 0, 0x00, 0x00,
    0x55,
];

fn records_datagram() -> Vec<u8> {
    let mut b = vec![
        b'S', b'K', 1, 1, // magic, version 1, kind records
        0x01, 0x02, 8, 0x01, // box id 0x0102, 8 ports, flushed by timeout
        0x01, 0x02, 0x03, 0x04, // sequence
        0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x00, // base tick 2^32
        0x00, 0x02, 0x00, 0x00, // 2 records, reserved
        3, 0x00, 0x00, 0x00, 0x00, 0x00, // port 3, no flags, offset 0
    ];
    b.extend_from_slice(&DATA);
    b.extend_from_slice(&[7, 0x01, 0xFF, 0xFF, 0xFF, 0xFB]); // port 7, loss before, -5
    b.extend_from_slice(&EVENT_1);
    b
}

fn status_datagram() -> Vec<u8> {
    let mut b = vec![
        b'S', b'K', 1, 2, // magic, version 1, kind status
        0x00, 0x01, 4, 0x00, // box id 1, 4 ports, no flags
        0x00, 0x00, 0x00, 0x07, // sequence 7
        0x00, 0x00, 0x00, 0x00, 0x07, 0x73, 0x59, 0x40, // tick 125,000,000 (1 s)
        0x00, 0x02, 0x00, 0x00, // 2 port blocks, reserved
        0xDE, 0xAD, 0xBE, 0xEF, // boot id
        0x00, 0x00, 0x00, 0x0A, // 10 records datagrams sent
        0x00, 0x00, 0x02, 0x26, // 550 records sent
        2, 0, 0, 0, // first port 2, reserved
    ];
    for port in 0..2u32 {
        for counter in 0..8u32 {
            b.extend_from_slice(&(port * 0x0100_0000 + counter + 1).to_be_bytes());
        }
    }
    b
}

fn poisoned_emit(len: usize, emit: impl FnOnce(&mut [u8])) -> Vec<u8> {
    let mut b = vec![0xA5; len];
    emit(&mut b);
    b
}

#[test]
fn data_packet_golden() {
    let repr = DataRepr::parse(&DATA).unwrap();
    assert_eq!(
        repr,
        DataRepr {
            cell_id: 0x0123,
            accel: [3, -2, 256],
            force: [1, 1024, 0],
            proximity: 450,
            temperature: [61, 0],
        }
    );
    let view = data::DataPacket::new_checked(&DATA[..]).unwrap();
    assert_eq!(view.raw(Channel::AccelY), -2);
    assert_eq!(view.raw(Channel::Proximity), 450);
    assert_eq!(Channel::AccelZ.to_units(view.raw(Channel::AccelZ)), 1.0);
    assert_eq!(
        Channel::Temperature1.to_units(view.raw(Channel::Temperature1)),
        30.5
    );
    assert_eq!(poisoned_emit(20, |b| repr.emit(b)), DATA);
    assert_eq!(
        DataRepr::from_raw(0x0123, [3, -2, 256, 1, 1024, 0, 450, 61, 0]).unwrap(),
        repr
    );
}

#[test]
fn event_packet_with_one_event_golden() {
    let repr = EventRepr::parse(&EVENT_1).unwrap();
    assert_eq!(repr.cell_id, 0x42);
    assert_eq!(repr.sequence, 0x1234);
    assert!(!repr.second_part);
    assert_eq!(
        repr.events().collect::<Vec<_>>(),
        vec![(Channel::Force2, 7)]
    );
    let built = EventRepr::new(0x42, 0x1234, false, &[(Channel::Force2, 7)]).unwrap();
    assert_eq!(built, repr);
    assert_eq!(poisoned_emit(20, |b| built.emit(b)), EVENT_1);
}

#[test]
fn event_packet_with_six_events_golden() {
    let events = [
        (Channel::AccelX, -6),
        (Channel::AccelZ, 262),
        (Channel::Force1, 3),
        (Channel::Proximity, 2048),
        (Channel::Temperature1, 62),
        (Channel::Temperature2, 1),
    ];
    let (first, second) = EventRepr::split(0x3FFE, 0xFFFF, &events).unwrap();
    assert_eq!(second, None);
    assert_eq!(poisoned_emit(20, |b| first.emit(b)), EVENT_6);
    let parsed = EventRepr::parse(&EVENT_6).unwrap();
    assert_eq!(parsed, first);
    assert_eq!(parsed.events().collect::<Vec<_>>(), events);
}

#[test]
fn event_packet_with_nine_events_splits_in_two_golden() {
    let events: Vec<_> = Channel::ALL.iter().zip(1..).map(|(c, v)| (*c, v)).collect();
    let (first, second) = EventRepr::split(5, 0xFFFF, &events).unwrap();
    let second = second.expect("seven or more events need a second packet");
    assert_eq!(poisoned_emit(20, |b| first.emit(b)), EVENT_9_FIRST);
    assert_eq!(poisoned_emit(20, |b| second.emit(b)), EVENT_9_SECOND);
    assert!(EventRepr::parse(&EVENT_9_SECOND).unwrap().second_part);
    assert_eq!(EventRepr::parse(&EVENT_9_SECOND).unwrap().sequence, 0);
    let rejoined: Vec<_> = EventRepr::parse(&EVENT_9_FIRST)
        .unwrap()
        .events()
        .chain(EventRepr::parse(&EVENT_9_SECOND).unwrap().events())
        .collect();
    assert_eq!(rejoined, events);
}

#[test]
fn seven_events_split_six_and_one() {
    let events: Vec<_> = Channel::ALL[..7].iter().map(|c| (*c, 1)).collect();
    let (first, second) = EventRepr::split(1, 10, &events).unwrap();
    assert_eq!(first.channels.len(), 6);
    let second = second.unwrap();
    assert_eq!(
        second.events().collect::<Vec<_>>(),
        vec![(Channel::Proximity, 1)]
    );
    assert_eq!(second.sequence, 11);
}

#[test]
fn records_datagram_golden() {
    let bytes = records_datagram();
    let repr = DatagramRepr::parse(&bytes).unwrap();
    assert_eq!(repr.box_id, 0x0102);
    assert_eq!(repr.port_count, 8);
    assert_eq!(repr.flags, FLAG_FLUSH_TIMEOUT);
    assert_eq!(repr.sequence, 0x0102_0304);
    assert_eq!(repr.base_tick, 1 << 32);
    let DatagramBody::Records(records) = &repr.body else {
        panic!("expected records, got {:?}", repr.body)
    };
    assert_eq!(records.len(), 2);
    assert_eq!(
        (records[0].port, records[0].flags, records[0].tick_offset),
        (3, 0, 0)
    );
    assert_eq!(records[0].cell_packet, DATA);
    assert_eq!(records[1].port, 7);
    assert_eq!(records[1].flags, FLAG_LOSS_BEFORE);
    assert_eq!(records[1].tick(repr.base_tick), (1 << 32) - 5);
    assert_eq!(
        CellRepr::parse(&records[1].cell_packet, &CellFraming::DEFAULT).unwrap(),
        CellRepr::Event(EventRepr::parse(&EVENT_1).unwrap())
    );
    assert_eq!(repr.buffer_len(), 76);
    assert_eq!(poisoned_emit(76, |b| repr.emit(b)), bytes);

    let view = datagram::Datagram::new_checked(&bytes[..]).unwrap();
    assert_eq!(view.kind(), DatagramKind::Records);
    let ports: Vec<u8> = view.records().map(|r| r.port()).collect();
    assert_eq!(ports, vec![3, 7]);
}

#[test]
fn status_datagram_golden() {
    let bytes = status_datagram();
    let repr = DatagramRepr::parse(&bytes).unwrap();
    assert_eq!(repr.kind(), DatagramKind::Status);
    assert_eq!(repr.base_tick, 125_000_000);
    let DatagramBody::Status(status) = &repr.body else {
        panic!("expected status, got {:?}", repr.body)
    };
    assert_eq!(status.boot_id, 0xDEAD_BEEF);
    assert_eq!(status.datagrams_sent, 10);
    assert_eq!(status.records_sent, 550);
    assert_eq!(status.first_port, 2);
    assert_eq!(status.ports.len(), 2);
    assert_eq!(status.ports[0].get(PortCounter::PacketsGood), 1);
    assert_eq!(status.ports[0].get(PortCounter::Resyncs), 8);
    assert_eq!(
        status.ports[1].get(PortCounter::DroppedOverflow),
        0x0100_0002
    );
    assert_eq!(poisoned_emit(bytes.len(), |b| repr.emit(b)), bytes);
}

#[test]
fn full_datagram_fits_one_ethernet_frame() {
    assert_eq!(datagram::MAX_RECORDS, 55);
    assert_eq!(DatagramKind::Records.payload_len(55), 1454);
    assert_eq!(datagram::MAX_STATUS_PORTS, 44);
    assert!(DatagramKind::Status.payload_len(44) <= datagram::MAX_PAYLOAD_LEN);
}

#[test]
fn display_shows_physical_units() {
    let text = DataRepr::parse(&DATA).unwrap().to_string();
    assert!(text.contains("+1.0000"), "{text}");
    assert!(text.contains("30.5"), "{text}");
    let text = DatagramRepr::parse(&records_datagram())
        .unwrap()
        .to_string();
    assert!(
        text.contains("2 records") && text.contains("port  7"),
        "{text}"
    );
}
