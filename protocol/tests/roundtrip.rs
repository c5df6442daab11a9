//! parse(emit(x)) == x for every format, and no input makes a parser panic.

use proptest::prelude::*;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::*;

fn data_repr() -> impl Strategy<Value = DataRepr> {
    (
        0..=cell::CELL_ID_MAX,
        proptest::array::uniform3(-512i16..=511),
        any::<[u16; 3]>(),
        any::<u16>(),
        any::<[u8; 2]>(),
    )
        .prop_map(|(cell_id, accel, force, proximity, temperature)| DataRepr {
            cell_id,
            accel,
            force,
            proximity,
            temperature,
        })
}

fn event_repr() -> impl Strategy<Value = EventRepr> {
    (
        0..=cell::CELL_ID_MAX,
        any::<u16>(),
        any::<bool>(),
        proptest::sample::subsequence(Channel::ALL.to_vec(), 1..=6),
        any::<[u16; 6]>(),
    )
        .prop_map(|(id, seq, second, channels, words)| {
            let events: Vec<_> = channels
                .iter()
                .zip(words)
                .map(|(c, w)| {
                    let range = c.word_range();
                    let span = range.end() - range.start() + 1;
                    (*c, range.start() + c.decode_word(w).rem_euclid(span))
                })
                .collect();
            EventRepr::new(id, seq, second, &events).unwrap()
        })
}

fn cell_bytes() -> impl Strategy<Value = [u8; 20]> {
    prop_oneof![
        data_repr().prop_map(|d| d.to_bytes()),
        event_repr().prop_map(|e| e.to_bytes()),
        any::<[u8; 20]>(),
    ]
}

fn datagram_repr() -> impl Strategy<Value = DatagramRepr> {
    let header = (any::<u16>(), 1u8..=64, 0u8..=1, any::<u32>(), any::<u64>());
    let records = proptest::collection::vec(
        (any::<u8>(), 0u8..=1, any::<i32>(), cell_bytes()),
        0..=datagram::MAX_RECORDS + 5,
    );
    let status = (
        any::<u32>(),
        any::<u32>(),
        any::<u32>(),
        any::<u8>(),
        proptest::collection::vec(any::<[u32; 8]>(), 0..=datagram::MAX_STATUS_PORTS + 5),
    );
    (header, any::<bool>(), records, status).prop_map(
        |((box_id, port_count, flags, sequence, base_tick), is_status, records, status)| {
            let body = if is_status {
                let (boot_id, datagrams_sent, records_sent, first, ports) = status;
                let n = ports.len().min(usize::from(port_count));
                let first_port = first % (port_count - n as u8 + 1);
                DatagramBody::Status(StatusRepr {
                    boot_id,
                    datagrams_sent,
                    records_sent,
                    first_port,
                    ports: ports[..n].iter().map(|p| PortCounters(*p)).collect(),
                })
            } else {
                DatagramBody::Records(
                    records
                        .into_iter()
                        .map(|(port, flags, tick_offset, cell_packet)| RecordRepr {
                            port: port % port_count,
                            flags,
                            tick_offset,
                            cell_packet,
                        })
                        .collect(),
                )
            };
            DatagramRepr {
                box_id,
                port_count,
                flags,
                sequence,
                base_tick,
                body,
            }
        },
    )
}

/// `repr` with the entries past the most one datagram holds taken off: the oracle for what
/// an over-full datagram emits, counted from the format's limits, not from the emitter.
fn capped(mut repr: DatagramRepr) -> DatagramRepr {
    match &mut repr.body {
        DatagramBody::Records(records) => records.truncate(55),
        DatagramBody::Status(status) => status.ports.truncate(44),
    }
    repr
}

