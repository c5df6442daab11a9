//! BatchClose: whether the record batcher's filling datagram is due to close, a register
//! whose next value comes from registers only (off the batcher's accept path).
//!
//! A datagram due to close stays due until it closes (`can_close`: the other buffer is
//! free; nothing moves meanwhile). Otherwise it is due at the next record boundary: at the
//! end of this clock's beat if that beat is a record's last and the datagram is then full
//! or its time is up, or now already when it is at a boundary, full or with its time up.
//! Between a record's tick and its offset bytes (`offset_idle` low) no boundary is near.
//! Cost: one flip-flop and its LUTs.

use crate::hdl::*;

/// The batcher's close decision.
#[derive(LogicBlock, Default)]
pub struct BatchClose {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: not due.
    pub reset: Signal<In, Bit>,
    /// The datagram due now closes this clock (the other buffer is free).
    pub can_close: Signal<In, Bit>,
    /// A record beat is offered.
    pub beat_valid: Signal<In, Bit>,
    /// No offset bytes are pending.
    pub offset_idle: Signal<In, Bit>,
    /// The beat is a record's first (a record boundary).
    pub beat_zero: Signal<In, Bit>,
    /// The beat is a record's last.
    pub beat_last: Signal<In, Bit>,
    /// The filling datagram holds its last record but one: the record ending fills it.
    pub fill_at_last: Signal<In, Bit>,
    /// The filling datagram holds its most records.
    pub fill_full: Signal<In, Bit>,
    /// The filling datagram holds a record.
    pub fill_nonzero: Signal<In, Bit>,
    /// The next clock's tick is at or past the filling datagram's flush deadline.
    pub deadline_passed_next: Signal<In, Bit>,
    /// The filling datagram is due to close.
    pub due: Signal<Out, Bit>,
    close_due: DFF<Bit>,
}

impl Logic for BatchClose {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, close_due);
        if self.close_due.q.val() {
            self.close_due.d.next = !self.can_close.val();
        } else if self.beat_valid.val() {
            self.close_due.d.next = self.offset_idle.val()
                & self.beat_last.val()
                & (self.fill_at_last.val() | self.deadline_passed_next.val());
        } else {
            self.close_due.d.next = self.offset_idle.val()
                & self.beat_zero.val()
                & (self.fill_full.val()
                    | (self.fill_nonzero.val() & self.deadline_passed_next.val()));
        }
        if self.reset.val() {
            self.close_due.d.next = false;
        }
        self.due.next = self.close_due.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Every combination of inputs, in random order from random states: the next `due` is
    /// the rule written out here.
    #[test]
    fn due_at_a_record_boundary_when_full_or_late_and_until_closed() {
        let mut bench = Bench::new(BatchClose::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0xC105E);
        bench.uut.reset.next = true;
        bench.cycle();
        let mut due = false;
        for round in 0..5_000 {
            let bits = rng.next_u64();
            let bit = |k: u32| bits >> k & 1 == 1;
            let reset = round % 97 == 0;
            let (can_close, valid, idle, zero, last) = (bit(0), bit(1), bit(2), bit(3), bit(4));
            let (at_last, full, nonzero, passed) = (bit(5), bit(6), bit(7), bit(8));
            bench.uut.reset.next = reset;
            bench.uut.can_close.next = can_close;
            bench.uut.beat_valid.next = valid;
            bench.uut.offset_idle.next = idle;
            bench.uut.beat_zero.next = zero;
            bench.uut.beat_last.next = last;
            bench.uut.fill_at_last.next = at_last;
            bench.uut.fill_full.next = full;
            bench.uut.fill_nonzero.next = nonzero;
            bench.uut.deadline_passed_next.next = passed;
            bench.settle();
            assert_eq!(bench.uut.due.val(), due, "round {round}");
            due = !reset
                && if due {
                    !can_close
                } else if valid {
                    idle && last && (at_last || passed)
                } else {
                    idle && zero && (full || (nonzero && passed))
                };
            bench.cycle();
        }
    }
}
