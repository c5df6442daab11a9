//! FrameTransmitter: sends one box datagram as a complete Ethernet frame on GMII.
//!
//! It takes a datagram's descriptor (kind, flags, entry count, base tick, body length and
//! the ones'-complement sum of the body's 16-bit words; [`DatagramSink`]) when it is idle
//! and emits, one byte per clock: preamble and SFD, Ethernet II header, IPv4 header with
//! its checksum, UDP header with its checksum, the 24-byte datagram header with the next
//! sequence number, the body from the datagram's body stream, the FCS, and then at least
//! 12 idle clocks. (The headers alone exceed the 60-byte minimum frame: no padding is
//! needed.) The descriptor's source holds it from the take until its body's last beat (the
//! [`DatagramArbiter`](crate::datagram_arbiter::DatagramArbiter) keeps the granted
//! source's descriptor on `datagrams` until then): the kind and the header fields are read
//! there as the header goes out, not copied; the body length, the body sum and the
//! destination are taken at the take.
//!
//! A descriptor of kind [`RAW_FRAME_KIND`](crate::stream::RAW_FRAME_KIND) is a raw frame: its body is the frame itself
//! from the destination MAC on, sent right after the SFD (its source pads it to the 60-byte
//! minimum; `body_len` 60..=1514), then the FCS and the gap; its other descriptor fields are
//! ignored and the datagram sequence number does not advance.
//!
//! A datagram goes to the destination (MAC, IPv4 address, UDP port) on the
//! `destination_*` inputs at the clock its descriptor is taken: the 12 bytes are loaded
//! into a shift register then and sent from it, the IPv4 checksum adds the address's words
//! to the total length, and the UDP checksum adds the address's and the port's words among
//! its last terms.
//!
//! The checksums are finished long before they are sent: the UDP sum
//! ([`DatagramChecksum`]) starts from the constant words (addresses, ports, magic, box id)
//! and adds the 16 bytes of the header fields (flags, sequence, base tick, entry count, a
//! zero) one per clock from index 2, each at its place in its word (a byte multiplexer
//! stepped by a counter, no word multiplexer), then from index 18 the kind, the UDP length
//! twice, the body sum and the destination's sum; it is final at index 27. The body is
//! taken one beat per clock from byte 74 on (`ready` is a register): a source must have
//! its beats ready by then (a [`crate::body_reader::BodyReader`] has them three clocks
//! after its start). A body beat missing when due is sent as it is with `gmii_tx_er` set,
//! so the PHY corrupts the frame and the host counts it lost instead of reading garbage.
//! The header's steady sources (lengths, checksums, kind) and the destination byte are ORed
//! a clock ahead into a register, so only the template and field bytes pass the OR in the
//! byte's own clock. Output: the selected byte goes into a register, the CRC is computed
//! from that register, and the output register takes the byte or, at the end, the FCS:
//! `gmii_txd`/`gmii_tx_en` follow the byte counter by two clocks, and no path runs from
//! byte selection through the CRC. The frame geometry (lengths, IPv4 checksum) is computed from the body length held
//! at the start, a clock later (no adder after the descriptor).

use crate::datagram_checksum::DatagramChecksum;
use crate::fcs_output::{FcsOutput, OUTPUT_LATENCY};
use crate::hdl::*;
use crate::header_sums::HeaderSums;
use crate::stream::DatagramSink;
use crate::transmit_fields::TransmitFields;
use crate::transmit_geometry::TransmitGeometry;
pub use crate::transmit_layout::BODY_START;
use crate::transmit_layout::*;
use crate::transmit_sequence::TransmitSequence;
use crate::transmit_source::TransmitSource;
use skinbox_protocol::datagram::field;
use skinbox_protocol::link::*;

/// Clocks from the clock a descriptor is taken (`valid & ready` at its edge) to the clock
/// the frame's first preamble byte is on `gmii_txd`: the transmitter registers `sending`,
/// then the output stage ([`FcsOutput`]) registers the byte and the output (with the FCS).
pub const TAKE_TO_FIRST_BYTE: u64 = 1 + OUTPUT_LATENCY;

/// Clocks from the clock a raw frame's descriptor is taken to the clock its first body
/// beat is taken (`ready`): the body follows the preamble and the SFD, then one beat per
/// clock. (A datagram's first body beat is taken [`BODY_START`] - [`PREAMBLE_LEN`] clocks
/// later.)
pub const TAKE_TO_RAW_BODY: u64 = TAKE_TO_FIRST_BYTE - 2 + PREAMBLE_LEN as u64;

/// Sum of the big-endian 16-bit words of `bytes` (odd length padded with 0), not folded.
pub fn word_sum(bytes: &[u8]) -> u64 {
    bytes
        .chunks(2)
        .map(|w| u64::from(w[0]) << 8 | u64::from(*w.get(1).unwrap_or(&0)))
        .sum()
}

