//! CellDownlink: queues whole 20-byte cell command packets per port and sends them on each
//! port's UART pin, the way back to the cells (the packet: docs/wire-format.md).
//!
//! - The packet is captured as the frame parser writes a received frame into the reply
//!   buffer: the bytes written at frame offsets [`PACKET_OFFSET`].. (where a cell command
//!   carries its packet) go into a 160-bit register a clock after they are written,
//!   whatever the frame is.
//! - `busy` (the previous packet is still being copied into the queues) and `full_ports`
//!   (bit `p`: port `p` holds [`QUEUE_PACKETS`] packets) come straight from registers. The
//!   command unit `offer`s the captured packet for a port (or `ALL_PORTS`) in the clock it
//!   decides a cell command, only when neither says no: a packet is queued whole in every
//!   target port or not at all, and nothing waits outside the queues.
//! - An accepted packet moves to the staging register (a clock after the offer) and is
//!   copied, a byte a clock, into each target port's queue (two packet slots per port in
//!   one [`BlockRam`]: port, slot and byte index form the address), port after port for
//!   `ALL_PORTS`: [`COPY_CLOCKS_PER_PORT`] clocks each. `accepted` pulses with
//!   `accepted_port` as each copy is committed.
//! - All pins share one bit time and one frame: a phase accumulator (31.25 clocks a bit at
//!   4 Mbit/s) steps a frame of [`frame_bits`] bits (start, eight data bits, stop; a second
//!   stop bit above [`TEN_BIT_FRAME_PORTS`] ports), and every port that has a byte sends it
//!   in that frame. A port keeps only its pin and the value the pin takes at the next start
//!   or data bit (`next_pin`): every pin changes at the same clock edges.
//! - After the frame's last data bit has gone to the pins, a refill scan visits one port a
//!   clock: it reads the port's read position (a RAM) and the next byte of its oldest
//!   packet (the queue RAM) into the port's word of the frame bytes (block RAM banks of
//!   [`DOWNLINK_BANK_PORTS`] ports), or 0xFF when the port's queue is empty, and sets `next_pin` to
//!   the port's start bit (low with a byte, high without), before the next frame's start
//!   bit. A slot is free when its last byte was read; a port's packets go out back to back,
//!   in order.
//! - During each bit that a data bit follows, the pin scan reads a word of every bank a
//!   clock and puts each port's next data bit into its `next_pin`
//!   ([`pin_scan_clocks`] after the bit's end): the bit shifting of every transmitter is
//!   one shared bit index and a RAM read.
//!
//! Latency, a packet committed on an idle port to its first start bit: up to one frame and
//! a refill (about 2.5 to 5 us). Cost per port: 5 flip-flops (pin, next pin value, queue
//! count, write slot) and a bit of the refill scan's ring.

use crate::block_ram::{BlockRam, READ_LATENCY};
use crate::geometry::{DOWNLINK_BANK_PORTS, MAX_PORTS};
use crate::hdl::*;
use crate::uart_rx::{phase_increment, PHASE_BITS};
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::{cell_command_field, ALL_PORTS, HEADER_LEN};
use skinbox_protocol::link::{ETHERNET_HEADER_LEN, IPV4_HEADER_LEN, UDP_HEADER_LEN};

/// Packets each port can hold.
pub const QUEUE_PACKETS: u64 = 2;

/// Clocks the copy of a packet into one port's queue takes.
pub const COPY_CLOCKS_PER_PORT: u64 = PACKET_LEN as u64;

/// Frame offset of the cell packet in a cell command frame: Ethernet, IPv4 (no options)
/// and UDP headers, the command header, then the arguments' packet field.
pub const PACKET_OFFSET: usize = ETHERNET_HEADER_LEN
    + IPV4_HEADER_LEN
    + UDP_HEADER_LEN
    + HEADER_LEN
    + cell_command_field::PACKET.start;

/// Most ports whose refill fits the two stop and start bit times of a 10-bit frame; more
/// ports get a second stop bit.
pub const TEN_BIT_FRAME_PORTS: usize = 56;

/// Clocks from a port's refill visit to its byte register: the read position RAM, then
/// the queue RAM, each two clocks, and the load.
pub const REFILL_LATENCY: u64 = 5;

/// Bits of a frame on every pin: start, eight data, one stop bit (two above
/// [`TEN_BIT_FRAME_PORTS`] ports).
pub fn frame_bits(ports: usize) -> u64 {
    if ports <= TEN_BIT_FRAME_PORTS {
        10
    } else {
        11
    }
}

/// Clock edges from tick 0 to the start of bit `bit` of the shared frames (counting the
/// bits of every frame, from frame 0's start bit): `ceil((bit + 1) * 2^16 / increment)`,
/// where the accumulator carries. A pin changes at such an edge (it is seen from that
/// tick on).
pub fn bit_start(clock_hz: u64, baud: u64, bit: u64) -> u64 {
    ((bit + 1) << PHASE_BITS).div_ceil(phase_increment(clock_hz, baud)) + 1
}

/// Queue RAM address: 6 bits of port, 1 of slot, 5 of byte index.
const ADDRESS_BITS: usize = 12;

/// Clocks of the pin scan after a bit's end before its last port's next data bit is in
/// place: the frame decode (2), the scan of a bank's words, the RAM (2), the value and
/// its write (2).
pub fn pin_scan_clocks(ports: usize) -> u64 {
    2 + ports.min(DOWNLINK_BANK_PORTS) as u64 + READ_LATENCY + 2
}

