//! ReportTimer: when the status reporter's next report is due.
//!
//! A report is due every `period_ticks`, counted from report start to report start: the
//! timer counts down from `period_ticks - 1` and at 0 makes a report due and starts again.
//! A due report stays due until the reporter takes it (`taken`); one that comes due while
//! the previous is still going starts right after it. `restart` (the period changed)
//! starts the count again from the new period; `now` makes a report due at once (over a
//! `taken` in the same clock). After reset a report is due a clock later. Cost: 32 + 2
//! flip-flops, a 32-bit decrement and its zero test kept in a register.

use crate::hdl::*;

/// The status reporter's period timer.
#[derive(LogicBlock, Default)]
pub struct ReportTimer {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing due; a report comes due at the next clock.
    pub reset: Signal<In, Bit>,
    /// The period in ticks, 1 to 2^32 - 1.
    pub period_ticks: Signal<In, Bits<32>>,
    /// One clock: the period changed; the next report is due a period from then.
    pub restart: Signal<In, Bit>,
    /// One clock: a report is due now.
    pub now: Signal<In, Bit>,
    /// One clock: the reporter starts the due report.
    pub taken: Signal<In, Bit>,
    /// A report is due.
    pub due: Signal<Out, Bit>,
    count: DFF<Bits<32>>,
    // count == 0, kept in a register
    count_zero: DFF<Bit>,
    report_due: DFF<Bit>,
}

impl Logic for ReportTimer {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, count, count_zero, report_due);
        if self.count_zero.q.val() {
            self.count.d.next = self.period_ticks.val() - 1;
            self.count_zero.d.next = self.period_ticks.val() == 1;
            self.report_due.d.next = true;
        } else {
            self.count.d.next = self.count.q.val() - 1;
            self.count_zero.d.next = self.count.q.val() == 1;
        }
        // a new period counts from its change
        if self.restart.val() {
            self.count.d.next = self.period_ticks.val() - 1;
            self.count_zero.d.next = self.period_ticks.val() == 1;
        }
        if self.taken.val() {
            self.report_due.d.next = false;
        }
        // (after the take: a report asked for in the clock the last due one is taken is
        // due again)
        if self.now.val() {
            self.report_due.d.next = true;
        }
        if self.reset.val() {
            self.count.d.next = 0.into();
            self.count_zero.d.next = true;
            self.report_due.d.next = false;
        }
        self.due.next = self.report_due.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Random periods, restarts, report-now pulses, takes and resets: `due` is the timer
    /// written out here, clock for clock.
    #[test]
    fn due_every_period_until_taken_and_at_once_when_asked() {
        let mut bench = Bench::new(ReportTimer::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0x7131);
        // the model: the count, its zero test and the due flag
        let (mut count, mut zero, mut due) = (0u64, true, false);
        let mut period = 5u64;
        let mut dues = 0;
        for clock in 0..20_000u64 {
            let bits = rng.next_u64();
            if clock % 1_500 == 0 {
                period = 1 + bits % 9;
            }
            let reset = clock < 2 || clock % 4_999 == 0;
            let restart = bits >> 8 & 0xFF == 0;
            let now = bits >> 16 & 0x7F == 0;
            let taken = due && bits >> 24 & 3 == 0;
            let u = &mut bench.uut;
            u.reset.next = reset;
            u.period_ticks.next = period.into();
            u.restart.next = restart;
            u.now.next = now;
            u.taken.next = taken;
            bench.settle();
            assert_eq!(bench.uut.due.val(), due, "clock {clock}");
            dues += u64::from(due && taken);
            if zero {
                (count, zero, due) = (period - 1, period == 1, true);
            } else {
                (count, zero) = (count - 1, count == 1);
            }
            if restart {
                (count, zero) = (period - 1, period == 1);
            }
            due = (due && !taken) || now;
            if reset {
                (count, zero, due) = (0, true, false);
            }
            bench.cycle();
        }
        assert!(dues > 1_000, "{dues} reports taken");
    }

    /// Without restarts or report-now, reports taken at once come due a period apart.
    #[test]
    fn reports_taken_at_once_come_a_period_apart() {
        let mut bench = Bench::new(ReportTimer::default(), |b| &mut b.clock);
        bench.uut.period_ticks.next = 100.into();
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut taken_at = vec![];
        for clock in 0..1_000u64 {
            bench.settle();
            let due = bench.uut.due.val();
            bench.uut.taken.next = due;
            if due {
                taken_at.push(clock);
            }
            bench.cycle();
        }
        assert_eq!(taken_at, (1..1_000).step_by(100).collect::<Vec<u64>>());
    }
}
