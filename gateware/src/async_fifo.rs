//! AsyncFifo: a 16-word FIFO between two unrelated clocks, words of `D` bits.
//!
//! The words sit in a distributed RAM (`LutRam`), written at the write clock and read
//! without a clock: the read side's word is the one at its pointer register, so no path
//! runs from the empty test and the pointer's step through the RAM. Each side counts its
//! pointer in binary with one bit more than the address (so full and empty differ) and
//! keeps its Gray code in a register; the other side takes that Gray code through two
//! flip-flops (a two-flop synchroniser: a Gray code changes one bit per step, so a sample
//! caught mid-change is either the old or the new pointer, never a third value). Full and
//! empty are therefore seen late, which is safe: the writer sees room only after the reader
//! freed it, and the reader sees a word only after it was written (two read clocks after
//! its Gray code changed, by then the RAM holds it).
//!
//! The read side is first-word-fall-through: while `empty` is low, `read_data` is the
//! oldest word, and `read_enable` takes it. `read_level` is the number of words the read
//! side saw a clock earlier (registered): after a take in the previous clock it counts
//! that word too, so only a reader that waits without taking may trust it as a lower
//! bound. Each side has its own synchronous reset: reset both
//! together (hold both for a few clocks of the slower clock); a word written while
//! `full` is high is dropped (the writer must look at `full`).

use crate::hdl::*;
use crate::lut_ram::LutRam;

/// Address bits of the RAM.
pub const ADDRESS_BITS: usize = 4;
/// Words the FIFO holds.
pub const DEPTH: usize = 1 << ADDRESS_BITS;

/// Binary pointers with one more bit than the address.
type Pointer = Bits<5>;

/// A dual-clock FIFO of [`DEPTH`] words of `D` bits.
#[derive(LogicBlock)]
pub struct AsyncFifo<const D: usize> {
    /// The write side's clock.
    pub write_clock: Signal<In, Clock>,
    /// Synchronous reset of the write side.
    pub write_reset: Signal<In, Bit>,
    /// The word to write.
    pub write_data: Signal<In, Bits<D>>,
    /// Write the word at this write clock edge (ignored while `full`).
    pub write_enable: Signal<In, Bit>,
    /// No room, as the write side sees it.
    pub full: Signal<Out, Bit>,
    /// The read side's clock.
    pub read_clock: Signal<In, Clock>,
    /// Synchronous reset of the read side.
    pub read_reset: Signal<In, Bit>,
    /// The oldest word, while `empty` is low.
    pub read_data: Signal<Out, Bits<D>>,
    /// Take the oldest word at this read clock edge (ignored while `empty`).
    pub read_enable: Signal<In, Bit>,
    /// No word, as the read side sees it.
    pub empty: Signal<Out, Bit>,
    /// Words the read side saw a clock earlier (see the module documentation).
    pub read_level: Signal<Out, Pointer>,
    ram: LutRam<D, ADDRESS_BITS>,
    write_pointer: DFF<Pointer>,
    write_gray: DFF<Pointer>,
    read_gray_meta: DFF<Pointer>,
    read_gray_sync: DFF<Pointer>,
    read_pointer: DFF<Pointer>,
    read_gray: DFF<Pointer>,
    write_gray_meta: DFF<Pointer>,
    write_gray_sync: DFF<Pointer>,
    level: DFF<Pointer>,
    write_now: Signal<Local, Bit>,
    write_next: Signal<Local, Pointer>,
    read_next: Signal<Local, Pointer>,
    write_seen: Signal<Local, Pointer>,
    full_pattern: Signal<Local, Pointer>,
    is_empty: Signal<Local, Bit>,
    top_bits: Constant<Pointer>,
}

impl<const D: usize> Default for AsyncFifo<D> {
    fn default() -> Self {
        Self {
            write_clock: Default::default(),
            write_reset: Default::default(),
            write_data: Default::default(),
            write_enable: Default::default(),
            full: Default::default(),
            read_clock: Default::default(),
            read_reset: Default::default(),
            read_data: Default::default(),
            read_enable: Default::default(),
            empty: Default::default(),
            read_level: Default::default(),
            ram: Default::default(),
            write_pointer: Default::default(),
            write_gray: Default::default(),
            read_gray_meta: Default::default(),
            read_gray_sync: Default::default(),
            read_pointer: Default::default(),
            read_gray: Default::default(),
            write_gray_meta: Default::default(),
            write_gray_sync: Default::default(),
            level: Default::default(),
            write_now: Default::default(),
            write_next: Default::default(),
            read_next: Default::default(),
            write_seen: Default::default(),
            full_pattern: Default::default(),
            is_empty: Default::default(),
            top_bits: Constant::new((3u64 << (ADDRESS_BITS - 1)).into()),
        }
    }
}

