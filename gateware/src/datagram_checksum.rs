//! DatagramChecksum: the frame transmitter's UDP checksum, the UDP layer's transmit half.
//!
//! One ones'-complement summer ([`OnesComplementSum`]) adds the complement of one 16-bit
//! term a clock: the sum of complements is the checksum itself (ones'-complement negation
//! is the complement), and since its end-around carry never yields 0x0000 from terms that
//! are not all zero, a checksum computed as 0 comes out as 0xFFFF, as RFC 768 sends it.
//! While no frame goes out (`restart`) the sum restarts from the complement of the
//! constant words (addresses, protocol, ports, the header's magic and box id: a build
//! parameter). While the header goes out the term register takes a term a clock,
//! complemented, or 0 (which only folds the carry in), and the summer adds it the clock
//! after: the 16 field bytes (`term_from_fields`, `high_byte`: the byte is its word's high
//! byte), then from `tail_start` on seven terms from steady inputs, one a clock: the kind,
//! the UDP length twice (header and pseudo header), the body sum's 16 bits and its carry,
//! the destination's sum's low 16 bits and its carries. The checksum
//! ([`DatagramChecksum::udp_checksum`], the summer's register) is final [`FOLD_CLOCKS`]
//! clock after the last term was added: the zero term after it folds the last carry in.
//! Cost: 17 bits of sum, 16 of term, 3 of tail step.

use crate::hdl::*;
use crate::ones_complement_sum::OnesComplementSum;
use crate::stream::BODY_SUM_BITS;
use skinbox_protocol::wire::checksum::fold;

/// Clocks from the last term's addition to the final checksum: the fold of its carry.
pub const FOLD_CLOCKS: u64 = 1;

/// Terms added from `tail_start` on, one a clock.
pub const TAIL_TERMS: u64 = 7;

/// The UDP checksum of a datagram frame.
#[derive(LogicBlock)]
pub struct DatagramChecksum {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// No frame goes out: the sum restarts from the constant words.
    pub restart: Signal<In, Bit>,
    /// The term is a field byte.
    pub term_from_fields: Signal<In, Bit>,
    /// The field byte is its word's high byte.
    pub high_byte: Signal<In, Bit>,
    /// The field byte.
    pub field_byte: Signal<In, Bits<8>>,
    /// The term is the kind; the other steady terms follow, one a clock.
    pub tail_start: Signal<In, Bit>,
    /// The datagram's kind (steady from `tail_start` for [`TAIL_TERMS`] clocks).
    pub kind: Signal<In, Bits<8>>,
    /// The UDP length (steady like `kind`).
    pub udp_len: Signal<In, Bits<16>>,
    /// The body's sum ([`BODY_SUM_BITS`], steady like `kind`).
    pub body_sum: Signal<In, Bits<BODY_SUM_BITS>>,
    /// The sum of the destination's IPv4 address and port words (steady like `kind`).
    pub destination_sum: Signal<In, Bits<18>>,
    /// The checksum.
    pub udp_checksum: Signal<Out, Bits<16>>,
    summer: OnesComplementSum,
    // the complement of the constant words' folded sum
    start: Constant<Bits<16>>,
    term: DFF<Bits<16>>,
    // the steady term after the kind: 2..=7, 0 when none
    tail_step: DFF<Bits<3>>,
    word: Signal<Local, Bits<16>>,
    any_term: Signal<Local, Bit>,
}

impl DatagramChecksum {
    /// The checksum of datagrams whose constant words sum to `constant_sum` (not folded).
    pub fn new(constant_sum: u64) -> Self {
        Self {
            clock: Default::default(),
            restart: Default::default(),
            term_from_fields: Default::default(),
            high_byte: Default::default(),
            field_byte: Default::default(),
            tail_start: Default::default(),
            kind: Default::default(),
            udp_len: Default::default(),
            body_sum: Default::default(),
            destination_sum: Default::default(),
            udp_checksum: Default::default(),
            summer: Default::default(),
            start: constant(u64::from(!fold(constant_sum))),
            term: Default::default(),
            tail_step: Default::default(),
            word: Default::default(),
            any_term: Default::default(),
        }
    }
}

