//! Decoding frames built independently: etherparse's PacketBuilder for Ethernet/IPv4/UDP,
//! pcap-file's writer for the file, the format crate's emitters for the payloads.

use etherparse::PacketBuilder;
use pcap_file::pcap::{PcapPacket, PcapWriter};
use skinbox_cosim::synthetic::{self, SyntheticConfig};
use skinbox_host::bad_input::{FormatFault, FrameFault, Reason};
use skinbox_host::other_traffic::OtherKind;
use skinbox_host::pcap::{decode_pcap_bytes, PcapOptions};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{CellFraming, CellRepr, DatagramRepr};
use std::time::Duration;

const BOX_PORT: u16 = 5_000;

fn udp_frame(src_port: u16, dst_port: u16, payload: &[u8]) -> Vec<u8> {
    let b = PacketBuilder::ethernet2([2, 0, 0, 0, 0, 2], [2, 0, 0, 0, 0, 1])
        .ipv4([192, 0, 2, 10], [192, 0, 2, 1], 64)
        .udp(src_port, dst_port);
    let mut v = Vec::new();
    b.write(&mut v, payload).unwrap();
    v
}

fn tcp_frame(payload: &[u8]) -> Vec<u8> {
    let b = PacketBuilder::ethernet2([2, 0, 0, 0, 0, 2], [2, 0, 0, 0, 0, 1])
        .ipv4([192, 0, 2, 10], [192, 0, 2, 1], 64)
        .tcp(BOX_PORT, 80, 1, 1024);
    let mut v = Vec::new();
    b.write(&mut v, payload).unwrap();
    v
}

fn pcap_of(frames: &[Vec<u8>]) -> Vec<u8> {
    let mut w = PcapWriter::new(Vec::new()).unwrap();
    for (i, f) in frames.iter().enumerate() {
        let p = PcapPacket::new(
            Duration::from_micros(1_000 + i as u64),
            f.len() as u32,
            &f[..],
        )
        .unwrap();
        w.write_packet(&p).unwrap();
    }
    w.into_inner()
}

#[test]
fn every_record_decodes_to_what_was_emitted() {
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 40,
        samples_per_cell: 30,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let mut frames: Vec<Vec<u8>> = capture
        .payloads()
        .iter()
        .map(|p| udp_frame(BOX_PORT, 6_000, p))
        .collect();
    // Ethernet padding and a trailing FCS do not change the payload.
    frames[0].extend_from_slice(&[0xde, 0xad, 0xbe, 0xef]);
    let decoded = decode_pcap_bytes(&pcap_of(&frames), &PcapOptions::default()).unwrap();

    assert_eq!(decoded.records.len(), capture.truth.len());
    for (got, want) in decoded.records.iter().zip(&capture.truth) {
        assert_eq!(got.datagram_sequence, want.datagram_sequence);
        assert_eq!(got.tick, want.tick);
        assert_eq!(got.port, want.record.port);
        assert_eq!(got.flags, want.record.flags);
        assert_eq!(
            got.cell.to_bytes(&CellFraming::DEFAULT),
            want.record.cell_packet
        );
        assert_eq!(
            got.cell,
            CellRepr::parse(&want.record.cell_packet, &CellFraming::DEFAULT).unwrap()
        );
    }
    let r = &decoded.report;
    assert_eq!(r.records, capture.truth.len() as u64);
    assert_eq!(r.data_packets, capture.data_packets);
    assert_eq!(r.event_packets, capture.event_packets);
    assert_eq!(r.cells_active, 40);
    assert_eq!(r.bad_input.total, 0);
    assert_eq!(r.losses.datagrams_missing, 0);
    assert_eq!(r.losses.event_packets_missing, 0);
    assert_eq!(r.frames.frames, frames.len() as u64);
    // Data-mode cells send every sample: 20 cells x 30 samples.
    assert_eq!(capture.data_packets, 20 * 30);
    // Event histogram sums to the event packets.
    assert_eq!(
        r.events_per_packet_histogram.iter().sum::<u64>(),
        capture.event_packets
    );
}

