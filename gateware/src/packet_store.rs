//! PacketStore: the ports' packet buffers in shared block RAM, and the round-robin reader
//! that merges them into one record stream.
//!
//! Write side. Each port owns two slots of 32 words (9 bits: a byte and the loss flag) in
//! the block RAM of its bank (ports 0-31 in bank 0, 32-63 in bank 1; one DP16KD of 2048 x
//! 9 each). A ring visits the ports of a bank one per clock (period: the bank's port count,
//! at most 32); a port's `ready` is its ring bit, so a deframer beat waits at most one round
//! and the RAM needs one write port. The deframer's burst of five beats after a header
//! (four tick bytes and the header) takes five rounds: 160 clocks at most, well inside a
//! byte time (about 300 clocks at 4 Mbit/s). The beat taken is written two clocks later,
//! through the register of its group of eight ports and then its bank's (the visited
//! port's address and data pass whether taken or not; only the write enable depends on
//! `valid`). A packet becomes visible when its `last` beat is taken without `error`
//! (counted a clock later, so the scan sees it two clocks after the beat); a packet with
//! `error` is forgotten; when both slots of the port are full as a packet starts, the whole packet is
//! dropped and `dropped` pulses for the port when it ends. The loss flag (bit 8 of
//! every stored word) is set when packets of the port were rejected or dropped since its
//! previous stored packet.
//!
//! Read side. A scan visits one port per clock while nothing is read; the occupancy bit of
//! the scanned port is registered (`hit`), and a hit grants that port the next clock. A
//! grant is held for the whole record (packet-atomic); the scan then resumes at the next
//! port, so with every port busy the grants cycle 0, 1, .., N-1 (starvation-free). A record
//! is 26 issues: the port number, the flags byte, the 24 stored bytes; each issue reads the
//! RAM (two clocks) into a four-entry output FIFO, and an issue happens only when the FIFO
//! has room for everything in flight, so the record stream's `ready` reaches nothing but
//! the FIFO; the slot is freed a clock after the last issue. With `ready` high a record
//! takes 30 clocks plus the scan distance.
//!
//! Output records: the layout of `skinbox_protocol::record` with the absolute low 32 tick
//! bits where the datagram has its tick offset. Cost per port: about 15 flip-flops and
//! their logic, no RAM of its own.

use crate::block_ram::BlockRam;
use crate::cell_deframer::TICK_BEATS;
use crate::hdl::*;
use crate::stream::{ByteStreamSink, ByteStreamSource};
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::PortCounter;

/// Most ports a store holds (the port number field of a record is a byte; two banks).
pub const MAX_PORTS: usize = 64;
/// Ports per bank: one block RAM and one write ring each.
pub const BANK_PORTS: usize = 32;
/// Ports per write group: their taken words meet in a group register first, the groups of
/// a bank in the bank's write register a clock later (two short OR trees, not one across
/// the chip).
pub const GROUP_PORTS: usize = 8;

/// Port `port`'s write group, one-hot (a bit of a `Bits<8>`: at most eight groups).
pub fn group_onehot(port: usize) -> Constant<Bits<8>> {
    Constant::new((1u64 << (port / GROUP_PORTS)).into())
}
/// Packets a port holds.
pub const SLOTS: usize = 2;
/// Stored words of a packet: tick and cell bytes.
pub const STORED_BEATS: usize = TICK_BEATS + PACKET_LEN;
/// Beats of an output record: port, flags, tick and cell bytes.
pub const RECORD_BEATS: usize = 2 + STORED_BEATS;
/// Entries of the output FIFO (its four registers `fifo_0` to `fifo_3`).
pub const FIFO_DEPTH: usize = 4;

/// Address bits of a bank: 5 port, 1 slot, 5 word.
const BANK_ADDRESS_BITS: usize = 11;

/// Clocks between two visits of a port by its bank's write ring.
pub fn visit_period(ports: usize) -> usize {
    ports.min(BANK_PORTS)
}

