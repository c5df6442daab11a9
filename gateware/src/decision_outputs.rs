//! DecisionOutputs: the deframing engine's decision's output registers (cycle `t + 4` of a
//! visit): the new state word and start tick for the state RAMs, the store's word write,
//! the commit and the counter increment.
//!
//! The state is written back at every visit, with the events still pending after the one
//! counted ([`PendingEvents`]: the lowest of the pending and the new ones); the ports' reset (`port_reset`) clears the
//! visited port's state and writes, commits and counts nothing; the reset clears the
//! write strobes. Latency 1: the outputs are the decision of the clock before. Cost: the
//! registers (about 100 bits), the event's priority encoder and the masks.

use crate::decision_inputs::STATE_BITS;
use crate::hdl::*;
use crate::pending_events::PendingEvents;

/// The decision's output registers.
#[derive(LogicBlock, Default)]
pub struct DecisionOutputs {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing written, committed or counted.
    pub reset: Signal<In, Bit>,
    /// The ports' reset: the visited port's state cleared, nothing written or counted.
    pub port_reset: Signal<In, Bit>,
    /// The visited port.
    pub port: Signal<In, Bits<6>>,
    /// Its new state word but the pending events (0 there).
    pub next_state: Signal<In, Bits<STATE_BITS>>,
    /// Its new start tick.
    pub next_tick: Signal<In, Bits<32>>,
    /// A word goes into the store.
    pub word_write: Signal<In, Bit>,
    /// Its slot.
    pub slot: Signal<In, Bit>,
    /// Its place in the slot.
    pub word: Signal<In, Bits<5>>,
    /// Its data (the loss flag in bit 8).
    pub word_data: Signal<In, Bits<9>>,
    /// The port's packet is complete.
    pub commit_now: Signal<In, Bit>,
    /// The port's events not yet counted (the state word's pending events).
    pub pending: Signal<In, Bits<8>>,
    /// This visit's new events.
    pub events: Signal<In, Bits<8>>,
    /// Write the state RAMs.
    pub state_write: Signal<Out, Bit>,
    /// The port of the state write.
    pub state_port: Signal<Out, Bits<6>>,
    /// The new state word.
    pub state_data: Signal<Out, Bits<STATE_BITS>>,
    /// The new start tick.
    pub tick_data: Signal<Out, Bits<32>>,
    /// A word goes into the store.
    pub write: Signal<Out, Bit>,
    /// Port of the word.
    pub write_port: Signal<Out, Bits<6>>,
    /// Slot of the word.
    pub write_slot: Signal<Out, Bit>,
    /// Word in the slot.
    pub write_word: Signal<Out, Bits<5>>,
    /// The word.
    pub write_data: Signal<Out, Bits<9>>,
    /// The port's packet is complete.
    pub commit: Signal<Out, Bit>,
    /// Count one event.
    pub increment: Signal<Out, Bit>,
    /// The counter to increment: port x 8 + counter.
    pub increment_address: Signal<Out, Bits<9>>,
    state_write_out: DFF<Bit>,
    state_port_out: DFF<Bits<6>>,
    state_next: DFF<Bits<STATE_BITS>>,
    tick_next: DFF<Bits<32>>,
    write_out: DFF<Bit>,
    write_port_out: DFF<Bits<6>>,
    write_slot_out: DFF<Bit>,
    write_word_out: DFF<Bits<5>>,
    write_data_out: DFF<Bits<9>>,
    commit_out: DFF<Bit>,
    increment_out: DFF<Bit>,
    increment_address_out: DFF<Bits<9>>,
    // the event counted, the others left pending
    pending_events: PendingEvents,
}

