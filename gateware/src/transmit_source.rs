//! TransmitSource: the frame transmitter's byte selection: for each index of a frame, the
//! byte from the header template, a header field (lengths, checksums, kind, the field
//! bytes), the destination, or the body.
//!
//! The header table (in block RAM, [`header_table`]) holds at address i the template's
//! byte i + 2 and, above it, the sources of byte i + 3 ([`header_sources`], one bit each);
//! it is read two clocks ahead (at [`TEMPLATE_IDLE`] between frames: the first byte and
//! the sources of byte 2). The byte at `index` comes from a multiplexer whose select is a
//! register (`byte_source`), chosen a clock ahead from the table's sources (registered
//! once after the block RAM, so no path runs from its output into a choice) and two flags
//! (a header byte, a body byte follows). The header's sources are ORed (each is 0 unless
//! chosen), the body beside them (it passes one multiplexer, not the header's OR). The
//! sources that are steady through the header (lengths, checksums, kind) and the
//! destination are ORed a clock ahead into `header_early`: only the template byte (a block
//! RAM output) and the field byte (stepped each clock) pass the OR in the byte's own
//! clock. The destination's 12 bytes (MAC, IPv4 address, UDP port) are loaded into a
//! shift register while no frame goes out and shifted a byte up as each goes out (from
//! index 8 on: until then the header sums read its address and port there).
//!
//! Latency: `frame_byte` is the byte of this clock's `index` (no register between it and
//! the output stage; the body's data passes one multiplexer). Cost: one DP16KD (128 x 21
//! bits), two 13-bit source registers, two flags, the early byte and the 96-bit
//! destination.

use crate::block_ram::BlockRam;
use crate::hdl::*;
use crate::transmit_layout::{
    DESTINATION_IP_AT, DESTINATION_IP_LEN, DESTINATION_MAC_AT, DESTINATION_MAC_LEN,
    DESTINATION_PORT_AT, DESTINATION_PORT_LEN, FIELDS_AT, FIELDS_LEN, IP_CHECKSUM_AT,
    IP_TOTAL_LEN_AT, KIND_AT, UDP_CHECKSUM_AT, UDP_LEN_AT,
};