/// Sends datagrams as Ethernet frames on GMII.
#[derive(LogicBlock)]
pub struct FrameTransmitter {
    /// The box clock, also the GMII transmit clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the sequence number restarts at 0.
    pub reset: Signal<In, Bit>,
    /// The datagrams to send; `ready` while idle (the inter-frame gap is over).
    pub datagrams: DatagramSink,
    /// GMII transmit data.
    pub gmii_txd: Signal<Out, Bits<8>>,
    /// GMII transmit enable.
    pub gmii_tx_en: Signal<Out, Bit>,
    /// GMII transmit error: a body beat was missing when due.
    pub gmii_tx_er: Signal<Out, Bit>,
    /// Destination MAC of the datagram frames, read at the clock a descriptor is taken.
    pub destination_mac: Signal<In, Bits<48>>,
    /// Destination IPv4 address of the datagram frames, read like `destination_mac`.
    pub destination_ip: Signal<In, Bits<32>>,
    /// Destination UDP port of the datagram frames, read like `destination_mac`.
    pub destination_port: Signal<In, Bits<16>>,
    // the phases (idle, sending, gap) and the byte index
    frame_steps: TransmitSequence,
    // the held descriptor (body length, raw) and the frame's lengths and positions
    geometry: TransmitGeometry,
    // the header fields (flags, sequence, base tick, entry count) and the sequence number
    header_fields: TransmitFields,
    // the byte at each index: template, header fields, destination or body
    source: TransmitSource,
    // the IPv4 header checksum and the destination's sum
    header_sums: HeaderSums,
    // the UDP checksum (final long before byte 48: at byte 27)
    udp_sum: DatagramChecksum,
    // the output stage with the FCS
    fcs_stage: FcsOutput,
    // the SFD's position minus one (the CRC starts after it), and the first byte in the CRC
    sfd_ahead: Constant<Bits<11>>,
    crc_from: Constant<Bits<11>>,
    // the byte at `index` is a body byte: the body stream's `ready`
    in_body: DFF<Bit>,
    // registered index tests, true at index 7 (the CRC starts)
    crc_starts: DFF<Bit>,
    // registered index tests, like `crc_starts`: the checksum's term is a field byte
    // (2..18), its steady terms start (index 18)
    term_from_fields: DFF<Bit>,
    checksum_tail_starts: DFF<Bit>,
    // the destination's sum is final (from index 2; kept from index 5: index 4 or more a
    // clock before, the IPv4 checksum final at index 5 needs no hold): keep it
    // while the destination shifts
    sums_kept: DFF<Bit>,
    // this clock's index, and a frame goes out
    index: Signal<Local, Bits<11>>,
    sending: Signal<Local, Bit>,
}

impl FrameTransmitter {
    /// A transmitter for a box with these addresses, id and port count.
    pub fn new(link: &LinkConfig, box_id: u16, port_count: u8) -> Self {
        let t = template(link, box_id, port_count);
        // Constant words of the UDP checksum: pseudo header (addresses, protocol), UDP
        // ports, and the constant words of the datagram header (magic, version, box id,
        // port count). Variable words are added while the preamble and the Ethernet header
        // go out.
        // (the destination's words are added at run time)
        let pseudo = word_sum(&link.box_ip) + u64::from(IP_PROTOCOL_UDP);
        let udp_constant = pseudo
            + word_sum(&t[UDP_AT_ON_WIRE..UDP_LEN_AT])
            + word_sum(&t[PAYLOAD_AT_ON_WIRE..PAYLOAD_AT_ON_WIRE + field::SEQUENCE.start]);
        let ip_constant = word_sum(&t[IPV4_AT_ON_WIRE..UDP_AT_ON_WIRE]);
        Self {
            clock: Default::default(),
            reset: Default::default(),
            datagrams: Default::default(),
            gmii_txd: Default::default(),
            gmii_tx_en: Default::default(),
            gmii_tx_er: Default::default(),
            destination_mac: Default::default(),
            destination_ip: Default::default(),
            destination_port: Default::default(),
            frame_steps: TransmitSequence::new((INTER_FRAME_GAP - 1) as u64),
            geometry: TransmitGeometry::default(),
            header_fields: Default::default(),
            source: TransmitSource::new(&t),
            header_sums: HeaderSums::new(ip_constant),
            udp_sum: DatagramChecksum::new(udp_constant),
            fcs_stage: Default::default(),
            sfd_ahead: position(PREAMBLE_LEN - 2),
            crc_from: position(PREAMBLE_LEN),
            in_body: Default::default(),
            crc_starts: Default::default(),
            term_from_fields: Default::default(),
            checksum_tail_starts: Default::default(),
            sums_kept: Default::default(),
            index: Default::default(),
            sending: Default::default(),
        }
    }
}