/// Per port `p`, the scan ring's bit `p + delay`.
fn ring_bits(ports: usize, delay: usize) -> Vec<Constant<Bits<68>>> {
    (0..ports)
        .map(|p| {
            let mut bit = Bits::<68>::default();
            bit = bit.replace_bit(p + delay, true);
            Constant::new(bit)
        })
        .collect()
}

/// The downlink of `ports` UART pins.
#[derive(LogicBlock)]
pub struct CellDownlink {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: queues emptied, pins idle, the frame restarts.
    pub reset: Signal<In, Bit>,
    /// A byte of a received frame is written into the reply buffer (the parser's write
    /// port): `capture_address` is its frame offset, `capture_data` the byte.
    pub capture: Signal<In, Bit>,
    /// Frame offset of the byte on `capture_data`.
    pub capture_address: Signal<In, Bits<11>>,
    /// The byte written.
    pub capture_data: Signal<In, Bits<8>>,
    /// One clock: queue the captured packet for `offer_port` (a port, or `ALL_PORTS`);
    /// only while not `busy` and no target port is full.
    pub offer: Signal<In, Bit>,
    /// Target of the offer.
    pub offer_port: Signal<In, Bits<8>>,
    /// An offer was taken or a packet is being copied into the queues: no offer now.
    pub busy: Signal<Out, Bit>,
    /// Bit `p`: port `p`'s queue is full (bits of ports the box does not have are 0).
    pub full_ports: Signal<Out, Bits<64>>,
    /// One UART pin per port, idle high.
    pub uart_tx: Vec<Signal<Out, Bit>>,
    /// High for one clock when a port's copy of an accepted packet is committed, with
    /// `accepted_port`.
    pub accepted: Signal<Out, Bit>,
    /// The port of that copy.
    pub accepted_port: Signal<Out, Bits<8>>,
    ram: BlockRam<8, ADDRESS_BITS>,
    /// Per port: the slot its oldest packet is in (bit 5) and the next byte's index.
    positions: BlockRam<6, 6>,
    port_number: Vec<Constant<Bits<8>>>,
    port_bit: Vec<Constant<Bits<64>>>,
    last_port: Constant<Bits<8>>,
    packet_first: Constant<Bits<11>>,
    packet_last: Constant<Bits<11>>,
    all_ports: Constant<Bits<8>>,
    phase_increment: Constant<Bits<17>>,
    last_frame_bit: Constant<Bits<4>>,
    // receive and copy
    /// A byte at the packet's offsets was written, registered: the packet register shifts
    /// it in a clock later (the offset's decode does not reach the 160 flip-flops).
    capture_hit: DFF<Bit>,
    capture_byte: DFF<Bits<8>>,
    captured: DFF<Bits<160>>,
    /// The offer, registered: the copy starts a clock after it.
    offered: DFF<Bit>,
    offered_port: DFF<Bits<8>>,
    staging: DFF<Bits<160>>,
    copying: DFF<Bit>,
    broadcast: DFF<Bit>,
    copy_port: DFF<Bits<8>>,
    copy_index: DFF<Bits<5>>,
    accepted_out: DFF<Bit>,
    accepted_port_out: DFF<Bits<8>>,
    write_enable: DFF<Bit>,
    write_address: DFF<Bits<ADDRESS_BITS>>,
    write_data: DFF<Bits<8>>,
    // the shared bit time and frame: the accumulator with its carry on top, the bit on
    // the pins
    phase: DFF<Bits<17>>,
    frame_bit: DFF<Bits<4>>,
    // decoded from `frame_bit` a clock after it changes (a bit lasts at least 4 clocks:
    // the clock is at least 4 x baud), so the pins' next values hang off registers: start
    // bit or data bit, which data bit, the last data bit
    next_is_start: DFF<Bit>,
    next_is_data: DFF<Bit>,
    next_data_bit: DFF<Bits<3>>,
    next_is_last_data: DFF<Bit>,
    // the bit's end and what the pins take then, a clock ahead (from the accumulator's sum
    // as it is written): a start bit, a data bit or a stop bit
    phase_sum: Signal<Local, Bits<17>>,
    pins_take_start: DFF<Bit>,
    pins_take_data: DFF<Bit>,
    pins_take_stop: DFF<Bit>,
    /// Each port's byte of the frame on the pins, written by the refill (0xFF for a port
    /// without a packet), read by the pin scan.
    bytes: Vec<BlockRam<8, 4>>,
    bank_number: Vec<Constant<Bits<2>>>,
    bank_bit: Vec<Constant<Bits<4>>>,
    first_word: Constant<Bits<16>>,
    last_word: Constant<Bits<4>>,
    /// Per port: its word of the pin scan (one bit) and its bank (one bit).
    port_word_bit: Vec<Constant<Bits<16>>>,
    port_bank_bit: Vec<Constant<Bits<4>>>,
    // the pin scan: during a bit followed by a data bit, the next data bit of every port,
    // a word of every bank a clock, into the ports' `next_pin`
    after_bit_end_1: DFF<Bit>,
    after_bit_end_2: DFF<Bit>,
    pin_scanning: DFF<Bit>,
    pin_word: DFF<Bits<4>>,
    pin_visit_1: DFF<Bit>,
    pin_word_1: DFF<Bits<4>>,
    pin_visit_2: DFF<Bit>,
    pin_word_2: DFF<Bits<4>>,
    pin_take: DFF<Bit>,
    pin_onehot: DFF<Bits<16>>,
    /// Bit `b`: the value read from bank `b`.
    pin_value: DFF<Bits<4>>,
    // the refill scan: the port visited, and the pipeline behind it
    refilling: DFF<Bit>,
    scan: DFF<Bits<6>>,
    /// One bit moving up a place a clock from the refill scan's start: bit `p` at port
    /// `p`'s visit, bit `p + 3` when its slot may be freed, bit `p + 4` at its load (the
    /// ports' selects are one bit each, no compare a port).
    scan_ring: DFF<Bits<68>>,
    scan_ring_start: Constant<Bits<68>>,
    /// Per port: its bit of the ring at its visit, its slot's freeing and its load.
    visit_bit: Vec<Constant<Bits<68>>>,
    freed_bit: Vec<Constant<Bits<68>>>,
    load_bit: Vec<Constant<Bits<68>>>,
    visit_1: DFF<Bit>,
    port_1: DFF<Bits<6>>,
    nonempty_1: DFF<Bit>,
    visit_2: DFF<Bit>,
    port_2: DFF<Bits<6>>,
    nonempty_2: DFF<Bit>,
    visit_3: DFF<Bit>,
    port_3: DFF<Bits<6>>,
    nonempty_3: DFF<Bit>,
    visit_4: DFF<Bit>,
    port_4: DFF<Bits<6>>,
    nonempty_4: DFF<Bit>,
    position_write: DFF<Bit>,
    position_port: DFF<Bits<6>>,
    position_next: DFF<Bits<6>>,
    freed: DFF<Bit>,
    clearing: DFF<Bit>,
    clear_address: DFF<Bits<6>>,
    // per port
    count: Vec<DFF<Bits<2>>>,
    tail: Vec<DFF<Bit>>,
    /// The value the pin takes at the next start or data bit.
    next_pin: Vec<DFF<Bit>>,
    pin: Vec<DFF<Bit>>,
    full: Signal<Local, Bits<64>>,
    nonempty: Signal<Local, Bit>,
    copy_tail: Signal<Local, Bit>,
    commit: Signal<Local, Bit>,
    advance: Signal<Local, Bit>,
    bit_end: Signal<Local, Bit>,
    next_bit: Signal<Local, Bits<4>>,
    data_bit: Signal<Local, Bits<3>>,
    position: Signal<Local, Bits<6>>,
    load_byte: Signal<Local, Bits<8>>,
    bank_byte: Signal<Local, Bits<8>>,
    bank_values: Signal<Local, Bits<4>>,
}

