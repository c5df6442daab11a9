//! CounterFile: the eight 32-bit counters of every port, in block RAM.
//!
//! Each port raises counter events as a bit vector (bit i = `PortCounter` i). Events set
//! sticky pending bits; a scanner visits one port per clock and, when that port has a
//! pending bit, adds one to the lowest such counter with a read-modify-write in RAM and
//! clears the bit. A second RAM receives the same writes and serves `read_address` for
//! the status reporter, so reading never delays counting.
//!
//! The scan is a pipeline: the visited port's pending bits go into the register of its
//! group of eight ports, the groups' registers into `sampled` a clock later; the lowest
//! bit's counter is read a clock after that, and the bit cleared through a register (the
//! clear reaches every port's pending bits) a clock later still. The scan's period is the
//! port count but at least four (positions past the last port are empty), so a port is
//! never sampled again before its bit is cleared.
//!
//! Limit: a port is visited every N clocks (N: the port count, at least 4), so an event is
//! counted within 8 N clocks, and no event is lost while a port raises at most three
//! events per N x 3 clocks. The deframer raises at most three per received byte (297
//! clocks at the fastest line the UART accepts), which holds for N <= 64. After reset the
//! scanner first clears both RAMs (512 clocks) with `ready` low; the box holds its ports
//! in reset until then.

use crate::block_ram::BlockRam;
use crate::hdl::*;
use crate::packet_store::{group_onehot, GROUP_PORTS};
use skinbox_protocol::PortCounter;

/// The event bit of `counter` in a port's 8-bit counter events (bit i = `PortCounter` i).
pub fn counter_bit(counter: PortCounter) -> Constant<Bits<8>> {
    Constant::new((1u64 << counter as u64).into())
}
/// Clocks the counter file spends clearing its memories after reset (`ready` low).
pub const CLEAR_CLOCKS: u64 = 512;

/// Counters per port (`skinbox_protocol::PortCounter`).
pub const COUNTERS: usize = 8;

/// Clocks between two visits of a port by the scanner: the port count, at least four
/// (the pipeline from a port's sample to the clear of its bit).
pub fn scan_period(ports: usize) -> usize {
    ports.max(4)
}

/// Event-driven counter memory of N ports.
#[derive(LogicBlock)]
pub struct CounterFile {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: clears every counter.
    pub reset: Signal<In, Bit>,
    /// One event vector per port, high for one clock per event.
    pub events: Vec<Signal<In, Bits<8>>>,
    /// Counter to read: port * 8 + counter.
    pub read_address: Signal<In, Bits<9>>,
    /// The counter, two clocks after its address (from the memory's output register).
    pub read_data: Signal<Out, Bits<32>>,
    /// Counting: the clearing after reset is over.
    pub ready: Signal<Out, Bit>,
    pending: Vec<DFF<Bits<8>>>,
    // the scan's last position (scan_period - 1)
    last_port: Constant<Bits<6>>,
    port: DFF<Bits<6>>,
    // `port`, `scanned`, `visited` and the port being cleared one-hot (bit i: port i), for
    // OR-of-terms selects, not mux chains
    port_onehot: DFF<Bits<64>>,
    scanned_onehot: DFF<Bits<64>>,
    visited_onehot: DFF<Bits<64>>,
    clear_onehot: DFF<Bits<64>>,
    // the bit to clear in that port's pending bits
    clear_bits: DFF<Bits<8>>,
    // the port whose bits are in the group registers (a clock after `port`)
    scanned: DFF<Bits<6>>,
    // the port's write group, one-hot
    port_group: Vec<Constant<Bits<8>>>,
    // the scanned port's pending bits, in the register of its group (zero in the others)
    group_bits: Vec<DFF<Bits<8>>>,
    group_term: Vec<Signal<Local, Bits<8>>>,
    // the ports' bits of a one-hot word
    onehot_keep: Constant<Bits<64>>,
    clearing: DFF<Bit>,
    clear_address: DFF<Bits<9>>,
    sampled: DFF<Bits<8>>,
    visited: DFF<Bits<6>>,
    update: DFF<Bit>,
    update_address: DFF<Bits<9>>,
    write_pending: DFF<Bit>,
    write_pending_address: DFF<Bits<9>>,
    // the incremented counter, written a clock after the addition (the 32-bit carry chain
    // between the memory's output register and its write port is cut here)
    increment_pending: DFF<Bit>,
    increment_address: DFF<Bits<9>>,
    increment_value: DFF<Bits<32>>,
    counting_memory: BlockRam<32, 9>,
    reading_memory: BlockRam<32, 9>,
    current: Signal<Local, Bits<8>>,
    current_term: Signal<Local, Bits<8>>,
    lowest: Signal<Local, Bits<3>>,
    clear_mask: Signal<Local, Bits<8>>,
    write_address: Signal<Local, Bits<9>>,
    write_data: Signal<Local, Bits<32>>,
    write_enable: Signal<Local, Bit>,
}

