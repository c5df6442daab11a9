//! ReplyStages: the reply builder's step pipeline, from a program's ROM word to the byte
//! written into the frame buffer and summed into the reply's checksums.
//!
//! The ROM word comes from the block RAM's output register, so its parts are taken from it
//! directly (no register of their own): the buffer read of a copy is issued from it
//! (`read_address`), the held field's byte is chosen (`field_byte_index` now, from a
//! register the previous word loaded: each word carries the next step's byte index in
//! bits 32..35, 0 between programs, so the 32 byte multiplexers are not driven from the
//! block RAM; `field_word_index` in the next stage: a
//! [`crate::reply_field_bytes::ReplyFieldBytes`] answers in between), the counter is loaded at its byte 0 (the next counter's read
//! starts: `counters_address` counts from 0 at `restart`, a read's data taken four clocks
//! after its address), and stage 4 registers the parts (frame address, value, source,
//! write, sums; a padding step writes only from the request's end on). Stage 5 chooses the
//! byte by its source (the value, the field byte, a counter byte, a checksum byte) into a
//! register; a copy's byte is the buffer's (`buffer_data`, read two clocks before). The
//! byte is written (`write`, `write_address`, `write_data`) and summed into the IPv4 or
//! UDP checksum ([`ReplyChecksums`], an even frame position a word's high byte).
//!
//! Latency: a word's byte is written 2 clocks after the word (`word_valid`). Cost: the
//! stage registers (2 x about 20 bits), the counter word and address, and the checksums.

use crate::hdl::*;
use crate::reply_checksums::ReplyChecksums;
use crate::reply_sequencer::STEP_BITS;

/// Clocks from a valid ROM word to the clock its byte is written.
pub const WORD_TO_WRITE: u64 = 2;

/// The builder's step pipeline.
#[derive(LogicBlock, Default)]
pub struct ReplyStages {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing written.
    pub reset: Signal<In, Bit>,
    /// A reply starts: the checksums and the counter address restart.
    pub restart: Signal<In, Bit>,
    /// The ROM word is a step.
    pub word_valid: Signal<In, Bit>,
    /// The ROM word.
    pub word: Signal<In, Bits<STEP_BITS>>,
    /// The echo request's end: a padding step writes from there on.
    pub frame_end: Signal<In, Bits<11>>,
    /// The buffer's byte at the last `read_address` but one.
    pub buffer_data: Signal<In, Bits<8>>,
    /// The counter, two clocks after its address.
    pub counters_data: Signal<In, Bits<32>>,
    /// The held field's byte (of the indices below).
    pub field_byte: Signal<In, Bits<8>>,
    /// Box counter to read.
    pub counters_address: Signal<Out, Bits<5>>,
    /// The held field byte's place in its word.
    pub field_byte_index: Signal<Out, Bits<3>>,
    /// The held field byte's word, a clock after its place.
    pub field_word_index: Signal<Out, Bits<2>>,
    /// The buffer address a copy reads.
    pub read_address: Signal<Out, Bits<8>>,
    /// A byte is written.
    pub write: Signal<Out, Bit>,
    /// Its frame position.
    pub write_address: Signal<Out, Bits<8>>,
    /// The byte.
    pub write_data: Signal<Out, Bits<8>>,
    // the IPv4 and UDP checksums of the written bytes
    checksums: ReplyChecksums,
    counter_address: DFF<Bits<5>>,
    counter_word: DFF<Bits<32>>,
    // the held-field byte index of the next word's step (its word's bits 32..35)
    field_byte_ahead: DFF<Bits<3>>,
    // stage 4: the ROM word's parts, registered
    s4_write: DFF<Bit>,
    s4_address: DFF<Bits<8>>,
    s4_value: DFF<Bits<8>>,
    s4_source: DFF<Bits<2>>,
    s4_sum_ip: DFF<Bit>,
    s4_sum_udp: DFF<Bit>,
    s4_from_buffer: DFF<Bit>,
    // stage 5: the byte written and summed
    s5_write: DFF<Bit>,
    s5_address: DFF<Bits<8>>,
    s5_byte: DFF<Bits<8>>,
    s5_from_buffer: DFF<Bit>,
    s5_sum_ip: DFF<Bit>,
    s5_sum_udp: DFF<Bit>,
    written: Signal<Local, Bits<8>>,
    reply_byte: Signal<Local, Bits<8>>,
    counter_word_shifted: Signal<Local, Bits<32>>,
}

