//! FlushDeadline: the record batcher's flush timeout: a filling datagram's base tick and
//! whether its deadline has passed.
//!
//! A clock after the batcher saw its first record's tick complete (`first_seen`, with the
//! record's age `first_age` = now - its tick, low 32 bits, taken a clock before), the block
//! sets the datagram's 64-bit base tick, (now - 1) - age = now + !age (sign-extended), and
//! its deadline less one, now + timeout - 2: the record has waited the timeout when the
//! tick reaches now + timeout. From then on `passed_next` says, a clock ahead, that the next
//! clock's tick is at or past the deadline: a registered, wrap-safe 32-bit test (the timeout
//! is far below 2^31 ticks; the next tick, now + 1, against the deadline is now against
//! the deadline less one), so the batcher's close decision takes no carry chain. The
//! timeout less two and "at most two" are registered from the input: a change reaches a
//! datagram whose first record is seen two clocks later or after.

use crate::hdl::*;

/// A filling datagram's base tick and flush deadline.
#[derive(LogicBlock, Default)]
pub struct FlushDeadline {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Box time.
    pub tick: Signal<In, Bits<64>>,
    /// Flush timeout in ticks, 1 to 2^31 - 1.
    pub flush_timeout_ticks: Signal<In, Bits<32>>,
    /// One clock: the datagram's first record's tick was complete a clock ago.
    pub first_seen: Signal<In, Bit>,
    /// With `first_seen`: the first record's age in ticks (low 32 bits).
    pub first_age: Signal<In, Bits<32>>,
    /// The datagram's base tick: the first record's full tick.
    pub base_tick: Signal<Out, Bits<64>>,
    /// The next clock's tick is at or past the deadline.
    pub passed_next: Signal<Out, Bit>,
    timeout_less_two: DFF<Bits<32>>,
    // a timeout of 1 or 2 ticks has passed a clock after the deadline is set
    short_timeout: DFF<Bit>,
    base: DFF<Bits<64>>,
    deadline_less_one: DFF<Bits<32>>,
    passed: DFF<Bit>,
    // (a bit of an expression is not Verilog: the difference gets its own signal)
    delta: Signal<Local, Bits<32>>,
}

impl Logic for FlushDeadline {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            timeout_less_two,
            short_timeout,
            base,
            deadline_less_one,
            passed
        );
        self.timeout_less_two.d.next = self.flush_timeout_ticks.val() - 2;
        self.short_timeout.d.next = self.flush_timeout_ticks.val() <= 2;
        self.delta.next = self.tick.val().get_bits::<32>(0) - self.deadline_less_one.q.val();
        self.passed.d.next = !self.delta.val().get_bit(31);
        if self.first_seen.val() {
            self.base.d.next = self.tick.val()
                + (bit_cast::<64, 32>(!self.first_age.val()) | 0xFFFF_FFFF_0000_0000_u64);
            self.deadline_less_one.d.next =
                self.tick.val().get_bits::<32>(0) + self.timeout_less_two.q.val();
            // (the next tick is now + 1: the deadline has passed if timeout - 1 <= 1)
            self.passed.d.next = self.short_timeout.q.val();
        }
        self.base_tick.next = self.base.q.val();
        self.passed_next.next = self.passed.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    #[test]
    fn the_deadline_passes_timeout_ticks_after_the_first_record() {
        let mut bench = Bench::new(FlushDeadline::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0xF1);
        let mut now: u64 = 0xFFFF_FF00; // the low 32 bits wrap during the test
        for round in 0..300 {
            let timeout = match round % 4 {
                0 => 1 + rng.next_u64() % 3,
                _ => 1 + rng.next_u64() % 200,
            };
            let age = rng.next_u64() % 50;
            let record_tick = now - age;
            bench.uut.flush_timeout_ticks.next = timeout.into();
            // the timeout is registered: set two clocks before the record is seen
            for _ in 0..2 {
                bench.uut.tick.next = now.into();
                bench.cycle();
                now += 1;
            }
            // the clock after the tick was complete: age counts from the clock before
            bench.uut.tick.next = now.into();
            let seen = now;
            bench.uut.first_seen.next = true;
            bench.uut.first_age.next = ((now - 1 - record_tick) as u32 as u64).into();
            bench.cycle();
            now += 1;
            bench.uut.first_seen.next = false;
            assert_eq!(
                bench.uut.base_tick.val().to_u64(),
                record_tick,
                "round {round}"
            );
            // the record waits from the clock it was seen: `passed_next` in the clock of
            // tick t says whether t + 1 >= seen + timeout
            for _ in 0..timeout + 3 {
                bench.uut.tick.next = now.into();
                bench.settle();
                assert_eq!(
                    bench.uut.passed_next.val(),
                    now + 1 >= seen + timeout,
                    "round {round}: timeout {timeout}, age {age}, tick {now}"
                );
                bench.cycle();
                now += 1;
            }
        }
    }
}