impl Logic for DecisionOutputs {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            state_write_out,
            state_port_out,
            state_next,
            tick_next,
            write_out,
            write_port_out,
            write_slot_out,
            write_word_out,
            write_data_out,
            commit_out,
            increment_out,
            increment_address_out
        );
        self.state_write_out.d.next = true;
        self.state_port_out.d.next = self.port.val();
        self.pending_events.pending.next = self.pending.val();
        self.pending_events.events.next = self.events.val();
        self.state_next.d.next = self.next_state.val()
            | (bit_cast::<STATE_BITS, 8>(self.pending_events.remaining.val()) << 26);
        self.tick_next.d.next = self.next_tick.val();
        self.write_out.d.next = self.word_write.val() & !self.port_reset.val();
        self.write_port_out.d.next = self.port.val();
        self.write_slot_out.d.next = self.slot.val();
        self.write_word_out.d.next = self.word.val();
        self.write_data_out.d.next = self.word_data.val();
        self.commit_out.d.next = self.commit_now.val() & !self.port_reset.val();
        self.increment_out.d.next = self.pending_events.increment.val() & !self.port_reset.val();
        self.increment_address_out.d.next = (bit_cast::<9, 6>(self.port.val()) << 3)
            | bit_cast::<9, 3>(self.pending_events.lowest.val());
        if self.port_reset.val() {
            self.state_next.d.next = 0.into();
            self.tick_next.d.next = 0.into();
        }
        self.state_write.next = self.state_write_out.q.val();
        self.state_port.next = self.state_port_out.q.val();
        self.state_data.next = self.state_next.q.val();
        self.tick_data.next = self.tick_next.q.val();
        self.write.next = self.write_out.q.val();
        self.write_port.next = self.write_port_out.q.val();
        self.write_slot.next = self.write_slot_out.q.val();
        self.write_word.next = self.write_word_out.q.val();
        self.write_data.next = self.write_data_out.q.val();
        self.commit.next = self.commit_out.q.val();
        self.increment.next = self.increment_out.q.val();
        self.increment_address.next = self.increment_address_out.q.val();
        if self.reset.val() {
            self.state_write_out.d.next = false;
            self.write_out.d.next = false;
            self.commit_out.d.next = false;
            self.increment_out.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Random decisions, some under the ports' reset: a clock later they are at the
    /// outputs, the state cleared and nothing written, committed or counted under the
    /// ports' reset; nothing at all after the reset.
    #[test]
    fn decisions_leave_registered_and_masked() {
        let mut rng = TestRng::new(0x0D0);
        let mut bench = Bench::new(DecisionOutputs::default(), |b| &mut b.clock);
        for round in 0..300 {
            let port_reset = rng.chance(0.2);
            let (port, state, tick) = (
                rng.next_u64() & 63,
                rng.next_u64() & ((1 << 26) - 1),
                rng.next_u64() & 0xFFFF_FFFF,
            );
            let flags: [bool; 3] = std::array::from_fn(|_| rng.chance(0.5));
            let (word, data) = (rng.next_u64() & 31, rng.next_u64() & 511);
            let pending = rng.next_u64() & 0xFF & !(rng.next_u64() & 0xFF);
            let events = rng.next_u64() & 0xFF & !(rng.next_u64() & 0xFF);
            let u = &mut bench.uut;
            u.reset.next = round == 0;
            u.port_reset.next = port_reset;
            u.port.next = port.into();
            u.next_state.next = state.into();
            u.next_tick.next = tick.into();
            u.word_write.next = flags[0];
            u.slot.next = flags[1];
            u.word.next = word.into();
            u.word_data.next = data.into();
            u.commit_now.next = flags[2];
            u.pending.next = pending.into();
            u.events.next = events.into();
            bench.cycle();
            let u = &bench.uut;
            let live = round != 0;
            let kept = live && !port_reset;
            assert_eq!(u.state_write.val(), live, "round {round}");
            assert_eq!(u.state_port.val().to_u64(), port);
            // the lowest event counted, the others pending in the state word
            let all = pending | events;
            let lowest = u64::from(all.trailing_zeros() % 8);
            let remaining = all & !(1 << lowest);
            let (want_state, want_tick) = if port_reset {
                (0, 0)
            } else {
                (state | remaining << 26, tick)
            };
            assert_eq!(u.state_data.val().to_u64(), want_state, "round {round}");
            assert_eq!(u.tick_data.val().to_u64(), want_tick, "round {round}");
            assert_eq!(u.write.val(), kept && flags[0], "round {round}");
            assert_eq!(u.write_port.val().to_u64(), port);
            assert_eq!(u.write_slot.val(), flags[1]);
            assert_eq!(u.write_word.val().to_u64(), word);
            assert_eq!(u.write_data.val().to_u64(), data);
            assert_eq!(u.commit.val(), kept && flags[2], "round {round}");
            assert_eq!(u.increment.val(), kept && all != 0, "round {round}");
            if all != 0 {
                assert_eq!(u.increment_address.val().to_u64(), port << 3 | lowest);
            }
        }
    }
}