impl CounterFile {
    /// Counters for `ports` ports (1 to 64).
    pub fn new(ports: usize) -> Self {
        assert!(
            (1..=64).contains(&ports),
            "CounterFile: {ports} ports, must be 1 to 64"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            events: (0..ports).map(|_| Default::default()).collect(),
            read_address: Default::default(),
            read_data: Default::default(),
            ready: Default::default(),
            pending: (0..ports).map(|_| Default::default()).collect(),
            last_port: Constant::new((scan_period(ports) as u64 - 1).into()),
            port: Default::default(),
            port_onehot: Default::default(),
            scanned_onehot: Default::default(),
            visited_onehot: Default::default(),
            clear_onehot: Default::default(),
            clear_bits: Default::default(),
            scanned: Default::default(),
            port_group: (0..ports).map(group_onehot).collect(),
            group_bits: (0..ports.div_ceil(GROUP_PORTS))
                .map(|_| Default::default())
                .collect(),
            group_term: (0..ports.div_ceil(GROUP_PORTS))
                .map(|_| Default::default())
                .collect(),
            onehot_keep: Constant::new(if ports == 64 {
                u64::MAX.into()
            } else {
                ((1u64 << scan_period(ports)) - 1).into()
            }),
            clearing: Default::default(),
            clear_address: Default::default(),
            sampled: Default::default(),
            visited: Default::default(),
            update: Default::default(),
            update_address: Default::default(),
            write_pending: Default::default(),
            write_pending_address: Default::default(),
            increment_pending: Default::default(),
            increment_address: Default::default(),
            increment_value: Default::default(),
            counting_memory: Default::default(),
            reading_memory: Default::default(),
            current: Default::default(),
            current_term: Default::default(),
            lowest: Default::default(),
            clear_mask: Default::default(),
            write_address: Default::default(),
            write_data: Default::default(),
            write_enable: Default::default(),
        }
    }
}

