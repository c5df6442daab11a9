//! TransportReceiver: the receive half of the ICMP and UDP layers (docs/control.md, steps
//! 11-14): the ICMP echo request and its checksum, the UDP length, checksum (with the
//! pseudo header) and destination port; and the two values a reply needs from them, the
//! UDP source port and the sum of the ICMP message after its checksum.
//!
//! It listens to the frame parser's beats ([`FrameBeats`]; positions from
//! `protocol::wire::{ipv4, icmp, udp}` after the Ethernet header) beside the IPv4 layer,
//! whose `carries_udp`, `in_payload` and `payload_length` say whether and how far the
//! transport message goes. ICMP and UDP share their header's first eight bytes, which are
//! compared as they pass, with no capture but the UDP source port's: each byte with its
//! expected byte (the echo request's type and code, the box's port, the IPv4 payload's
//! length, a zero checksum; one table by the byte's position), a flag per check cleared
//! when a byte differs and set again at a frame's first beat. They share one
//! ones'-complement sum: from the IPv4 protocol byte on it adds UDP's
//! pseudo header (the protocol word, the payload length in the place of the IPv4 checksum,
//! the addresses) when the protocol is UDP, then the message up to the payload's end.
//! Words enter the sum from a register of the arriving beat's word (`next_word`), so the
//! pseudo header's length takes the checksum's place without a multiplexer behind the
//! register. The checks stand from the clock after the header's last byte was registered
//! (the sum's two clocks after a frame's last beat was registered, with the IPv4 layer's)
//! until the next frame's first beat is registered.
use crate::field_capture::FieldCapture;
use crate::hdl::*;
use crate::ones_complement_sum::OnesComplementSum;
use crate::stream::FrameBeats;
use skinbox_protocol::link::{
    ICMP_AT, ICMP_ECHO_REQUEST, IPV4_AT, IP_PROTOCOL_UDP, PAYLOAD_AT, UDP_AT,
};
use skinbox_protocol::wire::{icmp, ipv4, udp};
use skinbox_protocol::Field;

/// Compared as they pass: the transport header's first eight bytes (ICMP or UDP).
const TRANSPORT: Field = UDP_AT..PAYLOAD_AT;
/// Captured: the UDP source port.
const SOURCE_PORT: Field =
    UDP_AT + udp::field::SOURCE_PORT.start..UDP_AT + udp::field::SOURCE_PORT.end;
const _: () = assert!(ICMP_AT == UDP_AT && TRANSPORT.end == ICMP_AT + icmp::HEADER_LEN);
/// The ICMP message from its identifier: what the echo reply's checksum sums.
const ICMP_REST_AT: usize = ICMP_AT + icmp::field::IDENTIFIER.start;
const IP_PROTOCOL_AT: usize = IPV4_AT + ipv4::field::PROTOCOL;
const IP_CHECKSUM_AT: usize = IPV4_AT + ipv4::field::CHECKSUM.start;

// the header's fields by the low three bits of their frame positions (the checks' groups
// are bits 2..1 of those, 5..4 of the position times 8: ICMP type and code 01, UDP destination port 10, length 11,
// checksum 00)
const _: () = assert!(
    TRANSPORT.start % 8 == 2
        && icmp::field::TYPE == 0
        && icmp::field::CODE == 1
        && udp::field::DESTINATION_PORT.start == 2
        && udp::field::LENGTH.start == 4
        && udp::field::CHECKSUM.start == 6
);

/// The expected header bytes by the low three bits of their frame positions, position 0
/// lowest (the UDP length's two bytes are the payload length's instead).
fn expected_header(box_port: u16) -> u64 {
    let mut header = [0u8; 8];
    header[..2].copy_from_slice(&[ICMP_ECHO_REQUEST, 0]);
    header[udp::field::DESTINATION_PORT].copy_from_slice(&box_port.to_be_bytes());
    header
        .iter()
        .enumerate()
        .map(|(i, &b)| u64::from(b) << (8 * ((TRANSPORT.start + i) % 8)))
        .sum()
}