// The kernel cannot name Rust constants: the frame positions are `Constant` signals made
// in `new()` from the format constants. Two tests are written from the index's bits (the
// body from byte 74, the field bytes' checksum terms over the 16 bytes of `fields_high`
// and `fields_low`); `frame_positions_match_the_formats` holds them to the formats. A frame
// is never below the 60-byte minimum (the headers alone end at 74 = 8 + 66), so it never
// needs padding.
impl Logic for FrameTransmitter {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            in_body,
            crc_starts,
            term_from_fields,
            checksum_tail_starts,
            sums_kept
        );
        // The phases: a descriptor is taken while `ready` (idle, the gap over); the index
        // counts the frame's bytes up to its last one, then the gap follows.
        self.frame_steps.clock.next = self.clock.val();
        self.frame_steps.reset.next = self.reset.val();
        self.frame_steps.valid.next = self.datagrams.valid.val();
        self.frame_steps.end_minus_one.next = self.geometry.end_minus_one.val();
        self.datagrams.ready.next = self.frame_steps.ready.val();
        self.sending.next = self.frame_steps.sending.val();
        self.index.next = self.frame_steps.index.val();

        // The descriptor is taken in every clock without a frame going out, so taking it
        // only has to set `sending`; the frame geometry follows the held body length a
        // clock later (valid from index 1 on).
        self.geometry.clock.next = self.clock.val();
        self.geometry.load.next = !self.sending.val();
        self.geometry.descriptor_kind.next = self.datagrams.kind.val();
        self.geometry.body_len.next = self.datagrams.body_len.val();
        self.header_fields.clock.next = self.clock.val();
        self.header_fields.reset.next = self.reset.val();
        self.header_fields.flags.next = self.datagrams.flags.val();
        self.header_fields.base_tick.next = self.datagrams.base_tick.val();
        self.header_fields.entry_count.next = self.datagrams.entry_count.val();
        self.header_fields.frame_goes_on.next = self.frame_steps.frame_goes_on.val();
        self.header_fields.index.next = self.index.val();
        // the frame's last clock: the sequence steps (a raw frame is no datagram)
        self.header_fields.advance.next =
            self.frame_steps.frame_ends.val() & !self.geometry.raw.val();

        // The IPv4 checksum from the total length and the destination (needed from byte 32
        // on), the UDP checksum's variable words one per clock from byte 0: the kind, the
        // UDP length term, the 16 field bytes, then the destination's sum.
        self.header_sums.clock.next = self.clock.val();
        self.header_sums.restart.next = !self.sending.val();
        self.header_sums.destination_ip.next = self.source.destination_ip_held.val();
        self.header_sums.destination_port.next = self.source.destination_port_held.val();
        self.header_sums.total_len.next = self.geometry.total_len.val();
        self.header_sums.hold.next = self.sums_kept.q.val();
        self.udp_sum.clock.next = self.clock.val();
        self.udp_sum.restart.next = !self.sending.val();
        self.udp_sum.term_from_fields.next = self.term_from_fields.q.val();
        self.udp_sum.high_byte.next = self.index.val().get_bit(0);
        self.udp_sum.tail_start.next = self.checksum_tail_starts.q.val();
        self.udp_sum.kind.next = self.datagrams.kind.val();
        self.udp_sum.udp_len.next = self.geometry.udp_len.val();
        self.udp_sum.body_sum.next = self.datagrams.body_sum.val();
        self.udp_sum.destination_sum.next = self.header_sums.destination_sum.val();
        self.udp_sum.field_byte.next = self.header_fields.field_byte.val();

        // The byte at `index`: template, header fields, destination or body.
        self.source.clock.next = self.clock.val();
        self.source.reset.next = self.reset.val();
        self.source.sending.next = self.sending.val();
        self.source.frame_goes_on.next = self.frame_steps.frame_goes_on.val();
        self.source.raw.next = self.geometry.raw.val();
        self.source.index.next = self.index.val();
        self.source.total_len.next = self.geometry.total_len.val();
        self.source.ip_checksum.next = self.header_sums.ip_checksum.val();
        self.source.udp_len.next = self.geometry.udp_len.val();
        self.source.udp_checksum.next = self.udp_sum.udp_checksum.val();
        self.source.kind.next = self.datagrams.kind.val();
        self.source.field_byte.next = self.header_fields.field_byte.val();
        self.source.body_data.next = self.datagrams.body.data.val();
        self.source.destination_mac.next = self.destination_mac.val();
        self.source.destination_ip.next = self.destination_ip.val();
        self.source.destination_port.next = self.destination_port.val();
        // The body beat is taken at its index: `in_body` is set a clock ahead, from the
        // flag of the next index's byte and the body's end.
        self.datagrams.body.ready.next = self.in_body.q.val();
        self.in_body.d.next = self.frame_steps.frame_goes_on.val()
            & self.source.next_is_body.val()
            & (self.index.val() < self.geometry.body_end_less_one.val());

        // Output stage: the byte through a register, the CRC from that register, the FCS
        // at the output (`FcsOutput`).
        self.fcs_stage.clock.next = self.clock.val();
        self.fcs_stage.reset.next = self.reset.val();
        self.fcs_stage.valid.next = self.sending.val();
        self.fcs_stage.data.next = self.source.frame_byte.val();
        self.fcs_stage.covered.next = (self.index.val() >= self.crc_from.val())
            & (self.index.val() < self.geometry.body_end.val());
        self.fcs_stage.fcs.next = self.index.val() >= self.geometry.body_end.val();
        self.fcs_stage.beat_missing.next = self.in_body.q.val() & !self.datagrams.body.valid.val();
        // index 7: the SFD is in the output stage now: the CRC starts with the next byte
        // (`crc_starts` is set only in a clock after index 6 of a frame, which goes on: no
        // gate from the phase into the CRC)
        self.fcs_stage.crc_start.next = self.crc_starts.q.val();

        // the index tests of the next clock, from this clock's index (it counts up by one
        // while sending)
        self.crc_starts.d.next = self.sending.val() & (self.index.val() == self.sfd_ahead.val());
        self.term_from_fields.d.next =
            self.sending.val() & (self.index.val() >= 1) & (self.index.val() < 17);
        self.checksum_tail_starts.d.next = self.sending.val() & (self.index.val() == 17);
        self.sums_kept.d.next = self.sending.val() & (self.index.val().get_bits::<9>(2) != 0);
        if self.reset.val() {
            self.checksum_tail_starts.d.next = false;
            self.sums_kept.d.next = false;
            self.crc_starts.d.next = false;
            self.term_from_fields.d.next = false;
            self.in_body.d.next = false;
        }
        self.gmii_txd.next = self.fcs_stage.gmii_txd.val();
        self.gmii_tx_en.next = self.fcs_stage.gmii_tx_en.val();
        self.gmii_tx_er.next = self.fcs_stage.gmii_tx_er.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream::RAW_FRAME_KIND;
    use crate::testbench::{body_sum_of, check_frame, Bench, GmiiCapture, TestRng};
    use skinbox_protocol::datagram::{DatagramBody, HEADER_LEN};
    use skinbox_protocol::{DataRepr, DatagramRepr, PortCounters, RecordRepr, StatusRepr};
    use std::collections::VecDeque;

    #[test]
    fn frame_positions_match_the_formats() {
        // the positions of RFC 791 / RFC 768 fields behind an 8-byte preamble and a
        // 14-byte Ethernet header, and the datagram header's table (protocol::datagram)
        assert_eq!(
            (IP_TOTAL_LEN_AT, IP_CHECKSUM_AT, UDP_AT_ON_WIRE),
            (24, 32, 42)
        );
        assert_eq!(
            (UDP_LEN_AT, UDP_CHECKSUM_AT, PAYLOAD_AT_ON_WIRE),
            (46, 48, 50)
        );
        assert_eq!((KIND_AT, FIELDS_AT, FIELDS_AT + FIELDS_LEN), (53, 57, 72));
        // the kernel's tests from the index's bits: the body from 74 (`body_follows` tests
        // 72, two ahead), 16 field bytes for the checksum (the 15 fields and the first
        // reserved byte: `fields_high` and `fields_low`)
        assert_eq!(BODY_START, 74);
        assert_eq!(FIELDS_LEN + 1, 16);
        let t = template(&LinkConfig::DEFAULT, 7, 8);
        // RFC 791 with the box's choices: IHL 5, identification 0, don't fragment, TTL 64, UDP
        let ip_fixed = [0x45, 0, 0, 0, 0, 0, 0x40, 0, 64, 17, 0, 0];
        assert_eq!(t[IPV4_AT_ON_WIRE..IPV4_AT_ON_WIRE + 12], ip_fixed);
        // the template byte is ORed in all through the header: 0 at every variable byte
        let variable = [IP_TOTAL_LEN_AT, IP_CHECKSUM_AT, UDP_LEN_AT, UDP_CHECKSUM_AT]
            .iter()
            .flat_map(|&at| [at, at + 1])
            .chain([KIND_AT])
            .chain(FIELDS_AT..FIELDS_AT + FIELDS_LEN);
        for at in variable {
            assert_eq!(t[at], 0, "template byte {at}");
        }
        assert_eq!(
            &t[FIELDS_AT + FIELDS_LEN..BODY_START],
            &[0, 0],
            "reserved header bytes"
        );
    }

    /// The descriptor's fields when the source holds none (no descriptor offered, the last
    /// body's last beat taken): noise that changes every clock.
    fn descriptor_noise(u: &mut FrameTransmitter, clock: u64) {
        let noise = clock.wrapping_mul(0x9E37_79B9_7F4A_7C15);
        u.datagrams.kind.next = (noise >> 56).into();
        u.datagrams.flags.next = (noise & 0xFF).into();
        u.datagrams.entry_count.next = (noise >> 8 & 0xFFFF).into();
        u.datagrams.base_tick.next = noise.rotate_left(17).into();
    }

    fn body_sum(body: &[u8]) -> u64 {
        body_sum_of(body)
    }

    /// Sends the datagrams (their sequence numbers are ignored: the transmitter numbers
    /// them) and returns the captured frames.
    fn send(datagrams: &[DatagramRepr]) -> GmiiCapture {
        let (capture, errors) = send_with_hole(datagrams, None);
        assert!(errors.is_empty(), "no body beat missing: {errors:?}");
        capture
    }

    /// Offers each datagram's descriptor and then its body, every beat ready before it is
    /// due, except that body byte `hole.1` of datagram `hole.0` is not offered the first
    /// clock it is due (the rest of that body is dropped when its frame ends). Returns the
    /// frames (the one with the hole left out) and the clocks `gmii_tx_er` was set.
    fn send_with_hole(
        datagrams: &[DatagramRepr],
        hole: Option<(usize, usize)>,
    ) -> (GmiiCapture, Vec<u64>) {
        let mut bench = Bench::new(
            FrameTransmitter::new(&LinkConfig::DEFAULT, 0x0102, 8),
            |b| &mut b.clock,
        );
        let link = LinkConfig::DEFAULT;
        bench.uut.destination_mac.next = big_endian(&link.host_mac).into();
        bench.uut.destination_ip.next = big_endian(&link.host_ip).into();
        bench.uut.destination_port.next = u64::from(link.host_port).into();
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        let mut capture = GmiiCapture::default();
        let mut errors = vec![];
        let mut next = 0;
        let mut body: VecDeque<u8> = VecDeque::new();
        let mut taken_of_current = 0;
        let mut hole_done = false;
        let mut frames = 0;
        let mut tx_en_before = false;
        for clock in 0..20_000u64 {
            let u = &mut bench.uut;
            let in_hole = hole == Some((next.max(1) - 1, taken_of_current)) && !hole_done;
            u.datagrams.body.valid.next = !body.is_empty() && !in_hole;
            u.datagrams.body.data.next = u64::from(*body.front().unwrap_or(&0xEE)).into();
            u.datagrams.body.last.next = body.len() == 1;
            u.datagrams.body.error.next = false;
            u.datagrams.valid.next = false;
            if body.is_empty() {
                descriptor_noise(u, clock);
            }
            if let Some(d) = datagrams.get(next).filter(|_| body.is_empty()) {
                let bytes = d.to_bytes();
                let b = &bytes[HEADER_LEN..];
                u.datagrams.valid.next = true;
                u.datagrams.kind.next = (d.kind() as u64).into();
                u.datagrams.flags.next = u64::from(d.flags).into();
                u.datagrams.entry_count.next =
                    (u64::from(bytes[20]) << 8 | u64::from(bytes[21])).into();
                u.datagrams.base_tick.next = d.base_tick.into();
                u.datagrams.body_len.next = (b.len() as u64).into();
                u.datagrams.body_sum.next = body_sum(b).into();
            }
            bench.settle();
            let u = &bench.uut;
            if u.datagrams.valid.val() && u.datagrams.ready.val() {
                body = datagrams[next].to_bytes()[HEADER_LEN..]
                    .iter()
                    .copied()
                    .collect();
                next += 1;
                taken_of_current = 0;
            }
            if u.datagrams.body.ready.val() {
                if in_hole {
                    hole_done = true;
                } else {
                    assert!(
                        u.datagrams.body.valid.val(),
                        "clock {clock}: body not ready"
                    );
                    body.pop_front();
                    taken_of_current += 1;
                }
            }
            if u.gmii_tx_er.val() {
                errors.push(clock);
            }
            let tx_en = u.gmii_tx_en.val();
            if hole.is_some_and(|(k, _)| k == frames) {
                // the broken frame is not captured
                if tx_en_before && !tx_en {
                    frames += 1;
                    body.clear();
                }
            } else {
                capture.clock(clock, tx_en, u.gmii_txd.val().to_u8(), false);
                if tx_en_before && !tx_en {
                    frames += 1;
                }
            }
            tx_en_before = tx_en;
            bench.cycle();
            if next == datagrams.len() && frames == datagrams.len() {
                break;
            }
        }
        (capture, errors)
    }

    fn records(n: usize, base_tick: u64) -> DatagramRepr {
        DatagramRepr {
            box_id: 0x0102,
            port_count: 8,
            flags: (n % 2) as u8,
            sequence: 0,
            base_tick,
            body: DatagramBody::Records(
                (0..n)
                    .map(|i| RecordRepr {
                        port: (i % 8) as u8,
                        flags: i.is_multiple_of(3) as u8,
                        tick_offset: i as i32 * 6250 - 3,
                        cell_packet: DataRepr::from_raw(
                            i as u16 + 1,
                            [i as i32, -1, 256, 3, 0, 0, 400, 60, 0],
                        )
                        .unwrap()
                        .to_bytes(),
                    })
                    .collect(),
            ),
        }
    }

    fn status(ports: usize) -> DatagramRepr {
        DatagramRepr {
            box_id: 0x0102,
            port_count: 8,
            flags: 0,
            sequence: 0,
            base_tick: 125_000_000,
            body: DatagramBody::Status(StatusRepr {
                boot_id: 0xB007,
                datagrams_sent: 12,
                records_sent: 345,
                first_port: 0,
                ports: (0..ports).map(|p| PortCounters([p as u32; 8])).collect(),
            }),
        }
    }

    #[test]
    fn frames_carry_the_datagrams_with_valid_checksums_and_fcs() {
        let sent = vec![
            records(1, 0x0123_4567_89AB_CDEF),
            records(3, 42),
            records(55, u64::MAX - 5),
            status(8),
            status(0),
        ];
        let capture = send(&sent);
        assert_eq!(capture.frames.len(), sent.len());
        for (i, (frame, expected)) in capture.frames.iter().zip(&sent).enumerate() {
            let payload = check_frame(frame).unwrap_or_else(|e| panic!("frame {i}: {e}"));
            let got = DatagramRepr::parse(&payload).unwrap_or_else(|e| panic!("frame {i}: {e}"));
            let expected = DatagramRepr {
                sequence: i as u32,
                ..expected.clone()
            };
            assert_eq!(got, expected, "frame {i}");
            let on_wire = 8 + 42 + expected.buffer_len() + 4;
            assert_eq!(frame.len(), on_wire.max(8 + 64), "frame {i} length");
        }
        assert!(
            capture.min_gap.unwrap() >= 12,
            "inter-frame gap {:?}",
            capture.min_gap
        );
    }

    #[test]
    fn addresses_and_ports_are_the_configured_ones() {
        let capture = send(&[records(2, 1)]);
        let frame = &capture.frames[0][8..];
        let link = LinkConfig::DEFAULT;
        assert_eq!(&frame[0..6], &link.host_mac);
        assert_eq!(&frame[6..12], &link.box_mac);
        let h = etherparse::PacketHeaders::from_ethernet_slice(frame).unwrap();
        let Some(etherparse::NetHeaders::Ipv4(ip, _)) = h.net else {
            panic!("not IPv4")
        };
        assert_eq!(
            (ip.source, ip.destination, ip.time_to_live),
            (link.box_ip, link.host_ip, 64)
        );
        assert!(ip.dont_fragment);
        let Some(etherparse::TransportHeader::Udp(udp)) = h.transport else {
            panic!("not UDP")
        };
        assert_eq!(
            (udp.source_port, udp.destination_port),
            (link.box_port, link.host_port)
        );
    }

    #[test]
    fn a_missing_body_beat_marks_its_frame_with_tx_er_and_the_next_frames_are_whole() {
        let sent = vec![records(3, 7), records(2, 8), status(4)];
        let (capture, errors) = send_with_hole(&sent, Some((1, 10)));
        // the error is set on the one byte that was missing, as it leaves GMII
        assert_eq!(errors.len(), 1, "{errors:?}");
        assert_eq!(capture.frames.len(), 2);
        for (frame, (i, expected)) in capture.frames.iter().zip([(0, &sent[0]), (2, &sent[2])]) {
            let got = DatagramRepr::parse(&check_frame(frame).unwrap()).unwrap();
            assert_eq!(
                got,
                DatagramRepr {
                    sequence: i,
                    ..expected.clone()
                }
            );
        }
        // the byte with tx_er is body byte 10 of the second frame
        let second_start = capture.starts[0] + capture.frames[0].len() as u64;
        assert!(errors[0] > second_start + BODY_START as u64);
    }

    /// Where a datagram frame goes.
    #[derive(Clone, Copy, Debug, PartialEq)]
    struct Destination {
        mac: [u8; 6],
        ip: [u8; 4],
        port: u16,
    }

    /// What the bench offers: a datagram to a destination or a raw frame (its bytes from
    /// the destination MAC on, at least 60).
    #[derive(Clone, Debug)]
    enum Item {
        Datagram(DatagramRepr, Destination),
        Raw(Vec<u8>),
    }

    /// The destination the inputs show on every clock but the take of a datagram's
    /// descriptor.
    const DECOY: Destination = Destination {
        mac: [0xDE, 0xC0, 0x1D, 0xDE, 0xC0, 0x1D],
        ip: [203, 0, 113, 99],
        port: 0xDEC0,
    };

    fn drive_destination(u: &mut FrameTransmitter, d: Destination) {
        u.destination_mac.next = big_endian(&d.mac).into();
        u.destination_ip.next = big_endian(&d.ip).into();
        u.destination_port.next = u64::from(d.port).into();
    }

    /// Offers the items in turn, each body's beats always valid (no gaps), the datagram's
    /// destination on the destination inputs only at the clock its descriptor is taken
    /// (the decoy on every other clock). Returns the frames and the take clocks.
    fn send_items(items: &[Item]) -> (GmiiCapture, Vec<u64>) {
        send_items_with_body_starts(items).0
    }

    /// [`send_items`], with the clock of each item's first body beat taken.
    fn send_items_with_body_starts(items: &[Item]) -> ((GmiiCapture, Vec<u64>), Vec<u64>) {
        let mut body_starts = vec![];
        let mut body_started = false;
        let mut bench = Bench::new(
            FrameTransmitter::new(&LinkConfig::DEFAULT, 0x0102, 8),
            |b| &mut b.clock,
        );
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        let mut capture = GmiiCapture::default();
        let mut takes = vec![];
        let mut next = 0;
        let mut body: VecDeque<u8> = VecDeque::new();
        for clock in 0..200_000u64 {
            let u = &mut bench.uut;
            u.datagrams.body.valid.next = !body.is_empty();
            u.datagrams.body.data.next = u64::from(*body.front().unwrap_or(&0xEE)).into();
            u.datagrams.body.last.next = body.len() == 1;
            u.datagrams.body.error.next = false;
            u.datagrams.valid.next = false;
            if body.is_empty() {
                descriptor_noise(u, clock);
            }
            drive_destination(u, DECOY);
            let offered = items.get(next).filter(|_| body.is_empty());
            let mut destination = None;
            let mut offered_body = vec![];
            match offered {
                Some(Item::Datagram(d, to)) => {
                    let bytes = d.to_bytes();
                    offered_body = bytes[HEADER_LEN..].to_vec();
                    u.datagrams.kind.next = (d.kind() as u64).into();
                    u.datagrams.flags.next = u64::from(d.flags).into();
                    u.datagrams.entry_count.next =
                        (u64::from(bytes[20]) << 8 | u64::from(bytes[21])).into();
                    u.datagrams.base_tick.next = d.base_tick.into();
                    destination = Some(*to);
                }
                Some(Item::Raw(frame)) => {
                    offered_body = frame.clone();
                    u.datagrams.kind.next = u64::from(RAW_FRAME_KIND).into();
                    // (a raw frame's descriptor carries no header fields: noise here)
                    u.datagrams.flags.next = 0xA5.into();
                    u.datagrams.entry_count.next = 0x5A5A.into();
                    u.datagrams.base_tick.next = 0x0123_4567_89AB_CDEF_u64.into();
                }
                None => {}
            }
            if offered.is_some() {
                u.datagrams.valid.next = true;
                u.datagrams.body_len.next = (offered_body.len() as u64).into();
                u.datagrams.body_sum.next = body_sum_of(&offered_body).into();
            }
            bench.settle();
            let taken = bench.uut.datagrams.valid.val() && bench.uut.datagrams.ready.val();
            if taken {
                if let Some(to) = destination {
                    // the datagram's destination at the take clock only
                    drive_destination(&mut bench.uut, to);
                    bench.settle();
                }
                body = offered_body.into_iter().collect();
                body_started = false;
                takes.push(clock);
                next += 1;
            }
            let u = &bench.uut;
            if u.datagrams.body.ready.val() {
                assert!(
                    u.datagrams.body.valid.val(),
                    "clock {clock}: body not ready"
                );
                body.pop_front();
                if !body_started {
                    body_starts.push(clock);
                    body_started = true;
                }
            }
            capture.clock(
                clock,
                u.gmii_tx_en.val(),
                u.gmii_txd.val().to_u8(),
                u.gmii_tx_er.val(),
            );
            bench.cycle();
            if next == items.len() && body.is_empty() && capture.frames.len() == items.len() {
                break;
            }
        }
        assert_eq!(capture.frames.len(), items.len(), "every item sent");
        ((capture, takes), body_starts)
    }

    /// The frame on GMII as an independent model has it: preamble, SFD, the bytes, and the
    /// CRC-32 (IEEE 802.3, the `crc` crate) least significant byte first.
    fn on_the_wire(frame: &[u8]) -> Vec<u8> {
        let fcs = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC).checksum(frame);
        let mut wire = vec![0x55; 7];
        wire.push(0xD5);
        wire.extend(frame);
        wire.extend(fcs.to_le_bytes());
        wire
    }

    /// Checks a datagram frame independently: FCS (crc), headers and both checksums
    /// (etherparse), addresses; returns the datagram.
    fn check_datagram_frame(wire: &[u8], to: Destination) -> DatagramRepr {
        assert_eq!(
            &wire[..8],
            &[0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55, 0xD5]
        );
        let frame = &wire[8..wire.len() - 4];
        assert_eq!(on_the_wire(frame), wire, "FCS");
        let h = etherparse::SlicedPacket::from_ethernet(frame).expect("etherparse parses it");
        let Some(etherparse::LinkSlice::Ethernet2(eth)) = h.link else {
            panic!("not Ethernet II")
        };
        let link = LinkConfig::DEFAULT;
        assert_eq!((eth.destination(), eth.source()), (to.mac, link.box_mac));
        let Some(etherparse::NetSlice::Ipv4(ip)) = h.net else {
            panic!("not IPv4")
        };
        let ip_header = ip.header().to_header();
        assert_eq!(
            (ip_header.source, ip_header.destination),
            (link.box_ip, to.ip)
        );
        assert_eq!(
            ip_header.header_checksum,
            ip_header.calc_header_checksum(),
            "IPv4 checksum"
        );
        let Some(etherparse::TransportSlice::Udp(udp)) = h.transport else {
            panic!("not UDP")
        };
        let udp_header = udp.to_header();
        assert_eq!(
            (udp_header.source_port, udp_header.destination_port),
            (link.box_port, to.port)
        );
        let expected = udp_header
            .calc_checksum_ipv4(&ip_header, udp.payload())
            .expect("UDP checksum");
        assert_eq!(udp_header.checksum, expected, "UDP checksum");
        DatagramRepr::parse(udp.payload()).expect("a datagram")
    }

    fn raw_frame(rng: &mut TestRng, len: usize) -> Vec<u8> {
        (0..len).map(|_| rng.byte()).collect()
    }

    fn host(n: u8) -> Destination {
        Destination {
            mac: [0x02, 0x48, 0x4F, 0x53, 0x54, n],
            ip: [10, 20, n, 200u8.wrapping_add(n)],
            port: 40_000 + u16::from(n),
        }
    }

    #[test]
    fn raw_frames_go_out_byte_for_byte_with_their_fcs() {
        let mut rng = TestRng::new(0x4A57);
        let mut lengths = vec![60, 61, 1514, 1513, 64];
        lengths.extend((0..10).map(|_| 60 + (rng.next_u64() % (1514 - 60 + 1)) as usize));
        let frames: Vec<_> = lengths.iter().map(|&n| raw_frame(&mut rng, n)).collect();
        let items: Vec<_> = frames.iter().cloned().map(Item::Raw).collect();
        let ((capture, takes), body_starts) = send_items_with_body_starts(&items);
        for (i, frame) in frames.iter().enumerate() {
            assert_eq!(capture.frames[i], on_the_wire(frame), "raw frame {i}");
            assert_eq!(body_starts[i] - takes[i], TAKE_TO_RAW_BODY, "raw frame {i}");
            assert_eq!(
                capture.starts[i] - takes[i],
                TAKE_TO_FIRST_BYTE,
                "raw frame {i}"
            );
        }
        assert!(capture.min_gap.unwrap() >= INTER_FRAME_GAP as u64);
    }

    #[test]
    fn raw_frames_do_not_advance_the_sequence_number() {
        let mut rng = TestRng::new(7);
        let items = vec![
            Item::Datagram(records(2, 5), host(1)),
            Item::Raw(raw_frame(&mut rng, 60)),
            Item::Datagram(status(3), host(1)),
            Item::Raw(raw_frame(&mut rng, 98)),
            Item::Raw(raw_frame(&mut rng, 342)),
            Item::Datagram(records(1, 9), host(1)),
        ];
        let (capture, takes) = send_items(&items);
        let mut sequence = 0;
        for (i, item) in items.iter().enumerate() {
            assert_eq!(capture.starts[i] - takes[i], TAKE_TO_FIRST_BYTE, "item {i}");
            match item {
                Item::Datagram(d, to) => {
                    let got = check_datagram_frame(&capture.frames[i], *to);
                    assert_eq!(
                        got,
                        DatagramRepr {
                            sequence,
                            ..d.clone()
                        },
                        "item {i}"
                    );
                    sequence += 1;
                }
                Item::Raw(frame) => assert_eq!(capture.frames[i], on_the_wire(frame)),
            }
        }
    }

    #[test]
    fn a_destination_changed_between_two_descriptors_takes_effect_from_the_next_take() {
        // every descriptor is offered as soon as the previous frame's body was taken, the
        // destination differs from one to the next and is right at the take clock only
        let items: Vec<_> = (0..6u8)
            .map(|n| {
                let d = if n % 2 == 0 {
                    records(usize::from(n) + 1, u64::from(n))
                } else {
                    status(usize::from(n))
                };
                Item::Datagram(d, host(n))
            })
            .chain([Item::Datagram(
                records(4, 77),
                Destination {
                    mac: [0xFF; 6],
                    ip: [255, 255, 255, 255],
                    port: 0xFFFF,
                },
            )])
            .collect();
        let (capture, takes) = send_items(&items);
        for (i, item) in items.iter().enumerate() {
            let Item::Datagram(d, to) = item else {
                unreachable!()
            };
            let got = check_datagram_frame(&capture.frames[i], *to);
            assert_eq!(
                got,
                DatagramRepr {
                    sequence: i as u32,
                    ..d.clone()
                }
            );
            assert_eq!(capture.starts[i] - takes[i], TAKE_TO_FIRST_BYTE);
        }
    }

    /// The block's Verilog (with the destination inputs) passes Verilator's lint with the
    /// box's waivers.
    #[test]
    fn verilog_lints_clean() {
        let mut uut = FrameTransmitter::new(&LinkConfig::DEFAULT, 0x0102, 8);
        uut.connect_all();
        let text = generate_verilog(&uut);
        let dir =
            std::env::temp_dir().join(format!("skinbox-frame-transmitter-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&text, &dir).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}
