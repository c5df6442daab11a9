//! How the box's datagrams travel: Ethernet II, IPv4 without options, UDP.
//!
//! The defaults address documentation networks (RFC 5737) and a dynamic UDP port; a real
//! installation sets its own through the box parameters.
//!
//! The headers themselves are declared in [`crate::wire`]; the lengths and field ranges
//! below are its, under the names the gateware uses.

use crate::wire::{ethernet, ipv4, udp};

/// Ethernet, IPv4 and UDP addresses of the box and its host.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct LinkConfig {
    /// Box MAC address (locally administered).
    pub box_mac: [u8; 6],
    /// Destination MAC address (broadcast by default, so no ARP is needed).
    pub host_mac: [u8; 6],
    /// Box IPv4 address.
    pub box_ip: [u8; 4],
    /// Host IPv4 address.
    pub host_ip: [u8; 4],
    /// Box UDP port.
    pub box_port: u16,
    /// Host UDP port.
    pub host_port: u16,
    /// The host subnet the box takes commands from: its network address...
    pub host_subnet: [u8; 4],
    /// ...and prefix length (0 = every address, 32 = one host).
    pub host_subnet_prefix_len: u8,
}

/// UDP port of box and host: 54091 (0xD34B, "SK" with the top bit set), in the dynamic
/// range that IANA never assigns to a service.
pub const DEFAULT_PORT: u16 = 0xD34B;

impl LinkConfig {
    /// Box 02:53:4b:00:00:01 at 192.0.2.10:54091 to broadcast, 192.0.2.1:54091; commands
    /// from 192.0.2.0/24.
    pub const DEFAULT: LinkConfig = LinkConfig {
        box_mac: [0x02, 0x53, 0x4B, 0x00, 0x00, 0x01],
        host_mac: [0xFF; 6],
        box_ip: [192, 0, 2, 10],
        host_ip: [192, 0, 2, 1],
        box_port: DEFAULT_PORT,
        host_port: DEFAULT_PORT,
        host_subnet: [192, 0, 2, 0],
        host_subnet_prefix_len: 24,
    };

    /// Whether `ip` is inside the host subnet (the prefix's bits equal; a prefix length
    /// above 32 counts as 32).
    pub fn in_host_subnet(&self, ip: [u8; 4]) -> bool {
        let bits = u32::from(self.host_subnet_prefix_len.min(32));
        let mask = u32::MAX.checked_shl(32 - bits).unwrap_or(0);
        (u32::from_be_bytes(ip) ^ u32::from_be_bytes(self.host_subnet)) & mask == 0
    }
}

