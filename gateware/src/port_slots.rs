//! PortSlots: every port's packet buffers in shared block RAM, written by the deframing
//! engine.
//!
//! Each port owns two slots of 32 words (9 bits: a byte and the loss flag) in the block RAM
//! of its bank (ports 0-31 in bank 0, 32-63 in bank 1; one DP16KD of 2048 x 9 each). The
//! engine ([`crate::cell_deframer::CellDeframer`]) is the only writer: one word per clock at
//! most, straight from its registers. It decides which slot a packet goes to and whether
//! it is dropped; here each port keeps only its occupancy (two bits: 0, 1 or 2 packets)
//! and the slot its next packet to read is in. A packet counts from the clock after its
//! commit (`commit_ports`); the reader
//! ([`crate::record_arbiter::RecordArbiter`]) reads slot `read_slots` bit `i` of port `i`
//! through `read_address` (port, slot, word) and frees it with `free_slot` and
//! `free_port`. Cost per port: three flip-flops and their logic, no RAM of its own.

use crate::block_ram::BlockRam;
use crate::geometry::{MAX_PORTS, SLOT_BANK_ADDRESS_BITS, SLOT_BANK_PORTS};
use crate::hdl::*;

/// The RAM address of word `word` of slot `slot` of port `port` in its bank.
pub fn slot_address(port: usize, slot: usize, word: usize) -> usize {
    (port % SLOT_BANK_PORTS) << 6 | slot << 5 | word
}

/// Packet buffers of N ports.
#[derive(LogicBlock)]
pub struct PortSlots {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: empties every port.
    pub port_reset: Signal<In, Bit>,
    /// Write a word (the engine's registers): port, slot, word and data.
    pub write: Signal<In, Bit>,
    /// Port of the word.
    pub write_port: Signal<In, Bits<6>>,
    /// Slot of the word.
    pub write_slot: Signal<In, Bit>,
    /// Word in the slot.
    pub write_word: Signal<In, Bits<5>>,
    /// The word: byte and loss flag (bit 8).
    pub write_data: Signal<In, Bits<9>>,
    /// Bit i: port i's packet is complete in its write slot (one clock).
    pub commit_ports: Signal<In, Bits<64>>,
    /// Bit i: port i holds a packet.
    pub occupied_ports: Signal<Out, Bits<64>>,
    /// Bit i: both of port i's slots hold a packet.
    pub full_ports: Signal<Out, Bits<64>>,
    /// Bit i: the slot port i's next packet to read is in.
    pub read_slots: Signal<Out, Bits<64>>,
    /// Word to read in every bank (port within the bank, slot, word).
    pub read_address: Signal<In, Bits<SLOT_BANK_ADDRESS_BITS>>,
    /// The word at `read_address` of each bank, two clocks later.
    pub bank_data: Vec<Signal<Out, Bits<9>>>,
    /// Free the slot read last of port `free_port`.
    pub free_slot: Signal<In, Bit>,
    /// The port whose slot is freed.
    pub free_port: Signal<In, Bits<6>>,
    memories: Vec<BlockRam<9, SLOT_BANK_ADDRESS_BITS>>,
    bank_high: Vec<Constant<Bit>>,
    port_number: Vec<Constant<Bits<6>>>,
    port_bit: Vec<Constant<Bits<64>>>,
    used: Vec<DFF<Bits<2>>>,
    read_slot: Vec<DFF<Bit>>,
    free: Vec<Signal<Local, Bit>>,
    commit: Vec<Signal<Local, Bit>>,
    write_address: Signal<Local, Bits<SLOT_BANK_ADDRESS_BITS>>,
}

