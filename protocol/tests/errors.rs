//! Every truncation and every wrong fixed byte gives its own error naming the format.

use skinbox_protocol::*;

fn data() -> [u8; 20] {
    DataRepr {
        cell_id: 9,
        ..Default::default()
    }
    .to_bytes()
}

fn event() -> [u8; 20] {
    EventRepr::new(9, 1, false, &[(Channel::Proximity, 4)])
        .unwrap()
        .to_bytes()
}

fn records(n: usize) -> Vec<u8> {
    DatagramRepr {
        box_id: 1,
        port_count: 4,
        flags: 0,
        sequence: 1,
        base_tick: 99,
        body: datagram::DatagramBody::Records(
            (0..n)
                .map(|i| RecordRepr {
                    port: (i % 4) as u8,
                    flags: 0,
                    tick_offset: i as i32,
                    cell_packet: data(),
                })
                .collect(),
        ),
    }
    .to_bytes()
}

fn status(ports: usize) -> Vec<u8> {
    DatagramRepr {
        box_id: 1,
        port_count: 4,
        flags: 0,
        sequence: 2,
        base_tick: 99,
        body: datagram::DatagramBody::Status(StatusRepr {
            boot_id: 5,
            datagrams_sent: 1,
            records_sent: 2,
            first_port: 0,
            ports: vec![PortCounters::default(); ports],
        }),
    }
    .to_bytes()
}

fn assert_truncated(err: Error, format: Format, required: usize, actual: usize) {
    assert_eq!(
        err,
        Error::Truncated {
            format,
            required,
            actual
        }
    );
    let text = err.to_string();
    assert!(text.starts_with(&format.to_string()), "{text}");
    assert!(
        text.contains(&format!("needs {required} bytes, got {actual}")),
        "{text}"
    );
}

#[test]
fn every_truncation_of_cell_packets() {
    for len in 0..20 {
        let e = DataRepr::parse(&data()[..len]).unwrap_err();
        assert_truncated(e, Format::DataPacket, 20, len);
        let e = EventRepr::parse(&event()[..len]).unwrap_err();
        assert_truncated(e, Format::EventPacket, 20, len);
        let e = CellRepr::parse(&event()[..len], &CellFraming::DEFAULT).unwrap_err();
        assert_truncated(e, Format::CellPacket, 20, len);
    }
}

#[test]
fn every_truncation_of_records_and_counters() {
    let r = records(1);
    for len in 0..26 {
        let e = RecordRepr::parse(&r[24..24 + len]).unwrap_err();
        assert_truncated(e, Format::Record, 26, len);
    }
    let s = status(1);
    for len in 0..32 {
        let e = PortCounters::parse(&s[40..40 + len]).unwrap_err();
        assert_truncated(e, Format::PortCounters, 32, len);
    }
}

#[test]
fn every_truncation_of_datagrams() {
    for n in [0, 1, 3, datagram::MAX_RECORDS] {
        let full = records(n);
        assert_eq!(full.len(), 24 + 26 * n);
        for len in 0..full.len() {
            let e = DatagramRepr::parse(&full[..len]).unwrap_err();
            let required = if len < 24 { 24 } else { full.len() };
            assert_truncated(e, Format::Datagram, required, len);
        }
    }
    for n in [0, 2, 4] {
        let full = status(n);
        for len in 0..full.len() {
            let e = DatagramRepr::parse(&full[..len]).unwrap_err();
            let (format, required) = if len < 24 {
                (Format::Datagram, 24)
            } else {
                (Format::Status, full.len())
            };
            assert_truncated(e, format, required, len);
        }
    }
}

#[test]
fn trailing_bytes_are_a_length_mismatch() {
    let mut b = records(2);
    b.push(0);
    assert_eq!(
        DatagramRepr::parse(&b),
        Err(Error::LengthMismatch {
            format: Format::Datagram,
            required: 76,
            actual: 77
        })
    );
}