#[test]
fn bad_input_is_counted_by_reason() {
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 8,
        samples_per_cell: 10,
        status_period_ticks: 0,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let good = capture.payloads();
    let mut frames: Vec<Vec<u8>> = good.iter().map(|p| udp_frame(BOX_PORT, 6_000, p)).collect();
    let sample = good[0].clone();

    let mut bad_magic = sample.clone();
    bad_magic[0] = b'X';
    let mut bad_version = sample.clone();
    bad_version[2] = 9;
    let mut bad_kind = sample.clone();
    bad_kind[3] = 7;
    let truncated = sample[..sample.len() - 3].to_vec();
    let mut bad_cell = sample.clone();
    // The first record's cell packet starts at 24 + 6: break its end-of-packet byte.
    bad_cell[24 + 6 + 19] = 0x00;
    // A fresh sequence number so the datagram is not a duplicate.
    bad_cell[8..12].copy_from_slice(&1_000u32.to_be_bytes());

    frames.push(udp_frame(BOX_PORT, 6_000, &bad_magic));
    frames.push(udp_frame(BOX_PORT, 6_000, &bad_version));
    frames.push(udp_frame(BOX_PORT, 6_000, &bad_kind));
    frames.push(udp_frame(BOX_PORT, 6_000, &truncated));
    frames.push(udp_frame(BOX_PORT, 6_000, &bad_cell));
    frames.push(tcp_frame(&sample));
    frames.push(udp_frame(BOX_PORT, 6_000, &[])); // empty payload
    frames.push(vec![0xff; 10]); // not even an Ethernet header
    let mut file = pcap_of(&frames);
    // One more packet record whose data is cut off: a truncated file.
    let extra = pcap_of(&[udp_frame(BOX_PORT, 6_000, &sample)]);
    file.extend_from_slice(&extra[24..extra.len() - 100]);

    let d = decode_pcap_bytes(&file, &PcapOptions::default()).unwrap();
    let b = &d.report.bad_input;
    let by = |reason: Reason| b.get(reason);
    assert_eq!(
        by(Reason::Datagram(FormatFault::UnsupportedVersion)),
        1,
        "{b:?}"
    );
    assert_eq!(by(Reason::Datagram(FormatFault::UnknownKind)), 1, "{b:?}");
    assert_eq!(by(Reason::Datagram(FormatFault::Truncated)), 1, "{b:?}");
    assert_eq!(by(Reason::Record(FormatFault::BadEndOfPacket)), 1, "{b:?}");
    assert_eq!(by(Reason::Frame(FrameFault::Malformed)), 1, "{b:?}");
    assert_eq!(by(Reason::PcapTruncated), 1, "{b:?}");
    assert_eq!(b.total, 6);
    // Without the magic "SK" (a wrong first byte, an empty payload) and over TCP, a frame
    // is someone else's: other traffic, not bad input.
    let other = &d.report.other_traffic;
    assert_eq!(other.get(OtherKind::UdpNotSkinbox), 2, "{other:?}");
    assert_eq!(other.get(OtherKind::Tcp), 1, "{other:?}");
    assert_eq!(other.total, 3);
    // The good records all arrived, plus the bad datagram's other records.
    let bad_cell_records = capture.datagrams[0].to_bytes().len() / 26 - 1;
    assert_eq!(
        d.records.len(),
        capture.truth.len() + bad_cell_records,
        "{:?}",
        d.report.losses
    );
}

