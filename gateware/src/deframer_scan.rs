//! DeframerScan: the deframing engine's visit of one port a clock, and the times it needs
//! from the box time.
//!
//! The scan runs round robin over [`scan_period`](crate::cell_deframer::scan_period)
//! positions: `ram_address` (the port whose state the RAMs read now, cycle `t`) and the
//! one-hot `ring` (bit `p`: port `p` is visited now). In cycle `t` the visited port's
//! receiver outputs and its store occupancy go into the register of its group of eight
//! ports (an OR of masked terms, not a chain of multiplexers); in `t + 1` the groups into
//! one register, with the byte's age from its stamp and the tick its idle time runs to.
//! In `t + 2` (`port`) the outputs say, from registers: the port's [scan word](SCAN_BITS)
//! (`sampled`), `idle_end` (now, or with a byte held its strobe tick), `deadline` (the
//! byte's strobe tick plus the truncation time) and `start_tick` (the tick of the first
//! clock edge that sampled the byte's start bit low).

use crate::geometry::{group_onehot, GROUP_PORTS};
use crate::hdl::*;
use crate::uart_rx::STAMP_BITS;

/// Bits of a port's word in the scan: data (8), stamp, framing error, held, full.
pub const SCAN_BITS: usize = 8 + STAMP_BITS + 3;
/// Scan word: the stamp's first bit.
pub const SCAN_STAMP: usize = 8;
/// Scan word: the byte's stop bit was low.
pub const SCAN_FRAMING_ERROR: usize = 8 + STAMP_BITS;
/// Scan word: a byte is held.
pub const SCAN_HELD: usize = SCAN_FRAMING_ERROR + 1;
/// Scan word: both of the port's slots hold a packet.
pub const SCAN_FULL: usize = SCAN_HELD + 1;
// (the kernels write these positions as literals: rust-hdl puts names into Verilog)
const _: () = assert!(
    SCAN_STAMP == 8
        && SCAN_FRAMING_ERROR == 15
        && SCAN_HELD == 16
        && SCAN_FULL == 17
        && STAMP_BITS == 7
);

/// The scan of N ports.
#[derive(LogicBlock)]
pub struct DeframerScan {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the scan restarts at port 0.
    pub reset: Signal<In, Bit>,
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
    /// Bit p: both of port p's slots hold a packet.
    pub full_ports: Signal<In, Bits<64>>,
    /// Bit p: port p is visited now (cycle `t`).
    pub ring: Signal<Out, Bits<64>>,
    /// The port visited now: the RAMs' read address.
    pub ram_address: Signal<Out, Bits<6>>,
    /// The port visited two clocks ago (cycle `t + 2`).
    pub port: Signal<Out, Bits<6>>,
    /// Its scan word.
    pub sampled: Signal<Out, Bits<SCAN_BITS>>,
    /// The tick its idle time runs to: now, or with a byte held, the byte's strobe tick.
    pub idle_end: Signal<Out, Bits<12>>,
    /// The byte's strobe tick plus the truncation time (the next deadline).
    pub deadline: Signal<Out, Bits<12>>,
    /// The byte's start tick.
    pub start_tick: Signal<Out, Bits<32>>,
    last_scan: Constant<Bits<6>>,
    truncation: Constant<Bits<12>>,
    strobe_to_start: Constant<Bits<32>>,
    ring_keep: Constant<Bits<64>>,
    bit_zero: Constant<Bits<64>>,
    port_group: Vec<Constant<Bits<8>>>,
    port_bit: Vec<Constant<Bits<64>>>,
    scan: DFF<Bits<6>>,
    visits: DFF<Bits<64>>,
    scanned: DFF<Bits<6>>,
    sampled_port: DFF<Bits<6>>,
    group_word: Vec<DFF<Bits<SCAN_BITS>>>,
    group_term: Vec<Signal<Local, Bits<SCAN_BITS>>>,
    port_word: Signal<Local, Bits<SCAN_BITS>>,
    term_data: Signal<Local, Bits<8>>,
    term_stamp: Signal<Local, Bits<STAMP_BITS>>,
    term_framing_error: Signal<Local, Bit>,
    term_held: Signal<Local, Bit>,
    term_full: Signal<Local, Bit>,
    sampled_word: DFF<Bits<SCAN_BITS>>,
    sampled_term: Signal<Local, Bits<SCAN_BITS>>,
    start_base: DFF<Bits<32>>,
    sampled_age: DFF<Bits<STAMP_BITS>>,
    limit_base: DFF<Bits<12>>,
    age: Signal<Local, Bits<STAMP_BITS>>,
    // the tick the idle time runs to, registered a clock ahead (the shared tick's wires are
    // long): now, or with a byte held, the byte's strobe tick (now less its age)
    idle_end_at: DFF<Bits<12>>,
    // the next cycle's tick + 1, and its bits 11..7 less one, registered a clock ahead
    tick_ahead: DFF<Bits<12>>,
    tick_ahead_high_less: DFF<Bits<5>>,
    strobe_borrow: Signal<Local, Bit>,
    tick_plus_two: Signal<Local, Bits<12>>,
}

