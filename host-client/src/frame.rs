//! From a captured frame to the UDP payload that may hold a box datagram.
//!
//! The box sends Ethernet II / IPv4 (no options) / UDP frames (docs/design.md section 4). Its
//! source port and addresses are parameters, so box datagrams are found by their payload
//! magic "SK" on any UDP port, or only on one port when a filter is given. Every other frame
//! is other traffic, counted by kind ([`crate::other_traffic`]), never bad input. Parsing is
//! etherparse's; this module only says why a frame is not a box datagram.
//!
//! Checksums are verified with etherparse's own computation (independent of the gateware's):
//! the IPv4 header checksum always, the UDP checksum unless it is 0 over IPv4 (RFC 768:
//! "not computed"; over IPv6 it is mandatory, RFC 8200), of the frames that carry a skinbox
//! datagram only. Such a frame with a wrong checksum gives nothing to the decoder.

use crate::bad_input::{BadInput, FrameFault, Reason};
use crate::other_traffic::{udp_service, OtherKind, OtherTraffic};
use etherparse::{IpNumber, LaxNetSlice, LaxSlicedPacket, NetSlice, SlicedPacket, TransportSlice};
use skinbox_protocol::datagram::has_magic;
use skinbox_protocol::wire::ethernet::{ETHERTYPE_ARP as ETHER_ARP, ETHERTYPE_IPV4 as ETHER_IPV4};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};

/// What the first bytes of a captured frame are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkType {
    /// Ethernet II (pcap link type 1).
    Ethernet,
    /// A bare IPv4 or IPv6 packet (pcap link types 101 and 228/229).
    RawIp,
    /// Linux cooked capture v1 (link type 113: `tcpdump -i any` on older systems).
    LinuxSll,
}

/// A UDP datagram found in a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UdpDatagram<'a> {
    /// Sender.
    pub source: SocketAddr,
    /// Receiver.
    pub destination: SocketAddr,
    /// The UDP payload, cut to the UDP length (padding and FCS are not part of it).
    pub payload: &'a [u8],
}

/// Why a frame does not carry a box datagram: someone else's traffic, or a frame that
/// carried one and is broken.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameReject {
    /// Not the box's: another protocol, another UDP port, a UDP payload without the magic
    /// "SK" ([`crate::other_traffic`]). Not bad input.
    Other(OtherKind),
    /// etherparse could not slice a frame that is (or may be) IP/UDP: too short, bad IP
    /// header, ...
    Malformed(String),
    /// The IPv4 header checksum of a skinbox datagram's frame does not match the header.
    BadIpv4Checksum {
        /// Checksum in the header.
        found: u16,
        /// Checksum of the header's bytes.
        computed: u16,
    },
    /// The UDP checksum of a skinbox datagram does not match the pseudo header, UDP header
    /// and payload.
    BadUdpChecksum {
        /// Checksum in the UDP header.
        found: u16,
        /// Checksum of the datagram as captured.
        computed: u16,
    },
}

impl FrameReject {
    /// The counting key of bad input (`None` for other traffic).
    pub fn reason(&self) -> Option<Reason> {
        Some(Reason::Frame(match self {
            FrameReject::Other(_) => return None,
            FrameReject::Malformed(_) => FrameFault::Malformed,
            FrameReject::BadIpv4Checksum { .. } => FrameFault::BadIpv4Checksum,
            FrameReject::BadUdpChecksum { .. } => FrameFault::BadUdpChecksum,
        }))
    }

    /// Counts this rejection: other traffic by kind, bad input by reason.
    pub fn count_in(&self, bad: &mut BadInput, other: &mut OtherTraffic) {
        let Some(reason) = self.reason() else {
            if let FrameReject::Other(kind) = self {
                other.count(*kind);
            }
            return;
        };
        bad.count(reason, || match self {
            FrameReject::Malformed(m) => format!("frame: malformed: {m}"),
            FrameReject::BadIpv4Checksum { found, computed } => format!(
                "frame: IPv4 header checksum 0x{found:04X}, the header's bytes give 0x{computed:04X}"
            ),
            FrameReject::BadUdpChecksum { found, computed } => format!(
                "frame: UDP checksum 0x{found:04X}, the datagram as captured gives 0x{computed:04X}"
            ),
            FrameReject::Other(_) => String::new(),
        });
    }
}

