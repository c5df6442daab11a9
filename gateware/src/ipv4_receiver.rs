//! Ipv4Receiver: the receive half of the IPv4 layer (docs/control.md, steps 6-10 and the
//! IPv4 part of 15): version and header length, header checksum, total length, fragments,
//! destination, protocol and the sender's subnet, and the extent of the packet's payload.
//!
//! It listens to the frame parser's beats ([`FrameBeats`], positions from
//! `protocol::wire::ipv4` after the Ethernet header). The total length and the source are
//! captured ([`FieldCapture`]); the destination is compared with the box's address as it
//! passes ([`FieldMatch`]); the version and header length, the fragment fields and the
//! protocol are checked as their bytes pass, each into a flag registered with the byte (a
//! decode of its position); the header's 16-bit words go through a ones'-complement sum.
//! The checks of the sum and the source are registered every clock. All stand two clocks
//! after a frame's last beat was registered (when the parser's rule table reads them) and
//! hold until the next frame reaches the fields.
//!
//! The payload's extent is counted down from the total length: `in_payload` says whether
//! the registered beat (from the first byte after the header) is inside the packet, so the
//! transport and command layers stop at its end (later bytes are Ethernet padding or the
//! FCS), and `fits` whether the packet ended before the frame's FCS.
use crate::field_capture::FieldCapture;
use crate::field_match::FieldMatch;
use crate::hdl::*;
use crate::ones_complement_sum::OnesComplementSum;
use crate::stream::FrameBeats;
use skinbox_protocol::link::{IPV4_AT, IPV4_HEADER_LEN, IP_PROTOCOL_ICMP, IP_PROTOCOL_UDP};
use skinbox_protocol::wire::ipv4;
use skinbox_protocol::Field;

/// The frame bytes of the IPv4 header's field `f`.
const fn in_frame(f: Field) -> Field {
    IPV4_AT + f.start..IPV4_AT + f.end
}

// the more-fragments flag is in the flags and fragment offset's high byte
const _: () = assert!(ipv4::FLAG_MORE_FRAGMENTS >= 0x100);

/// Frame position of the byte after the IPv4 header.
const PAYLOAD_AT: usize = IPV4_AT + IPV4_HEADER_LEN;

/// The receive half of the IPv4 layer; see the module documentation.
#[derive(LogicBlock)]
pub struct Ipv4Receiver {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The frame's beats.
    pub beats: FrameBeats,
    /// The registered beat is a frame's first.
    pub beat_first: Signal<In, Bit>,
    /// The registered beat as a 16-bit word of the frame (even positions are high bytes).
    pub beat_word: Signal<In, Bits<16>>,
    /// Check: the version is not 4 or the header length is below 5 words.
    pub bad_version: Signal<Out, Bit>,
    /// Check: the header has options (its length is above 5 words).
    pub options: Signal<Out, Bit>,
    /// Check: the header checksum is wrong or the total length is below the header's.
    pub bad_header: Signal<Out, Bit>,
    /// Check: more fragments follow, or this is not the first.
    pub fragment: Signal<Out, Bit>,
    /// Check: the destination is the box's address.
    pub to_box: Signal<Out, Bit>,
    /// Check: the source is in the box's host subnet.
    pub from_subnet: Signal<Out, Bit>,
    /// Check: the protocol is ICMP.
    pub icmp: Signal<Out, Bit>,
    /// Check: the protocol is UDP.
    pub udp: Signal<Out, Bit>,
    /// The protocol is UDP, from the clock the byte after it is registered.
    pub carries_udp: Signal<Out, Bit>,
    /// The total length, from the clock its last byte's successor is registered.
    pub total_length: Signal<Out, Bits<16>>,
    /// The total length less the header's, from the clock after `total_length`.
    pub payload_length: Signal<Out, Bits<16>>,
    /// The source address, from the clock after its last byte was registered.
    pub source: Signal<Out, Bits<32>>,
    /// The registered beat, from the first byte after the header, is inside the packet.
    pub in_payload: Signal<Out, Bit>,
    /// With a frame's last registered beat: its first FCS byte (three beats before) was
    /// outside the packet, so the packet fits the frame.
    pub fits: Signal<Out, Bit>,
    host_subnet: Constant<Bits<32>>,
    host_mask: Constant<Bits<32>>,
    protocol_icmp: Constant<Bits<8>>,
    protocol_udp: Constant<Bits<8>>,
    more_fragments_bit: Constant<Bits<3>>,
    header_len: Constant<Bits<16>>,
    header_at: Constant<Bits<11>>,
    fragment_at: Constant<Bits<11>>,
    fragment_low_at: Constant<Bits<11>>,
    protocol_at: Constant<Bits<11>>,
    total_len_end: Constant<Bits<11>>,
    header_last: Constant<Bits<11>>,
    payload_at: Constant<Bits<11>>,
    total_len: FieldCapture<16>,
    source_address: FieldCapture<32>,
    destination: FieldMatch,
    header_sum: OnesComplementSum,
    // where the registered beat is: in the header, its first byte (version and header
    // length), the flags and fragment offset's bytes, the protocol, the byte after the
    // total length, the header's last byte
    at_header: DFF<Bit>,
    at_version: DFF<Bit>,
    at_fragment: DFF<Bit>,
    at_fragment_low: DFF<Bit>,
    at_protocol: DFF<Bit>,
    at_total_len_end: DFF<Bit>,
    at_header_last: DFF<Bit>,
    // the payload's bytes after the registered one, whether it is in the payload, and
    // that flag for the three beats before
    payload_left: DFF<Bits<16>>,
    in_packet: DFF<Bit>,
    in_packet_history: DFF<Bits<3>>,
    payload_len: DFF<Bits<16>>,
    // the checks of the bytes as they pass
    bad_version_flag: DFF<Bit>,
    options_flag: DFF<Bit>,
    fragment_flag: DFF<Bit>,
    icmp_flag: DFF<Bit>,
    udp_flag: DFF<Bit>,
    // the registered checks
    bad_header_check: DFF<Bit>,
    subnet_check: DFF<Bit>,
}