#[test]
fn port_filter_skips_other_traffic() {
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 4,
        samples_per_cell: 5,
        status_period_ticks: 0,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let mut frames: Vec<Vec<u8>> = capture
        .payloads()
        .iter()
        .map(|p| udp_frame(BOX_PORT, 6_000, p))
        .collect();
    frames.push(udp_frame(53, 53, b"not a box datagram: other traffic"));
    let file = pcap_of(&frames);
    let options = PcapOptions {
        udp_port: Some(BOX_PORT),
        ..PcapOptions::default()
    };
    let d = decode_pcap_bytes(&file, &options).unwrap();
    assert_eq!(d.report.other_traffic.get(OtherKind::UdpService("DNS")), 1);
    assert_eq!(d.report.bad_input.total, 0);
    assert_eq!(d.records.len(), capture.truth.len());
    // Without the filter, the DNS payload is still not a skinbox datagram (no magic).
    let d = decode_pcap_bytes(&file, &PcapOptions::default()).unwrap();
    assert_eq!(d.report.bad_input.total, 0);
    assert_eq!(d.report.other_traffic.get(OtherKind::UdpService("DNS")), 1);
    assert_eq!(d.records.len(), capture.truth.len());
}

#[test]
fn status_datagrams_give_counter_deltas() {
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 16,
        samples_per_cell: 40,
        status_period_ticks: 2_500_000,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let statuses: Vec<_> = capture
        .datagrams
        .iter()
        .filter_map(|d| match &d.body {
            DatagramBody::Status(s) => Some(s.clone()),
            _ => None,
        })
        .collect();
    assert!(statuses.len() >= 3);
    let frames: Vec<Vec<u8>> = capture
        .payloads()
        .iter()
        .map(|p| udp_frame(BOX_PORT, 6_000, p))
        .collect();
    let d = decode_pcap_bytes(&pcap_of(&frames), &PcapOptions::default()).unwrap();
    let (first, last) = (&statuses[0], statuses.last().unwrap());
    let s = &d.report.box_status;
    assert_eq!(s.status_reports, statuses.len() as u64);
    assert_eq!(
        s.records_sent_delta,
        u64::from(last.records_sent - first.records_sent)
    );
    for port in 0..8u8 {
        let want = last.ports[usize::from(port)].0[0] - first.ports[usize::from(port)].0[0];
        assert_eq!(s.counter_deltas[&port]["packets_good"], u64::from(want));
    }
    assert_eq!(d.report.losses.box_packets_lost, 0);
    assert_eq!(d.report.losses.box_resets, 0);
}

#[test]
fn datagram_repr_roundtrip_through_frames() {
    // A hand-made datagram, emitted by the format crate, decoded through the whole path.
    use skinbox_protocol::{Channel, DataRepr, EventRepr, RecordRepr};
    let data = DataRepr::from_raw(17, [2, -3, 258, 1, 0, 2, 310, 61, 0]).unwrap();
    let event = EventRepr::new(17, 41, false, &[(Channel::Force1, 212)]).unwrap();
    let d = DatagramRepr {
        box_id: 3,
        port_count: 8,
        flags: 0,
        sequence: 77,
        base_tick: 1_000_000,
        body: DatagramBody::Records(vec![
            RecordRepr {
                port: 2,
                flags: 0,
                tick_offset: -50,
                cell_packet: data.to_bytes(),
            },
            RecordRepr {
                port: 2,
                flags: 1,
                tick_offset: 6_250,
                cell_packet: event.to_bytes(),
            },
        ]),
    };
    let file = pcap_of(&[udp_frame(BOX_PORT, 6_000, &d.to_bytes())]);
    let out = decode_pcap_bytes(&file, &PcapOptions::default()).unwrap();
    assert_eq!(out.records.len(), 2);
    assert_eq!(out.records[0].tick, 999_950);
    assert_eq!(out.records[0].cell, CellRepr::Data(data));
    assert_eq!(out.records[1].tick, 1_006_250);
    assert_eq!(out.records[1].time_s(), 1_006_250.0 * 8e-9);
    assert_eq!(out.records[1].cell, CellRepr::Event(event));
    assert_eq!(out.records[1].box_id, 3);
    assert_eq!(out.report.losses.records_flagged_loss_before[&2], 1);
    assert_eq!(
        out.report.events_per_packet_histogram,
        vec![1, 0, 0, 0, 0, 0]
    );
}

