//! PortSlots: every port's packet buffers in shared block RAM, written one port per clock.
//!
//! Each port owns two slots of 32 words (9 bits: a byte and the loss flag) in the block RAM
//! of its bank (ports 0-31 in bank 0, 32-63 in bank 1; one DP16KD of 2048 x 9 each). A
//! ring visits the ports of a bank one per clock (period: the bank's port count, at most
//! 32); a port's `ready` is its ring bit, so a deframer beat waits at most one round and
//! the RAM needs one write port. The deframer's burst of five beats after a header (four
//! tick bytes and the header) takes five rounds: 160 clocks at most, well inside a byte
//! time (about 300 clocks at 4 Mbit/s). The beat taken is written two clocks later,
//! through the register of its group of eight ports and then its bank's (the visited
//! port's address and data pass whether taken or not; only the write enable depends on
//! `valid`). A packet becomes visible in `occupied_ports` when its `last` beat is taken
//! without `error` (counted a clock later, so a reader sees it two clocks after the beat);
//! a packet with `error` is forgotten; when both slots of the port are full as a packet
//! starts, the whole packet is dropped and the port's counter event
//! `PortCounter::DroppedOverflow` pulses when it ends. The loss flag (bit 8 of every stored
//! word) is set when packets of the port were rejected or dropped since its previous
//! stored packet.
//!
//! The reader ([`crate::record_arbiter::RecordArbiter`]) reads slot `read_slots` bit `i` of
//! port `i` through `read_address` (port, slot, word) and frees it with `free_slot` and
//! `free_port`. Cost per port: about 15 flip-flops and their logic, no RAM of its own.

use crate::block_ram::BlockRam;
use crate::cell_deframer::TICK_BEATS;
use crate::counter_file::counter_bit;
use crate::hdl::*;
use crate::stream::ByteStreamSink;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::PortCounter;

/// Most ports (the port number field of a record is a byte; two banks).
pub const MAX_PORTS: usize = 64;
/// Ports per bank: one block RAM and one write ring each.
pub const BANK_PORTS: usize = 32;
/// Ports per write group: their taken words meet in a group register first, the groups of
/// a bank in the bank's write register a clock later (two short OR trees, not one across
/// the chip).
pub const GROUP_PORTS: usize = 8;
/// Packets a port holds.
pub const SLOTS: usize = 2;
/// Stored words of a packet: tick and cell bytes.
pub const STORED_BEATS: usize = TICK_BEATS + PACKET_LEN;
/// Address bits of a bank: 5 port, 1 slot, 5 word.
pub const BANK_ADDRESS_BITS: usize = 11;

/// Port `port`'s write group, one-hot (a bit of a `Bits<8>`: at most eight groups).
pub fn group_onehot(port: usize) -> Constant<Bits<8>> {
    Constant::new((1u64 << (port / GROUP_PORTS)).into())
}

/// Clocks between two visits of a port by its bank's write ring.
pub fn visit_period(ports: usize) -> usize {
    ports.min(BANK_PORTS)
}

/// The RAM address of word `word` of slot `slot` of port `port` in its bank.
pub fn slot_address(port: usize, slot: usize, word: usize) -> usize {
    (port % BANK_PORTS) << 6 | slot << 5 | word
}

/// `n` default values (the per-port and per-bank parts of a block).
fn each<T: Default>(n: usize) -> Vec<T> {
    (0..n).map(|_| T::default()).collect()
}