#[test]
fn wrong_fixed_bytes_give_distinct_errors() {
    let mut b = data();
    b[0] = 0xA0;
    let header = DataRepr::parse(&b).unwrap_err();
    assert!(
        matches!(header, Error::BadHeader { found: 0xA0, .. }),
        "{header}"
    );

    let mut b = data();
    b[19] = 0x54;
    let end = DataRepr::parse(&b).unwrap_err();
    assert_eq!(
        end,
        Error::BadEndOfPacket {
            format: Format::DataPacket,
            found: 0x54,
            expected: 0x55
        }
    );

    let mut b = event();
    b[1] = 0x40;
    let id = EventRepr::parse(&b).unwrap_err();
    assert_eq!(
        id,
        Error::BadCellId {
            format: Format::EventPacket,
            found: 0x4009
        }
    );

    // A data packet where an event packet is expected, and the other way round.
    assert!(matches!(
        EventRepr::parse(&data()),
        Err(Error::BadHeader { found: 0xA1, .. })
    ));
    assert!(matches!(
        DataRepr::parse(&event()),
        Err(Error::BadHeader { found: 0xA2, .. })
    ));

    let mut b = records(1);
    b[1] = b'X';
    let magic = DatagramRepr::parse(&b).unwrap_err();
    assert_eq!(magic, Error::BadMagic { found: *b"SX" });

    let mut b = records(1);
    b[2] = 2;
    let version = DatagramRepr::parse(&b).unwrap_err();
    assert_eq!(
        version,
        Error::UnsupportedVersion {
            found: 2,
            supported: 1
        }
    );

    let mut b = records(1);
    b[3] = 9;
    let kind = DatagramRepr::parse(&b).unwrap_err();
    assert_eq!(kind, Error::UnknownKind { found: 9 });

    let all = [header, end, id, magic, version, kind];
    let texts: std::collections::HashSet<_> = all.iter().map(|e| e.to_string()).collect();
    assert_eq!(texts.len(), all.len());
}

#[test]
fn bad_event_masks_are_rejected() {
    let cases = [
        (0x0200u16, "reserved"),
        (0x0000, "no channel"),
        (0x007F, "more than six"),
    ];
    for (mask, why) in cases {
        let mut b = event();
        b[3..5].copy_from_slice(&mask.to_be_bytes());
        let err = EventRepr::parse(&b).unwrap_err();
        assert!(
            matches!(err, Error::BadEventMask { mask: m, .. } if m == mask),
            "{err}"
        );
        assert!(err.to_string().contains(why), "{err}");
    }
}

#[test]
fn ports_beyond_the_port_count_are_rejected() {
    let mut b = records(1);
    b[24] = 4; // first record's port, the box has 4
    assert_eq!(
        DatagramRepr::parse(&b),
        Err(Error::BadPort {
            format: Format::Record,
            port: 4,
            port_count: 4
        })
    );
    let mut b = status(2);
    b[24 + 12] = 3; // first port 3 with two blocks: port 4 does not exist
    assert!(matches!(
        DatagramRepr::parse(&b),
        Err(Error::BadPort { port: 4, .. })
    ));
}

#[test]
fn too_many_entries_are_rejected() {
    let mut b = records(0);
    b[20..22].copy_from_slice(&56u16.to_be_bytes());
    assert_eq!(
        DatagramRepr::parse(&b),
        Err(Error::TooManyEntries {
            format: Format::Datagram,
            count: 56,
            max: 55
        })
    );
}

#[test]
fn events_must_be_ordered_and_in_range() {
    let unordered = [(Channel::Force1, 1), (Channel::AccelX, 1)];
    assert!(matches!(
        EventRepr::new(1, 0, false, &unordered),
        Err(Error::BadEvents { .. })
    ));
    assert!(matches!(
        EventRepr::new(1, 0, false, &[(Channel::Proximity, 70_000)]),
        Err(Error::ValueOutOfRange {
            channel: Channel::Proximity,
            ..
        })
    ));
    assert!(matches!(
        DataRepr::from_raw(1, [0, 0, 0, 0, 0, 0, 0, 256, 0]),
        Err(Error::ValueOutOfRange {
            channel: Channel::Temperature1,
            ..
        })
    ));
    assert!(EventRepr::split(1, 0, &[]).is_err());
}