proptest! {
    #[test]
    fn data_roundtrip(repr in data_repr()) {
        prop_assert_eq!(DataRepr::parse(&repr.to_bytes()), Ok(repr));
        prop_assert_eq!(DataRepr::from_raw(repr.cell_id, repr.raw_values()), Ok(repr));
    }

    #[test]
    fn event_roundtrip(repr in event_repr()) {
        prop_assert_eq!(EventRepr::parse(&repr.to_bytes()), Ok(repr));
        prop_assert_eq!(
            CellRepr::parse(&repr.to_bytes(), &CellFraming::DEFAULT),
            Ok(CellRepr::Event(repr))
        );
    }

    #[test]
    fn split_keeps_every_event(
        channels in proptest::sample::subsequence(Channel::ALL.to_vec(), 1..=9),
        seq in any::<u16>(),
    ) {
        let events: Vec<_> = channels.iter().map(|c| (*c, c.index() as i32 + 100)).collect();
        let (first, second) = EventRepr::split(3, seq, &events).unwrap();
        let mut back: Vec<_> = first.events().collect();
        if let Some(s) = second {
            prop_assert!(s.second_part && s.sequence == seq.wrapping_add(1));
            back.extend(s.events());
        }
        prop_assert_eq!(back, events);
    }

    #[test]
    fn datagram_roundtrip(repr in datagram_repr()) {
        let bytes = repr.to_bytes();
        prop_assert_eq!(bytes.len(), repr.buffer_len());
        prop_assert!(bytes.len() <= datagram::MAX_PAYLOAD_LEN);
        // An over-full body is written up to the most one datagram holds.
        prop_assert_eq!(DatagramRepr::parse(&bytes), Ok(capped(repr)));
    }

    #[test]
    fn cell_parse_agrees_with_the_packet_views(
        bytes in cell_bytes(),
        at in 0usize..20,
        value in any::<u8>(),
        mutate in any::<bool>(),
    ) {
        let mut bytes = bytes;
        if mutate {
            bytes[at] = value;
        }
        // The decoder's one-pass parse against the checked views, which check the same
        // rules their own way.
        match CellRepr::parse(&bytes, &CellFraming::DEFAULT) {
            Ok(CellRepr::Data(d)) => {
                prop_assert_eq!(DataRepr::parse(&bytes), Ok(d));
                prop_assert!(data::DataPacket::new_checked(&bytes[..]).is_ok());
            }
            Ok(CellRepr::Event(e)) => {
                prop_assert_eq!(EventRepr::parse(&bytes), Ok(e));
                prop_assert!(event::EventPacket::new_checked(&bytes[..]).is_ok());
            }
            Err(_) => {
                prop_assert!(DataRepr::parse(&bytes).is_err());
                prop_assert!(EventRepr::parse(&bytes).is_err());
                prop_assert!(data::DataPacket::new_checked(&bytes[..]).is_err());
                prop_assert!(event::EventPacket::new_checked(&bytes[..]).is_err());
            }
        }
    }

    #[test]
    fn parsers_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..1600)) {
        let _ = DatagramRepr::parse(&bytes);
        let _ = CellRepr::parse(&bytes, &CellFraming::DEFAULT);
        let _ = RecordRepr::parse(&bytes);
        let _ = PortCounters::parse(&bytes);
    }

    #[test]
    fn mutated_datagrams_never_panic(
        repr in datagram_repr(),
        at in any::<prop::sample::Index>(),
        value in any::<u8>(),
    ) {
        let mut bytes = repr.to_bytes();
        let i = at.index(bytes.len());
        bytes[i] = value;
        // Reserved bytes are ignored on input, so compare what was parsed.
        if let Ok(d) = DatagramRepr::parse(&bytes) {
            prop_assert_eq!(DatagramRepr::parse(&d.to_bytes()), Ok(d));
        }
    }
}

/// An over-full datagram: 56 records or 45 port blocks. The bytes are the header and the
/// first 55 records (24 + 55 x 26 = 1454) or the first 44 blocks (24 + 16 + 44 x 32 = 1448),
/// the entry count says so, and they parse.
#[test]
fn over_full_datagrams_are_written_up_to_the_limit() {
    let record = |i: usize| RecordRepr {
        port: (i % 8) as u8,
        flags: 0,
        tick_offset: i as i32,
        cell_packet: [i as u8; 20],
    };
    let records = DatagramRepr {
        box_id: 1,
        port_count: 8,
        flags: 0,
        sequence: 7,
        base_tick: 1000,
        body: DatagramBody::Records((0..56).map(record).collect()),
    };
    let status = DatagramRepr {
        port_count: 64,
        body: DatagramBody::Status(StatusRepr {
            boot_id: 5,
            datagrams_sent: 1,
            records_sent: 2,
            first_port: 0,
            ports: (0..45).map(|p| PortCounters([p; 8])).collect(),
        }),
        ..records.clone()
    };
    for (repr, len, count) in [(records, 1454, 55u16), (status, 1448, 44)] {
        let bytes = repr.to_bytes();
        assert_eq!(repr.buffer_len(), len);
        assert_eq!(bytes.len(), len);
        assert_eq!(bytes[20..22], count.to_be_bytes());
        assert_eq!(repr.written_entries(), usize::from(count));
        let parsed = DatagramRepr::parse(&bytes).expect("an over-full datagram parses");
        assert_eq!(parsed, capped(repr));
    }
}

#[test]
fn datagram_kind_names_are_their_json_names() {
    use skinbox_protocol::DatagramKind;
    for kind in DatagramKind::ALL {
        assert_eq!(
            serde_json::to_value(kind).unwrap(),
            serde_json::Value::from(kind.name())
        );
    }
    assert_eq!(DatagramKind::ALL.map(|k| k as u8), [1, 2]);
}
