//! Captures of a real network: the box's datagrams among other traffic, commands and
//! acknowledgements judged as strictly as records, two boxes that share an id, and the
//! sequence accounting of refused datagrams. Frames are built with etherparse.

use etherparse::PacketBuilder;
use skinbox_host::bad_input::{FormatFault, FrameFault, Reason};
use skinbox_host::decoder::DatagramOutcome;
use skinbox_host::other_traffic::OtherKind;
use skinbox_host::output::{sort_by_host_time, RowFormat, RowKind, RowWriter};
use skinbox_host::pcap::{decode_pcap_bytes, decode_pcap_with, PcapFrameWriter, PcapOptions};
use skinbox_host::sample_clock::{PathModel, Positions};
use skinbox_host::timing::Timing;
use skinbox_host::Decoder;
use skinbox_protocol::box_counters::{BoxCounters, BOX_COUNTERS_LEN};
use skinbox_protocol::command::{
    ack_field, AckReply, AckRepr, AckResult, CommandRepr, Destination, Opcode, Request, HEADER_LEN,
};
use skinbox_protocol::datagram::{DatagramBody, FLAG_BOX_COUNTERS};
use skinbox_protocol::{DataRepr, DatagramRepr, RecordRepr, StatusRepr};
use std::time::Duration;

const BOX_MAC: [u8; 6] = [0x02, 0x53, 0x4b, 0, 0, 1];
const HOST_MAC: [u8; 6] = [0x02, 0, 0, 0, 0, 1];
const BOX_IP: [u8; 4] = [192, 0, 2, 10];
const HOST_IP: [u8; 4] = [192, 0, 2, 1];
const PORT: u16 = 54091;

fn udp(src: ([u8; 4], u16), dst: ([u8; 4], u16), payload: &[u8]) -> Vec<u8> {
    let b = PacketBuilder::ethernet2(BOX_MAC, HOST_MAC)
        .ipv4(src.0, dst.0, 64)
        .udp(src.1, dst.1);
    let mut f = Vec::new();
    b.write(&mut f, payload).unwrap();
    f
}

fn records(box_id: u16, sequence: u32, base_tick: u64, cells: &[(u16, i32)]) -> Vec<u8> {
    DatagramRepr {
        box_id,
        port_count: 4,
        flags: 0,
        sequence,
        base_tick,
        body: DatagramBody::Records(
            cells
                .iter()
                .map(|&(cell, offset)| RecordRepr {
                    port: 1,
                    flags: 0,
                    tick_offset: offset,
                    cell_packet: DataRepr::from_raw(cell, [1, 2, 3, 4, 5, 6, 7, 8, 9])
                        .unwrap()
                        .to_bytes(),
                })
                .collect(),
        ),
    }
    .to_bytes()
}

fn status(box_id: u16, sequence: u32, base_tick: u64) -> DatagramRepr {
    DatagramRepr {
        box_id,
        port_count: 4,
        flags: 0,
        sequence,
        base_tick,
        body: DatagramBody::Status(StatusRepr {
            boot_id: 0x5eed,
            datagrams_sent: sequence,
            records_sent: 0,
            first_port: 0,
            ports: vec![Default::default(); 4],
        }),
    }
}

fn ack(result: AckResult, opcode: Opcode, reply: AckReply) -> AckRepr {
    AckRepr {
        box_id: 1,
        port_count: 4,
        sequence: 77,
        host_time: 123_456,
        opcode: opcode as u8,
        result,
        last_accepted: if matches!(result, AckResult::Replay | AckResult::OtherBox) {
            80
        } else {
            77
        },
        receive_tick: 1_000,
        send_tick: 1_100,
        reply,
    }
}

fn pcap(frames: &[(Duration, Vec<u8>)]) -> Vec<u8> {
    let mut w = PcapFrameWriter::new(Vec::new()).unwrap();
    for (t, f) in frames {
        w.write_frame(*t, f).unwrap();
    }
    w.finish().unwrap()
}

