//! DeframerDecision: the deframing engine's decision about the port it visits, from the
//! port's state and its scan word, by the rules of [`crate::cell_deframer`].
//!
//! In cycle `t + 2` of a visit the scan's outputs and the state RAMs' output registers
//! (the port's state word and its packet's start tick) go into registers, with the one
//! carry chain the truncation test needs (the idle time against the state's deadline); in
//! `t + 3` ([`DECISION_CLOCKS`]) the decision is taken from registers only; at `t + 4` the
//! new state (`state_write`), the slot write, the commit and one counter increment leave
//! registers.

use crate::decision_inputs::DecisionInputs;
pub use crate::decision_inputs::STATE_BITS;
use crate::decision_outputs::DecisionOutputs;
use crate::deframer_scan::SCAN_BITS;
use crate::geometry::TICK_BEATS;
use crate::hdl::*;
use skinbox_protocol::cell::{CellFraming, PACKET_LEN};
use skinbox_protocol::PortCounter;

/// Clocks from a port's visit to the clock of the engine's decision about it.
pub const DECISION_CLOCKS: u64 = 3;

// fields of the state word
const IN_PACKET: usize = 0;
const INDEX: usize = 1; // 5 bits: bytes of the packet so far
const ALIGNED: usize = 6;
const WRITE_SLOT: usize = 7;
const LOSS: usize = 8;
const FLAG: usize = 9;
const DROPPING: usize = 10;
const TICKS_LEFT: usize = 11; // 3 bits
const DEADLINE: usize = 14; // 12 bits: the last strobe's tick + the truncation time
const PENDING: usize = 26; // 8 bits
const _: () = assert!(PENDING + 8 == STATE_BITS);
// (the kernel below writes these positions as literals: rust-hdl puts names into Verilog)
const _: () = assert!(
    IN_PACKET == 0
        && INDEX == 1
        && ALIGNED == 6
        && WRITE_SLOT == 7
        && LOSS == 8
        && FLAG == 9
        && DROPPING == 10
        && TICKS_LEFT == 11
        && DEADLINE == 14
        && PENDING == 26
);

/// The event bit of `counter` in a port's 8-bit counter events (bit i = `PortCounter` i).
pub fn counter_bit(counter: PortCounter) -> Constant<Bits<8>> {
    Constant::new((1u64 << counter as u64).into())
}

