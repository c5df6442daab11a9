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
//! Cost per port: the visit bit of the one-hot scan and a share of the group registers; the
//! state lives in two RAMs (34 bits and the 32-bit start tick per port).

use crate::block_ram::BlockRam;
use crate::geometry::{group_onehot, GROUP_PORTS, MAX_PORTS, TICK_BEATS};
use crate::hdl::*;
use crate::uart_rx::{bit_middles, STAMP_BITS};
use skinbox_protocol::cell::{CellFraming, PACKET_LEN};
use skinbox_protocol::PortCounter;

/// Longest idle gap, in bit times (the limit's 11-bit arithmetic).
pub const MAX_IDLE_GAP_BITS: u64 = 21;

/// Clocks from a port's visit to the clock of the engine's decision about it.
pub const DECISION_CLOCKS: u64 = 3;

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

/// Bits of the per-port state word.
const STATE_BITS: usize = 34;
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
        && SCAN_STAMP == 8
        && SCAN_FRAMING_ERROR == 15
        && SCAN_HELD == 16
        && SCAN_FULL == 17
        && STAMP_BITS == 7
);

/// Bits of a port's word in the scan: data (8), stamp, framing error, held, full.
const SCAN_BITS: usize = 8 + STAMP_BITS + 3;
const SCAN_STAMP: usize = 8;
const SCAN_FRAMING_ERROR: usize = 8 + STAMP_BITS;
const SCAN_HELD: usize = SCAN_FRAMING_ERROR + 1;
const SCAN_FULL: usize = SCAN_HELD + 1;

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
    data_header: Constant<Bits<8>>,
    event_header: Constant<Bits<8>>,
    end_of_packet: Constant<Bits<8>>,
    last_index: Constant<Bits<5>>,
    tick_words: Constant<Bits<5>>,
    last_scan: Constant<Bits<6>>,
    truncation: Constant<Bits<12>>,
    strobe_to_start: Constant<Bits<32>>,
    ring_keep: Constant<Bits<64>>,
    bit_zero: Constant<Bits<64>>,
    // per port: its group, one-hot, and the ring bit that is set four clocks after its
    // visit (its commit)
    port_group: Vec<Constant<Bits<8>>>,
    commit_mask: Vec<Constant<Bits<64>>>,
    port_bit: Vec<Constant<Bits<64>>>,
    state_ram: BlockRam<STATE_BITS, 6>,
    tick_ram: BlockRam<32, 6>,
    scan: DFF<Bits<6>>,
    ring: DFF<Bits<64>>,
    scanned: DFF<Bits<6>>,
    port: DFF<Bits<6>>,
    group_word: Vec<DFF<Bits<SCAN_BITS>>>,
    group_term: Vec<Signal<Local, Bits<SCAN_BITS>>>,
    port_word: Signal<Local, Bits<SCAN_BITS>>,
    term_data: Signal<Local, Bits<8>>,
    term_stamp: Signal<Local, Bits<STAMP_BITS>>,
    term_framing_error: Signal<Local, Bit>,
    term_held: Signal<Local, Bit>,
    term_full: Signal<Local, Bit>,
    sampled: DFF<Bits<SCAN_BITS>>,
    sampled_term: Signal<Local, Bits<SCAN_BITS>>,
    start_base: DFF<Bits<32>>,
    // the decision's input registers (cycle t + 3)
    a_port: DFF<Bits<6>>,
    a_state: DFF<Bits<STATE_BITS>>,
    a_tick: DFF<Bits<32>>,
    a_sampled: DFF<Bits<SCAN_BITS>>,
    a_truncate: DFF<Bit>,
    a_header: DFF<Bit>,
    a_end: DFF<Bit>,
    a_deadline: DFF<Bits<12>>,
    sampled_age: DFF<Bits<STAMP_BITS>>,
    limit_base: DFF<Bits<12>>,
    // the tick the idle time runs to, registered a clock ahead (the shared tick's wires are
    // long): now, or with a byte held, the byte's strobe tick (now less its age)
    idle_end: DFF<Bits<12>>,
    // the next cycle's tick + 1, and its bits 11..7 less one, registered a clock ahead
    tick_ahead: DFF<Bits<12>>,
    tick_ahead_high_less: DFF<Bits<5>>,
    strobe_borrow: Signal<Local, Bit>,
    tick_plus_two: Signal<Local, Bits<12>>,
    a_start_tick: DFF<Bits<32>>,
    // the decision's registers
    state_write: DFF<Bit>,
    state_port: DFF<Bits<6>>,
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
    // the decision
    state: Signal<Local, Bits<STATE_BITS>>,
    next: Signal<Local, Bits<STATE_BITS>>,
    held_byte: Signal<Local, Bits<8>>,
    held_now: Signal<Local, Bit>,
    byte_error: Signal<Local, Bit>,
    full: Signal<Local, Bit>,
    age: Signal<Local, Bits<STAMP_BITS>>,
    deadline: Signal<Local, Bits<12>>,
    idle: Signal<Local, Bits<12>>,
    truncate: Signal<Local, Bit>,
    in_packet: Signal<Local, Bit>,
    aligned: Signal<Local, Bit>,
    loss: Signal<Local, Bit>,
    index: Signal<Local, Bits<5>>,
    ticks_left: Signal<Local, Bits<3>>,
    events: Signal<Local, Bits<8>>,
    all_events: Signal<Local, Bits<8>>,
    lowest: Signal<Local, Bits<3>>,
    lowest_bit: Signal<Local, Bits<8>>,
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