impl PortSlots {
    /// Slots for `ports` ports (1 to 64).
    pub fn new(ports: usize) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "PortSlots: {ports} ports, must be 1 to {MAX_PORTS}"
        );
        Self {
            clock: Default::default(),
            port_reset: Default::default(),
            write: Default::default(),
            write_port: Default::default(),
            write_slot: Default::default(),
            write_word: Default::default(),
            write_data: Default::default(),
            commit_ports: Default::default(),
            occupied_ports: Default::default(),
            full_ports: Default::default(),
            read_slots: Default::default(),
            read_address: Default::default(),
            bank_data: each(ports.div_ceil(SLOT_BANK_PORTS)),
            free_slot: Default::default(),
            free_port: Default::default(),
            memories: each(ports.div_ceil(SLOT_BANK_PORTS)),
            bank_high: (0..ports.div_ceil(SLOT_BANK_PORTS))
                .map(|b| Constant::new(b == 1))
                .collect(),
            port_number: (0..ports)
                .map(|i| Constant::new((i as u64).into()))
                .collect(),
            port_bit: (0..ports)
                .map(|i| Constant::new((1u64 << i).into()))
                .collect(),
            used: each(ports),
            read_slot: each(ports),
            free: each(ports),
            commit: each(ports),
            write_address: Default::default(),
        }
    }
}

