//! Host frames for the control and downlink models' tests (cosim's receive-path tests use
//! them too): frames built with etherparse and the crc crate (ARP requests, echo requests,
//! UDP datagrams, commands), a generator of random good and bad frames that knows each
//! one's expected fate from how it built it, and a decoder of the downlink's UART pins.

#![allow(dead_code)]

use etherparse::{
    ArpHardwareId, ArpOperation, ArpPacket, EtherType, IpNumber, Ipv4Header, Ipv4Options,
    PacketBuilder,
};
use skinbox_frame_check::{check, encode, UdpAddresses};
use skinbox_model::control::{ControlConfig, Effect, Reply};
use skinbox_model::downlink::PinChange;
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::{
    AckRepr, AckResult, CommandRepr, Destination, Request, MIN_STATUS_PERIOD_TICKS,
};
use skinbox_protocol::link::{
    LinkConfig, ETHERNET_HEADER_LEN, IPV4_CHECKSUM, IPV4_HEADER_LEN, UDP_CHECKSUM,
};
use skinbox_protocol::wire::ipv4::Ipv4Packet;
use skinbox_protocol::TICKS_PER_SECOND;
use std::collections::BTreeMap;

pub const BOX_MAC: [u8; 6] = [0x02, 0x53, 0x4B, 0x00, 0x00, 0x01];
pub const BOX_IP: [u8; 4] = [192, 0, 2, 10];
pub const PORT: u16 = 54091;
pub const HOST_MAC: [u8; 6] = [0x02, 0, 0, 0, 0, 0x77];
pub const HOST_IP: [u8; 4] = [192, 0, 2, 1];
pub const HOST_PORT: u16 = 40000;

pub fn config() -> ControlConfig {
    ControlConfig {
        link: LinkConfig::DEFAULT,
        box_id: 1,
        port_count: 8,
        flush_timeout_ticks: 12_500,
        status_period_ticks: 12_500_000,
        // (the rules' tests; the downlink's syncs have tests of their own)
        sync_period_ticks: 0,
        clock_hz: skinbox_gateware::CLOCK_HZ,
        cell_baud: skinbox_gateware::CELL_BAUD,
    }
}

/// Pads to 60 bytes and appends the FCS computed by the crc crate.
pub fn with_fcs(mut ethernet: Vec<u8>) -> Vec<u8> {
    ethernet.resize(ethernet.len().max(60), 0);
    let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(&ethernet);
    ethernet.extend_from_slice(&fcs.to_le_bytes());
    ethernet
}

