//! CellUplink: the way up from the cells: each port's UART pin to whole, stamped records,
//! every port event counted.
//!
//! Per port only a bit-level [`UartRx`]; one [`CellDeframer`] engine serves every port in
//! turn and writes their packets into the [`PacketStore`], which holds them in shared block
//! RAM and merges them, one whole record at a time, into `records`. The [`CounterFile`]
//! counts every port's events (read at `counter_address`). The ports stay in reset until
//! the counters are cleared (about 4 us after reset), so no event goes uncounted; their
//! reset is a register per group of [`GROUP_PORTS`] ports (one net across the chip to every
//! port's flip-flops would be the slowest path at 64 ports) and one for the engine's and the
//! store's per-port state.
//!
//! Timestamps: a record's tick is the tick of the first clock edge that sampled its
//! packet's first start bit low at the pin (the true falling edge lies in the tick before).

use crate::cell_deframer::{scan_period, CellDeframer};
use crate::counter_file::{counter_file, CounterFile};
use crate::geometry::{group_onehot, GROUP_PORTS, MAX_PORTS};
use crate::hdl::*;
use crate::packet_store::PacketStore;
use crate::replica_register::ReplicaRegister;
use crate::stream::ByteStreamSource;
use crate::uart_rx::{shift_hold_clocks, UartRx};
use skinbox_protocol::CellFraming;

/// The uplink of N ports.
#[derive(LogicBlock)]
pub struct CellUplink {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset (the ports' reset lasts until the counters are cleared).
    pub reset: Signal<In, Bit>,
    /// The box time.
    pub tick: Signal<In, Bits<64>>,
    /// The UART pins of the ports, idle high.
    pub uart_rx: Vec<Signal<In, Bit>>,
    /// The records, one whole record at a time: port, flags, tick, cell bytes.
    pub records: ByteStreamSource,
    /// The counter file finished clearing (the ports are out of reset a clock later).
    pub counters_ready: Signal<Out, Bit>,
    /// Counter to read: port * 8 + counter (`skinbox_protocol::PortCounter`).
    pub counter_address: Signal<In, Bits<9>>,
    /// The counter, two clocks after its address.
    pub counter_data: Signal<Out, Bits<32>>,
    uarts: Vec<UartRx>,
    deframer: CellDeframer,
    store: PacketStore,
    counters: CounterFile,
    /// The ports' reset before its copies.
    port_reset: Signal<Local, Bit>,
    /// The ports' reset, one register per group of [`GROUP_PORTS`] ports.
    group_resets: Vec<ReplicaRegister>,
    /// The ports' reset for the engine's and the store's per-port state.
    store_port_reset: ReplicaRegister,
    /// Port i's group, one-hot.
    port_group: Vec<Constant<Bits<8>>>,
}

impl CellUplink {
    /// The uplink of `ports` ports (1 to [`MAX_PORTS`]) for `framing`, receivers at `baud`
    /// with a `clock_hz` clock, the engine truncating a packet after `idle_gap_bits` idle bit
    /// times.
    pub fn new(
        ports: usize,
        clock_hz: u64,
        baud: u64,
        framing: CellFraming,
        idle_gap_bits: u64,
    ) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "CellUplink: {ports} ports, must be 1 to {MAX_PORTS}"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            tick: Default::default(),
            uart_rx: (0..ports).map(|_| Default::default()).collect(),
            records: Default::default(),
            counters_ready: Default::default(),
            counter_address: Default::default(),
            counter_data: Default::default(),
            uarts: (0..ports)
                .map(|_| {
                    // a byte waits in the receiver's shift register for the engine's
                    // visit, or in a hold register when visits are further apart
                    if scan_period(ports) as u64 > shift_hold_clocks(clock_hz, baud) {
                        UartRx::with_hold_register(clock_hz, baud)
                    } else {
                        UartRx::new(clock_hz, baud)
                    }
                })
                .collect(),
            deframer: CellDeframer::new(ports, clock_hz, baud, framing, idle_gap_bits),
            store: PacketStore::new(ports),
            counters: counter_file(),
            port_reset: Default::default(),
            group_resets: (0..ports.div_ceil(GROUP_PORTS))
                .map(|_| Default::default())
                .collect(),
            store_port_reset: Default::default(),
            port_group: (0..ports).map(group_onehot).collect(),
        }
    }
}