/// Packet buffers of N ports.
#[derive(LogicBlock)]
pub struct PortSlots {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: empties every port and restarts the ring.
    pub port_reset: Signal<In, Bit>,
    /// Packets from the deframers, one stream per port (4 tick bytes, 20 cell bytes).
    pub ports: Vec<ByteStreamSink>,
    /// Per port, counter events, bit i = `skinbox_protocol::PortCounter` i: bit 1
    /// (dropped overflow) for one clock per good packet dropped because both slots were
    /// full.
    pub events: Vec<Signal<Out, Bits<8>>>,
    /// Bit i: port i holds a packet.
    pub occupied_ports: Signal<Out, Bits<64>>,
    /// Bit i: the slot port i's next packet to read is in.
    pub read_slots: Signal<Out, Bits<64>>,
    /// Word to read in every bank (port within the bank, slot, word).
    pub read_address: Signal<In, Bits<BANK_ADDRESS_BITS>>,
    /// The word at `read_address` of each bank, two clocks later.
    pub bank_data: Vec<Signal<Out, Bits<9>>>,
    /// Free the slot read last of port `free_port`.
    pub free_slot: Signal<In, Bit>,
    /// The port whose slot is freed.
    pub free_port: Signal<In, Bits<6>>,
    dropped_event: Constant<Bits<8>>,
    memories: Vec<BlockRam<9, BANK_ADDRESS_BITS>>,
    // write ring: one token per bank; bank 1's token runs in bits 32..63
    ring_start: Constant<Bits<64>>,
    ring_keep: Constant<Bits<64>>,
    ring_wrap_low: Constant<Bits<64>>,
    ring_wrap_high: Constant<Bits<64>>,
    ring_high: Constant<Bits<64>>,
    bit_zero: Constant<Bits<64>>,
    visit: DFF<Bits<64>>,
    visit_next: Signal<Local, Bits<64>>,
    // per port
    port_address: Vec<Constant<Bits<BANK_ADDRESS_BITS>>>,
    port_number: Vec<Constant<Bits<6>>>,
    port_bit: Vec<Constant<Bits<64>>>,
    // the port's write group, one-hot
    port_group: Vec<Constant<Bits<8>>>,
    // the group's bank
    group_bank: Vec<Constant<Bit>>,
    store_word: Signal<Local, Bit>,
    term_slot: Signal<Local, Bit>,
    term_index: Signal<Local, Bits<5>>,
    term_byte: Signal<Local, Bits<8>>,
    term_loss: Signal<Local, Bit>,
    // the port's packet ends this clock (its `last` beat taken without `error`), and a
    // packet ending now is dropped (both slots were full as it started)
    packet_ends: Signal<Local, Bit>,
    packet_refused: Signal<Local, Bit>,
    word_address: Signal<Local, Bits<BANK_ADDRESS_BITS>>,
    word_data: Signal<Local, Bits<9>>,
    write_index: Vec<DFF<Bits<5>>>,
    write_slot: Vec<DFF<Bit>>,
    dropping: Vec<DFF<Bit>>,
    loss_pending: Vec<DFF<Bit>>,
    dropped_pulse: Vec<DFF<Bit>>,
    used: Vec<DFF<Bits<2>>>,
    occupied: Vec<DFF<Bit>>,
    full: Vec<DFF<Bit>>,
    read_slot: Vec<DFF<Bit>>,
    take: Vec<Signal<Local, Bit>>,
    // a packet of the port was stored whole (registered: it counts a clock later)
    commit: Vec<DFF<Bit>>,
    free: Vec<Signal<Local, Bit>>,
    used_next: Vec<Signal<Local, Bits<2>>>,
    // per write group: the OR of its ports' taken words
    group_write: Vec<DFF<Bit>>,
    group_address: Vec<DFF<Bits<BANK_ADDRESS_BITS>>>,
    group_data: Vec<DFF<Bits<9>>>,
    group_write_term: Vec<Signal<Local, Bit>>,
    group_address_term: Vec<Signal<Local, Bits<BANK_ADDRESS_BITS>>>,
    group_data_term: Vec<Signal<Local, Bits<9>>>,
    // per bank (two, the second unused with 32 ports or fewer): the write register
    bank_write: Vec<DFF<Bit>>,
    bank_address: Vec<DFF<Bits<BANK_ADDRESS_BITS>>>,
    bank_word_data: Vec<DFF<Bits<9>>>,
    bank_write_term: Vec<Signal<Local, Bit>>,
    bank_address_term: Vec<Signal<Local, Bits<BANK_ADDRESS_BITS>>>,
    bank_data_term: Vec<Signal<Local, Bits<9>>>,
    stored_beats: Constant<Bits<5>>,
    slot_count: Constant<Bits<2>>,
}