impl Logic for DatagramChecksum {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, term, tail_step);
        self.word.next = 0.into();
        // (every tail step is a term)
        self.any_term.next =
            self.term_from_fields.val() | self.tail_start.val() | (self.tail_step.q.val() != 0);
        if self.term_from_fields.val() {
            if self.high_byte.val() {
                self.word.next = bit_cast::<16, 8>(self.field_byte.val()) << 8;
            } else {
                self.word.next = bit_cast::<16, 8>(self.field_byte.val());
            }
        }
        if self.tail_start.val() {
            self.word.next = self.word.val() | bit_cast::<16, 8>(self.kind.val());
        }
        if (self.tail_step.q.val() == 2) | (self.tail_step.q.val() == 3) {
            self.word.next = self.word.val() | self.udp_len.val();
        }
        if self.tail_step.q.val() == 4 {
            self.word.next = self.word.val() | self.body_sum.val().get_bits::<16>(0);
        }
        if self.tail_step.q.val() == 5 {
            self.word.next =
                self.word.val() | bit_cast::<16, 1>(self.body_sum.val().get_bit(16).into());
        }
        if self.tail_step.q.val() == 6 {
            self.word.next = self.word.val() | self.destination_sum.val().get_bits::<16>(0);
        }
        if self.tail_step.q.val() == 7 {
            self.word.next =
                self.word.val() | bit_cast::<16, 2>(self.destination_sum.val().get_bits::<2>(16));
        }
        // a term goes in complemented; no term is 0, which folds the carry in
        self.term.d.next = 0.into();
        if self.any_term.val() {
            self.term.d.next = !self.word.val();
        }
        self.tail_step.d.next = 0.into();
        if self.tail_step.q.val() != 0 {
            self.tail_step.d.next = self.tail_step.q.val() + 1;
        }
        if self.tail_start.val() {
            self.tail_step.d.next = 2.into();
        }
        if self.restart.val() {
            self.tail_step.d.next = 0.into();
            self.term.d.next = 0.into();
        }
        self.summer.clock.next = self.clock.val();
        self.summer.add.next = true;
        self.summer.word.next = self.term.q.val();
        self.summer.restart.next = self.restart.val();
        self.summer.start.next = self.start.val();
        self.udp_checksum.next = self.summer.sum.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame_transmitter::word_sum;
    use crate::testbench::{body_sum_of, Bench, TestRng};
    use skinbox_protocol::wire::checksum::checksum;

    /// Random constant words, bodies, lengths, fields and destinations, with idle clocks
    /// between the field bytes and the tail: the checksum is the protocol's over the same
    /// words (0 sent as 0xFFFF), and a second frame's sum starts afresh.
    #[test]
    fn the_checksum_is_the_protocols_over_the_constant_words_and_the_terms() {
        let mut rng = TestRng::new(0xDC);
        let mut zero = 0;
        for round in 0..300 {
            let constant: Vec<u8> = (0..2 * (1 + rng.next_u64() % 12))
                .map(|_| rng.byte())
                .collect();
            let mut bench =
                Bench::new(DatagramChecksum::new(word_sum(&constant)), |b| &mut b.clock);
            for frame in 0..2 {
                let body: Vec<u8> = (0..2 * (rng.next_u64() % 700))
                    .map(|_| rng.byte())
                    .collect();
                let kind = rng.byte();
                let udp_len = rng.next_u64() as u16;
                let fields: Vec<u8> = (0..16).map(|_| rng.byte()).collect();
                let mut destination: Vec<u8> = (0..6).map(|_| rng.byte()).collect();
                if round % 20 == 0 && frame == 1 {
                    // make the whole sum 0xFFFF: a computed checksum of 0
                    let rest = checksum(&[
                        &constant,
                        &body,
                        &[0, kind],
                        &udp_len.to_be_bytes(),
                        &udp_len.to_be_bytes(),
                        &fields,
                    ]);
                    destination = [rest.to_be_bytes(), [0, 0], [0, 0]].concat();
                }
                let destination_sum = word_sum(&destination);
                let u = &mut bench.uut;
                u.restart.next = true;
                u.term_from_fields.next = false;
                u.tail_start.next = false;
                bench.cycles(1 + rng.next_u64() % 3);
                bench.uut.restart.next = false;
                for (i, &byte) in fields.iter().enumerate() {
                    while rng.chance(0.2) {
                        bench.uut.term_from_fields.next = false;
                        bench.uut.field_byte.next = u64::from(rng.byte()).into();
                        bench.cycle();
                    }
                    let u = &mut bench.uut;
                    u.term_from_fields.next = true;
                    u.high_byte.next = i % 2 == 0;
                    u.field_byte.next = u64::from(byte).into();
                    bench.cycle();
                }
                let u = &mut bench.uut;
                u.term_from_fields.next = false;
                u.tail_start.next = true;
                u.kind.next = u64::from(kind).into();
                u.udp_len.next = u64::from(udp_len).into();
                u.body_sum.next = body_sum_of(&body).into();
                u.destination_sum.next = destination_sum.into();
                bench.cycle();
                bench.uut.tail_start.next = false;
                // the last term is registered TAIL_TERMS - 1 clocks later and added a
                // clock after that
                bench.cycles(TAIL_TERMS - 1 + 1 + FOLD_CLOCKS);
                let mut want = checksum(&[
                    &constant,
                    &body,
                    &[0, kind],
                    &udp_len.to_be_bytes(),
                    &udp_len.to_be_bytes(),
                    &fields,
                    &destination,
                ]);
                if want == 0 {
                    want = 0xFFFF;
                    zero += 1;
                }
                assert_eq!(
                    bench.uut.udp_checksum.val().to_u64() as u16,
                    want,
                    "round {round} frame {frame}"
                );
            }
        }
        assert!(zero > 0, "a computed 0 came up");
    }
}