/// Frames of a lab network that are not the box's, each with its kind.
fn other_frames() -> Vec<(Vec<u8>, OtherKind)> {
    let mut out = Vec::new();
    // ARP request for the box's address
    let arp = etherparse::ArpPacket::new(
        etherparse::ArpHardwareId::ETHERNET,
        etherparse::EtherType::IPV4,
        etherparse::ArpOperation::REQUEST,
        &HOST_MAC,
        &HOST_IP,
        &[0; 6],
        &BOX_IP,
    )
    .unwrap();
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, [0xFF; 6])
        .arp(arp)
        .write(&mut f)
        .unwrap();
    out.push((f, OtherKind::Arp));
    // TCP (an SSH session) with a checksum left to the NIC: zero, wrong on the wire
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, BOX_MAC)
        .ipv4(HOST_IP, [192, 0, 2, 20], 64)
        .tcp(50_000, 22, 1, 64_000)
        .write(&mut f, b"SSH-2.0-x")
        .unwrap();
    let tcp_checksum = 14 + 20 + 16;
    f[tcp_checksum..tcp_checksum + 2].copy_from_slice(&[0, 0]);
    out.push((f, OtherKind::Tcp));
    // LLDP from a switch
    let mut f = vec![
        0x01, 0x80, 0xC2, 0, 0, 0x0E, 0x02, 0, 0, 0, 0, 9, 0x88, 0xCC,
    ];
    f.extend_from_slice(&[0x02, 0x07, 0x04, 0x02, 0, 0, 0, 0, 9, 0, 0]);
    f.resize(60, 0);
    out.push((f, OtherKind::Lldp));
    // mDNS over IPv4 (a payload that even begins with "SK" is not ours with a port filter)
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, [0x01, 0, 0x5E, 0, 0, 0xFB])
        .ipv4(HOST_IP, [224, 0, 0, 251], 255)
        .udp(5353, 5353)
        .write(&mut f, &[0u8; 40])
        .unwrap();
    out.push((f, OtherKind::UdpService("mDNS")));
    // mDNS over IPv6
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, [0x33, 0x33, 0, 0, 0, 0xFB])
        .ipv6([0xFE; 16], [0xFF; 16], 255)
        .udp(5353, 5353)
        .write(&mut f, &[0u8; 30])
        .unwrap();
    out.push((f, OtherKind::Ipv6));
    // ICMPv6 neighbour solicitation
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, [0x33, 0x33, 0xFF, 0, 0, 1])
        .ipv6([0xFE; 16], [0xFF; 16], 255)
        .icmpv6_echo_request(1, 1)
        .write(&mut f, &[0u8; 8])
        .unwrap();
    out.push((f, OtherKind::Ipv6));
    // ping of the box
    let mut f = Vec::new();
    PacketBuilder::ethernet2(HOST_MAC, BOX_MAC)
        .ipv4(HOST_IP, BOX_IP, 64)
        .icmpv4_echo_request(1, 2)
        .write(&mut f, &[0u8; 32])
        .unwrap();
    out.push((f, OtherKind::Icmp));
    // UDP of another application, payload without the magic
    out.push((
        udp((HOST_IP, 40_000), ([192, 0, 2, 30], 9_999), b"hello"),
        OtherKind::UdpNotSkinbox,
    ));
    out
}

