//! StatusPageWriter: writes the status reporter's page into its memory, a word in
//! [`CLOCKS_PER_WORD`] clocks, and sums the body while it writes.
//!
//! A word's clocks (`phase` 0 to 6): the word's address (the reporter's), the counter
//! memory's read, its register, the word's `value` into the shift register (phase 2), then
//! its four bytes, most significant first, each written a clock later at the next offset
//! of the page (phases 3 to 6). `word_done` is the word's last clock. The sum is the body's
//! 16-bit big-endian words' ones'-complement running sum ([`BODY_SUM_BITS`]; a byte at an
//! even offset is a word's high byte). `start` (a page starts) begins at phase 0, offset 0,
//! sum 0. Cost: 32 + 11 + 17 + 3 + 1 flip-flops, an 11-bit and a 17-bit adder.

use crate::hdl::*;
use crate::stream::BODY_SUM_BITS;

/// Clocks per 32-bit word of the status body: the address, the memory read, its register,
/// the word into the shift register, four bytes out.
pub const CLOCKS_PER_WORD: u64 = 7;

/// The status page's write side.
#[derive(LogicBlock, Default)]
pub struct StatusPageWriter {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing written.
    pub reset: Signal<In, Bit>,
    /// A page starts: phase, offset and sum 0.
    pub start: Signal<In, Bit>,
    /// The page is being written: the phase steps.
    pub build: Signal<In, Bit>,
    /// The word's value (taken in its phase 2).
    pub value: Signal<In, Bits<32>>,
    /// The word's last clock (phase 6 while writing).
    pub word_done: Signal<Out, Bit>,
    /// The memory's write enable.
    pub memory_write: Signal<Out, Bit>,
    /// Address of that write: the offset in the page.
    pub memory_address: Signal<Out, Bits<11>>,
    /// The byte of that write.
    pub memory_data: Signal<Out, Bits<8>>,
    /// Bytes written into the page.
    pub length: Signal<Out, Bits<11>>,
    /// The sum of the page's 16-bit words.
    pub body_sum: Signal<Out, Bits<BODY_SUM_BITS>>,
    phase: DFF<Bits<3>>,
    shift: DFF<Bits<32>>,
    // a byte of the page is written (phases 3 to 6), registered a clock ahead
    write: DFF<Bit>,
    offset: DFF<Bits<11>>,
    sum: DFF<Bits<BODY_SUM_BITS>>,
    tx_byte: Signal<Local, Bits<8>>,
    word: Signal<Local, Bits<16>>,
}

impl Logic for StatusPageWriter {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, phase, shift, write, offset, sum);
        // (while writing the phase steps from 2..=5 to 3..=6)
        self.write.d.next =
            self.build.val() & (self.phase.q.val().get_bit(2) != self.phase.q.val().get_bit(1));
        if self.start.val() {
            self.phase.d.next = 0.into();
            self.offset.d.next = 0.into();
            self.sum.d.next = 0.into();
        }
        if self.build.val() {
            self.phase.d.next = self.phase.q.val() + 1;
            if self.phase.q.val() == 2 {
                self.shift.d.next = self.value.val();
            } else if self.phase.q.val() >= 3 {
                self.shift.d.next = self.shift.q.val() << 8;
            }
            if self.phase.q.val() == 6 {
                self.phase.d.next = 0.into();
            }
        }
        self.word_done.next = self.build.val() & (self.phase.q.val() == 6);
        self.tx_byte.next = self.shift.q.val().get_bits::<8>(24);
        self.word.next = bit_cast::<16, 8>(self.tx_byte.val()) << 8;
        if self.offset.q.val().get_bit(0) {
            self.word.next = bit_cast::<16, 8>(self.tx_byte.val());
        }
        self.memory_write.next = self.write.q.val();
        self.memory_address.next = self.offset.q.val();
        self.memory_data.next = self.tx_byte.val();
        if self.write.q.val() {
            self.offset.d.next = self.offset.q.val() + 1;
            // the byte at its place in its word, added with the last carry (end-around)
            self.sum.d.next = bit_cast::<17, 16>(self.sum.q.val().get_bits::<16>(0))
                + bit_cast::<17, 16>(self.word.val())
                + bit_cast::<17, 1>(self.sum.q.val().get_bit(16).into());
        }
        self.length.next = self.offset.q.val();
        self.body_sum.next = self.sum.q.val();
        if self.reset.val() {
            self.write.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{is_body_sum_of, Bench, TestRng};

    /// Pages of random words, built with pauses between them: each word's bytes are written
    /// at the next offsets, most significant first, in the word's phases 3 to 6 (a clock
    /// late), the word done at its seventh clock, and the sum is that of the 16-bit words.
    #[test]
    fn words_become_bytes_at_the_next_offsets_and_their_sum() {
        let mut bench = Bench::new(StatusPageWriter::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0x9A6E);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for words in [1usize, 3, 20] {
            let values: Vec<u32> = (0..words).map(|_| rng.next_u64() as u32).collect();
            bench.uut.start.next = true;
            bench.cycle();
            bench.uut.start.next = false;
            let mut written = vec![];
            let mut done_at = vec![];
            for clock in 0..7 * words as u64 + 1 {
                let u = &mut bench.uut;
                let building = clock < 7 * words as u64;
                u.build.next = building;
                // the value is the word's from its third clock on, garbage before
                let word = (clock / 7) as usize;
                u.value.next = if clock % 7 >= 2 && building {
                    u64::from(values[word]).into()
                } else {
                    (rng.next_u64() & 0xFFFF_FFFF).into()
                };
                bench.settle();
                let u = &bench.uut;
                if u.word_done.val() {
                    done_at.push(clock);
                }
                if u.memory_write.val() {
                    assert_eq!(u.memory_address.val().index(), written.len());
                    assert_eq!(clock % 7, 3 + written.len() as u64 % 4);
                    written.push(u.memory_data.val().to_u8());
                }
                bench.cycle();
            }
            let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_be_bytes()).collect();
            assert_eq!(written, bytes);
            assert_eq!(
                done_at,
                (0..words as u64).map(|w| 7 * w + 6).collect::<Vec<_>>()
            );
            let u = &bench.uut;
            assert_eq!(u.length.val().index(), bytes.len());
            assert!(is_body_sum_of(u.body_sum.val().to_u64(), &bytes));
            bench.cycles(3);
        }
    }
}