impl DeframerScan {
    /// The scan of `ports` ports over `period` positions (at least `ports`), truncating
    /// `truncation` clocks after a byte's strobe, the receivers' strobe `strobe_to_start`
    /// clocks after the start bit's first low sample.
    pub fn new(ports: usize, period: usize, truncation: u64, strobe_to_start: u64) -> Self {
        assert!(
            ports <= period && period <= 64,
            "DeframerScan: {ports} ports, period {period}"
        );
        let groups = ports.div_ceil(GROUP_PORTS);
        Self {
            clock: Default::default(),
            reset: Default::default(),
            tick: Default::default(),
            held: each(ports),
            data: each(ports),
            framing_error: each(ports),
            stamp: each(ports),
            full_ports: Default::default(),
            ring: Default::default(),
            ram_address: Default::default(),
            port: Default::default(),
            sampled: Default::default(),
            idle_end: Default::default(),
            deadline: Default::default(),
            start_tick: Default::default(),
            last_scan: Constant::new((period as u64 - 1).into()),
            truncation: Constant::new(truncation.into()),
            strobe_to_start: Constant::new(strobe_to_start.into()),
            ring_keep: Constant::new(if period == 64 {
                u64::MAX.into()
            } else {
                ((1u64 << period) - 1).into()
            }),
            bit_zero: Constant::new(1u64.into()),
            port_group: (0..ports).map(group_onehot).collect(),
            port_bit: (0..ports)
                .map(|p| Constant::new((1u64 << p).into()))
                .collect(),
            scan: Default::default(),
            visits: Default::default(),
            scanned: Default::default(),
            sampled_port: Default::default(),
            group_word: each(groups),
            group_term: each(groups),
            port_word: Default::default(),
            term_data: Default::default(),
            term_stamp: Default::default(),
            term_framing_error: Default::default(),
            term_held: Default::default(),
            term_full: Default::default(),
            sampled_word: Default::default(),
            sampled_term: Default::default(),
            start_base: Default::default(),
            sampled_age: Default::default(),
            limit_base: Default::default(),
            age: Default::default(),
            idle_end_at: Default::default(),
            tick_ahead: Default::default(),
            tick_ahead_high_less: Default::default(),
            strobe_borrow: Default::default(),
            tick_plus_two: Default::default(),
        }
    }
}