#[test]
fn a_mixed_capture_has_no_bad_input_and_names_the_other_traffic() {
    let others = other_frames();
    let mut frames = Vec::new();
    let mut sequence = 0;
    for round in 0..5u64 {
        for (f, _) in &others {
            frames.push(f.clone());
        }
        let tick = 1_000_000 * (round + 1);
        let payload = records(1, sequence, tick, &[(5, 0), (6, 40)]);
        frames.push(udp((BOX_IP, PORT), (HOST_IP, PORT), &payload));
        sequence += 1;
        let s = status(1, sequence, tick + 100).to_bytes();
        frames.push(udp((BOX_IP, PORT), (HOST_IP, PORT), &s));
        sequence += 1;
        // a command and its acknowledgement, both ways
        let c = CommandRepr {
            box_id: 1,
            sequence: 77,
            host_time: 123_456,
            request: Request::ReadTick,
        };
        frames.push(udp((HOST_IP, PORT), (BOX_IP, PORT), &c.to_bytes()));
        let a = ack(AckResult::Ok, Opcode::ReadTick, AckReply::None).to_bytes();
        frames.push(udp((BOX_IP, PORT), (HOST_IP, PORT), &a));
    }
    let timed: Vec<(Duration, Vec<u8>)> = frames
        .into_iter()
        .enumerate()
        .map(|(i, f)| (Duration::from_micros(1_000 + i as u64 * 10), f))
        .collect();
    let bytes = pcap(&timed);
    for port in [None, Some(PORT)] {
        let d = decode_pcap_bytes(
            &bytes,
            &PcapOptions {
                udp_port: port,
                ..Default::default()
            },
        )
        .unwrap();
        let r = &d.report;
        assert_eq!(r.bad_input.total, 0, "{port:?}: {:?}", r.bad_input);
        assert_eq!(r.records, 10);
        assert_eq!(r.status_datagrams, 5);
        assert_eq!((r.commands, r.acknowledgements), (5, 5));
        assert_eq!(r.acknowledgements_by_result.get("ok"), Some(&5));
        assert_eq!(r.losses.datagrams_missing, 0);
        let mut want = std::collections::BTreeMap::new();
        for (_, kind) in &others {
            *want.entry(*kind).or_insert(0u64) += 5;
        }
        if port.is_some() {
            // the other application's UDP is on another port
            let n = want.remove(&OtherKind::UdpNotSkinbox).unwrap();
            want.insert(OtherKind::UdpOtherPort, n);
        }
        assert_eq!(r.other_traffic.by_kind, want, "{port:?}");
        assert_eq!(r.other_traffic.total, 5 * others.len() as u64);
        assert_eq!(r.frames.frames, 5 * (others.len() as u64 + 4));
        // in JSON and in the summary, by name
        let json = serde_json::to_value(r).unwrap();
        assert_eq!(json["other_traffic"]["by_kind"]["ARP"], 5);
        assert_eq!(json["other_traffic"]["by_kind"]["UDP mDNS"], 5);
        assert_eq!(json["bad_input"]["total"], 0);
        let summary = r.summary();
        assert!(summary.contains("bad input: 0\n"), "{summary}");
        assert!(
            summary
                .contains("other traffic: 40 (ARP 5, LLDP 5, IPv6 10, TCP 5, ICMP 5, UDP mDNS 5"),
            "{summary}"
        );
    }
}

#[test]
fn a_skinbox_frame_with_a_stale_checksum_is_bad_input_and_other_traffic_is_not() {
    let payload = records(1, 0, 1_000, &[(5, 0)]);
    let mut bad = udp((BOX_IP, PORT), (HOST_IP, PORT), &payload);
    *bad.last_mut().unwrap() ^= 1;
    // a DNS reply with the same kind of damage is someone else's business
    let mut dns = udp(([192, 0, 2, 53], 53), (HOST_IP, 40_000), &[0u8; 20]);
    *dns.last_mut().unwrap() ^= 1;
    let bytes = pcap(&[
        (Duration::from_millis(1), bad),
        (Duration::from_millis(2), dns),
    ]);
    let r = decode_pcap_bytes(&bytes, &PcapOptions::default())
        .unwrap()
        .report;
    assert_eq!(r.bad_input.total, 1);
    assert_eq!(
        r.bad_input.get(Reason::Frame(FrameFault::BadUdpChecksum)),
        1
    );
    assert_eq!(r.other_traffic.get(OtherKind::UdpService("DNS")), 1);
}

