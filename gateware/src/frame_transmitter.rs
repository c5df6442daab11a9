//! FrameTransmitter: sends one box datagram as a complete Ethernet frame on GMII.
//!
//! It takes a datagram's descriptor (kind, flags, entry count, base tick, body length and
//! the ones'-complement sum of the body's 16-bit words; [`DatagramSink`]) when it is idle
//! and emits, one byte per clock: preamble and SFD, Ethernet II header, IPv4 header with
//! its checksum, UDP header with its checksum, the 24-byte datagram header with the next
//! sequence number, the body from the datagram's body stream, the FCS, and then at least
//! 12 idle clocks. (The headers alone exceed the 60-byte minimum frame: no padding is
//! needed.)
//!
//! A descriptor of kind [`RAW_FRAME_KIND`] is a raw frame: its body is the frame itself
//! from the destination MAC on, sent right after the SFD (its source pads it to the 60-byte
//! minimum; `body_len` 60..=1514), then the FCS and the gap; its other descriptor fields are
//! ignored and the datagram sequence number does not advance.
//!
//! A datagram goes to the destination (MAC, IPv4 address, UDP port) on the
//! `destination_*` inputs at the clock its descriptor is taken: the 12 bytes are loaded
//! into a shift register then and sent from it, the IPv4 checksum adds the address's words
//! to the total length, and the UDP checksum adds the address's and the port's words as its
//! last term (index 18).
//!
//! The checksums are finished long before they are sent: the UDP sum starts from the
//! constant words (addresses, ports, magic, box id) plus the body sum, and adds the UDP
//! length, the kind and then the 16 bytes of the header fields (flags, sequence, base tick,
//! entry count, a zero) one per clock, each at its place in its word (a byte multiplexer
//! stepped by a counter, no word multiplexer); the sum is folded by byte 21. The body is
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

use crate::block_ram::BlockRam;
use crate::datagram_checksum::DatagramChecksum;
use crate::fcs_output::{FcsOutput, OUTPUT_LATENCY};
use crate::hdl::*;
use crate::header_sums::HeaderSums;
use crate::stream::{DatagramSink, RAW_FRAME_KIND};
use skinbox_protocol::datagram::{self, field, HEADER_LEN};
use skinbox_protocol::link::*;
use skinbox_protocol::wire::{ethernet, ipv4, udp, EthernetRepr, UdpRepr};

/// Clocks from the clock a descriptor is taken (`valid & ready` at its edge) to the clock
/// the frame's first preamble byte is on `gmii_txd`: the transmitter registers `sending`,
/// then the output stage ([`FcsOutput`]) registers the byte and the output (with the FCS).
pub const TAKE_TO_FIRST_BYTE: u64 = 1 + OUTPUT_LATENCY;

/// Clocks from the clock a raw frame's descriptor is taken to the clock its first body
/// beat is taken (`ready`): the body follows the preamble and the SFD, then one beat per
/// clock. (A datagram's first body beat is taken [`BODY_START`] - [`PREAMBLE_LEN`] clocks
/// later.)
pub const TAKE_TO_RAW_BODY: u64 = TAKE_TO_FIRST_BYTE - 2 + PREAMBLE_LEN as u64;

/// Frame byte where the datagram body starts (preamble, Ethernet, IPv4, UDP, box header).
pub const BODY_START: usize = PAYLOAD_AT_ON_WIRE + HEADER_LEN;

// A datagram with an empty body still makes a minimum-size frame: no padding is ever needed.
const _: () = assert!(BODY_START >= PREAMBLE_LEN + MIN_FRAME_LEN);

// Positions on the wire: the frame positions of `link` after the preamble and SFD.
const IPV4_AT_ON_WIRE: usize = PREAMBLE_LEN + IPV4_AT;
const UDP_AT_ON_WIRE: usize = PREAMBLE_LEN + UDP_AT;
const PAYLOAD_AT_ON_WIRE: usize = PREAMBLE_LEN + PAYLOAD_AT;
const IP_TOTAL_LEN_AT: usize = IPV4_AT_ON_WIRE + IPV4_TOTAL_LEN.start;
const IP_CHECKSUM_AT: usize = IPV4_AT_ON_WIRE + IPV4_CHECKSUM.start;
const UDP_LEN_AT: usize = UDP_AT_ON_WIRE + UDP_LEN.start;
const UDP_CHECKSUM_AT: usize = UDP_AT_ON_WIRE + UDP_CHECKSUM.start;
const KIND_AT: usize = PAYLOAD_AT_ON_WIRE + field::KIND;
/// First of the header bytes sent from the `fields` shift registers: flags, sequence, base
/// tick, entry count.
const FIELDS_AT: usize = PAYLOAD_AT_ON_WIRE + field::FLAGS;
const FIELDS_LEN: usize = field::ENTRY_COUNT.end - field::FLAGS;

