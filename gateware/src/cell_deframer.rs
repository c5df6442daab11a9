//! CellDeframer: one engine that finds the cell packets of every port, writes them into
//! the packet store's slots and counts what it rejects.
//!
//! The ports' [`UartRx`](crate::uart_rx::UartRx) receivers only sample bits; each holds a
//! finished byte with the low bits of its strobe tick. The engine visits one port per
//! clock, round robin over [`scan_period`] positions (port `p` in the cycles `c` with
//! `(c - tick 0's cycle) mod P = p`), and keeps every port's deframing state in block RAM:
//!
//! - cycle `t`: the visited port's receiver outputs (held, byte, framing error, stamp) and
//!   its store occupancy (both slots full) go into the register of its group of eight
//!   ports, and its receiver drops `held`; the port's state is read from RAM;
//! - `t + 1`: the groups' registers into one register, with the byte's age from its stamp
//!   and the tick its idle time runs to (its strobe, or now without a byte);
//! - `t + 2`: the arithmetic (the idle time, the deadline, the start tick) from registers
//!   and the RAM's output register, into registers;
//! - `t + 3` ([`DECISION_CLOCKS`]): the decision, from registers only; at `t + 4` the new
//!   state, the slot write, the commit and one counter increment leave registers (the
//!   state is written back at `t + 5`, before the port's next visit: the period is at
//!   least five).
//!
//! The rules, per port: hunting, every byte that is not a data or event header is garbage.
//! After a header the engine collects 19 more bytes; the packet is good when the 20th byte
//! is the end-of-packet value. A byte with a framing error inside a packet rejects it. A
//! packet is truncated when no byte of it completes within `10 + idle_gap_bits` bit times
//! of the previous one (the line was idle at least `idle_gap_bits` bit times): at the first
//! visit that sees that much time since the last strobe, or at the visit of a late byte,
//! which then starts afresh. A packet's start tick is its header's strobe tick less the
//! receiver's fixed latency ([`bit_middles`]`[9]`): the tick of the first clock edge that
//! sampled its start bit low.
//!
//! Store writes: a good header takes the port's next slot unless both are full (then the
//! whole packet is dropped and `dropped_overflow` counted at its end); the header and each
//! byte are written at their visit (words 4 to 23 of the slot), the four start tick bytes
//! (words 0 to 3, most significant first) at the port's next visits without a byte, long
//! before the 20th byte. Every word carries the packet's loss flag (bit 8): packets of the
//! port were rejected or dropped since its previous stored packet. A good packet is
//! committed (`commit_ports`) at its 20th byte's decision.
//!
//! Counter events (bits in `skinbox_protocol::PortCounter` order) join the port's pending
//! bits in its state; each visit sends the lowest pending bit to the counter file as one
//! increment. A visit raises at most four events and a byte comes at most every
//! 298 clocks, so with P <= 64 every event is counted before its bit can be raised again
//! (`BoxConfig::validate`).
//!
//! The engine is two blocks: [`DeframerScan`] (the visit and the times from the box time,
//! cycles `t` to `t + 2`) and [`DeframerDecision`] (the rules, `t + 2` to `t + 4`); this
//! block holds the state RAMs between them and each port's visit and commit bits.
//!
//! Cost per port: the visit bit of the one-hot scan and a share of the group registers; the
//! state lives in two RAMs (34 bits and the 32-bit start tick per port).

use crate::block_ram::BlockRam;
pub use crate::deframer_decision::{counter_bit, DECISION_CLOCKS};
use crate::deframer_decision::{DeframerDecision, STATE_BITS};
use crate::deframer_scan::DeframerScan;
use crate::geometry::MAX_PORTS;
use crate::hdl::*;
use crate::uart_rx::{bit_middles, STAMP_BITS};
use skinbox_protocol::cell::CellFraming;

/// Longest idle gap, in bit times (the limit's 11-bit arithmetic).
pub const MAX_IDLE_GAP_BITS: u64 = 21;

/// Clocks between two visits of a port: the port count, at least five (the state is read
/// and written back in that time).
pub fn scan_period(ports: usize) -> usize {
    ports.max(5)
}

/// Clocks from a byte's strobe (the cycle its stop bit is sampled) at which the engine
/// closes a packet whose next byte did not complete: `10 + idle_gap_bits` bit times.
pub fn truncation_clocks(clock_hz: u64, baud: u64, idle_gap_bits: u64) -> u64 {
    ((10 + idle_gap_bits) as f64 * clock_hz as f64 / baud as f64).ceil() as u64
}

/// The deframing engine of N ports.
#[derive(LogicBlock)]
pub struct CellDeframer {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the scan restarts at port 0.
    pub reset: Signal<In, Bit>,
    /// The ports' reset: every visited port's state is cleared, nothing is written or
    /// counted (it lasts longer than a scan).
    pub port_reset: Signal<In, Bit>,
    /// The box time (the current tick).
    pub tick: Signal<In, Bits<64>>,
    /// Per port, from its receiver: a byte is held.
    pub held: Vec<Signal<In, Bit>>,
    /// Per port: the byte held.
    pub data: Vec<Signal<In, Bits<8>>>,
    /// Per port: its stop bit was low.
    pub framing_error: Vec<Signal<In, Bit>>,
    /// Per port: the low tick bits of its strobe.
    pub stamp: Vec<Signal<In, Bits<STAMP_BITS>>>,
    /// Per port: the engine reads it now (the receiver drops `held`).
    pub visit: Vec<Signal<Out, Bit>>,
    /// Bit p: both of port p's slots hold a packet.
    pub full_ports: Signal<In, Bits<64>>,
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
    /// Bit p: port p's packet in its write slot is complete (one clock).
    pub commit_ports: Signal<Out, Bits<64>>,
    /// Count one event: counter `increment_address` (port x 8 + `PortCounter`).
    pub increment: Signal<Out, Bit>,
    /// The counter to increment.
    pub increment_address: Signal<Out, Bits<9>>,
    scan: DeframerScan,
    decision: DeframerDecision,
    state_ram: BlockRam<STATE_BITS, 6>,
    tick_ram: BlockRam<32, 6>,
    /// Per port: the scan ring's bit four clocks after its visit (its commit).
    commit_mask: Vec<Constant<Bits<64>>>,
    port_bit: Vec<Constant<Bits<64>>>,
}

