//! What docs/wire-format.md forbids is refused, each field on both sides of its limit:
//! accepted at the limit, refused just past it, with an error naming the field.

use skinbox_protocol::data::DataPacket;
use skinbox_protocol::datagram::{Datagram, DatagramBody, MAX_PORTS};
use skinbox_protocol::event::EventPacket;
use skinbox_protocol::record::Record;
use skinbox_protocol::*;

fn records_datagram(port_count: u8, flags: u8, port: u8, record_flags: u8) -> Vec<u8> {
    DatagramRepr {
        box_id: 1,
        port_count,
        flags,
        sequence: 1,
        base_tick: 99,
        body: DatagramBody::Records(vec![RecordRepr {
            port,
            flags: record_flags,
            tick_offset: 0,
            cell_packet: DataRepr::default().to_bytes(),
        }]),
    }
    .to_bytes()
}

#[test]
fn port_count_is_1_to_64() {
    for ok in [1, 2, MAX_PORTS] {
        assert!(
            DatagramRepr::parse(&records_datagram(ok, 0, 0, 0)).is_ok(),
            "{ok}"
        );
    }
    for bad in [0, MAX_PORTS + 1, 255] {
        let err = DatagramRepr::parse(&records_datagram(bad, 0, 0, 0)).unwrap_err();
        assert_eq!(
            err,
            Error::BadPortCount {
                found: bad,
                max: 64
            }
        );
        assert!(err.to_string().contains("port count"), "{err}");
    }
}

#[test]
fn datagram_flags_other_than_bit_0_are_refused() {
    assert!(DatagramRepr::parse(&records_datagram(4, 0x01, 0, 0)).is_ok());
    for bad in [0x02, 0x04, 0x80, 0x03] {
        assert_eq!(
            DatagramRepr::parse(&records_datagram(4, bad, 0, 0)),
            Err(Error::BadFlags {
                format: Format::Datagram,
                found: bad,
                defined: 0x01
            })
        );
    }
}

#[test]
fn a_status_datagram_may_say_the_box_sends_time_syncs_and_no_more() {
    let status = |flags: u8| {
        DatagramRepr {
            box_id: 1,
            port_count: 4,
            flags,
            sequence: 1,
            base_tick: 99,
            body: DatagramBody::Status(StatusRepr {
                boot_id: 7,
                datagrams_sent: 0,
                records_sent: 0,
                first_port: 0,
                ports: vec![],
            }),
        }
        .to_bytes()
    };
    let parsed = DatagramRepr::parse(&status(datagram::FLAG_TIME_SYNCS)).unwrap();
    assert_eq!(parsed.flags, 0x04);
    for bad in [0x08, 0x80] {
        assert_eq!(
            DatagramRepr::parse(&status(bad)),
            Err(Error::BadFlags {
                format: Format::Datagram,
                found: bad,
                defined: 0x07
            })
        );
    }
}

#[test]
fn record_port_and_flags_are_checked_per_record() {
    let ok = records_datagram(4, 0, 3, 0x01);
    assert!(DatagramRepr::parse(&ok).is_ok());
    let d = Datagram::new_checked(&ok[..]).unwrap();
    assert_eq!(d.records().next().unwrap().check(4), Ok(()));

    // The datagram header stays valid; the record is what is wrong.
    let bad_port = records_datagram(4, 0, 4, 0);
    let d = Datagram::new_checked(&bad_port[..]).unwrap();
    let err = d
        .records()
        .next()
        .unwrap()
        .check(d.port_count())
        .unwrap_err();
    assert_eq!(
        err,
        Error::BadPort {
            format: Format::Record,
            port: 4,
            port_count: 4
        }
    );
    let bad_flags = records_datagram(4, 0, 0, 0x02);
    let r = Record::new_checked(&bad_flags[24..]).unwrap();
    assert_eq!(
        r.check(4),
        Err(Error::BadFlags {
            format: Format::Record,
            found: 0x02,
            defined: 0x01
        })
    );
}

fn data_with_accel(axis: usize, raw: i32) -> [u8; 20] {
    let mut b = DataRepr::default().to_bytes();
    let at = 3 + 2 * axis;
    b[at..at + 2].copy_from_slice(&(raw as i16).to_be_bytes());
    b
}