const ETHER_LLDP: u16 = 0x88CC;
const ETHER_IPV6: u16 = 0x86DD;

fn ether_kind(ether_type: u16) -> OtherKind {
    match ether_type {
        ETHER_ARP => OtherKind::Arp,
        ETHER_LLDP => OtherKind::Lldp,
        ETHER_IPV6 => OtherKind::Ipv6,
        t => OtherKind::EtherType(t),
    }
}

fn ip_kind(protocol: IpNumber) -> OtherKind {
    match protocol {
        IpNumber::TCP => OtherKind::Tcp,
        IpNumber::ICMP => OtherKind::Icmp,
        p => OtherKind::IpProtocol(p.0),
    }
}

/// A frame etherparse cannot slice strictly: bad input when it is (or may be) IP/UDP,
/// other traffic when its EtherType or IP protocol says it is not.
fn classify_unsliceable(frame: &[u8], link: LinkType, error: String) -> FrameReject {
    let lax = match link {
        LinkType::Ethernet => LaxSlicedPacket::from_ethernet(frame).ok(),
        LinkType::RawIp => LaxSlicedPacket::from_ip(frame).ok(),
        LinkType::LinuxSll => None,
    };
    let Some(lax) = lax else {
        return FrameReject::Malformed(error);
    };
    match &lax.net {
        Some(LaxNetSlice::Arp(_)) => FrameReject::Other(OtherKind::Arp),
        Some(LaxNetSlice::Ipv6(ip)) if ip.payload().ip_number != IpNumber::UDP => {
            FrameReject::Other(OtherKind::Ipv6)
        }
        Some(LaxNetSlice::Ipv4(ip)) if ip.payload().ip_number != IpNumber::UDP => {
            FrameReject::Other(ip_kind(ip.payload().ip_number))
        }
        Some(_) => FrameReject::Malformed(error),
        None => match lax.ether_payload().map(|p| p.ether_type.0) {
            Some(ETHER_IPV4 | ETHER_IPV6) | None => FrameReject::Malformed(error),
            Some(t) => FrameReject::Other(ether_kind(t)),
        },
    }
}