impl CellDeframer {
    /// The engine of `ports` ports (1 to 64) for `framing`, receivers at `baud` with a
    /// `clock_hz` clock, truncating after `idle_gap_bits` idle bit times (1 to
    /// [`MAX_IDLE_GAP_BITS`]).
    pub fn new(
        ports: usize,
        clock_hz: u64,
        baud: u64,
        framing: CellFraming,
        idle_gap_bits: u64,
    ) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "CellDeframer: {ports} ports, must be 1 to {MAX_PORTS}"
        );
        assert!(
            framing.data_header != framing.event_header,
            "CellDeframer: data and event headers must differ"
        );
        assert!(
            (1..=MAX_IDLE_GAP_BITS).contains(&idle_gap_bits),
            "CellDeframer: idle gap of {idle_gap_bits} bits must be 1 to {MAX_IDLE_GAP_BITS}"
        );
        let period = scan_period(ports);
        let truncation = truncation_clocks(clock_hz, baud, idle_gap_bits);
        assert!(
            truncation + period as u64 + 8 < 1 << 11,
            "CellDeframer: idle gap too long"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            port_reset: Default::default(),
            tick: Default::default(),
            held: each(ports),
            data: each(ports),
            framing_error: each(ports),
            stamp: each(ports),
            visit: each(ports),
            full_ports: Default::default(),
            write: Default::default(),
            write_port: Default::default(),
            write_slot: Default::default(),
            write_word: Default::default(),
            write_data: Default::default(),
            commit_ports: Default::default(),
            increment: Default::default(),
            increment_address: Default::default(),
            scan: DeframerScan::new(ports, period, truncation, bit_middles(clock_hz, baud)[9]),
            decision: DeframerDecision::new(framing),
            state_ram: Default::default(),
            tick_ram: Default::default(),
            commit_mask: (0..ports)
                .map(|p| Constant::new((1u64 << ((p + 4) % period)).into()))
                .collect(),
            port_bit: (0..ports)
                .map(|p| Constant::new((1u64 << p).into()))
                .collect(),
        }
    }
}

impl Logic for CellDeframer {
    #[hdl_gen]
    fn update(&mut self) {
        self.scan.clock.next = self.clock.val();
        self.decision.clock.next = self.clock.val();
        self.state_ram.clock.next = self.clock.val();
        self.tick_ram.clock.next = self.clock.val();
        self.scan.reset.next = self.reset.val();
        self.decision.reset.next = self.reset.val();
        self.decision.port_reset.next = self.port_reset.val();
        // cycle t: the visit; the port's state read from the RAMs
        self.scan.tick.next = self.tick.val();
        self.scan.full_ports.next = self.full_ports.val();
        for i in 0..self.held.len() {
            self.scan.held[i].next = self.held[i].val();
            self.scan.data[i].next = self.data[i].val();
            self.scan.framing_error[i].next = self.framing_error[i].val();
            self.scan.stamp[i].next = self.stamp[i].val();
            self.visit[i].next = self.scan.ring.val().get_bit(i);
        }
        self.state_ram.read_address.next = self.scan.ram_address.val();
        self.tick_ram.read_address.next = self.scan.ram_address.val();
        // cycle t + 2: the scan's word and times and the state into the decision
        self.decision.port.next = self.scan.port.val();
        self.decision.sampled.next = self.scan.sampled.val();
        self.decision.idle_end.next = self.scan.idle_end.val();
        self.decision.deadline.next = self.scan.deadline.val();
        self.decision.start_tick.next = self.scan.start_tick.val();
        self.decision.state_read.next = self.state_ram.read_data.val();
        self.decision.tick_read.next = self.tick_ram.read_data.val();
        // cycle t + 4: the new state, the store's word, the commit and the count
        self.state_ram.write_enable.next = self.decision.state_write.val();
        self.state_ram.write_address.next = self.decision.state_port.val();
        self.state_ram.write_data.next = self.decision.state_data.val();
        self.tick_ram.write_enable.next = self.decision.state_write.val();
        self.tick_ram.write_address.next = self.decision.state_port.val();
        self.tick_ram.write_data.next = self.decision.tick_data.val();
        self.write.next = self.decision.write.val();
        self.write_port.next = self.decision.write_port.val();
        self.write_slot.next = self.decision.write_slot.val();
        self.write_word.next = self.decision.write_word.val();
        self.write_data.next = self.decision.write_data.val();
        self.commit_ports.next = 0.into();
        for i in 0..self.commit_mask.len() {
            if self.decision.commit.val()
                & ((self.scan.ring.val() & self.commit_mask[i].val()) != 0)
            {
                self.commit_ports.next = self.commit_ports.val() | self.port_bit[i].val();
            }
        }
        self.increment.next = self.decision.increment.val();
        self.increment_address.next = self.decision.increment_address.val();
    }
}