#[test]
fn data_accelerations_are_10_bit_signed() {
    for axis in 0..3 {
        let channel = Channel::ALL[axis];
        for ok in [-512, -1, 0, 511] {
            let b = data_with_accel(axis, ok);
            let d = DataRepr::parse(&b).unwrap();
            assert_eq!(d.raw(channel), ok);
            // The view and the decoder's path agree.
            assert_eq!(DataPacket::new_checked(&b[..]).unwrap().raw(channel), ok);
            assert_eq!(
                CellRepr::parse(&b, &CellFraming::DEFAULT),
                Ok(CellRepr::Data(d))
            );
        }
        for bad in [-513, 512, i32::from(i16::MIN), i32::from(i16::MAX)] {
            let b = data_with_accel(axis, bad);
            let err = DataRepr::parse(&b).unwrap_err();
            assert_eq!(DataPacket::new_checked(&b[..]).unwrap_err(), err);
            assert_eq!(CellRepr::parse(&b, &CellFraming::DEFAULT), Err(err));
            assert_eq!(
                err,
                Error::ValueOutOfRange {
                    format: Format::DataPacket,
                    channel,
                    value: bad,
                    min: -512,
                    max: 511
                }
            );
            assert!(err.to_string().contains(channel.name()), "{err}");
        }
    }
    // Built from values, the same limits hold.
    assert!(DataRepr::from_raw(1, [511, -512, 0, 0, 0, 0, 0, 0, 0]).is_ok());
    assert!(DataRepr::from_raw(1, [512, 0, 0, 0, 0, 0, 0, 0, 0]).is_err());
}

fn event_bytes(mask: u16, words: [u16; 6]) -> [u8; 20] {
    let mut b = EventRepr::new(3, 7, false, &[(Channel::Proximity, 1)])
        .unwrap()
        .to_bytes();
    b[3..5].copy_from_slice(&mask.to_be_bytes());
    for (i, w) in words.iter().enumerate() {
        b[5 + 2 * i..7 + 2 * i].copy_from_slice(&w.to_be_bytes());
    }
    b
}

#[test]
fn event_accelerations_are_10_bit_signed() {
    // Mask: accel_z alone, and accel_x with force_1.
    for (mask, slot) in [(0b100u16, 0usize), (0b1001, 0)] {
        for ok in [-512i32, 511] {
            let mut words = [0u16; 6];
            words[slot] = ok as i16 as u16;
            let e = EventRepr::parse(&event_bytes(mask, words)).unwrap();
            assert_eq!(e.events().next().unwrap().1, ok);
        }
        for bad in [-513i32, 512] {
            let mut words = [0u16; 6];
            words[slot] = bad as i16 as u16;
            let b = event_bytes(mask, words);
            let err = EventRepr::parse(&b).unwrap_err();
            assert_eq!(EventPacket::new_checked(&b[..]).unwrap_err(), err);
            assert_eq!(CellRepr::parse(&b, &CellFraming::DEFAULT), Err(err));
            assert!(
                matches!(err, Error::ValueOutOfRange { format: Format::EventPacket, value, min: -512, max: 511, .. } if value == bad),
                "{err}"
            );
        }
    }
    assert!(EventRepr::new(1, 0, false, &[(Channel::AccelY, -512)]).is_ok());
    assert!(EventRepr::new(1, 0, false, &[(Channel::AccelY, -513)]).is_err());
}

#[test]
fn unused_event_value_slots_are_0() {
    // Two channels (force_1, force_2): slots 3..6 must be 0.
    let mask = 0b11000;
    assert!(EventRepr::parse(&event_bytes(mask, [5, 6, 0, 0, 0, 0])).is_ok());
    for slot in 2..6 {
        let mut words = [5, 6, 0, 0, 0, 0];
        words[slot] = 1;
        let err = EventRepr::parse(&event_bytes(mask, words)).unwrap_err();
        assert_eq!(
            err,
            Error::UnusedValueSet {
                slot,
                used: 2,
                word: 1
            }
        );
        assert!(
            err.to_string().contains(&format!("value_{}", slot + 1)),
            "{err}"
        );
    }
    // Six channels use every slot.
    let six = 0b1_1111_1000;
    assert!(EventRepr::parse(&event_bytes(six, [1, 2, 3, 4, 5, 6])).is_ok());
}