impl Logic for PortSlots {
    #[hdl_gen]
    fn update(&mut self) {
        self.occupied_ports.next = 0.into();
        self.full_ports.next = 0.into();
        self.read_slots.next = 0.into();
        for i in 0..self.used.len() {
            self.used[i].clock.next = self.clock.val();
            self.read_slot[i].clock.next = self.clock.val();
            self.read_slot[i].d.next = self.read_slot[i].q.val();
            // occupancy: +1 on commit, -1 when the reader finished this port's record
            self.commit[i].next = (self.commit_ports.val() & self.port_bit[i].val()) != 0;
            self.free[i].next =
                self.free_slot.val() & (self.free_port.val() == self.port_number[i].val());
            if self.free[i].val() {
                self.read_slot[i].d.next = !self.read_slot[i].q.val();
            }
            self.used[i].d.next = self.used[i].q.val();
            if self.commit[i].val() & !self.free[i].val() {
                self.used[i].d.next = self.used[i].q.val() + 1;
            } else if !self.commit[i].val() & self.free[i].val() {
                self.used[i].d.next = self.used[i].q.val() - 1;
            }
            if self.port_reset.val() {
                self.used[i].d.next = 0.into();
                self.read_slot[i].d.next = false;
            }
            // (0, 1 or 2 packets: bit 1 is "full")
            if self.used[i].q.val() != 0 {
                self.occupied_ports.next = self.occupied_ports.val() | self.port_bit[i].val();
            }
            if self.used[i].q.val().get_bit(1) {
                self.full_ports.next = self.full_ports.val() | self.port_bit[i].val();
            }
            if self.read_slot[i].q.val() {
                self.read_slots.next = self.read_slots.val() | self.port_bit[i].val();
            }
        }
        self.write_address.next =
            (bit_cast::<SLOT_BANK_ADDRESS_BITS, 5>(self.write_port.val().get_bits::<5>(0)) << 6)
                | (bit_cast::<SLOT_BANK_ADDRESS_BITS, 1>(self.write_slot.val().into()) << 5)
                | bit_cast::<SLOT_BANK_ADDRESS_BITS, 5>(self.write_word.val());
        for b in 0..self.memories.len() {
            self.memories[b].clock.next = self.clock.val();
            self.memories[b].read_address.next = self.read_address.val();
            self.bank_data[b].next = self.memories[b].read_data.val();
            self.memories[b].write_address.next = self.write_address.val();
            self.memories[b].write_data.next = self.write_data.val();
            // bank 1 takes the words of ports 32 and up
            self.memories[b].write_enable.next =
                self.write.val() & (self.write_port.val().get_bit(5) == self.bank_high[b].val());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::STORED_BEATS;
    use crate::testbench::Bench;

    fn packet(k: u8) -> Vec<u8> {
        (0..STORED_BEATS as u8)
            .map(|i| k.wrapping_mul(31) ^ i)
            .collect()
    }

    fn slots(ports: usize) -> Bench<PortSlots> {
        let mut bench = Bench::new(PortSlots::new(ports), |b| &mut b.clock);
        bench.uut.port_reset.next = true;
        bench.cycles(2);
        bench.uut.port_reset.next = false;
        bench
    }

    /// Writes `bytes` into `port`'s `slot` (words in reverse order: the engine writes the
    /// tick words last), with the loss flag, and commits it if asked.
    fn store(b: &mut Bench<PortSlots>, port: usize, slot: usize, bytes: &[u8], loss: bool) {
        for (w, byte) in bytes.iter().enumerate().rev() {
            b.uut.write.next = true;
            b.uut.write_port.next = (port as u64).into();
            b.uut.write_slot.next = slot == 1;
            b.uut.write_word.next = (w as u64).into();
            b.uut.write_data.next = (u64::from(*byte) | u64::from(loss) << 8).into();
            b.cycle();
        }
        b.uut.write.next = false;
    }

    fn commit(b: &mut Bench<PortSlots>, port: usize) {
        b.uut.commit_ports.next = (1u64 << port).into();
        b.cycle();
        b.uut.commit_ports.next = 0.into();
        b.cycle();
    }

    fn read(b: &mut Bench<PortSlots>, port: usize, slot: usize) -> Vec<u16> {
        (0..STORED_BEATS)
            .map(|w| {
                b.uut.read_address.next = (slot_address(port, slot, w) as u64).into();
                b.cycles(2);
                b.uut.bank_data[port / SLOT_BANK_PORTS].val().to_u16()
            })
            .collect()
    }

    fn bits(b: &mut Bench<PortSlots>, port: usize) -> (bool, bool, bool) {
        b.settle();
        let u = &b.uut;
        (
            u.occupied_ports.val().get_bit(port),
            u.full_ports.val().get_bit(port),
            u.read_slots.val().get_bit(port),
        )
    }

    fn free(b: &mut Bench<PortSlots>, port: usize) {
        b.uut.free_slot.next = true;
        b.uut.free_port.next = (port as u64).into();
        b.cycle();
        b.uut.free_slot.next = false;
        b.cycle();
    }

    fn words(bytes: &[u8], loss: bool) -> Vec<u16> {
        bytes
            .iter()
            .map(|&b| u16::from(b) | u16::from(loss) << 8)
            .collect()
    }

    #[test]
    fn commits_fill_both_slots_and_frees_empty_them_in_order() {
        // port 35 of 40: bank 1, so the second bank's RAM is written and read
        for (ports, port) in [(3, 1), (40, 35)] {
            let mut s = slots(ports);
            let other = (port + 1) % ports;
            assert_eq!(bits(&mut s, port), (false, false, false));
            store(&mut s, port, 0, &packet(1), false);
            // another port's words and commit leave this one alone
            store(&mut s, other, 0, &packet(9), true);
            commit(&mut s, other);
            assert_eq!(bits(&mut s, port), (false, false, false));
            commit(&mut s, port);
            assert_eq!(bits(&mut s, port), (true, false, false), "one packet");
            store(&mut s, port, 1, &packet(2), true);
            commit(&mut s, port);
            assert_eq!(bits(&mut s, port), (true, true, false), "both slots full");
            assert_eq!(read(&mut s, port, 0), words(&packet(1), false));
            assert_eq!(read(&mut s, port, 1), words(&packet(2), true));
            assert_eq!(read(&mut s, other, 0), words(&packet(9), true));
            free(&mut s, port);
            assert_eq!(
                bits(&mut s, port),
                (true, false, true),
                "one left, in slot 1"
            );
            // a commit and a free in the same clock leave the count
            s.uut.commit_ports.next = (1u64 << port).into();
            s.uut.free_slot.next = true;
            s.uut.free_port.next = (port as u64).into();
            s.cycle();
            s.uut.commit_ports.next = 0.into();
            s.uut.free_slot.next = false;
            s.cycle();
            assert_eq!(bits(&mut s, port), (true, false, false));
            free(&mut s, port);
            assert_eq!(bits(&mut s, port), (false, false, true));
        }
    }
}
