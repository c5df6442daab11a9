//! CountingRam: 2^A event counters of 32 bits in block RAM, counted by read-modify-write,
//! with any number of read ports.
//!
//! `increment` adds one to the counter at `increment_address`: the counter is read in
//! that clock (two clocks through the memory's output register), incremented into a
//! register and written a clock later ([`INCREMENT_WRITE_EDGE`] edges after the increment
//! is offered). The same counter must not be incremented again before its write. Each read
//! port is a further RAM taking the same writes, so reading never delays counting.
//!
//! After reset the file first clears every RAM (2^A clocks) with `ready` low; increments in
//! that time are lost. Both counter files of the box are one of these: the ports'
//! ([`crate::counter_file`]) and the box's ([`crate::box_counter_file`]).

use crate::block_ram::BlockRam;
use crate::hdl::*;

/// Edges from the cycle an increment is offered to the edge that writes it: a read whose
/// address is taken at a later edge sees the new value (at that edge, the old one).
pub const INCREMENT_WRITE_EDGE: u64 = 4;

/// Clocks a `CountingRam<A>` spends clearing its memories after reset (`ready` low).
pub const fn clear_clocks(address_bits: usize) -> u64 {
    1 << address_bits
}

/// 2^A counters counted by increments, read through `read_address.len()` ports.
#[derive(LogicBlock)]
pub struct CountingRam<const A: usize> {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: clears every counter.
    pub reset: Signal<In, Bit>,
    /// Add one to the counter at `increment_address`.
    pub increment: Signal<In, Bit>,
    /// Counter to increment.
    pub increment_address: Signal<In, Bits<A>>,
    /// Per read port: the counter to read.
    pub read_address: Vec<Signal<In, Bits<A>>>,
    /// Per read port: the counter at its `read_address` two clocks ago.
    pub read_data: Vec<Signal<Out, Bits<32>>>,
    /// Counting: the clearing after reset is over.
    pub ready: Signal<Out, Bit>,
    last_address: Constant<Bits<A>>,
    clearing: DFF<Bit>,
    clear_address: DFF<Bits<A>>,
    // reads in flight: (valid, address) for the two clocks of the RAM's latency
    read_1: DFF<Bit>,
    address_1: DFF<Bits<A>>,
    read_2: DFF<Bit>,
    address_2: DFF<Bits<A>>,
    // the incremented counter, written a clock after the addition (the 32-bit carry chain
    // between the memory's output register and its write port is cut here)
    increment_pending: DFF<Bit>,
    increment_target: DFF<Bits<A>>,
    increment_value: DFF<Bits<32>>,
    counting_memory: BlockRam<32, A>,
    reading_memories: Vec<BlockRam<32, A>>,
    write_address: Signal<Local, Bits<A>>,
    write_data: Signal<Local, Bits<32>>,
    write_enable: Signal<Local, Bit>,
}

impl<const A: usize> CountingRam<A> {
    /// Counters with `read_ports` read ports (at least one).
    pub fn new(read_ports: usize) -> Self {
        assert!(read_ports >= 1, "CountingRam: at least one read port");
        Self {
            clock: Default::default(),
            reset: Default::default(),
            increment: Default::default(),
            increment_address: Default::default(),
            read_address: each(read_ports),
            read_data: each(read_ports),
            ready: Default::default(),
            last_address: Constant::new((clear_clocks(A) - 1).into()),
            clearing: Default::default(),
            clear_address: Default::default(),
            read_1: Default::default(),
            address_1: Default::default(),
            read_2: Default::default(),
            address_2: Default::default(),
            increment_pending: Default::default(),
            increment_target: Default::default(),
            increment_value: Default::default(),
            counting_memory: Default::default(),
            reading_memories: each(read_ports),
            write_address: Default::default(),
            write_data: Default::default(),
            write_enable: Default::default(),
        }
    }
}

impl<const A: usize> Logic for CountingRam<A> {
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
            if self.clear_address.q.val() == self.last_address.val() {
                self.clearing.d.next = false;
            }
        }
        self.counting_memory.write_enable.next = self.write_enable.val();
        self.counting_memory.write_address.next = self.write_address.val();
        self.counting_memory.write_data.next = self.write_data.val();
        for i in 0..self.reading_memories.len() {
            self.reading_memories[i].clock.next = self.clock.val();
            self.reading_memories[i].write_enable.next = self.write_enable.val();
            self.reading_memories[i].write_address.next = self.write_address.val();
            self.reading_memories[i].write_data.next = self.write_data.val();
            self.reading_memories[i].read_address.next = self.read_address[i].val();
            self.read_data[i].next = self.reading_memories[i].read_data.val();
        }
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
    use crate::testbench::{Bench, TestRng};

    fn cleared<const A: usize>(read_ports: usize) -> Bench<CountingRam<A>> {
        let mut bench = Bench::new(CountingRam::<A>::new(read_ports), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        bench.cycles(1);
        while !bench.uut.ready.val() {
            bench.cycle();
        }
        assert_eq!(
            bench.cycles,
            1 + clear_clocks(A),
            "clearing takes 2^A clocks"
        );
        bench
    }

    /// Every read port reads every counter, each port its own address in the same clocks.
    #[test]
    fn every_read_port_sees_every_count() {
        let mut bench = cleared::<5>(3);
        let mut expected = [0u32; 32];
        let mut rng = TestRng::new(11);
        let mut recent = [usize::MAX; 4];
        for clock in 0..3_000 {
            let address = (rng.next_u64() % 32) as usize;
            let offer = rng.chance(0.7) && !recent.contains(&address);
            bench.uut.increment.next = offer;
            bench.uut.increment_address.next = (address as u64).into();
            if offer {
                expected[address] += 1;
            }
            recent[clock % 4] = if offer { address } else { usize::MAX };
            bench.cycle();
        }
        bench.uut.increment.next = false;
        bench.cycles(8);
        for a in 0..32 {
            for port in 0..3 {
                bench.uut.read_address[port].next = (((a + 7 * port) % 32) as u64).into();
            }
            bench.cycles(2);
            for port in 0..3 {
                let read = (a + 7 * port) % 32;
                assert_eq!(
                    bench.uut.read_data[port].val().to_u32(),
                    expected[read],
                    "port {port}, counter {read}"
                );
            }
        }
    }

    /// Increments offered while clearing are lost, and the clearing takes the same time
    /// again after a second reset.
    #[test]
    fn increments_while_clearing_are_lost() {
        let mut bench = cleared::<4>(1);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        bench.uut.increment.next = true;
        bench.uut.increment_address.next = 3u64.into();
        bench.cycles(4);
        bench.uut.increment.next = false;
        while !bench.uut.ready.val() {
            bench.cycle();
        }
        bench.cycles(8);
        bench.uut.read_address[0].next = 3u64.into();
        bench.cycles(2);
        assert_eq!(bench.uut.read_data[0].val().to_u32(), 0);
    }
}
