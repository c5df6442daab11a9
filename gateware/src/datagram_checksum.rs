//! DatagramChecksum: the frame transmitter's UDP checksum, the UDP layer's transmit half.
//!
//! The sum starts, while no frame goes out (`load`), from the body's sum alone (the
//! descriptor's `body_sum`: no adder after the descriptor). While the header goes out it
//! adds one term a clock (`add`, the term registered a clock before): the kind, then the
//! UDP length's term (the length counted twice, header and pseudo header, with the sum of
//! the constant words), then the 16 field bytes one a clock (`high_byte`: the byte is its
//! word's high byte), then the destination's sum. The selects are registers and exclusive,
//! so the terms are ORed. The sum's carries are folded twice, a register each, and the
//! complement is held in a register ([`DatagramChecksum::udp_checksum`]), final
//! [`FOLD_CLOCKS`] clocks after the last term was added. A checksum computed as 0 is sent
//! as 0xFFFF (RFC 768).

use crate::hdl::*;

/// Clocks from the last term's addition to the held checksum: two folds and the register.
pub const FOLD_CLOCKS: u64 = 3;

/// The UDP checksum of a datagram frame.
#[derive(LogicBlock, Default)]
pub struct DatagramChecksum {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// No frame goes out: the sum is the body's.
    pub load: Signal<In, Bit>,
    /// The body's sum (the descriptor's).
    pub body_sum: Signal<In, Bits<32>>,
    /// Add the term registered in the last clock.
    pub add: Signal<In, Bit>,
    /// The term is the kind.
    pub term_is_kind: Signal<In, Bit>,
    /// The term is the UDP length's.
    pub term_is_udp_len: Signal<In, Bit>,
    /// The term is the destination's sum.
    pub term_is_destination: Signal<In, Bit>,
    /// The term is a field byte.
    pub term_from_fields: Signal<In, Bit>,
    /// The field byte is its word's high byte.
    pub high_byte: Signal<In, Bit>,
    /// The datagram's kind.
    pub kind: Signal<In, Bits<8>>,
    /// The UDP length's term.
    pub udp_term: Signal<In, Bits<32>>,
    /// The sum of the destination's IPv4 address and port words.
    pub destination_sum: Signal<In, Bits<18>>,
    /// The field byte.
    pub field_byte: Signal<In, Bits<8>>,
    /// The checksum, held.
    pub udp_checksum: Signal<Out, Bits<16>>,
    sum: DFF<Bits<32>>,
    term: DFF<Bits<32>>,
    // the sum's carries folded in, twice, a clock each
    fold: DFF<Bits<17>>,
    folded: DFF<Bits<16>>,
    held: DFF<Bits<16>>,
    word: Signal<Local, Bits<32>>,
    complement: Signal<Local, Bits<16>>,
}

impl Logic for DatagramChecksum {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, sum, term, fold, folded, held);
        self.word.next = 0.into();
        if self.term_is_kind.val() {
            self.word.next = bit_cast::<32, 8>(self.kind.val());
        }
        if self.term_is_udp_len.val() {
            self.word.next = self.word.val() | self.udp_term.val();
        }
        if self.term_is_destination.val() {
            self.word.next = self.word.val() | bit_cast::<32, 18>(self.destination_sum.val());
        }
        if self.term_from_fields.val() {
            if self.high_byte.val() {
                self.word.next = self.word.val() | (bit_cast::<32, 8>(self.field_byte.val()) << 8);
            } else {
                self.word.next = self.word.val() | bit_cast::<32, 8>(self.field_byte.val());
            }
        }
        self.term.d.next = self.word.val();
        if self.add.val() {
            self.sum.d.next = self.sum.q.val() + self.term.q.val();
        }
        if self.load.val() {
            self.sum.d.next = self.body_sum.val();
        }
        self.fold.d.next = bit_cast::<17, 16>(self.sum.q.val().get_bits::<16>(0))
            + bit_cast::<17, 16>(self.sum.q.val().get_bits::<16>(16));
        // (at most 0x1FFFE: adding its carry bit cannot carry again)
        self.folded.d.next = self.fold.q.val().get_bits::<16>(0)
            + bit_cast::<16, 1>(self.fold.q.val().get_bits::<1>(16));
        self.complement.next = !self.folded.q.val();
        if self.folded.q.val() == 0xFFFF {
            // a computed 0 is sent as 0xFFFF (RFC 768)
            self.complement.next = 0xFFFF.into();
        }
        self.held.d.next = self.complement.val();
        self.udp_checksum.next = self.held.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::wire::checksum::checksum;

    /// Random bodies and header terms against the protocol's checksum over the same bytes.
    #[test]
    fn the_checksum_is_the_protocols_over_the_body_and_the_terms() {
        let mut bench = Bench::new(DatagramChecksum::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0xDC);
        let mut zero = 0;
        for round in 0..300 {
            let body: Vec<u8> = (0..2 * (rng.next_u64() % 700))
                .map(|_| rng.byte())
                .collect();
            let kind = rng.byte();
            let udp_term = rng.next_u64() as u16;
            let fields: Vec<u8> = (0..16).map(|_| rng.byte()).collect();
            let mut destination = rng.next_u64() as u16;
            let body_sum: u64 = body
                .chunks(2)
                .map(|w| u64::from(u16::from_be_bytes([w[0], w[1]])))
                .sum();
            if round % 40 == 0 {
                // make the whole sum 0xFFFF: a computed checksum of 0
                let rest = checksum(&[&body, &[0, kind], &udp_term.to_be_bytes(), &fields]);
                destination = rest;
            }
            let u = &mut bench.uut;
            u.load.next = true;
            u.body_sum.next = body_sum.into();
            u.kind.next = u64::from(kind).into();
            u.udp_term.next = u64::from(udp_term).into();
            u.destination_sum.next = u64::from(destination).into();
            bench.cycle();
            bench.uut.load.next = false;
            // the terms, each registered a clock before it is added
            let terms = 3 + fields.len();
            for t in 0..=terms {
                let u = &mut bench.uut;
                u.add.next = t > 0;
                u.term_is_kind.next = t == 0;
                u.term_is_udp_len.next = t == 1;
                u.term_from_fields.next = (2..2 + fields.len()).contains(&t);
                u.term_is_destination.next = t == 2 + fields.len();
                let field = t.saturating_sub(2).min(fields.len() - 1);
                u.high_byte.next = field % 2 == 0;
                u.field_byte.next = u64::from(fields[field]).into();
                bench.cycle();
            }
            bench.uut.add.next = false;
            bench.uut.term_is_destination.next = false;
            bench.cycles(FOLD_CLOCKS);
            let mut want = checksum(&[
                &body,
                &[0, kind],
                &udp_term.to_be_bytes(),
                &fields,
                &destination.to_be_bytes(),
            ]);
            if want == 0 {
                want = 0xFFFF;
                zero += 1;
            }
            assert_eq!(
                bench.uut.udp_checksum.val().to_u64() as u16,
                want,
                "round {round}"
            );
        }
        assert!(zero > 0, "a computed 0 came up");
    }
}