#[test]
fn corrupted_payload_with_stale_checksum_is_refused_and_counted() {
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 40,
        samples_per_cell: 10,
        status_period_ticks: 0,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let payloads = capture.payloads();
    assert!(payloads.len() >= 4);
    let mut frames: Vec<Vec<u8>> = payloads
        .iter()
        .map(|p| udp_frame(BOX_PORT, 6_000, p))
        .collect();
    // Frame 1: a bit of a record's cell value flipped after the checksum was computed.
    // The datagram still parses (its value is in range), so only the checksum can tell.
    let at = 14 + 20 + 8 + 24 + 6 + 9; // force_1 low byte of the first record
    frames[1][at] ^= 0x01;
    let corrupted = frames[1][34 + 8..].to_vec();
    assert!(DatagramRepr::parse(&corrupted).is_ok());
    // Frame 2: the IPv4 header's TTL changed, its checksum stale.
    frames[2][22] ^= 0x20;
    let decoded = decode_pcap_bytes(&pcap_of(&frames), &PcapOptions::default()).unwrap();
    let bad = &decoded.report.bad_input;
    assert_eq!(
        bad.get(Reason::Frame(FrameFault::BadUdpChecksum)),
        1,
        "{bad:?}"
    );
    assert_eq!(
        bad.get(Reason::Frame(FrameFault::BadIpv4Checksum)),
        1,
        "{bad:?}"
    );
    assert_eq!(bad.total, 2);
    // Nothing of either frame was decoded: the records are those of the other frames.
    let records_in = |p: &[u8]| match DatagramRepr::parse(p).unwrap().body {
        DatagramBody::Records(r) => r.len(),
        DatagramBody::Status(_) => 0,
    };
    let expected: usize = payloads
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != 1 && *i != 2)
        .map(|(_, p)| records_in(p))
        .sum();
    assert_eq!(decoded.records.len(), expected);
    let sequences: Vec<u32> = decoded
        .records
        .iter()
        .map(|r| r.datagram_sequence)
        .collect();
    assert!(!sequences.contains(&1) && !sequences.contains(&2));
    assert_eq!(decoded.report.losses.datagrams_missing, 2);
}

#[test]
fn linux_cooked_captures_decode_like_ethernet() {
    // `tcpdump -i any` on older systems: Linux cooked capture v1 (link type 113), a
    // 16-byte header in place of the Ethernet header.
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 10,
        samples_per_cell: 10,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let ethernet: Vec<Vec<u8>> = capture
        .payloads()
        .iter()
        .map(|p| udp_frame(BOX_PORT, 6_000, p))
        .collect();
    let header = pcap_file::pcap::PcapHeader {
        datalink: pcap_file::DataLink::LINUX_SLL,
        ..pcap_file::pcap::PcapHeader::default()
    };
    let mut w = PcapWriter::with_header(Vec::new(), header).unwrap();
    for (i, f) in ethernet.iter().enumerate() {
        // packet type 1 (broadcast), ARPHRD_ETHER, 6-byte address padded to 8, IPv4.
        let mut sll = vec![0, 1, 0, 1, 0, 6, 2, 0, 0, 0, 0, 2, 0, 0, 0x08, 0x00];
        sll.extend_from_slice(&f[14..]);
        let p =
            PcapPacket::new(Duration::from_micros(i as u64), sll.len() as u32, &sll[..]).unwrap();
        w.write_packet(&p).unwrap();
    }
    let cooked = decode_pcap_bytes(&w.into_inner(), &PcapOptions::default()).unwrap();
    let plain = decode_pcap_bytes(&pcap_of(&ethernet), &PcapOptions::default()).unwrap();
    assert_eq!(
        cooked.report.bad_input.total, 0,
        "{:?}",
        cooked.report.bad_input
    );
    assert_eq!(cooked.records.len(), capture.truth.len());
    assert_eq!(cooked.records, plain.records);
}
