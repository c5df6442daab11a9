//! CellDownlink: queues whole 20-byte cell command packets per port and sends them on each
//! port's UART pin, the way back to the cells (the packet: docs/wire-format.md).
//!
//! - A command is a target `port` (or `ALL_PORTS`) and its packet on `packet`. The packet is
//!   staged whole in a 160-bit register first; one that is not exactly
//!   [`PACKET_LEN`] bytes, carries `error` on its last beat or names a port the box does not
//!   have is dropped whole with a `malformed` pulse.
//! - A staged packet is then copied, a byte a clock, into the target port's queue (two
//!   packet slots per port in one [`BlockRam`]: port, slot and byte index form the address);
//!   for `ALL_PORTS` into every port in turn. A port whose two slots are full refuses it:
//!   `refused` pulses with `refused_port`; a copy that goes in pulses `accepted` with
//!   `accepted_port`. A packet is queued whole or not at all. `packet.ready` is low while a
//!   packet is copied (21 clocks per port).
//! - A scan visits one port per clock and reads the next byte of its oldest packet into the
//!   port's one-byte holding register, which feeds the port's [`UartTx`]; the scan comes back
//!   every `ports` clocks, well within a byte time (312.5 clocks), so a port's packets go out
//!   back to back, in order.
//!
//! Cost (yosys `synth_ecp5` of the block alone, `read_verilog -DSKINBOX_ECP5_BRAM`): 8 ports
//! 847 LUT4, 112 CCU2C, 626 FF, 2 DP16KD; 64 ports 4,328 LUT4, 782 CCU2C, 3,426 FF, 2 DP16KD.
//! The queues in registers instead would take 320 FF per port (two 20-byte packets).

use crate::block_ram::{BlockRam, READ_LATENCY};
use crate::hdl::*;
use crate::stream::ByteStreamSink;
use crate::uart_tx::UartTx;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::ALL_PORTS;

