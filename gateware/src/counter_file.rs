//! CounterFile: the eight 32-bit counters of every port, in block RAM.
//!
//! The deframing engine ([`crate::cell_deframer::CellDeframer`]) keeps each port's pending
//! counter events and sends one increment per visit (`increment`, with the counter's
//! address: port x 8 + `PortCounter`). Each increment is a read-modify-write in RAM: the
//! counter is read (two clocks, through the memory's output register), incremented into a
//! register and written a clock later ([`INCREMENT_WRITE_EDGE`] edges after the increment
//! is offered). A second RAM receives the same writes and serves `read_address` for the
//! status reporter, so reading never delays counting. The same counter is never
//! incremented again before its write (the engine visits a port at most every four
//! clocks).
//!
//! After reset the file first clears both RAMs (512 clocks) with `ready` low; the box
//! holds its ports in reset until then.

use crate::block_ram::BlockRam;
use crate::hdl::*;

/// Clocks the counter file spends clearing its memories after reset (`ready` low).
pub const CLEAR_CLOCKS: u64 = 512;

/// Counters per port (`skinbox_protocol::PortCounter`).
pub const COUNTERS: usize = 8;

/// Edges from the cycle an increment is offered to the edge that writes it: a read whose
/// address is taken at a later edge sees the new value (at that edge, the old one).
pub const INCREMENT_WRITE_EDGE: u64 = 4;

/// Event-driven counter memory of up to 64 ports.
#[derive(LogicBlock, Default)]
pub struct CounterFile {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: clears every counter.
    pub reset: Signal<In, Bit>,
    /// Add one to the counter at `increment_address`.
    pub increment: Signal<In, Bit>,
    /// Counter to increment: port * 8 + counter.
    pub increment_address: Signal<In, Bits<9>>,
    /// Counter to read: port * 8 + counter.
    pub read_address: Signal<In, Bits<9>>,
    /// The counter, two clocks after its address (from the memory's output register).
    pub read_data: Signal<Out, Bits<32>>,
    /// Counting: the clearing after reset is over.
    pub ready: Signal<Out, Bit>,
    clearing: DFF<Bit>,
    clear_address: DFF<Bits<9>>,
    read_1: DFF<Bit>,
    address_1: DFF<Bits<9>>,
    read_2: DFF<Bit>,
    address_2: DFF<Bits<9>>,
    // the incremented counter, written a clock after the addition (the 32-bit carry chain
    // between the memory's output register and its write port is cut here)
    increment_pending: DFF<Bit>,
    increment_target: DFF<Bits<9>>,
    increment_value: DFF<Bits<32>>,
    counting_memory: BlockRam<32, 9>,
    reading_memory: BlockRam<32, 9>,
    write_address: Signal<Local, Bits<9>>,
    write_data: Signal<Local, Bits<32>>,
    write_enable: Signal<Local, Bit>,
}

impl CounterFile {
    /// Counters for up to 64 ports.
    pub fn new() -> Self {
        Self::default()
    }
}

impl Logic for CounterFile {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            clearing,
            clear_address,
            read_1,
            address_1,
            read_2,
            address_2,
            increment_pending,
            increment_target,
            increment_value
        );
        self.counting_memory.clock.next = self.clock.val();
        self.reading_memory.clock.next = self.clock.val();
        self.counting_memory.read_address.next = self.increment_address.val();
        self.read_1.d.next = self.increment.val() & !self.clearing.q.val();
        self.address_1.d.next = self.increment_address.val();
        self.read_2.d.next = self.read_1.q.val();
        self.address_2.d.next = self.address_1.q.val();
        self.increment_pending.d.next = self.read_2.q.val();
        self.increment_target.d.next = self.address_2.q.val();
        self.increment_value.d.next = self.counting_memory.read_data.val() + 1;
        self.write_enable.next = self.increment_pending.q.val();
        self.write_address.next = self.increment_target.q.val();
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
        if self.reset.val() {
            self.clearing.d.next = true;
            self.clear_address.d.next = 0.into();
            self.read_1.d.next = false;
            self.read_2.d.next = false;
            self.increment_pending.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    fn cleared() -> Bench<CounterFile> {
        let mut bench = Bench::new(CounterFile::new(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        bench.cycles(1);
        while !bench.uut.ready.val() {
            bench.cycle();
        }
        assert_eq!(
            bench.cycles,
            1 + CLEAR_CLOCKS,
            "clearing takes 512 clocks after the reset edge"
        );
        bench
    }

    fn read(bench: &mut Bench<CounterFile>, address: usize) -> u32 {
        bench.uut.read_address.next = (address as u64).into();
        bench.cycles(2);
        bench.uut.read_data.val().to_u32()
    }

    /// Increments at random addresses (the same one at most every four clocks, as the
    /// engine's scan does) and checks every counter against a count kept here.
    #[test]
    fn counts_every_increment_of_64_ports() {
        let mut bench = cleared();
        let mut expected = vec![0u32; 512];
        let mut state = 7u64;
        let mut recent = [usize::MAX; 4];
        for clock in 0..20_000 {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let mut address = (state >> 33) as usize % 512;
            if state >> 62 == 0 || recent.contains(&address) {
                address = usize::MAX;
            }
            bench.uut.increment.next = address != usize::MAX;
            if address != usize::MAX {
                bench.uut.increment_address.next = (address as u64).into();
                expected[address] += 1;
            } else {
                // an address on the bus without `increment` counts nothing
                bench.uut.increment_address.next = ((state >> 20) % 512).into();
            }
            recent[clock % 4] = address;
            bench.cycle();
        }
        bench.uut.increment.next = false;
        bench.cycles(8);
        for (a, count) in expected.iter().enumerate() {
            assert_eq!(read(&mut bench, a), *count, "counter {a}");
        }
    }

    #[test]
    fn an_increment_is_read_back_from_its_write_edge_on() {
        let mut bench = cleared();
        bench.uut.increment.next = true;
        bench.uut.increment_address.next = 15u64.into();
        let offered = bench.cycles;
        bench.cycle();
        bench.uut.increment.next = false;
        // a read whose address is taken at edge `offered + INCREMENT_WRITE_EDGE` sees the
        // old value, one taken an edge later the new one
        while bench.cycles < offered + INCREMENT_WRITE_EDGE - 1 {
            bench.cycle();
        }
        bench.uut.read_address.next = 15u64.into();
        bench.cycles(2);
        assert_eq!(bench.uut.read_data.val().to_u32(), 0);
        bench.cycles(2);
        assert_eq!(bench.uut.read_data.val().to_u32(), 1);
    }

    #[test]
    fn reset_clears_the_counters() {
        let mut bench = cleared();
        bench.uut.increment.next = true;
        bench.uut.increment_address.next = 15u64.into();
        bench.cycle();
        bench.uut.increment.next = false;
        bench.cycles(8);
        assert_eq!(read(&mut bench, 15), 1);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        bench.cycles(600);
        assert_eq!(read(&mut bench, 15), 0);
    }
}