impl PortSlots {
    /// Slots for `ports` ports (1 to 64).
    pub fn new(ports: usize) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "PortSlots: {ports} ports, must be 1 to {MAX_PORTS}"
        );
        let banks = ports.div_ceil(BANK_PORTS);
        let period = visit_period(ports);
        let two_banks = banks > 1;
        let wrap_low = 1u64 << (period - 1);
        let wrap_high = if two_banks { 1u64 << 63 } else { 0 };
        let high = if two_banks { 1u64 << 32 } else { 0 };
        let groups = ports.div_ceil(GROUP_PORTS);
        Self {
            clock: Default::default(),
            port_reset: Default::default(),
            ports: each(ports),
            events: each(ports),
            occupied_ports: Default::default(),
            read_slots: Default::default(),
            read_address: Default::default(),
            bank_data: each(banks),
            free_slot: Default::default(),
            free_port: Default::default(),
            dropped_event: counter_bit(PortCounter::DroppedOverflow),
            memories: each(banks),
            ring_start: Constant::new((1 | high).into()),
            ring_keep: Constant::new((!(wrap_low | wrap_high)).into()),
            ring_wrap_low: Constant::new(wrap_low.into()),
            ring_wrap_high: Constant::new(wrap_high.into()),
            ring_high: Constant::new(high.into()),
            bit_zero: Constant::new(1u64.into()),
            visit: Default::default(),
            visit_next: Default::default(),
            port_address: (0..ports)
                .map(|i| Constant::new((slot_address(i, 0, 0) as u64).into()))
                .collect(),
            port_number: (0..ports)
                .map(|i| Constant::new((i as u64).into()))
                .collect(),
            port_bit: (0..ports)
                .map(|i| Constant::new((1u64 << i).into()))
                .collect(),
            port_group: (0..ports).map(group_onehot).collect(),
            group_bank: (0..groups)
                .map(|g| Constant::new(g * GROUP_PORTS >= BANK_PORTS))
                .collect(),
            store_word: Default::default(),
            term_slot: Default::default(),
            term_index: Default::default(),
            term_byte: Default::default(),
            term_loss: Default::default(),
            packet_ends: Default::default(),
            packet_refused: Default::default(),
            word_address: Default::default(),
            word_data: Default::default(),
            write_index: each(ports),
            write_slot: each(ports),
            dropping: each(ports),
            loss_pending: each(ports),
            dropped_pulse: each(ports),
            used: each(ports),
            occupied: each(ports),
            full: each(ports),
            read_slot: each(ports),
            take: each(ports),
            commit: each(ports),
            free: each(ports),
            used_next: each(ports),
            group_write: each(groups),
            group_address: each(groups),
            group_data: each(groups),
            group_write_term: each(groups),
            group_address_term: each(groups),
            group_data_term: each(groups),
            bank_write: each(2),
            bank_address: each(2),
            bank_word_data: each(2),
            bank_write_term: each(2),
            bank_address_term: each(2),
            bank_data_term: each(2),
            stored_beats: Constant::new((STORED_BEATS as u64).into()),
            slot_count: Constant::new((SLOTS as u64).into()),
        }
    }
}