/// Packets each port can hold.
pub const QUEUE_PACKETS: u64 = 2;

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
    /// Target of the packet on `packet`: a port, or `ALL_PORTS` (0xFF); read with the last
    /// beat.
    pub port: Signal<In, Bits<8>>,
    /// The 20-byte cell command packet.
    pub packet: ByteStreamSink,
    /// One UART pin per port, idle high.
    pub uart_tx: Vec<Signal<Out, Bit>>,
    /// High for one clock when a port queued a packet, with `accepted_port`.
    pub accepted: Signal<Out, Bit>,
    /// The port that queued it.
    pub accepted_port: Signal<Out, Bits<8>>,
    /// High for one clock when a full port refused a packet, with `refused_port`.
    pub refused: Signal<Out, Bit>,
    /// The port that refused it.
    pub refused_port: Signal<Out, Bits<8>>,
    /// High for one clock when a packet was dropped as malformed (length, error flag or
    /// no such port).
    pub malformed: Signal<Out, Bit>,
    ram: BlockRam<8, ADDRESS_BITS>,
    uarts: Vec<UartTx>,
    port_number: Vec<Constant<Bits<8>>>,
    port_count: Constant<Bits<8>>,
    last_port: Constant<Bits<8>>,
    all_ports: Constant<Bits<8>>,
    // receive and copy
    staging: DFF<Bits<160>>,
    received: DFF<Bits<5>>,
    overlong: DFF<Bit>,
    copying: DFF<Bit>,
    broadcast: DFF<Bit>,
    copy_port: DFF<Bits<8>>,
    copy_index: DFF<Bits<5>>,
    accepted_out: DFF<Bit>,
    accepted_port_out: DFF<Bits<8>>,
    refused_out: DFF<Bit>,
    refused_port_out: DFF<Bits<8>>,
    malformed_out: DFF<Bit>,
    // per port
    count: Vec<DFF<Bits<2>>>,
    head: Vec<DFF<Bit>>,
    read_index: Vec<DFF<Bits<5>>>,
    fetching: Vec<DFF<Bit>>,
    holding_valid: Vec<DFF<Bit>>,
    holding: Vec<DFF<Bits<8>>>,
    // read scan and the RAM's read pipeline
    scan: DFF<Bits<8>>,
    /// Reads in flight: bit 1 marks the data of the read issued two clocks ago.
    read_valid: DFF<Bits<2>>,
    read_port_1: DFF<Bits<8>>,
    read_port_2: DFF<Bits<8>>,
    take: Signal<Local, Bit>,
    good_packet: Signal<Local, Bit>,
    copy_count: Signal<Local, Bits<2>>,
    copy_head: Signal<Local, Bit>,
    copy_full: Signal<Local, Bit>,
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
            port: Default::default(),
            packet: Default::default(),
            uart_tx: (0..ports).map(|_| Default::default()).collect(),
            accepted: Default::default(),
            accepted_port: Default::default(),
            refused: Default::default(),
            refused_port: Default::default(),
            malformed: Default::default(),
            ram: Default::default(),
            uarts: (0..ports).map(|_| UartTx::new(clock_hz, baud)).collect(),
            port_number: (0..ports)
                .map(|p| Constant::new((p as u64).into()))
                .collect(),
            port_count: Constant::new((ports as u64).into()),
            last_port: Constant::new((ports as u64 - 1).into()),
            all_ports: Constant::new(u64::from(ALL_PORTS).into()),
            staging: Default::default(),
            received: Default::default(),
            overlong: Default::default(),
            copying: Default::default(),
            broadcast: Default::default(),
            copy_port: Default::default(),
            copy_index: Default::default(),
            accepted_out: Default::default(),
            accepted_port_out: Default::default(),
            refused_out: Default::default(),
            refused_port_out: Default::default(),
            malformed_out: Default::default(),
            count: (0..ports).map(|_| Default::default()).collect(),
            head: (0..ports).map(|_| Default::default()).collect(),
            read_index: (0..ports).map(|_| Default::default()).collect(),
            fetching: (0..ports).map(|_| Default::default()).collect(),
            holding_valid: (0..ports).map(|_| Default::default()).collect(),
            holding: (0..ports).map(|_| Default::default()).collect(),
            scan: Default::default(),
            read_valid: Default::default(),
            read_port_1: Default::default(),
            read_port_2: Default::default(),
            take: Default::default(),
            good_packet: Default::default(),
            copy_count: Default::default(),
            copy_head: Default::default(),
            copy_full: Default::default(),
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
            staging,
            received,
            overlong,
            copying,
            broadcast,
            copy_port,
            copy_index,
            accepted_out,
            accepted_port_out,
            refused_out,
            refused_port_out,
            malformed_out,
            scan,
            read_valid,
            read_port_1,
            read_port_2
        );
        self.ram.clock.next = self.clock.val();
        self.ram.write_enable.next = false;
        self.ram.write_address.next = 0.into();
        self.ram.write_data.next = self.staging.q.val().get_bits::<8>(0);
        self.ram.read_address.next = 0.into();
        self.accepted_out.d.next = false;
        self.refused_out.d.next = false;
        self.malformed_out.d.next = false;

        // receive: stage the packet whole
        self.packet.ready.next = !self.copying.q.val();
        self.take.next = self.packet.valid.val() & !self.copying.q.val();
        self.good_packet.next = (self.received.q.val() == 19)
            & !self.overlong.q.val()
            & !self.packet.error.val()
            & ((self.port.val() < self.port_count.val())
                | (self.port.val() == self.all_ports.val()));
        if self.take.val() {
            self.staging.d.next =
                (self.staging.q.val() >> 8) | (bit_cast::<160, 8>(self.packet.data.val()) << 152);
            if self.received.q.val() == 20 {
                self.overlong.d.next = true;
            } else {
                self.received.d.next = self.received.q.val() + 1;
            }
            if self.packet.last.val() {
                self.received.d.next = 0.into();
                self.overlong.d.next = false;
                if self.good_packet.val() {
                    self.copying.d.next = true;
                    self.copy_index.d.next = 0.into();
                    self.broadcast.d.next = self.port.val() == self.all_ports.val();
                    self.copy_port.d.next = self.port.val();
                    if self.port.val() == self.all_ports.val() {
                        self.copy_port.d.next = 0.into();
                    }
                } else {
                    self.malformed_out.d.next = true;
                }
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
        self.copy_full.next = self.copy_count.val() == 2;
        self.commit.next = false;
        self.advance.next = false;
        if self.copying.q.val() {
            if (self.copy_index.q.val() == 0) & self.copy_full.val() {
                self.refused_out.d.next = true;
                self.refused_port_out.d.next = self.copy_port.q.val();
                self.advance.next = true;
            } else {
                self.ram.write_enable.next = true;
                self.ram.write_address.next = (bit_cast::<ADDRESS_BITS, 8>(self.copy_port.q.val())
                    << 6)
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
            if self.read_valid.q.val().get_bit(1)
                & (self.read_port_2.q.val() == self.port_number[i].val())
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
        self.ram.read_address.next = (bit_cast::<ADDRESS_BITS, 8>(self.scan.q.val()) << 6)
            | (bit_cast::<ADDRESS_BITS, 1>(self.scan_head.val().into()) << 5)
            | bit_cast::<ADDRESS_BITS, 5>(self.scan_index.val());
        self.read_valid.d.next =
            (self.read_valid.q.val() << 1) | bit_cast::<2, 1>(self.issue.val().into());
        if self.reset.val() {
            self.copying.d.next = false;
            self.received.d.next = 0.into();
            self.overlong.d.next = false;
            self.read_valid.d.next = 0.into();
            self.accepted_out.d.next = false;
            self.refused_out.d.next = false;
            self.malformed_out.d.next = false;
        }
        self.accepted.next = self.accepted_out.q.val();
        self.accepted_port.next = self.accepted_port_out.q.val();
        self.refused.next = self.refused_out.q.val();
        self.refused_port.next = self.refused_port_out.q.val();
        self.malformed.next = self.malformed_out.q.val();
    }
}

// the staging register and byte indices are sized for 20-byte packets, the read pipeline
// (`read_valid` bit 1) for the RAM's read latency
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
        /// The packets each port accepted, in order.
        queued: Vec<Vec<[u8; 20]>>,
        refused: Vec<u64>,
        malformed: u64,
        /// The last packet sent in full.
        last_sent: [u8; 20],
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
                refused: vec![0; ports],
                malformed: 0,
                last_sent: [0; 20],
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
                self.queued[p].push(self.last_sent);
            }
            if uut.refused.val() {
                self.refused[uut.refused_port.val().index()] += 1;
            }
            if uut.malformed.val() {
                self.malformed += 1;
            }
        }

        /// Offers `bytes` for `port` as fast as taken, the last with `error`, and waits
        /// until the packet is queued or refused.
        fn send(&mut self, port: u8, bytes: &[u8], error: bool) {
            self.bench.uut.port.next = u64::from(port).into();
            for (i, b) in bytes.iter().enumerate() {
                let last = i + 1 == bytes.len();
                self.bench.uut.packet.valid.next = true;
                self.bench.uut.packet.data.next = u64::from(*b).into();
                self.bench.uut.packet.last.next = last;
                self.bench.uut.packet.error.next = last && error;
                loop {
                    self.bench.settle();
                    let took = self.bench.uut.packet.ready.val();
                    self.cycle();
                    if took {
                        break;
                    }
                }
            }
            self.bench.uut.packet.valid.next = false;
            if bytes.len() == 20 && !error {
                self.last_sent.copy_from_slice(bytes);
            }
            // until the copy is over: its accepted and refused pulses are seen by then
            self.cycle();
            loop {
                self.bench.settle();
                if self.bench.uut.packet.ready.val() {
                    break;
                }
                self.cycle();
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
        run.send(3, &a, false);
        run.send(3, &b, false);
        run.drain();
        assert_eq!(run.queued[3], vec![a, b]);
        assert_eq!(run.refused, vec![0; 8]);
        run.check_pins();
        // the two packets form one burst of 40 frames
        let frames = decode_uart_line(&run.pins[3]);
        let span = (frames[39].0 - frames[0].0) as f64;
        // (up to a clock late, plus the rounding of the increment: 0.007 % slow)
        assert!((span - 390.0 * bit_period(0.0)).abs() < 2.5, "{span}");
    }

    #[test]
    fn a_full_queue_refuses_whole_packets_and_takes_again_once_drained() {
        let mut rng = TestRng::new(2);
        let mut run = Run::new(2);
        let sent: Vec<[u8; 20]> = (0..5).map(|_| packet(&mut rng)).collect();
        for p in &sent[..4] {
            run.send(1, p, false);
        }
        assert_eq!(run.refused, vec![0, 2]);
        run.drain();
        run.send(1, &sent[4], false);
        run.drain();
        assert_eq!(run.queued[1], vec![sent[0], sent[1], sent[4]]);
        assert_eq!(run.refused, vec![0, 2]);
        assert!(run.queued[0].is_empty());
        run.check_pins();
    }

    #[test]
    fn all_ports_goes_to_every_port_with_room_and_malformed_packets_are_dropped() {
        let mut rng = TestRng::new(3);
        let mut run = Run::new(4);
        let (a, b, c) = (packet(&mut rng), packet(&mut rng), packet(&mut rng));
        run.send(2, &a, false);
        run.send(2, &b, false);
        run.send(ALL_PORTS, &c, false);
        assert_eq!(run.refused, vec![0, 0, 1, 0]);
        // a short, a long, a flagged packet and one for a port the box does not have
        run.send(0, &c[..19], false);
        let long: Vec<u8> = c.iter().copied().chain([0x00]).collect();
        run.send(0, &long, false);
        run.send(0, &c, true);
        run.send(4, &c, false);
        assert_eq!(run.malformed, 4);
        run.drain();
        assert_eq!(run.queued, vec![vec![c], vec![c], vec![a, b], vec![c]]);
        run.check_pins();
    }

    #[test]
    fn a_one_port_box_takes_all_ports_packets() {
        let mut rng = TestRng::new(5);
        let mut run = Run::new(1);
        let sent: Vec<[u8; 20]> = (0..3).map(|_| packet(&mut rng)).collect();
        for p in &sent {
            run.send(ALL_PORTS, p, false);
        }
        assert_eq!(run.refused, vec![1]);
        run.drain();
        assert_eq!(run.queued, vec![vec![sent[0], sent[1]]]);
        run.check_pins();
    }

    #[test]
    fn random_traffic_on_eight_ports_and_verilog_of_1_8_64_ports_passes_lint() {
        let mut rng = TestRng::new(4);
        let mut run = Run::new(8);
        let mut sent = 0;
        for _ in 0..24 {
            let port = if rng.chance(0.2) {
                ALL_PORTS
            } else {
                (rng.next_u64() % 8) as u8
            };
            let p = packet(&mut rng);
            run.send(port, &p, false);
            sent += if port == ALL_PORTS { 8 } else { 1 };
            run.idle(rng.next_u64() % 2000);
        }
        run.drain();
        let queued: usize = run.queued.iter().map(Vec::len).sum();
        let refused: u64 = run.refused.iter().sum();
        assert_eq!(
            queued as u64 + refused,
            sent,
            "every packet queued or refused"
        );
        assert!(refused > 0 && queued > 0);
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
