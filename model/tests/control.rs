//! The box's control model against independent oracles: frames built with etherparse and
//! the crc crate, replies read back with etherparse and checked against `frame_check`
//! (which builds the box's UDP frames with etherparse), and a random mix of good and bad
//! frames whose expected fate the generator knows from how it built each one.

use etherparse::{ArpOperation, Icmpv4Type, IpNumber, NetSlice, SlicedPacket, TransportSlice};
use skinbox_model::control::{BoxControl, Effect, Reply, HOST_SLOTS};
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::{
    AckReply, AckResult, CommandRepr, Destination, Request, ALL_PORTS, ANY_BOX,
    MIN_STATUS_PERIOD_TICKS,
};
use skinbox_protocol::link::LinkConfig;
use std::collections::BTreeMap;

mod support;

use support::*;

#[test]
fn arp_request_is_answered_with_the_box_mac() {
    let mut b = BoxControl::new(config());
    let requester = [0x02, 0x11, 0x22, 0x33, 0x44, 0x55];
    let out = b.receive(&arp_request(BOX_IP, requester, [192, 0, 2, 77]), 5);
    assert_eq!(out.fate, BoxCounter::ArpAnswered);
    let Some(Reply::Arp(frame)) = out.reply else {
        panic!("no ARP reply: {out:?}")
    };
    assert_eq!(frame[..8], [0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0xD5]);
    let ethernet = &frame[8..frame.len() - 4];
    let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(ethernet);
    assert_eq!(frame[frame.len() - 4..], fcs.to_le_bytes());
    let p = SlicedPacket::from_ethernet(ethernet).unwrap();
    let eth = p.link.unwrap().to_header().unwrap().ethernet2().unwrap();
    assert_eq!(eth.destination, requester);
    assert_eq!(eth.source, BOX_MAC);
    let Some(NetSlice::Arp(arp)) = p.net else {
        panic!("not ARP")
    };
    let arp = arp.to_packet().try_eth_ipv4().unwrap();
    assert_eq!(arp.operation, ArpOperation::REPLY);
    assert_eq!(arp.sender_mac, BOX_MAC);
    assert_eq!(arp.sender_ipv4, BOX_IP);
    assert_eq!(arp.target_mac, requester);
    assert_eq!(arp.target_ipv4, [192, 0, 2, 77]);
    // for another address: counted, not answered
    let out = b.receive(&arp_request([192, 0, 2, 11], requester, [192, 0, 2, 77]), 6);
    assert_eq!((out.fate, out.reply), (BoxCounter::NotForUs, None));
}

#[test]
fn echo_request_is_answered_with_its_identifier_sequence_and_data() {
    let mut b = BoxControl::new(config());
    for len in [0usize, 1, 17, 18, 56, 1472] {
        let data: Vec<u8> = (0..len).map(|i| (i * 7 + 3) as u8).collect();
        let out = b.receive(&ping(BOX_MAC, BOX_IP, 0xBEEF, len as u16, &data), 9);
        assert_eq!(out.fate, BoxCounter::PingsAnswered, "{len}");
        let Some(Reply::Echo(frame)) = out.reply else {
            panic!("no echo reply")
        };
        let ethernet = &frame[8..frame.len() - 4];
        let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(ethernet);
        assert_eq!(frame[frame.len() - 4..], fcs.to_le_bytes());
        let p = SlicedPacket::from_ethernet(ethernet).unwrap();
        let Some(NetSlice::Ipv4(ip)) = &p.net else {
            panic!("not IPv4")
        };
        let h = ip.header().to_header();
        assert_eq!(h.header_checksum, h.calc_header_checksum());
        assert_eq!((h.source, h.destination), (BOX_IP, HOST_IP));
        assert_eq!(h.protocol, IpNumber::ICMP);
        let Some(TransportSlice::Icmpv4(icmp)) = &p.transport else {
            panic!("not ICMP")
        };
        let Icmpv4Type::EchoReply(echo) = icmp.icmp_type() else {
            panic!("not an echo reply: {:?}", icmp.icmp_type())
        };
        assert_eq!((echo.id, echo.seq), (0xBEEF, len as u16));
        assert_eq!(icmp.payload(), &data[..]);
        assert_eq!(
            icmp.checksum(),
            icmp.header().icmp_type.calc_checksum(icmp.payload())
        );
    }
    assert_eq!(b.counters.get(BoxCounter::PingsAnswered), 6);
}