impl Logic for DeframerScan {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            scan,
            visits,
            scanned,
            sampled_port,
            sampled_word,
            start_base,
            sampled_age,
            limit_base,
            idle_end_at,
            tick_ahead,
            tick_ahead_high_less
        );
        // the scan: a counter for the RAM address, a one-hot ring for the ports
        if self.scan.q.val() == self.last_scan.val() {
            self.scan.d.next = 0.into();
            self.visits.d.next = self.bit_zero.val();
        } else {
            self.scan.d.next = self.scan.q.val() + 1;
            self.visits.d.next = (self.visits.q.val() << 1) & self.ring_keep.val();
        }
        self.ring.next = self.visits.q.val();
        self.ram_address.next = self.scan.q.val();
        self.scanned.d.next = self.scan.q.val();
        self.sampled_port.d.next = self.scanned.q.val();
        self.port.next = self.sampled_port.q.val();
        // tick - (strobe to start) in the next cycle's tick
        self.start_base.d.next = self.tick.val().get_bits::<32>(0) + 1 - self.strobe_to_start.val();

        // cycle t: the visited port's word into its group's register
        for g in 0..self.group_word.len() {
            self.group_word[g].clock.next = self.clock.val();
            self.group_term[g].next = 0.into();
        }
        for i in 0..self.held.len() {
            // (rust-hdl cannot pass an indexed signal to a function: copy it first)
            self.term_data.next = self.data[i].val();
            self.term_stamp.next = self.stamp[i].val();
            self.term_framing_error.next = self.framing_error[i].val();
            self.term_held.next = self.held[i].val();
            self.term_full.next = (self.full_ports.val() & self.port_bit[i].val()) != 0;
            self.port_word.next = 0.into();
            if self.visits.q.val().get_bit(i) {
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
        self.sampled_word.d.next = self.sampled_term.val();
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
        self.idle_end_at.d.next = self.tick_ahead.q.val();
        if self.sampled_term.val().get_bit(16) {
            self.idle_end_at.d.next = (bit_cast::<12, 5>(self.tick_ahead.q.val().get_bits::<5>(7))
                << 7)
                | bit_cast::<12, 7>(self.sampled_term.val().get_bits::<7>(8));
            if self.strobe_borrow.val() {
                self.idle_end_at.d.next = (bit_cast::<12, 5>(self.tick_ahead_high_less.q.val())
                    << 7)
                    | bit_cast::<12, 7>(self.sampled_term.val().get_bits::<7>(8));
            }
        }

        // cycle t + 2, from registers
        self.sampled.next = self.sampled_word.q.val();
        self.idle_end.next = self.idle_end_at.q.val();
        self.deadline.next =
            self.limit_base.q.val() - bit_cast::<12, STAMP_BITS>(self.sampled_age.q.val());
        self.start_tick.next =
            self.start_base.q.val() - bit_cast::<32, STAMP_BITS>(self.sampled_age.q.val());
        if self.reset.val() {
            self.scan.d.next = 0.into();
            self.visits.d.next = self.bit_zero.val();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Ports are visited in order, one a clock; two clocks after its visit a port's word
    /// is out with its strobe tick (`idle_end`), its deadline and its start tick, each
    /// computed here from the strobe the stamp was taken from.
    #[test]
    fn each_visit_gives_the_ports_word_and_its_strobes_times() {
        let (ports, period, truncation, strobe_to_start) = (12, 12, 1_000u64, 30u64);
        let mut bench = Bench::new(
            DeframerScan::new(ports, period, truncation, strobe_to_start),
            |b| &mut b.clock,
        );
        let mut rng = TestRng::new(5);
        let first_tick = 5_000u64;
        bench.uut.reset.next = true;
        bench.uut.tick.next = first_tick.into();
        bench.cycle();
        bench.uut.reset.next = false;
        // (visited port, its strobe tick, the word) per clock
        let mut visits: Vec<Option<(usize, Option<u64>, u64)>> = vec![];
        for clock in 0..400 {
            let tick = first_tick + clock as u64;
            let ring = bench.uut.ring.val();
            assert_eq!(
                ring.to_u64().count_ones(),
                1,
                "clock {clock}: one port visited"
            );
            let visited = ring.to_u64().trailing_zeros() as usize;
            assert_eq!(bench.uut.ram_address.val().index(), visited);
            // every port's inputs change each clock; the visited one's are remembered
            let mut seen = None;
            for p in 0..ports {
                let held = rng.chance(0.5);
                let strobe = tick - 1 - rng.next_u64() % 100;
                let data = rng.byte();
                let framing_error = rng.chance(0.2);
                let full = rng.chance(0.5);
                bench.uut.held[p].next = held;
                bench.uut.data[p].next = u64::from(data).into();
                bench.uut.stamp[p].next = (strobe & 0x7F).into();
                bench.uut.framing_error[p].next = framing_error;
                let full_ports = bench.uut.full_ports.next.to_u64();
                let full_ports = full_ports & !(1 << p) | u64::from(full) << p;
                bench.uut.full_ports.next = full_ports.into();
                if p == visited {
                    let word = u64::from(data)
                        | (strobe & 0x7F) << SCAN_STAMP
                        | u64::from(framing_error) << SCAN_FRAMING_ERROR
                        | u64::from(held) << SCAN_HELD
                        | u64::from(full) << SCAN_FULL;
                    seen = Some((p, held.then_some(strobe), word));
                }
            }
            visits.push(seen);
            bench.uut.tick.next = tick.into();
            bench.cycle();
            // now in the clock two after the visit (the inputs set at a clock's start hold
            // through it)
            if clock < 1 {
                continue;
            }
            let (port, strobe, word) = visits[clock - 1].unwrap();
            let uut = &bench.uut;
            assert_eq!(uut.port.val().index(), port, "clock {clock}");
            assert_eq!(uut.sampled.val().to_u64(), word, "clock {clock}");
            let now = tick + 1;
            let strobe_or_now = strobe.unwrap_or(now);
            assert_eq!(
                uut.idle_end.val().to_u64(),
                strobe_or_now & 0xFFF,
                "clock {clock}"
            );
            if let Some(strobe) = strobe {
                assert_eq!(uut.deadline.val().to_u64(), (strobe + truncation) & 0xFFF);
                assert_eq!(
                    uut.start_tick.val().to_u64(),
                    (strobe - strobe_to_start) & 0xFFFF_FFFF
                );
            }
        }
    }
}