/// The event bit of `counter` in a port's 8-bit counter events (bit i = `PortCounter` i).
pub fn counter_bit(counter: PortCounter) -> Constant<Bits<8>> {
    Constant::new((1u64 << counter as u64).into())
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
        let groups = ports.div_ceil(GROUP_PORTS);
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
            data_header: Constant::new(u64::from(framing.data_header).into()),
            event_header: Constant::new(u64::from(framing.event_header).into()),
            end_of_packet: Constant::new(u64::from(framing.end_of_packet).into()),
            last_index: Constant::new((PACKET_LEN as u64 - 1).into()),
            tick_words: Constant::new((TICK_BEATS as u64).into()),
            last_scan: Constant::new((period as u64 - 1).into()),
            truncation: Constant::new(truncation.into()),
            strobe_to_start: Constant::new(bit_middles(clock_hz, baud)[9].into()),
            ring_keep: Constant::new(if period == 64 {
                u64::MAX.into()
            } else {
                ((1u64 << period) - 1).into()
            }),
            bit_zero: Constant::new(1u64.into()),
            port_group: (0..ports).map(group_onehot).collect(),
            commit_mask: (0..ports)
                .map(|p| Constant::new((1u64 << ((p + 4) % period)).into()))
                .collect(),
            port_bit: (0..ports)
                .map(|p| Constant::new((1u64 << p).into()))
                .collect(),
            state_ram: Default::default(),
            tick_ram: Default::default(),
            scan: Default::default(),
            ring: Default::default(),
            scanned: Default::default(),
            port: Default::default(),
            group_word: each(groups),
            group_term: each(groups),
            port_word: Default::default(),
            term_data: Default::default(),
            term_stamp: Default::default(),
            term_framing_error: Default::default(),
            term_held: Default::default(),
            term_full: Default::default(),
            sampled: Default::default(),
            sampled_term: Default::default(),
            start_base: Default::default(),
            a_port: Default::default(),
            a_state: Default::default(),
            a_tick: Default::default(),
            a_sampled: Default::default(),
            a_truncate: Default::default(),
            a_header: Default::default(),
            a_end: Default::default(),
            a_deadline: Default::default(),
            sampled_age: Default::default(),
            limit_base: Default::default(),
            idle_end: Default::default(),
            tick_ahead: Default::default(),
            tick_ahead_high_less: Default::default(),
            strobe_borrow: Default::default(),
            tick_plus_two: Default::default(),
            a_start_tick: Default::default(),
            state_write: Default::default(),
            state_port: Default::default(),
            state_next: Default::default(),
            tick_next: Default::default(),
            write_out: Default::default(),
            write_port_out: Default::default(),
            write_slot_out: Default::default(),
            write_word_out: Default::default(),
            write_data_out: Default::default(),
            commit_out: Default::default(),
            increment_out: Default::default(),
            increment_address_out: Default::default(),
            state: Default::default(),
            next: Default::default(),
            held_byte: Default::default(),
            held_now: Default::default(),
            byte_error: Default::default(),
            full: Default::default(),
            age: Default::default(),
            deadline: Default::default(),
            idle: Default::default(),
            truncate: Default::default(),
            in_packet: Default::default(),
            aligned: Default::default(),
            loss: Default::default(),
            index: Default::default(),
            ticks_left: Default::default(),
            events: Default::default(),
            all_events: Default::default(),
            lowest: Default::default(),
            lowest_bit: Default::default(),
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

impl Logic for CellDeframer {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            scan,
            ring,
            scanned,
            port,
            sampled,
            start_base,
            a_port,
            a_state,
            a_tick,
            a_sampled,
            a_truncate,
            a_header,
            a_end,
            a_deadline,
            sampled_age,
            limit_base,
            idle_end,
            tick_ahead,
            tick_ahead_high_less,
            a_start_tick,
            state_write,
            state_port,
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
        self.state_ram.clock.next = self.clock.val();
        self.tick_ram.clock.next = self.clock.val();
        // the scan: a counter for the RAM address, a one-hot ring for the ports
        if self.scan.q.val() == self.last_scan.val() {
            self.scan.d.next = 0.into();
            self.ring.d.next = self.bit_zero.val();
        } else {
            self.scan.d.next = self.scan.q.val() + 1;
            self.ring.d.next = (self.ring.q.val() << 1) & self.ring_keep.val();
        }
        self.scanned.d.next = self.scan.q.val();
        self.port.d.next = self.scanned.q.val();
        self.state_ram.read_address.next = self.scan.q.val();
        self.tick_ram.read_address.next = self.scan.q.val();
        // tick - (strobe to start) in the next cycle's tick
        self.start_base.d.next = self.tick.val().get_bits::<32>(0) + 1 - self.strobe_to_start.val();

        // cycle t: the visited port's word into its group's register (an OR of masked
        // terms, not a chain of multiplexers)
        for g in 0..self.group_word.len() {
            self.group_word[g].clock.next = self.clock.val();
            self.group_term[g].next = 0.into();
        }
        for i in 0..self.held.len() {
            self.visit[i].next = self.ring.q.val().get_bit(i);
            // (rust-hdl cannot pass an indexed signal to a function: copy it first)
            self.term_data.next = self.data[i].val();
            self.term_stamp.next = self.stamp[i].val();
            self.term_framing_error.next = self.framing_error[i].val();
            self.term_held.next = self.held[i].val();
            self.term_full.next = (self.full_ports.val() & self.port_bit[i].val()) != 0;
            self.port_word.next = 0.into();
            if self.ring.q.val().get_bit(i) {
                self.port_word.next = bit_cast::<SCAN_BITS, 8>(self.term_data.val())
                    | (bit_cast::<SCAN_BITS, STAMP_BITS>(self.term_stamp.val()) << 8)
                    | (bit_cast::<SCAN_BITS, 1>(self.term_framing_error.val().into()) << 15)
                    | (bit_cast::<SCAN_BITS, 1>(self.term_held.val().into()) << 16)
                    | (bit_cast::<SCAN_BITS, 1>(self.term_full.val().into()) << 17);
            }
            for g in 0..self.group_word.len() {
                if self.port_group[i].val().get_bit(g) {
                    self.group_term[g].next = self.group_term[g].val() | self.port_word.val();
                }
            }
        }
        // cycle t + 1: the groups into one register
        self.sampled_term.next = 0.into();
        for g in 0..self.group_word.len() {
            self.group_word[g].d.next = self.group_term[g].val();
            self.sampled_term.next = self.sampled_term.val() | self.group_word[g].q.val();
        }
        self.sampled.d.next = self.sampled_term.val();
        // the byte's age in the next cycle, from its stamp
        self.age.next =
            (self.tick.val().get_bits::<7>(0) + 1) - self.sampled_term.val().get_bits::<7>(8);
        self.sampled_age.d.next = self.age.val();
        // tick + truncation time in the next cycle's tick
        self.limit_base.d.next = self.tick.val().get_bits::<12>(0) + 1 + self.truncation.val();
        // the strobe tick: the stamp as the low bits under now's high bits, or under the
        // ones before when the stamp is above now's low bits (a compare and a choice of
        // registers: no subtraction after the groups' OR)
        self.tick_plus_two.next = self.tick.val().get_bits::<12>(0) + 2;
        self.tick_ahead.d.next = self.tick_plus_two.val();
        self.tick_ahead_high_less.d.next = self.tick_plus_two.val().get_bits::<5>(7) - 1;
        self.strobe_borrow.next =
            self.sampled_term.val().get_bits::<7>(8) > self.tick_ahead.q.val().get_bits::<7>(0);
        self.idle_end.d.next = self.tick_ahead.q.val();
        if self.sampled_term.val().get_bit(16) {
            self.idle_end.d.next = (bit_cast::<12, 5>(self.tick_ahead.q.val().get_bits::<5>(7))
                << 7)
                | bit_cast::<12, 7>(self.sampled_term.val().get_bits::<7>(8));
            if self.strobe_borrow.val() {
                self.idle_end.d.next = (bit_cast::<12, 5>(self.tick_ahead_high_less.q.val()) << 7)
                    | bit_cast::<12, 7>(self.sampled_term.val().get_bits::<7>(8));
            }
        }

        // cycle t + 2: the arithmetic, from the registers and the RAMs' output registers,
        // into the decision's input registers
        // idle: now (with a byte held, its strobe) - deadline, signed: one carry chain from
        // the RAM's output register
        self.idle.next = self.idle_end.q.val() - self.state_ram.read_data.val().get_bits::<12>(14);
        self.deadline.next =
            self.limit_base.q.val() - bit_cast::<12, STAMP_BITS>(self.sampled_age.q.val());
        self.a_port.d.next = self.port.q.val();
        self.a_state.d.next = self.state_ram.read_data.val();
        self.a_tick.d.next = self.tick_ram.read_data.val();
        self.a_sampled.d.next = self.sampled.q.val();
        self.a_truncate.d.next =
            self.state_ram.read_data.val().get_bit(0) & !self.idle.val().get_bit(11);
        self.a_header.d.next = !self.sampled.q.val().get_bit(15)
            & ((self.sampled.q.val().get_bits::<8>(0) == self.data_header.val())
                | (self.sampled.q.val().get_bits::<8>(0) == self.event_header.val()));
        self.a_end.d.next = self.sampled.q.val().get_bits::<8>(0) == self.end_of_packet.val();
        self.a_deadline.d.next = self.deadline.val();
        self.a_start_tick.d.next =
            self.start_base.q.val() - bit_cast::<32, STAMP_BITS>(self.sampled_age.q.val());

        // cycle t + 3: the decision, from registers only
        self.state.next = self.a_state.q.val();
        self.held_byte.next = self.a_sampled.q.val().get_bits::<8>(0);
        self.held_now.next = self.a_sampled.q.val().get_bit(16);
        self.byte_error.next = self.a_sampled.q.val().get_bit(15);
        self.full.next = self.a_sampled.q.val().get_bit(17);
        self.truncate.next = self.a_truncate.q.val();
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
        self.n_tick.next = self.a_tick.q.val();
        self.events.next = 0.into();
        self.word_write.next = false;
        self.word.next = bit_cast::<5, 3>(self.ticks_left.val());
        self.word_data.next = self.held_byte.val();
        self.commit_now.next = false;
        if self.truncate.val() {
            self.events.next = self.truncated_event.val() | self.resync_event.val();
        }
        if self.held_now.val() {
            self.n_last.next = self.a_deadline.q.val();
            if self.byte_error.val() {
                self.events.next = self.events.val() | self.framing_error_event.val();
            }
            if !self.in_packet.val() {
                if self.a_header.q.val() {
                    self.n_in_packet.next = true;
                    self.n_index.next = 1.into();
                    self.n_dropping.next = self.full.val();
                    self.n_flag.next = self.loss.val();
                    self.n_ticks_left.next = 4.into();
                    self.n_tick.next = self.a_start_tick.q.val();
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
                    if self.a_end.q.val() {
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
            self.word_data.next = self.a_tick.q.val().get_bits::<8>(24);
            self.n_tick.next = self.a_tick.q.val() << 8;
            self.n_ticks_left.next = self.ticks_left.val() - 1;
        }
        // one pending event counted per visit: the lowest
        self.all_events.next = self.state.val().get_bits::<8>(26) | self.events.val();
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
        self.next.next = bit_cast::<STATE_BITS, 1>(self.n_in_packet.val().into())
            | (bit_cast::<STATE_BITS, 5>(self.n_index.val()) << 1)
            | (bit_cast::<STATE_BITS, 1>(self.n_aligned.val().into()) << 6)
            | (bit_cast::<STATE_BITS, 1>(self.n_write_slot.val().into()) << 7)
            | (bit_cast::<STATE_BITS, 1>(self.n_loss.val().into()) << 8)
            | (bit_cast::<STATE_BITS, 1>(self.n_flag.val().into()) << 9)
            | (bit_cast::<STATE_BITS, 1>(self.n_dropping.val().into()) << 10)
            | (bit_cast::<STATE_BITS, 3>(self.n_ticks_left.val()) << 11)
            | (bit_cast::<STATE_BITS, 12>(self.n_last.val()) << 14)
            | (bit_cast::<STATE_BITS, 8>(self.all_events.val() & !self.lowest_bit.val()) << 26);
        // the decision's registers (the ports' reset clears each visited port's state)
        self.state_write.d.next = true;
        self.state_port.d.next = self.a_port.q.val();
        self.state_next.d.next = self.next.val();
        self.tick_next.d.next = self.n_tick.val();
        self.write_out.d.next = self.word_write.val() & !self.port_reset.val();
        self.write_port_out.d.next = self.a_port.q.val();
        self.write_slot_out.d.next = self.state.val().get_bit(7);
        self.write_word_out.d.next = self.word.val();
        self.write_data_out.d.next = bit_cast::<9, 8>(self.word_data.val())
            | (bit_cast::<9, 1>(self.n_flag.val().into()) << 8);
        self.commit_out.d.next = self.commit_now.val() & !self.port_reset.val();
        self.increment_out.d.next = (self.all_events.val() != 0) & !self.port_reset.val();
        self.increment_address_out.d.next =
            (bit_cast::<9, 6>(self.a_port.q.val()) << 3) | bit_cast::<9, 3>(self.lowest.val());
        if self.port_reset.val() {
            self.state_next.d.next = 0.into();
            self.tick_next.d.next = 0.into();
        }
        self.state_ram.write_enable.next = self.state_write.q.val();
        self.state_ram.write_address.next = self.state_port.q.val();
        self.state_ram.write_data.next = self.state_next.q.val();
        self.tick_ram.write_enable.next = self.state_write.q.val();
        self.tick_ram.write_address.next = self.state_port.q.val();
        self.tick_ram.write_data.next = self.tick_next.q.val();
        self.write.next = self.write_out.q.val();
        self.write_port.next = self.write_port_out.q.val();
        self.write_slot.next = self.write_slot_out.q.val();
        self.write_word.next = self.write_word_out.q.val();
        self.write_data.next = self.write_data_out.q.val();
        self.commit_ports.next = 0.into();
        for i in 0..self.commit_mask.len() {
            if self.commit_out.q.val() & ((self.ring.q.val() & self.commit_mask[i].val()) != 0) {
                self.commit_ports.next = self.commit_ports.val() | self.port_bit[i].val();
            }
        }
        self.increment.next = self.increment_out.q.val();
        self.increment_address.next = self.increment_address_out.q.val();
        if self.reset.val() {
            self.scan.d.next = 0.into();
            self.ring.d.next = self.bit_zero.val();
            self.state_write.d.next = false;
            self.write_out.d.next = false;
            self.commit_out.d.next = false;
            self.increment_out.d.next = false;
        }
    }
}
