//! The box's control model against independent oracles: frames built with etherparse and
//! the crc crate, replies read back with etherparse and checked against `frame_check`
//! (which builds the box's UDP frames with etherparse), and a random mix of good and bad
//! frames whose expected fate the generator knows from how it built each one.

use etherparse::{
    ArpHardwareId, ArpOperation, ArpPacket, EtherType, Icmpv4Type, IpNumber, Ipv4Header,
    Ipv4Options, NetSlice, PacketBuilder, SlicedPacket, TransportSlice,
};
use skinbox_cosim::control::{BoxControl, ControlConfig, Effect, Reply, HOST_SLOTS};
use skinbox_frame_check::{check, encode, UdpAddresses};
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::{
    AckReply, AckRepr, AckResult, CommandRepr, Destination, Request, ALL_PORTS, ANY_BOX,
    MIN_STATUS_PERIOD_TICKS,
};
use skinbox_protocol::link::LinkConfig;
use std::collections::BTreeMap;

const BOX_MAC: [u8; 6] = [0x02, 0x53, 0x4B, 0x00, 0x00, 0x01];
const BOX_IP: [u8; 4] = [192, 0, 2, 10];
const PORT: u16 = 54091;
const HOST_MAC: [u8; 6] = [0x02, 0, 0, 0, 0, 0x77];
const HOST_IP: [u8; 4] = [192, 0, 2, 1];
const HOST_PORT: u16 = 40000;

fn config() -> ControlConfig {
    ControlConfig {
        link: LinkConfig::DEFAULT,
        box_id: 1,
        port_count: 8,
        flush_timeout_ticks: 12_500,
        status_period_ticks: 12_500_000,
    }
}

/// Pads to 60 bytes and appends the FCS computed by the crc crate.
fn with_fcs(mut ethernet: Vec<u8>) -> Vec<u8> {
    ethernet.resize(ethernet.len().max(60), 0);
    let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&ethernet);
    ethernet.extend_from_slice(&fcs.to_le_bytes());
    ethernet
}

fn arp_request(target_ip: [u8; 4], sender_mac: [u8; 6], sender_ip: [u8; 4]) -> Vec<u8> {
    let builder = PacketBuilder::ethernet2(sender_mac, [0xFF; 6]).arp(
        ArpPacket::new(
            ArpHardwareId::ETHERNET,
            EtherType::IPV4,
            ArpOperation::REQUEST,
            &sender_mac,
            &sender_ip,
            &[0; 6],
            &target_ip,
        )
        .unwrap(),
    );
    let mut e = Vec::new();
    builder.write(&mut e).unwrap();
    with_fcs(e)
}

fn ping(dst_mac: [u8; 6], dst_ip: [u8; 4], id: u16, seq: u16, data: &[u8]) -> Vec<u8> {
    let builder = PacketBuilder::ethernet2(HOST_MAC, dst_mac)
        .ipv4(HOST_IP, dst_ip, 64)
        .icmpv4_echo_request(id, seq);
    let mut e = Vec::new();
    builder.write(&mut e, data).unwrap();
    with_fcs(e)
}

/// A UDP frame from `src_ip`:`HOST_PORT` to the box, built by etherparse.
fn udp(src_ip: [u8; 4], dst_mac: [u8; 6], dst_ip: [u8; 4], port: u16, payload: &[u8]) -> Vec<u8> {
    let builder = PacketBuilder::ethernet2(HOST_MAC, dst_mac)
        .ipv4(src_ip, dst_ip, 64)
        .udp(HOST_PORT, port);
    let mut e = Vec::new();
    builder.write(&mut e, payload).unwrap();
    with_fcs(e)
}

/// A UDP frame with a hand-made IPv4 header (options, fragments).
fn udp_with_ip(ip: Ipv4Header, payload: &[u8]) -> Vec<u8> {
    let builder = PacketBuilder::ethernet2(HOST_MAC, BOX_MAC)
        .ip(etherparse::IpHeaders::Ipv4(ip, Default::default()))
        .udp(HOST_PORT, PORT);
    let mut e = Vec::new();
    builder.write(&mut e, payload).unwrap();
    with_fcs(e)
}

