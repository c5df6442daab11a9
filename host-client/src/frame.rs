//! From a captured frame to the UDP payload that may hold a box datagram.
//!
//! The box sends Ethernet II / IPv4 (no options) / UDP frames (docs/design.md section 4). Its
//! source port and addresses are parameters, so box datagrams are found by their payload
//! magic "SK" on any UDP port, or only on one port when a filter is given. Parsing is
//! etherparse's; this module only says why a frame is not a box datagram.

use crate::BadInput;
use etherparse::{NetSlice, SlicedPacket, TransportSlice};
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4};

/// What the first bytes of a captured frame are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkType {
    /// Ethernet II (pcap link type 1).
    Ethernet,
    /// A bare IPv4 or IPv6 packet (pcap link types 101 and 228/229).
    RawIp,
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

/// Why a frame does not carry a box datagram.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameReject {
    /// etherparse could not slice the frame (too short, bad IP header, ...).
    Malformed(String),
    /// Not an IP packet (ARP, other ether types).
    NotIp,
    /// An IP fragment: the box never fragments, so it is not ours.
    Fragment,
    /// IP, but not UDP.
    NotUdp,
    /// UDP on another port than the filter.
    OtherPort(u16),
}

impl FrameReject {
    /// A short counting key.
    pub fn reason(&self) -> &'static str {
        match self {
            FrameReject::Malformed(_) => "frame: malformed",
            FrameReject::NotIp => "frame: not IP",
            FrameReject::Fragment => "frame: IP fragment",
            FrameReject::NotUdp => "frame: not UDP",
            FrameReject::OtherPort(_) => "frame: other UDP port",
        }
    }

    /// Counts this rejection.
    pub fn count_in(&self, bad: &mut BadInput) {
        bad.count(self.reason(), || match self {
            FrameReject::Malformed(m) => format!("frame: malformed: {m}"),
            FrameReject::OtherPort(p) => format!("frame: UDP port {p} is not the filter's"),
            other => other.reason().to_string(),
        });
    }
}

/// The UDP datagram in `frame`, if it has one on `port` (either side) or on any port.
pub fn udp_payload(
    frame: &[u8],
    link: LinkType,
    port: Option<u16>,
) -> Result<UdpDatagram<'_>, FrameReject> {
    let sliced = match link {
        LinkType::Ethernet => SlicedPacket::from_ethernet(frame),
        LinkType::RawIp => SlicedPacket::from_ip(frame),
    }
    .map_err(|e| FrameReject::Malformed(e.to_string()))?;
    let (source_ip, destination_ip) = match &sliced.net {
        Some(NetSlice::Ipv4(ip)) => {
            if ip.is_payload_fragmented() {
                return Err(FrameReject::Fragment);
            }
            let h = ip.header();
            (
                std::net::IpAddr::V4(h.source_addr()),
                std::net::IpAddr::V4(h.destination_addr()),
            )
        }
        Some(NetSlice::Ipv6(ip)) => {
            if ip.is_payload_fragmented() {
                return Err(FrameReject::Fragment);
            }
            let h = ip.header();
            (
                std::net::IpAddr::V6(h.source_addr()),
                std::net::IpAddr::V6(h.destination_addr()),
            )
        }
        _ => return Err(FrameReject::NotIp),
    };
    let udp = match &sliced.transport {
        Some(TransportSlice::Udp(udp)) => udp,
        _ => return Err(FrameReject::NotUdp),
    };
    let (sp, dp) = (udp.source_port(), udp.destination_port());
    if let Some(p) = port {
        if sp != p && dp != p {
            return Err(FrameReject::OtherPort(dp));
        }
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
            Err(FrameReject::OtherPort(6000))
        );
        assert!(udp_payload(&frame, LinkType::Ethernet, Some(5000)).is_ok());
        assert!(matches!(
            udp_payload(&frame[..20], LinkType::Ethernet, None),
            Err(FrameReject::Malformed(_))
        ));
        assert!(udp_payload(&frame[14..], LinkType::RawIp, None).is_ok());
    }
}