pub fn arp_request(target_ip: [u8; 4], sender_mac: [u8; 6], sender_ip: [u8; 4]) -> Vec<u8> {
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

pub fn ping(dst_mac: [u8; 6], dst_ip: [u8; 4], id: u16, seq: u16, data: &[u8]) -> Vec<u8> {
    let builder = PacketBuilder::ethernet2(HOST_MAC, dst_mac)
        .ipv4(HOST_IP, dst_ip, 64)
        .icmpv4_echo_request(id, seq);
    let mut e = Vec::new();
    builder.write(&mut e, data).unwrap();
    with_fcs(e)
}

/// A UDP frame from `src_ip`:`HOST_PORT` to the box, built by etherparse.
pub fn udp(
    src_ip: [u8; 4],
    dst_mac: [u8; 6],
    dst_ip: [u8; 4],
    port: u16,
    payload: &[u8],
) -> Vec<u8> {
    let builder = PacketBuilder::ethernet2(HOST_MAC, dst_mac)
        .ipv4(src_ip, dst_ip, 64)
        .udp(HOST_PORT, port);
    let mut e = Vec::new();
    builder.write(&mut e, payload).unwrap();
    with_fcs(e)
}

/// A UDP frame with a hand-made IPv4 header (options, fragments).
pub fn udp_with_ip(ip: Ipv4Header, payload: &[u8]) -> Vec<u8> {
    let builder = PacketBuilder::ethernet2(HOST_MAC, BOX_MAC)
        .ip(etherparse::IpHeaders::Ipv4(ip, Default::default()))
        .udp(HOST_PORT, PORT);
    let mut e = Vec::new();
    builder.write(&mut e, payload).unwrap();
    with_fcs(e)
}

pub fn command(from: [u8; 4], sequence: u32, request: Request) -> Vec<u8> {
    let c = CommandRepr {
        box_id: 1,
        sequence,
        host_time: 0x1122_3344_5566_7788,
        request,
    };
    udp(from, BOX_MAC, BOX_IP, PORT, &c.to_bytes())
}

/// Recomputes the FCS after an edit of the frame body.
pub fn refcs(mut frame: Vec<u8>) -> Vec<u8> {
    frame.truncate(frame.len() - 4);
    with_fcs(frame)
}

/// Checks an acknowledgement frame with etherparse (via frame_check) and against the frame
/// frame_check builds for the same payload; returns it parsed.
pub fn check_ack(reply: &Reply, to: Destination, send_tick: u64) -> AckRepr {
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

pub fn sender(ip: [u8; 4]) -> Destination {
    Destination {
        mac: HOST_MAC,
        ip,
        port: HOST_PORT,
    }
}

/// xorshift64*: the random cases, seeded.
pub struct Rng(pub u64);

impl Rng {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    pub fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
}

/// The frames mutations start from: an ARP request, a ping, a status-now and a cell
/// command, all to the box.
pub fn mutation_seeds() -> Vec<Vec<u8>> {
    vec![
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
    ]
}

/// `seed` (a frame with its FCS) with one to four random mutations (a byte changed, the
/// frame cut to 14 bytes or more, up to 63 random bytes added) and then a right FCS, so
/// that the mutation reaches the parsers rather than the FCS check.
pub fn mutated_frame(rng: &mut Rng, seed: &[u8]) -> Vec<u8> {
    let mut f = seed[..seed.len() - 4].to_vec();
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
    with_fcs(f)
}

/// What the test expects of one frame.
pub struct Case {
    pub frame: Vec<u8>,
    pub fate: BoxCounter,
    /// Expected acknowledgement result and sender, when answered with one.
    pub ack: Option<(AckResult, [u8; 4])>,
    pub effect: Option<Effect>,
}

/// One random frame, good or bad, with its expected fate. `next_sequence` is the test's
/// own book of sequence numbers per host; `accepted` the frames accepted so far.
pub fn random_case(
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
            f[ETHERNET_HEADER_LEN + IPV4_CHECKSUM.start] ^= 0x40;
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
            let at = ETHERNET_HEADER_LEN + IPV4_HEADER_LEN + UDP_CHECKSUM.start;
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
            let ip = Ipv4Packet::new_checked(&f[ETHERNET_HEADER_LEN..])
                .unwrap()
                .source();
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
            // queued: the tests space frames so that no port's queue fills (the full
            // queue has tests of its own)
            fate: BoxCounter::CommandsAccepted,
            ack: Some((AckResult::Ok, host)),
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

/// A cell command packet, `n` telling them apart.
pub fn cell_packet(n: u8) -> [u8; skinbox_protocol::cell::PACKET_LEN] {
    let mut p = [0u8; skinbox_protocol::cell::PACKET_LEN];
    for (i, b) in p.iter_mut().enumerate() {
        *b = n.wrapping_mul(37).wrapping_add(i as u8 * 11);
    }
    p[0] = skinbox_protocol::cell_command::COMMAND_HEADER;
    p
}

/// Ticks per bit at 4 Mbit/s.
pub const BIT_TICKS: f64 = TICKS_PER_SECOND as f64 / 4_000_000.0;

/// The bytes on each port's pin: a start bit is a fall from high; each bit is sampled in
/// its middle, the stop bit must be high.
pub fn decode_pins(changes: &[PinChange], ports: usize) -> Vec<Vec<(u64, u8)>> {
    (0..ports)
        .map(|port| {
            let mine: Vec<&PinChange> = changes.iter().filter(|c| c.port == port).collect();
            let level_at = |t: f64| {
                let t = t as u64;
                mine.iter()
                    .take_while(|c| c.tick <= t)
                    .last()
                    .is_none_or(|c| c.level)
            };
            let mut out = vec![];
            let mut free_from = 0.0;
            for c in &mine {
                if c.level || (c.tick as f64) < free_from {
                    continue;
                }
                let start = c.tick as f64;
                let byte = (0..8).fold(0u8, |b, i| {
                    b | u8::from(level_at(start + (1.5 + i as f64) * BIT_TICKS)) << i
                });
                assert!(
                    level_at(start + 9.5 * BIT_TICKS),
                    "port {port}: stop bit low at {start}"
                );
                out.push((c.tick, byte));
                free_from = start + 9.5 * BIT_TICKS;
            }
            out
        })
        .collect()
}
