//! DecisionInputs: the deframing engine's decision's input registers (cycle `t + 2` of a
//! visit): the scan's port, word, deadline and start tick and the state RAMs' outputs
//! registered, with the three tests the decision needs precomputed: the truncation test
//! (the one carry chain: the idle time against the state's deadline, signed), whether the
//! byte is a header byte (data or event, without a framing error) and whether it is the
//! end-of-packet byte.
//!
//! Latency 1: the outputs are the inputs of the clock before. Cost: the registers (6 + 34 +
//! 32 + scan word + 12 + 32 bits and three flags), a 12-bit subtractor, three 8-bit
//! compares.

use crate::deframer_scan::SCAN_BITS;
use crate::hdl::*;
use skinbox_protocol::cell::CellFraming;

/// Bits of the per-port state word.
pub const STATE_BITS: usize = 34;

/// The decision's input registers.
#[derive(LogicBlock)]
pub struct DecisionInputs {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// The scan's port.
    pub port: Signal<In, Bits<6>>,
    /// Its scan word.
    pub sampled: Signal<In, Bits<SCAN_BITS>>,
    /// The tick its idle time runs to.
    pub idle_end: Signal<In, Bits<12>>,
    /// The byte's deadline.
    pub deadline: Signal<In, Bits<12>>,
    /// The byte's start tick.
    pub start_tick: Signal<In, Bits<32>>,
    /// The port's state word.
    pub state_read: Signal<In, Bits<STATE_BITS>>,
    /// The port's packet's start tick.
    pub tick_read: Signal<In, Bits<32>>,
    /// The port, registered.
    pub held_port: Signal<Out, Bits<6>>,
    /// The state word, registered.
    pub held_state: Signal<Out, Bits<STATE_BITS>>,
    /// The packet's start tick, registered.
    pub held_tick: Signal<Out, Bits<32>>,
    /// The scan word, registered.
    pub held_sampled: Signal<Out, Bits<SCAN_BITS>>,
    /// The port is in a packet whose deadline passed: the packet is truncated.
    pub truncate: Signal<Out, Bit>,
    /// The byte is a header byte (data or event) without a framing error.
    pub header: Signal<Out, Bit>,
    /// The byte is the end-of-packet byte.
    pub end_byte: Signal<Out, Bit>,
    /// The byte's deadline, registered.
    pub held_deadline: Signal<Out, Bits<12>>,
    /// The byte's start tick, registered.
    pub held_start_tick: Signal<Out, Bits<32>>,
    data_header: Constant<Bits<8>>,
    event_header: Constant<Bits<8>>,
    end_of_packet: Constant<Bits<8>>,
    a_port: DFF<Bits<6>>,
    a_state: DFF<Bits<STATE_BITS>>,
    a_tick: DFF<Bits<32>>,
    a_sampled: DFF<Bits<SCAN_BITS>>,
    a_truncate: DFF<Bit>,
    a_header: DFF<Bit>,
    a_end: DFF<Bit>,
    a_deadline: DFF<Bits<12>>,
    a_start_tick: DFF<Bits<32>>,
    idle: Signal<Local, Bits<12>>,
}

impl DecisionInputs {
    /// The input registers for `framing`.
    pub fn new(framing: CellFraming) -> Self {
        Self {
            clock: Default::default(),
            port: Default::default(),
            sampled: Default::default(),
            idle_end: Default::default(),
            deadline: Default::default(),
            start_tick: Default::default(),
            state_read: Default::default(),
            tick_read: Default::default(),
            held_port: Default::default(),
            held_state: Default::default(),
            held_tick: Default::default(),
            held_sampled: Default::default(),
            truncate: Default::default(),
            header: Default::default(),
            end_byte: Default::default(),
            held_deadline: Default::default(),
            held_start_tick: Default::default(),
            data_header: constant(u64::from(framing.data_header)),
            event_header: constant(u64::from(framing.event_header)),
            end_of_packet: constant(u64::from(framing.end_of_packet)),
            a_port: Default::default(),
            a_state: Default::default(),
            a_tick: Default::default(),
            a_sampled: Default::default(),
            a_truncate: Default::default(),
            a_header: Default::default(),
            a_end: Default::default(),
            a_deadline: Default::default(),
            a_start_tick: Default::default(),
            idle: Default::default(),
        }
    }
}

