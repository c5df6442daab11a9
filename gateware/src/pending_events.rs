//! PendingEvents: the deframing engine's choice of the one counter event it counts at a
//! port's visit: the lowest of the port's pending events and this visit's new ones.
//!
//! The port's state word keeps the events not yet counted (bit i = `PortCounter` i); at a
//! visit they are ORed with the decision's new events, the lowest set bit is counted
//! (`increment`, `lowest` its counter) and the others stay pending (`remaining`). Latency:
//! none (logic only, between the decision's registers); cost: a priority encoder over 8
//! bits.

use crate::hdl::*;

/// The event counted at a visit.
#[derive(LogicBlock, Default)]
pub struct PendingEvents {
    /// The port's events not yet counted.
    pub pending: Signal<In, Bits<8>>,
    /// This visit's new events.
    pub events: Signal<In, Bits<8>>,
    /// An event is counted.
    pub increment: Signal<Out, Bit>,
    /// Its counter: the lowest event's bit number.
    pub lowest: Signal<Out, Bits<3>>,
    /// The events still pending after this visit.
    pub remaining: Signal<Out, Bits<8>>,
    all_events: Signal<Local, Bits<8>>,
    lowest_bit: Signal<Local, Bits<8>>,
}

impl Logic for PendingEvents {
    #[hdl_gen]
    fn update(&mut self) {
        self.all_events.next = self.pending.val() | self.events.val();
        self.lowest.next = 0.into();
        self.lowest_bit.next = 0.into();
        if self.all_events.val().get_bit(0) {
            self.lowest_bit.next = 1.into();
        } else if self.all_events.val().get_bit(1) {
            self.lowest.next = 1.into();
            self.lowest_bit.next = 2.into();
        } else if self.all_events.val().get_bit(2) {
            self.lowest.next = 2.into();
            self.lowest_bit.next = 4.into();
        } else if self.all_events.val().get_bit(3) {
            self.lowest.next = 3.into();
            self.lowest_bit.next = 8.into();
        } else if self.all_events.val().get_bit(4) {
            self.lowest.next = 4.into();
            self.lowest_bit.next = 16.into();
        } else if self.all_events.val().get_bit(5) {
            self.lowest.next = 5.into();
            self.lowest_bit.next = 32.into();
        } else if self.all_events.val().get_bit(6) {
            self.lowest.next = 6.into();
            self.lowest_bit.next = 64.into();
        } else if self.all_events.val().get_bit(7) {
            self.lowest.next = 7.into();
            self.lowest_bit.next = 128.into();
        }
        self.increment.next = self.all_events.val() != 0;
        self.remaining.next = self.all_events.val() & !self.lowest_bit.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every pair of pending and new events: the lowest of their union is counted, the
    /// others remain.
    #[test]
    fn the_lowest_event_is_counted_and_the_rest_remain() {
        let mut uut = PendingEvents::default();
        uut.connect_all();
        for pending in 0..256u64 {
            for events in (0..256u64).step_by(7) {
                uut.pending.next = pending.into();
                uut.events.next = events.into();
                assert!(simulate(&mut uut, 100));
                let all = pending | events;
                assert_eq!(uut.increment.val(), all != 0);
                if all != 0 {
                    let lowest = all.trailing_zeros() as u64;
                    assert_eq!(
                        uut.lowest.val().to_u64(),
                        lowest,
                        "{pending:#x} {events:#x}"
                    );
                    assert_eq!(uut.remaining.val().to_u64(), all & !(1 << lowest));
                } else {
                    assert_eq!(uut.remaining.val().to_u64(), 0);
                }
            }
        }
    }
}
