//! DownlinkSyncBytes: the bytes of a time-sync cell command as the downlink sends it: byte
//! `index` of a sync packet loaded for the frame the refill scan is loading.
//!
//! Bytes 4 to 11 (`box_tick`, big-endian) are the tick of the packet's first start bit:
//! a port's bytes go out back to back, a frame each, so byte `k` loaded for frame `f`
//! belongs to a packet that started in frame `f - k`. The start tick of each of the last
//! 16 frames is kept in a [`LutRam`] (16 x 64 bits of distributed RAM) at the frame number
//! mod 16, written the clock its start bit is on the pins (the tick then is the model's
//! `PacketStart::tick`). Between scans the block reads, one a clock, the eight bytes the
//! next frame's loads can want (byte `k - 4` of the start tick of frame `f + 1 - k`, `k` =
//! 4 to 11) into a table of eight registers; during a scan (the `ports` visits and the
//! refill's latency after `scan_start`) the table holds still, and a load picks its byte
//! from it: no RAM read behind any load. The validated downlink timing leaves at least
//! eight bit times between scans (`BoxConfig::validate`). The other bytes are the box's own
//! sync packet: the command framing's header, cell id [`ALL_CELLS`], command 5, reserved
//! bytes 0, end byte. `sync_byte` and `replace` follow `index` and `wanted` by two clocks
//! (the queue RAM's read latency, so the refill's byte and this one arrive together).

use crate::hdl::*;
use crate::lut_ram::LutRam;
use skinbox_protocol::cell_command::{CellCommandFraming, CommandCode, ALL_CELLS};

