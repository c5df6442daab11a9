//! DownlinkRefill: after each frame's last data bit, gives every downlink port its next
//! byte.
//!
//! The scan visits one port a clock (`scan_ring`: a one-hot ring moving up a place a clock
//! from the scan's start, so a port's visit, slot freeing and load are bits `p`, `p + 3`
//! and `p + 4` of it: no decoder, no compare a port). It reads the port's read position
//! (the slot of its oldest packet and the byte index, a RAM of its own) a clock before the
//! visit (port 0's between scans) into a register, which holds it two clocks after the
//! visit (no path from the RAM's output into logic), then that byte from the queue RAM, and
//! [`REFILL_LATENCY`] clocks after the visit loads it into the port's word of the frame
//! bytes (`byte_write`), or 0xFF when the port's queue was empty at the visit (`nonempty`,
//! which the downlink ORs from the ports' counts at the ring's visit bits). The position
//! moves on by a byte; past a slot's last byte it moves to the other slot and `freed` (one
//! clock, at the ring's freeing bits) frees the slot. After reset the positions are cleared
//! (64 clocks) and every port's byte is 0xFF (`clearing`).
//!
//! Time syncs (cell command 5): a port's position word also says whether the packet on
//! its line is a time sync (set as byte 3 is loaded, from the queue byte) or the sync
//! generator's own packet, and the generator's epoch of the port's last generated sync.
//! Bytes 4 to 11 of every sync, and every byte of a generated one, come from
//! [`DownlinkSyncBytes`] (stamped with the packet's start tick) instead of the queue. At a
//! packet boundary (byte index 0) a port whose epoch differs from the generator's `epoch`
//! sends a generated sync before its queued packets; it takes no queue slot. The new
//! position is written five clocks after the visit (a clock after the queue byte), so no
//! per-port flip-flop holds any of this.
//!
//! What a visited port sends and its position after the byte are the
//! [`DownlinkNextPosition`] block's, from the position word as read.

use crate::block_ram::BlockRam;
use crate::downlink_next_position::DownlinkNextPosition;
use crate::downlink_packet_copy::QUEUE_ADDRESS_BITS;
use crate::downlink_sync_bytes::DownlinkSyncBytes;
use crate::hdl::*;
use skinbox_protocol::cell_command::{CellCommandFraming, CommandCode};

/// Clocks from a port's refill visit to its byte register: the read position RAM, then
/// the queue RAM, each two clocks, and the load.
pub const REFILL_LATENCY: u64 = 5;

/// Bits of the refill ring: a port's load is 4 places after its visit.
pub const RING_BITS: usize = 68;

/// Per port, its bit of the refill ring `delay` places after its visit.
pub fn ring_bits(ports: usize, delay: usize) -> Vec<Constant<Bits<RING_BITS>>> {
    (0..ports)
        .map(|p| {
            let mut bit = Bits::<RING_BITS>::default();
            bit = bit.replace_bit(p + delay, true);
            Constant::new(bit)
        })
        .collect()
}