fn command(from: [u8; 4], sequence: u32, request: Request) -> Vec<u8> {
    let c = CommandRepr {
        box_id: 1,
        sequence,
        host_time: 0x1122_3344_5566_7788,
        request,
    };
    udp(from, BOX_MAC, BOX_IP, PORT, &c.to_bytes())
}

/// Recomputes the FCS after an edit of the frame body.
fn refcs(mut frame: Vec<u8>) -> Vec<u8> {
    frame.truncate(frame.len() - 4);
    with_fcs(frame)
}

/// Checks an acknowledgement frame with etherparse (via frame_check) and against the frame
/// frame_check builds for the same payload; returns it parsed.
fn check_ack(reply: &Reply, to: Destination, send_tick: u64) -> AckRepr {
    let frame = reply.frame(&LinkConfig::DEFAULT, send_tick);
    let (_, payload) = check(&frame).expect("the acknowledgement frame is well formed");
    let expected = encode(
        &UdpAddresses {
            source_mac: BOX_MAC,
            destination_mac: to.mac,
            source_ip: BOX_IP,
            destination_ip: to.ip,
            source_port: PORT,
            destination_port: to.port,
        },
        payload,
    )
    .unwrap();
    assert_eq!(frame, expected, "byte for byte as etherparse builds it");
    let ack = AckRepr::parse(payload).unwrap();
    assert_eq!(ack.send_tick, send_tick);
    ack
}

fn sender(ip: [u8; 4]) -> Destination {
    Destination {
        mac: HOST_MAC,
        ip,
        port: HOST_PORT,
    }
}

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
            AckResult::NoDownlink,
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
    assert_eq!(b.counters.get(BoxCounter::RefusedNoDownlink), 1);
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

/// xorshift64*: the random cases, seeded.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
}

/// What the test expects of one frame.
struct Case {
    frame: Vec<u8>,
    fate: BoxCounter,
    /// Expected acknowledgement result and sender, when answered with one.
    ack: Option<(AckResult, [u8; 4])>,
    effect: Option<Effect>,
}