impl CellDownlink {
    /// A downlink of `ports` pins (1 to 64) at `baud` with a `clock_hz` box clock.
    pub fn new(ports: usize, clock_hz: u64, baud: u64) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "CellDownlink: {ports} ports (1 to {MAX_PORTS})"
        );
        assert!(
            baud > 0 && clock_hz >= 4 * baud,
            "CellDownlink: clock {clock_hz} Hz must be at least 4 x baud {baud}"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            capture: Default::default(),
            capture_address: Default::default(),
            capture_data: Default::default(),
            offer: Default::default(),
            offer_port: Default::default(),
            busy: Default::default(),
            full_ports: Default::default(),
            uart_tx: each(ports),
            accepted: Default::default(),
            accepted_port: Default::default(),
            ram: Default::default(),
            positions: Default::default(),
            port_number: (0..ports)
                .map(|p| Constant::new((p as u64).into()))
                .collect(),
            port_bit: (0..ports)
                .map(|p| Constant::new((1u64 << p).into()))
                .collect(),
            last_port: Constant::new((ports as u64 - 1).into()),
            packet_first: Constant::new((PACKET_OFFSET as u64).into()),
            packet_last: Constant::new(((PACKET_OFFSET + PACKET_LEN - 1) as u64).into()),
            all_ports: Constant::new(u64::from(ALL_PORTS).into()),
            phase_increment: Constant::new(phase_increment(clock_hz, baud).into()),
            last_frame_bit: Constant::new((frame_bits(ports) - 1).into()),
            capture_hit: Default::default(),
            capture_byte: Default::default(),
            captured: Default::default(),
            offered: Default::default(),
            offered_port: Default::default(),
            staging: Default::default(),
            copying: Default::default(),
            broadcast: Default::default(),
            copy_port: Default::default(),
            copy_index: Default::default(),
            accepted_out: Default::default(),
            accepted_port_out: Default::default(),
            write_enable: Default::default(),
            write_address: Default::default(),
            write_data: Default::default(),
            phase: Default::default(),
            frame_bit: Default::default(),
            next_is_start: Default::default(),
            next_is_data: Default::default(),
            next_data_bit: Default::default(),
            next_is_last_data: Default::default(),
            phase_sum: Default::default(),
            pins_take_start: Default::default(),
            pins_take_data: Default::default(),
            pins_take_stop: Default::default(),
            bytes: each(ports.div_ceil(DOWNLINK_BANK_PORTS)),
            bank_number: (0..ports.div_ceil(DOWNLINK_BANK_PORTS))
                .map(|b| Constant::new((b as u64).into()))
                .collect(),
            bank_bit: (0..ports.div_ceil(DOWNLINK_BANK_PORTS))
                .map(|b| Constant::new((1u64 << b).into()))
                .collect(),
            first_word: Constant::new(1.into()),
            last_word: Constant::new((ports.min(DOWNLINK_BANK_PORTS) as u64 - 1).into()),
            port_word_bit: (0..ports)
                .map(|p| Constant::new((1u64 << (p % DOWNLINK_BANK_PORTS)).into()))
                .collect(),
            port_bank_bit: (0..ports)
                .map(|p| Constant::new((1u64 << (p / DOWNLINK_BANK_PORTS)).into()))
                .collect(),
            after_bit_end_1: Default::default(),
            after_bit_end_2: Default::default(),
            pin_scanning: Default::default(),
            pin_word: Default::default(),
            pin_visit_1: Default::default(),
            pin_word_1: Default::default(),
            pin_visit_2: Default::default(),
            pin_word_2: Default::default(),
            pin_take: Default::default(),
            pin_onehot: Default::default(),
            pin_value: Default::default(),
            refilling: Default::default(),
            scan: Default::default(),
            scan_ring: Default::default(),
            scan_ring_start: Constant::new(1.into()),
            visit_bit: ring_bits(ports, 0),
            freed_bit: ring_bits(ports, 3),
            load_bit: ring_bits(ports, 4),
            visit_1: Default::default(),
            port_1: Default::default(),
            nonempty_1: Default::default(),
            visit_2: Default::default(),
            port_2: Default::default(),
            nonempty_2: Default::default(),
            visit_3: Default::default(),
            port_3: Default::default(),
            nonempty_3: Default::default(),
            visit_4: Default::default(),
            port_4: Default::default(),
            nonempty_4: Default::default(),
            position_write: Default::default(),
            position_port: Default::default(),
            position_next: Default::default(),
            freed: Default::default(),
            clearing: Default::default(),
            clear_address: Default::default(),
            count: each(ports),
            tail: each(ports),
            next_pin: each(ports),
            pin: each(ports),
            full: Default::default(),
            nonempty: Default::default(),
            copy_tail: Default::default(),
            commit: Default::default(),
            advance: Default::default(),
            bit_end: Default::default(),
            next_bit: Default::default(),
            data_bit: Default::default(),
            position: Default::default(),
            load_byte: Default::default(),
            bank_byte: Default::default(),
            bank_values: Default::default(),
        }
    }
}