/// The receive half of the ICMP and UDP layers; see the module documentation.
#[derive(LogicBlock)]
pub struct TransportReceiver {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The frame's beats.
    pub beats: FrameBeats,
    /// The registered beat is a frame's first.
    pub beat_first: Signal<In, Bit>,
    /// The arriving beat (`beats.next_valid`) as a 16-bit word of the frame (even positions
    /// are high bytes).
    pub next_word: Signal<In, Bits<16>>,
    /// The IPv4 layer: the protocol is UDP.
    pub carries_udp: Signal<In, Bit>,
    /// The IPv4 layer: the registered beat is inside the IPv4 payload.
    pub in_payload: Signal<In, Bit>,
    /// The IPv4 layer: the payload's length.
    pub payload_length: Signal<In, Bits<16>>,
    /// Check: the ICMP type and code are an echo request's.
    pub echo_request: Signal<Out, Bit>,
    /// Check: the message's sum (with UDP's pseudo header) verifies.
    pub sum_ok: Signal<Out, Bit>,
    /// Check: the UDP length is the IPv4 payload's.
    pub udp_length_ok: Signal<Out, Bit>,
    /// Check: the UDP checksum is 0 (none sent).
    pub udp_no_checksum: Signal<Out, Bit>,
    /// Check: the UDP destination port is the box's.
    pub to_box_port: Signal<Out, Bit>,
    /// The UDP source port, from the clock after its last byte was registered.
    pub source_port: Signal<Out, Bits<16>>,
    /// The folded sum of the ICMP message from its identifier (odd length padded).
    pub icmp_rest_sum: Signal<Out, Bits<16>>,
    protocol_udp: Constant<Bits<8>>,
    // the expected header bytes by position mod 8
    expected: Constant<Bits<64>>,
    ip_protocol_at: Constant<Bits<11>>,
    ip_checksum_at: Constant<Bits<11>>,
    ip_checksum_low_at: Constant<Bits<11>>,
    transport_at: Constant<Bits<11>>,
    transport_end: Constant<Bits<11>>,
    icmp_rest_at: Constant<Bits<11>>,
    source_port_field: FieldCapture<16>,
    message_sum: OnesComplementSum,
    rest_sum: OnesComplementSum,
    // the word the sum adds: the registered beat's, or the pseudo header's length
    sum_word: DFF<Bits<16>>,
    // where the registered beat is: the IPv4 protocol, the pseudo header's place (IPv4
    // checksum to the transport header), from the transport header on, from the ICMP
    // identifier on
    at_protocol: DFF<Bit>,
    at_pseudo_header: DFF<Bit>,
    at_from_transport: DFF<Bit>,
    at_from_icmp_rest: DFF<Bit>,
    // the registered beat is in the transport header, and its position mod 8, times 8
    at_header: DFF<Bit>,
    header_position: DFF<Bits<6>>,
    // the checks: the header's bytes so far are the expected ones; the sum's, registered
    echo_request_flag: DFF<Bit>,
    port_flag: DFF<Bit>,
    length_flag: DFF<Bit>,
    no_checksum_flag: DFF<Bit>,
    sum_check: DFF<Bit>,
    expected_byte: Signal<Local, Bits<8>>,
    byte_differs: Signal<Local, Bit>,
}

impl TransportReceiver {
    /// The layers of a box listening on UDP port `box_port`.
    pub fn new(box_port: u16) -> Self {
        Self {
            clock: Default::default(),
            beats: Default::default(),
            beat_first: Default::default(),
            next_word: Default::default(),
            carries_udp: Default::default(),
            in_payload: Default::default(),
            payload_length: Default::default(),
            echo_request: Default::default(),
            sum_ok: Default::default(),
            udp_length_ok: Default::default(),
            udp_no_checksum: Default::default(),
            to_box_port: Default::default(),
            source_port: Default::default(),
            icmp_rest_sum: Default::default(),
            protocol_udp: constant(u64::from(IP_PROTOCOL_UDP)),
            expected: Constant::new(expected_header(box_port).into()),
            ip_protocol_at: constant(IP_PROTOCOL_AT as u64),
            ip_checksum_at: constant(IP_CHECKSUM_AT as u64),
            ip_checksum_low_at: constant(IP_CHECKSUM_AT as u64 + 1),
            transport_at: constant(TRANSPORT.start as u64),
            transport_end: constant(TRANSPORT.end as u64),
            icmp_rest_at: constant(ICMP_REST_AT as u64),
            source_port_field: FieldCapture::of(SOURCE_PORT),
            message_sum: Default::default(),
            rest_sum: Default::default(),
            sum_word: Default::default(),
            at_protocol: Default::default(),
            at_pseudo_header: Default::default(),
            at_from_transport: Default::default(),
            at_from_icmp_rest: Default::default(),
            at_header: Default::default(),
            header_position: Default::default(),
            echo_request_flag: Default::default(),
            port_flag: Default::default(),
            length_flag: Default::default(),
            no_checksum_flag: Default::default(),
            sum_check: Default::default(),
            expected_byte: Default::default(),
            byte_differs: Default::default(),
        }
    }
}