/// The skinbox datagram in `frame`, if it carries one: UDP on `port` (either side; any
/// port when `None`) whose payload begins with the magic "SK". Every other frame is
/// [`FrameReject::Other`], whatever its checksums; a skinbox datagram's frame with a wrong
/// IPv4 header or UDP checksum, or one etherparse cannot slice, is bad input.
pub fn udp_payload(
    frame: &[u8],
    link: LinkType,
    port: Option<u16>,
) -> Result<UdpDatagram<'_>, FrameReject> {
    let sliced = match link {
        LinkType::Ethernet => SlicedPacket::from_ethernet(frame),
        LinkType::RawIp => SlicedPacket::from_ip(frame),
        LinkType::LinuxSll => SlicedPacket::from_linux_sll(frame),
    };
    let sliced = match sliced {
        Ok(s) => s,
        Err(e) => return Err(classify_unsliceable(frame, link, e.to_string())),
    };
    let is_v6 = matches!(sliced.net, Some(NetSlice::Ipv6(_)));
    // What the frame is, before any checksum: other traffic is never judged.
    let (source_ip, destination_ip) = match &sliced.net {
        Some(NetSlice::Ipv4(ip)) => {
            if ip.is_payload_fragmented() {
                return Err(FrameReject::Other(OtherKind::IpFragment));
            }
            let h = ip.header();
            (
                std::net::IpAddr::V4(h.source_addr()),
                std::net::IpAddr::V4(h.destination_addr()),
            )
        }
        Some(NetSlice::Ipv6(ip)) => {
            if ip.is_payload_fragmented() {
                return Err(FrameReject::Other(OtherKind::Ipv6));
            }
            let h = ip.header();
            (
                std::net::IpAddr::V6(h.source_addr()),
                std::net::IpAddr::V6(h.destination_addr()),
            )
        }
        Some(NetSlice::Arp(_)) => return Err(FrameReject::Other(OtherKind::Arp)),
        None => {
            let kind = sliced
                .payload_ether_type()
                .map_or(OtherKind::EtherType(0), |t| ether_kind(t.0));
            return Err(FrameReject::Other(kind));
        }
    };
    let udp = match &sliced.transport {
        Some(TransportSlice::Udp(udp)) => udp,
        _ if is_v6 => return Err(FrameReject::Other(OtherKind::Ipv6)),
        _ => {
            let protocol = sliced.ip_payload().map_or(IpNumber(255), |p| p.ip_number);
            return Err(FrameReject::Other(ip_kind(protocol)));
        }
    };
    let (sp, dp) = (udp.source_port(), udp.destination_port());
    let not_ours = |fallback: OtherKind| {
        let kind = if is_v6 {
            OtherKind::Ipv6
        } else {
            udp_service(dp)
                .or_else(|| udp_service(sp))
                .map_or(fallback, OtherKind::UdpService)
        };
        FrameReject::Other(kind)
    };
    if let Some(p) = port {
        if sp != p && dp != p {
            return Err(not_ours(OtherKind::UdpOtherPort));
        }
    }
    if !has_magic(udp.payload()) {
        return Err(not_ours(OtherKind::UdpNotSkinbox));
    }
    // A skinbox datagram: its checksums must hold.
    if let Some(NetSlice::Ipv4(ip)) = &sliced.net {
        let h = ip.header();
        let computed = h.to_header().calc_header_checksum();
        if computed != h.header_checksum() {
            return Err(FrameReject::BadIpv4Checksum {
                found: h.header_checksum(),
                computed,
            });
        }
    }
    let found = udp.checksum();
    let computed = match (source_ip, destination_ip) {
        // RFC 768: a zero checksum over IPv4 means the sender computed none.
        (std::net::IpAddr::V4(_), _) if found == 0 => None,
        (std::net::IpAddr::V4(s), std::net::IpAddr::V4(d)) => udp
            .to_header()
            .calc_checksum_ipv4_raw(s.octets(), d.octets(), udp.payload())
            .ok(),
        (std::net::IpAddr::V6(s), std::net::IpAddr::V6(d)) => udp
            .to_header()
            .calc_checksum_ipv6_raw(s.octets(), d.octets(), udp.payload())
            .ok(),
        _ => None,
    };
    if let Some(computed) = computed.filter(|c| *c != found) {
        return Err(FrameReject::BadUdpChecksum { found, computed });
    }
    Ok(UdpDatagram {
        source: SocketAddr::new(source_ip, sp),
        destination: SocketAddr::new(destination_ip, dp),
        payload: udp.payload(),
    })
}

/// Default addresses for frames the host writes around payloads it received on a socket
/// (pcap recording, synthetic captures): locally administered MACs, documentation-free
/// loopback IPs. They only have to be well-formed; the decoder ignores them.
pub const HOST_MAC: [u8; 6] = [0x02, 0x00, 0x00, 0x00, 0x00, 0x01];
/// See [`HOST_MAC`].
pub const BOX_MAC: [u8; 6] = [0x02, 0x53, 0x4b, 0x00, 0x00, 0x01];