impl Logic for CellDownlink {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            capture_hit,
            capture_byte,
            captured,
            offered,
            offered_port,
            staging,
            copying,
            broadcast,
            copy_port,
            copy_index,
            accepted_out,
            accepted_port_out,
            write_enable,
            write_address,
            write_data,
            phase,
            frame_bit,
            next_is_start,
            next_is_data,
            next_data_bit,
            next_is_last_data,
            pins_take_start,
            pins_take_data,
            pins_take_stop,
            after_bit_end_1,
            after_bit_end_2,
            pin_scanning,
            pin_word,
            pin_visit_1,
            pin_word_1,
            pin_visit_2,
            pin_word_2,
            pin_take,
            pin_onehot,
            pin_value,
            refilling,
            scan,
            scan_ring,
            visit_1,
            port_1,
            nonempty_1,
            visit_2,
            port_2,
            nonempty_2,
            visit_3,
            port_3,
            nonempty_3,
            visit_4,
            port_4,
            nonempty_4,
            position_write,
            position_port,
            position_next,
            freed,
            clearing,
            clear_address
        );
        self.ram.clock.next = self.clock.val();
        self.positions.clock.next = self.clock.val();
        for b in 0..self.bytes.len() {
            self.bytes[b].clock.next = self.clock.val();
        }
        // the copy's writes are registered: no copy logic in front of the RAM (a slot's
        // last byte lands a clock after its commit, long before a refill reads it)
        self.write_enable.d.next = false;
        self.write_data.d.next = self.staging.q.val().get_bits::<8>(0);
        self.ram.write_enable.next = self.write_enable.q.val();
        self.ram.write_address.next = self.write_address.q.val();
        self.ram.write_data.next = self.write_data.q.val();
        self.accepted_out.d.next = false;

        // capture: the bytes at the packet's frame offsets, the first ending in bits 7..0
        self.capture_hit.d.next = self.capture.val()
            & (self.capture_address.val() >= self.packet_first.val())
            & (self.capture_address.val() <= self.packet_last.val());
        self.capture_byte.d.next = self.capture_data.val();
        if self.capture_hit.q.val() {
            self.captured.d.next = (self.captured.q.val() >> 8)
                | (bit_cast::<160, 8>(self.capture_byte.q.val()) << 152);
        }
        self.busy.next = self.copying.q.val() | self.offered.q.val();
        // (registered: the offer reaches two flip-flops, the copy starts a clock later)
        self.offered.d.next = self.offer.val();
        self.offered_port.d.next = self.offer_port.val();
        if self.offered.q.val() {
            self.staging.d.next = self.captured.q.val();
            self.copying.d.next = true;
            self.copy_index.d.next = 0.into();
            self.broadcast.d.next = self.offered_port.q.val() == self.all_ports.val();
            self.copy_port.d.next = self.offered_port.q.val();
            if self.offered_port.q.val() == self.all_ports.val() {
                self.copy_port.d.next = 0.into();
            }
        }
        // copy the staged packet into the target port's free slot (its `tail`)
        self.copy_tail.next = false;
        for i in 0..self.count.len() {
            if self.copy_port.q.val() == self.port_number[i].val() {
                self.copy_tail.next = self.tail[i].q.val();
            }
        }
        self.commit.next = false;
        self.advance.next = false;
        if self.copying.q.val() {
            self.write_enable.d.next = true;
            self.write_address.d.next = (bit_cast::<ADDRESS_BITS, 8>(self.copy_port.q.val()) << 6)
                | (bit_cast::<ADDRESS_BITS, 1>(self.copy_tail.val().into()) << 5)
                | bit_cast::<ADDRESS_BITS, 5>(self.copy_index.q.val());
            self.staging.d.next = (self.staging.q.val() >> 8)
                | (bit_cast::<160, 8>(self.staging.q.val().get_bits::<8>(0)) << 152);
            self.copy_index.d.next = self.copy_index.q.val() + 1;
            if self.copy_index.q.val() == 19 {
                self.commit.next = true;
                self.accepted_out.d.next = true;
                self.accepted_port_out.d.next = self.copy_port.q.val();
                self.advance.next = true;
            }
        }
        if self.advance.val() {
            self.copy_index.d.next = 0.into();
            if self.broadcast.q.val() & (self.copy_port.q.val() != self.last_port.val()) {
                self.copy_port.d.next = self.copy_port.q.val() + 1;
            } else {
                self.copying.d.next = false;
            }
        }

        // the shared bit time: the accumulator carries at each bit's end
        self.bit_end.next = self.phase.q.val().get_bit(16);
        self.phase_sum.next =
            bit_cast::<17, 16>(self.phase.q.val().get_bits::<16>(0)) + self.phase_increment.val();
        self.phase.d.next = self.phase_sum.val();
        // (the decodes are those of the bit now: they change two clocks after a bit's end)
        self.pins_take_start.d.next = self.phase_sum.val().get_bit(16) & self.next_is_start.q.val();
        self.pins_take_data.d.next = self.phase_sum.val().get_bit(16) & self.next_is_data.q.val();
        self.pins_take_stop.d.next = self.phase_sum.val().get_bit(16)
            & !self.next_is_start.q.val()
            & !self.next_is_data.q.val();
        self.next_bit.next = self.frame_bit.q.val() + 1;
        if self.frame_bit.q.val() == self.last_frame_bit.val() {
            self.next_bit.next = 0.into();
        }
        self.data_bit.next = self.next_bit.val().get_bits::<3>(0) - 1;
        self.next_is_start.d.next = self.next_bit.val() == 0;
        self.next_is_data.d.next = (self.next_bit.val() != 0) & (self.next_bit.val() <= 8);
        self.next_data_bit.d.next = self.data_bit.val();
        self.next_is_last_data.d.next = self.next_bit.val() == 8;
        if self.bit_end.val() {
            self.frame_bit.d.next = self.next_bit.val();
        }
        // the pin scan: two clocks after a bit's end the decodes say what the next bit is;
        // before a data bit, every bank's words are read (port by port of each bank) and
        // each port's next data bit is in its `next_pin` long before the bit's end
        self.after_bit_end_1.d.next = self.bit_end.val();
        self.after_bit_end_2.d.next = self.after_bit_end_1.q.val();
        if self.pin_scanning.q.val() {
            self.pin_word.d.next = self.pin_word.q.val() + 1;
            if self.pin_word.q.val() == self.last_word.val() {
                self.pin_scanning.d.next = false;
            }
        }
        if self.after_bit_end_2.q.val() & self.next_is_data.q.val() {
            self.pin_scanning.d.next = true;
            self.pin_word.d.next = 0.into();
        }
        self.pin_visit_1.d.next = self.pin_scanning.q.val();
        self.pin_word_1.d.next = self.pin_word.q.val();
        self.pin_visit_2.d.next = self.pin_visit_1.q.val();
        self.pin_word_2.d.next = self.pin_word_1.q.val();
        self.pin_take.d.next = self.pin_visit_2.q.val();
        self.pin_onehot.d.next = self.first_word.val() << self.pin_word_2.q.val();
        self.bank_values.next = 0.into();
        for b in 0..self.bytes.len() {
            self.bytes[b].read_address.next = self.pin_word.q.val();
            self.bank_byte.next = self.bytes[b].read_data.val() >> self.next_data_bit.q.val();
            if self.bank_byte.val().get_bit(0) {
                self.bank_values.next = self.bank_values.val() | self.bank_bit[b].val();
            }
        }
        self.pin_value.d.next = self.bank_values.val();
        // the refill scan starts as the pins take the last data bit
        if self.refilling.q.val() {
            self.scan.d.next = self.scan.q.val() + 1;
            if bit_cast::<8, 6>(self.scan.q.val()) == self.last_port.val() {
                self.refilling.d.next = false;
            }
        }
        self.scan_ring.d.next = self.scan_ring.q.val() << 1;
        if self.bit_end.val() & self.next_is_last_data.q.val() {
            self.refilling.d.next = true;
            self.scan.d.next = 0.into();
            self.scan_ring.d.next = self.scan_ring_start.val();
        }
        // visit: the port's queue count; its position read from RAM
        self.nonempty.next = false;
        self.full.next = 0.into();
        for i in 0..self.count.len() {
            if ((self.scan_ring.q.val() & self.visit_bit[i].val()) != 0)
                & (self.count[i].q.val() != 0)
            {
                self.nonempty.next = true;
            }
            if self.count[i].q.val().get_bit(1) {
                self.full.next = self.full.val() | self.port_bit[i].val();
            }
        }
        self.full_ports.next = self.full.val();
        self.positions.read_address.next = self.scan.q.val();
        self.visit_1.d.next = self.refilling.q.val();
        self.port_1.d.next = self.scan.q.val();
        self.nonempty_1.d.next = self.nonempty.val();
        self.visit_2.d.next = self.visit_1.q.val();
        self.port_2.d.next = self.port_1.q.val();
        self.nonempty_2.d.next = self.nonempty_1.q.val() & self.visit_1.q.val();
        // two clocks later: the byte's address, and the next position
        self.position.next = self.positions.read_data.val();
        self.ram.read_address.next = (bit_cast::<ADDRESS_BITS, 6>(self.port_2.q.val()) << 6)
            | bit_cast::<ADDRESS_BITS, 6>(self.position.val());
        self.position_write.d.next = self.nonempty_2.q.val();
        self.position_port.d.next = self.port_2.q.val();
        self.position_next.d.next = self.position.val() + 1;
        self.freed.d.next = false;
        if self.position.val().get_bits::<5>(0) == 19 {
            // the last byte of the slot: the other slot next, this one is free
            self.position_next.d.next =
                bit_cast::<6, 1>((!self.position.val().get_bit(5)).into()) << 5;
            self.freed.d.next = self.nonempty_2.q.val();
        }
        self.visit_3.d.next = self.visit_2.q.val();
        self.port_3.d.next = self.port_2.q.val();
        self.nonempty_3.d.next = self.nonempty_2.q.val();
        self.visit_4.d.next = self.visit_3.q.val();
        self.port_4.d.next = self.port_3.q.val();
        self.nonempty_4.d.next = self.nonempty_3.q.val();
        // two clocks after the address: the byte, or 0xFF and no start bit when empty
        self.load_byte.next = self.ram.read_data.val();
        if !self.nonempty_4.q.val() {
            self.load_byte.next = 0xFF.into();
        }
        for b in 0..self.bytes.len() {
            self.bytes[b].write_enable.next = self.visit_4.q.val()
                & (self.port_4.q.val().get_bits::<2>(4) == self.bank_number[b].val());
            self.bytes[b].write_address.next = self.port_4.q.val().get_bits::<4>(0);
            self.bytes[b].write_data.next = self.load_byte.val();
            if self.clearing.q.val() {
                // after reset every port's byte is 0xFF: no data bit before the first refill
                self.bytes[b].write_enable.next = true;
                self.bytes[b].write_address.next = self.clear_address.q.val().get_bits::<4>(0);
                self.bytes[b].write_data.next = 0xFF.into();
            }
        }
        self.positions.write_enable.next = self.position_write.q.val() | self.clearing.q.val();
        self.positions.write_address.next = self.position_port.q.val();
        self.positions.write_data.next = self.position_next.q.val();
        if self.clearing.q.val() {
            // after reset every port reads slot 0 from byte 0
            self.positions.write_address.next = self.clear_address.q.val();
            self.positions.write_data.next = 0.into();
            self.clear_address.d.next = self.clear_address.q.val() + 1;
            if self.clear_address.q.val() == 63 {
                self.clearing.d.next = false;
            }
        }

        for i in 0..self.count.len() {
            self.count[i].clock.next = self.clock.val();
            self.tail[i].clock.next = self.clock.val();
            self.next_pin[i].clock.next = self.clock.val();
            self.pin[i].clock.next = self.clock.val();
            self.tail[i].d.next = self.tail[i].q.val();
            self.next_pin[i].d.next = self.next_pin[i].q.val();
            self.pin[i].d.next = self.pin[i].q.val();
            // the queue count: +1 on a copy's commit, -1 when the last byte is read
            self.count[i].d.next = self.count[i].q.val();
            if self.commit.val() & (self.copy_port.q.val() == self.port_number[i].val()) {
                self.tail[i].d.next = !self.tail[i].q.val();
                self.count[i].d.next = self.count[i].q.val() + 1;
                if self.freed.q.val() & ((self.scan_ring.q.val() & self.freed_bit[i].val()) != 0) {
                    self.count[i].d.next = self.count[i].q.val();
                }
            } else if self.freed.q.val() & ((self.scan_ring.q.val() & self.freed_bit[i].val()) != 0)
            {
                self.count[i].d.next = self.count[i].q.val() - 1;
            }
            // the next start bit, at the refill's load (high: no packet, no start bit); the
            // next data bit, from the pin scan
            if self.visit_4.q.val() & ((self.scan_ring.q.val() & self.load_bit[i].val()) != 0) {
                self.next_pin[i].d.next = !self.nonempty_4.q.val();
            }
            if self.pin_take.q.val()
                & ((self.pin_onehot.q.val() & self.port_word_bit[i].val()) != 0)
            {
                self.next_pin[i].d.next =
                    (self.pin_value.q.val() & self.port_bank_bit[i].val()) != 0;
            }
            // the pin at each bit's start: start bit, data bit, stop bits
            if self.pins_take_start.q.val() | self.pins_take_data.q.val() {
                self.pin[i].d.next = self.next_pin[i].q.val();
            }
            if self.pins_take_stop.q.val() {
                self.pin[i].d.next = true;
            }
            if self.reset.val() {
                self.count[i].d.next = 0.into();
                self.tail[i].d.next = false;
                self.next_pin[i].d.next = true;
                self.pin[i].d.next = true;
            }
            self.uart_tx[i].next = self.pin[i].q.val();
        }
        if self.reset.val() {
            self.copying.d.next = false;
            self.offered.d.next = false;
            self.write_enable.d.next = false;
            self.accepted_out.d.next = false;
            self.phase.d.next = 0.into();
            self.pins_take_start.d.next = false;
            self.pins_take_data.d.next = false;
            self.pins_take_stop.d.next = false;
            self.frame_bit.d.next = self.last_frame_bit.val();
            self.refilling.d.next = false;
            self.pin_scanning.d.next = false;
            self.pin_visit_1.d.next = false;
            self.pin_visit_2.d.next = false;
            self.pin_take.d.next = false;
            self.visit_1.d.next = false;
            self.visit_2.d.next = false;
            self.nonempty_2.d.next = false;
            self.visit_3.d.next = false;
            self.visit_4.d.next = false;
            self.position_write.d.next = false;
            self.freed.d.next = false;
            self.clearing.d.next = true;
            self.clear_address.d.next = 0.into();
        }
        self.accepted.next = self.accepted_out.q.val();
        self.accepted_port.next = self.accepted_port_out.q.val();
    }
}

