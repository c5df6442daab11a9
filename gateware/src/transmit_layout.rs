//! The transmitter's frame layout: where each field of a datagram's frame is on the wire
//! (after the preamble and SFD), from the `protocol` tables, and the frame's constant bytes
//! up to the body. Shared by the transmitter and its blocks.

use crate::hdl::*;
use skinbox_protocol::datagram::{self, field, HEADER_LEN};
use skinbox_protocol::link::*;
use skinbox_protocol::wire::{ethernet, ipv4, udp, EthernetRepr, UdpRepr};

/// Frame byte where the datagram body starts (preamble, Ethernet, IPv4, UDP, box header).
pub const BODY_START: usize = PAYLOAD_AT_ON_WIRE + HEADER_LEN;

// A datagram with an empty body still makes a minimum-size frame: no padding is ever needed.
const _: () = assert!(BODY_START >= PREAMBLE_LEN + MIN_FRAME_LEN);

// Positions on the wire: the frame positions of `link` after the preamble and SFD.
pub(crate) const IPV4_AT_ON_WIRE: usize = PREAMBLE_LEN + IPV4_AT;
pub(crate) const UDP_AT_ON_WIRE: usize = PREAMBLE_LEN + UDP_AT;
pub(crate) const PAYLOAD_AT_ON_WIRE: usize = PREAMBLE_LEN + PAYLOAD_AT;
pub(crate) const IP_TOTAL_LEN_AT: usize = IPV4_AT_ON_WIRE + IPV4_TOTAL_LEN.start;
pub(crate) const IP_CHECKSUM_AT: usize = IPV4_AT_ON_WIRE + IPV4_CHECKSUM.start;
pub(crate) const UDP_LEN_AT: usize = UDP_AT_ON_WIRE + UDP_LEN.start;
pub(crate) const UDP_CHECKSUM_AT: usize = UDP_AT_ON_WIRE + UDP_CHECKSUM.start;
pub(crate) const KIND_AT: usize = PAYLOAD_AT_ON_WIRE + field::KIND;
/// First of the header bytes sent from the `fields` shift registers: flags, sequence, base
/// tick, entry count.
pub(crate) const FIELDS_AT: usize = PAYLOAD_AT_ON_WIRE + field::FLAGS;
pub(crate) const FIELDS_LEN: usize = field::ENTRY_COUNT.end - field::FLAGS;

// The destination's bytes: the destination MAC, the IPv4 destination address and the UDP
// destination port, sent from the `destination` shift registers.
pub(crate) const DESTINATION_MAC_AT: usize = PREAMBLE_LEN + ethernet::field::DESTINATION.start;
pub(crate) const DESTINATION_IP_AT: usize = IPV4_AT_ON_WIRE + ipv4::field::DESTINATION.start;
pub(crate) const DESTINATION_PORT_AT: usize = UDP_AT_ON_WIRE + udp::field::DESTINATION_PORT.start;
pub(crate) const DESTINATION_MAC_LEN: usize =
    ethernet::field::DESTINATION.end - ethernet::field::DESTINATION.start;
pub(crate) const DESTINATION_IP_LEN: usize =
    ipv4::field::DESTINATION.end - ipv4::field::DESTINATION.start;
pub(crate) const DESTINATION_PORT_LEN: usize =
    udp::field::DESTINATION_PORT.end - udp::field::DESTINATION_PORT.start;

/// A frame position (or length) as a kernel constant; panics if it does not fit.
pub(crate) fn position<const N: usize>(at: usize) -> Constant<Bits<N>> {
    constant(at as u64)
}

/// The constant bytes of a frame up to the body; variable fields (the destination's too)
/// are 0 here.
pub(crate) fn template(link: &LinkConfig, box_id: u16, port_count: u8) -> Vec<u8> {
    let mut t = vec![0x55; 7];
    t.push(0xD5);
    // Ethernet, IPv4 and UDP headers as the protocol writes them, destination 0
    let mut headers = [0; PAYLOAD_AT];
    let ethernet = EthernetRepr {
        destination: [0; 6],
        source: link.box_mac,
        ethertype: ETHERTYPE_IPV4,
    };
    ethernet.emit(&mut headers);
    let ip = &mut headers[IPV4_AT..UDP_AT];
    box_ipv4_header(IP_PROTOCOL_UDP, link.box_ip, [0; 4], 0).emit(ip);
    ip[IPV4_TOTAL_LEN].fill(0);
    ip[IPV4_CHECKSUM].fill(0);
    let udp = UdpRepr {
        source_port: link.box_port,
        destination_port: 0,
        payload: &[],
    };
    let udp_header = &mut headers[UDP_AT..];
    udp.emit(udp_header, link.box_ip, [0; 4]);
    udp_header[UDP_LEN].fill(0);
    udp_header[UDP_CHECKSUM].fill(0);
    t.extend(headers);
    t.extend(datagram::MAGIC);
    t.push(datagram::VERSION);
    t.push(0); // kind
    t.extend(box_id.to_be_bytes());
    t.push(port_count);
    t.extend([0; 15]); // flags, sequence, base tick, entry count
    t.extend([0, 0]); // reserved
    assert_eq!(t.len(), BODY_START);
    t
}
