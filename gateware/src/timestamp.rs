//! TimestampCounter: the box time, a free-running 64-bit count of 8 ns ticks.
//!
//! At 125 MHz it wraps after 4,677 years. Latency: the count after a rising edge is the
//! number of edges since reset went low. Cost: one 64-bit incrementer and two 32-bit copies
//! of earlier counts (the start stamp, shared by every deframer instead of a subtractor
//! each).

use crate::hdl::*;

/// Ticks `start_stamp` lags `tick`: the receiver's synchroniser
/// ([`crate::uart_rx::START_LATENCY_TICKS`]) and the deframer's input register
/// ([`crate::cell_deframer::INPUT_REGISTER_CLOCKS`]).
pub const START_STAMP_LAG: u64 = 2;

/// Free-running 64-bit tick counter.
#[derive(LogicBlock, Default)]
pub struct TimestampCounter {
    /// The 125 MHz box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the count restarts at 0.
    pub reset: Signal<In, Bit>,
    /// The current tick.
    pub tick: Signal<Out, Bits<64>>,
    /// The low 32 bits of `tick - START_STAMP_LAG`, from registers (from tick
    /// `START_STAMP_LAG` on): when a deframer takes its registered start edge, the tick of
    /// the first edge that sampled the start bit low.
    pub start_stamp: Signal<Out, Bits<32>>,
    count: DFF<Bits<64>>,
    previous_low: DFF<Bits<32>>,
    stamp_low: DFF<Bits<32>>,
}

impl Logic for TimestampCounter {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, count, previous_low, stamp_low);
        self.count.d.next = self.count.q.val() + 1;
        self.previous_low.d.next = self.count.q.val().get_bits::<32>(0);
        self.stamp_low.d.next = self.previous_low.q.val();
        // (the copies need no reset: they are right from tick START_STAMP_LAG on, and the
        // ports leave reset long after, once the counter file is cleared)
        if self.reset.val() {
            self.count.d.next = 0.into();
        }
        self.tick.next = self.count.q.val();
        self.start_stamp.next = self.stamp_low.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    #[test]
    fn start_stamp_lag_is_the_latency_from_pin_to_deframer() {
        use crate::{cell_deframer::INPUT_REGISTER_CLOCKS, uart_rx::START_LATENCY_TICKS};
        assert_eq!(START_STAMP_LAG, START_LATENCY_TICKS + INPUT_REGISTER_CLOCKS);
    }

    #[test]
    fn counts_clock_edges_from_reset() {
        let mut bench = Bench::new(TimestampCounter::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycles(3);
        assert_eq!(bench.uut.tick.val(), 0);
        bench.uut.reset.next = false;
        for expected in 1..=1000u64 {
            bench.cycle();
            assert_eq!(bench.uut.tick.val(), expected);
            if expected >= START_STAMP_LAG {
                let stamp = expected - START_STAMP_LAG;
                assert_eq!(bench.uut.start_stamp.val(), stamp, "tick {expected}");
            }
        }
    }

    #[test]
    fn carries_across_32_bits() {
        let mut bench = Bench::new(TimestampCounter::default(), |b| &mut b.clock);
        bench.uut.reset.next = false;
        bench.uut.count.q.next = 0xFFFF_FFFE_u64.into();
        // the DFF's output is forced once; the next edges count on from there
        bench.settle();
        bench.cycles(3);
        assert_eq!(bench.uut.tick.val(), 0x1_0000_0001_u64);
    }
}