/// Packet buffers of N ports and their round-robin reader.
#[derive(LogicBlock)]
pub struct PacketStore {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset of the reader.
    pub reset: Signal<In, Bit>,
    /// Synchronous reset of the write side: empties every port and restarts the ring.
    pub port_reset: Signal<In, Bit>,
    /// Packets from the deframers, one stream per port (4 tick bytes, 20 cell bytes).
    pub ports: Vec<ByteStreamSink>,
    /// Records, port number first.
    pub records: ByteStreamSource,
    /// Per port, counter events, bit i = `skinbox_protocol::PortCounter` i: bit 1
    /// (dropped overflow) for one clock per good packet dropped because both slots were
    /// full.
    pub events: Vec<Signal<Out, Bits<8>>>,
    dropped_event: Constant<Bits<8>>,
    memories: Vec<BlockRam<9, BANK_ADDRESS_BITS>>,
    // write ring: one token per bank; bank 1's token runs in bits 32..63
    ring_start: Constant<Bits<64>>,
    ring_keep: Constant<Bits<64>>,
    ring_wrap_low: Constant<Bits<64>>,
    ring_wrap_high: Constant<Bits<64>>,
    ring_high: Constant<Bits<64>>,
    visit: DFF<Bits<64>>,
    visit_next: Signal<Local, Bits<64>>,
    // per port
    port_address: Vec<Constant<Bits<BANK_ADDRESS_BITS>>>,
    port_number: Vec<Constant<Bits<6>>>,
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
    bank_data: Vec<DFF<Bits<9>>>,
    bank_write_term: Vec<Signal<Local, Bit>>,
    bank_address_term: Vec<Signal<Local, Bits<BANK_ADDRESS_BITS>>>,
    bank_data_term: Vec<Signal<Local, Bits<9>>>,
    stored_beats: Constant<Bits<5>>,
    slots: Constant<Bits<2>>,
    fifo_depth: Constant<Bits<3>>,
    // reader
    // bit 0 set: the first position of the write ring and of the scan
    bit_zero: Constant<Bits<64>>,
    scan_wrap: Constant<Bits<64>>,
    scan: DFF<Bits<6>>,
    scan_onehot: DFF<Bits<64>>,
    hit: DFF<Bit>,
    hit_port: DFF<Bits<6>>,
    hit_slot: DFF<Bit>,
    hit_term: Signal<Local, Bit>,
    hit_slot_term: Signal<Local, Bit>,
    reading: DFF<Bit>,
    port: DFF<Bits<6>>,
    slot: DFF<Bit>,
    issue_index: DFF<Bits<5>>,
    word: DFF<Bits<5>>,
    last_issue: Constant<Bits<5>>,
    issue: Signal<Local, Bit>,
    finishing: Signal<Local, Bit>,
    // the record's last issue was a clock ago: its slot is freed now
    freeing: DFF<Bit>,
    // read pipeline: kind 0 port number, 1 flags, 2 stored byte
    read1_valid: DFF<Bit>,
    read1_kind: DFF<Bits<2>>,
    read1_last: DFF<Bit>,
    read2_valid: DFF<Bit>,
    read2_kind: DFF<Bits<2>>,
    read2_last: DFF<Bit>,
    read_word: Signal<Local, Bits<9>>,
    arrival: Signal<Local, Bits<9>>,
    // output FIFO, a shift register with the head in entry 0 (the output leaves a
    // register): entries of data and last (bit 8)
    fifo_0: DFF<Bits<9>>,
    fifo_1: DFF<Bits<9>>,
    fifo_2: DFF<Bits<9>>,
    fifo_3: DFF<Bits<9>>,
    fifo_count: DFF<Bits<3>>,
    fifo_slot: Signal<Local, Bits<3>>,
    fifo_pop: Signal<Local, Bit>,
}

