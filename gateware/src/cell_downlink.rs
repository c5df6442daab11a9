//! CellDownlink: queues whole 20-byte cell command packets per port and sends them on each
//! port's UART pin, the way back to the cells (the packet: docs/wire-format.md).
//!
//! - The packet is captured as the frame parser writes a received frame into the reply
//!   buffer: the bytes written at frame offsets [`PACKET_OFFSET`].. (where a cell command
//!   carries its packet) go into a 160-bit register, whatever the frame is.
//! - `busy` (the previous packet is still being copied into the queues) and `full_ports`
//!   (bit `p`: port `p` holds [`QUEUE_PACKETS`] packets) come straight from registers. The
//!   command unit `offer`s the captured packet for a port (or `ALL_PORTS`) in the clock it
//!   decides a cell command, only when neither says no: a packet is queued whole in every
//!   target port or not at all, and nothing waits outside the queues.
//! - An accepted packet moves to the staging register (a clock after the offer) and is
//!   copied, a byte a clock, into
//!   each target port's queue (two packet slots per port in one [`BlockRam`]: port, slot
//!   and byte index form the address), port after port for `ALL_PORTS`:
//!   [`COPY_CLOCKS_PER_PORT`] clocks each. `accepted` pulses with `accepted_port` as each
//!   copy is committed.
//! - A scan visits one port per clock (port `n` in the clocks `n`, `n + ports`, ... after
//!   reset) and reads the next byte of its oldest packet into the port's one-byte holding
//!   register, which feeds the port's [`UartTx`]; the scan comes back every `ports`
//!   clocks, well within a byte time (312.5 clocks), so a port's packets go out back to
//!   back, in order. A slot is free in the clock after its last byte was read.
//!
//! Cost (yosys `synth_ecp5` of the block alone, `read_verilog -DSKINBOX_ECP5_BRAM`): 8 ports
//! 847 LUT4, 112 CCU2C, 626 FF, 2 DP16KD; 64 ports 4,328 LUT4, 782 CCU2C, 3,426 FF, 2 DP16KD
//! (measured with a byte-stream input in place of the capture register).
//! The queues in registers instead would take 320 FF per port (two 20-byte packets).

use crate::block_ram::{BlockRam, READ_LATENCY};
use crate::hdl::*;
use crate::uart_tx::UartTx;
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

/// Largest port count.
pub const MAX_PORTS: usize = 64;

/// Queue RAM address: 6 bits of port, 1 of slot, 5 of byte index.
const ADDRESS_BITS: usize = 12;

/// The downlink of `ports` UART pins.
#[derive(LogicBlock)]
pub struct CellDownlink {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: queues emptied, pins idle.
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
    uarts: Vec<UartTx>,
    port_number: Vec<Constant<Bits<8>>>,
    port_bit: Vec<Constant<Bits<64>>>,
    last_port: Constant<Bits<8>>,
    packet_first: Constant<Bits<11>>,
    packet_last: Constant<Bits<11>>,
    all_ports: Constant<Bits<8>>,
    // receive and copy
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
    // per port
    count: Vec<DFF<Bits<2>>>,
    head: Vec<DFF<Bit>>,
    read_index: Vec<DFF<Bits<5>>>,
    fetching: Vec<DFF<Bit>>,
    holding_valid: Vec<DFF<Bit>>,
    holding: Vec<DFF<Bits<8>>>,
    // read scan and the RAM's read pipeline
    scan: DFF<Bits<8>>,
    /// Reads in flight: bit 2 marks the data of the read issued three clocks ago (the
    /// address is registered before the RAM).
    read_valid: DFF<Bits<3>>,
    read_address: DFF<Bits<ADDRESS_BITS>>,
    write_enable: DFF<Bit>,
    write_address: DFF<Bits<ADDRESS_BITS>>,
    write_data: DFF<Bits<8>>,
    read_port_1: DFF<Bits<8>>,
    read_port_2: DFF<Bits<8>>,
    read_port_3: DFF<Bits<8>>,
    full: Signal<Local, Bits<64>>,
    copy_count: Signal<Local, Bits<2>>,
    copy_head: Signal<Local, Bit>,
    commit: Signal<Local, Bit>,
    advance: Signal<Local, Bit>,
    issue: Signal<Local, Bit>,
    scan_head: Signal<Local, Bit>,
    scan_index: Signal<Local, Bits<5>>,
}