/// Address of the header table read between frames: it holds the first byte, which the
/// first two bytes of a frame are (the preamble), read before the frame's own addresses.
pub const TEMPLATE_IDLE: usize = 127;

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
pub fn header_sources(at: usize) -> u64 {
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
/// i + 2 and, above it, the sources of byte i + 4 (registered twice more before they choose
/// the byte); at [`TEMPLATE_IDLE`] the first byte and the sources of bytes 2 and 3 (the
/// preamble's: none).
pub fn header_table(t: &[u8]) -> Vec<u64> {
    assert_eq!(t[0], t[1], "the frame starts with two equal bytes");
    assert!(
        t.len() - 2 <= TEMPLATE_IDLE,
        "the template fits below the idle address"
    );
    let mut table: Vec<u64> = (0..TEMPLATE_IDLE)
        .map(|a| u64::from(*t.get(a + 2).unwrap_or(&0)) | header_sources(a + 4) << 8)
        .collect();
    assert_eq!(
        header_sources(2),
        header_sources(3),
        "bytes 2 and 3 share the idle entry"
    );
    table.push(u64::from(t[0]) | header_sources(2) << 8);
    table
}

/// The byte selection of the frame transmitter.
#[derive(LogicBlock)]
pub struct TransmitSource {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: no frame.
    pub reset: Signal<In, Bit>,
    /// A frame goes out (otherwise the destination is loaded).
    pub sending: Signal<In, Bit>,
    /// The frame goes on after this clock's index.
    pub frame_goes_on: Signal<In, Bit>,
    /// The frame is a raw frame (its body follows the SFD).
    pub raw: Signal<In, Bit>,
    /// The frame's index in this clock.
    pub index: Signal<In, Bits<11>>,
    /// The IPv4 total length.
    pub total_len: Signal<In, Bits<16>>,
    /// The IPv4 header checksum.
    pub ip_checksum: Signal<In, Bits<16>>,
    /// The UDP length.
    pub udp_len: Signal<In, Bits<16>>,
    /// The UDP checksum.
    pub udp_checksum: Signal<In, Bits<16>>,
    /// The datagram's kind.
    pub kind: Signal<In, Bits<8>>,
    /// The header field byte of this clock's index.
    pub field_byte: Signal<In, Bits<8>>,
    /// The body beat's byte.
    pub body_data: Signal<In, Bits<8>>,
    /// The destination MAC, read while no frame goes out.
    pub destination_mac: Signal<In, Bits<48>>,
    /// The destination IPv4 address, read like `destination_mac`.
    pub destination_ip: Signal<In, Bits<32>>,
    /// The destination UDP port, read like `destination_mac`.
    pub destination_port: Signal<In, Bits<16>>,
    /// The frame's byte at `index` (the FCS replaces what follows the body at the output).
    pub frame_byte: Signal<Out, Bits<8>>,
    /// The next index's byte is a body byte.
    pub next_is_body: Signal<Out, Bit>,
    /// The destination IPv4 address taken (from the take until index 8, the first shift).
    pub destination_ip_held: Signal<Out, Bits<32>>,
    /// The destination UDP port taken (like `destination_ip_held`).
    pub destination_port_held: Signal<Out, Bits<16>>,
    template: BlockRam<HEADER_ENTRY_BITS, 7>,
    template_idle: Constant<Bits<7>>,
    // the byte sources, one bit each (see `byte_source`)
    source_template: Constant<Bits<SOURCE_BITS>>,
    source_body: Constant<Bits<SOURCE_BITS>>,
    // where the byte at `index` comes from (`SOURCE_*`)
    byte_source: DFF<Bits<SOURCE_BITS>>,
    // the byte after the next is a header byte (from the table's sources), or a body byte
    header_ahead: DFF<Bit>,
    body_ahead: DFF<Bit>,
    // the steady sources and the destination of the next clock's byte, ORed a clock ahead
    header_early: DFF<Bits<8>>,
    // the destination's 12 bytes (MAC, IP, port), most significant first (cut in two: no
    // word over 64 bits to simulate)
    destination_high: DFF<Bits<64>>,
    destination_low: DFF<Bits<32>>,
    header_index: Signal<Local, Bits<7>>,
    // the index is 72 or more: the next index's following byte is in the body
    body_follows: Signal<Local, Bit>,
    // the sources `header_early` is chosen by, and the destination's next byte
    // the table's sources of the byte after the next, as read
    table_sources: DFF<Bits<SOURCE_BITS>>,
    // those sources under `header_ahead` (0 otherwise)
    early_sources: Signal<Local, Bits<SOURCE_BITS>>,
    early_byte: Signal<Local, Bits<8>>,
    destination_next_byte: Signal<Local, Bits<8>>,
    header_byte: Signal<Local, Bits<8>>,
}

impl TransmitSource {
    /// The byte selection of frames with this template (the constant bytes up to the body).
    pub fn new(template: &[u8]) -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            sending: Default::default(),
            frame_goes_on: Default::default(),
            raw: Default::default(),
            index: Default::default(),
            total_len: Default::default(),
            ip_checksum: Default::default(),
            udp_len: Default::default(),
            udp_checksum: Default::default(),
            kind: Default::default(),
            field_byte: Default::default(),
            body_data: Default::default(),
            destination_mac: Default::default(),
            destination_ip: Default::default(),
            destination_port: Default::default(),
            frame_byte: Default::default(),
            next_is_body: Default::default(),
            destination_ip_held: Default::default(),
            destination_port_held: Default::default(),
            template: BlockRam::with_contents(&header_table(template)),
            template_idle: constant(TEMPLATE_IDLE as u64),
            source_template: Constant::new(SOURCE_TEMPLATE.into()),
            source_body: Constant::new(SOURCE_BODY.into()),
            byte_source: Default::default(),
            header_ahead: Default::default(),
            body_ahead: Default::default(),
            header_early: Default::default(),
            destination_high: Default::default(),
            destination_low: Default::default(),
            header_index: Default::default(),
            body_follows: Default::default(),
            table_sources: Default::default(),
            early_sources: Default::default(),
            early_byte: Default::default(),
            destination_next_byte: Default::default(),
            header_byte: Default::default(),
        }
    }
}