#[test]
fn every_command_is_acknowledged_with_its_effect() {
    let mut b = BoxControl::new(config());
    let me = sender(HOST_IP);
    let given = Destination {
        mac: [0x02, 9, 9, 9, 9, 9],
        ip: [192, 0, 2, 99],
        port: 7777,
    };
    let cases = [
        (
            Request::StreamTo { to: None },
            AckResult::Ok,
            Some(Effect::StreamTo(me)),
        ),
        (
            Request::StreamTo { to: Some(given) },
            AckResult::Ok,
            Some(Effect::StreamTo(given)),
        ),
        (
            Request::SetFlushTimeout { ticks: 1250 },
            AckResult::Ok,
            Some(Effect::SetFlushTimeout(1250)),
        ),
        (
            Request::SetStatusPeriod {
                ticks: MIN_STATUS_PERIOD_TICKS,
            },
            AckResult::Ok,
            Some(Effect::SetStatusPeriod(MIN_STATUS_PERIOD_TICKS)),
        ),
        (Request::StatusNow, AckResult::Ok, Some(Effect::StatusNow)),
        (Request::ReadTick, AckResult::Ok, None),
        (
            Request::CellCommand {
                port: ALL_PORTS,
                packet: [0xC5; PACKET_LEN],
            },
            AckResult::Ok,
            None,
        ),
    ];
    for (i, (request, result, effect)) in cases.into_iter().enumerate() {
        let sequence = 100 + i as u32;
        let receive_tick = 1000 * i as u64;
        let out = b.receive(&command(HOST_IP, sequence, request), receive_tick);
        assert_eq!(out.effect, effect, "{request:?}");
        let ack = check_ack(out.reply.as_ref().unwrap(), me, receive_tick + 200);
        assert_eq!(ack.sequence, sequence);
        assert_eq!(ack.host_time, 0x1122_3344_5566_7788);
        assert_eq!(ack.opcode, request.opcode() as u8);
        assert_eq!(ack.result, result);
        assert_eq!(ack.last_accepted, sequence);
        assert_eq!(ack.receive_tick, receive_tick);
        assert_eq!((ack.box_id, ack.port_count), (1, 8));
        match (request, ack.reply) {
            (Request::StreamTo { to }, AckReply::Destination(d)) => {
                assert_eq!(d, to.unwrap_or(me));
                assert_eq!(b.destination, d);
            }
            (Request::StatusNow, AckReply::Counters(c)) => {
                assert_eq!(c, b.counters);
                assert_eq!(c.get(BoxCounter::CommandsAccepted), 5);
                assert_eq!(c.get(BoxCounter::FramesReceived), 5);
            }
            (_, AckReply::None) => {}
            (r, reply) => panic!("{r:?} answered with {reply:?}"),
        }
    }
    assert_eq!(b.flush_timeout_ticks, 1250);
    assert_eq!(b.status_period_ticks, MIN_STATUS_PERIOD_TICKS);
    assert_eq!(b.counters.get(BoxCounter::RefusedDownlinkFull), 0);
    assert_eq!(b.counters.get(BoxCounter::CommandsAccepted), 7);
}