impl Ipv4Receiver {
    /// The layer of a box at IPv4 address `box_ip`, taking commands from `host_subnet` /
    /// `prefix_len`.
    pub fn new(box_ip: [u8; 4], host_subnet: [u8; 4], prefix_len: u8) -> Self {
        let prefix = u32::from(prefix_len.min(32));
        let mask = u32::MAX.checked_shl(32 - prefix).unwrap_or(0);
        let subnet = u32::from_be_bytes(host_subnet) & mask;
        let fragment_at = in_frame(ipv4::field::FLAGS_FRAGMENT_OFFSET).start;
        Self {
            clock: Default::default(),
            beats: Default::default(),
            beat_first: Default::default(),
            beat_word: Default::default(),
            bad_version: Default::default(),
            options: Default::default(),
            bad_header: Default::default(),
            fragment: Default::default(),
            to_box: Default::default(),
            from_subnet: Default::default(),
            icmp: Default::default(),
            udp: Default::default(),
            carries_udp: Default::default(),
            total_length: Default::default(),
            payload_length: Default::default(),
            source: Default::default(),
            in_payload: Default::default(),
            fits: Default::default(),
            host_subnet: constant(u64::from(subnet)),
            host_mask: constant(u64::from(mask)),
            protocol_icmp: constant(u64::from(IP_PROTOCOL_ICMP)),
            protocol_udp: constant(u64::from(IP_PROTOCOL_UDP)),
            more_fragments_bit: constant(u64::from(ipv4::FLAG_MORE_FRAGMENTS.trailing_zeros() - 8)),
            header_len: constant(IPV4_HEADER_LEN as u64),
            header_at: constant(IPV4_AT as u64),
            fragment_at: constant(fragment_at as u64),
            fragment_low_at: constant(fragment_at as u64 + 1),
            protocol_at: constant((IPV4_AT + ipv4::field::PROTOCOL) as u64),
            total_len_end: constant(in_frame(ipv4::field::TOTAL_LEN).end as u64),
            header_last: constant(PAYLOAD_AT as u64 - 1),
            payload_at: constant(PAYLOAD_AT as u64),
            total_len: FieldCapture::of(in_frame(ipv4::field::TOTAL_LEN)),
            source_address: FieldCapture::of(in_frame(ipv4::field::SOURCE)),
            destination: FieldMatch::of(in_frame(ipv4::field::DESTINATION), &box_ip),
            header_sum: Default::default(),
            at_header: Default::default(),
            at_version: Default::default(),
            at_fragment: Default::default(),
            at_fragment_low: Default::default(),
            at_protocol: Default::default(),
            at_total_len_end: Default::default(),
            at_header_last: Default::default(),
            payload_left: Default::default(),
            in_packet: Default::default(),
            in_packet_history: Default::default(),
            payload_len: Default::default(),
            bad_version_flag: Default::default(),
            options_flag: Default::default(),
            fragment_flag: Default::default(),
            icmp_flag: Default::default(),
            udp_flag: Default::default(),
            bad_header_check: Default::default(),
            subnet_check: Default::default(),
        }
    }
}