/// The decision of the deframing engine.
#[derive(LogicBlock)]
pub struct DeframerDecision {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing written, committed or counted.
    pub reset: Signal<In, Bit>,
    /// The ports' reset: every visited port's state is cleared, nothing is written or
    /// counted.
    pub port_reset: Signal<In, Bit>,
    /// The scan's port (cycle `t + 2`).
    pub port: Signal<In, Bits<6>>,
    /// Its scan word.
    pub sampled: Signal<In, Bits<SCAN_BITS>>,
    /// The tick its idle time runs to.
    pub idle_end: Signal<In, Bits<12>>,
    /// The byte's deadline.
    pub deadline: Signal<In, Bits<12>>,
    /// The byte's start tick.
    pub start_tick: Signal<In, Bits<32>>,
    /// The port's state word (the state RAM's output register).
    pub state_read: Signal<In, Bits<STATE_BITS>>,
    /// The port's packet's start tick (the tick RAM's output register).
    pub tick_read: Signal<In, Bits<32>>,
    /// Write the state RAMs: `state_data` and `tick_data` at `state_port`.
    pub state_write: Signal<Out, Bit>,
    /// The port of the state write.
    pub state_port: Signal<Out, Bits<6>>,
    /// The new state word.
    pub state_data: Signal<Out, Bits<STATE_BITS>>,
    /// The new start tick (shifted a byte at each tick word written).
    pub tick_data: Signal<Out, Bits<32>>,
    /// A word goes into the store: port, slot and word, data with the loss flag in bit 8.
    pub write: Signal<Out, Bit>,
    /// Port of the word.
    pub write_port: Signal<Out, Bits<6>>,
    /// Slot of the word.
    pub write_slot: Signal<Out, Bit>,
    /// Word in the slot: 0-3 start tick, 4-23 cell bytes.
    pub write_word: Signal<Out, Bits<5>>,
    /// The word.
    pub write_data: Signal<Out, Bits<9>>,
    /// The packet of the port decided two clocks ago (`port` at `t + 4`) is complete.
    pub commit: Signal<Out, Bit>,
    /// Count one event: counter `increment_address` (port x 8 + `PortCounter`).
    pub increment: Signal<Out, Bit>,
    /// The counter to increment.
    pub increment_address: Signal<Out, Bits<9>>,
    last_index: Constant<Bits<5>>,
    tick_words: Constant<Bits<5>>,
    // the decision's input registers (cycle t + 3)
    visit: DecisionInputs,
    // the decision's output registers (cycle t + 4)
    decision_out: DecisionOutputs,
    // the decision
    state: Signal<Local, Bits<STATE_BITS>>,
    next: Signal<Local, Bits<STATE_BITS>>,
    held_byte: Signal<Local, Bits<8>>,
    held_now: Signal<Local, Bit>,
    byte_error: Signal<Local, Bit>,
    full: Signal<Local, Bit>,
    truncate: Signal<Local, Bit>,
    in_packet: Signal<Local, Bit>,
    aligned: Signal<Local, Bit>,
    loss: Signal<Local, Bit>,
    index: Signal<Local, Bits<5>>,
    ticks_left: Signal<Local, Bits<3>>,
    events: Signal<Local, Bits<8>>,
    n_in_packet: Signal<Local, Bit>,
    n_index: Signal<Local, Bits<5>>,
    n_aligned: Signal<Local, Bit>,
    n_write_slot: Signal<Local, Bit>,
    n_loss: Signal<Local, Bit>,
    n_flag: Signal<Local, Bit>,
    n_dropping: Signal<Local, Bit>,
    n_ticks_left: Signal<Local, Bits<3>>,
    n_last: Signal<Local, Bits<12>>,
    n_tick: Signal<Local, Bits<32>>,
    word_write: Signal<Local, Bit>,
    word: Signal<Local, Bits<5>>,
    word_data: Signal<Local, Bits<8>>,
    commit_now: Signal<Local, Bit>,
    good_event: Constant<Bits<8>>,
    dropped_event: Constant<Bits<8>>,
    end_byte_event: Constant<Bits<8>>,
    framing_event: Constant<Bits<8>>,
    truncated_event: Constant<Bits<8>>,
    garbage_event: Constant<Bits<8>>,
    framing_error_event: Constant<Bits<8>>,
    resync_event: Constant<Bits<8>>,
}

impl DeframerDecision {
    /// The decision for `framing`.
    pub fn new(framing: CellFraming) -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            port_reset: Default::default(),
            port: Default::default(),
            sampled: Default::default(),
            idle_end: Default::default(),
            deadline: Default::default(),
            start_tick: Default::default(),
            state_read: Default::default(),
            tick_read: Default::default(),
            state_write: Default::default(),
            state_port: Default::default(),
            state_data: Default::default(),
            tick_data: Default::default(),
            write: Default::default(),
            write_port: Default::default(),
            write_slot: Default::default(),
            write_word: Default::default(),
            write_data: Default::default(),
            commit: Default::default(),
            increment: Default::default(),
            increment_address: Default::default(),
            last_index: Constant::new((PACKET_LEN as u64 - 1).into()),
            tick_words: Constant::new((TICK_BEATS as u64).into()),
            visit: DecisionInputs::new(framing),
            decision_out: Default::default(),
            state: Default::default(),
            next: Default::default(),
            held_byte: Default::default(),
            held_now: Default::default(),
            byte_error: Default::default(),
            full: Default::default(),
            truncate: Default::default(),
            in_packet: Default::default(),
            aligned: Default::default(),
            loss: Default::default(),
            index: Default::default(),
            ticks_left: Default::default(),
            events: Default::default(),
            n_in_packet: Default::default(),
            n_index: Default::default(),
            n_aligned: Default::default(),
            n_write_slot: Default::default(),
            n_loss: Default::default(),
            n_flag: Default::default(),
            n_dropping: Default::default(),
            n_ticks_left: Default::default(),
            n_last: Default::default(),
            n_tick: Default::default(),
            word_write: Default::default(),
            word: Default::default(),
            word_data: Default::default(),
            commit_now: Default::default(),
            good_event: counter_bit(PortCounter::PacketsGood),
            dropped_event: counter_bit(PortCounter::DroppedOverflow),
            end_byte_event: counter_bit(PortCounter::RejectedEndByte),
            framing_event: counter_bit(PortCounter::RejectedFraming),
            truncated_event: counter_bit(PortCounter::RejectedTruncated),
            garbage_event: counter_bit(PortCounter::GarbageBytes),
            framing_error_event: counter_bit(PortCounter::FramingErrors),
            resync_event: counter_bit(PortCounter::Resyncs),
        }
    }
}