/// Builds an Ethernet II / IPv4 / UDP frame around `payload` (etherparse computes the
/// lengths and checksums). Non-IPv4 addresses are written as 127.0.0.1.
pub fn build_udp_frame(source: SocketAddr, destination: SocketAddr, payload: &[u8]) -> Vec<u8> {
    let v4 = |a: SocketAddr| match a {
        SocketAddr::V4(a) => a,
        SocketAddr::V6(a) => SocketAddrV4::new(Ipv4Addr::LOCALHOST, a.port()),
    };
    let (s, d) = (v4(source), v4(destination));
    let builder = etherparse::PacketBuilder::ethernet2(BOX_MAC, HOST_MAC)
        .ipv4(s.ip().octets(), d.ip().octets(), 64)
        .udp(s.port(), d.port());
    let mut frame = Vec::with_capacity(builder.size(payload.len()));
    // Writing into a Vec fails only for payloads over the UDP/IPv4 length limit; the
    // frame then holds what was written, and the decoder reports it as malformed.
    let _ = builder.write(&mut frame, payload);
    frame
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_payload_and_ignores_padding_and_fcs() {
        let src: SocketAddr = "10.0.0.2:5000".parse().unwrap();
        let dst: SocketAddr = "10.0.0.1:6000".parse().unwrap();
        let mut frame = build_udp_frame(src, dst, b"SK");
        frame.extend_from_slice(&[0; 16]); // padding to 60 bytes and a fake FCS
        let udp = udp_payload(&frame, LinkType::Ethernet, None).unwrap();
        assert_eq!(udp.payload, b"SK");
        assert_eq!((udp.source, udp.destination), (src, dst));
        assert_eq!(
            udp_payload(&frame, LinkType::Ethernet, Some(7)),
            Err(FrameReject::Other(OtherKind::UdpOtherPort))
        );
        assert!(udp_payload(&frame, LinkType::Ethernet, Some(5000)).is_ok());
        assert!(matches!(
            udp_payload(&frame[..20], LinkType::Ethernet, None),
            Err(FrameReject::Malformed(_))
        ));
        assert!(udp_payload(&frame[14..], LinkType::RawIp, None).is_ok());
    }

    /// Internet checksum (RFC 1071) written here on its own, as the oracle.
    fn ones_complement(chunks: &[&[u8]]) -> u16 {
        let bytes: Vec<u8> = chunks.concat();
        let mut sum: u32 = bytes
            .chunks(2)
            .map(|c| u32::from(u16::from_be_bytes([c[0], *c.get(1).unwrap_or(&0)])))
            .sum();
        while sum > 0xFFFF {
            sum = (sum & 0xFFFF) + (sum >> 16);
        }
        !(sum as u16)
    }

    #[test]
    fn checksums_are_verified() {
        let src: SocketAddr = "192.0.2.10:54091".parse().unwrap();
        let dst: SocketAddr = "192.0.2.1:54091".parse().unwrap();
        let good = build_udp_frame(src, dst, b"SK payload");
        // The builder's checksums agree with the oracle: every sum folds to zero.
        assert_eq!(ones_complement(&[&good[14..34]]), 0);
        let udp_len = (good.len() - 34) as u16;
        let pseudo = [&good[26..34], &[0, 17], &udp_len.to_be_bytes()[..]].concat();
        assert_eq!(ones_complement(&[&pseudo, &good[34..]]), 0);
        assert!(udp_payload(&good, LinkType::Ethernet, None).is_ok());

        // A payload byte changed, the UDP checksum left as it was.
        let mut stale = good.clone();
        *stale.last_mut().unwrap() ^= 0x01;
        assert!(matches!(
            udp_payload(&stale, LinkType::Ethernet, None),
            Err(FrameReject::BadUdpChecksum { .. })
        ));
        // The same with the checksum zeroed: "not computed", accepted over IPv4.
        stale[40..42].copy_from_slice(&[0, 0]);
        assert!(udp_payload(&stale, LinkType::Ethernet, None).is_ok());

        // A TTL changed, the IPv4 header checksum left as it was.
        let mut ip = good.clone();
        ip[22] = 63;
        let err = udp_payload(&ip, LinkType::Ethernet, None).unwrap_err();
        assert!(
            matches!(err, FrameReject::BadIpv4Checksum { .. }),
            "{err:?}"
        );
        // Fixed with the oracle's checksum, it is accepted again.
        ip[24..26].copy_from_slice(&[0, 0]);
        let fixed = ones_complement(&[&ip[14..34]]);
        ip[24..26].copy_from_slice(&fixed.to_be_bytes());
        assert!(udp_payload(&ip, LinkType::Ethernet, None).is_ok());
    }
}
