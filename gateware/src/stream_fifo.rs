//! StreamFifo: a four-entry byte-stream FIFO whose output leaves registers.
//!
//! A shift register with the head in entry 0: a pop moves every entry down one, a push
//! goes behind the last kept entry, both in one clock. Which entries are held is kept as a
//! thermometer code, so each entry's next value is chosen by registers and the pop alone
//! (one multiplexer after the consumer's `ready`), and the count is decoded from it.
//! `beats_in.ready` is "fewer than four entries"; `count` lets a producer with a read latency reserve room for the beats it has
//! in flight (it issues a read only while `count` plus its beats in flight is below
//! [`FIFO_DEPTH`], and then pushes without looking at `ready`), so the consumer's `ready`
//! reaches nothing but this FIFO's registers.

use crate::hdl::*;
use crate::stream::{ByteStreamSink, ByteStreamSource};

/// Entries of the FIFO.
pub const FIFO_DEPTH: usize = 4;

/// A four-entry FIFO of stream beats (data, last, error).
#[derive(LogicBlock, Default)]
pub struct StreamFifo {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: empties the FIFO.
    pub reset: Signal<In, Bit>,
    /// Beats in.
    pub beats_in: ByteStreamSink,
    /// Beats out, oldest first.
    pub beats_out: ByteStreamSource,
    /// Entries held.
    pub count: Signal<Out, Bits<3>>,
    // entries of data (bits 0-7), last (8) and error (9)
    entry_0: DFF<Bits<10>>,
    entry_1: DFF<Bits<10>>,
    entry_2: DFF<Bits<10>>,
    entry_3: DFF<Bits<10>>,
    // which entries are held, as a thermometer code (entry k is held while more than k
    // are): `not_empty` is entry 0's, `full` entry 3's (`valid` and `ready` start at a
    // flip-flop; all 0 at power-up)
    not_empty: DFF<Bit>,
    holds_1: DFF<Bit>,
    holds_2: DFF<Bit>,
    full: DFF<Bit>,
    push: Signal<Local, Bit>,
    pop: Signal<Local, Bit>,
    beat: Signal<Local, Bits<10>>,
    // the count's bits 1 and 0, from the thermometer code
    count_two: Signal<Local, Bit>,
    count_odd: Signal<Local, Bit>,
}