/// Each malformed acknowledgement with the reason it is refused for.
fn malformed_acks() -> Vec<(&'static str, Vec<u8>, FormatFault)> {
    let good = ack(AckResult::Ok, Opcode::ReadTick, AckReply::None).to_bytes();
    let mut out = Vec::new();
    let mut b = good.clone();
    b[HEADER_LEN + ack_field::RESULT] = 6;
    out.push(("result 6", b, FormatFault::BadField));
    let mut b = good.clone();
    b.push(0);
    b[21] = 25;
    out.push(("body length 25", b, FormatFault::LengthMismatch));
    let mut b = good.clone();
    b[ack_field::PORT_COUNT] = 0;
    out.push(("port count 0", b, FormatFault::BadPortCount));
    let mut b = good.clone();
    b[7] = 0x80;
    out.push(("flag bits set", b, FormatFault::BadFlags));
    let mut b = good.clone();
    b[23] = 1;
    out.push(("header reserved set", b, FormatFault::BadField));
    let mut b = good.clone();
    b[HEADER_LEN + 3] = 1;
    out.push(("body reserved set", b, FormatFault::BadField));
    let b = good[..HEADER_LEN].to_vec();
    out.push(("body missing", b, FormatFault::LengthMismatch));
    let mut b = good[..HEADER_LEN].to_vec();
    b[20..22].fill(0);
    out.push(("body missing, length 0", b, FormatFault::Truncated));
    let b = ack(AckResult::Ok, Opcode::StatusNow, AckReply::None).to_bytes();
    out.push((
        "status now ok without its counters",
        b,
        FormatFault::LengthMismatch,
    ));
    let mut b = ack(
        AckResult::Ok,
        Opcode::StatusNow,
        AckReply::Counters(BoxCounters::default()),
    )
    .to_bytes();
    b[HEADER_LEN + 24] = 2; // link_up 2
    out.push(("counters with link_up 2", b, FormatFault::BadField));
    let b = ack(
        AckResult::Replay,
        Opcode::StreamTo,
        AckReply::Destination(Destination {
            mac: [0; 6],
            ip: [1, 2, 3, 4],
            port: 5,
        }),
    )
    .to_bytes();
    out.push(("replay with a destination", b, FormatFault::LengthMismatch));
    let b = ack(AckResult::DownlinkFull, Opcode::ReadTick, AckReply::None).to_bytes();
    out.push(("downlink_full of a read tick", b, FormatFault::BadField));
    let b = ack(AckResult::UnknownOpcode, Opcode::ReadTick, AckReply::None).to_bytes();
    out.push(("unknown_opcode of a known opcode", b, FormatFault::BadField));
    let mut b = good.clone();
    b[HEADER_LEN + ack_field::OPCODE] = 99;
    out.push(("ok of an unknown opcode", b, FormatFault::BadField));
    let mut b = good.clone();
    b[HEADER_LEN + 7] ^= 1;
    out.push((
        "ok, last accepted not the sequence",
        b,
        FormatFault::BadField,
    ));
    let mut b = good;
    b[2] = 2;
    out.push(("version 2", b, FormatFault::UnsupportedVersion));
    out
}

