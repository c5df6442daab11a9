//! TransportReceiver: the receive half of the ICMP and UDP layers (docs/control.md, steps
//! 11-14): the ICMP echo request and its checksum, the UDP length, checksum (with the
//! pseudo header) and destination port; and the two values a reply needs from them, the
//! UDP source port and the sum of the ICMP message after its checksum.
//!
//! It listens to the frame parser's beats ([`FrameBeats`]; positions from
//! `protocol::wire::{ipv4, icmp, udp}` after the Ethernet header) beside the IPv4 layer,
//! whose `carries_udp`, `in_payload` and `payload_length` say whether and how far the
//! transport message goes. ICMP and UDP share their header's first eight bytes (one
//! capture) and one ones'-complement sum: from the IPv4 protocol byte on it adds UDP's
//! pseudo header (the protocol word, the payload length in the place of the IPv4 checksum,
//! the addresses) when the protocol is UDP, then the message up to the payload's end.
//! Words enter the sum from a register of the arriving beat's word (`next_word`), so the
//! pseudo header's length takes the checksum's place without a multiplexer behind the
//! register. The checks are registered every clock from the captures: they stand two
//! clocks after a frame's last beat was registered, with the IPv4 layer's.
use crate::field_capture::FieldCapture;
use crate::hdl::*;
use crate::ones_complement_sum::OnesComplementSum;
use crate::stream::FrameBeats;
use skinbox_protocol::link::{
    ICMP_AT, ICMP_ECHO_REQUEST, IPV4_AT, IP_PROTOCOL_UDP, PAYLOAD_AT, UDP_AT,
};
use skinbox_protocol::wire::{icmp, ipv4, udp};
use skinbox_protocol::Field;

/// Captured: the transport header's first eight bytes (ICMP or UDP).
const TRANSPORT: Field = UDP_AT..PAYLOAD_AT;
const _: () = assert!(ICMP_AT == UDP_AT && TRANSPORT.end == ICMP_AT + icmp::HEADER_LEN);
/// The ICMP message from its identifier: what the echo reply's checksum sums.
const ICMP_REST_AT: usize = ICMP_AT + icmp::field::IDENTIFIER.start;
const IP_PROTOCOL_AT: usize = IPV4_AT + ipv4::field::PROTOCOL;
const IP_CHECKSUM_AT: usize = IPV4_AT + ipv4::field::CHECKSUM.start;

/// The lowest bit of the UDP header's field `f` in the capture (the last byte is low).
fn udp_bit(f: Field) -> Constant<Bits<6>> {
    constant((8 * (TRANSPORT.end - (UDP_AT + f.end))) as u64)
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
    box_port: Constant<Bits<16>>,
    protocol_udp: Constant<Bits<8>>,
    icmp_echo_request: Constant<Bits<16>>,
    ip_protocol_at: Constant<Bits<11>>,
    ip_checksum_at: Constant<Bits<11>>,
    ip_checksum_low_at: Constant<Bits<11>>,
    transport_at: Constant<Bits<11>>,
    icmp_rest_at: Constant<Bits<11>>,
    icmp_type_code_bit: Constant<Bits<6>>,
    source_port_bit: Constant<Bits<6>>,
    destination_port_bit: Constant<Bits<6>>,
    length_bit: Constant<Bits<6>>,
    checksum_bit: Constant<Bits<6>>,
    header: FieldCapture<64>,
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
    // the registered checks
    echo_request_check: DFF<Bit>,
    sum_check: DFF<Bit>,
    length_check: DFF<Bit>,
    no_checksum_check: DFF<Bit>,
    port_check: DFF<Bit>,
}

impl TransportReceiver {
    /// The layers of a box listening on UDP port `box_port`.
    pub fn new(box_port: u16) -> Self {
        let echo_request = u64::from(u16::from_be_bytes([ICMP_ECHO_REQUEST, 0]));
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
            box_port: constant(u64::from(box_port)),
            protocol_udp: constant(u64::from(IP_PROTOCOL_UDP)),
            icmp_echo_request: constant(echo_request),
            ip_protocol_at: constant(IP_PROTOCOL_AT as u64),
            ip_checksum_at: constant(IP_CHECKSUM_AT as u64),
            ip_checksum_low_at: constant(IP_CHECKSUM_AT as u64 + 1),
            transport_at: constant(TRANSPORT.start as u64),
            icmp_rest_at: constant(ICMP_REST_AT as u64),
            icmp_type_code_bit: udp_bit(icmp::field::TYPE..icmp::field::CODE + 1),
            source_port_bit: udp_bit(udp::field::SOURCE_PORT),
            destination_port_bit: udp_bit(udp::field::DESTINATION_PORT),
            length_bit: udp_bit(udp::field::LENGTH),
            checksum_bit: udp_bit(udp::field::CHECKSUM),
            header: FieldCapture::of(TRANSPORT),
            message_sum: Default::default(),
            rest_sum: Default::default(),
            sum_word: Default::default(),
            at_protocol: Default::default(),
            at_pseudo_header: Default::default(),
            at_from_transport: Default::default(),
            at_from_icmp_rest: Default::default(),
            echo_request_check: Default::default(),
            sum_check: Default::default(),
            length_check: Default::default(),
            no_checksum_check: Default::default(),
            port_check: Default::default(),
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
            echo_request_check,
            sum_check,
            length_check,
            no_checksum_check,
            port_check
        );
        self.header.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.header.beats);
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

        // the checks, registered from the captures
        self.echo_request_check.d.next = self
            .header
            .value
            .val()
            .get_bits::<16>(self.icmp_type_code_bit.val().index())
            == self.icmp_echo_request.val();
        self.sum_check.d.next = self.message_sum.verifies.val();
        self.length_check.d.next = self
            .header
            .value
            .val()
            .get_bits::<16>(self.length_bit.val().index())
            == self.payload_length.val();
        self.no_checksum_check.d.next = self
            .header
            .value
            .val()
            .get_bits::<16>(self.checksum_bit.val().index())
            == 0;
        self.port_check.d.next = self
            .header
            .value
            .val()
            .get_bits::<16>(self.destination_port_bit.val().index())
            == self.box_port.val();
        self.echo_request.next = self.echo_request_check.q.val();
        self.sum_ok.next = self.sum_check.q.val();
        self.udp_length_ok.next = self.length_check.q.val();
        self.udp_no_checksum.next = self.no_checksum_check.q.val();
        self.to_box_port.next = self.port_check.q.val();
        self.source_port.next = self
            .header
            .value
            .val()
            .get_bits::<16>(self.source_port_bit.val().index());
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