impl Logic for ReplyStages {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            counter_address,
            counter_word,
            field_byte_ahead,
            s4_write,
            s4_address,
            s4_value,
            s4_source,
            s4_sum_ip,
            s4_sum_udp,
            s4_from_buffer,
            s5_write,
            s5_address,
            s5_byte,
            s5_from_buffer,
            s5_sum_ip,
            s5_sum_udp
        );
        // The ROM word (stage 3, from the block RAM's output register): the buffer read of
        // a copy (its byte is there in stage 5), the held field's byte in each word (the
        // word in the next stage), the counter loaded at its byte 0 (the next counter's
        // read starts); its parts registered.
        self.read_address.next = self.word.val().get_bits::<8>(16);
        self.field_byte_ahead.d.next = 0.into();
        if self.word_valid.val() {
            self.field_byte_ahead.d.next = self.word.val().get_bits::<3>(32);
        }
        self.field_byte_index.next = self.field_byte_ahead.q.val();
        self.field_word_index.next = self.s4_value.q.val().get_bits::<2>(3);
        self.s4_write.d.next = self.word_valid.val()
            & self.word.val().get_bit(26)
            & (!self.word.val().get_bit(29)
                | (bit_cast::<11, 8>(self.word.val().get_bits::<8>(0)) >= self.frame_end.val()));
        self.s4_sum_ip.d.next = self.word_valid.val() & self.word.val().get_bit(27);
        self.s4_sum_udp.d.next = self.word_valid.val() & self.word.val().get_bit(28);
        self.s4_from_buffer.d.next = self.word.val().get_bit(31);
        self.s4_address.d.next = self.word.val().get_bits::<8>(0);
        self.s4_value.d.next = self.word.val().get_bits::<8>(8);
        self.s4_source.d.next = self.word.val().get_bits::<2>(24);
        self.counters_address.next = self.counter_address.q.val();
        if self.word_valid.val()
            & self.word.val().get_bit(26)
            & (self.word.val().get_bits::<2>(24) == 2)
            & (self.word.val().get_bits::<2>(8) == 0)
        {
            self.counter_word.d.next = self.counters_data.val();
            self.counter_address.d.next = self.counter_address.q.val() + 1;
        }

        // Stage 4 -> 5: the byte by its source (a field byte: its word).
        self.reply_byte.next = self.s4_value.q.val();
        self.counter_word_shifted.next = self.counter_word.q.val()
            << (bit_cast::<32, 2>(self.s4_value.q.val().get_bits::<2>(0)) << 3);
        if self.s4_source.q.val() == 1 {
            self.reply_byte.next = self.field_byte.val();
        } else if self.s4_source.q.val() == 2 {
            self.reply_byte.next = self.counter_word_shifted.val().get_bits::<8>(24);
        } else if self.s4_source.q.val() == 3 {
            if self.s4_value.q.val().get_bits::<2>(0) == 0 {
                self.reply_byte.next = self.checksums.ip_checksum.val().get_bits::<8>(8);
            } else if self.s4_value.q.val().get_bits::<2>(0) == 1 {
                self.reply_byte.next = self.checksums.ip_checksum.val().get_bits::<8>(0);
            } else if self.s4_value.q.val().get_bits::<2>(0) == 2 {
                self.reply_byte.next = self.checksums.udp_checksum.val().get_bits::<8>(8);
            } else {
                self.reply_byte.next = self.checksums.udp_checksum.val().get_bits::<8>(0);
            }
        }
        self.s5_byte.d.next = self.reply_byte.val();
        self.s5_write.d.next = self.s4_write.q.val();
        self.s5_address.d.next = self.s4_address.q.val();
        self.s5_sum_ip.d.next = self.s4_sum_ip.q.val();
        self.s5_sum_udp.d.next = self.s4_sum_udp.q.val();
        self.s5_from_buffer.d.next = self.s4_from_buffer.q.val();

        // Stage 5: write and sum (an even frame position is a word's high byte); a copy's
        // byte is the buffer's, read two clocks ago.
        self.written.next = self.s5_byte.q.val();
        if self.s5_from_buffer.q.val() {
            self.written.next = self.buffer_data.val();
        }
        self.checksums.clock.next = self.clock.val();
        self.checksums.reset.next = self.reset.val();
        self.checksums.restart.next = self.restart.val();
        self.checksums.written.next = self.written.val();
        self.checksums.low_byte.next = self.s5_address.q.val().get_bit(0);
        self.checksums.sum_ip.next = self.s5_sum_ip.q.val();
        self.checksums.sum_udp.next = self.s5_sum_udp.q.val();
        if self.restart.val() {
            self.counter_address.d.next = 0.into();
        }
        if self.reset.val() {
            self.s4_write.d.next = false;
            self.s4_sum_ip.d.next = false;
            self.s4_sum_udp.d.next = false;
            self.s5_write.d.next = false;
        }
        self.write.next = self.s5_write.q.val();
        self.write_address.next = self.s5_address.q.val();
        self.write_data.next = self.written.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use skinbox_protocol::wire::checksum::checksum;

    const WRITE: u64 = 1 << 26;
    const SUM_IP: u64 = 1 << 27;
    const FROM_BUFFER: u64 = 1 << 31;

    fn step(address: u64, value: u64, source: u64) -> u64 {
        address | value << 8 | source << 24 | WRITE
    }

    /// A program of constant bytes, copies from a buffer, counter bytes and then the IPv4
    /// checksum of the bytes summed: each byte is written at its address
    /// [`WORD_TO_WRITE`] clocks after its word, the checksum is the protocol's.
    #[test]
    fn steps_write_their_bytes_and_the_checksum() {
        let mut rng = TestRng::new(0x57A);
        let mut bench = Bench::new(ReplyStages::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for round in 0..20 {
            let buffer: Vec<u8> = (0..256).map(|_| rng.byte()).collect();
            let counters: Vec<u32> = (0..4).map(|_| rng.next_u64() as u32).collect();
            let mut words = vec![];
            let mut want = vec![];
            // 10 constant bytes summed, 6 copies (summed), 2 counters
            for at in 0..10u64 {
                let value = u64::from(rng.byte());
                words.push(step(at, value, 0) | SUM_IP);
                want.push((at, value as u8));
            }
            for at in 10..16u64 {
                let from = 100 + at;
                words.push(step(at, 0, 0) | SUM_IP | FROM_BUFFER | from << 16);
                want.push((at, buffer[from as usize]));
            }
            let summed: Vec<u8> = want.iter().map(|w| w.1).collect();
            for (c, counter) in counters[..2].iter().enumerate() {
                for k in 0..4u64 {
                    let at = 16 + 4 * c as u64 + k;
                    words.push(step(at, k, 2));
                    want.push((at, counter.to_be_bytes()[k as usize]));
                }
            }
            // idle steps until the sum is final, then the checksum
            words.extend([0; 4]);
            words.push(step(30, 0, 3));
            words.push(step(31, 1, 3));
            let ip = checksum(&[summed.as_slice()]);
            want.extend([(30, (ip >> 8) as u8), (31, ip as u8)]);
            bench.uut.restart.next = true;
            bench.cycle();
            bench.uut.restart.next = false;
            let mut written = vec![];
            let mut reads = std::collections::VecDeque::from([0u8; 2]);
            let mut counter_reads = std::collections::VecDeque::from([0u32; 2]);
            for clock in 0..words.len() + 6 {
                let u = &mut bench.uut;
                u.word_valid.next = clock < words.len();
                u.word.next = (*words.get(clock).unwrap_or(&0)).into();
                u.frame_end.next = 0.into();
                u.buffer_data.next = u64::from(reads[0]).into();
                u.counters_data.next = u64::from(counter_reads[0]).into();
                bench.settle();
                let u = &bench.uut;
                if u.write.val() {
                    let at = u.write_address.val().to_u64();
                    written.push((at, u.write_data.val().to_u64() as u8));
                }
                // the buffer and the counters answer two clocks after the address
                reads.pop_front();
                reads.push_back(buffer[u.read_address.val().to_u64() as usize]);
                counter_reads.pop_front();
                let counter = u.counters_address.val().to_u64() as usize;
                counter_reads.push_back(*counters.get(counter).unwrap_or(&0));
                bench.cycle();
            }
            assert_eq!(written, want, "round {round}");
        }
    }
}