impl Logic for CounterFile {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            port,
            port_onehot,
            scanned_onehot,
            visited_onehot,
            clear_onehot,
            clear_bits,
            scanned,
            clearing,
            clear_address,
            sampled,
            visited,
            update,
            update_address,
            write_pending,
            write_pending_address,
            increment_pending,
            increment_address,
            increment_value
        );
        self.counting_memory.clock.next = self.clock.val();
        self.reading_memory.clock.next = self.clock.val();

        // Stage 1: the visited port's pending bits into its group's register.
        for g in 0..self.group_bits.len() {
            self.group_bits[g].clock.next = self.clock.val();
            self.group_term[g].next = 0.into();
        }
        for i in 0..self.pending.len() {
            self.pending[i].clock.next = self.clock.val();
            self.current_term.next = 0.into();
            if self.port_onehot.q.val().get_bit(i) {
                self.current_term.next = self.pending[i].q.val();
            }
            for g in 0..self.group_bits.len() {
                if self.port_group[i].val().get_bit(g) {
                    self.group_term[g].next = self.group_term[g].val() | self.current_term.val();
                }
            }
        }
        // Stage 2: the groups' registers into `sampled`.
        self.current.next = 0.into();
        for g in 0..self.group_bits.len() {
            self.group_bits[g].d.next = self.group_term[g].val();
            self.current.next = self.current.val() | self.group_bits[g].q.val();
            if self.reset.val() {
                self.group_bits[g].d.next = 0.into();
            }
        }
        self.sampled.d.next = self.current.val();
        self.scanned.d.next = self.port.q.val();
        self.scanned_onehot.d.next = self.port_onehot.q.val();
        // Stage 3: the lowest pending bit of the port sampled two clocks ago.
        self.lowest.next = 0.into();
        self.clear_mask.next = 0.into();
        if self.sampled.q.val().get_bit(0) {
            self.lowest.next = 0.into();
            self.clear_mask.next = 1.into();
        } else if self.sampled.q.val().get_bit(1) {
            self.lowest.next = 1.into();
            self.clear_mask.next = 2.into();
        } else if self.sampled.q.val().get_bit(2) {
            self.lowest.next = 2.into();
            self.clear_mask.next = 4.into();
        } else if self.sampled.q.val().get_bit(3) {
            self.lowest.next = 3.into();
            self.clear_mask.next = 8.into();
        } else if self.sampled.q.val().get_bit(4) {
            self.lowest.next = 4.into();
            self.clear_mask.next = 16.into();
        } else if self.sampled.q.val().get_bit(5) {
            self.lowest.next = 5.into();
            self.clear_mask.next = 32.into();
        } else if self.sampled.q.val().get_bit(6) {
            self.lowest.next = 6.into();
            self.clear_mask.next = 64.into();
        } else if self.sampled.q.val().get_bit(7) {
            self.lowest.next = 7.into();
            self.clear_mask.next = 128.into();
        }
        if self.clearing.q.val() {
            self.clear_mask.next = 0.into();
        }
        self.visited.d.next = self.scanned.q.val();
        self.visited_onehot.d.next = self.scanned_onehot.q.val();
        // Stage 4: the clear, from registers.
        self.clear_onehot.d.next = self.visited_onehot.q.val();
        self.clear_bits.d.next = self.clear_mask.val();
        for i in 0..self.pending.len() {
            self.pending[i].d.next = self.pending[i].q.val() | self.events[i].val();
            if self.clear_onehot.q.val().get_bit(i) {
                self.pending[i].d.next =
                    (self.pending[i].q.val() & !self.clear_bits.q.val()) | self.events[i].val();
            }
            if self.reset.val() {
                self.pending[i].d.next = 0.into();
            }
        }

        // Read now, the value comes two clocks later from the memory's output register, is
        // incremented into a register at the next edge and written at the one after. A
        // counter's next event comes at least a byte time later, long after its write.
        self.counting_memory.read_address.next =
            (bit_cast::<9, 6>(self.visited.q.val()) << 3) | bit_cast::<9, 3>(self.lowest.val());
        self.update.d.next = (self.clear_mask.val() != 0) & !self.clearing.q.val();
        self.update_address.d.next = self.counting_memory.read_address.val();
        self.write_pending.d.next = self.update.q.val();
        self.write_pending_address.d.next = self.update_address.q.val();
        self.increment_pending.d.next = self.write_pending.q.val();
        self.increment_address.d.next = self.write_pending_address.q.val();
        self.increment_value.d.next = self.counting_memory.read_data.val() + 1;
        self.write_enable.next = self.increment_pending.q.val();
        self.write_address.next = self.increment_address.q.val();
        self.write_data.next = self.increment_value.q.val();
        if self.clearing.q.val() {
            self.write_enable.next = true;
            self.write_address.next = self.clear_address.q.val();
            self.write_data.next = 0.into();
            self.clear_address.d.next = self.clear_address.q.val() + 1;
            if self.clear_address.q.val() == 511 {
                self.clearing.d.next = false;
            }
        }
        self.counting_memory.write_enable.next = self.write_enable.val();
        self.counting_memory.write_address.next = self.write_address.val();
        self.counting_memory.write_data.next = self.write_data.val();
        self.reading_memory.write_enable.next = self.write_enable.val();
        self.reading_memory.write_address.next = self.write_address.val();
        self.reading_memory.write_data.next = self.write_data.val();
        self.reading_memory.read_address.next = self.read_address.val();
        self.read_data.next = self.reading_memory.read_data.val();
        self.ready.next = !self.clearing.q.val();

        if self.port.q.val() == self.last_port.val() {
            self.port.d.next = 0.into();
            self.port_onehot.d.next = 1.into();
        } else {
            self.port.d.next = self.port.q.val() + 1;
            self.port_onehot.d.next = (self.port_onehot.q.val() << 1) & self.onehot_keep.val();
        }
        if self.reset.val() {
            self.port.d.next = 0.into();
            self.port_onehot.d.next = 1.into();
            self.clearing.d.next = true;
            self.clear_address.d.next = 0.into();
            self.update.d.next = false;
            self.write_pending.d.next = false;
            self.increment_pending.d.next = false;
            self.sampled.d.next = 0.into();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    /// Raises random events (at most three per port per 300 clocks) and checks every
    /// counter against a count kept here.
    fn random_events(ports: usize, clocks: u64, seed: u64) {
        let mut bench = Bench::new(CounterFile::new(ports), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut expected = vec![[0u32; COUNTERS]; ports];
        let mut state = seed;
        bench.cycles(1);
        while !bench.uut.ready.val() {
            bench.cycle();
        }
        assert_eq!(
            bench.cycles,
            1 + CLEAR_CLOCKS,
            "clearing takes 512 clocks after the reset edge"
        );
        let mut next_event = vec![0; ports];
        for clock in 0..clocks {
            for p in 0..ports {
                let mut bits = 0u64;
                if clock >= next_event[p] {
                    state = state
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    // one to three distinct counters at once, like a deframer byte
                    for k in 0..1 + (state >> 60) % 3 {
                        bits |= 1 << ((state >> (8 * k + 8)) % 8);
                    }
                    next_event[p] = clock + 297 + (state >> 40) % 50;
                    for (c, count) in expected[p].iter_mut().enumerate() {
                        *count += (bits >> c & 1) as u32;
                    }
                }
                bench.uut.events[p].next = bits.into();
            }
            bench.cycle();
        }
        for p in 0..ports {
            bench.uut.events[p].next = 0.into();
        }
        bench.cycles(8 * ports as u64 + 10);
        for (p, counts) in expected.iter().enumerate() {
            for (c, count) in counts.iter().enumerate() {
                bench.uut.read_address.next = ((p * COUNTERS + c) as u64).into();
                bench.cycles(2);
                let got = bench.uut.read_data.val().to_u32();
                assert_eq!(got, *count, "port {p} counter {c}");
            }
        }
    }

    #[test]
    fn counts_every_event_of_one_port() {
        random_events(1, 20_000, 1);
    }

    #[test]
    fn counts_every_event_of_64_ports() {
        random_events(64, 3_000, 2);
    }

    #[test]
    fn reset_clears_the_counters() {
        let mut bench = Bench::new(CounterFile::new(2), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        bench.cycles(600);
        bench.uut.events[1].next = 0b1000_0001u64.into();
        bench.cycle();
        bench.uut.events[1].next = 0.into();
        bench.cycles(40);
        bench.uut.read_address.next = 15u64.into();
        bench.cycles(2);
        assert_eq!(bench.uut.read_data.val().to_u32(), 1);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        bench.cycles(600);
        bench.uut.read_address.next = 15u64.into();
        bench.cycles(2);
        assert_eq!(bench.uut.read_data.val().to_u32(), 0);
    }
}