#[test]
fn malformed_acknowledgements_and_commands_are_refused_with_their_reason() {
    let mut d = Decoder::default();
    let cases = malformed_acks();
    for (what, bytes, fault) in &cases {
        let before = d.bad_input_mut().get(Reason::Ack(*fault));
        assert_eq!(
            d.push_datagram(bytes, &mut ()),
            DatagramOutcome::Rejected,
            "{what}"
        );
        assert_eq!(
            d.bad_input_mut().get(Reason::Ack(*fault)),
            before + 1,
            "{what}"
        );
    }
    assert_eq!(d.acknowledgements(), 0);
    assert_eq!(d.bad_input_total(), cases.len() as u64);
    // the well-formed ones of every reply length: 24, 36 and 24 + the counter block
    let good = [
        ack(AckResult::Ok, Opcode::ReadTick, AckReply::None),
        ack(
            AckResult::Ok,
            Opcode::StreamTo,
            AckReply::Destination(Destination {
                mac: [0xFF; 6],
                ip: [192, 0, 2, 1],
                port: PORT,
            }),
        ),
        ack(
            AckResult::Ok,
            Opcode::StatusNow,
            AckReply::Counters(BoxCounters::default()),
        ),
        ack(AckResult::DownlinkFull, Opcode::CellCommand, AckReply::None),
        ack(AckResult::Replay, Opcode::SetFlushTimeout, AckReply::None),
    ];
    let lengths: Vec<usize> = good
        .iter()
        .map(|a| a.to_bytes().len() - HEADER_LEN)
        .collect();
    assert_eq!(lengths, [24, 36, 24 + BOX_COUNTERS_LEN, 24, 24]);
    for a in &good {
        assert_eq!(
            d.push_datagram(&a.to_bytes(), &mut ()),
            DatagramOutcome::Acknowledgement
        );
    }
    let r = d.report();
    assert_eq!(r.acknowledgements, 5);
    assert_eq!(r.acknowledgements_by_result.get("ok"), Some(&3));
    assert_eq!(r.bad_input.total, cases.len() as u64);

    // commands: header, arguments and the cell command packet inside
    let command = |request| CommandRepr {
        box_id: 1,
        sequence: 9,
        host_time: 0,
        request,
    };
    let cell_packet = skinbox_protocol::cell_command::CellCommandRepr {
        cell_id: 7,
        command: skinbox_protocol::cell_command::CellCommand::Mode(
            skinbox_protocol::cell_command::CellMode::Event,
        ),
    }
    .to_bytes();
    let good_cell = command(Request::CellCommand {
        port: 1,
        packet: cell_packet,
    })
    .to_bytes();
    let mut bad_packet = good_cell.clone();
    bad_packet[HEADER_LEN + 4 + 19] = 0x54; // end-of-packet byte
    let mut reserved = good_cell.clone();
    reserved[HEADER_LEN + 2] = 1; // reserved byte 2 of the arguments
    let mut bad_arguments = command(Request::SetStatusPeriod { ticks: 200_000 }).to_bytes();
    bad_arguments[HEADER_LEN..].copy_from_slice(&10u32.to_be_bytes());
    let mut unknown = command(Request::ReadTick).to_bytes();
    unknown[6] = 42;
    let mut flags = command(Request::ReadTick).to_bytes();
    flags[7] = 1;
    let before = d.bad_input_total();
    for (bytes, reason) in [
        (bad_packet, Reason::Command(FormatFault::BadEndOfPacket)),
        (reserved, Reason::Command(FormatFault::BadArgument)),
        (bad_arguments, Reason::Command(FormatFault::BadArgument)),
        (unknown, Reason::Command(FormatFault::UnknownOpcode)),
        (flags, Reason::Command(FormatFault::BadFlags)),
    ] {
        let n = d.bad_input_mut().get(reason);
        assert_eq!(d.push_datagram(&bytes, &mut ()), DatagramOutcome::Rejected);
        assert_eq!(d.bad_input_mut().get(reason), n + 1, "{reason}");
    }
    assert_eq!(d.bad_input_total(), before + 5);
    assert_eq!(
        d.push_datagram(&good_cell, &mut ()),
        DatagramOutcome::Command
    );
    // a payload without the magic is other traffic, not bad input
    assert_eq!(
        d.push_datagram(b"GET / HTTP/1.1", &mut ()),
        DatagramOutcome::NotSkinbox
    );
    assert_eq!(d.bad_input_total(), before + 5);
    assert_eq!(d.other_traffic().get(OtherKind::UdpNotSkinbox), 1);
}

/// A status datagram refused for its box counter block is refused whole, like one with a
/// bad port counter block: its number is not taken, so it counts as missing.
#[test]
fn every_refused_status_datagram_counts_as_missing() {
    let bad_box_counters = {
        let mut b = status(1, 1, 2_000).to_bytes_with_box_counters(&BoxCounters::default());
        let at = b.len() - BOX_COUNTERS_LEN;
        b[at] = 7; // link_up 7
        b
    };
    let bad_port_block = {
        let mut s = status(1, 1, 2_000);
        if let DatagramBody::Status(st) = &mut s.body {
            st.first_port = 3; // blocks for ports 3..6 of a 4-port box
        }
        s.to_bytes()
    };
    let mut outcomes = Vec::new();
    for bad in [bad_box_counters, bad_port_block] {
        let mut d = Decoder::default();
        d.push_datagram(&status(1, 0, 1_000).to_bytes(), &mut ());
        assert_eq!(d.push_datagram(&bad, &mut ()), DatagramOutcome::Rejected);
        d.push_datagram(&records(1, 2, 3_000, &[(5, 0)]), &mut ());
        let r = d.report();
        outcomes.push((
            r.bad_input.total,
            r.losses.datagrams_missing,
            r.status_datagrams,
            r.box_status.last_box_counters.is_some(),
        ));
    }
    assert_eq!(outcomes[0], (1, 1, 1, false));
    assert_eq!(outcomes[0], outcomes[1]);
    // with a good block the flag's counters are read
    let mut d = Decoder::default();
    let good = status(1, 0, 1_000).to_bytes_with_box_counters(&BoxCounters::default());
    assert_eq!(good[7] & FLAG_BOX_COUNTERS, FLAG_BOX_COUNTERS);
    assert_eq!(d.push_datagram(&good, &mut ()), DatagramOutcome::Status);
    assert!(d.report().box_status.last_box_counters.is_some());
}

