//! CounterFile: the eight 32-bit counters of every port, in block RAM.
//!
//! The deframing engine ([`crate::cell_deframer::CellDeframer`]) keeps each port's pending
//! counter events and sends one increment per visit (`increment`, with the counter's
//! address: port x 8 + `PortCounter`); the status reporter reads them through the one
//! read port. The file is a [`CountingRam`] of 512 counters: each increment is written
//! [`INCREMENT_WRITE_EDGE`] edges after it is offered, and the same counter is never
//! incremented again before its write (the engine visits a port at most every four
//! clocks).
//!
//! After reset the file first clears its RAMs (512 clocks) with `ready` low; the box
//! holds its ports in reset until then.

pub use crate::counting_ram::INCREMENT_WRITE_EDGE;
use crate::counting_ram::{clear_clocks, CountingRam};

/// Address bits of the file: 6 of port, 3 of counter.
pub const ADDRESS_BITS: usize = 9;

/// Clocks the counter file spends clearing its memories after reset (`ready` low).
pub const CLEAR_CLOCKS: u64 = clear_clocks(ADDRESS_BITS);

/// Counters per port (`skinbox_protocol::PortCounter`).
pub const COUNTERS: usize = 8;

const _: () = assert!(crate::geometry::MAX_PORTS * COUNTERS == 1 << ADDRESS_BITS);

/// Event-driven counter memory of up to 64 ports, one read port.
pub type CounterFile = CountingRam<ADDRESS_BITS>;

/// The ports' counter file.
pub fn counter_file() -> CounterFile {
    CountingRam::new(1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    fn cleared() -> Bench<CounterFile> {
        let mut bench = Bench::new(counter_file(), |b| &mut b.clock);
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
        bench.uut.read_address[0].next = (address as u64).into();
        bench.cycles(2);
        bench.uut.read_data[0].val().to_u32()
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
        bench.uut.read_address[0].next = 15u64.into();
        bench.cycles(2);
        assert_eq!(bench.uut.read_data[0].val().to_u32(), 0);
        bench.cycles(2);
        assert_eq!(bench.uut.read_data[0].val().to_u32(), 1);
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