impl Logic for DecisionInputs {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            a_port,
            a_state,
            a_tick,
            a_sampled,
            a_truncate,
            a_header,
            a_end,
            a_deadline,
            a_start_tick
        );
        // idle: now (with a byte held, its strobe) - deadline, signed: one carry chain from
        // the RAM's output register
        self.idle.next = self.idle_end.val() - self.state_read.val().get_bits::<12>(14);
        self.a_port.d.next = self.port.val();
        self.a_state.d.next = self.state_read.val();
        self.a_tick.d.next = self.tick_read.val();
        self.a_sampled.d.next = self.sampled.val();
        self.a_truncate.d.next = self.state_read.val().get_bit(0) & !self.idle.val().get_bit(11);
        self.a_header.d.next = !self.sampled.val().get_bit(15)
            & ((self.sampled.val().get_bits::<8>(0) == self.data_header.val())
                | (self.sampled.val().get_bits::<8>(0) == self.event_header.val()));
        self.a_end.d.next = self.sampled.val().get_bits::<8>(0) == self.end_of_packet.val();
        self.a_deadline.d.next = self.deadline.val();
        self.a_start_tick.d.next = self.start_tick.val();
        self.held_port.next = self.a_port.q.val();
        self.held_state.next = self.a_state.q.val();
        self.held_tick.next = self.a_tick.q.val();
        self.held_sampled.next = self.a_sampled.q.val();
        self.truncate.next = self.a_truncate.q.val();
        self.header.next = self.a_header.q.val();
        self.end_byte.next = self.a_end.q.val();
        self.held_deadline.next = self.a_deadline.q.val();
        self.held_start_tick.next = self.a_start_tick.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Random visits: a clock later the inputs are held, a port in a packet is truncated
    /// when its idle time reached its deadline (mod 4096, signed), the header and end
    /// tests are the framing's.
    #[test]
    fn visits_are_registered_with_their_tests() {
        let framing = CellFraming::DEFAULT;
        let mut rng = TestRng::new(0xDEC);
        let mut bench = Bench::new(DecisionInputs::new(framing), |b| &mut b.clock);
        for round in 0..500 {
            let special = [
                framing.data_header,
                framing.event_header,
                framing.end_of_packet,
            ];
            let byte = if rng.chance(0.5) {
                special[rng.next_u64() as usize % 3]
            } else {
                rng.byte()
            };
            let error = rng.chance(0.2);
            let sampled = u64::from(byte) | u64::from(error) << 15 | (rng.next_u64() & (0x3 << 16));
            let state = rng.next_u64() & ((1 << STATE_BITS) - 1);
            let idle_end = rng.next_u64() & 0xFFF;
            let (port, tick, deadline, start) = (
                rng.next_u64() & 63,
                rng.next_u64() as u32,
                rng.next_u64() & 0xFFF,
                rng.next_u64() as u32,
            );
            let u = &mut bench.uut;
            u.port.next = port.into();
            u.sampled.next = sampled.into();
            u.idle_end.next = idle_end.into();
            u.deadline.next = deadline.into();
            u.start_tick.next = u64::from(start).into();
            u.state_read.next = state.into();
            u.tick_read.next = u64::from(tick).into();
            bench.cycle();
            let u = &bench.uut;
            assert_eq!(u.held_port.val().to_u64(), port);
            assert_eq!(u.held_state.val().to_u64(), state);
            assert_eq!(u.held_tick.val().to_u64(), u64::from(tick));
            assert_eq!(u.held_sampled.val().to_u64(), sampled);
            assert_eq!(u.held_deadline.val().to_u64(), deadline);
            assert_eq!(u.held_start_tick.val().to_u64(), u64::from(start));
            let state_deadline = (state >> 14) & 0xFFF;
            let idle = idle_end.wrapping_sub(state_deadline) & 0xFFF;
            let reached = idle < 0x800;
            assert_eq!(u.truncate.val(), state & 1 == 1 && reached, "round {round}");
            let header = byte == framing.data_header || byte == framing.event_header;
            assert_eq!(u.header.val(), header && !error, "round {round}");
            assert_eq!(
                u.end_byte.val(),
                byte == framing.end_of_packet,
                "round {round}"
            );
        }
    }
}