/// Two boxes with the same box id from two addresses, the second's clock 0.5 s behind and
/// its capture 0.5 s later: each keeps its own map, every row names its box, and the merge
/// by host time interleaves them.
#[test]
fn two_boxes_sharing_an_id_keep_their_own_host_times() {
    let boxes = [
        ([192, 0, 2, 10], 0u64, 0i64),
        // box 2: reset 0.5 s after box 1, its datagrams 0.5 s later on the host
        ([192, 0, 2, 11], 500_000_000, -500_000_000),
    ];
    const DELAY_NS: u64 = 40_000;
    let mut frames = Vec::new();
    // Truth: host time of box tick t is t * 8 + offset(box); delivery 40 us after the
    // datagram's latest record.
    for k in 0..40u64 {
        for (i, (ip, host_start, _)) in boxes.iter().enumerate() {
            let box_offset_ns = boxes[i].2;
            let host_ns = 1_000_000_000 + host_start + k * 8_000_000 + i as u64 * 1_000_000;
            let tick = ((host_ns as i64 + box_offset_ns - 1_000_000_000) / 8) as u64 + 1_000_000;
            let payload = records(1, k as u32, tick, &[(5, 0), (6, 125)]);
            frames.push((
                Duration::from_nanos(host_ns + 1_000 + DELAY_NS),
                udp((*ip, PORT), (HOST_IP, PORT), &payload),
            ));
        }
    }
    frames.sort_by_key(|f| f.0);
    let bytes = pcap(&frames);
    let timing = Timing::new(125.0, PathModel::bus_model(Positions::Unknown));
    let mut w =
        RowWriter::new(Vec::new(), RowFormat::JsonLines, RowKind::Packets).with_timing(timing);
    let report = decode_pcap_with(&bytes, &PcapOptions::default(), &mut w).unwrap();
    assert_eq!(report.boxes.len(), 2);
    assert_eq!(report.losses.datagrams_missing, 0);
    let summary = w.timing().unwrap().summary();
    assert_eq!(summary.len(), 2);
    let (_, text) = w.finish_into().unwrap();
    let text = String::from_utf8(text).unwrap();
    let mut per_source = std::collections::BTreeMap::new();
    for line in text.lines() {
        let row: serde_json::Value = serde_json::from_str(line).unwrap();
        let source = row["source"].as_str().unwrap().to_string();
        let i = usize::from(source.starts_with("192.0.2.11"));
        let sample_box_ns = row["sample_box_time_s"].as_f64().unwrap() * 1e9;
        let host = row["sample_host_time_ns"].as_f64().unwrap();
        // the stamp 8 ns * tick is host time - 1 s + 8 ms (tick origin) - offset
        // The receive map is late by the shortest delivery delay of the box's datagrams
        // (40 us after their latest record here).
        let truth =
            sample_box_ns - 8_000_000.0 + 1_000_000_000.0 - boxes[i].2 as f64 + DELAY_NS as f64;
        let err = host - truth;
        assert!(
            err.abs() < 1_000.0,
            "{source}: host time {host} vs {truth} ({err} ns)"
        );
        *per_source.entry(source).or_insert(0) += 1;
    }
    assert_eq!(per_source.len(), 2, "{per_source:?}");
    assert!(per_source.values().all(|n| *n == 80));
    // merged on the host time line, the rows of the two boxes alternate where they overlap
    let merged = sort_by_host_time(&text, RowFormat::JsonLines);
    let times: Vec<f64> = merged
        .lines()
        .map(|l| {
            serde_json::from_str::<serde_json::Value>(l).unwrap()["sample_host_time_ns"]
                .as_f64()
                .unwrap()
        })
        .collect();
    assert!(times.windows(2).all(|w| w[0] <= w[1]));
}