// the staging register and byte indices are sized for 20-byte packets, the refill
// pipeline for the RAMs' read latency
const _: () = assert!(PACKET_LEN == 20 && READ_LATENCY == 2);
// the refill of every port fits between the frame's last data bit and the next start bit
const _: () = assert!(TEN_BIT_FRAME_PORTS as u64 + REFILL_LATENCY < 62);
const _: () = assert!(MAX_PORTS as u64 + REFILL_LATENCY < 93);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{bit_period, decode_uart_line, Bench, TestRng};
    use crate::{CELL_BAUD, CLOCK_HZ};
    use skinbox_protocol::cell_command::COMMAND_HEADER;

    struct Run {
        bench: Bench<CellDownlink>,
        /// Every port's pin after each edge.
        pins: Vec<Vec<bool>>,
        /// The packets each port committed, in order.
        queued: Vec<Vec<[u8; 20]>>,
        /// Offers refused.
        refused: u64,
        /// The last packet offered.
        last_offered: [u8; 20],
    }

    impl Run {
        fn new(ports: usize) -> Self {
            let mut bench = Bench::new(CellDownlink::new(ports, CLOCK_HZ, CELL_BAUD), |b| {
                &mut b.clock
            });
            bench.uut.reset.next = true;
            bench.cycles(2);
            bench.uut.reset.next = false;
            Run {
                bench,
                pins: vec![vec![]; ports],
                queued: vec![vec![]; ports],
                refused: 0,
                last_offered: [0; 20],
            }
        }

        fn cycle(&mut self) {
            self.bench.cycle();
            let uut = &self.bench.uut;
            for (p, pin) in self.pins.iter_mut().enumerate() {
                pin.push(uut.uart_tx[p].val());
            }
            if uut.accepted.val() {
                let p = uut.accepted_port.val().index();
                self.queued[p].push(self.last_offered);
            }
        }

        /// Writes a 90-byte frame whose bytes at the packet offsets are `packet` (the
        /// others random), as the parser writes the reply buffer, one byte a clock.
        fn capture(&mut self, packet: &[u8; 20], rng: &mut TestRng) {
            for offset in 0..PACKET_OFFSET + PACKET_LEN + 4 {
                let byte = match offset.checked_sub(PACKET_OFFSET) {
                    Some(i) if i < PACKET_LEN => packet[i],
                    _ => rng.byte(),
                };
                self.bench.uut.capture.next = true;
                self.bench.uut.capture_address.next = (offset as u64).into();
                self.bench.uut.capture_data.next = u64::from(byte).into();
                self.cycle();
            }
            self.bench.uut.capture.next = false;
        }

        /// Offers the captured packet for `port` when `busy` and `full_ports` leave room,
        /// as the command unit does; true when offered.
        fn offer(&mut self, port: u8) -> bool {
            self.bench.settle();
            let full = self.bench.uut.full_ports.val().to_u64();
            let room = !self.bench.uut.busy.val()
                && if port == ALL_PORTS {
                    full == 0
                } else {
                    full >> port & 1 == 0
                };
            self.bench.uut.offer.next = room;
            self.bench.uut.offer_port.next = u64::from(port).into();
            self.cycle();
            self.bench.uut.offer.next = false;
            if !room {
                self.refused += 1;
            }
            room
        }

        /// Captures `packet`, offers it for `port` and, when accepted, waits until every
        /// copy is committed; true when accepted.
        fn send(&mut self, port: u8, packet: &[u8; 20], rng: &mut TestRng) -> bool {
            self.capture(packet, rng);
            let before = self.last_offered;
            self.last_offered = *packet;
            if !self.offer(port) {
                self.last_offered = before;
                return false;
            }
            let copies = if port == ALL_PORTS {
                self.pins.len()
            } else {
                1
            };
            self.idle(copies as u64 * COPY_CLOCKS_PER_PORT + 2);
            true
        }

        fn idle(&mut self, clocks: u64) {
            for _ in 0..clocks {
                self.cycle();
            }
        }

        /// Idles until every pin has been idle for two byte times.
        fn drain(&mut self) {
            loop {
                self.idle(700);
                let quiet = self
                    .pins
                    .iter()
                    .all(|p| p[p.len() - 700..].iter().all(|l| *l));
                if quiet {
                    return;
                }
            }
        }

        /// Every port's pin, decoded by the line model, equals the packets it accepted, and
        /// each port's frames follow each other back to back.
        fn check_pins(&self) {
            let period = bit_period(0.0);
            for (p, pin) in self.pins.iter().enumerate() {
                let frames = decode_uart_line(pin);
                let bytes: Vec<u8> = frames.iter().map(|f| f.1).collect();
                let expected: Vec<u8> = self.queued[p].concat();
                assert_eq!(bytes, expected, "port {p}");
                assert!(frames.iter().all(|f| f.2), "port {p}: stop bits high");
                for packet in frames.chunks(20) {
                    for pair in packet.windows(2) {
                        let gap = (pair[1].0 - pair[0].0) as f64;
                        assert!(
                            (gap - frame_bits(self.pins.len()) as f64 * period).abs() < 1.5,
                            "port {p}: frames {} clocks apart",
                            gap
                        );
                    }
                }
            }
        }
    }

    fn packet(rng: &mut TestRng) -> [u8; 20] {
        let mut p = [0; 20];
        p.iter_mut().for_each(|b| *b = rng.byte());
        p[0] = COMMAND_HEADER;
        p
    }

    #[test]
    fn one_port_sends_its_packets_back_to_back_in_order() {
        let mut rng = TestRng::new(1);
        let mut run = Run::new(8);
        let (a, b) = (packet(&mut rng), packet(&mut rng));
        assert!(run.send(3, &a, &mut rng));
        assert!(run.send(3, &b, &mut rng));
        run.drain();
        assert_eq!(run.queued[3], vec![a, b]);
        assert_eq!(run.refused, 0);
        run.check_pins();
        // the two packets form one burst of 40 frames
        let frames = decode_uart_line(&run.pins[3]);
        let span = (frames[39].0 - frames[0].0) as f64;
        // (up to a clock late, plus the rounding of the increment: 0.007 % slow)
        assert!(
            (span - 39.0 * frame_bits(8) as f64 * bit_period(0.0)).abs() < 2.5,
            "{span}"
        );
    }

    #[test]
    fn a_full_queue_refuses_whole_packets_and_takes_again_once_a_slot_is_free() {
        let mut rng = TestRng::new(2);
        let mut run = Run::new(2);
        let sent: Vec<[u8; 20]> = (0..5).map(|_| packet(&mut rng)).collect();
        let accepted: Vec<bool> = sent[..4].iter().map(|p| run.send(1, p, &mut rng)).collect();
        assert_eq!(accepted, [true, true, false, false]);
        assert_eq!(run.refused, 2);
        run.drain();
        assert!(run.send(1, &sent[4], &mut rng));
        run.drain();
        assert_eq!(run.queued[1], vec![sent[0], sent[1], sent[4]]);
        assert!(run.queued[0].is_empty());
        run.check_pins();
    }

    #[test]
    fn all_ports_is_queued_in_every_port_or_in_none() {
        let mut rng = TestRng::new(3);
        let mut run = Run::new(4);
        let (a, b, c) = (packet(&mut rng), packet(&mut rng), packet(&mut rng));
        assert!(run.send(2, &a, &mut rng));
        assert!(run.send(2, &b, &mut rng));
        // port 2 is full: the broadcast goes nowhere
        assert!(!run.send(ALL_PORTS, &c, &mut rng));
        run.drain();
        assert!(run.send(ALL_PORTS, &c, &mut rng));
        run.drain();
        assert_eq!(run.queued, vec![vec![c], vec![c], vec![a, b, c], vec![c]]);
        assert_eq!(run.refused, 1);
        run.check_pins();
    }

    #[test]
    fn an_offer_while_a_copy_is_under_way_is_refused() {
        let mut rng = TestRng::new(6);
        let mut run = Run::new(4);
        let (a, b) = (packet(&mut rng), packet(&mut rng));
        run.capture(&a, &mut rng);
        run.last_offered = a;
        assert!(run.offer(ALL_PORTS));
        // the registered offer and the copy into 4 ports take 81 clocks; offers in all of
        // them are refused
        for _ in 0..4 * COPY_CLOCKS_PER_PORT + 1 {
            assert!(!run.offer(0));
        }
        assert!(run.offer(1), "the clock after the last copy");
        run.idle(COPY_CLOCKS_PER_PORT + 2);
        run.drain();
        assert_eq!(run.queued, vec![vec![a], vec![a, a], vec![a], vec![a]]);
        // a capture between offers replaces the packet
        assert!(run.send(0, &b, &mut rng));
        run.drain();
        assert_eq!(run.queued[0], vec![a, b]);
        run.check_pins();
    }

    #[test]
    fn a_one_port_box_takes_all_ports_packets() {
        let mut rng = TestRng::new(5);
        let mut run = Run::new(1);
        let sent: Vec<[u8; 20]> = (0..3).map(|_| packet(&mut rng)).collect();
        for p in &sent {
            run.send(ALL_PORTS, p, &mut rng);
        }
        assert_eq!(run.refused, 1);
        run.drain();
        assert_eq!(run.queued, vec![vec![sent[0], sent[1]]]);
        run.check_pins();
    }

    #[test]
    fn random_traffic_on_eight_ports_and_verilog_of_1_8_64_ports_passes_lint() {
        let mut rng = TestRng::new(4);
        let mut run = Run::new(8);
        let (mut offered, mut copies) = (0, 0);
        for _ in 0..24 {
            let port = if rng.chance(0.2) {
                ALL_PORTS
            } else {
                (rng.next_u64() % 8) as u8
            };
            let p = packet(&mut rng);
            offered += 1;
            if run.send(port, &p, &mut rng) {
                copies += if port == ALL_PORTS { 8 } else { 1 };
            }
            run.idle(rng.next_u64() % 2000);
        }
        run.drain();
        let queued: usize = run.queued.iter().map(Vec::len).sum();
        assert_eq!(queued, copies, "every accepted packet queued in its ports");
        assert!(run.refused > 0 && run.refused < offered);
        run.check_pins();

        for ports in [1, 8, 64] {
            let mut uut = CellDownlink::new(ports, CLOCK_HZ, CELL_BAUD);
            uut.connect_all();
            let dir = std::env::temp_dir().join(format!(
                "skinbox-downlink-lint-{}-{ports}",
                std::process::id()
            ));
            std::fs::create_dir_all(&dir).unwrap();
            let report = crate::verilog::lint(&generate_verilog(&uut), &dir).unwrap();
            std::fs::remove_dir_all(&dir).ok();
            assert!(report.clean, "{ports} ports: {}", report.output);
        }
    }
}