impl CellDownlink {
    /// A downlink of `ports` pins (1 to 64) at `baud` with a `clock_hz` box clock.
    pub fn new(ports: usize, clock_hz: u64, baud: u64) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "CellDownlink: {ports} ports (1 to {MAX_PORTS})"
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
            uart_tx: (0..ports).map(|_| Default::default()).collect(),
            accepted: Default::default(),
            accepted_port: Default::default(),
            ram: Default::default(),
            uarts: (0..ports).map(|_| UartTx::new(clock_hz, baud)).collect(),
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
            count: (0..ports).map(|_| Default::default()).collect(),
            head: (0..ports).map(|_| Default::default()).collect(),
            read_index: (0..ports).map(|_| Default::default()).collect(),
            fetching: (0..ports).map(|_| Default::default()).collect(),
            holding_valid: (0..ports).map(|_| Default::default()).collect(),
            holding: (0..ports).map(|_| Default::default()).collect(),
            scan: Default::default(),
            read_valid: Default::default(),
            read_address: Default::default(),
            write_enable: Default::default(),
            write_address: Default::default(),
            write_data: Default::default(),
            read_port_1: Default::default(),
            read_port_2: Default::default(),
            read_port_3: Default::default(),
            full: Default::default(),
            copy_count: Default::default(),
            copy_head: Default::default(),
            commit: Default::default(),
            advance: Default::default(),
            issue: Default::default(),
            scan_head: Default::default(),
            scan_index: Default::default(),
        }
    }
}