/// The refill scan of N ports.
#[derive(LogicBlock)]
pub struct DownlinkRefill {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: no scan; positions and bytes cleared.
    pub reset: Signal<In, Bit>,
    /// The frame timer's bit end...
    pub bit_end: Signal<In, Bit>,
    /// ... before the last data bit: the scan starts as the pins take it.
    pub next_is_last_data: Signal<In, Bit>,
    /// The frame timer's `take_start`: the pins take a start bit at the next edge.
    pub take_start: Signal<In, Bit>,
    /// The box tick (the time syncs' stamps).
    pub tick: Signal<In, Bits<64>>,
    /// The sync generator's epoch.
    pub epoch: Signal<In, Bit>,
    /// The one-hot ring (bit `p`: port `p`'s visit; `p + 3` its freeing; `p + 4` its load).
    pub scan_ring: Signal<Out, Bits<RING_BITS>>,
    /// The visited port's queue holds a packet (from the downlink, in the visit's clock).
    pub nonempty: Signal<In, Bit>,
    /// Read address of the queue RAM (port, slot, byte).
    pub queue_read_address: Signal<Out, Bits<QUEUE_ADDRESS_BITS>>,
    /// The queue RAM's byte ([`crate::block_ram::READ_LATENCY`] clocks after its address).
    pub queue_read_data: Signal<In, Bits<8>>,
    /// One clock: the port whose freeing bit is set in the ring has a free slot.
    pub freed: Signal<Out, Bit>,
    /// Load the port whose load bit is set in the ring: its next start bit is low if
    /// `load_nonempty`.
    pub load: Signal<Out, Bit>,
    /// The loaded port sends a byte (queued or generated).
    pub load_nonempty: Signal<Out, Bit>,
    /// Write `byte_data` at the frame bytes' word of `byte_port`.
    pub byte_write: Signal<Out, Bit>,
    /// The port of that write.
    pub byte_port: Signal<Out, Bits<6>>,
    /// The byte written (0xFF for a port without a packet).
    pub byte_data: Signal<Out, Bits<8>>,
    /// After reset: every word of every bank of frame bytes is written 0xFF at word
    /// `byte_port` (no data bit before the first refill).
    pub clearing: Signal<Out, Bit>,
    /// Per port: the next byte's index (bits 0-4), the slot of its oldest packet (5), the
    /// packet on the line is a time sync (6) or a generated one (7), the epoch of its last
    /// generated sync (8).
    positions: BlockRam<9, 6>,
    // the position RAM's read address: the port visited in the next clock (0 between scans)
    position_read: DFF<Bits<6>>,
    // the visited port's position word, two clocks after the visit
    position_2: DFF<Bits<9>>,
    /// The visited port's byte source and next position, from its position word.
    position_step: DownlinkNextPosition,
    sync_bytes: DownlinkSyncBytes,
    last_port: Constant<Bits<8>>,
    ring_start: Constant<Bits<RING_BITS>>,
    sync_command: Constant<Bits<8>>,
    refilling: DFF<Bit>,
    scan: DFF<Bits<6>>,
    ring: DFF<Bits<RING_BITS>>,
    visit_1: DFF<Bit>,
    port_1: DFF<Bits<6>>,
    nonempty_1: DFF<Bit>,
    visit_2: DFF<Bit>,
    port_2: DFF<Bits<6>>,
    nonempty_2: DFF<Bit>,
    visit_3: DFF<Bit>,
    port_3: DFF<Bits<6>>,
    visit_4: DFF<Bit>,
    port_4: DFF<Bits<6>>,
    sends_4: DFF<Bit>,
    /// The new position, written after the queue byte: byte 3 of a queued packet says
    /// whether it is a sync.
    check_sync_4: DFF<Bit>,
    // the position RAM's write, a clock after the queue byte it depends on
    write_5: DFF<Bit>,
    write_port_5: DFF<Bits<6>>,
    write_position_5: DFF<Bits<9>>,
    position_next_4: DFF<Bits<9>>,
    clear: DFF<Bit>,
    clear_address: DFF<Bits<6>>,
    sync_bit: Signal<Local, Bits<9>>,
}

impl DownlinkRefill {
    /// The refill of `ports` ports; generated syncs are framed by `framing`.
    pub fn new(ports: usize, framing: CellCommandFraming) -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            bit_end: Default::default(),
            next_is_last_data: Default::default(),
            take_start: Default::default(),
            tick: Default::default(),
            epoch: Default::default(),
            scan_ring: Default::default(),
            nonempty: Default::default(),
            queue_read_address: Default::default(),
            queue_read_data: Default::default(),
            freed: Default::default(),
            load: Default::default(),
            load_nonempty: Default::default(),
            byte_write: Default::default(),
            byte_port: Default::default(),
            byte_data: Default::default(),
            clearing: Default::default(),
            positions: Default::default(),
            position_read: Default::default(),
            position_2: Default::default(),
            position_step: Default::default(),
            // the visits, the latency after them, and a clock to spare
            sync_bytes: DownlinkSyncBytes::new(framing, ports as u64 + REFILL_LATENCY + 1),
            last_port: Constant::new((ports as u64 - 1).into()),
            ring_start: Constant::new(1.into()),
            sync_command: constant(CommandCode::TimeSync as u64),
            refilling: Default::default(),
            scan: Default::default(),
            ring: Default::default(),
            visit_1: Default::default(),
            port_1: Default::default(),
            nonempty_1: Default::default(),
            visit_2: Default::default(),
            port_2: Default::default(),
            nonempty_2: Default::default(),
            visit_3: Default::default(),
            port_3: Default::default(),
            visit_4: Default::default(),
            port_4: Default::default(),
            sends_4: Default::default(),
            check_sync_4: Default::default(),
            write_5: Default::default(),
            write_port_5: Default::default(),
            write_position_5: Default::default(),
            position_next_4: Default::default(),
            clear: Default::default(),
            clear_address: Default::default(),
            sync_bit: Default::default(),
        }
    }
}