impl<const D: usize> Logic for AsyncFifo<D> {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            write_clock,
            write_pointer,
            write_gray,
            read_gray_meta,
            read_gray_sync
        );
        dff_setup!(
            self,
            read_clock,
            read_pointer,
            read_gray,
            write_gray_meta,
            write_gray_sync,
            level
        );
        // write side
        self.read_gray_meta.d.next = self.read_gray.q.val();
        self.read_gray_sync.d.next = self.read_gray_meta.q.val();
        // full: the Gray codes differ in their top two bits only
        self.full_pattern.next = self.read_gray_sync.q.val() ^ self.top_bits.val();
        self.full.next = self.write_gray.q.val() == self.full_pattern.val();
        self.ram.clock.next = self.write_clock.val();
        self.ram.write_address.next = self.write_pointer.q.val().get_bits::<4>(0);
        self.ram.write_data.next = self.write_data.val();
        self.write_now.next =
            self.write_enable.val() & (self.write_gray.q.val() != self.full_pattern.val());
        self.ram.write_enable.next = self.write_now.val();
        self.write_next.next = self.write_pointer.q.val() + 1;
        if self.write_now.val() {
            self.write_pointer.d.next = self.write_next.val();
            self.write_gray.d.next = self.write_next.val() ^ (self.write_next.val() >> 1);
        }
        if self.write_reset.val() {
            self.write_pointer.d.next = 0.into();
            self.write_gray.d.next = 0.into();
        }
        // read side
        self.write_gray_meta.d.next = self.write_gray.q.val();
        self.write_gray_sync.d.next = self.write_gray_meta.q.val();
        self.is_empty.next = self.write_gray_sync.q.val() == self.read_gray.q.val();
        self.empty.next = self.is_empty.val();
        self.read_level.next = self.level.q.val();
        // the write pointer as the read side sees it, from its Gray code
        self.write_seen.next = self.write_gray_sync.q.val()
            ^ (self.write_gray_sync.q.val() >> 1)
            ^ (self.write_gray_sync.q.val() >> 2)
            ^ (self.write_gray_sync.q.val() >> 3)
            ^ (self.write_gray_sync.q.val() >> 4);
        self.level.d.next = self.write_seen.val() - self.read_pointer.q.val();
        self.read_next.next = self.read_pointer.q.val();
        if self.read_enable.val() & !self.is_empty.val() {
            self.read_next.next = self.read_pointer.q.val() + 1;
        }
        self.read_pointer.d.next = self.read_next.val();
        self.read_gray.d.next = self.read_next.val() ^ (self.read_next.val() >> 1);
        if self.read_reset.val() {
            self.read_pointer.d.next = 0.into();
            self.read_gray.d.next = 0.into();
        }
        // the oldest word, at the read pointer: first word fall-through
        self.ram.read_address.next = self.read_pointer.q.val().get_bits::<4>(0);
        self.read_data.next = self.ram.read_data.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::TestRng;
    use std::collections::VecDeque;

    /// Words written at random under `full` at one clock, read at random at another (both
    /// orders of speed): every word comes out once and in order; `full` and `empty` are
    /// never wrong in the unsafe direction (no word lost, none read that was not written);
    /// the FIFO fills up when the writer is the faster side.
    #[test]
    fn words_cross_in_order_between_unrelated_clocks() {
        for (seed, write_period, read_period, write_p, read_p) in [
            (1, 8000.0, 8001.0, 0.9, 0.95),
            (2, 8000.0, 13_000.0, 1.0, 1.0),
            (3, 13_000.0, 8000.0, 1.0, 1.0),
            (4, 7000.0, 9000.0, 0.5, 0.3),
        ] {
            let mut rng = TestRng::new(seed);
            let mut uut = AsyncFifo::<10>::default();
            uut.connect_all();
            let sent: Vec<u64> = (0..1500).map(|_| rng.next_u64() & 0x3FF).collect();
            let (mut next, mut got) = (0usize, Vec::new());
            let mut model: VecDeque<u64> = VecDeque::new();
            let mut was_full = false;
            let (mut write_edge, mut read_edge) = (0u64, 0u64);
            let write_time = |e: u64| 500.0 + e as f64 * write_period / 2.0;
            let read_time = |e: u64| 2345.0 + e as f64 * read_period / 2.0;
            uut.write_reset.next = true;
            uut.read_reset.next = true;
            assert!(simulate(&mut uut, 1000));
            while got.len() < sent.len() && read_edge < 2_000_000 {
                if write_time(write_edge) <= read_time(read_edge) {
                    let rising = write_edge % 2 == 0;
                    uut.write_clock.next = rising.into();
                    assert!(simulate(&mut uut, 1000));
                    if !rising {
                        uut.write_reset.next = write_edge < 8;
                        // the word of the next rising edge, if any and there is room
                        let offer = next < sent.len() && rng.chance(write_p) && write_edge >= 8;
                        assert!(simulate(&mut uut, 1000));
                        let full = uut.full.val();
                        was_full |= full;
                        assert!(model.len() < DEPTH || full, "full missed");
                        uut.write_enable.next = offer && !full;
                        uut.write_data.next = sent.get(next).copied().unwrap_or(0).into();
                        if offer && !full {
                            model.push_back(sent[next]);
                            next += 1;
                        }
                        assert!(simulate(&mut uut, 1000));
                    }
                    write_edge += 1;
                } else {
                    let rising = read_edge % 2 == 0;
                    uut.read_clock.next = rising.into();
                    assert!(simulate(&mut uut, 1000));
                    if !rising {
                        uut.read_reset.next = read_edge < 8;
                        assert!(simulate(&mut uut, 1000));
                        let take = rng.chance(read_p) && read_edge >= 8;
                        let empty = uut.empty.val();
                        assert!(
                            !model.is_empty() || empty,
                            "a word read that was not written"
                        );
                        if !empty && take {
                            assert_eq!(Some(uut.read_data.val().to_u64()), model.pop_front());
                            got.push(uut.read_data.val().to_u64());
                        }
                        uut.read_enable.next = take;
                        assert!(simulate(&mut uut, 1000));
                    }
                    read_edge += 1;
                }
            }
            assert_eq!(got, sent, "seed {seed}");
            let writes_faster = write_p / write_period > read_p / read_period;
            assert_eq!(was_full, writes_faster, "seed {seed}: full seen");
        }
    }
}