impl Logic for Ipv4Receiver {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            at_header,
            at_version,
            at_fragment,
            at_fragment_low,
            at_protocol,
            at_total_len_end,
            at_header_last,
            payload_left,
            in_packet,
            in_packet_history,
            payload_len,
            bad_version_flag,
            options_flag,
            fragment_flag,
            icmp_flag,
            udp_flag,
            bad_header_check,
            subnet_check
        );
        self.total_len.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.total_len.beats);
        self.source_address.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.source_address.beats);
        self.destination.clock.next = self.clock.val();
        FrameBeats::link(&mut self.beats, &mut self.destination.beats);

        // positions of the next registered beat: equality decodes only
        if self.beats.next_valid.val() {
            self.at_header.d.next = (self.beats.next_index.val() == self.header_at.val())
                | (self.at_header.q.val()
                    & (self.beats.next_index.val() != self.payload_at.val())
                    & self.beats.in_frame.val());
            self.at_version.d.next = self.beats.next_index.val() == self.header_at.val();
            self.at_fragment.d.next = self.beats.next_index.val() == self.fragment_at.val();
            self.at_fragment_low.d.next = self.beats.next_index.val() == self.fragment_low_at.val();
            self.at_protocol.d.next = self.beats.next_index.val() == self.protocol_at.val();
            self.at_total_len_end.d.next = self.beats.next_index.val() == self.total_len_end.val();
            self.at_header_last.d.next = self.beats.next_index.val() == self.header_last.val();
        }
        // the header's words, restarted at a frame's first beat
        self.header_sum.clock.next = self.clock.val();
        self.header_sum.word.next = self.beat_word.val();
        self.header_sum.add.next = self.beats.beat_valid.val() & self.at_header.q.val();
        self.header_sum.restart.next = self.beats.beat_valid.val() & self.beat_first.val();
        self.header_sum.start.next = 0.into();

        // the payload's extent: whether the registered beat (from the byte after the
        // header) is inside it
        if self.beats.beat_valid.val() {
            self.in_packet_history.d.next = (self.in_packet_history.q.val() << 1)
                | bit_cast::<3, 1>(self.in_packet.q.val().into());
            if self.in_packet.q.val() {
                self.payload_left.d.next = self.payload_left.q.val() - 1;
                self.in_packet.d.next = self.payload_left.q.val() != 1;
            }
            if self.at_total_len_end.q.val() {
                self.payload_len.d.next = self.total_len.value.val() - self.header_len.val();
            }
            if self.at_header_last.q.val() {
                self.payload_left.d.next = self.payload_len.q.val();
                self.in_packet.d.next = self.payload_len.q.val() != 0;
            }
            if self.beat_first.val() {
                self.in_packet.d.next = false;
            }
        }

        // the checks of the bytes as they pass: version and header length, the flags and
        // fragment offset (more fragments, or an offset), the protocol
        if self.beats.beat_valid.val() & self.at_version.q.val() {
            self.bad_version_flag.d.next = (self.beats.beat_data.val().get_bits::<4>(4) != 4)
                | (self.beats.beat_data.val().get_bits::<4>(0) < 5);
            self.options_flag.d.next = self.beats.beat_data.val().get_bits::<4>(0) > 5;
        }
        if self.beats.beat_valid.val() & self.at_fragment.q.val() {
            self.fragment_flag.d.next = self
                .beats
                .beat_data
                .val()
                .get_bit(self.more_fragments_bit.val().index())
                | (self.beats.beat_data.val().get_bits::<5>(0) != 0);
        }
        if self.beats.beat_valid.val()
            & self.at_fragment_low.q.val()
            & (self.beats.beat_data.val() != 0)
        {
            self.fragment_flag.d.next = true;
        }
        if self.beats.beat_valid.val() & self.at_protocol.q.val() {
            self.icmp_flag.d.next = self.beats.beat_data.val() == self.protocol_icmp.val();
            self.udp_flag.d.next = self.beats.beat_data.val() == self.protocol_udp.val();
        }
        // the checks, registered from the sum and the captures
        self.bad_header_check.d.next =
            !self.header_sum.verifies.val() | (self.total_len.value.val() < self.header_len.val());
        self.subnet_check.d.next =
            (self.source_address.value.val() & self.host_mask.val()) == self.host_subnet.val();

        self.bad_version.next = self.bad_version_flag.q.val();
        self.options.next = self.options_flag.q.val();
        self.bad_header.next = self.bad_header_check.q.val();
        self.fragment.next = self.fragment_flag.q.val();
        self.to_box.next = self.destination.equals.val();
        self.from_subnet.next = self.subnet_check.q.val();
        self.icmp.next = self.icmp_flag.q.val();
        self.udp.next = self.udp_flag.q.val();
        self.carries_udp.next = self.udp_flag.q.val();
        self.total_length.next = self.total_len.value.val();
        self.payload_length.next = self.payload_len.q.val();
        self.source.next = self.source_address.value.val();
        self.in_payload.next = self.in_packet.q.val();
        self.fits.next = !self.in_packet_history.q.val().get_bit(2);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{frame_word, send_frame_beats, Bench, TestRng};
    use skinbox_protocol::link::LinkConfig;
    use skinbox_protocol::wire::ipv4::{Ipv4Packet, Ipv4Repr};

    fn repr(source: [u8; 4], destination: [u8; 4], protocol: u8, payload_len: usize) -> Ipv4Repr {
        Ipv4Repr {
            source,
            destination,
            protocol,
            payload_len,
            dscp_ecn: 0,
            identification: 0x1234,
            dont_fragment: true,
            ttl: 64,
        }
    }

    /// Random IPv4 headers behind an Ethernet header (good ones, and ones with a field or
    /// the checksum changed, options, fragments, other addresses and protocols, short
    /// total lengths), payloads of random length and random padding: every check is what
    /// the wire layer reads from the same bytes.
    #[test]
    fn checks_are_the_wire_layers() {
        let link = LinkConfig::DEFAULT;
        let mut rng = TestRng::new(53);
        let mut bench = Bench::new(
            Ipv4Receiver::new(link.box_ip, link.host_subnet, link.host_subnet_prefix_len),
            |u| &mut u.clock,
        );
        let (mut good, mut bad) = (0, 0);
        let (mut fitting, mut overlong) = (0, 0);
        for case in 0..400 {
            let payload_len = rng.next_u64() as usize % 40;
            let mut destination = link.box_ip;
            if rng.chance(0.2) {
                destination[3] ^= 1 << (rng.next_u64() % 8);
            }
            let mut source = link.host_subnet;
            source[3] = rng.byte();
            if rng.chance(0.2) {
                source[rng.next_u64() as usize % 4] ^= 0x80;
            }
            let protocol = match rng.next_u64() % 4 {
                0 => ipv4::PROTOCOL_ICMP,
                1 => 6,
                _ => ipv4::PROTOCOL_UDP,
            };
            let repr = repr(source, destination, protocol, payload_len);
            let mut frame = vec![0u8; IPV4_AT + repr.buffer_len() + rng.next_u64() as usize % 24];
            repr.emit(&mut frame[IPV4_AT..]);
            let header = IPV4_AT..IPV4_AT + IPV4_HEADER_LEN;
            if rng.chance(0.5) {
                // a header byte changed, checksum left (or refilled) as it is
                let at = header.start + rng.next_u64() as usize % IPV4_HEADER_LEN;
                frame[at] ^= 1 << (rng.next_u64() % 8);
                if rng.chance(0.5) {
                    Ipv4Packet::new_unchecked(&mut frame[IPV4_AT..]).fill_checksum();
                }
            }
            // the FCS: four bytes after the padding
            frame.extend([0xAA; 4]);
            send_frame_beats(
                &mut bench,
                &mut rng,
                &frame,
                0.2,
                |u| &mut u.beats,
                |u, r| {
                    u.beat_first.next = r == Some(0);
                    u.beat_word.next = r.map_or(0, |i| frame_word(&frame, i)).into();
                },
            );
            let packet = Ipv4Packet::new_unchecked(&frame[IPV4_AT..]);
            let ihl = packet.ihl();
            let total = usize::from(packet.total_len());
            let u = &bench.uut;
            assert_eq!(
                u.bad_version.val(),
                packet.version() != 4 || ihl < 5,
                "case {case}"
            );
            assert_eq!(u.options.val(), ihl > 5, "case {case}");
            assert_eq!(
                u.bad_header.val(),
                !packet.verify_checksum() || total < IPV4_HEADER_LEN,
                "case {case}"
            );
            assert_eq!(
                u.fragment.val(),
                packet.more_fragments() || packet.fragment_offset() != 0,
                "case {case}"
            );
            assert_eq!(u.to_box.val(), packet.destination() == link.box_ip);
            let mask = u32::MAX << (32 - u32::from(link.host_subnet_prefix_len));
            assert_eq!(
                u.from_subnet.val(),
                u32::from_be_bytes(packet.source()) & mask
                    == u32::from_be_bytes(link.host_subnet) & mask,
                "case {case}"
            );
            assert_eq!(u.icmp.val(), packet.protocol() == ipv4::PROTOCOL_ICMP);
            assert_eq!(u.udp.val(), packet.protocol() == ipv4::PROTOCOL_UDP);
            assert_eq!(u.total_length.val().to_u64(), total as u64);
            assert_eq!(
                u.source.val().to_u64(),
                u64::from(u32::from_be_bytes(packet.source()))
            );
            // the packet fits the frame when it ends before the FCS (a total length below
            // the header's leaves no payload to count down)
            if total >= IPV4_HEADER_LEN {
                let fits = IPV4_AT + total <= frame.len() - 4;
                assert_eq!(u.fits.val(), fits, "case {case}: total length {total}");
                if fits {
                    fitting += 1;
                } else {
                    overlong += 1;
                }
            }
            if Ipv4Repr::parse(&frame[IPV4_AT..frame.len() - 4]).is_ok() {
                good += 1;
            } else {
                bad += 1;
            }
        }
        assert!(good > 100 && bad > 100, "{good} good headers, {bad} bad");
        assert!(
            fitting > 100 && overlong > 5,
            "{fitting} packets fit their frames, {overlong} longer"
        );
    }

    /// `in_payload` marks exactly the payload's bytes (from the byte after the header up
    /// to the total length), whatever the frame carries after them.
    #[test]
    fn the_payload_is_the_total_lengths() {
        let mut rng = TestRng::new(54);
        let link = LinkConfig::DEFAULT;
        let mut bench = Bench::new(
            Ipv4Receiver::new(link.box_ip, link.host_subnet, link.host_subnet_prefix_len),
            |u| &mut u.clock,
        );
        for case in 0..100 {
            let payload_len = rng.next_u64() as usize % 30;
            let repr = repr(
                link.host_subnet,
                link.box_ip,
                ipv4::PROTOCOL_UDP,
                payload_len,
            );
            let mut frame = vec![0u8; IPV4_AT + repr.buffer_len() + rng.next_u64() as usize % 20];
            repr.emit(&mut frame[IPV4_AT..]);
            let seen = std::cell::RefCell::new(vec![]);
            send_frame_beats(
                &mut bench,
                &mut rng,
                &frame,
                0.2,
                |u| &mut u.beats,
                |u, r| {
                    u.beat_first.next = r == Some(0);
                    u.beat_word.next = r.map_or(0, |i| frame_word(&frame, i)).into();
                    if let Some(i) = r {
                        seen.borrow_mut().push((i, u.in_payload.val()));
                    }
                },
            );
            let end = PAYLOAD_AT + payload_len;
            for (i, in_payload) in seen.into_inner() {
                if i >= PAYLOAD_AT {
                    assert_eq!(
                        in_payload,
                        i < end,
                        "case {case}: byte {i}, payload to {end}"
                    );
                }
            }
        }
    }
}