impl Default for LinkConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Bit rate of the link (Gigabit Ethernet).
pub const LINK_BITS_PER_S: u64 = 1_000_000_000;
/// Largest IPv4 packet on the link (the Ethernet MTU).
pub const MTU: usize = 1500;
/// Ethernet II header length.
pub const ETHERNET_HEADER_LEN: usize = ethernet::HEADER_LEN;
/// IPv4 header length (no options).
pub const IPV4_HEADER_LEN: usize = ipv4::HEADER_LEN;
/// UDP header length.
pub const UDP_HEADER_LEN: usize = udp::HEADER_LEN;
/// IPv4 total length field, from the start of the IPv4 header (RFC 791).
pub const IPV4_TOTAL_LEN: crate::Field = ipv4::field::TOTAL_LEN;
/// IPv4 header checksum field, from the start of the IPv4 header (RFC 791).
pub const IPV4_CHECKSUM: crate::Field = ipv4::field::CHECKSUM;
/// UDP length field, from the start of the UDP header (RFC 768).
pub const UDP_LEN: crate::Field = udp::field::LENGTH;
/// UDP checksum field, from the start of the UDP header (RFC 768).
pub const UDP_CHECKSUM: crate::Field = udp::field::CHECKSUM;
/// Frame position of the ARP packet or the IPv4 header (from the destination MAC, no
/// preamble).
pub const ARP_AT: usize = ETHERNET_HEADER_LEN;
/// Frame position of the IPv4 header.
pub const IPV4_AT: usize = ETHERNET_HEADER_LEN;
/// Frame position of the ICMP message (IPv4 without options).
pub const ICMP_AT: usize = IPV4_AT + IPV4_HEADER_LEN;
/// Frame position of the UDP header (IPv4 without options).
pub const UDP_AT: usize = IPV4_AT + IPV4_HEADER_LEN;
/// Frame position of the UDP payload: the box datagram, command or acknowledgement header.
pub const PAYLOAD_AT: usize = UDP_AT + UDP_HEADER_LEN;
/// Preamble and start-of-frame delimiter on the wire.
pub const PREAMBLE_LEN: usize = 8;
/// Frame check sequence length.
pub const FCS_LEN: usize = 4;
/// Smallest Ethernet frame without FCS.
pub const MIN_FRAME_LEN: usize = 60;
/// Shortest frame the box's MAC takes, FCS included (IEEE 802.3).
pub const MIN_RECEIVE_LEN: usize = MIN_FRAME_LEN + FCS_LEN;
/// Longest frame the box's MAC takes, FCS included (1500-byte MTU, no VLAN tag).
pub const MAX_RECEIVE_LEN: usize = ETHERNET_HEADER_LEN + MTU + FCS_LEN;
/// Idle bytes the box leaves between frames (the IEEE 802.3 inter-packet gap).
pub const INTER_FRAME_GAP: usize = 12;
/// IPv4 time to live of the box's packets.
pub const IPV4_TTL: u8 = 64;
pub use crate::wire::arp::{
    REPLY_HEADER as ARP_REPLY_HEADER, REQUEST_HEADER as ARP_REQUEST_HEADER,
};
pub use crate::wire::ethernet::{ETHERTYPE_ARP, ETHERTYPE_IPV4};
pub use crate::wire::icmp::{
    TYPE_ECHO_REPLY as ICMP_ECHO_REPLY, TYPE_ECHO_REQUEST as ICMP_ECHO_REQUEST,
};
pub use crate::wire::ipv4::{PROTOCOL_ICMP as IP_PROTOCOL_ICMP, PROTOCOL_UDP as IP_PROTOCOL_UDP};

/// The IPv4 header of a packet the box sends: DSCP/ECN 0, identification 0, don't
/// fragment, TTL [`IPV4_TTL`].
pub const fn box_ipv4_header(
    protocol: u8,
    source: [u8; 4],
    destination: [u8; 4],
    payload_len: usize,
) -> crate::wire::Ipv4Repr {
    crate::wire::Ipv4Repr {
        source,
        destination,
        protocol,
        payload_len,
        dscp_ecn: 0,
        identification: 0,
        dont_fragment: true,
        ttl: IPV4_TTL,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_positions() {
        assert_eq!((ARP_AT, IPV4_AT, ICMP_AT, UDP_AT), (14, 14, 34, 34));
        assert_eq!(PAYLOAD_AT, 42);
    }

    #[test]
    fn host_subnet_prefixes() {
        let mut l = LinkConfig::DEFAULT;
        assert!(l.in_host_subnet([192, 0, 2, 1]));
        assert!(l.in_host_subnet([192, 0, 2, 255]));
        assert!(!l.in_host_subnet([192, 0, 3, 1]));
        assert!(!l.in_host_subnet([127, 0, 0, 1]));
        l.host_subnet_prefix_len = 0;
        assert!(l.in_host_subnet([127, 0, 0, 1]));
        l.host_subnet = [127, 0, 0, 1];
        l.host_subnet_prefix_len = 32;
        assert!(l.in_host_subnet([127, 0, 0, 1]));
        assert!(!l.in_host_subnet([127, 0, 0, 2]));
    }
}