impl Logic for DownlinkRefill {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            refilling,
            scan,
            ring,
            visit_1,
            position_read,
            position_2,
            port_1,
            nonempty_1,
            visit_2,
            port_2,
            nonempty_2,
            visit_3,
            port_3,
            visit_4,
            port_4,
            sends_4,
            check_sync_4,
            write_5,
            write_port_5,
            write_position_5,
            position_next_4,
            clear,
            clear_address
        );
        self.positions.clock.next = self.clock.val();
        self.sync_bytes.clock.next = self.clock.val();
        self.sync_bytes.reset.next = self.reset.val();
        self.sync_bytes.take_start.next = self.take_start.val();
        self.sync_bytes.tick.next = self.tick.val();
        // the scan starts as the pins take the last data bit
        if self.refilling.q.val() {
            self.scan.d.next = self.scan.q.val() + 1;
            if bit_cast::<8, 6>(self.scan.q.val()) == self.last_port.val() {
                self.refilling.d.next = false;
            }
        }
        self.ring.d.next = self.ring.q.val() << 1;
        self.sync_bytes.scan_start.next = self.bit_end.val() & self.next_is_last_data.val();
        if self.bit_end.val() & self.next_is_last_data.val() {
            self.refilling.d.next = true;
            self.scan.d.next = 0.into();
            self.ring.d.next = self.ring_start.val();
        }
        self.scan_ring.next = self.ring.q.val();
        // the position of the port visited in the next clock, read from RAM (port 0 between
        // scans)
        self.positions.read_address.next = self.position_read.q.val();
        self.position_2.d.next = self.positions.read_data.val();
        self.visit_1.d.next = self.refilling.q.val();
        self.port_1.d.next = self.scan.q.val();
        self.nonempty_1.d.next = self.nonempty.val();
        self.visit_2.d.next = self.visit_1.q.val();
        self.port_2.d.next = self.port_1.q.val();
        self.nonempty_2.d.next = self.nonempty_1.q.val() & self.visit_1.q.val();
        // two clocks later: a generated sync (under way, or due at a packet boundary), else
        // the queue's byte
        self.position_step.clock.next = self.clock.val();
        self.position_step.reset.next = self.reset.val();
        self.position_step.visit.next = self.visit_2.q.val();
        self.position_step.position.next = self.position_2.q.val();
        self.position_step.nonempty.next = self.nonempty_2.q.val();
        self.position_step.epoch.next = self.epoch.val();
        self.queue_read_address.next = (bit_cast::<QUEUE_ADDRESS_BITS, 6>(self.port_2.q.val())
            << 6)
            | bit_cast::<QUEUE_ADDRESS_BITS, 5>(self.position_step.index.val())
            | (bit_cast::<QUEUE_ADDRESS_BITS, 1>(self.position_step.slot.val().into()) << 5);
        self.sync_bytes.index.next = self.position_step.index.val();
        self.sync_bytes.wanted.next = self.position_step.sync_byte.val();
        self.freed.next = self.position_step.freed.val();
        self.visit_3.d.next = self.visit_2.q.val();
        self.port_3.d.next = self.port_2.q.val();
        self.visit_4.d.next = self.visit_3.q.val();
        self.port_4.d.next = self.port_3.q.val();
        self.sends_4.d.next = self.position_step.sends.val();
        self.check_sync_4.d.next = self.position_step.check_sync.val();
        self.position_next_4.d.next = self.position_step.next_position.val();
        // two clocks after the address: the byte, or 0xFF and no start bit when none
        self.load.next = self.visit_4.q.val();
        self.load_nonempty.next = self.sends_4.q.val();
        self.byte_write.next = self.visit_4.q.val();
        self.byte_port.next = self.port_4.q.val();
        self.byte_data.next = self.queue_read_data.val();
        if self.sync_bytes.replace.val() {
            self.byte_data.next = self.sync_bytes.sync_byte.val();
        }
        if !self.sends_4.q.val() {
            self.byte_data.next = 0xFF.into();
        }
        self.clearing.next = self.clear.q.val();
        self.sync_bit.next = bit_cast::<9, 1>(true.into()) << 6;
        self.write_5.d.next = self.sends_4.q.val() | self.clear.q.val();
        self.write_port_5.d.next = self.port_4.q.val();
        self.write_position_5.d.next = self.position_next_4.q.val();
        if self.check_sync_4.q.val() & (self.queue_read_data.val() == self.sync_command.val()) {
            self.write_position_5.d.next = self.position_next_4.q.val() | self.sync_bit.val();
        }
        if self.clear.q.val() {
            // after reset every port reads slot 0 from byte 0, and its byte is 0xFF
            self.byte_write.next = true;
            self.byte_port.next = self.clear_address.q.val();
            self.byte_data.next = 0xFF.into();
            self.write_port_5.d.next = self.clear_address.q.val();
            self.write_position_5.d.next = 0.into();
            self.clear_address.d.next = self.clear_address.q.val() + 1;
            if self.clear_address.q.val() == 63 {
                self.clear.d.next = false;
            }
        }
        self.positions.write_enable.next = self.write_5.q.val();
        self.positions.write_address.next = self.write_port_5.q.val();
        self.positions.write_data.next = self.write_position_5.q.val();
        // (from the scan's next state: the port after the next clock's, 0 when it ends)
        self.position_read.d.next = 0.into();
        if self.refilling.d.val() {
            self.position_read.d.next = self.scan.d.val() + 1;
        }
        if self.reset.val() {
            self.position_read.d.next = 0.into();
            self.refilling.d.next = false;
            self.visit_1.d.next = false;
            self.visit_2.d.next = false;
            self.nonempty_2.d.next = false;
            self.visit_3.d.next = false;
            self.visit_4.d.next = false;
            self.sends_4.d.next = false;
            self.clear.d.next = true;
            self.clear_address.d.next = 0.into();
            self.write_5.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::block_ram::BlockRam;
    use crate::testbench::Bench;

    /// The refill with a queue RAM whose byte at each address is its address's low byte.
    #[derive(LogicBlock)]
    struct RefillWithQueues {
        clock: Signal<In, Clock>,
        refill: DownlinkRefill,
        queues: BlockRam<8, QUEUE_ADDRESS_BITS>,
    }

    impl Logic for RefillWithQueues {
        #[hdl_gen]
        fn update(&mut self) {
            self.refill.clock.next = self.clock.val();
            self.queues.clock.next = self.clock.val();
            self.queues.read_address.next = self.refill.queue_read_address.val();
            self.refill.queue_read_data.next = self.queues.read_data.val();
        }
    }

    /// Scan after scan, ports 1 and 4 of 6 (the ones with packets) get the bytes of slot 0
    /// then slot 1 in order, the slot freed at its last byte; the others get 0xFF; each
    /// port's load comes [`REFILL_LATENCY`] clocks after its visit, at its ring bits.
    #[test]
    fn each_scan_loads_every_port_its_next_byte() {
        let ports = 6;
        let queues = BlockRam::default();
        let mut bench = Bench::new(
            RefillWithQueues {
                clock: Default::default(),
                refill: DownlinkRefill::new(ports, CellCommandFraming::DEFAULT),
                queues,
            },
            |b| &mut b.clock,
        );
        // the queue RAM holds each address's low byte
        for a in 0..1u64 << QUEUE_ADDRESS_BITS {
            bench.uut.queues.write_enable.next = true;
            bench.uut.queues.write_address.next = a.into();
            bench.uut.queues.write_data.next = (a & 0xFF).into();
            bench.cycle();
        }
        bench.uut.queues.write_enable.next = false;
        bench.uut.refill.reset.next = true;
        bench.cycle();
        bench.uut.refill.reset.next = false;
        let mut cleared = 0;
        while bench.uut.refill.clearing.val() || cleared == 0 {
            if bench.uut.refill.clearing.val() {
                assert!(bench.uut.refill.byte_write.val());
                assert_eq!(bench.uut.refill.byte_data.val().to_u32(), 0xFF);
                cleared += 1;
            }
            bench.cycle();
        }
        assert_eq!(cleared, 64);
        let with_packets = [1usize, 4];
        for scan in 0..44u32 {
            bench.uut.refill.bit_end.next = true;
            bench.uut.refill.next_is_last_data.next = true;
            let start = bench.cycles;
            bench.cycle();
            bench.uut.refill.bit_end.next = false;
            let mut loads = vec![];
            let mut freed = vec![];
            for _ in 0..ports + 8 {
                let ring = bench.uut.refill.scan_ring.val();
                let visited = (0..ports).find(|&p| ring.get_bit(p));
                bench.uut.refill.nonempty.next = visited.is_some_and(|p| with_packets.contains(&p));
                bench.cycle();
                let refill = &bench.uut.refill;
                let ring = refill.scan_ring.val();
                if refill.load.val() {
                    let port = refill.byte_port.val().index();
                    assert!(
                        ring.get_bit(port + 4),
                        "load of port {port} at its ring bit"
                    );
                    assert!(refill.byte_write.val());
                    // visited in the clock `start + 1 + port`; the load's write is seen from the
                    // clock after this one
                    assert_eq!(bench.cycles + 1 - (start + 1 + port as u64), REFILL_LATENCY);
                    loads.push((
                        port,
                        refill.load_nonempty.val(),
                        refill.byte_data.val().to_u32(),
                    ));
                }
                if refill.freed.val() {
                    freed.push((0..ports).find(|&p| ring.get_bit(p + 3)).unwrap());
                }
            }
            let (slot, byte) = ((scan / 20) % 2, scan % 20);
            let expected: Vec<(usize, bool, u32)> = (0..ports)
                .map(|p| {
                    if with_packets.contains(&p) {
                        (p, true, ((p as u32) << 6 | slot << 5 | byte) & 0xFF)
                    } else {
                        (p, false, 0xFF)
                    }
                })
                .collect();
            assert_eq!(loads, expected, "scan {scan}");
            let expected_freed: &[usize] = if byte == 19 { &with_packets } else { &[] };
            assert_eq!(freed, expected_freed, "scan {scan}");
        }
    }
}
