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
//! - Time syncs (cell command 5): every sync packet leaves with bytes 4-11 = the box tick
//!   of its first start bit on the pin, whoever queued it; and every `sync_period` ticks
//!   ([`SyncGenerator`]) every port sends a time sync to every cell of its own, before its
//!   queued packets at its next packet boundary, taking no queue slot (the refill keeps
//!   what it needs in its position RAM; [`DownlinkSyncBytes`] the frames' start ticks).
//!
//! The parts are blocks of their own: [`DownlinkPacketCopy`] (capture and copy),
//! [`DownlinkFrameTimer`] (the shared bit time and frame), [`DownlinkRefill`],
//! [`DownlinkPinScan`] and [`SyncGenerator`]; this block holds the RAMs they share and
//! each port's registers.
//!
//! Latency, a packet committed on an idle port to its first start bit: up to one frame and
//! a refill (about 2.5 to 5 us). Cost per port: 5 flip-flops (pin, next pin value, queue
//! count, write slot) and a bit of the refill scan's ring.

use crate::block_ram::{BlockRam, READ_LATENCY};
use crate::downlink_frame_timer::DownlinkFrameTimer;
pub use crate::downlink_frame_timer::{bit_start, frame_bits, TEN_BIT_FRAME_PORTS};
use crate::downlink_packet_copy::{DownlinkPacketCopy, QUEUE_ADDRESS_BITS};
pub use crate::downlink_packet_copy::{COPY_CLOCKS_PER_PORT, PACKET_OFFSET};
pub use crate::downlink_pin_scan::pin_scan_clocks;
use crate::downlink_pin_scan::DownlinkPinScan;
pub use crate::downlink_refill::REFILL_LATENCY;
use crate::downlink_refill::{ring_bits, DownlinkRefill, RING_BITS};
#[cfg(doc)]
use crate::downlink_sync_bytes::DownlinkSyncBytes;
use crate::geometry::{DOWNLINK_BANK_PORTS, MAX_PORTS};
use crate::hdl::*;
use crate::sync_generator::SyncGenerator;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::cell_command::CellCommandFraming;

/// Packets each port can hold.
pub const QUEUE_PACKETS: u64 = 2;

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
    /// The box tick (time syncs are stamped with it).
    pub tick: Signal<In, Bits<64>>,
    /// Ticks between the box's own time syncs; 0: none.
    pub sync_period: Signal<In, Bits<32>>,
    /// One clock: `sync_period` was just set (the count restarts; a sync at once unless 0).
    pub sync_restart: Signal<In, Bit>,
    /// The box sends its own time syncs (`sync_period` is not 0).
    pub syncs_on: Signal<Out, Bit>,
    copy: DownlinkPacketCopy,
    timer: DownlinkFrameTimer,
    pin_scan: DownlinkPinScan,
    refill: DownlinkRefill,
    generator: SyncGenerator,
    /// Two packet slots per port: port, slot and byte index form the address.
    queues: BlockRam<8, QUEUE_ADDRESS_BITS>,
    /// Each port's byte of the frame on the pins, written by the refill (0xFF for a port
    /// without a packet), read by the pin scan.
    bytes: Vec<BlockRam<8, 4>>,
    port_number: Vec<Constant<Bits<8>>>,
    port_bit: Vec<Constant<Bits<64>>>,
    bank_number: Vec<Constant<Bits<2>>>,
    /// Per port: its word of the pin scan (one bit) and its bank (one bit).
    port_word_bit: Vec<Constant<Bits<16>>>,
    port_bank_bit: Vec<Constant<Bits<4>>>,
    /// Per port: its bit of the refill ring at its visit, its slot's freeing and its load.
    visit_bit: Vec<Constant<Bits<RING_BITS>>>,
    freed_bit: Vec<Constant<Bits<RING_BITS>>>,
    load_bit: Vec<Constant<Bits<RING_BITS>>>,
    // per port
    count: Vec<DFF<Bits<2>>>,
    tail: Vec<DFF<Bit>>,
    /// The value the pin takes at the next start or data bit.
    next_pin: Vec<DFF<Bit>>,
    pin: Vec<DFF<Bit>>,
    full: Signal<Local, Bits<64>>,
    nonempty: Signal<Local, Bit>,
    copy_tail: Signal<Local, Bit>,
}

