//! OnesComplementSum: the Internet checksum's running sum (RFC 1071), one 16-bit word a
//! clock, with an end-around carry.
//!
//! The sum is kept as 16 bits and a carry that is added with the next word (one adder, no
//! fold between words). `restart` starts it again from `start` (over an `add` in the same
//! clock). The outputs are the registers and two tests on them: `verifies` (the sum with
//! its carry folded in is 0xFFFF: a header or message whose checksum field was summed with
//! it is right) and `folded` (the sum with its carry folded in, 16 bits).

use crate::hdl::*;

/// A running ones'-complement sum of 16-bit words.
#[derive(LogicBlock, Default)]
pub struct OnesComplementSum {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Add `word` at this clock's edge.
    pub add: Signal<In, Bit>,
    /// The word to add.
    pub word: Signal<In, Bits<16>>,
    /// Start again from `start` at this clock's edge (over `add`).
    pub restart: Signal<In, Bit>,
    /// The sum a restart starts from.
    pub start: Signal<In, Bits<16>>,
    /// The sum, its last carry not yet added.
    pub sum: Signal<Out, Bits<16>>,
    /// The last addition's carry.
    pub carry: Signal<Out, Bit>,
    /// The sum with its carry folded in is 0xFFFF.
    pub verifies: Signal<Out, Bit>,
    /// The sum with its carry folded in.
    pub folded: Signal<Out, Bits<16>>,
    total: DFF<Bits<16>>,
    end_carry: DFF<Bit>,
    next: Signal<Local, Bits<17>>,
}

impl Logic for OnesComplementSum {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, total, end_carry);
        self.next.next = bit_cast::<17, 16>(self.total.q.val())
            + bit_cast::<17, 16>(self.word.val())
            + bit_cast::<17, 1>(self.end_carry.q.val().into());
        if self.add.val() {
            self.total.d.next = self.next.val().get_bits::<16>(0);
            self.end_carry.d.next = self.next.val().get_bit(16);
        }
        if self.restart.val() {
            self.total.d.next = self.start.val();
            self.end_carry.d.next = false;
        }
        self.sum.next = self.total.q.val();
        self.carry.next = self.end_carry.q.val();
        // (0xFFFE with a carry folds to 0xFFFF; 0xFFFF with a carry cannot occur)
        self.verifies.next = ((self.total.q.val() == 0xFFFF) & !self.end_carry.q.val())
            | ((self.total.q.val() == 0xFFFE) & self.end_carry.q.val());
        self.folded.next = self.total.q.val() + bit_cast::<16, 1>(self.end_carry.q.val().into());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::wire::checksum;

    /// Random byte strings summed a word a clock with random idle clocks between the words:
    /// `folded` is the protocol's ones'-complement sum of the bytes (the wire layer's, an
    /// independent fold of a 32-bit sum), and `verifies` holds exactly when the bytes with
    /// their checksum put in (the complement of that sum) are summed.
    #[test]
    fn sums_equal_the_wire_layers_and_a_right_checksum_verifies() {
        let mut rng = TestRng::new(3);
        let mut bench = Bench::new(OnesComplementSum::default(), |b| &mut b.clock);
        for case in 0..300 {
            let len = 2 * (1 + rng.next_u64() as usize % 40);
            let mut bytes: Vec<u8> = (0..len).map(|_| rng.next_u64() as u8).collect();
            if case % 5 == 0 {
                // sums that wrap often: mostly 0xFF bytes
                bytes.iter_mut().for_each(|b| *b |= 0xFE);
            }
            let with_checksum = case % 2 == 1;
            if with_checksum {
                bytes.extend([0, 0]);
                let c = checksum::checksum(&[&bytes]);
                let n = bytes.len();
                bytes[n - 2..].copy_from_slice(&c.to_be_bytes());
            }
            let start = if case % 3 == 0 {
                rng.next_u64() as u16
            } else {
                0
            };
            let u = &mut bench.uut;
            u.restart.next = true;
            u.start.next = u64::from(start).into();
            u.add.next = true; // the restart wins
            u.word.next = 0xFFFF.into();
            bench.cycle();
            bench.uut.restart.next = false;
            for w in bytes.chunks(2) {
                while rng.chance(0.3) {
                    bench.uut.add.next = false;
                    bench.cycle();
                }
                bench.uut.add.next = true;
                bench.uut.word.next = u64::from(u16::from_be_bytes([w[0], w[1]])).into();
                bench.cycle();
            }
            bench.uut.add.next = false;
            bench.settle();
            let mut with_start = start.to_be_bytes().to_vec();
            with_start.extend(&bytes);
            // the sum is the complement of the checksum over the same words
            let expected = !checksum::checksum(&[&with_start]);
            let u = &bench.uut;
            assert_eq!(u.folded.val().to_u64() as u16, expected, "case {case}");
            assert_eq!(u.verifies.val(), expected == 0xFFFF, "case {case}");
            if with_checksum && start == 0 {
                assert!(u.verifies.val(), "case {case}: a right checksum verifies");
            }
        }
    }
}
