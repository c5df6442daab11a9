//! PayloadWriter: the record batcher's write side: each byte the batcher decides to write
//! goes into its payload buffer a clock later, at the next offset of the filling datagram,
//! and the body's sum grows with it.
//!
//! The write port is registered (a clock after the decision, off the batcher's accept
//! path): the buffer is read only after its datagram closed, many clocks after its last
//! byte was written. The sum is the body's 16-bit big-endian words' ones'-complement
//! running sum ([`BODY_SUM_BITS`]: each byte added at its place in its word with the last
//! carry, end-around): a byte at an even offset is a word's high byte. `body_sum_next`
//! includes the byte on its way to the buffer, so a datagram that closes now carries it.
//! `clear` (the datagram closes) starts the offset and the sum again. Cost: 17 + 11 + 29 flip-flops, one 17-bit adder.

use crate::hdl::*;
use crate::stream::BODY_SUM_BITS;

/// Bits of a payload buffer's byte address (2 KB buffers).
pub const OFFSET_BITS: usize = 11;

/// The batcher's payload write port and body sum.
#[derive(LogicBlock, Default)]
pub struct PayloadWriter {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing written, offset and sum 0.
    pub reset: Signal<In, Bit>,
    /// Write `write_data` at the next offset (taken this clock, written the next).
    pub write: Signal<In, Bit>,
    /// The byte.
    pub write_data: Signal<In, Bits<8>>,
    /// The filling buffer (the address's top bit).
    pub buffer: Signal<In, Bit>,
    /// The filling datagram closes: offset and sum start again.
    pub clear: Signal<In, Bit>,
    /// The buffer memory's write enable, address and byte.
    pub memory_write: Signal<Out, Bit>,
    /// Address of that write: the buffer, then the offset.
    pub memory_address: Signal<Out, Bits<12>>,
    /// The byte of that write.
    pub memory_data: Signal<Out, Bits<8>>,
    /// Bytes taken into the filling datagram.
    pub offset: Signal<Out, Bits<OFFSET_BITS>>,
    /// The body's sum with the byte now on its way to the buffer.
    pub body_sum_next: Signal<Out, Bits<BODY_SUM_BITS>>,
    pending: DFF<Bit>,
    pending_address: DFF<Bits<12>>,
    // the byte at its place in its word (0 when nothing is written)
    pending_word: DFF<Bits<16>>,
    fill_offset: DFF<Bits<OFFSET_BITS>>,
    sum: DFF<Bits<BODY_SUM_BITS>>,
    sum_next: Signal<Local, Bits<BODY_SUM_BITS>>,
}

impl Logic for PayloadWriter {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            pending,
            pending_address,
            pending_word,
            fill_offset,
            sum
        );
        self.pending.d.next = self.write.val();
        self.pending_word.d.next = 0.into();
        if self.write.val() {
            self.pending_word.d.next = bit_cast::<16, 8>(self.write_data.val()) << 8;
            if self.fill_offset.q.val().get_bit(0) {
                self.pending_word.d.next = bit_cast::<16, 8>(self.write_data.val());
            }
        }
        self.pending_address.d.next = (bit_cast::<12, 1>(self.buffer.val().into()) << 11)
            | bit_cast::<12, 11>(self.fill_offset.q.val());
        if self.write.val() {
            self.fill_offset.d.next = self.fill_offset.q.val() + 1;
        }
        // the word added with the last carry (end-around) in every clock: a word of 0
        // folds the carry in; no multiplexer between the registers and the adder
        self.sum_next.next = bit_cast::<17, 16>(self.sum.q.val().get_bits::<16>(0))
            + bit_cast::<17, 16>(self.pending_word.q.val())
            + bit_cast::<17, 1>(self.sum.q.val().get_bit(16).into());
        self.sum.d.next = self.sum_next.val();
        if self.clear.val() {
            self.fill_offset.d.next = 0.into();
            self.sum.d.next = 0.into();
        }
        if self.reset.val() {
            self.pending.d.next = false;
            self.fill_offset.d.next = 0.into();
            self.sum.d.next = 0.into();
        }
        self.memory_write.next = self.pending.q.val();
        self.memory_address.next = self.pending_address.q.val();
        // (one of the word's bytes is 0)
        self.memory_data.next =
            self.pending_word.q.val().get_bits::<8>(8) | self.pending_word.q.val().get_bits::<8>(0);
        self.offset.next = self.fill_offset.q.val();
        self.body_sum_next.next = self.sum_next.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{is_body_sum_of, Bench, TestRng};

    /// Random bytes written with gaps into alternating buffers, each datagram closed after
    /// a random count: every byte lands a clock later at its buffer and offset, and the sum
    /// at the close is the body's big-endian 16-bit words added up (the oracle written out
    /// here).
    #[test]
    fn bytes_land_a_clock_later_at_their_offset_and_the_sum_follows_them() {
        let mut bench = Bench::new(PayloadWriter::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0x9A1);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut buffer = false;
        for datagram in 0..40 {
            let len = 1 + rng.next_u64() % 80;
            let mut body = Vec::new();
            let mut expected_write: Option<(u64, u8)> = None;
            while (body.len() as u64) < len {
                let write = !rng.next_u64().is_multiple_of(3);
                let byte = rng.next_u64() as u8;
                bench.uut.write.next = write;
                bench.uut.write_data.next = u64::from(byte).into();
                bench.uut.buffer.next = buffer;
                bench.uut.clear.next = false;
                bench.settle();
                // last clock's decision is on the memory port now
                assert_eq!(bench.uut.memory_write.val(), expected_write.is_some());
                if let Some((address, data)) = expected_write {
                    assert_eq!(bench.uut.memory_address.val().to_u64(), address);
                    assert_eq!(bench.uut.memory_data.val().to_u64(), u64::from(data));
                }
                assert_eq!(bench.uut.offset.val().to_u64(), body.len() as u64);
                expected_write = write.then(|| {
                    let address = (u64::from(buffer) << 11) | body.len() as u64;
                    body.push(byte);
                    (address, byte)
                });
                bench.cycle();
            }
            // the close: the last byte is still on its way and counted
            bench.uut.write.next = false;
            bench.uut.clear.next = true;
            bench.settle();
            let sum = bench.uut.body_sum_next.val().to_u64();
            assert!(is_body_sum_of(sum, &body), "datagram {datagram}: {sum:#x}");
            bench.cycle();
            bench.uut.clear.next = false;
            bench.settle();
            assert_eq!(bench.uut.offset.val().to_u64(), 0);
            assert_eq!(bench.uut.body_sum_next.val().to_u64(), 0);
            buffer = !buffer;
        }
    }
}