/// One random frame, good or bad, with its expected fate. `next_sequence` is the test's
/// own book of sequence numbers per host; `accepted` the frames accepted so far.
fn random_case(
    rng: &mut Rng,
    next_sequence: &mut BTreeMap<[u8; 4], u32>,
    accepted: &mut Vec<Vec<u8>>,
) -> Case {
    let hosts = [HOST_IP, [192, 0, 2, 2], [192, 0, 2, 3]];
    let host = hosts[rng.below(3) as usize];
    let plain = |frame, fate| Case {
        frame,
        fate,
        ack: None,
        effect: None,
    };
    let mut fresh = |host: [u8; 4], rng: &mut Rng| {
        let s = next_sequence.entry(host).or_insert(1000);
        *s = s.wrapping_add(1 + rng.below(3) as u32);
        *s
    };
    match rng.below(24) {
        0 => plain(arp_request(BOX_IP, HOST_MAC, host), BoxCounter::ArpAnswered),
        1 => plain(
            arp_request([192, 0, 2, 200], HOST_MAC, host),
            BoxCounter::NotForUs,
        ),
        2 => {
            let n = rng.below(200) as usize;
            let data = rng.bytes(n);
            plain(
                ping(BOX_MAC, BOX_IP, rng.next() as u16, rng.next() as u16, &data),
                BoxCounter::PingsAnswered,
            )
        }
        3 => {
            // bad FCS: one bit of the frame or of the FCS flipped
            let mut f = ping(BOX_MAC, BOX_IP, 1, 2, &rng.bytes(30));
            let at = rng.below(f.len() as u64) as usize;
            f[at] ^= 1 << rng.below(8);
            plain(f, BoxCounter::BadFcs)
        }
        4 => {
            // truncated below the minimum frame
            let mut f = ping(BOX_MAC, BOX_IP, 1, 2, &rng.bytes(60));
            f.truncate(rng.below(64) as usize);
            plain(f, BoxCounter::BadLength)
        }
        5 => {
            // a giant: more than 1518 bytes with the FCS
            let n = 1515 + rng.below(100) as usize;
            let mut e = rng.bytes(n);
            e[..6].copy_from_slice(&BOX_MAC);
            plain(with_fcs(e), BoxCounter::BadLength)
        }
        6 => plain(
            ping([0x02, 0, 0, 0, 0, 0x42], BOX_IP, 1, 2, b"x"),
            BoxCounter::NotForUs,
        ),
        7 => plain(
            ping(BOX_MAC, [192, 0, 2, 11], 1, 2, b"x"),
            BoxCounter::NotForUs,
        ),
        8 => {
            let mut ip = Ipv4Header::new(0, 64, IpNumber::UDP, host, BOX_IP).unwrap();
            ip.options = Ipv4Options::try_from(&[1u8, 1, 1, 0][..]).unwrap();
            plain(udp_with_ip(ip, b"options"), BoxCounter::Ipv4Options)
        }
        9 => {
            let mut ip = Ipv4Header::new(0, 64, IpNumber::UDP, host, BOX_IP).unwrap();
            if rng.below(2) == 0 {
                ip.more_fragments = true;
            } else {
                ip.fragment_offset =
                    etherparse::IpFragOffset::try_new(1 + rng.below(100) as u16).unwrap();
            }
            plain(udp_with_ip(ip, b"fragment"), BoxCounter::Ipv4Fragment)
        }
        10 => {
            // a wrong IPv4 header checksum
            let mut f = command(host, fresh(host, rng), Request::ReadTick);
            f[14 + 10] ^= 0x40;
            plain(refcs(f), BoxCounter::Ipv4BadHeader)
        }
        11 => plain(
            udp(
                host,
                BOX_MAC,
                BOX_IP,
                PORT + 1 + rng.below(100) as u16,
                b"hello",
            ),
            BoxCounter::UnknownUdpPort,
        ),
        12 => {
            // a wrong UDP checksum (never 0: the field after the flip is not 0 by chance)
            let mut f = command(host, 1, Request::ReadTick);
            let at = 14 + 20 + 6;
            f[at] ^= 0x01;
            if f[at] == 0 && f[at + 1] == 0 {
                f[at + 1] = 1;
            }
            plain(refcs(f), BoxCounter::BadTransport)
        }
        13 => {
            // malformed: random bytes, or a command with a wrong length or a flag set
            let payload = match rng.below(3) {
                0 => {
                    let n = rng.below(40) as usize;
                    rng.bytes(n)
                }
                1 => {
                    let mut c = CommandRepr {
                        box_id: 1,
                        sequence: 1,
                        host_time: 0,
                        request: Request::StatusNow,
                    }
                    .to_bytes();
                    c.push(0);
                    c
                }
                _ => {
                    let mut c = CommandRepr {
                        box_id: 1,
                        sequence: 1,
                        host_time: 0,
                        request: Request::StatusNow,
                    }
                    .to_bytes();
                    c[7] = 0x80;
                    c
                }
            };
            plain(
                udp(host, BOX_MAC, BOX_IP, PORT, &payload),
                BoxCounter::RefusedMalformed,
            )
        }
        14 => plain(
            command(
                [10, 0, rng.below(256) as u8, 1],
                1,
                Request::StreamTo { to: None },
            ),
            BoxCounter::RefusedForeignSubnet,
        ),
        15 if !accepted.is_empty() => {
            let f = accepted[rng.below(accepted.len() as u64) as usize].clone();
            let ip = f[14 + 12..14 + 16].try_into().unwrap();
            Case {
                frame: f,
                fate: BoxCounter::RefusedReplay,
                ack: Some((AckResult::Replay, ip)),
                effect: None,
            }
        }
        16 => {
            // an unknown opcode
            let mut c = CommandRepr {
                box_id: 1,
                sequence: fresh(host, rng),
                host_time: 0,
                request: Request::ReadTick,
            }
            .to_bytes();
            c[6] = 7 + rng.below(240) as u8;
            Case {
                frame: udp(host, BOX_MAC, BOX_IP, PORT, &c),
                fate: BoxCounter::RefusedUnknownOpcode,
                ack: Some((AckResult::UnknownOpcode, host)),
                effect: None,
            }
        }
        17 => Case {
            frame: command(
                host,
                fresh(host, rng),
                Request::SetFlushTimeout { ticks: 0 },
            ),
            fate: BoxCounter::RefusedBadArgument,
            ack: Some((AckResult::BadArgument, host)),
            effect: None,
        },
        18 => {
            // an IPv6 frame
            let builder = PacketBuilder::ethernet2(HOST_MAC, BOX_MAC)
                .ipv6([1; 16], [2; 16], 64)
                .udp(1, PORT);
            let mut e = Vec::new();
            builder.write(&mut e, b"v6").unwrap();
            plain(with_fcs(e), BoxCounter::NotForUs)
        }
        19 => {
            let c = CommandRepr {
                box_id: 2 + rng.below(1000) as u16,
                sequence: fresh(host, rng),
                host_time: 0,
                request: Request::StatusNow,
            };
            // another box's command does not take the sequence number: use it once more
            *next_sequence.get_mut(&host).unwrap() -= 1;
            Case {
                frame: udp(host, BOX_MAC, BOX_IP, PORT, &c.to_bytes()),
                fate: BoxCounter::RefusedOtherBox,
                ack: Some((AckResult::OtherBox, host)),
                effect: None,
            }
        }
        20 => Case {
            frame: command(
                host,
                fresh(host, rng),
                Request::CellCommand {
                    port: rng.below(8) as u8,
                    packet: [0xA5; PACKET_LEN],
                },
            ),
            fate: BoxCounter::RefusedNoDownlink,
            ack: Some((AckResult::NoDownlink, host)),
            effect: None,
        },
        _ => {
            let request = match rng.below(5) {
                0 => Request::StreamTo { to: None },
                1 => Request::SetFlushTimeout {
                    ticks: 1 + rng.below(100_000) as u32,
                },
                2 => Request::SetStatusPeriod {
                    ticks: MIN_STATUS_PERIOD_TICKS + rng.below(1 << 20) as u32,
                },
                3 => Request::StatusNow,
                _ => Request::ReadTick,
            };
            let effect = match request {
                Request::StreamTo { .. } => Some(Effect::StreamTo(sender(host))),
                Request::SetFlushTimeout { ticks } => Some(Effect::SetFlushTimeout(ticks)),
                Request::SetStatusPeriod { ticks } => Some(Effect::SetStatusPeriod(ticks)),
                Request::StatusNow => Some(Effect::StatusNow),
                _ => None,
            };
            let frame = command(host, fresh(host, rng), request);
            accepted.push(frame.clone());
            Case {
                frame,
                fate: BoxCounter::CommandsAccepted,
                ack: Some((AckResult::Ok, host)),
                effect,
            }
        }
    }
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
        // every fate the generator makes occurred
        assert_eq!(
            expected.len(),
            BoxCounter::ALL.len() - 1,
            "seed {seed}: {expected:?}"
        );
    }
}