impl PacketStore {
    /// A store for `ports` ports (1 to 64).
    pub fn new(ports: usize) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "PacketStore: {ports} ports, must be 1 to {MAX_PORTS}"
        );
        let banks = ports.div_ceil(BANK_PORTS);
        let period = visit_period(ports);
        let two_banks = banks > 1;
        let wrap_low = 1u64 << (period - 1);
        let wrap_high = if two_banks { 1u64 << 63 } else { 0 };
        let high = if two_banks { 1u64 << 32 } else { 0 };
        let groups = ports.div_ceil(GROUP_PORTS);
        let scan_wrap = 1u64 << (ports - 1);
        Self {
            clock: Default::default(),
            reset: Default::default(),
            port_reset: Default::default(),
            ports: (0..ports).map(|_| Default::default()).collect(),
            records: Default::default(),
            events: (0..ports).map(|_| Default::default()).collect(),
            dropped_event: Constant::new((1u64 << PortCounter::DroppedOverflow as u64).into()),
            memories: (0..banks).map(|_| Default::default()).collect(),
            ring_start: Constant::new((1 | high).into()),
            ring_keep: Constant::new((!(wrap_low | wrap_high)).into()),
            ring_wrap_low: Constant::new(wrap_low.into()),
            ring_wrap_high: Constant::new(wrap_high.into()),
            ring_high: Constant::new(high.into()),
            visit: Default::default(),
            visit_next: Default::default(),
            port_address: (0..ports)
                .map(|i| Constant::new((((i % BANK_PORTS) as u64) << 6).into()))
                .collect(),
            port_number: (0..ports)
                .map(|i| Constant::new((i as u64).into()))
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
            write_index: (0..ports).map(|_| Default::default()).collect(),
            write_slot: (0..ports).map(|_| Default::default()).collect(),
            dropping: (0..ports).map(|_| Default::default()).collect(),
            loss_pending: (0..ports).map(|_| Default::default()).collect(),
            dropped_pulse: (0..ports).map(|_| Default::default()).collect(),
            used: (0..ports).map(|_| Default::default()).collect(),
            occupied: (0..ports).map(|_| Default::default()).collect(),
            full: (0..ports).map(|_| Default::default()).collect(),
            read_slot: (0..ports).map(|_| Default::default()).collect(),
            take: (0..ports).map(|_| Default::default()).collect(),
            commit: (0..ports).map(|_| Default::default()).collect(),
            free: (0..ports).map(|_| Default::default()).collect(),
            used_next: (0..ports).map(|_| Default::default()).collect(),
            group_write: (0..groups).map(|_| Default::default()).collect(),
            group_address: (0..groups).map(|_| Default::default()).collect(),
            group_data: (0..groups).map(|_| Default::default()).collect(),
            group_write_term: (0..groups).map(|_| Default::default()).collect(),
            group_address_term: (0..groups).map(|_| Default::default()).collect(),
            group_data_term: (0..groups).map(|_| Default::default()).collect(),
            bank_write: (0..2).map(|_| Default::default()).collect(),
            bank_address: (0..2).map(|_| Default::default()).collect(),
            bank_data: (0..2).map(|_| Default::default()).collect(),
            bank_write_term: (0..2).map(|_| Default::default()).collect(),
            bank_address_term: (0..2).map(|_| Default::default()).collect(),
            bank_data_term: (0..2).map(|_| Default::default()).collect(),
            stored_beats: Constant::new((STORED_BEATS as u64).into()),
            slots: Constant::new((SLOTS as u64).into()),
            fifo_depth: Constant::new((FIFO_DEPTH as u64).into()),
            bit_zero: Constant::new(1u64.into()),
            scan_wrap: Constant::new(scan_wrap.into()),
            scan: Default::default(),
            scan_onehot: Default::default(),
            hit: Default::default(),
            hit_port: Default::default(),
            hit_slot: Default::default(),
            hit_term: Default::default(),
            hit_slot_term: Default::default(),
            reading: Default::default(),
            port: Default::default(),
            slot: Default::default(),
            issue_index: Default::default(),
            word: Default::default(),
            last_issue: Constant::new((RECORD_BEATS as u64 - 1).into()),
            issue: Default::default(),
            finishing: Default::default(),
            freeing: Default::default(),
            read1_valid: Default::default(),
            read1_kind: Default::default(),
            read1_last: Default::default(),
            read2_valid: Default::default(),
            read2_kind: Default::default(),
            read2_last: Default::default(),
            read_word: Default::default(),
            arrival: Default::default(),
            fifo_0: Default::default(),
            fifo_1: Default::default(),
            fifo_2: Default::default(),
            fifo_3: Default::default(),
            fifo_count: Default::default(),
            fifo_slot: Default::default(),
            fifo_pop: Default::default(),
        }
    }
}