impl Logic for TransmitSource {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            byte_source,
            header_ahead,
            table_sources,
            body_ahead,
            header_early,
            destination_high,
            destination_low
        );
        self.template.clock.next = self.clock.val();
        self.template.write_enable.next = false;
        self.template.write_address.next = 0.into();
        self.template.write_data.next = 0.into();
        // (past the header only the body follows: the header's tests need the index's low
        // seven bits only)
        self.header_index.next = self.index.val().get_bits::<7>(0);
        self.template.read_address.next = self.template_idle.val();
        if self.sending.val() {
            self.template.read_address.next = self.header_index.val();
        }
        // index >= 72, from its bits: 72 is 0b100_1000; for a raw frame index >= 6
        self.body_follows.next = (self.index.val().get_bits::<4>(7) != 0)
            | (self.header_index.val().get_bit(6)
                & (self.header_index.val().get_bits::<3>(3) != 0));
        if self.raw.val() {
            self.body_follows.next = (self.index.val().get_bits::<8>(3) != 0)
                | (self.index.val().get_bit(2) & self.index.val().get_bit(1));
        }
        // The byte's source: the table's sources of byte `index + 3` (read at `index - 1`
        // for the next index, `index + 1` while the frame goes on: when it does not, the
        // flags below choose the template alone) under the flags of this index's byte after
        // the next.
        self.header_ahead.d.next = self.frame_goes_on.val() & !self.body_follows.val();
        self.body_ahead.d.next = self.frame_goes_on.val() & self.body_follows.val();
        self.byte_source.d.next = self.source_template.val();
        if self.body_ahead.q.val() {
            self.byte_source.d.next = self.source_body.val();
        } else if self.header_ahead.q.val() {
            self.byte_source.d.next = self.source_template.val() | self.table_sources.q.val();
        }
        // the steady sources and the destination byte that is on top after this clock's
        // shift, ORed a clock ahead from the table's sources of the next byte (read only
        // under `header_ahead`, so while sending: the shift's `sending` is left out, and
        // with it the phase's decode from this path)
        self.destination_next_byte.next = self.destination_high.q.val().get_bits::<8>(56);
        if self.byte_source.q.val().get_bit(12) {
            self.destination_next_byte.next = self.destination_high.q.val().get_bits::<8>(48);
        }
        self.table_sources.d.next = self.template.read_data.val().get_bits::<SOURCE_BITS>(8);
        self.early_sources.next = 0.into();
        if self.header_ahead.q.val() {
            self.early_sources.next = self.table_sources.q.val();
        }
        self.early_byte.next = 0.into();
        if self.early_sources.val().get_bit(1) {
            self.early_byte.next = self.total_len.val().get_bits::<8>(8);
        }
        if self.early_sources.val().get_bit(2) {
            self.early_byte.next = self.early_byte.val() | self.total_len.val().get_bits::<8>(0);
        }
        if self.early_sources.val().get_bit(3) {
            self.early_byte.next = self.early_byte.val() | self.ip_checksum.val().get_bits::<8>(8);
        }
        if self.early_sources.val().get_bit(4) {
            self.early_byte.next = self.early_byte.val() | self.ip_checksum.val().get_bits::<8>(0);
        }
        if self.early_sources.val().get_bit(5) {
            self.early_byte.next = self.early_byte.val() | self.udp_len.val().get_bits::<8>(8);
        }
        if self.early_sources.val().get_bit(6) {
            self.early_byte.next = self.early_byte.val() | self.udp_len.val().get_bits::<8>(0);
        }
        if self.early_sources.val().get_bit(7) {
            self.early_byte.next = self.early_byte.val() | self.udp_checksum.val().get_bits::<8>(8);
        }
        if self.early_sources.val().get_bit(8) {
            self.early_byte.next = self.early_byte.val() | self.udp_checksum.val().get_bits::<8>(0);
        }
        if self.early_sources.val().get_bit(9) {
            self.early_byte.next = self.early_byte.val() | self.kind.val();
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
            self.header_byte.next = self.header_byte.val() | self.field_byte.val();
        }
        self.frame_byte.next = self.header_byte.val();
        if self.byte_source.q.val().get_bit(11) {
            self.frame_byte.next = self.body_data.val();
        }
        // the destination is loaded while no frame goes out; a destination byte leaves: the
        // next one moves up
        if !self.sending.val() {
            self.destination_high.d.next = (bit_cast::<64, 48>(self.destination_mac.val()) << 16)
                | bit_cast::<64, 16>(self.destination_ip.val().get_bits::<16>(16));
            self.destination_low.d.next =
                (bit_cast::<32, 16>(self.destination_ip.val().get_bits::<16>(0)) << 16)
                    | bit_cast::<32, 16>(self.destination_port.val());
        }
        if self.sending.val() & self.byte_source.q.val().get_bit(12) {
            self.destination_high.d.next = (self.destination_high.q.val() << 8)
                | bit_cast::<64, 8>(self.destination_low.q.val().get_bits::<8>(24));
            self.destination_low.d.next = self.destination_low.q.val() << 8;
        }
        self.destination_ip_held.next =
            (bit_cast::<32, 16>(self.destination_high.q.val().get_bits::<16>(0)) << 16)
                | bit_cast::<32, 16>(self.destination_low.q.val().get_bits::<16>(16));
        self.destination_port_held.next = self.destination_low.q.val().get_bits::<16>(0);
        if self.reset.val() {
            self.header_ahead.d.next = false;
            self.body_ahead.d.next = false;
        }
        self.next_is_body.next = self.body_ahead.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use crate::transmit_layout::{template, BODY_START};
    use skinbox_protocol::link::LinkConfig;

    /// Frames with random header values, destinations and body bytes, indexed as the
    /// transmitter does (two clocks with no frame, then 0, 1, ...): each byte is the
    /// template's with the values at their places, the destination at its three places,
    /// the field bytes at theirs, then the body.
    #[test]
    fn each_byte_comes_from_its_source() {
        let t = template(&LinkConfig::DEFAULT, 7, 8);
        let mut rng = TestRng::new(0x50C);
        let mut bench = Bench::new(TransmitSource::new(&t), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for round in 0..20 {
            let values: Vec<u64> = (0..4).map(|_| rng.next_u64() & 0xFFFF).collect();
            let kind = rng.byte();
            let destination: Vec<u8> = (0..12).map(|_| rng.byte()).collect();
            let mut want = t.clone();
            let words = [IP_TOTAL_LEN_AT, IP_CHECKSUM_AT, UDP_LEN_AT, UDP_CHECKSUM_AT];
            for (at, value) in words.iter().zip(&values) {
                want[*at..*at + 2].copy_from_slice(&(*value as u16).to_be_bytes());
            }
            want[KIND_AT] = kind;
            want[DESTINATION_MAC_AT..DESTINATION_MAC_AT + 6].copy_from_slice(&destination[..6]);
            want[DESTINATION_IP_AT..DESTINATION_IP_AT + 4].copy_from_slice(&destination[6..10]);
            want[DESTINATION_PORT_AT..DESTINATION_PORT_AT + 2].copy_from_slice(&destination[10..]);
            let u = &mut bench.uut;
            u.sending.next = false;
            u.frame_goes_on.next = false;
            u.index.next = 0.into();
            u.destination_mac.next = big_endian(&destination[..6]).into();
            u.destination_ip.next = big_endian(&destination[6..10]).into();
            u.destination_port.next = big_endian(&destination[10..]).into();
            // (the transmitter's gap: the table is read at its idle address for two clocks)
            bench.cycles(2);
            let u = &mut bench.uut;
            u.destination_mac.next = 0.into();
            u.destination_ip.next = 0.into();
            u.destination_port.next = 0.into();
            u.total_len.next = values[0].into();
            u.ip_checksum.next = values[1].into();
            u.udp_len.next = values[2].into();
            u.udp_checksum.next = values[3].into();
            u.kind.next = u64::from(kind).into();
            let len = BODY_START + 20;
            let mut sent = Vec::new();
            for i in 0..len {
                let field = rng.byte();
                let body = rng.byte();
                if (FIELDS_AT..FIELDS_AT + FIELDS_LEN).contains(&i) {
                    want[i] = field;
                }
                if i >= BODY_START {
                    want.push(body);
                }
                let u = &mut bench.uut;
                u.sending.next = true;
                u.frame_goes_on.next = i + 1 != len;
                u.index.next = (i as u64).into();
                u.field_byte.next = u64::from(field).into();
                u.body_data.next = u64::from(body).into();
                bench.settle();
                sent.push(bench.uut.frame_byte.val().to_u64() as u8);
                if i < DESTINATION_MAC_AT {
                    // the address and port for the header sums, before the first shift
                    let u = &bench.uut;
                    let ip = big_endian(&destination[6..10]);
                    assert_eq!(u.destination_ip_held.val().to_u64(), ip);
                    let port = big_endian(&destination[10..]);
                    assert_eq!(u.destination_port_held.val().to_u64(), port);
                }
                // the body's beats are taken from its first byte on
                assert_eq!(
                    bench.uut.next_is_body.val(),
                    (BODY_START - 1..len).contains(&i),
                    "round {round} index {i}"
                );
                bench.cycle();
            }
            assert_eq!(sent, want, "round {round}");
        }
    }
}