impl CellDownlink {
    /// A downlink of `ports` pins (1 to 64) at `baud` with a `clock_hz` box clock; its
    /// own time syncs are framed by `framing`.
    pub fn new(ports: usize, clock_hz: u64, baud: u64, framing: CellCommandFraming) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "CellDownlink: {ports} ports (1 to {MAX_PORTS})"
        );
        assert!(
            baud > 0 && clock_hz >= 4 * baud,
            "CellDownlink: clock {clock_hz} Hz must be at least 4 x baud {baud}"
        );
        let banks = ports.div_ceil(DOWNLINK_BANK_PORTS);
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
            tick: Default::default(),
            sync_period: Default::default(),
            sync_restart: Default::default(),
            syncs_on: Default::default(),
            copy: DownlinkPacketCopy::new(ports),
            timer: DownlinkFrameTimer::new(ports, clock_hz, baud),
            pin_scan: DownlinkPinScan::new(ports),
            refill: DownlinkRefill::new(ports, framing),
            generator: Default::default(),
            queues: Default::default(),
            bytes: each(banks),
            port_number: (0..ports)
                .map(|p| Constant::new((p as u64).into()))
                .collect(),
            port_bit: (0..ports)
                .map(|p| Constant::new((1u64 << p).into()))
                .collect(),
            bank_number: (0..banks)
                .map(|b| Constant::new((b as u64).into()))
                .collect(),
            port_word_bit: (0..ports)
                .map(|p| Constant::new((1u64 << (p % DOWNLINK_BANK_PORTS)).into()))
                .collect(),
            port_bank_bit: (0..ports)
                .map(|p| Constant::new((1u64 << (p / DOWNLINK_BANK_PORTS)).into()))
                .collect(),
            visit_bit: ring_bits(ports, 0),
            freed_bit: ring_bits(ports, 3),
            load_bit: ring_bits(ports, 4),
            count: each(ports),
            tail: each(ports),
            next_pin: each(ports),
            pin: each(ports),
            full: Default::default(),
            nonempty: Default::default(),
            copy_tail: Default::default(),
        }
    }
}