impl Logic for PortSlots {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, visit);
        self.occupied_ports.next = 0.into();
        self.read_slots.next = 0.into();
        // the ring, each port's state, the bank write registers
        self.visit_next.next = (self.visit.q.val() & self.ring_keep.val()) << 1;
        if (self.visit.q.val() & self.ring_wrap_low.val()) != 0 {
            self.visit_next.next = self.visit_next.val() | self.bit_zero.val();
        }
        if (self.visit.q.val() & self.ring_wrap_high.val()) != 0 {
            self.visit_next.next = self.visit_next.val() | self.ring_high.val();
        }
        self.visit.d.next = self.visit_next.val();
        for b in 0..self.bank_write.len() {
            self.bank_write[b].clock.next = self.clock.val();
            self.bank_address[b].clock.next = self.clock.val();
            self.bank_word_data[b].clock.next = self.clock.val();
            self.bank_write_term[b].next = false;
            self.bank_address_term[b].next = 0.into();
            self.bank_data_term[b].next = 0.into();
        }
        for g in 0..self.group_write.len() {
            self.group_write[g].clock.next = self.clock.val();
            self.group_address[g].clock.next = self.clock.val();
            self.group_data[g].clock.next = self.clock.val();
            self.group_write_term[g].next = false;
            self.group_address_term[g].next = 0.into();
            self.group_data_term[g].next = 0.into();
        }
        for i in 0..self.ports.len() {
            self.write_index[i].clock.next = self.clock.val();
            self.write_slot[i].clock.next = self.clock.val();
            self.dropping[i].clock.next = self.clock.val();
            self.loss_pending[i].clock.next = self.clock.val();
            self.dropped_pulse[i].clock.next = self.clock.val();
            self.used[i].clock.next = self.clock.val();
            self.occupied[i].clock.next = self.clock.val();
            self.full[i].clock.next = self.clock.val();
            self.read_slot[i].clock.next = self.clock.val();
            self.commit[i].clock.next = self.clock.val();
            self.write_index[i].d.next = self.write_index[i].q.val();
            self.write_slot[i].d.next = self.write_slot[i].q.val();
            self.dropping[i].d.next = self.dropping[i].q.val();
            self.loss_pending[i].d.next = self.loss_pending[i].q.val();
            self.read_slot[i].d.next = self.read_slot[i].q.val();

            self.ports[i].ready.next = self.visit.q.val().get_bit(i);
            self.take[i].next = self.ports[i].valid.val() & self.visit.q.val().get_bit(i);
            self.packet_ends.next =
                self.take[i].val() & self.ports[i].last.val() & !self.ports[i].error.val();
            self.packet_refused.next = self.dropping[i].q.val()
                | ((self.write_index[i].q.val() == 0) & self.full[i].q.val());
            // the commit and drop pulses as one expression each: set and cleared in the
            // branches below, each flip-flop would get its own reset net (one per port),
            // which crowds the placement of a 64-port box
            self.commit[i].d.next =
                self.packet_ends.val() & !self.packet_refused.val() & !self.port_reset.val();
            self.dropped_pulse[i].d.next =
                self.packet_ends.val() & self.packet_refused.val() & !self.port_reset.val();
            self.store_word.next = false;
            self.term_slot.next = false;
            self.term_index.next = 0.into();
            self.term_byte.next = 0.into();
            self.term_loss.next = false;
            self.word_address.next = 0.into();
            self.word_data.next = 0.into();
            if self.visit.q.val().get_bit(i) {
                // the visited port's address and data for its bank's write register, taken
                // or not (only the write enable depends on `valid`: the data path is one
                // AND with the ring bit)
                // (rust-hdl cannot pass an indexed signal to a function: copy it first)
                self.term_slot.next = self.write_slot[i].q.val();
                self.term_index.next = self.write_index[i].q.val();
                self.term_byte.next = self.ports[i].data.val();
                self.term_loss.next = self.loss_pending[i].q.val();
                self.word_address.next = self.port_address[i].val()
                    | (bit_cast::<11, 1>(self.term_slot.val().into()) << 5)
                    | bit_cast::<11, 5>(self.term_index.val());
                self.word_data.next = bit_cast::<9, 8>(self.term_byte.val())
                    | (bit_cast::<9, 1>(self.term_loss.val().into()) << 8);
            }
            if self.take[i].val() {
                // the write enable of this port's word
                self.store_word.next = !self.dropping[i].q.val()
                    & (self.write_index[i].q.val() < self.stored_beats.val());
                if self.write_index[i].q.val() == 0 {
                    self.dropping[i].d.next = self.full[i].q.val();
                    self.store_word.next = !self.full[i].q.val();
                }
                if self.write_index[i].q.val() < self.stored_beats.val() {
                    self.write_index[i].d.next = self.write_index[i].q.val() + 1;
                }
                if self.ports[i].last.val() {
                    self.write_index[i].d.next = 0.into();
                    if self.ports[i].error.val() | self.packet_refused.val() {
                        self.loss_pending[i].d.next = true;
                    } else {
                        self.loss_pending[i].d.next = false;
                        self.write_slot[i].d.next = !self.write_slot[i].q.val();
                    }
                }
            }
            // the group's register takes the OR of its ports' words, each zero unless its port
            // is visited (the write enable: unless taken)
            // (an OR tree, not a chain of multiplexers)
            for g in 0..self.group_write.len() {
                if self.port_group[i].val().get_bit(g) {
                    self.group_write_term[g].next =
                        self.group_write_term[g].val() | self.store_word.val();
                    self.group_address_term[g].next =
                        self.group_address_term[g].val() | self.word_address.val();
                    self.group_data_term[g].next =
                        self.group_data_term[g].val() | self.word_data.val();
                }
            }
            // occupancy: +1 on commit, -1 when the reader finished this port's record
            self.free[i].next =
                self.free_slot.val() & (self.free_port.val() == self.port_number[i].val());
            if self.free[i].val() {
                self.read_slot[i].d.next = !self.read_slot[i].q.val();
            }
            self.used_next[i].next = self.used[i].q.val();
            if self.commit[i].q.val() & !self.free[i].val() {
                self.used_next[i].next = self.used[i].q.val() + 1;
            } else if !self.commit[i].q.val() & self.free[i].val() {
                self.used_next[i].next = self.used[i].q.val() - 1;
            }
            if self.port_reset.val() {
                self.used_next[i].next = 0.into();
                self.write_slot[i].d.next = false;
                self.write_index[i].d.next = 0.into();
                self.dropping[i].d.next = false;
                self.loss_pending[i].d.next = false;
                self.read_slot[i].d.next = false;
            }
            self.used[i].d.next = self.used_next[i].val();
            self.occupied[i].d.next = self.used_next[i].val() != 0;
            if self.occupied[i].q.val() {
                self.occupied_ports.next = self.occupied_ports.val() | self.port_bit[i].val();
            }
            if self.read_slot[i].q.val() {
                self.read_slots.next = self.read_slots.val() | self.port_bit[i].val();
            }
            self.full[i].d.next = self.used_next[i].val() == self.slot_count.val();
            self.events[i].next = 0.into();
            if self.dropped_pulse[i].q.val() {
                self.events[i].next = self.dropped_event.val();
            }
        }
        // a clock later, the bank's write register takes the OR of its groups' registers
        for g in 0..self.group_write.len() {
            self.group_write[g].d.next = self.group_write_term[g].val();
            self.group_address[g].d.next = self.group_address_term[g].val();
            self.group_data[g].d.next = self.group_data_term[g].val();
            if self.group_bank[g].val() {
                self.bank_write_term[1].next =
                    self.bank_write_term[1].val() | self.group_write[g].q.val();
                self.bank_address_term[1].next =
                    self.bank_address_term[1].val() | self.group_address[g].q.val();
                self.bank_data_term[1].next =
                    self.bank_data_term[1].val() | self.group_data[g].q.val();
            } else {
                self.bank_write_term[0].next =
                    self.bank_write_term[0].val() | self.group_write[g].q.val();
                self.bank_address_term[0].next =
                    self.bank_address_term[0].val() | self.group_address[g].q.val();
                self.bank_data_term[0].next =
                    self.bank_data_term[0].val() | self.group_data[g].q.val();
            }
        }
        for b in 0..self.bank_write.len() {
            self.bank_write[b].d.next = self.bank_write_term[b].val();
            self.bank_address[b].d.next = self.bank_address_term[b].val();
            self.bank_word_data[b].d.next = self.bank_data_term[b].val();
        }
        for b in 0..self.memories.len() {
            self.memories[b].clock.next = self.clock.val();
            self.memories[b].read_address.next = self.read_address.val();
            self.bank_data[b].next = self.memories[b].read_data.val();
            self.memories[b].write_enable.next = self.bank_write[b].q.val();
            self.memories[b].write_address.next = self.bank_address[b].q.val();
            self.memories[b].write_data.next = self.bank_word_data[b].q.val();
        }
        if self.port_reset.val() {
            self.visit.d.next = self.ring_start.val();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    fn packet(k: u8) -> Vec<u8> {
        (0..STORED_BEATS as u8)
            .map(|i| k.wrapping_mul(31) ^ i)
            .collect()
    }

    struct Slots {
        bench: Bench<PortSlots>,
        drops: u32,
    }

    impl Slots {
        fn new(ports: usize) -> Self {
            let mut bench = Bench::new(PortSlots::new(ports), |b| &mut b.clock);
            bench.uut.port_reset.next = true;
            bench.cycles(2);
            bench.uut.port_reset.next = false;
            Slots { bench, drops: 0 }
        }

        /// One clock; counts the port's drop events.
        fn cycle(&mut self, port: usize) {
            self.bench.settle();
            let events = self.bench.uut.events[port].val().to_u8();
            self.drops += u32::from(events >> PortCounter::DroppedOverflow as u8 & 1);
            self.bench.cycle();
        }

        /// Offers `bytes` on `port` beat by beat (each beat held until the ring takes it),
        /// the last with `error` if asked, then a few clocks for the commit.
        fn offer(&mut self, port: usize, bytes: &[u8], error: bool) {
            for (i, &b) in bytes.iter().enumerate() {
                let last = i + 1 == bytes.len();
                loop {
                    let s = &mut self.bench.uut.ports[port];
                    s.valid.next = true;
                    s.data.next = u64::from(b).into();
                    s.last.next = last;
                    s.error.next = error && last;
                    self.bench.settle();
                    let taken = self.bench.uut.ports[port].ready.val();
                    self.cycle(port);
                    if taken {
                        break;
                    }
                }
            }
            self.bench.uut.ports[port].valid.next = false;
            for _ in 0..4 {
                self.cycle(port);
            }
        }

        /// The words of `port`'s slot `slot`, through the read port (two clocks each).
        fn read(&mut self, port: usize, slot: usize) -> Vec<u16> {
            (0..STORED_BEATS)
                .map(|w| {
                    self.bench.uut.read_address.next = (slot_address(port, slot, w) as u64).into();
                    self.bench.cycles(2);
                    self.bench.uut.bank_data[port / BANK_PORTS].val().to_u16()
                })
                .collect()
        }

        fn bits(&mut self, port: usize) -> (bool, bool) {
            self.bench.settle();
            let u = &self.bench.uut;
            (
                u.occupied_ports.val().get_bit(port),
                u.read_slots.val().get_bit(port),
            )
        }

        fn free(&mut self, port: usize) {
            self.bench.uut.free_slot.next = true;
            self.bench.uut.free_port.next = (port as u64).into();
            self.cycle(port);
            self.bench.uut.free_slot.next = false;
            self.cycle(port);
        }
    }

    fn words(bytes: &[u8], loss: bool) -> Vec<u16> {
        bytes
            .iter()
            .map(|&b| u16::from(b) | u16::from(loss) << 8)
            .collect()
    }

    #[test]
    fn packets_fill_both_slots_a_third_drops_and_the_next_carries_the_loss() {
        // port 35 of 40: bank 1, so the second bank's ring and RAM are used
        for (ports, port) in [(3, 1), (40, 35)] {
            let mut s = Slots::new(ports);
            assert_eq!(s.bits(port), (false, false));
            s.offer(port, &packet(1), false);
            assert_eq!(s.bits(port), (true, false), "one packet, read slot 0");
            s.offer(port, &packet(2)[..9], true);
            s.offer(port, &packet(3), false);
            s.offer(port, &packet(4), false);
            assert_eq!(s.drops, 1, "both slots full: the third good packet dropped");
            assert_eq!(s.read(port, 0), words(&packet(1), false));
            // after a rejected packet, the next stored packet carries the loss flag
            assert_eq!(s.read(port, 1), words(&packet(3), true));
            s.free(port);
            assert_eq!(s.bits(port), (true, true), "one left, in slot 1");
            s.offer(port, &packet(5), false);
            assert_eq!(s.read(port, 0), words(&packet(5), true), "after the drop");
            s.free(port);
            s.free(port);
            // empty; the next packet will be written to and read from slot 1
            assert_eq!(s.bits(port), (false, true));
            assert_eq!(s.drops, 1);
        }
    }
}