impl Logic for TransportReceiver {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            sum_word,
            at_protocol,
            at_pseudo_header,
            at_from_transport,
            at_from_icmp_rest,
            at_header,
            header_position,
            echo_request_flag,
            port_flag,
            length_flag,
            no_checksum_flag,
            sum_check
        );
        self.source_port_field.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.source_port_field.beats);
        // positions of the next registered beat: equality decodes only
        if self.beats.next_valid.val() {
            self.at_protocol.d.next = self.beats.next_index.val() == self.ip_protocol_at.val();
            self.at_pseudo_header.d.next = (self.beats.next_index.val()
                == self.ip_checksum_at.val())
                | (self.at_pseudo_header.q.val()
                    & (self.beats.next_index.val() != self.transport_at.val())
                    & self.beats.in_frame.val());
            self.at_from_transport.d.next = (self.beats.next_index.val()
                == self.transport_at.val())
                | (self.at_from_transport.q.val() & self.beats.in_frame.val());
            self.at_from_icmp_rest.d.next = (self.beats.next_index.val()
                == self.icmp_rest_at.val())
                | (self.at_from_icmp_rest.q.val() & self.beats.in_frame.val());
            self.at_header.d.next = (self.beats.next_index.val() == self.transport_at.val())
                | (self.at_header.q.val()
                    & (self.beats.next_index.val() != self.transport_end.val())
                    & self.beats.in_frame.val());
            self.header_position.d.next =
                bit_cast::<6, 3>(self.beats.next_index.val().get_bits::<3>(0)) << 3;
        }
        // UDP's pseudo header: the payload length in the clock of the IPv4 checksum's
        // high byte, nothing in that of its low byte, then the addresses
        self.sum_word.d.next = self.next_word.val();
        if self.beats.in_frame.val() & (self.beats.next_index.val() == self.ip_checksum_at.val()) {
            self.sum_word.d.next = self.payload_length.val();
        }
        if self.beats.in_frame.val()
            & (self.beats.next_index.val() == self.ip_checksum_low_at.val())
        {
            self.sum_word.d.next = 0.into();
        }
        // the message's sum restarts at the IPv4 protocol (with UDP's pseudo-header
        // protocol word); the ICMP rest's at a frame's first beat
        self.message_sum.clock.next = self.clock.val();
        self.message_sum.word.next = self.sum_word.q.val();
        self.message_sum.add.next = self.beats.beat_valid.val()
            & ((self.carries_udp.val() & self.at_pseudo_header.q.val())
                | (self.in_payload.val() & self.at_from_transport.q.val()));
        self.message_sum.restart.next = self.beats.beat_valid.val() & self.at_protocol.q.val();
        self.message_sum.start.next = 0.into();
        if self.beats.beat_data.val() == self.protocol_udp.val() {
            self.message_sum.start.next = bit_cast::<16, 8>(self.protocol_udp.val());
        }
        self.rest_sum.clock.next = self.clock.val();
        self.rest_sum.word.next = self.sum_word.q.val();
        self.rest_sum.add.next =
            self.beats.beat_valid.val() & self.in_payload.val() & self.at_from_icmp_rest.q.val();
        self.rest_sum.restart.next = self.beats.beat_valid.val() & self.beat_first.val();
        self.rest_sum.start.next = 0.into();

        // the header's bytes compared as they pass (a frame's first beat sets the flags)
        self.expected_byte.next = self
            .expected
            .val()
            .get_bits::<8>(self.header_position.q.val().index());
        if self.header_position.q.val() == 48 {
            self.expected_byte.next = self.payload_length.val().get_bits::<8>(8);
        }
        if self.header_position.q.val() == 56 {
            self.expected_byte.next = self.payload_length.val().get_bits::<8>(0);
        }
        self.byte_differs.next = self.beats.beat_valid.val()
            & self.at_header.q.val()
            & (self.beats.beat_data.val() != self.expected_byte.val());
        if self.beats.beat_valid.val() & self.beat_first.val() {
            self.echo_request_flag.d.next = true;
            self.port_flag.d.next = true;
            self.length_flag.d.next = true;
            self.no_checksum_flag.d.next = true;
        }
        if self.byte_differs.val() {
            if self.header_position.q.val().get_bits::<2>(4) == 1 {
                self.echo_request_flag.d.next = false;
            }
            if self.header_position.q.val().get_bits::<2>(4) == 2 {
                self.port_flag.d.next = false;
            }
            if self.header_position.q.val().get_bits::<2>(4) == 3 {
                self.length_flag.d.next = false;
            }
            if self.header_position.q.val().get_bits::<2>(4) == 0 {
                self.no_checksum_flag.d.next = false;
            }
        }
        self.sum_check.d.next = self.message_sum.verifies.val();
        self.echo_request.next = self.echo_request_flag.q.val();
        self.sum_ok.next = self.sum_check.q.val();
        self.udp_length_ok.next = self.length_flag.q.val();
        self.udp_no_checksum.next = self.no_checksum_flag.q.val();
        self.to_box_port.next = self.port_flag.q.val();
        self.source_port.next = self.source_port_field.value.val();
        self.icmp_rest_sum.next = self.rest_sum.folded.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{frame_word, send_frame_beats, Bench, TestRng};
    use skinbox_protocol::link::LinkConfig;
    use skinbox_protocol::wire::checksum::{checksum, ipv4_pseudo_header};
    use skinbox_protocol::wire::icmp::{EchoMessage, IcmpEchoRepr};
    use skinbox_protocol::wire::ipv4::Ipv4Repr;
    use skinbox_protocol::wire::udp::{UdpPacket, UdpRepr};

    /// A random ICMP echo or UDP datagram in an IPv4 packet behind an Ethernet header,
    /// with random padding and an FCS; sometimes a transport byte or the UDP length
    /// changed, a UDP checksum left 0, another port.
    fn frame(rng: &mut TestRng, link: &LinkConfig) -> (Vec<u8>, u8, usize) {
        let data: Vec<u8> = (0..rng.next_u64() % 30).map(|_| rng.byte()).collect();
        let source = [192, 0, 2, rng.byte()];
        let udp = rng.chance(0.5);
        let (protocol, message) = if udp {
            let repr = UdpRepr {
                source_port: rng.next_u64() as u16,
                destination_port: if rng.chance(0.8) {
                    link.box_port
                } else {
                    rng.next_u64() as u16
                },
                payload: &data,
            };
            let mut m = vec![0; repr.buffer_len()];
            repr.emit(&mut m, source, link.box_ip);
            if rng.chance(0.2) {
                m[udp::field::CHECKSUM].fill(0);
            }
            if rng.chance(0.2) {
                m[udp::field::LENGTH.end - 1] ^= 1 << (rng.next_u64() % 3);
            }
            (ipv4::PROTOCOL_UDP, m)
        } else {
            let repr = IcmpEchoRepr {
                message: if rng.chance(0.8) {
                    EchoMessage::Request
                } else {
                    EchoMessage::Reply
                },
                identifier: rng.next_u64() as u16,
                sequence: rng.next_u64() as u16,
                data: &data,
            };
            let mut m = vec![0; repr.buffer_len()];
            repr.emit(&mut m);
            (ipv4::PROTOCOL_ICMP, m)
        };
        let mut message = message;
        if rng.chance(0.2) {
            let at = rng.next_u64() as usize % message.len();
            message[at] ^= 1 << (rng.next_u64() % 8);
        }
        let ip = Ipv4Repr {
            source,
            destination: link.box_ip,
            protocol,
            payload_len: message.len(),
            dscp_ecn: 0,
            identification: 1,
            dont_fragment: true,
            ttl: 64,
        };
        let mut f = vec![0u8; IPV4_AT];
        f.resize(IPV4_AT + ip.buffer_len(), 0);
        ip.emit(&mut f[IPV4_AT..]);
        f[UDP_AT..].copy_from_slice(&message);
        f.extend((0..rng.next_u64() % 20).map(|_| rng.byte()));
        f.extend([0xAA; 4]);
        (f, protocol, message.len())
    }

    /// Random ICMP and UDP messages, good and damaged: every check is what the protocol's
    /// wire layer reads from the same bytes, the source port is the UDP header's, and the
    /// ICMP rest's sum is the ones'-complement sum of the message after its checksum.
    #[test]
    fn checks_are_the_wire_layers() {
        let link = LinkConfig::DEFAULT;
        let mut rng = TestRng::new(61);
        let mut bench = Bench::new(TransportReceiver::new(link.box_port), |u| &mut u.clock);
        let (mut good, mut bad) = (0, 0);
        for case in 0..400 {
            let (f, protocol, payload_len) = frame(&mut rng, &link);
            let payload = UDP_AT..UDP_AT + payload_len;
            let u = &mut bench.uut;
            u.carries_udp.next = protocol == ipv4::PROTOCOL_UDP;
            u.payload_length.next = (payload_len as u64).into();
            // the arriving beat's word: the next index's
            let words: Vec<u64> = (0..f.len()).map(|i| frame_word(&f, i)).collect();
            let next = std::cell::Cell::new(0usize);
            send_frame_beats(
                &mut bench,
                &mut rng,
                &f,
                0.2,
                |u| &mut u.beats,
                |u, r| {
                    u.beat_first.next = r == Some(0);
                    u.in_payload.next = r.is_some_and(|i| payload.contains(&i));
                    let i = r.map_or(next.get(), |i| i + 1);
                    next.set(i);
                    u.next_word.next = words.get(i).copied().unwrap_or(0).into();
                },
            );
            let message = &f[payload.clone()];
            let u = &bench.uut;
            let expected_sum_ok = if protocol == ipv4::PROTOCOL_UDP {
                let pseudo = ipv4_pseudo_header(
                    f[IPV4_AT + 12..IPV4_AT + 16].try_into().unwrap(),
                    link.box_ip,
                    protocol,
                    payload_len as u16,
                );
                checksum(&[&pseudo, message]) == 0
            } else {
                checksum(&[message]) == 0
            };
            assert_eq!(u.sum_ok.val(), expected_sum_ok, "case {case}");
            assert_eq!(
                u.echo_request.val(),
                message[..2] == [ICMP_ECHO_REQUEST, 0],
                "case {case}"
            );
            let header = UdpPacket::new_unchecked(message);
            assert_eq!(
                u.udp_length_ok.val(),
                usize::from(header.length()) == payload_len
            );
            assert_eq!(u.udp_no_checksum.val(), header.checksum() == 0);
            assert_eq!(
                u.to_box_port.val(),
                header.destination_port() == link.box_port
            );
            assert_eq!(
                u.source_port.val().to_u64(),
                u64::from(header.source_port())
            );
            assert_eq!(
                u.icmp_rest_sum.val().to_u64(),
                u64::from(!checksum(&[&message[icmp::field::IDENTIFIER.start..]])),
                "case {case}"
            );
            let parsed_ok = if protocol == ipv4::PROTOCOL_UDP {
                UdpRepr::parse(
                    message,
                    f[IPV4_AT + 12..IPV4_AT + 16].try_into().unwrap(),
                    link.box_ip,
                )
                .is_ok()
            } else {
                IcmpEchoRepr::parse(message).is_ok()
            };
            if parsed_ok {
                good += 1;
            } else {
                bad += 1;
            }
        }
        assert!(good > 100 && bad > 60, "{good} good messages, {bad} bad");
    }
}