#[test]
fn replays_foreign_hosts_and_other_boxes_are_refused_and_counted() {
    let mut b = BoxControl::new(config());
    let first = command(HOST_IP, 7, Request::ReadTick);
    assert_eq!(b.receive(&first, 1).fate, BoxCounter::CommandsAccepted);
    // the same bytes again, and an older sequence number
    for (frame, tick) in [
        (first.clone(), 2),
        (command(HOST_IP, 6, Request::ReadTick), 3),
    ] {
        let out = b.receive(&frame, tick);
        assert_eq!(out.fate, BoxCounter::RefusedReplay);
        assert_eq!(out.effect, None);
        let ack = check_ack(out.reply.as_ref().unwrap(), sender(HOST_IP), tick + 1);
        assert_eq!((ack.result, ack.last_accepted), (AckResult::Replay, 7));
    }
    // a foreign subnet: not answered, not remembered
    let foreign = command([198, 51, 100, 1], 8, Request::StreamTo { to: None });
    let out = b.receive(&foreign, 4);
    assert_eq!(
        (out.fate, out.reply, out.effect),
        (BoxCounter::RefusedForeignSubnet, None, None)
    );
    // another box id: answered, sequence not taken
    let other = CommandRepr {
        box_id: 2,
        sequence: 9,
        host_time: 0,
        request: Request::StatusNow,
    };
    let out = b.receive(&udp(HOST_IP, BOX_MAC, BOX_IP, PORT, &other.to_bytes()), 5);
    assert_eq!(out.fate, BoxCounter::RefusedOtherBox);
    let ack = check_ack(out.reply.as_ref().unwrap(), sender(HOST_IP), 6);
    assert_eq!((ack.result, ack.last_accepted), (AckResult::OtherBox, 7));
    // any box: accepted; serial arithmetic across the wrap
    let any = CommandRepr {
        box_id: ANY_BOX,
        sequence: 9,
        host_time: 0,
        request: Request::ReadTick,
    };
    let out = b.receive(&udp(HOST_IP, BOX_MAC, BOX_IP, PORT, &any.to_bytes()), 7);
    assert_eq!(out.fate, BoxCounter::CommandsAccepted);
    let mut b = BoxControl::new(config());
    assert_eq!(
        b.receive(&command(HOST_IP, u32::MAX, Request::ReadTick), 1)
            .fate,
        BoxCounter::CommandsAccepted
    );
    assert_eq!(
        b.receive(&command(HOST_IP, 0, Request::ReadTick), 2).fate,
        BoxCounter::CommandsAccepted
    );
    // hosts beyond the remembered ones push out the one accepted longest ago
    for h in 0..HOST_SLOTS as u8 {
        let ip = [192, 0, 2, 20 + h];
        assert_eq!(
            b.receive(&command(ip, 50, Request::ReadTick), 3).fate,
            BoxCounter::CommandsAccepted
        );
    }
    // HOST_IP was forgotten: its old number is accepted again; the newest host is not
    assert_eq!(
        b.receive(&command(HOST_IP, 0, Request::ReadTick), 4).fate,
        BoxCounter::CommandsAccepted
    );
    let newest = [192, 0, 2, 20 + HOST_SLOTS as u8 - 1];
    assert_eq!(
        b.receive(&command(newest, 50, Request::ReadTick), 5).fate,
        BoxCounter::RefusedReplay
    );
}
#[test]
fn a_random_mix_of_good_and_bad_frames_is_counted_by_reason() {
    for seed in [1u64, 0x5EED, 0xC0FFEE] {
        let mut rng = Rng(seed);
        let mut b = BoxControl::new(config());
        let mut expected: BTreeMap<&'static str, u32> = BTreeMap::new();
        let mut next_sequence = BTreeMap::new();
        let mut accepted = Vec::new();
        let cases = 400;
        for i in 0..cases {
            let mut case = random_case(&mut rng, &mut next_sequence, &mut accepted);
            let tick = 1000 * i as u64;
            // a tenth of the answered frames that change no state find the reply buffer
            // still taken: not answered, counted as reply_busy
            let stateless = matches!(
                case.fate,
                BoxCounter::ArpAnswered
                    | BoxCounter::PingsAnswered
                    | BoxCounter::RefusedOtherBox
                    | BoxCounter::RefusedReplay
            );
            let slot_free = !(stateless && rng.below(10) == 0);
            if !slot_free {
                case = Case {
                    fate: BoxCounter::ReplyBusy,
                    ack: None,
                    effect: None,
                    ..case
                };
            }
            let out = b.receive_with_slot(&case.frame, tick, slot_free);
            assert_eq!(out.fate, case.fate, "seed {seed} case {i}");
            assert_eq!(out.effect, case.effect, "seed {seed} case {i}");
            *expected.entry(case.fate.name()).or_default() += 1;
            match (&case.ack, &out.reply) {
                (Some((result, ip)), Some(reply @ Reply::Ack { .. })) => {
                    let ack = check_ack(reply, sender(*ip), tick + 100);
                    assert_eq!(ack.result, *result, "seed {seed} case {i}");
                    assert_eq!(ack.receive_tick, tick);
                }
                (None, Some(Reply::Arp(f) | Reply::Echo(f))) => {
                    let e = &f[8..f.len() - 4];
                    assert!(SlicedPacket::from_ethernet(e).is_ok());
                    assert!(matches!(
                        case.fate,
                        BoxCounter::ArpAnswered | BoxCounter::PingsAnswered
                    ));
                }
                (None, None) => {}
                (want, got) => panic!("seed {seed} case {i}: expected {want:?}, got {got:?}"),
            }
        }
        for c in BoxCounter::ALL.iter().skip(1) {
            assert_eq!(
                b.counters.get(*c),
                expected.get(c.name()).copied().unwrap_or(0),
                "seed {seed}: {}",
                c.name()
            );
        }
        assert_eq!(b.counters.get(BoxCounter::FramesReceived), cases);
        assert_eq!(b.counters.unaccounted_frames(), 0);
        // every fate occurred but refused_downlink_full, which needs a full queue (its
        // own tests below)
        assert_eq!(
            expected.len(),
            BoxCounter::ALL.len() - 2,
            "seed {seed}: {expected:?}"
        );
        assert!(!expected.contains_key(BoxCounter::RefusedDownlinkFull.name()));
    }
}

#[test]
fn mutated_frames_never_panic_and_are_each_counted_once() {
    let mut rng = Rng(0xF00D);
    let mut b = BoxControl::new(config());
    let seeds = mutation_seeds();
    let cases = 3000u32;
    for i in 0..cases {
        let frame = mutated_frame(&mut rng, &seeds[i as usize % seeds.len()]);
        let out = b.receive(&frame, u64::from(i));
        if let Some(reply) = &out.reply {
            // whatever it answers is a well-formed frame
            let bytes = reply.frame(&LinkConfig::DEFAULT, 0);
            let e = &bytes[8..bytes.len() - 4];
            assert!(SlicedPacket::from_ethernet(e).is_ok(), "case {i}");
        }
    }
    assert_eq!(b.counters.get(BoxCounter::FramesReceived), cases);
    assert_eq!(b.counters.unaccounted_frames(), 0);
}