impl Logic for PacketStore {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            visit,
            scan,
            scan_onehot,
            hit,
            hit_port,
            hit_slot,
            reading,
            port,
            slot,
            issue_index,
            word,
            read1_valid,
            read1_kind,
            read1_last,
            read2_valid,
            read2_kind,
            read2_last,
            fifo_0,
            fifo_1,
            fifo_2,
            fifo_3,
            fifo_count,
            freeing
        );

        // ---- reader: scan, grant, issue ----
        self.hit_term.next = false;
        self.hit_slot_term.next = false;
        // an OR of AND terms, not a chain of multiplexers: it maps to a tree
        for i in 0..self.ports.len() {
            self.hit_term.next = self.hit_term.val()
                | (self.scan_onehot.q.val().get_bit(i) & self.occupied[i].q.val());
            self.hit_slot_term.next = self.hit_slot_term.val()
                | (self.scan_onehot.q.val().get_bit(i) & self.read_slot[i].q.val());
        }
        self.issue.next = self.reading.q.val()
            & ((bit_cast::<3, 1>(self.read1_valid.q.val().into())
                + bit_cast::<3, 1>(self.read2_valid.q.val().into())
                + self.fifo_count.q.val())
                < self.fifo_depth.val());
        self.finishing.next =
            self.issue.val() & (self.issue_index.q.val() == self.last_issue.val());
        self.hit.d.next = false;
        self.freeing.d.next = self.finishing.val();
        // while a slot is freed (a clock after the last issue) the scan waits, so it never
        // sees the freed port's occupancy before the free
        if !self.reading.q.val() & !self.freeing.q.val() {
            if self.hit.q.val() {
                // grant: the scan already stands on the next port and waits there
                self.reading.d.next = true;
                self.port.d.next = self.hit_port.q.val();
                self.slot.d.next = self.hit_slot.q.val();
                self.issue_index.d.next = 0.into();
                self.word.d.next = 0.into();
            } else {
                self.hit.d.next = self.hit_term.val();
                self.hit_port.d.next = self.scan.q.val();
                self.hit_slot.d.next = self.hit_slot_term.val();
                if (self.scan_onehot.q.val() & self.scan_wrap.val()) != 0 {
                    self.scan.d.next = 0.into();
                    self.scan_onehot.d.next = self.bit_zero.val();
                } else {
                    self.scan.d.next = self.scan.q.val() + 1;
                    self.scan_onehot.d.next = self.scan_onehot.q.val() << 1;
                }
            }
        }
        if self.issue.val() {
            self.issue_index.d.next = self.issue_index.q.val() + 1;
            if self.issue_index.q.val() >= 2 {
                self.word.d.next = self.word.q.val() + 1;
            }
            if self.finishing.val() {
                self.reading.d.next = false;
            }
        }
        for b in 0..self.memories.len() {
            self.memories[b].clock.next = self.clock.val();
            self.memories[b].read_address.next = (bit_cast::<11, 6>(self.port.q.val()) << 6)
                | (bit_cast::<11, 1>(self.slot.q.val().into()) << 5)
                | bit_cast::<11, 5>(self.word.q.val());
        }
        self.read1_valid.d.next = self.issue.val();
        self.read1_kind.d.next = 2.into();
        if self.issue_index.q.val() == 0 {
            self.read1_kind.d.next = 0.into();
        }
        if self.issue_index.q.val() == 1 {
            self.read1_kind.d.next = 1.into();
        }
        self.read1_last.d.next = self.finishing.val();
        self.read2_valid.d.next = self.read1_valid.q.val();
        self.read2_kind.d.next = self.read1_kind.q.val();
        self.read2_last.d.next = self.read1_last.q.val();

        // the word arriving from the RAM, and the beat it makes (`port` still holds the
        // record's port: the next grant comes after its last read arrived)
        self.read_word.next = self.memories[0].read_data.val();
        for b in 1..self.memories.len() {
            if self.port.q.val().get_bit(5) {
                self.read_word.next = self.memories[b].read_data.val();
            }
        }
        self.arrival.next = bit_cast::<9, 8>(self.read_word.val().get_bits::<8>(0))
            | (bit_cast::<9, 1>(self.read2_last.q.val().into()) << 8);
        if self.read2_kind.q.val() == 0 {
            self.arrival.next = bit_cast::<9, 6>(self.port.q.val());
        }
        if self.read2_kind.q.val() == 1 {
            self.arrival.next = bit_cast::<9, 1>(self.read_word.val().get_bit(8).into());
        }

        // ---- output FIFO ----
        self.records.valid.next = self.fifo_count.q.val() != 0;
        self.records.data.next = self.fifo_0.q.val().get_bits::<8>(0);
        self.records.last.next = self.fifo_0.q.val().get_bit(8);
        self.records.error.next = false;
        // (from the count, not from `records.valid`: Verilator orders the statements
        // apart only when no assigned output is read back)
        self.fifo_pop.next = (self.fifo_count.q.val() != 0) & self.records.ready.val();
        // a pop moves every entry down one; the arrival goes behind the last kept entry
        self.fifo_slot.next = self.fifo_count.q.val();
        if self.fifo_pop.val() {
            self.fifo_0.d.next = self.fifo_1.q.val();
            self.fifo_1.d.next = self.fifo_2.q.val();
            self.fifo_2.d.next = self.fifo_3.q.val();
            self.fifo_slot.next = self.fifo_count.q.val() - 1;
        }
        if self.read2_valid.q.val() {
            if self.fifo_slot.val() == 0 {
                self.fifo_0.d.next = self.arrival.val();
            }
            if self.fifo_slot.val() == 1 {
                self.fifo_1.d.next = self.arrival.val();
            }
            if self.fifo_slot.val() == 2 {
                self.fifo_2.d.next = self.arrival.val();
            }
            if self.fifo_slot.val() == 3 {
                self.fifo_3.d.next = self.arrival.val();
            }
        }
        if self.read2_valid.q.val() & !self.fifo_pop.val() {
            self.fifo_count.d.next = self.fifo_count.q.val() + 1;
        } else if !self.read2_valid.q.val() & self.fifo_pop.val() {
            self.fifo_count.d.next = self.fifo_count.q.val() - 1;
        }

        // ---- write side: the ring, each port's state, the bank write registers ----
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
            self.bank_data[b].clock.next = self.clock.val();
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
            // occupancy: +1 on commit, -1 when the reader finishes this port's record
            // (`port` still holds the freed port: the next grant comes two clocks later)
            self.free[i].next =
                self.freeing.q.val() & (self.port.q.val() == self.port_number[i].val());
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
            self.full[i].d.next = self.used_next[i].val() == self.slots.val();
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
            self.bank_data[b].d.next = self.bank_data_term[b].val();
        }
        for b in 0..self.memories.len() {
            self.memories[b].write_enable.next = self.bank_write[b].q.val();
            self.memories[b].write_address.next = self.bank_address[b].q.val();
            self.memories[b].write_data.next = self.bank_data[b].q.val();
        }
        if self.port_reset.val() {
            self.visit.d.next = self.ring_start.val();
        }
        if self.reset.val() {
            self.scan.d.next = 0.into();
            self.scan_onehot.d.next = self.bit_zero.val();
            self.hit.d.next = false;
            self.reading.d.next = false;
            self.freeing.d.next = false;
            self.read1_valid.d.next = false;
            self.read2_valid.d.next = false;
            self.fifo_count.d.next = 0.into();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;
    use std::collections::VecDeque;

    /// A packet a deframer offers: its 24 stored bytes, cut to `bytes.len()` beats and
    /// ended with `error` when it is rejected.
    #[derive(Clone, Debug, PartialEq)]
    struct Offer {
        bytes: Vec<u8>,
        error: bool,
    }

    fn good(port: usize, k: usize) -> Offer {
        Offer {
            bytes: (0..STORED_BEATS)
                .map(|i| (port * 53 + k * 31 + i) as u8)
                .collect(),
            error: false,
        }
    }

    fn rejected(port: usize, k: usize, beats: usize) -> Offer {
        let mut o = good(port, k);
        o.bytes.truncate(beats);
        o.error = true;
        o
    }

    /// A record as it leaves the store: port, flags, stored bytes.
    type Record = (u8, u8, Vec<u8>);

    struct Run {
        records: Vec<Record>,
        /// Clock of each record's first beat.
        record_clocks: Vec<u64>,
        drops: Vec<u32>,
    }

    /// Offers each port's packets beat by beat (a new beat `gap` clocks after the previous
    /// one moved, the stream contract: a beat stays offered until taken) while the record
    /// sink takes beats per `ready` from clock `read_after` on.
    fn run(
        queues: Vec<VecDeque<Offer>>,
        gap: u64,
        ready: &[bool],
        read_after: u64,
        clocks: u64,
    ) -> Run {
        let n = queues.len();
        let mut queues = queues;
        let mut bench = Bench::new(PacketStore::new(n), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.uut.port_reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        bench.uut.port_reset.next = false;
        let mut position = vec![0usize; n];
        let mut wait = vec![0u64; n];
        let mut beats: Vec<(u8, bool, u64)> = vec![];
        let mut drops = vec![0u32; n];
        for clock in 0..clocks {
            for p in 0..n {
                let beat = queues[p].front().filter(|_| wait[p] == 0).map(|o| {
                    (
                        o.bytes[position[p]],
                        position[p] + 1 == o.bytes.len(),
                        o.error,
                    )
                });
                let s = &mut bench.uut.ports[p];
                s.valid.next = beat.is_some();
                if let Some((d, last, error)) = beat {
                    s.data.next = u64::from(d).into();
                    s.last.next = last;
                    s.error.next = error && last;
                }
            }
            let r = clock >= read_after && ready[clock as usize % ready.len()];
            bench.uut.records.ready.next = r;
            bench.settle();
            let u = &bench.uut;
            for p in 0..n {
                wait[p] = wait[p].saturating_sub(1);
                if u.ports[p].ready.val() && u.ports[p].valid.val() {
                    position[p] += 1;
                    wait[p] = gap;
                    if position[p] == queues[p][0].bytes.len() {
                        queues[p].pop_front();
                        position[p] = 0;
                    }
                }
                let events = u.events[p].val().to_u8();
                assert_eq!(events & !2, 0, "only the dropped-overflow event");
                drops[p] += u32::from(events >> 1);
            }
            assert!(!u.records.error.val());
            if r && u.records.valid.val() {
                beats.push((u.records.data.val().to_u8(), u.records.last.val(), clock));
            }
            bench.cycle();
        }
        assert!(
            queues.iter().all(|q| q.is_empty()),
            "offers left: {:?}",
            queues.iter().map(|q| q.len()).collect::<Vec<_>>()
        );
        let mut records = vec![];
        let mut record_clocks = vec![];
        let mut current = vec![];
        for (d, last, clock) in beats {
            if current.is_empty() {
                record_clocks.push(clock);
            }
            current.push(d);
            if last {
                assert_eq!(current.len(), RECORD_BEATS, "record length: {current:?}");
                records.push((current[0], current[1], current[2..].to_vec()));
                current.clear();
            }
        }
        assert!(current.is_empty(), "unfinished record {current:?}");
        Run {
            records,
            record_clocks,
            drops,
        }
    }

    fn queues(n: usize, per_port: usize) -> Vec<VecDeque<Offer>> {
        (0..n)
            .map(|p| (0..per_port).map(|k| good(p, k)).collect())
            .collect()
    }

    #[test]
    fn every_port_busy_gets_one_grant_per_round() {
        for n in [1, 3, 8] {
            // beats every 12 clocks: each port has a packet ready in every round
            let out = run(
                queues(n, 4),
                12,
                &[true],
                0,
                4 * 24 * 13 + 60 * n as u64 + 200,
            );
            assert_eq!(out.records.len(), 4 * n, "{n} ports");
            assert_eq!(out.drops.iter().sum::<u32>(), 0);
            let mut seen = vec![0usize; n];
            for (i, (port, flags, bytes)) in out.records.iter().enumerate() {
                let p = *port as usize;
                assert_eq!(flags, &0);
                assert_eq!(
                    bytes,
                    &good(p, seen[p]).bytes,
                    "port {p} packet {}",
                    seen[p]
                );
                seen[p] += 1;
                if i > 0 {
                    // every port always has a packet: the grants go round in port order
                    let previous = out.records[i - 1].0 as usize;
                    assert_eq!(p, (previous + 1) % n, "record {i}: round robin");
                }
            }
        }
    }

    #[test]
    fn two_banks_carry_every_port() {
        // 40 ports: bank 0 holds 32, bank 1 holds 8; both rings run with period 32
        let n = 40;
        assert_eq!(visit_period(n), 32);
        let out = run(queues(n, 2), 0, &[true], 0, 5000);
        every_port_in_order(&out.records, n, 2);
    }

    /// Each of `n` ports' records are its `per_port` good packets, in order, unflagged.
    fn every_port_in_order(records: &[Record], n: usize, per_port: usize) {
        assert_eq!(records.len(), per_port * n);
        for p in 0..n {
            let got: Vec<(u8, &Vec<u8>)> = records
                .iter()
                .filter(|r| r.0 as usize == p)
                .map(|r| (r.1, &r.2))
                .collect();
            let want: Vec<Vec<u8>> = (0..per_port).map(|k| good(p, k).bytes).collect();
            assert_eq!(
                got,
                want.iter().map(|w| (0, w)).collect::<Vec<_>>(),
                "port {p}"
            );
        }
    }

    #[test]
    fn records_survive_any_backpressure() {
        let n = 5;
        for ready in [
            &[true, false][..],
            &[false, false, true],
            &[true, true, false, true, false, false, false, true],
        ] {
            let out = run(queues(n, 3), 30, ready, 0, 20_000);
            every_port_in_order(&out.records, n, 3);
        }
    }

    #[test]
    fn rejected_packets_vanish_and_flag_the_next() {
        let q: VecDeque<Offer> = vec![
            good(0, 1),
            rejected(0, 9, 7),
            good(0, 2),
            rejected(0, 10, STORED_BEATS),
            good(0, 3),
        ]
        .into();
        // the reader keeps up: nothing drops
        let out = run(vec![VecDeque::new(), q], 3, &[true], 0, 2000);
        let got: Vec<(u8, u8, Vec<u8>)> = out.records;
        assert_eq!(
            got,
            vec![
                (1, 0, good(0, 1).bytes),
                (1, 1, good(0, 2).bytes),
                (1, 1, good(0, 3).bytes)
            ]
        );
        assert_eq!(out.drops, vec![0, 0]);
    }

    #[test]
    fn overflow_drops_whole_packets_counts_them_and_flags_the_next() {
        // the reader sleeps until all five packets were offered: two fit, three drop
        let n = 3;
        let mut qs: Vec<VecDeque<Offer>> = vec![VecDeque::new(); n];
        qs[2] = (0..5).map(|k| good(2, k)).collect();
        let out = run(qs, 0, &[true], 5 * 24 * 3 + 20, 1200);
        let got: Vec<&Vec<u8>> = out.records.iter().map(|r| &r.2).collect();
        assert_eq!(got, vec![&good(2, 0).bytes, &good(2, 1).bytes]);
        assert_eq!(out.drops, vec![0, 0, 3]);

        // a packet after drops carries the loss flag
        let mut qs: Vec<VecDeque<Offer>> = vec![VecDeque::new(); n];
        qs[0] = (0..4).map(|k| good(0, k)).collect();
        // a beat 7 clocks after the previous one moved, taken at the next visit (every 3
        // clocks): a packet takes 24 x 9 = 216 clocks. Packet 2 starts at about 432 and
        // finds both slots full; the reader wakes at 540 and frees a slot before packet 3
        // starts at about 648
        let out = run(qs, 7, &[true], 540, 1500);
        assert_eq!(out.drops, vec![1, 0, 0]);
        let got: Vec<(u8, u8, Vec<u8>)> = out.records;
        assert_eq!(
            got,
            vec![
                (0, 0, good(0, 0).bytes),
                (0, 0, good(0, 1).bytes),
                (0, 1, good(0, 3).bytes)
            ]
        );
    }

    #[test]
    fn a_lone_port_is_found_wherever_the_scan_is() {
        let n = 8;
        let mut qs: Vec<VecDeque<Offer>> = vec![VecDeque::new(); n];
        qs[6] = (0..3).map(|k| good(6, k)).collect();
        qs[2] = (0..1).map(|k| good(2, k)).collect();
        let out = run(qs, 0, &[true], 0, 1500);
        let ports: Vec<u8> = out.records.iter().map(|r| r.0).collect();
        assert_eq!(ports, vec![2, 6, 6, 6]);
    }

    #[test]
    fn a_record_streams_one_beat_per_clock() {
        // one port, the reader free: the 26 beats of a record leave on 26 clocks in a row
        let out = run(queues(1, 2), 0, &[true], 0, 400);
        assert_eq!(out.records.len(), 2);
        let gap = out.record_clocks[1] - out.record_clocks[0];
        assert!(
            gap >= RECORD_BEATS as u64,
            "records overlap: {:?}",
            out.record_clocks
        );
    }

    #[test]
    #[should_panic(expected = "65 ports")]
    fn more_than_64_ports_is_refused() {
        PacketStore::new(65);
    }
}