// The destination's bytes: the destination MAC, the IPv4 destination address and the UDP
// destination port, sent from the `destination` shift registers.
const DESTINATION_MAC_AT: usize = PREAMBLE_LEN + ethernet::field::DESTINATION.start;
const DESTINATION_IP_AT: usize = IPV4_AT_ON_WIRE + ipv4::field::DESTINATION.start;
const DESTINATION_PORT_AT: usize = UDP_AT_ON_WIRE + udp::field::DESTINATION_PORT.start;
const DESTINATION_MAC_LEN: usize =
    ethernet::field::DESTINATION.end - ethernet::field::DESTINATION.start;
const DESTINATION_IP_LEN: usize = ipv4::field::DESTINATION.end - ipv4::field::DESTINATION.start;
const DESTINATION_PORT_LEN: usize =
    udp::field::DESTINATION_PORT.end - udp::field::DESTINATION_PORT.start;

/// A frame position (or length) as a kernel constant; panics if it does not fit.
fn position<const N: usize>(at: usize) -> Constant<Bits<N>> {
    constant(at as u64)
}

/// The constant bytes of a frame up to the body; variable fields (the destination's too)
/// are 0 here.
fn template(link: &LinkConfig, box_id: u16, port_count: u8) -> Vec<u8> {
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

/// Address of the header table read between frames: it holds the first byte, which the
/// first two bytes of a frame are (the preamble), read before the frame's own addresses.
const TEMPLATE_IDLE: usize = 127;

// Where a header byte comes from, one bit each (`byte_source`): the template is ORed in all
// through the header (it is 0 at the other sources' bytes); the body is alone.
const SOURCE_TEMPLATE: u64 = 1;
const SOURCE_TOTAL_LEN: u64 = 1 << 1; // and 1 << 2, its low byte
const SOURCE_IP_CHECKSUM: u64 = 1 << 3; // and 1 << 4
const SOURCE_UDP_LEN: u64 = 1 << 5; // and 1 << 6
const SOURCE_UDP_CHECKSUM: u64 = 1 << 7; // and 1 << 8
const SOURCE_KIND: u64 = 1 << 9;
const SOURCE_FIELDS: u64 = 1 << 10;
const SOURCE_BODY: u64 = 1 << 11;
const SOURCE_DESTINATION: u64 = 1 << 12;
const SOURCE_BITS: usize = 13;
/// Width of a header table entry: the template byte, then the byte sources.
const HEADER_ENTRY_BITS: usize = 8 + SOURCE_BITS;

/// The sources of header byte `at` other than the template (0 for the preamble and the
/// bytes past the header).
fn header_sources(at: usize) -> u64 {
    let word = |first: usize, high: u64| {
        if at == first {
            high
        } else if at == first + 1 {
            high << 1
        } else {
            0
        }
    };
    let within = |first: usize, len: usize| (first..first + len).contains(&at);
    let mut sources = word(IP_TOTAL_LEN_AT, SOURCE_TOTAL_LEN)
        | word(IP_CHECKSUM_AT, SOURCE_IP_CHECKSUM)
        | word(UDP_LEN_AT, SOURCE_UDP_LEN)
        | word(UDP_CHECKSUM_AT, SOURCE_UDP_CHECKSUM);
    if at == KIND_AT {
        sources |= SOURCE_KIND;
    }
    if within(FIELDS_AT, FIELDS_LEN) {
        sources |= SOURCE_FIELDS;
    }
    if within(DESTINATION_MAC_AT, DESTINATION_MAC_LEN)
        || within(DESTINATION_IP_AT, DESTINATION_IP_LEN)
        || within(DESTINATION_PORT_AT, DESTINATION_PORT_LEN)
    {
        sources |= SOURCE_DESTINATION;
    }
    sources
}

/// The transmitter's header table, read two clocks ahead: at address i the template's byte
/// i + 2 and, above it, the sources of byte i + 3 (registered once more before they choose
/// the byte); at [`TEMPLATE_IDLE`] the first byte and the sources of byte 2.
fn header_table(t: &[u8]) -> Vec<u64> {
    assert_eq!(t[0], t[1], "the frame starts with two equal bytes");
    assert!(
        t.len() - 2 <= TEMPLATE_IDLE,
        "the template fits below the idle address"
    );
    let mut table: Vec<u64> = (0..TEMPLATE_IDLE)
        .map(|a| u64::from(*t.get(a + 2).unwrap_or(&0)) | header_sources(a + 3) << 8)
        .collect();
    table.push(u64::from(t[0]) | header_sources(2) << 8);
    table
}

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
    // the header table in block RAM (`header_table`): the template byte and, above it, the
    // byte sources of the byte after it
    template: BlockRam<HEADER_ENTRY_BITS, 7>,
    // the UDP checksum's constant words with the UDP length's constant part (the UDP and
    // datagram headers), counted twice like the length
    udp_term_constant: Constant<Bits<32>>,
    // Frame positions from the format constants. The byte at `index` is chosen two clocks
    // ahead (see the kernel), so the positions the byte-source tests name are "ahead": two
    // lower than the bytes.
    // the SFD's position minus one (the CRC starts after it), and the first byte in the CRC
    sfd_ahead: Constant<Bits<11>>,
    crc_from: Constant<Bits<11>>,
    // the body's first byte; the frame's last byte minus one, less the body length (from it
    // `end_minus_one`); the body's first byte - 2 (the payload is read two clocks ahead);
    // the same two for a raw frame (its body follows the SFD)
    body_start: Constant<Bits<11>>,
    frame_end_over_body: Constant<Bits<11>>,
    raw_body_start: Constant<Bits<11>>,
    raw_frame_end_over_body: Constant<Bits<11>>,
    raw_kind: Constant<Bits<8>>,
    // IPv4 total length and UDP length minus the body length
    ip_len_over_body: Constant<Bits<16>>,
    udp_len_over_body: Constant<Bits<16>>,
    // clocks of the inter-frame gap after the frame's last clock
    gap_clocks: Constant<Bits<4>>,
    // the first field byte and the byte after the fields, each two lower (the field
    // position steps there)
    fields_ahead: Constant<Bits<7>>,
    fields_end_ahead: Constant<Bits<7>>,
    template_idle: Constant<Bits<7>>,
    // the byte sources, one bit each (see `byte_source`)
    source_template: Constant<Bits<SOURCE_BITS>>,
    source_body: Constant<Bits<SOURCE_BITS>>,
    // the IPv4 header checksum and the destination's sum
    header_sums: HeaderSums,
    // the UDP checksum (final long before byte 48: the sum is done by byte 21)
    udp_sum: DatagramChecksum,
    // the output stage with the FCS
    fcs_stage: FcsOutput,
    sending: DFF<Bit>,
    index: DFF<Bits<11>>,
    gap: DFF<Bits<4>>,
    // gap == 0, kept in a register (`idle` is one gate from registers)
    gap_done: DFF<Bit>,
    // `!sending & gap_done`, the descriptor's `ready`, as a register of its own (no gate
    // between it and the arbiter's handshake)
    idle: DFF<Bit>,
    kind_held: DFF<Bits<8>>,
    body_len_held: DFF<Bits<11>>,
    // the descriptor is a raw frame's (its kind is `RAW_FRAME_KIND`)
    raw_held: DFF<Bit>,
    // the destination's 12 bytes (MAC, IP, port), most significant first, loaded at the
    // take and shifted a byte up as each goes out (cut in two like the fields)
    destination_high: DFF<Bits<64>>,
    destination_low: DFF<Bits<32>>,
    // the checksum's term is the destination's sum (index 18), registered like `term_is_kind`
    term_is_destination: DFF<Bit>,
    // the body's first byte and the frame's end over the body, of the held kind
    geometry_start: Signal<Local, Bits<11>>,
    geometry_end_over_body: Signal<Local, Bits<11>>,
    // the 15 header bytes (flags, sequence, base tick, entry count), most significant
    // first, and a zero byte, held while the frame goes out (cut in two: no word over 64
    // bits to simulate); `field_byte` steps through them, once to sum their words and
    // once to send them
    fields_high: DFF<Bits<64>>,
    fields_low: DFF<Bits<64>>,
    // the position of the next clock's field byte, and the field byte, a register read
    // from the fields at that position (no multiplexer between the position and its use)
    next_field_position: DFF<Bits<4>>,
    field_word: Signal<Local, Bits<64>>,
    field_word_shifted: Signal<Local, Bits<64>>,
    field_byte: DFF<Bits<8>>,
    next_sequence: DFF<Bits<32>>,
    body_end: DFF<Bits<11>>,
    body_end_less_one: DFF<Bits<11>>,
    // the byte at `index` is a body byte: the body stream's `ready`
    in_body: DFF<Bit>,
    // the index before the frame's last one (its last FCS byte), set with the descriptor
    end_minus_one: DFF<Bits<11>>,
    // registered index tests, true at index 7 (the CRC starts) and at the last index
    crc_starts: DFF<Bit>,
    frame_ends: DFF<Bit>,
    // registered index ranges, like `crc_starts`: the checksum's term is a field byte
    // (2..18), the checksum adds its term (1..=18); registered two clocks ahead, the field
    // position steps from the next clock's to the one after it (the field byte steps at
    // 2..18 and 57..72)
    term_from_fields: DFF<Bit>,
    checksum_adds: DFF<Bit>,
    next_field_steps: DFF<Bit>,
    header_index: Signal<Local, Bits<7>>,
    total_len: DFF<Bits<16>>,
    udp_len: DFF<Bits<16>>,
    // the checksum's term at this index: the kind (index 0), the UDP length words with the
    // constant words (index 1), registered a clock ahead like `term_from_fields`
    term_is_kind: DFF<Bit>,
    term_is_udp_len: DFF<Bit>,
    // the UDP length term (twice the UDP length plus the constant words), from the held
    // body length like `udp_len`
    udp_term: DFF<Bits<32>>,
    // where the byte at `index` comes from (`SOURCE_*`), chosen a clock ahead from the
    // header table's sources and the two flags below
    byte_source: DFF<Bits<SOURCE_BITS>>,
    // the byte after the next is a header byte (from the table's sources), or a body byte
    header_ahead: DFF<Bit>,
    body_ahead: DFF<Bit>,
    // the index is 72 or more: the next index's following byte is in the body
    body_follows: Signal<Local, Bit>,
    // sending, and the next index is this one + 1 (otherwise it is 0)
    frame_goes_on: Signal<Local, Bit>,
    header_byte: Signal<Local, Bits<8>>,
    // the steady sources and the destination of the next clock's byte, ORed a clock ahead
    // (see the kernel), the sources they are chosen by, and the destination's next byte
    header_early: DFF<Bits<8>>,
    early_sources: Signal<Local, Bits<SOURCE_BITS>>,
    early_byte: Signal<Local, Bits<8>>,
    destination_next_byte: Signal<Local, Bits<8>>,
    tx_byte: Signal<Local, Bits<8>>,
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
            template: BlockRam::with_contents(&header_table(&t)),
            udp_term_constant: Constant::new(
                (udp_constant + 2 * (BODY_START - UDP_AT_ON_WIRE) as u64).into(),
            ),
            sfd_ahead: position(PREAMBLE_LEN - 2),
            crc_from: position(PREAMBLE_LEN),
            body_start: position(BODY_START),
            frame_end_over_body: position(BODY_START + FCS_LEN - 2),
            raw_body_start: position(PREAMBLE_LEN),
            raw_frame_end_over_body: position(PREAMBLE_LEN + FCS_LEN - 2),
            raw_kind: Constant::new(u64::from(RAW_FRAME_KIND).into()),
            ip_len_over_body: position(BODY_START - IPV4_AT_ON_WIRE),
            udp_len_over_body: position(BODY_START - UDP_AT_ON_WIRE),
            gap_clocks: position(INTER_FRAME_GAP - 1),
            fields_ahead: position(FIELDS_AT - 2),
            fields_end_ahead: position(FIELDS_AT + FIELDS_LEN - 2),
            template_idle: position(TEMPLATE_IDLE),
            source_template: Constant::new(SOURCE_TEMPLATE.into()),
            source_body: Constant::new(SOURCE_BODY.into()),
            header_sums: HeaderSums::new(ip_constant),
            udp_sum: Default::default(),
            fcs_stage: Default::default(),
            sending: Default::default(),
            index: Default::default(),
            gap: Default::default(),
            gap_done: Default::default(),
            idle: Default::default(),
            kind_held: Default::default(),
            body_len_held: Default::default(),
            raw_held: Default::default(),
            destination_high: Default::default(),
            destination_low: Default::default(),
            term_is_destination: Default::default(),
            geometry_start: Default::default(),
            geometry_end_over_body: Default::default(),
            fields_high: Default::default(),
            fields_low: Default::default(),
            next_field_position: Default::default(),
            field_word: Default::default(),
            field_word_shifted: Default::default(),
            field_byte: Default::default(),
            next_sequence: Default::default(),
            body_end: Default::default(),
            body_end_less_one: Default::default(),
            in_body: Default::default(),
            end_minus_one: Default::default(),
            crc_starts: Default::default(),
            term_from_fields: Default::default(),
            checksum_adds: Default::default(),
            next_field_steps: Default::default(),
            header_index: Default::default(),
            frame_ends: Default::default(),
            total_len: Default::default(),
            udp_len: Default::default(),
            term_is_kind: Default::default(),
            term_is_udp_len: Default::default(),
            udp_term: Default::default(),
            byte_source: Default::default(),
            header_ahead: Default::default(),
            body_ahead: Default::default(),
            body_follows: Default::default(),
            frame_goes_on: Default::default(),
            header_byte: Default::default(),
            header_early: Default::default(),
            early_sources: Default::default(),
            early_byte: Default::default(),
            destination_next_byte: Default::default(),
            tx_byte: Default::default(),
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
            sending,
            index,
            gap,
            gap_done,
            idle,
            kind_held,
            body_len_held,
            fields_high,
            fields_low,
            next_field_position,
            field_byte,
            next_sequence,
            body_end,
            body_end_less_one,
            in_body,
            end_minus_one,
            crc_starts,
            term_from_fields,
            checksum_adds,
            next_field_steps,
            frame_ends,
            total_len,
            udp_len,
            byte_source,
            header_ahead,
            body_ahead,
            term_is_kind,
            term_is_udp_len,
            udp_term,
            raw_held,
            destination_high,
            destination_low,
            term_is_destination,
            header_early
        );
        // Frame geometry: registered at the start from the body length (lengths), two clocks
        // later the IPv4 checksum (needed from byte 32 on), through its first fold.
        // (the destination's words a clock after the take, with the total length a clock later)
        self.header_sums.clock.next = self.clock.val();
        self.header_sums.load.next = !self.sending.q.val();
        self.header_sums.destination_ip.next = self.destination_ip.val();
        self.header_sums.destination_port.next = self.destination_port.val();
        self.header_sums.total_len.next = self.total_len.q.val();

        // The variable words of the UDP checksum, one per clock from byte 0: the kind, the
        // UDP length (counted twice: header and pseudo header; valid from byte 1) with the
        // constant words' sum (the checksum starts from the body's sum alone, no adder after
        // the descriptor), then the 16 field bytes one per clock as the position steps,
        // alternately the low and the high byte of a word (flags is the low byte of its
        // word).
        // the field byte of the next clock: byte 0 is the top byte of `fields_high` (the
        // fields are held from index 0 on; the byte is read from index 2 on)
        self.field_word.next = self.fields_high.q.val();
        if self.next_field_position.q.val().get_bit(3) {
            self.field_word.next = self.fields_low.q.val();
        }
        self.field_word_shifted.next = self.field_word.val()
            << (bit_cast::<64, 3>(self.next_field_position.q.val().get_bits::<3>(0)) << 3);
        self.field_byte.d.next = self.field_word_shifted.val().get_bits::<8>(56);
        self.udp_sum.clock.next = self.clock.val();
        self.udp_sum.load.next = !self.sending.q.val();
        self.udp_sum.body_sum.next = self.datagrams.body_sum.val();
        // the word chosen at byte i is added at byte i + 1 (from a register)
        self.udp_sum.add.next = self.sending.q.val() & self.checksum_adds.q.val();
        self.udp_sum.term_is_kind.next = self.term_is_kind.q.val();
        self.udp_sum.term_is_udp_len.next = self.term_is_udp_len.q.val();
        self.udp_sum.term_is_destination.next = self.term_is_destination.q.val();
        self.udp_sum.term_from_fields.next = self.term_from_fields.q.val();
        self.udp_sum.high_byte.next = self.index.q.val().get_bit(0);
        self.udp_sum.kind.next = self.kind_held.q.val();
        self.udp_sum.udp_term.next = self.udp_term.q.val();
        self.udp_sum.destination_sum.next = self.header_sums.destination_sum.val();
        self.udp_sum.field_byte.next = self.field_byte.q.val();

        // The byte at `index`, from a multiplexer whose select is a register
        // (`byte_source`); the template byte and the sources come from the header table,
        // read two clocks ahead (127 is TEMPLATE_IDLE, read between frames).
        self.template.clock.next = self.clock.val();
        self.template.write_enable.next = false;
        self.template.write_address.next = 0.into();
        self.template.write_data.next = 0.into();
        // (past the header only the body follows: the header's tests need the index's low
        // seven bits only)
        self.header_index.next = self.index.q.val().get_bits::<7>(0);
        self.template.read_address.next = self.template_idle.val();
        if self.sending.q.val() {
            self.template.read_address.next = self.header_index.val();
        }
        // index >= 72, from its bits: 72 is 0b100_1000; for a raw frame index >= 6
        self.body_follows.next = (self.index.q.val().get_bits::<4>(7) != 0)
            | (self.header_index.val().get_bit(6)
                & (self.header_index.val().get_bits::<3>(3) != 0));
        if self.raw_held.q.val() {
            self.body_follows.next = (self.index.q.val().get_bits::<8>(3) != 0)
                | (self.index.q.val().get_bit(2) & self.index.q.val().get_bit(1));
        }
        // The byte's source: the table's sources of byte `index + 3` (read at `index - 1`
        // for the next index, `index + 1` while the frame goes on: when it does not, the
        // flags below choose the template alone) under the flags of this index's byte after
        // the next.
        self.frame_goes_on.next = self.sending.q.val() & !self.frame_ends.q.val();
        self.header_ahead.d.next = self.frame_goes_on.val() & !self.body_follows.val();
        self.body_ahead.d.next = self.frame_goes_on.val() & self.body_follows.val();
        self.byte_source.d.next = self.source_template.val();
        if self.body_ahead.q.val() {
            // the body (the FCS replaces what follows it at the output)
            self.byte_source.d.next = self.source_body.val();
        } else if self.header_ahead.q.val() {
            self.byte_source.d.next = self.source_template.val()
                | self.template.read_data.val().get_bits::<SOURCE_BITS>(8);
        }
        // The header's sources are ORed (each is 0 unless chosen), the body beside them (it
        // is alone: its data passes one multiplexer, not the header's OR). The sources
        // that are steady through the header (lengths, checksums, kind) and the destination
        // are ORed a clock ahead into `header_early`, from the table's sources of the next
        // byte (those `byte_source` takes) and the destination byte that is on top after
        // this clock's shift: only the template byte (a block RAM output) and the field
        // byte (stepped each clock) pass the OR in the byte's own clock.
        self.destination_next_byte.next = self.destination_high.q.val().get_bits::<8>(56);
        if self.sending.q.val() & self.byte_source.q.val().get_bit(12) {
            self.destination_next_byte.next = self.destination_high.q.val().get_bits::<8>(48);
        }
        self.early_sources.next = 0.into();
        if self.header_ahead.q.val() {
            self.early_sources.next = self.template.read_data.val().get_bits::<SOURCE_BITS>(8);
        }
        self.early_byte.next = 0.into();
        if self.early_sources.val().get_bit(1) {
            self.early_byte.next = self.total_len.q.val().get_bits::<8>(8);
        }
        if self.early_sources.val().get_bit(2) {
            self.early_byte.next = self.early_byte.val() | self.total_len.q.val().get_bits::<8>(0);
        }
        if self.early_sources.val().get_bit(3) {
            self.early_byte.next =
                self.early_byte.val() | self.header_sums.ip_checksum.val().get_bits::<8>(8);
        }
        if self.early_sources.val().get_bit(4) {
            self.early_byte.next =
                self.early_byte.val() | self.header_sums.ip_checksum.val().get_bits::<8>(0);
        }
        if self.early_sources.val().get_bit(5) {
            self.early_byte.next = self.early_byte.val() | self.udp_len.q.val().get_bits::<8>(8);
        }
        if self.early_sources.val().get_bit(6) {
            self.early_byte.next = self.early_byte.val() | self.udp_len.q.val().get_bits::<8>(0);
        }
        if self.early_sources.val().get_bit(7) {
            self.early_byte.next =
                self.early_byte.val() | self.udp_sum.udp_checksum.val().get_bits::<8>(8);
        }
        if self.early_sources.val().get_bit(8) {
            self.early_byte.next =
                self.early_byte.val() | self.udp_sum.udp_checksum.val().get_bits::<8>(0);
        }
        if self.early_sources.val().get_bit(9) {
            self.early_byte.next = self.early_byte.val() | self.kind_held.q.val();
        }
        if self.early_sources.val().get_bit(12) {
            self.early_byte.next = self.early_byte.val() | self.destination_next_byte.val();
        }
        self.header_early.d.next = self.early_byte.val();
        self.header_byte.next = self.header_early.q.val();
        if self.byte_source.q.val().get_bit(0) {
            self.header_byte.next =
                self.header_byte.val() | self.template.read_data.val().get_bits::<8>(0);
        }
        if self.byte_source.q.val().get_bit(10) {
            self.header_byte.next = self.header_byte.val() | self.field_byte.q.val();
        }
        self.tx_byte.next = self.header_byte.val();
        if self.byte_source.q.val().get_bit(11) {
            self.tx_byte.next = self.datagrams.body.data.val();
        }
        // The body beat is taken at its index: `in_body` is set a clock ahead, from the
        // flag of the next index's byte (`body_ahead`) and the body's end.
        self.datagrams.body.ready.next = self.in_body.q.val();
        self.in_body.d.next = self.frame_goes_on.val()
            & self.body_ahead.q.val()
            & (self.index.q.val() < self.body_end_less_one.q.val());

        // Output stage: the byte through a register, the CRC from that register, the FCS
        // at the output (`FcsOutput`).
        self.fcs_stage.clock.next = self.clock.val();
        self.fcs_stage.reset.next = self.reset.val();
        self.fcs_stage.valid.next = self.sending.q.val();
        self.fcs_stage.data.next = self.tx_byte.val();
        self.fcs_stage.covered.next = (self.index.q.val() >= self.crc_from.val())
            & (self.index.q.val() < self.body_end.q.val());
        self.fcs_stage.fcs.next = self.index.q.val() >= self.body_end.q.val();
        self.fcs_stage.beat_missing.next = self.in_body.q.val() & !self.datagrams.body.valid.val();
        // index 7: the SFD is in the output stage now: the CRC starts with the next byte
        self.fcs_stage.crc_start.next = self.sending.q.val() & self.crc_starts.q.val();

        // the index tests of the next clock, from this clock's index (it counts up by one
        // while sending)
        self.crc_starts.d.next =
            self.sending.q.val() & (self.index.q.val() == self.sfd_ahead.val());
        self.term_from_fields.d.next =
            self.sending.q.val() & (self.index.q.val() >= 1) & (self.index.q.val() < 17);
        self.term_is_destination.d.next = self.sending.q.val() & (self.index.q.val() == 17);
        self.checksum_adds.d.next = self.sending.q.val() & (self.index.q.val() < 19);
        // the next index is 0 unless the frame goes on, 1 after 0
        self.term_is_kind.d.next = !self.frame_goes_on.val();
        self.term_is_udp_len.d.next = self.frame_goes_on.val() & self.term_is_kind.q.val();
        // (the index after the next is this one + 2 while the frame goes on)
        self.next_field_steps.d.next = self.frame_goes_on.val()
            & ((self.index.q.val() < 16)
                | ((self.index.q.val() >= bit_cast::<11, 7>(self.fields_ahead.val()))
                    & (self.index.q.val() < bit_cast::<11, 7>(self.fields_end_ahead.val()))));
        // the position goes once round for the checksum (back at 0 after 16 bytes) and
        // then through the first 15 bytes to send them; 0 between frames
        self.next_field_position.d.next = 0.into();
        if self.frame_goes_on.val() {
            self.next_field_position.d.next = self.next_field_position.q.val();
            if self.next_field_steps.q.val() {
                self.next_field_position.d.next = self.next_field_position.q.val() + 1;
            }
        }
        self.frame_ends.d.next =
            self.sending.q.val() & (self.index.q.val() == self.end_minus_one.q.val());
        if self.sending.q.val() {
            self.index.d.next = self.index.q.val() + 1;
            // the frame's last clock: the index is back at 0 for the next frame and the
            // sequence steps (the next descriptor is taken with it), so `start` only sets
            // `sending`
            if self.frame_ends.q.val() {
                self.sending.d.next = false;
                self.index.d.next = 0.into();
                if !self.raw_held.q.val() {
                    // (a raw frame is no datagram: the sequence stays)
                    self.next_sequence.d.next = self.next_sequence.q.val() + 1;
                }
                self.gap.d.next = self.gap_clocks.val();
                self.gap_done.d.next = false;
            }
        } else if !self.gap_done.q.val() {
            self.gap.d.next = self.gap.q.val() - 1;
            self.gap_done.d.next = self.gap.q.val() == 1;
        } else if self.datagrams.valid.val() {
            self.sending.d.next = true;
        }
        // The frame geometry follows the held body length a clock later: it is valid from
        // index 1 on (nothing reads it at index 0).
        self.geometry_start.next = self.body_start.val();
        self.geometry_end_over_body.next = self.frame_end_over_body.val();
        if self.raw_held.q.val() {
            self.geometry_start.next = self.raw_body_start.val();
            self.geometry_end_over_body.next = self.raw_frame_end_over_body.val();
        }
        self.body_end.d.next = self.body_len_held.q.val() + self.geometry_start.val();
        self.body_end_less_one.d.next = self.body_len_held.q.val() + self.geometry_start.val() - 1;
        self.end_minus_one.d.next = self.body_len_held.q.val() + self.geometry_end_over_body.val();
        self.total_len.d.next =
            bit_cast::<16, 11>(self.body_len_held.q.val()) + self.ip_len_over_body.val();
        self.udp_len.d.next =
            bit_cast::<16, 11>(self.body_len_held.q.val()) + self.udp_len_over_body.val();
        self.udp_term.d.next =
            (bit_cast::<32, 11>(self.body_len_held.q.val()) << 1) + self.udp_term_constant.val();
        // The descriptor is taken in every clock without a frame going out, so taking it
        // only has to set `sending`.
        if !self.sending.q.val() {
            self.kind_held.d.next = self.datagrams.kind.val();
            self.body_len_held.d.next = self.datagrams.body_len.val();
            self.raw_held.d.next = self.datagrams.kind.val() == self.raw_kind.val();
            self.destination_high.d.next = (bit_cast::<64, 48>(self.destination_mac.val()) << 16)
                | bit_cast::<64, 16>(self.destination_ip.val().get_bits::<16>(16));
            self.destination_low.d.next =
                (bit_cast::<32, 16>(self.destination_ip.val().get_bits::<16>(0)) << 16)
                    | bit_cast::<32, 16>(self.destination_port.val());
            self.fields_high.d.next = (bit_cast::<64, 8>(self.datagrams.flags.val()) << 56)
                | (bit_cast::<64, 32>(self.next_sequence.q.val()) << 24)
                | bit_cast::<64, 24>(self.datagrams.base_tick.val().get_bits::<24>(40));
            self.fields_low.d.next =
                (bit_cast::<64, 40>(self.datagrams.base_tick.val().get_bits::<40>(0)) << 24)
                    | (bit_cast::<64, 16>(self.datagrams.entry_count.val()) << 8);
        }
        // a destination byte leaves: the next one moves up
        if self.sending.q.val() & self.byte_source.q.val().get_bit(12) {
            self.destination_high.d.next = (self.destination_high.q.val() << 8)
                | bit_cast::<64, 8>(self.destination_low.q.val().get_bits::<8>(24));
            self.destination_low.d.next = self.destination_low.q.val() << 8;
        }
        // `!sending & gap_done` of the next clock: a frame goes on or ends (then the gap
        // starts), the gap's last clock, or idle and no descriptor taken
        self.idle.d.next = false;
        if !self.sending.q.val() {
            if self.gap_done.q.val() {
                self.idle.d.next = !self.datagrams.valid.val();
            } else {
                self.idle.d.next = self.gap.q.val() == 1;
            }
        }
        if self.reset.val() {
            self.idle.d.next = true;
            self.term_is_destination.d.next = false;
            self.sending.d.next = false;
            self.crc_starts.d.next = false;
            self.frame_ends.d.next = false;
            self.term_from_fields.d.next = false;
            self.checksum_adds.d.next = false;
            self.next_field_steps.d.next = false;
            self.next_field_position.d.next = 0.into();
            self.gap.d.next = 0.into();
            self.gap_done.d.next = true;
            self.next_sequence.d.next = 0.into();
            self.index.d.next = 0.into();
            self.term_is_kind.d.next = true;
            self.term_is_udp_len.d.next = false;
            self.header_ahead.d.next = false;
            self.body_ahead.d.next = false;
            self.in_body.d.next = false;
        }
        self.datagrams.ready.next = self.idle.q.val();
        self.gmii_txd.next = self.fcs_stage.gmii_txd.val();
        self.gmii_tx_en.next = self.fcs_stage.gmii_tx_en.val();
        self.gmii_tx_er.next = self.fcs_stage.gmii_tx_er.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{check_frame, Bench, GmiiCapture, TestRng};
    use skinbox_protocol::datagram::DatagramBody;
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

    fn body_sum(body: &[u8]) -> u64 {
        word_sum(body)
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
                u.datagrams.body_sum.next = word_sum(&offered_body).into();
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