impl Logic for CellUplink {
    #[hdl_gen]
    fn update(&mut self) {
        self.port_reset.next = self.reset.val() | !self.counters.ready.val();
        for g in 0..self.group_resets.len() {
            self.group_resets[g].clock.next = self.clock.val();
            self.group_resets[g].d.next = self.port_reset.val();
        }
        self.store_port_reset.clock.next = self.clock.val();
        self.store_port_reset.d.next = self.port_reset.val();
        for i in 0..self.uarts.len() {
            // pin -> UART, held bytes -> the deframing engine
            self.uarts[i].clock.next = self.clock.val();
            self.uarts[i].reset.next = false;
            for g in 0..self.group_resets.len() {
                if self.port_group[i].val().get_bit(g) {
                    self.uarts[i].reset.next = self.group_resets[g].q.val();
                }
            }
            self.uarts[i].rx.next = self.uart_rx[i].val();
            self.uarts[i].tick_low.next = self.tick.val().get_bits::<7>(0);
            self.uarts[i].visit.next = self.deframer.visit[i].val();
            self.deframer.held[i].next = self.uarts[i].held.val();
            self.deframer.data[i].next = self.uarts[i].data.val();
            self.deframer.framing_error[i].next = self.uarts[i].framing_error.val();
            self.deframer.stamp[i].next = self.uarts[i].stamp.val();
        }
        self.deframer.clock.next = self.clock.val();
        self.deframer.reset.next = self.reset.val();
        self.deframer.port_reset.next = self.store_port_reset.q.val();
        self.deframer.tick.next = self.tick.val();
        self.deframer.full_ports.next = self.store.full_ports.val();
        self.store.write.next = self.deframer.write.val();
        self.store.write_port.next = self.deframer.write_port.val();
        self.store.write_slot.next = self.deframer.write_slot.val();
        self.store.write_word.next = self.deframer.write_word.val();
        self.store.write_data.next = self.deframer.write_data.val();
        self.store.commit_ports.next = self.deframer.commit_ports.val();
        self.counters.increment.next = self.deframer.increment.val();
        self.counters.increment_address.next = self.deframer.increment_address.val();
        self.store.clock.next = self.clock.val();
        self.store.reset.next = self.reset.val();
        self.store.port_reset.next = self.store_port_reset.q.val();
        self.counters.clock.next = self.clock.val();
        self.counters.reset.next = self.reset.val();
        self.counters.read_address[0].next = self.counter_address.val();
        self.counter_data.next = self.counters.read_data[0].val();
        self.counters_ready.next = self.counters.ready.val();
        // the store's output FIFO holds every beat in flight: `ready` reaches its
        // registers only
        self.records.data.next = self.store.records.data.val();
        self.records.valid.next = self.store.records.valid.val();
        self.records.last.next = self.store.records.last.val();
        self.records.error.next = self.store.records.error.val();
        self.store.records.ready.next = self.records.ready.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::counter_file::COUNTERS;
    use crate::testbench::{bit_period, Bench, UartLine};
    use skinbox_protocol::status::PortCounter;
    use skinbox_protocol::DataRepr;

    /// A packet on each of three pins (one at +1 % baud error, one at -2 %), and garbage
    /// before the third: each becomes a record stamped with the tick of its first start
    /// bit's first low sample (the tick the counter reads after that edge: here the tick
    /// input is the edge's number before it, so the edge's number + 1), and the counters
    /// count the packets and the garbage bytes.
    #[test]
    fn packets_on_the_pins_become_stamped_records_and_counted_events() {
        let ports = 3;
        let mut bench = Bench::new(
            CellUplink::new(
                ports,
                crate::CLOCK_HZ,
                crate::CELL_BAUD,
                CellFraming::DEFAULT,
                10,
            ),
            |b| &mut b.clock,
        );
        let packet = |id: u16| {
            DataRepr {
                cell_id: id,
                ..Default::default()
            }
            .to_bytes()
        };
        let mut lines = [
            UartLine::default(),
            UartLine::default(),
            UartLine::default(),
        ];
        let starts = [900.3, 1300.8, 2000.0];
        lines[0].bytes(&packet(10), starts[0], bit_period(1e4));
        lines[1].bytes(&packet(11), starts[1], bit_period(-2e4));
        let p = bit_period(0.0);
        let t = lines[2].bytes(&[0x00, 0x13], 600.0, p);
        assert!(t + 3.0 * p < starts[2]);
        lines[2].bytes(&packet(12), starts[2], p);
        let clocks = 9_000u64;
        let levels: Vec<Vec<bool>> = lines.iter().map(|l| l.levels(clocks)).collect();
        // records as (port, flags, tick, cell bytes)
        let mut records = vec![];
        let mut beats: Vec<u8> = vec![];
        for e in 1..clocks {
            let u = &mut bench.uut;
            // reset for edges 1 to 3; the tick counts edges
            u.reset.next = e <= 3;
            u.tick.next = e.into();
            for (port, l) in levels.iter().enumerate() {
                u.uart_rx[port].next = l[e as usize];
            }
            u.records.ready.next = e % 3 != 0;
            bench.settle();
            let u = &bench.uut;
            if u.records.valid.val() && u.records.ready.val() {
                beats.push(u.records.data.val().to_u8());
                assert!(!u.records.error.val());
                if u.records.last.val() {
                    let tick = u32::from_be_bytes(beats[2..6].try_into().unwrap());
                    records.push((beats[0], beats[1], tick, beats[6..].to_vec()));
                    beats.clear();
                }
            }
            bench.cycle();
        }
        let mut expected: Vec<(u8, u8, u32, Vec<u8>)> = (0..ports)
            .map(|p| {
                let id = 10 + p as u16;
                (p as u8, 0, starts[p].ceil() as u32 + 1, packet(id).to_vec())
            })
            .collect();
        // in order of completion: the packets end in the order they start
        expected.sort_by_key(|r| r.2);
        assert_eq!(records, expected);
        assert!(bench.uut.counters_ready.val());
        let mut read = |port: usize, c: PortCounter| {
            bench.uut.counter_address.next = ((port * COUNTERS) as u64 + c as u64).into();
            bench.cycles(3);
            bench.uut.counter_data.val().to_u32()
        };
        for port in 0..ports {
            assert_eq!(read(port, PortCounter::PacketsGood), 1, "port {port}");
        }
        assert_eq!(read(2, PortCounter::GarbageBytes), 2);
        assert_eq!(read(0, PortCounter::GarbageBytes), 0);
    }

    /// The uplink's Verilog at 1, 9 and 64 ports passes Verilator's lint with the box's
    /// waivers.
    #[test]
    fn verilog_lints_clean() {
        for ports in [1, 9, 64] {
            let mut uut = CellUplink::new(
                ports,
                crate::CLOCK_HZ,
                crate::CELL_BAUD,
                CellFraming::DEFAULT,
                10,
            );
            uut.connect_all();
            let text = generate_verilog(&uut);
            let dir = std::env::temp_dir().join(format!(
                "skinbox-lint-cell-uplink-{ports}-{}",
                std::process::id()
            ));
            std::fs::create_dir_all(&dir).unwrap();
            let report = crate::verilog::lint(&text, &dir).unwrap_or_else(|e| panic!("{e}"));
            std::fs::remove_dir_all(&dir).ok();
            assert!(report.clean, "{ports} ports: {}", report.output);
        }
    }
}
