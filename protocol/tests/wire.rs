//! The Ethernet II, ARP, IPv4, ICMP echo and UDP layer: frames written by hand from the
//! RFCs parse to the expected reprs and emit back byte for byte; random reprs agree with
//! etherparse both ways.

use etherparse::{
    ArpHardwareId, ArpPacket, EtherType, Ethernet2Header, IcmpEchoHeader, Icmpv4Header, Icmpv4Type,
    IpNumber, Ipv4Header, UdpHeader,
};
use proptest::prelude::*;
use skinbox_protocol::wire::checksum::{checksum, ipv4_pseudo_header};
use skinbox_protocol::wire::icmp::IcmpPacket;
use skinbox_protocol::wire::ipv4::Ipv4Packet;
use skinbox_protocol::wire::udp::UdpPacket;
use skinbox_protocol::wire::{
    ethernet, ipv4, ArpOperation, ArpRepr, EchoMessage, EthernetRepr, IcmpEchoRepr, Ipv4Repr,
    UdpRepr,
};
use skinbox_protocol::{Error, Format};

fn hex(s: &str) -> Vec<u8> {
    let s: String = s.split_whitespace().collect();
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

const HOST_MAC: [u8; 6] = [0x02, 0x00, 0x00, 0x00, 0x00, 0x01];
const BOX_MAC: [u8; 6] = [0x02, 0x53, 0x4B, 0x00, 0x00, 0x01];
const HOST_IP: [u8; 4] = [192, 0, 2, 1];
const BOX_IP: [u8; 4] = [192, 0, 2, 10];

/// A host at 192.0.2.1 asks who has 192.0.2.10 (RFC 826), broadcast.
#[test]
fn arp_request_golden() {
    let frame = hex("ffffffffffff 020000000001 0806
         0001 0800 06 04 0001 020000000001 c0000201 000000000000 c000020a");
    let ethernet = EthernetRepr::parse(&frame).unwrap();
    assert_eq!(
        ethernet,
        EthernetRepr {
            destination: ethernet::BROADCAST,
            source: HOST_MAC,
            ethertype: ethernet::ETHERTYPE_ARP,
        }
    );
    let arp = ArpRepr::parse(&frame[ethernet::HEADER_LEN..]).unwrap();
    assert_eq!(
        arp,
        ArpRepr {
            operation: ArpOperation::Request,
            sender_mac: HOST_MAC,
            sender_ip: HOST_IP,
            target_mac: [0; 6],
            target_ip: BOX_IP,
        }
    );
    let mut out = vec![0u8; ethernet.buffer_len() + arp.buffer_len()];
    ethernet.emit(&mut out);
    arp.emit(&mut out[ethernet::HEADER_LEN..]);
    assert_eq!(out, frame);
}

/// The IPv4 header of Wikipedia's "IPv4 header checksum" example: 192.168.0.1 to
/// 192.168.0.199, UDP, total length 115, don't fragment, TTL 64, checksum 0xB861.
#[test]
fn ipv4_header_golden() {
    let header = hex("4500 0073 0000 4000 4011 b861 c0a8 0001 c0a8 00c7");
    let mut packet = header.clone();
    packet.resize(0x73, 0);
    let repr = Ipv4Repr::parse(&packet).unwrap();
    assert_eq!(
        repr,
        Ipv4Repr {
            source: [192, 168, 0, 1],
            destination: [192, 168, 0, 199],
            protocol: ipv4::PROTOCOL_UDP,
            payload_len: 0x73 - 20,
            dscp_ecn: 0,
            identification: 0,
            dont_fragment: true,
            ttl: 64,
        }
    );
    let mut out = vec![0u8; 20];
    repr.emit(&mut out);
    assert_eq!(out, header);
}

/// An echo request from 192.0.2.1 to 192.0.2.10: identification 0x1C46, identifier
/// 0x1234, sequence 1, Windows ping's 32 data bytes; checksums summed by hand.
#[test]
fn icmp_echo_request_golden() {
    let frame = hex("02534b000001 020000000001 0800
         4500 003c 1c46 4000 4001 9a6f c0000201 c000020a
         08 00 3b27 1234 0001
         6162636465666768696a6b6c6d6e6f7071727374757677616263646566676869");
    let ip = &frame[ethernet::HEADER_LEN..];
    let ip_repr = Ipv4Repr::parse(ip).unwrap();
    assert_eq!(
        ip_repr,
        Ipv4Repr {
            source: HOST_IP,
            destination: BOX_IP,
            protocol: ipv4::PROTOCOL_ICMP,
            payload_len: 40,
            dscp_ecn: 0,
            identification: 0x1C46,
            dont_fragment: true,
            ttl: 64,
        }
    );
    let message = &ip[ipv4::HEADER_LEN..];
    let echo = IcmpEchoRepr::parse(message).unwrap();
    assert_eq!(
        echo,
        IcmpEchoRepr {
            message: EchoMessage::Request,
            identifier: 0x1234,
            sequence: 1,
            data: b"abcdefghijklmnopqrstuvwabcdefghi",
        }
    );
    let ethernet = EthernetRepr::parse(&frame).unwrap();
    assert_eq!(
        ethernet,
        EthernetRepr {
            destination: BOX_MAC,
            source: HOST_MAC,
            ethertype: ethernet::ETHERTYPE_IPV4,
        }
    );
    let mut out = vec![0u8; frame.len()];
    ethernet.emit(&mut out);
    ip_repr.emit(&mut out[14..]);
    echo.emit(&mut out[34..]);
    assert_eq!(out, frame);
}

/// "hello, box" from 192.0.2.1:40000 to 192.0.2.10:54091, padded to the 60-byte minimum
/// frame: the IPv4 total length and the UDP length leave the padding out.
#[test]
fn udp_datagram_golden() {
    let frame = hex("02534b000001 020000000001 0800
         4500 0026 0000 4000 4011 b6bb c0000201 c000020a
         9c40 d34b 0012 3859 68656c6c6f2c20626f78
         0000 0000 0000 0000");
    assert_eq!(frame.len(), 60);
    let ip = &frame[ethernet::HEADER_LEN..];
    let ip_repr = Ipv4Repr::parse(ip).unwrap();
    assert_eq!(ip_repr.payload_len, 18);
    let packet = Ipv4Packet::new_checked(ip).unwrap();
    let payload = packet.payload().unwrap();
    let udp = UdpRepr::parse(payload, ip_repr.source, ip_repr.destination).unwrap();
    assert_eq!(
        udp,
        UdpRepr {
            source_port: 40000,
            destination_port: 54091,
            payload: b"hello, box",
        }
    );
    let mut out = vec![0u8; frame.len()];
    EthernetRepr::parse(&frame).unwrap().emit(&mut out);
    ip_repr.emit(&mut out[14..]);
    udp.emit(&mut out[34..], HOST_IP, BOX_IP);
    assert_eq!(out, frame);
}

fn udp_golden() -> Vec<u8> {
    hex("4500 0026 0000 4000 4011 b6bb c0000201 c000020a
         9c40 d34b 0012 3859 68656c6c6f2c20626f78")
}

#[test]
fn ipv4_refusals_name_the_field() {
    let good = udp_golden();
    let with = |at: usize, byte: u8| {
        let mut b = good.clone();
        b[at] = byte;
        // keep the header checksum right so only the field itself is wrong
        Ipv4Packet::new_unchecked(&mut b[..]).fill_checksum();
        Ipv4Repr::parse(&b)
    };
    assert!(matches!(
        with(0, 0x65),
        Err(Error::BadField {
            format: Format::Ipv4,
            field: "version",
            found: 6
        })
    ));
    assert!(matches!(
        with(0, 0x44),
        Err(Error::BadField {
            format: Format::Ipv4,
            field: "ihl",
            found: 4
        })
    ));
    assert!(matches!(
        with(0, 0x46),
        Err(Error::Unsupported {
            format: Format::Ipv4,
            field: "ihl",
            found: 6,
            ..
        })
    ));
    assert!(matches!(
        with(6, 0x60),
        Err(Error::Unsupported {
            field: "flags_fragment_offset",
            found: 0x6000,
            ..
        })
    ));
    assert!(matches!(
        with(7, 0x01),
        Err(Error::Unsupported {
            field: "flags_fragment_offset",
            found: 0x4001,
            ..
        })
    ));
    // the reserved flag is ignored, as the box ignores it
    assert!(with(6, 0xC0).is_ok());
    assert!(matches!(
        with(3, 0x27),
        Err(Error::LengthMismatch {
            format: Format::Ipv4,
            required: 0x27,
            actual: 0x26
        })
    ));
    assert!(matches!(
        with(3, 19),
        Err(Error::LengthMismatch {
            format: Format::Ipv4,
            required: 19,
            ..
        })
    ));
    let mut bad_sum = good.clone();
    bad_sum[11] ^= 1;
    assert_eq!(
        Ipv4Repr::parse(&bad_sum),
        Err(Error::BadChecksum {
            format: Format::Ipv4,
            found: 0xB6BA,
            computed: 0xB6BB
        })
    );
    assert!(matches!(
        Ipv4Repr::parse(&good[..19]),
        Err(Error::Truncated {
            format: Format::Ipv4,
            required: 20,
            actual: 19
        })
    ));
}

#[test]
fn udp_checks_length_and_checksum() {
    let ip = udp_golden();
    let udp = &ip[20..];
    let mut b = udp.to_vec();
    b[7] ^= 1;
    assert_eq!(
        UdpRepr::parse(&b, HOST_IP, BOX_IP),
        Err(Error::BadChecksum {
            format: Format::Udp,
            found: 0x3858,
            computed: 0x3859
        })
    );
    // checksum 0: none computed, taken
    b[6..8].fill(0);
    assert!(UdpRepr::parse(&b, HOST_IP, BOX_IP).is_ok());
    // another address: the pseudo header no longer matches
    assert!(UdpRepr::parse(udp, HOST_IP, [192, 0, 2, 11]).is_err());
    let mut long = udp.to_vec();
    long.push(0);
    assert_eq!(
        UdpRepr::parse(&long, HOST_IP, BOX_IP),
        Err(Error::LengthMismatch {
            format: Format::Udp,
            required: 18,
            actual: 19
        })
    );
    assert!(matches!(
        UdpRepr::parse(&udp[..7], HOST_IP, BOX_IP),
        Err(Error::Truncated {
            format: Format::Udp,
            ..
        })
    ));
}

/// A datagram whose sum comes to 0 is sent with checksum 0xFFFF (RFC 768), which verifies.
#[test]
fn udp_sum_of_zero_is_sent_as_all_ones() {
    let header = [0x9C, 0x40, 0xD3, 0x4B, 0x00, 0x0A, 0x00, 0x00];
    let pseudo = ipv4_pseudo_header(HOST_IP, BOX_IP, ipv4::PROTOCOL_UDP, 10);
    // the payload word that makes the one's complement sum all ones
    let word = checksum(&[&pseudo, &header, &[0, 0]]).to_be_bytes();
    let repr = UdpRepr {
        source_port: 40000,
        destination_port: 54091,
        payload: &word,
    };
    let mut out = [0u8; 10];
    repr.emit(&mut out, HOST_IP, BOX_IP);
    assert_eq!(out[6..8], [0xFF, 0xFF]);
    assert_eq!(UdpRepr::parse(&out, HOST_IP, BOX_IP), Ok(repr));
}

#[test]
fn arp_and_icmp_refusals() {
    let arp = hex("0001 0800 06 04 0001 020000000001 c0000201 000000000000 c000020a");
    for (at, byte, field) in [
        (1, 6, "hardware_type"),
        (2, 0x86, "protocol_type"),
        (4, 8, "hardware_len"),
        (5, 16, "protocol_len"),
        (7, 3, "operation"),
    ] {
        let mut b = arp.clone();
        b[at] = byte;
        assert!(
            matches!(ArpRepr::parse(&b), Err(Error::BadField { format: Format::Arp, field: f, .. }) if f == field),
            "{field}"
        );
    }
    assert!(matches!(
        ArpRepr::parse(&arp[..27]),
        Err(Error::Truncated {
            format: Format::Arp,
            required: 28,
            ..
        })
    ));
    let mut echo = hex(
        "08 00 3b27 1234 0001 6162636465666768696a6b6c6d6e6f7071727374757677616263646566676869",
    );
    assert!(IcmpPacket::new_checked(&echo[..])
        .unwrap()
        .verify_checksum());
    echo[8] = b'A';
    assert_eq!(
        IcmpEchoRepr::parse(&echo),
        Err(Error::BadChecksum {
            format: Format::Icmp,
            found: 0x3B27,
            computed: 0x5B27
        })
    );
    // a destination unreachable (type 3) with a right checksum is no echo
    let mut unreachable = hex("03 01 0000 00000000");
    let sum = checksum(&[&unreachable]);
    unreachable[2..4].copy_from_slice(&sum.to_be_bytes());
    assert!(matches!(
        IcmpEchoRepr::parse(&unreachable),
        Err(Error::BadField {
            format: Format::Icmp,
            field: "type",
            found: 3
        })
    ));
}

fn ipv4_repr() -> impl Strategy<Value = Ipv4Repr> {
    (
        any::<[u8; 4]>(),
        any::<[u8; 4]>(),
        any::<u8>(),
        any::<u8>(),
        any::<u16>(),
        any::<bool>(),
        any::<u8>(),
    )
        .prop_map(
            |(source, destination, protocol, dscp_ecn, identification, dont_fragment, ttl)| {
                Ipv4Repr {
                    source,
                    destination,
                    protocol,
                    payload_len: 0,
                    dscp_ecn,
                    identification,
                    dont_fragment,
                    ttl,
                }
            },
        )
}

fn etherparse_ipv4(r: &Ipv4Repr) -> Ipv4Header {
    let mut h = Ipv4Header::new(
        r.payload_len as u16,
        r.ttl,
        IpNumber(r.protocol),
        r.source,
        r.destination,
    )
    .unwrap();
    h.dscp = etherparse::IpDscp::try_new(r.dscp_ecn >> 2).unwrap();
    h.ecn = etherparse::IpEcn::try_new(r.dscp_ecn & 3).unwrap();
    h.identification = r.identification;
    h.dont_fragment = r.dont_fragment;
    h.header_checksum = h.calc_header_checksum();
    h
}

proptest! {
    /// Ethernet, IPv4 and UDP emitted here are what etherparse writes for the same
    /// fields, checksums included, and parse back to the same reprs.
    #[test]
    fn udp_frames_agree_with_etherparse(
        destination in any::<[u8; 6]>(),
        source in any::<[u8; 6]>(),
        ip in ipv4_repr(),
        ports in any::<(u16, u16)>(),
        payload in proptest::collection::vec(any::<u8>(), 0..64),
    ) {
        let ip = Ipv4Repr { protocol: ipv4::PROTOCOL_UDP, payload_len: 8 + payload.len(), ..ip };
        let ethernet = EthernetRepr { destination, source, ethertype: ethernet::ETHERTYPE_IPV4 };
        let udp = UdpRepr { source_port: ports.0, destination_port: ports.1, payload: &payload };
        let mut ours = vec![0u8; 14 + ip.buffer_len()];
        ethernet.emit(&mut ours);
        ip.emit(&mut ours[14..]);
        udp.emit(&mut ours[34..], ip.source, ip.destination);

        let ip_header = etherparse_ipv4(&ip);
        let mut theirs = Vec::new();
        Ethernet2Header { source, destination, ether_type: EtherType::IPV4 }
            .write(&mut theirs).unwrap();
        ip_header.write(&mut theirs).unwrap();
        UdpHeader::with_ipv4_checksum(ports.0, ports.1, &ip_header, &payload)
            .unwrap()
            .write(&mut theirs)
            .unwrap();
        theirs.extend_from_slice(&payload);
        prop_assert_eq!(&ours, &theirs);

        prop_assert_eq!(EthernetRepr::parse(&theirs).unwrap(), ethernet);
        prop_assert_eq!(Ipv4Repr::parse(&theirs[14..]).unwrap(), ip);
        let packet = UdpPacket::new_checked(&theirs[34..]).unwrap();
        prop_assert!(packet.verify_checksum(ip.source, ip.destination));
        prop_assert_eq!(UdpRepr::parse(&theirs[34..], ip.source, ip.destination).unwrap(), udp);
    }

    /// ICMP echo messages and ARP packets emitted here are etherparse's.
    #[test]
    fn echo_and_arp_agree_with_etherparse(
        reply in any::<bool>(),
        identifier in any::<u16>(),
        sequence in any::<u16>(),
        data in proptest::collection::vec(any::<u8>(), 0..64),
        arp_reply in any::<bool>(),
        macs in any::<([u8; 6], [u8; 6])>(),
        ips in any::<([u8; 4], [u8; 4])>(),
    ) {
        let echo = IcmpEchoRepr {
            message: if reply { EchoMessage::Reply } else { EchoMessage::Request },
            identifier,
            sequence,
            data: &data,
        };
        let mut ours = vec![0u8; echo.buffer_len()];
        echo.emit(&mut ours);
        let kind = IcmpEchoHeader { id: identifier, seq: sequence };
        let kind = if reply { Icmpv4Type::EchoReply(kind) } else { Icmpv4Type::EchoRequest(kind) };
        let mut theirs = Icmpv4Header::with_checksum(kind, &data).to_bytes().to_vec();
        theirs.extend_from_slice(&data);
        prop_assert_eq!(&ours, &theirs);
        prop_assert_eq!(IcmpEchoRepr::parse(&theirs).unwrap(), echo);

        let arp = ArpRepr {
            operation: if arp_reply { ArpOperation::Reply } else { ArpOperation::Request },
            sender_mac: macs.0,
            sender_ip: ips.0,
            target_mac: macs.1,
            target_ip: ips.1,
        };
        let mut ours = vec![0u8; arp.buffer_len()];
        arp.emit(&mut ours);
        let theirs = ArpPacket::new(
            ArpHardwareId::ETHERNET,
            EtherType::IPV4,
            etherparse::ArpOperation(arp.operation.code()),
            &macs.0,
            &ips.0,
            &macs.1,
            &ips.1,
        )
        .unwrap()
        .to_bytes()
        .to_vec();
        prop_assert_eq!(&ours, &theirs);
        prop_assert_eq!(ArpRepr::parse(&theirs).unwrap(), arp);
    }
}