impl Logic for StreamFifo {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self, clock, entry_0, entry_1, entry_2, entry_3, not_empty, holds_1, holds_2, full
        );
        self.count_two.next = self.holds_1.q.val() & !self.full.q.val();
        self.count_odd.next = (self.not_empty.q.val() & !self.holds_1.q.val())
            | (self.holds_2.q.val() & !self.full.q.val());
        self.count.next = (bit_cast::<3, 1>(self.full.q.val().into()) << 2)
            | (bit_cast::<3, 1>(self.count_two.val().into()) << 1)
            | bit_cast::<3, 1>(self.count_odd.val().into());
        self.beats_in.ready.next = !self.full.q.val();
        self.beats_out.valid.next = self.not_empty.q.val();
        self.beats_out.data.next = self.entry_0.q.val().get_bits::<8>(0);
        self.beats_out.last.next = self.entry_0.q.val().get_bit(8);
        self.beats_out.error.next = self.entry_0.q.val().get_bit(9);
        // (from the registers, not from the outputs: Verilator orders the statements apart
        // only when no assigned output is read back)
        self.push.next = self.beats_in.valid.val() & !self.full.q.val();
        self.pop.next = self.not_empty.q.val() & self.beats_out.ready.val();
        self.beat.next = bit_cast::<10, 8>(self.beats_in.data.val())
            | (bit_cast::<10, 1>(self.beats_in.last.val().into()) << 8)
            | (bit_cast::<10, 1>(self.beats_in.error.val().into()) << 9);
        // Each entry keeps its beat (or after a pop takes the next entry's) while that is
        // held, and takes the arriving beat otherwise: an entry not held is free, so what
        // it takes matters only when the push goes to it. The pop, which comes from the
        // consumer's `ready`, only chooses between two choices made from registers.
        self.entry_0.d.next = self.beat.val();
        if self.not_empty.q.val() {
            self.entry_0.d.next = self.entry_0.q.val();
        }
        self.entry_1.d.next = self.beat.val();
        if self.holds_1.q.val() {
            self.entry_1.d.next = self.entry_1.q.val();
        }
        self.entry_2.d.next = self.beat.val();
        if self.holds_2.q.val() {
            self.entry_2.d.next = self.entry_2.q.val();
        }
        self.entry_3.d.next = self.beat.val();
        if self.full.q.val() {
            self.entry_3.d.next = self.entry_3.q.val();
        }
        if self.pop.val() {
            self.entry_0.d.next = self.beat.val();
            if self.holds_1.q.val() {
                self.entry_0.d.next = self.entry_1.q.val();
            }
            self.entry_1.d.next = self.beat.val();
            if self.holds_2.q.val() {
                self.entry_1.d.next = self.entry_2.q.val();
            }
            self.entry_2.d.next = self.beat.val();
            if self.full.q.val() {
                self.entry_2.d.next = self.entry_3.q.val();
            }
            self.entry_3.d.next = self.beat.val();
        }
        if self.push.val() & !self.pop.val() {
            self.not_empty.d.next = true;
            self.holds_1.d.next = self.not_empty.q.val();
            self.holds_2.d.next = self.holds_1.q.val();
            self.full.d.next = self.holds_2.q.val();
        } else if !self.push.val() & self.pop.val() {
            self.not_empty.d.next = self.holds_1.q.val();
            self.holds_1.d.next = self.holds_2.q.val();
            self.holds_2.d.next = self.full.q.val();
            self.full.d.next = false;
        }
        if self.reset.val() {
            self.not_empty.d.next = false;
            self.holds_1.d.next = false;
            self.holds_2.d.next = false;
            self.full.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use std::collections::VecDeque;

    /// Beats offered with random gaps, taken with random backpressure: every beat comes
    /// out once, in order, with its flags; `count` and `ready` follow a queue model; the
    /// FIFO ends empty.
    #[test]
    fn beats_pass_in_order_under_random_valid_and_ready() {
        for (seed, offer_p, take_p) in [
            (1, 1.0, 1.0),
            (2, 0.5, 0.7),
            (3, 0.9, 0.3),
            (4, 0.2, 0.1),
            (5, 1.0, 0.5),
            (6, 0.3, 1.0),
        ] {
            let mut rng = TestRng::new(seed);
            let sent: Vec<(u8, bool, bool)> = (0..600)
                .map(|_| (rng.byte(), rng.chance(0.2), rng.chance(0.05)))
                .collect();
            let mut bench = Bench::new(StreamFifo::default(), |f| &mut f.clock);
            bench.uut.reset.next = true;
            bench.cycle();
            bench.uut.reset.next = false;
            let (mut next, mut got, mut model) = (0, Vec::new(), VecDeque::new());
            let mut offering = false;
            for _ in 0..40_000 {
                if !offering && next < sent.len() {
                    offering = rng.chance(offer_p);
                }
                let take = rng.chance(take_p);
                let u = &mut bench.uut;
                u.beats_in.valid.next = offering;
                if offering {
                    let (d, l, e) = sent[next];
                    u.beats_in.data.next = u64::from(d).into();
                    u.beats_in.last.next = l;
                    u.beats_in.error.next = e;
                }
                u.beats_out.ready.next = take;
                bench.settle();
                let u = &bench.uut;
                let held = model.len();
                assert_eq!(u.count.val().index(), held);
                assert_eq!(u.beats_out.valid.val(), held != 0);
                assert_eq!(u.beats_in.ready.val(), held != FIFO_DEPTH);
                if u.beats_out.valid.val() && take {
                    let beat = (
                        u.beats_out.data.val().to_u8(),
                        u.beats_out.last.val(),
                        u.beats_out.error.val(),
                    );
                    assert_eq!(Some(beat), model.pop_front());
                    got.push(beat);
                }
                if offering && u.beats_in.ready.val() {
                    model.push_back(sent[next]);
                    next += 1;
                    offering = false;
                }
                bench.cycle();
                if got.len() == sent.len() {
                    break;
                }
            }
            assert_eq!(got, sent, "seed {seed}");
            assert_eq!(bench.uut.count.val().index(), 0, "nothing left over");
        }
    }
}
