//! SyncGenerator: the box's time-sync period. Every `period` ticks its `epoch` bit
//! toggles; the downlink's refill keeps each port's epoch of its last generated sync in
//! the port's read position (a RAM word), so a port whose bit differs has a time sync
//! pending and sends one at its next packet boundary: no flip-flop per port.
//!
//! Timing: the first clock after reset counts as a `restart` (the clock the new `period`
//! is seen); the count starts at 0 in the clock after it, `origin`; the epoch toggles at
//! `origin` unless the period is 0 (a box out of reset, or given a new period, sends a
//! sync at once) and then at the clocks `origin + n * period` (`n` >= 1). Period 0: off
//! (no toggle). Cost: a 32-bit down count and its zero test, two flip-flops.

use crate::hdl::*;

/// The sync period counter.
#[derive(LogicBlock, Default)]
pub struct SyncGenerator {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the count restarts, epoch 0.
    pub reset: Signal<In, Bit>,
    /// Ticks between syncs; 0: none.
    pub period: Signal<In, Bits<32>>,
    /// One clock: `period` was just set: restart the count (and toggle if not 0).
    pub restart: Signal<In, Bit>,
    /// Toggles once a period.
    pub epoch: Signal<Out, Bit>,
    /// The period is not 0: the box sends syncs.
    pub on: Signal<Out, Bit>,
    /// Clocks left in the period after this one (loaded with `period - 1`; the period
    /// only changes with a restart): its zero test is the wrap, no adder before it.
    remaining: DFF<Bits<32>>,
    epoch_bit: DFF<Bit>,
    // the first clock after reset
    fresh: DFF<Bit>,
    running: Signal<Local, Bit>,
}

impl Logic for SyncGenerator {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, remaining, epoch_bit, fresh);
        self.running.next = self.period.val() != 0;
        self.remaining.d.next = self.remaining.q.val() - 1;
        if self.remaining.q.val() == 0 {
            self.remaining.d.next = self.period.val() - 1;
            self.epoch_bit.d.next = self.epoch_bit.q.val() ^ self.running.val();
        }
        self.fresh.d.next = false;
        if self.restart.val() | self.fresh.q.val() {
            self.remaining.d.next = self.period.val() - 1;
            self.epoch_bit.d.next = self.epoch_bit.q.val() ^ self.running.val();
        }
        if self.reset.val() {
            self.remaining.d.next = 0.into();
            self.epoch_bit.d.next = false;
            self.fresh.d.next = true;
        }
        self.epoch.next = self.epoch_bit.q.val();
        self.on.next = self.running.val();
    }
}

/// The epoch a [`SyncGenerator`] shows in clock `tick`, `origin` being the clock after its
/// reset or last restart, `at_origin` its epoch then, `period` its period since.
pub fn epoch_at(origin: u64, at_origin: bool, period: u64, tick: u64) -> bool {
    if period == 0 || tick < origin {
        return at_origin;
    }
    at_origin ^ ((tick - origin) / period % 2 == 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Clock after clock, the epoch is [`epoch_at`]'s, across random periods, restarts
    /// (a new period toggles at once unless 0) and resets.
    #[test]
    fn the_epoch_toggles_every_period_from_each_restart() {
        let mut rng = TestRng::new(0x5C);
        let mut bench = Bench::new(SyncGenerator::default(), |b| &mut b.clock);
        bench.uut.period.next = 7u64.into();
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let (mut origin, mut at_origin, mut period) = (bench.cycles, false, 7u64);
        let mut toggles = 0;
        let mut last = false;
        let mut just_reset = true;
        for step in 0..20_000u64 {
            let r = rng.next_u64();
            // (not in the clock after a reset, which restarts the generator itself)
            let restart = r.is_multiple_of(400) && !just_reset;
            let reset = r % 5000 == 1;
            let new_period = match (r >> 16) % 4 {
                0 => 0,
                _ => 1 + (r >> 20) % 40,
            };
            let now = bench.cycles;
            if restart {
                // the period as seen in the restart's clock
                bench.uut.period.next = new_period.into();
            }
            bench.uut.restart.next = restart;
            bench.uut.reset.next = reset;
            bench.settle();
            assert_eq!(bench.uut.on.val(), bench.uut.period.val().to_u64() != 0);
            bench.cycle();
            // the clock after a reset restarts the generator on the period it has
            let fresh = just_reset;
            just_reset = reset;
            if reset {
                (origin, at_origin) = (now + 1, false);
                period = bench.uut.period.val().to_u64();
            } else if restart || fresh {
                let new_period = if restart { new_period } else { period };
                let before = epoch_at(origin, at_origin, period, now);
                (origin, at_origin, period) = (now + 1, before ^ (new_period != 0), new_period);
            }
            let epoch = bench.uut.epoch.val();
            assert_eq!(
                epoch,
                epoch_at(origin, at_origin, period, bench.cycles),
                "step {step}"
            );
            toggles += u64::from(epoch != last);
            last = epoch;
        }
        assert!(toggles > 500, "{toggles} toggles");
    }
}