impl Logic for CellDownlink {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
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
            scan,
            read_valid,
            read_address,
            write_enable,
            write_address,
            write_data,
            read_port_1,
            read_port_2,
            read_port_3
        );
        self.ram.clock.next = self.clock.val();
        // the writes are registered: no copy logic in front of the RAM (a slot's last byte
        // lands a clock after its commit, long before a read can reach it)
        self.write_enable.d.next = false;
        self.write_address.d.next = self.write_address.q.val();
        self.write_data.d.next = self.staging.q.val().get_bits::<8>(0);
        self.ram.write_enable.next = self.write_enable.q.val();
        self.ram.write_address.next = self.write_address.q.val();
        self.ram.write_data.next = self.write_data.q.val();
        self.accepted_out.d.next = false;

        // capture: the bytes at the packet's frame offsets, the first ending in bits 7..0
        if self.capture.val()
            & (self.capture_address.val() >= self.packet_first.val())
            & (self.capture_address.val() <= self.packet_last.val())
        {
            self.captured.d.next =
                (self.captured.q.val() >> 8) | (bit_cast::<160, 8>(self.capture_data.val()) << 152);
        }

        // room: from registers only (the command unit decides from them)
        self.full.next = 0.into();
        for i in 0..self.uarts.len() {
            if self.count[i].q.val() == 2 {
                self.full.next = self.full.val() | self.port_bit[i].val();
            }
        }
        self.full_ports.next = self.full.val();
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

        // copy the staged packet into the target port's free slot
        self.copy_count.next = 0.into();
        self.copy_head.next = false;
        for i in 0..self.uarts.len() {
            if self.copy_port.q.val() == self.port_number[i].val() {
                self.copy_count.next = self.count[i].q.val();
                self.copy_head.next = self.head[i].q.val();
            }
        }
        self.commit.next = false;
        self.advance.next = false;
        if self.copying.q.val() {
            self.write_enable.d.next = true;
            self.write_address.d.next = (bit_cast::<ADDRESS_BITS, 8>(self.copy_port.q.val()) << 6)
                | (bit_cast::<ADDRESS_BITS, 1>(
                    (self.copy_head.val() ^ (self.copy_count.val() == 1)).into(),
                ) << 5)
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

        // read scan: one port per clock fetches the next byte of its oldest packet
        self.scan.d.next = self.scan.q.val() + 1;
        if self.scan.q.val() == self.last_port.val() {
            self.scan.d.next = 0.into();
        }
        self.issue.next = false;
        self.scan_head.next = false;
        self.scan_index.next = 0.into();
        self.read_valid.d.next = self.read_valid.q.val() << 1;
        self.read_port_1.d.next = self.scan.q.val();
        self.read_port_2.d.next = self.read_port_1.q.val();
        self.read_port_3.d.next = self.read_port_2.q.val();
        for i in 0..self.uarts.len() {
            self.count[i].clock.next = self.clock.val();
            self.head[i].clock.next = self.clock.val();
            self.read_index[i].clock.next = self.clock.val();
            self.fetching[i].clock.next = self.clock.val();
            self.holding_valid[i].clock.next = self.clock.val();
            self.holding[i].clock.next = self.clock.val();
            self.count[i].d.next = self.count[i].q.val();
            self.head[i].d.next = self.head[i].q.val();
            self.read_index[i].d.next = self.read_index[i].q.val();
            self.fetching[i].d.next = self.fetching[i].q.val();
            self.holding_valid[i].d.next = self.holding_valid[i].q.val();
            self.holding[i].d.next = self.holding[i].q.val();
            self.uarts[i].clock.next = self.clock.val();
            self.uarts[i].reset.next = self.reset.val();
            self.uarts[i].bytes.data.next = self.holding[i].q.val();
            self.uarts[i].bytes.valid.next = self.holding_valid[i].q.val();
            self.uarts[i].bytes.last.next = false;
            self.uarts[i].bytes.error.next = false;
            self.uart_tx[i].next = self.uarts[i].tx.val();
            if self.holding_valid[i].q.val() & self.uarts[i].bytes.ready.val() {
                self.holding_valid[i].d.next = false;
            }
            if (self.scan.q.val() == self.port_number[i].val())
                & (self.count[i].q.val() != 0)
                & !self.fetching[i].q.val()
                & !self.holding_valid[i].q.val()
            {
                self.issue.next = true;
                self.scan_head.next = self.head[i].q.val();
                self.scan_index.next = self.read_index[i].q.val();
                self.fetching[i].d.next = true;
                self.read_index[i].d.next = self.read_index[i].q.val() + 1;
                if self.read_index[i].q.val() == 19 {
                    // the last byte is read: the slot is free
                    self.read_index[i].d.next = 0.into();
                    self.head[i].d.next = !self.head[i].q.val();
                    self.count[i].d.next = self.count[i].q.val() - 1;
                    if self.commit.val() & (self.copy_port.q.val() == self.port_number[i].val()) {
                        self.count[i].d.next = self.count[i].q.val();
                    }
                }
            }
            if self.commit.val()
                & (self.copy_port.q.val() == self.port_number[i].val())
                & !(self.issue.val()
                    & (self.scan.q.val() == self.port_number[i].val())
                    & (self.read_index[i].q.val() == 19))
            {
                self.count[i].d.next = self.count[i].q.val() + 1;
            }
            if self.read_valid.q.val().get_bit(2)
                & (self.read_port_3.q.val() == self.port_number[i].val())
            {
                self.holding[i].d.next = self.ram.read_data.val();
                self.holding_valid[i].d.next = true;
                self.fetching[i].d.next = false;
            }
            if self.reset.val() {
                self.count[i].d.next = 0.into();
                self.head[i].d.next = false;
                self.read_index[i].d.next = 0.into();
                self.fetching[i].d.next = false;
                self.holding_valid[i].d.next = false;
            }
        }
        // the address is registered: no scan logic in front of the RAM
        self.read_address.d.next = (bit_cast::<ADDRESS_BITS, 8>(self.scan.q.val()) << 6)
            | (bit_cast::<ADDRESS_BITS, 1>(self.scan_head.val().into()) << 5)
            | bit_cast::<ADDRESS_BITS, 5>(self.scan_index.val());
        self.ram.read_address.next = self.read_address.q.val();
        self.read_valid.d.next =
            (self.read_valid.q.val() << 1) | bit_cast::<3, 1>(self.issue.val().into());
        if self.reset.val() {
            self.copying.d.next = false;
            self.offered.d.next = false;
            self.write_enable.d.next = false;
            self.scan.d.next = 0.into();
            self.read_valid.d.next = 0.into();
            self.accepted_out.d.next = false;
        }
        self.accepted.next = self.accepted_out.q.val();
        self.accepted_port.next = self.accepted_port_out.q.val();
    }
}

// the staging register and byte indices are sized for 20-byte packets, the read pipeline
// (`read_valid` bit 2) for the address register and the RAM's read latency
const _: () = assert!(PACKET_LEN == 20 && READ_LATENCY == 2);

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
                            (gap - 10.0 * period).abs() < 1.5,
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
        assert!((span - 390.0 * bit_period(0.0)).abs() < 2.5, "{span}");
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