impl Logic for CellDownlink {
    #[hdl_gen]
    fn update(&mut self) {
        self.copy.clock.next = self.clock.val();
        self.timer.clock.next = self.clock.val();
        self.pin_scan.clock.next = self.clock.val();
        self.refill.clock.next = self.clock.val();
        self.queues.clock.next = self.clock.val();
        self.copy.reset.next = self.reset.val();
        self.timer.reset.next = self.reset.val();
        self.pin_scan.reset.next = self.reset.val();
        self.refill.reset.next = self.reset.val();
        self.generator.clock.next = self.clock.val();
        self.generator.reset.next = self.reset.val();
        self.generator.period.next = self.sync_period.val();
        self.generator.restart.next = self.sync_restart.val();
        self.syncs_on.next = self.generator.on.val();
        self.refill.epoch.next = self.generator.epoch.val();
        self.refill.tick.next = self.tick.val();
        self.refill.take_start.next = self.timer.take_start.val();

        // the packet's capture and its copy into the queue RAM
        self.copy.capture.next = self.capture.val();
        self.copy.capture_address.next = self.capture_address.val();
        self.copy.capture_data.next = self.capture_data.val();
        self.copy.offer.next = self.offer.val();
        self.copy.offer_port.next = self.offer_port.val();
        self.busy.next = self.copy.busy.val();
        self.accepted.next = self.copy.accepted.val();
        self.accepted_port.next = self.copy.accepted_port.val();
        self.copy_tail.next = false;
        for i in 0..self.count.len() {
            if self.copy.copy_port.val() == self.port_number[i].val() {
                self.copy_tail.next = self.tail[i].q.val();
            }
        }
        self.copy.copy_tail.next = self.copy_tail.val();
        self.queues.write_enable.next = self.copy.queue_write.val();
        self.queues.write_address.next = self.copy.queue_write_address.val();
        self.queues.write_data.next = self.copy.queue_write_data.val();

        // the refill reads the queues into the frame bytes; the pin scan reads those
        self.pin_scan.bit_end.next = self.timer.bit_end.val();
        self.pin_scan.next_is_data.next = self.timer.next_is_data.val();
        self.pin_scan.next_data_bit.next = self.timer.next_data_bit.val();
        self.refill.bit_end.next = self.timer.bit_end.val();
        self.refill.next_is_last_data.next = self.timer.next_is_last_data.val();
        self.queues.read_address.next = self.refill.queue_read_address.val();
        self.refill.queue_read_data.next = self.queues.read_data.val();
        for b in 0..self.bytes.len() {
            self.bytes[b].clock.next = self.clock.val();
            self.bytes[b].read_address.next = self.pin_scan.read_word.val();
            self.pin_scan.bank_data[b].next = self.bytes[b].read_data.val();
            self.bytes[b].write_enable.next = (self.refill.byte_write.val()
                & (self.refill.byte_port.val().get_bits::<2>(4) == self.bank_number[b].val()))
                | self.refill.clearing.val();
            self.bytes[b].write_address.next = self.refill.byte_port.val().get_bits::<4>(0);
            self.bytes[b].write_data.next = self.refill.byte_data.val();
        }
        // the visited port's queue count, and the full queues
        self.nonempty.next = false;
        self.full.next = 0.into();
        for i in 0..self.count.len() {
            if ((self.refill.scan_ring.val() & self.visit_bit[i].val()) != 0)
                & (self.count[i].q.val() != 0)
            {
                self.nonempty.next = true;
            }
            if self.count[i].q.val().get_bit(1) {
                self.full.next = self.full.val() | self.port_bit[i].val();
            }
        }
        self.refill.nonempty.next = self.nonempty.val();
        self.full_ports.next = self.full.val();

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
            if self.copy.commit.val() & (self.copy.copy_port.val() == self.port_number[i].val()) {
                self.tail[i].d.next = !self.tail[i].q.val();
                self.count[i].d.next = self.count[i].q.val() + 1;
                if self.refill.freed.val()
                    & ((self.refill.scan_ring.val() & self.freed_bit[i].val()) != 0)
                {
                    self.count[i].d.next = self.count[i].q.val();
                }
            } else if self.refill.freed.val()
                & ((self.refill.scan_ring.val() & self.freed_bit[i].val()) != 0)
            {
                self.count[i].d.next = self.count[i].q.val() - 1;
            }
            // the next start bit, at the refill's load (high: no packet, no start bit); the
            // next data bit, from the pin scan
            if self.refill.load.val()
                & ((self.refill.scan_ring.val() & self.load_bit[i].val()) != 0)
            {
                self.next_pin[i].d.next = !self.refill.load_nonempty.val();
            }
            if self.pin_scan.take.val()
                & ((self.pin_scan.take_word.val() & self.port_word_bit[i].val()) != 0)
            {
                self.next_pin[i].d.next =
                    (self.pin_scan.values.val() & self.port_bank_bit[i].val()) != 0;
            }
            // the pin at each bit's start: start bit, data bit, stop bits
            if self.timer.take_start.val() | self.timer.take_data.val() {
                self.pin[i].d.next = self.next_pin[i].q.val();
            }
            if self.timer.take_stop.val() {
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
    use skinbox_protocol::cell_command::{
        CellCommand, CellCommandRepr, CommandCode, ALL_CELLS, COMMAND_HEADER,
    };
    use skinbox_protocol::command::ALL_PORTS;

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
        /// The box tick of the next clock (0: the first clock out of reset).
        tick: u64,
    }

    impl Run {
        fn new(ports: usize) -> Self {
            let mut bench = Bench::new(
                CellDownlink::new(ports, CLOCK_HZ, CELL_BAUD, CellCommandFraming::DEFAULT),
                |b| &mut b.clock,
            );
            bench.uut.reset.next = true;
            bench.cycles(2);
            bench.uut.reset.next = false;
            Run {
                bench,
                pins: vec![vec![]; ports],
                queued: vec![vec![]; ports],
                refused: 0,
                last_offered: [0; 20],
                tick: 0,
            }
        }

        /// `pins[p][i]` is the pin at this tick.
        fn pin_tick(i: u64) -> u64 {
            i + 1
        }

        fn cycle(&mut self) {
            self.bench.uut.tick.next = self.tick.into();
            self.bench.cycle();
            self.tick += 1;
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

        /// With syncs every `period` from tick `set_at` (the epoch's toggles: `set_at` and
        /// `set_at + n * period`) until `off_at`: each port's pin carries the accepted
        /// packets in order with one generated sync per toggle, each the first packet to
        /// start after its toggle (within a packet and a frame), all stamped with their
        /// measured start ticks.
        fn check_pins_with_syncs(&self, set_at: u64, period: u64, off_at: u64) {
            let toggles: Vec<u64> = (0..)
                .map(|n| set_at + n * period)
                .take_while(|&t| t < off_at)
                .collect();
            let packet_ticks = 20 * frame_bits(self.pins.len()) * 32;
            for (p, packets) in self.packets_on_pins().iter().enumerate() {
                let (mut host, mut syncs) = (vec![], vec![]);
                for &(start, packet) in packets {
                    if packet == generated_sync(start) {
                        syncs.push(start);
                    } else {
                        host.push(packet);
                        let sent = self.queued[p][host.len() - 1];
                        assert_eq!(packet, stamped(sent, start), "port {p}");
                    }
                }
                assert_eq!(host.len(), self.queued[p].len(), "port {p}");
                assert_eq!(syncs.len(), toggles.len(), "port {p}: {syncs:?}");
                for (start, toggle) in syncs.iter().zip(&toggles) {
                    assert!(
                        (*toggle..toggle + packet_ticks + 400).contains(start),
                        "port {p}: sync at {start}, toggle {toggle}"
                    );
                    // the first packet to start after the toggle
                    // (one loaded before the toggle may start up to a frame after it)
                    let before = packets
                        .iter()
                        .filter(|(s, _)| *s > toggle + 400 && s < start);
                    assert_eq!(before.count(), 0, "port {p}: sync at {start}");
                }
            }
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

        /// Sets the sync period (a restart: a sync at once unless 0).
        fn set_sync_period(&mut self, ticks: u64) {
            self.bench.uut.sync_period.next = ticks.into();
            self.bench.uut.sync_restart.next = true;
            self.cycle();
            self.bench.uut.sync_restart.next = false;
        }

        /// Each port's packets on its pin: (the tick of the first start bit's falling
        /// edge, the packet), measured by the line model.
        fn packets_on_pins(&self) -> Vec<Vec<(u64, [u8; 20])>> {
            self.pins
                .iter()
                .map(|pin| {
                    decode_uart_line(pin)
                        .chunks(20)
                        .map(|frames| {
                            let mut packet = [0; 20];
                            frames.iter().zip(&mut packet).for_each(|(f, b)| *b = f.1);
                            (Self::pin_tick(frames[0].0), packet)
                        })
                        .collect()
                })
                .collect()
        }

        /// Every port's pin, decoded by the line model, equals the packets it accepted
        /// (time syncs stamped with their start ticks on the pin), and each port's frames
        /// follow each other back to back.
        fn check_pins(&self) {
            let period = bit_period(0.0);
            for (p, pin) in self.pins.iter().enumerate() {
                let frames = decode_uart_line(pin);
                let bytes: Vec<u8> = frames.iter().map(|f| f.1).collect();
                let starts = frames.chunks(20).map(|f| Self::pin_tick(f[0].0));
                let expected: Vec<u8> = self.queued[p]
                    .iter()
                    .zip(starts)
                    .flat_map(|(packet, start)| stamped(*packet, start))
                    .collect();
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

    /// `packet` as it leaves at `start`: a time sync's bytes 4-11 are the tick.
    fn stamped(mut packet: [u8; 20], start: u64) -> [u8; 20] {
        if packet[3] == CommandCode::TimeSync as u8 {
            packet[4..12].copy_from_slice(&start.to_be_bytes());
        }
        packet
    }

    /// The box's own sync leaving at `start`.
    fn generated_sync(start: u64) -> [u8; 20] {
        CellCommandRepr {
            cell_id: ALL_CELLS,
            command: CellCommand::TimeSync { box_tick: start },
        }
        .to_bytes()
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

    /// With a sync period of 15,000 ticks (a packet takes 6,250) set at tick 100: every port sends the box's sync
    /// at once and then each period, at its next packet boundary before its queued
    /// packets (which take no fewer slots: four host packets to one port are all taken),
    /// every sync (a host's too) carries the tick of its first start bit measured on the
    /// pin, and period 0 stops them.
    #[test]
    fn the_box_sends_syncs_every_period_stamped_as_they_leave() {
        let mut rng = TestRng::new(8);
        let mut run = Run::new(4);
        run.idle(100);
        let period = 15_000;
        run.set_sync_period(period);
        let set_at = run.tick;
        let mut host_sync = packet(&mut rng);
        host_sync[3] = CommandCode::TimeSync as u8;
        assert!(run.send(1, &host_sync, &mut rng));
        assert!(run.send(ALL_PORTS, &packet(&mut rng), &mut rng));
        run.idle(period - 5000);
        for _ in 0..2 {
            while !run.send(2, &packet(&mut rng), &mut rng) {
                run.idle(500);
            }
        }
        run.idle(2 * period);
        run.set_sync_period(0);
        let off_at = run.tick;
        run.idle(2 * period);
        run.drain();
        run.check_pins_with_syncs(set_at, period, off_at);
        assert_eq!(run.queued[1][0], host_sync);
        assert_eq!(run.queued[2].len(), 3);
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
            let mut uut =
                CellDownlink::new(ports, CLOCK_HZ, CELL_BAUD, CellCommandFraming::DEFAULT);
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