/// The sync packet bytes of the downlink's refill.
#[derive(LogicBlock)]
pub struct DownlinkSyncBytes {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the frame count restarts (the frame timer's first frame is 0).
    pub reset: Signal<In, Bit>,
    /// One clock: a refill scan starts; it loads the next frame.
    pub scan_start: Signal<In, Bit>,
    /// One clock: the pins take a start bit at the next edge.
    pub take_start: Signal<In, Bit>,
    /// The box tick.
    pub tick: Signal<In, Bits<64>>,
    /// Byte index in the packet (0 to 19).
    pub index: Signal<In, Bits<5>>,
    /// The refill wants this byte instead of the queue's.
    pub wanted: Signal<In, Bit>,
    /// Two clocks after `index`: its byte of a sync packet loaded for the frame being
    /// loaded then.
    pub sync_byte: Signal<Out, Bits<8>>,
    /// Two clocks after `wanted`: `wanted`.
    pub replace: Signal<Out, Bit>,
    header: Constant<Bits<8>>,
    cell_high: Constant<Bits<8>>,
    cell_low: Constant<Bits<8>>,
    sync_command: Constant<Bits<8>>,
    end_byte: Constant<Bits<8>>,
    /// The frame being loaded (or on the pins, once it started), mod 16.
    frame: DFF<Bits<4>>,
    /// The pins took the frame's start bit: its tick is the tick now.
    started: DFF<Bit>,
    starts: LutRam<64, 4>,
    /// Clocks of the scan still to come: the table holds still.
    scanning: DFF<Bits<7>>,
    scan_clocks: Constant<Bits<7>>,
    /// The table entry read this clock (byte index `lane + 4`).
    lane: DFF<Bits<3>>,
    /// The next frame's start-tick bytes, by byte index 4 to 11.
    table: [DFF<Bits<8>>; 8],
    // a clock after `index`: which of the start tick's bytes it is, whether it is one, and
    // the byte when it is not
    tick_byte_1: DFF<Bits<3>>,
    from_tick_1: DFF<Bit>,
    fixed_1: DFF<Bits<8>>,
    byte_2: DFF<Bits<8>>,
    wanted_1: DFF<Bit>,
    wanted_2: DFF<Bit>,
    fixed: Signal<Local, Bits<8>>,
    stamp: Signal<Local, Bits<64>>,
    table_byte: Signal<Local, Bits<8>>,
}

impl DownlinkSyncBytes {
    /// The sync packet of a box whose cell commands are framed by `framing` and whose
    /// refill scan lasts `scan_clocks` clocks from `scan_start` (its visits and its
    /// latency after them; at most 127).
    pub fn new(framing: CellCommandFraming, scan_clocks: u64) -> Self {
        let [cell_high, cell_low] = ALL_CELLS.to_be_bytes();
        Self {
            clock: Default::default(),
            reset: Default::default(),
            scan_start: Default::default(),
            take_start: Default::default(),
            tick: Default::default(),
            index: Default::default(),
            wanted: Default::default(),
            sync_byte: Default::default(),
            replace: Default::default(),
            header: constant(framing.header.into()),
            cell_high: constant(cell_high.into()),
            cell_low: constant(cell_low.into()),
            sync_command: constant(CommandCode::TimeSync as u64),
            end_byte: constant(framing.end_of_packet.into()),
            frame: Default::default(),
            started: Default::default(),
            starts: Default::default(),
            scanning: Default::default(),
            scan_clocks: constant(scan_clocks),
            lane: Default::default(),
            table: Default::default(),
            tick_byte_1: Default::default(),
            from_tick_1: Default::default(),
            fixed_1: Default::default(),
            byte_2: Default::default(),
            wanted_1: Default::default(),
            wanted_2: Default::default(),
            fixed: Default::default(),
            stamp: Default::default(),
            table_byte: Default::default(),
        }
    }
}

impl Logic for DownlinkSyncBytes {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            frame,
            started,
            scanning,
            lane,
            tick_byte_1,
            from_tick_1,
            fixed_1,
            byte_2,
            wanted_1,
            wanted_2
        );
        for k in 0..8 {
            self.table[k].clock.next = self.clock.val();
            self.table[k].d.next = self.table[k].q.val();
        }
        self.starts.clock.next = self.clock.val();
        if self.scan_start.val() {
            self.frame.d.next = self.frame.q.val() + 1;
        }
        self.started.d.next = self.take_start.val();
        self.starts.write_enable.next = self.started.q.val();
        self.starts.write_address.next = self.frame.q.val();
        self.starts.write_data.next = self.tick.val();
        // between scans: table entry `lane` (byte index lane + 4) for the next frame
        self.starts.read_address.next =
            self.frame.q.val() + 1 - 4 - bit_cast::<4, 3>(self.lane.q.val());
        self.stamp.next = self.starts.read_data.val();
        if self.scanning.q.val() == 0 {
            self.lane.d.next = self.lane.q.val() + 1;
            if self.lane.q.val() == 0 {
                self.table[0].d.next = self.stamp.val().get_bits::<8>(56);
            }
            if self.lane.q.val() == 1 {
                self.table[1].d.next = self.stamp.val().get_bits::<8>(48);
            }
            if self.lane.q.val() == 2 {
                self.table[2].d.next = self.stamp.val().get_bits::<8>(40);
            }
            if self.lane.q.val() == 3 {
                self.table[3].d.next = self.stamp.val().get_bits::<8>(32);
            }
            if self.lane.q.val() == 4 {
                self.table[4].d.next = self.stamp.val().get_bits::<8>(24);
            }
            if self.lane.q.val() == 5 {
                self.table[5].d.next = self.stamp.val().get_bits::<8>(16);
            }
            if self.lane.q.val() == 6 {
                self.table[6].d.next = self.stamp.val().get_bits::<8>(8);
            }
            if self.lane.q.val() == 7 {
                self.table[7].d.next = self.stamp.val().get_bits::<8>(0);
            }
        } else {
            self.scanning.d.next = self.scanning.q.val() - 1;
        }
        if self.scan_start.val() {
            self.scanning.d.next = self.scan_clocks.val();
        }
        // first clock: which byte of the start tick the index is, and the bytes that are
        // no tick's
        self.tick_byte_1.d.next = self.index.val().get_bits::<3>(0) - 4;
        self.from_tick_1.d.next = (self.index.val() >= 4) & (self.index.val() <= 11);
        self.fixed.next = 0.into();
        if self.index.val() == 0 {
            self.fixed.next = self.header.val();
        }
        if self.index.val() == 1 {
            self.fixed.next = self.cell_high.val();
        }
        if self.index.val() == 2 {
            self.fixed.next = self.cell_low.val();
        }
        if self.index.val() == 3 {
            self.fixed.next = self.sync_command.val();
        }
        if self.index.val() == 19 {
            self.fixed.next = self.end_byte.val();
        }
        self.fixed_1.d.next = self.fixed.val();
        // second clock: the byte from the table
        self.table_byte.next = self.table[0].q.val();
        if self.tick_byte_1.q.val() == 1 {
            self.table_byte.next = self.table[1].q.val();
        }
        if self.tick_byte_1.q.val() == 2 {
            self.table_byte.next = self.table[2].q.val();
        }
        if self.tick_byte_1.q.val() == 3 {
            self.table_byte.next = self.table[3].q.val();
        }
        if self.tick_byte_1.q.val() == 4 {
            self.table_byte.next = self.table[4].q.val();
        }
        if self.tick_byte_1.q.val() == 5 {
            self.table_byte.next = self.table[5].q.val();
        }
        if self.tick_byte_1.q.val() == 6 {
            self.table_byte.next = self.table[6].q.val();
        }
        if self.tick_byte_1.q.val() == 7 {
            self.table_byte.next = self.table[7].q.val();
        }
        self.byte_2.d.next = self.fixed_1.q.val();
        if self.from_tick_1.q.val() {
            self.byte_2.d.next = self.table_byte.val();
        }
        self.wanted_1.d.next = self.wanted.val();
        self.wanted_2.d.next = self.wanted_1.q.val();
        self.sync_byte.next = self.byte_2.q.val();
        self.replace.next = self.wanted_2.q.val();
        if self.reset.val() {
            self.frame.d.next = 0.into();
            self.started.d.next = false;
            self.scanning.d.next = 0.into();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;
    use skinbox_protocol::cell_command::{CellCommand, CellCommandRepr};

    /// Frames of random length start at random ticks; a packet whose first frame is `f0`
    /// reads, byte by byte in frames `f0`..`f0 + 19`, the emitted sync packet of `f0`'s
    /// start tick.
    #[test]
    fn a_packet_reads_the_sync_of_its_first_frames_start_tick() {
        let framing = CellCommandFraming::DEFAULT;
        let mut bench = Bench::new(DownlinkSyncBytes::new(framing, 64 + 6), |b| &mut b.clock);
        let mut rng = crate::testbench::TestRng::new(0x57);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut tick = rng.next_u64() >> 1;
        // frame n's start tick: its start is taken (the pins take it at the next edge)
        let mut starts: Vec<u64> = vec![];
        for frame in 0..60u64 {
            bench.uut.take_start.next = true;
            bench.uut.tick.next = tick.into();
            bench.cycle();
            bench.uut.take_start.next = false;
            tick += 1;
            starts.push(tick);
            bench.uut.tick.next = tick.into();
            let gap = 150 + rng.next_u64() % 300;
            bench.cycles(gap);
            tick += gap;
            // the scan loading frame + 1
            bench.uut.scan_start.next = true;
            bench.cycle();
            bench.uut.scan_start.next = false;
            tick += 1;
            // a new index every clock, as the refill visits its ports
            let want = |k: u64| {
                let first = (frame + 1).checked_sub(k.max(1))?;
                let mut want = [0; 20];
                CellCommandRepr {
                    cell_id: ALL_CELLS,
                    command: CellCommand::TimeSync {
                        box_tick: starts[first as usize],
                    },
                }
                .emit_with(&mut want, &framing);
                Some(want[k as usize])
            };
            let order: Vec<u64> = (0..20).map(|i| (i * 7 + frame) % 20).collect();
            for (i, &k) in order.iter().enumerate() {
                bench.uut.index.next = k.into();
                bench.uut.wanted.next = k % 2 == 1;
                bench.cycle();
                tick += 1;
                if i == 0 {
                    continue;
                }
                // the index of the clock before, two clocks after it was given
                let before = order[i - 1];
                assert_eq!(bench.uut.replace.val(), before % 2 == 1);
                // (bytes 0 to 3 do not depend on the start tick)
                if let Some(want) = want(before) {
                    assert_eq!(
                        bench.uut.sync_byte.val().to_u64(),
                        u64::from(want),
                        "frame {frame} byte {before}"
                    );
                }
            }
            let gap = 150 + rng.next_u64() % 300;
            bench.cycles(gap);
            tick += gap;
        }
    }
}