impl Logic for DeframerDecision {
    #[hdl_gen]
    fn update(&mut self) {
        // cycle t + 2: into the decision's input registers, with the truncation test (the
        // one carry chain) and the header and end-of-packet tests
        self.visit.clock.next = self.clock.val();
        self.visit.port.next = self.port.val();
        self.visit.sampled.next = self.sampled.val();
        self.visit.idle_end.next = self.idle_end.val();
        self.visit.deadline.next = self.deadline.val();
        self.visit.start_tick.next = self.start_tick.val();
        self.visit.state_read.next = self.state_read.val();
        self.visit.tick_read.next = self.tick_read.val();

        // cycle t + 3: the decision, from registers only
        self.state.next = self.visit.held_state.val();
        self.held_byte.next = self.visit.held_sampled.val().get_bits::<8>(0);
        self.held_now.next = self.visit.held_sampled.val().get_bit(16);
        self.byte_error.next = self.visit.held_sampled.val().get_bit(15);
        self.full.next = self.visit.held_sampled.val().get_bit(17);
        self.truncate.next = self.visit.truncate.val();
        self.in_packet.next = self.state.val().get_bit(0) & !self.truncate.val();
        self.aligned.next = self.state.val().get_bit(6) & !self.truncate.val();
        self.loss.next = self.state.val().get_bit(8) | self.truncate.val();
        self.index.next = self.state.val().get_bits::<5>(1);
        self.ticks_left.next = self.state.val().get_bits::<3>(11);
        // the next state, by default the same
        self.n_in_packet.next = self.in_packet.val();
        self.n_index.next = self.index.val();
        self.n_aligned.next = self.aligned.val();
        self.n_write_slot.next = self.state.val().get_bit(7);
        self.n_loss.next = self.loss.val();
        self.n_flag.next = self.state.val().get_bit(9);
        self.n_dropping.next = self.state.val().get_bit(10);
        self.n_ticks_left.next = self.ticks_left.val();
        self.n_last.next = self.state.val().get_bits::<12>(14);
        self.n_tick.next = self.visit.held_tick.val();
        self.events.next = 0.into();
        self.word_write.next = false;
        self.word.next = bit_cast::<5, 3>(self.ticks_left.val());
        self.word_data.next = self.held_byte.val();
        self.commit_now.next = false;
        if self.truncate.val() {
            self.events.next = self.truncated_event.val() | self.resync_event.val();
        }
        if self.held_now.val() {
            self.n_last.next = self.visit.held_deadline.val();
            if self.byte_error.val() {
                self.events.next = self.events.val() | self.framing_error_event.val();
            }
            if !self.in_packet.val() {
                if self.visit.header.val() {
                    self.n_in_packet.next = true;
                    self.n_index.next = 1.into();
                    self.n_dropping.next = self.full.val();
                    self.n_flag.next = self.loss.val();
                    self.n_ticks_left.next = 4.into();
                    self.n_tick.next = self.visit.held_start_tick.val();
                    self.word_write.next = !self.full.val();
                    self.word.next = 4.into();
                } else {
                    self.events.next = self.events.val() | self.garbage_event.val();
                    if self.aligned.val() {
                        self.events.next = self.events.val() | self.resync_event.val();
                    }
                    self.n_aligned.next = false;
                }
            } else {
                self.word_write.next = !self.state.val().get_bit(10);
                self.word.next = self.index.val() + 4;
                self.n_index.next = self.index.val() + 1;
                if self.byte_error.val() {
                    self.n_in_packet.next = false;
                    self.n_aligned.next = false;
                    self.n_loss.next = true;
                    self.events.next =
                        self.events.val() | self.framing_event.val() | self.resync_event.val();
                } else if self.index.val() == self.last_index.val() {
                    self.n_in_packet.next = false;
                    if self.visit.end_byte.val() {
                        self.n_aligned.next = true;
                        self.events.next = self.events.val() | self.good_event.val();
                        if self.state.val().get_bit(10) {
                            self.events.next = self.events.val() | self.dropped_event.val();
                            self.n_loss.next = true;
                        } else {
                            self.commit_now.next = true;
                            self.n_write_slot.next = !self.state.val().get_bit(7);
                            self.n_loss.next = false;
                        }
                    } else {
                        self.n_aligned.next = false;
                        self.n_loss.next = true;
                        self.events.next =
                            self.events.val() | self.end_byte_event.val() | self.resync_event.val();
                    }
                }
            }
        } else if (self.ticks_left.val() != 0) & !self.state.val().get_bit(10) {
            // a start tick byte, most significant first, at a visit without a byte
            self.word_write.next = true;
            self.word.next = self.tick_words.val() - bit_cast::<5, 3>(self.ticks_left.val());
            self.word_data.next = self.visit.held_tick.val().get_bits::<8>(24);
            self.n_tick.next = self.visit.held_tick.val() << 8;
            self.n_ticks_left.next = self.ticks_left.val() - 1;
        }
        self.next.next = bit_cast::<STATE_BITS, 1>(self.n_in_packet.val().into())
            | (bit_cast::<STATE_BITS, 5>(self.n_index.val()) << 1)
            | (bit_cast::<STATE_BITS, 1>(self.n_aligned.val().into()) << 6)
            | (bit_cast::<STATE_BITS, 1>(self.n_write_slot.val().into()) << 7)
            | (bit_cast::<STATE_BITS, 1>(self.n_loss.val().into()) << 8)
            | (bit_cast::<STATE_BITS, 1>(self.n_flag.val().into()) << 9)
            | (bit_cast::<STATE_BITS, 1>(self.n_dropping.val().into()) << 10)
            | (bit_cast::<STATE_BITS, 3>(self.n_ticks_left.val()) << 11)
            | (bit_cast::<STATE_BITS, 12>(self.n_last.val()) << 14);
        // the decision's registers (the ports' reset clears each visited port's state)
        self.decision_out.clock.next = self.clock.val();
        self.decision_out.reset.next = self.reset.val();
        self.decision_out.port_reset.next = self.port_reset.val();
        self.decision_out.port.next = self.visit.held_port.val();
        self.decision_out.next_state.next = self.next.val();
        self.decision_out.next_tick.next = self.n_tick.val();
        self.decision_out.word_write.next = self.word_write.val();
        self.decision_out.slot.next = self.state.val().get_bit(7);
        self.decision_out.word.next = self.word.val();
        self.decision_out.word_data.next = bit_cast::<9, 8>(self.word_data.val())
            | (bit_cast::<9, 1>(self.n_flag.val().into()) << 8);
        self.decision_out.commit_now.next = self.commit_now.val();
        // one pending event counted per visit: the lowest (the others stay in the state)
        self.decision_out.pending.next = self.state.val().get_bits::<8>(26);
        self.decision_out.events.next = self.events.val();
        self.state_write.next = self.decision_out.state_write.val();
        self.state_port.next = self.decision_out.state_port.val();
        self.state_data.next = self.decision_out.state_data.val();
        self.tick_data.next = self.decision_out.tick_data.val();
        self.write.next = self.decision_out.write.val();
        self.write_port.next = self.decision_out.write_port.val();
        self.write_slot.next = self.decision_out.write_slot.val();
        self.write_word.next = self.decision_out.write_word.val();
        self.write_data.next = self.decision_out.write_data.val();
        self.commit.next = self.decision_out.commit.val();
        self.increment.next = self.decision_out.increment.val();
        self.increment_address.next = self.decision_out.increment_address.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::deframer_scan::{SCAN_FRAMING_ERROR, SCAN_HELD};
    use crate::testbench::Bench;
    use std::collections::HashMap;

    /// What the decision did to one port over a run.
    #[derive(Default)]
    struct Outcome {
        /// (word, byte, loss flag) written into the store.
        words: Vec<(u32, u8, bool)>,
        commits: u32,
        counted: HashMap<u32, u32>,
    }

    /// Visits port 3 every fifth clock (other ports, without bytes, between), with the
    /// bytes `script` (byte, framing error; `None`: no byte), the state RAMs emulated here.
    fn run(script: &[Option<(u8, bool)>], start_tick: u32) -> Outcome {
        let mut bench = Bench::new(DeframerDecision::new(CellFraming::DEFAULT), |b| {
            &mut b.clock
        });
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut ram: HashMap<u64, (u64, u64)> = HashMap::new();
        let mut outcome = Outcome::default();
        let mut script = script.iter();
        for clock in 0u64.. {
            let now = 10_000 + clock;
            let port = if clock % 5 == 0 { 3 } else { 8 + clock % 5 };
            let byte = if port == 3 {
                script.next()
            } else {
                Some(&None)
            };
            let Some(byte) = byte else { break };
            let sampled = byte.map_or(0, |(b, error)| {
                u64::from(b) | 1 << SCAN_HELD | u64::from(error) << SCAN_FRAMING_ERROR
            });
            let (state, tick) = ram.get(&port).copied().unwrap_or_default();
            let uut = &mut bench.uut;
            uut.port.next = port.into();
            uut.sampled.next = sampled.into();
            uut.idle_end.next = (now & 0xFFF).into();
            uut.deadline.next = ((now + 2_000) & 0xFFF).into();
            uut.start_tick.next = u64::from(start_tick).into();
            uut.state_read.next = state.into();
            uut.tick_read.next = tick.into();
            bench.cycle();
            let uut = &bench.uut;
            if uut.state_write.val() {
                let at = uut.state_port.val().to_u64();
                ram.insert(
                    at,
                    (uut.state_data.val().to_u64(), uut.tick_data.val().to_u64()),
                );
            }
            let decided = uut.write_port.val().to_u64();
            if uut.write.val() && decided == 3 {
                let data = uut.write_data.val().to_u32();
                outcome
                    .words
                    .push((uut.write_word.val().to_u32(), data as u8, data >> 8 == 1));
            }
            if uut.commit.val() {
                outcome.commits += 1;
            }
            if uut.increment.val() {
                *outcome
                    .counted
                    .entry(uut.increment_address.val().to_u32())
                    .or_default() += 1;
            }
        }
        outcome
    }

    fn counted(outcome: &Outcome, counter: PortCounter) -> u32 {
        let address = 3 * 8 + counter as u32;
        outcome.counted.get(&address).copied().unwrap_or(0)
    }

    /// Garbage, then a good packet: the packet's bytes are words 4 to 23 of slot 0, its
    /// start tick words 0 to 3 (most significant first) at the visits without a byte, one
    /// commit; then a packet cut by a framing error. Every event is counted once.
    #[test]
    fn garbage_a_good_packet_and_a_framing_error() {
        let framing = CellFraming::DEFAULT;
        let mut packet = [0u8; PACKET_LEN];
        packet[0] = framing.data_header;
        for (i, b) in packet.iter_mut().enumerate().skip(1) {
            *b = (i * 7) as u8;
        }
        packet[PACKET_LEN - 1] = framing.end_of_packet;
        let mut script = vec![Some((0x00, false))];
        script.push(Some((packet[0], false)));
        script.extend([None; 4]);
        script.extend(packet[1..].iter().map(|&b| Some((b, false))));
        script.extend([
            Some((framing.event_header, false)),
            Some((1, false)),
            Some((2, true)),
        ]);
        script.extend([None; 12]);
        let start_tick = 0x1234_5678;
        let outcome = run(&script, start_tick);
        let mut expected: Vec<(u32, u8, bool)> = vec![(4, packet[0], false)];
        expected.extend(
            start_tick
                .to_be_bytes()
                .iter()
                .enumerate()
                .map(|(i, &b)| (i as u32, b, false)),
        );
        expected.extend(
            packet[1..]
                .iter()
                .enumerate()
                .map(|(i, &b)| (5 + i as u32, b, false)),
        );
        // the second packet goes into slot 1: its header, its tick and the byte before the
        // error
        let written: Vec<(u32, u8, bool)> = outcome.words[..expected.len()].to_vec();
        assert_eq!(written, expected);
        assert_eq!(outcome.commits, 1);
        assert_eq!(counted(&outcome, PortCounter::GarbageBytes), 1);
        assert_eq!(counted(&outcome, PortCounter::PacketsGood), 1);
        assert_eq!(counted(&outcome, PortCounter::FramingErrors), 1);
        assert_eq!(counted(&outcome, PortCounter::RejectedFraming), 1);
        assert_eq!(counted(&outcome, PortCounter::Resyncs), 1);
        let total: u32 = outcome.counted.values().sum();
        assert_eq!(total, 5, "no other event");
    }
}