#[test]
fn mutated_frames_never_panic_and_are_each_counted_once() {
    let mut rng = Rng(0xF00D);
    let mut b = BoxControl::new(config());
    let seeds = [
        arp_request(BOX_IP, HOST_MAC, HOST_IP),
        ping(BOX_MAC, BOX_IP, 1, 2, b"abcdefgh"),
        command(HOST_IP, 5, Request::StatusNow),
        command(
            HOST_IP,
            6,
            Request::CellCommand {
                port: 1,
                packet: [0; PACKET_LEN],
            },
        ),
    ];
    let cases = 3000u32;
    for i in 0..cases {
        let mut f = seeds[i as usize % seeds.len()].clone();
        f.truncate(f.len() - 4);
        // flip, cut or grow, then a right FCS so the mutation reaches the parsers
        for _ in 0..1 + rng.below(4) {
            match rng.below(3) {
                0 => {
                    let at = rng.below(f.len() as u64) as usize;
                    f[at] = rng.next() as u8;
                }
                1 => {
                    let n = 14 + rng.below(f.len() as u64 - 13) as usize;
                    f.truncate(n);
                }
                _ => {
                    let n = rng.below(64) as usize;
                    let tail = rng.bytes(n);
                    f.extend_from_slice(&tail);
                }
            }
        }
        let frame = with_fcs(f);
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
