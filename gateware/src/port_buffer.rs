//! PortBuffer: holds whole packets of one port until the arbiter takes them.
//!
//! Two slots of 32 bytes in one RAM. A packet from the deframer (4 tick bytes and 20 cell
//! bytes) is written as it arrives and becomes visible only when its `last` beat arrives
//! without `error`; a packet with `error` is forgotten. When both slots are full as a packet
//! starts, the whole packet is dropped and a dropped-overflow event pulses when it ends.
//!
//! Output: 25 beats per packet, `last` on the final one: a flags byte (bit 0 =
//! `skinbox_protocol::record::FLAG_LOSS_BEFORE`: packets of this port were dropped or
//! rejected since the previous packet out), then the 24 stored bytes. The input is always
//! ready. Latency: the first output beat is valid two clocks after the input's `last`.
//! Cost: a 64 x 9 RAM and about 30 flip-flops.

use crate::cell_deframer::TICK_BEATS;
use crate::lut_ram::LutRam;
use crate::stream::{ByteStreamSink, ByteStreamSource};
use rust_hdl::prelude::*;
use skinbox_protocol::cell::PACKET_LEN;

/// Packets a port buffer holds (the slot index is one bit wide, so this is 2).
pub const SLOTS: usize = 2;
/// Beats of a stored packet: tick and cell bytes.
pub const STORED_BEATS: usize = TICK_BEATS + PACKET_LEN;
/// Beats of an output packet: flags, tick and cell bytes.
pub const OUTPUT_BEATS: usize = 1 + STORED_BEATS;

/// Two-packet buffer of one port.
#[derive(LogicBlock)]
pub struct PortBuffer {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: empties the buffer.
    pub reset: Signal<In, Bit>,
    /// Packets from the deframer.
    pub sink: ByteStreamSink,
    /// Whole good packets, flags first.
    pub source: ByteStreamSource,
    /// Counter events, bit i = `skinbox_protocol::PortCounter` i: bit 1 (dropped
    /// overflow) for one clock per good packet dropped because both slots were full.
    pub events: Signal<Out, Bits<8>>,
    memory: LutRam<9, 6>,
    stored_beats: Constant<Bits<5>>,
    slots: Constant<Bits<2>>,
    used: DFF<Bits<2>>,
    // used != 0 and used == 2, kept in registers
    occupied: DFF<Bit>,
    full: DFF<Bit>,
    used_next: Signal<Local, Bits<2>>,
    write_slot: DFF<Bit>,
    write_index: DFF<Bits<5>>,
    dropping: DFF<Bit>,
    loss_pending: DFF<Bit>,
    dropped_pulse: DFF<Bit>,
    read_slot: DFF<Bit>,
    read_beat: DFF<Bits<5>>,
    // read_beat == the last beat, kept in a register
    last_beat: DFF<Bit>,
    current_address: DFF<Bits<6>>,
    next_address: DFF<Bits<6>>,
    last_stored_index: Constant<Bits<5>>,
    read_fire: Signal<Local, Bit>,
    commit: Signal<Local, Bit>,
}

impl Default for PortBuffer {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            sink: Default::default(),
            source: Default::default(),
            events: Default::default(),
            memory: Default::default(),
            stored_beats: Constant::new((STORED_BEATS as u64).into()),
            slots: Constant::new((SLOTS as u64).into()),
            used: Default::default(),
            occupied: Default::default(),
            full: Default::default(),
            used_next: Default::default(),
            write_slot: Default::default(),
            write_index: Default::default(),
            dropping: Default::default(),
            loss_pending: Default::default(),
            dropped_pulse: Default::default(),
            read_slot: Default::default(),
            read_beat: Default::default(),
            last_beat: Default::default(),
            current_address: Default::default(),
            read_fire: Default::default(),
            commit: Default::default(),
            next_address: Default::default(),
            last_stored_index: Constant::new((STORED_BEATS as u64 - 1).into()),
        }
    }
}

impl Logic for PortBuffer {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            used,
            occupied,
            full,
            write_slot,
            write_index,
            dropping,
            loss_pending,
            dropped_pulse,
            read_slot,
            read_beat,
            last_beat,
            current_address,
            next_address
        );
        self.memory.clock.next = self.clock.val();

        // Write side: always ready; store beats, commit on a good last beat.
        self.sink.ready.next = true;
        self.dropped_pulse.d.next = false;
        self.commit.next = false;
        self.memory.write_enable.next = false;
        self.memory.write_address.next = (bit_cast::<6, 1>(self.write_slot.q.val().into()) << 5)
            | bit_cast::<6, 5>(self.write_index.q.val());
        self.memory.write_data.next = bit_cast::<9, 8>(self.sink.data.val())
            | (bit_cast::<9, 1>(self.loss_pending.q.val().into()) << 8);
        if self.sink.valid.val() {
            if self.write_index.q.val() == 0 {
                self.dropping.d.next = self.full.q.val();
                self.memory.write_enable.next = !self.full.q.val();
            } else {
                self.memory.write_enable.next =
                    !self.dropping.q.val() & (self.write_index.q.val() < self.stored_beats.val());
            }
            if self.write_index.q.val() < self.stored_beats.val() {
                self.write_index.d.next = self.write_index.q.val() + 1;
            }
            if self.sink.last.val() {
                self.write_index.d.next = 0.into();
                if self.sink.error.val() {
                    self.loss_pending.d.next = true;
                } else if self.dropping.q.val()
                    | ((self.write_index.q.val() == 0) & self.full.q.val())
                {
                    self.loss_pending.d.next = true;
                    self.dropped_pulse.d.next = true;
                } else {
                    self.commit.next = true;
                    self.loss_pending.d.next = false;
                    self.write_slot.d.next = !self.write_slot.q.val();
                }
            }
        }

        // Read side: beat 0 is the flags byte, beats 1..=24 the stored bytes. The RAM reads
        // one clock late, so it is addressed with the beat shown after this edge.
        self.source.valid.next = self.occupied.q.val();
        self.source.last.next = self.last_beat.q.val();
        self.source.error.next = false;
        if self.read_beat.q.val() == 0 {
            self.source.data.next = bit_cast::<8, 1>(self.memory.read_data.val().get_bit(8).into());
        } else {
            self.source.data.next = self.memory.read_data.val().get_bits::<8>(0);
        }
        self.read_fire.next = self.source.valid.val() & self.source.ready.val();
        // Beat k > 0 is stored at address k - 1 of its slot, and the flags ride on the word
        // of beat 1, so beats 0 and 1 read the same word. `next_address` (a register) is the
        // word of the beat after the one shown. The output register of the memory loads it
        // on a transfer and holds the shown beat otherwise (its slot is committed, so its
        // words do not change); while nothing is shown it follows the first word of the
        // read slot. So `ready` only enables the register: no path runs from it, nor from
        // the beat count, through the memory.
        self.memory.read_enable.next = self.read_fire.val() | !self.source.valid.val();
        self.memory.read_address.next = self.current_address.q.val();
        if self.source.valid.val() {
            self.memory.read_address.next = self.next_address.q.val();
        }
        if self.read_fire.val() {
            self.current_address.d.next = self.next_address.q.val();
            self.next_address.d.next = (bit_cast::<6, 1>(self.read_slot.q.val().into()) << 5)
                | bit_cast::<6, 5>(self.read_beat.q.val() + 1);
            self.last_beat.d.next = false;
            if self.last_beat.q.val() {
                self.read_beat.d.next = 0.into();
                self.read_slot.d.next = !self.read_slot.q.val();
                self.next_address.d.next = bit_cast::<6, 1>((!self.read_slot.q.val()).into()) << 5;
            } else {
                self.read_beat.d.next = self.read_beat.q.val() + 1;
                if self.read_beat.q.val() == self.last_stored_index.val() {
                    self.last_beat.d.next = true;
                    self.next_address.d.next =
                        bit_cast::<6, 1>((!self.read_slot.q.val()).into()) << 5;
                }
            }
        }

        // Occupancy.
        self.used_next.next = self.used.q.val();
        if self.commit.val() & !(self.read_fire.val() & self.source.last.val()) {
            self.used_next.next = self.used.q.val() + 1;
        } else if !self.commit.val() & self.read_fire.val() & self.source.last.val() {
            self.used_next.next = self.used.q.val() - 1;
        }

        if self.reset.val() {
            self.used_next.next = 0.into();
            self.write_slot.d.next = false;
            self.write_index.d.next = 0.into();
            self.dropping.d.next = false;
            self.loss_pending.d.next = false;
            self.dropped_pulse.d.next = false;
            self.read_slot.d.next = false;
            self.read_beat.d.next = 0.into();
            self.last_beat.d.next = false;
            self.current_address.d.next = 0.into();
            self.next_address.d.next = 0.into();
        }
        self.used.d.next = self.used_next.val();
        self.occupied.d.next = self.used_next.val() != 0;
        self.full.d.next = self.used_next.val() == self.slots.val();
        self.events.next = bit_cast::<8, 1>(self.dropped_pulse.q.val().into()) << 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    /// A packet offered to the buffer: its 24 stored bytes and whether it ends in error
    /// after `len` beats.
    #[derive(Clone)]
    struct Offer {
        bytes: Vec<u8>,
        error: bool,
    }

    fn good(n: u8) -> Offer {
        Offer {
            bytes: (0..STORED_BEATS as u8)
                .map(|i| n.wrapping_mul(31).wrapping_add(i))
                .collect(),
            error: false,
        }
    }

    /// Feeds the offers with `spacing` idle clocks between beats while reading with the
    /// ready pattern, starting to read after `read_after` clocks. Returns the output
    /// packets (flags, bytes) and the number of drop pulses.
    fn run(
        offers: &[Offer],
        spacing: u64,
        ready: &[bool],
        read_after: u64,
    ) -> (Vec<(u8, Vec<u8>)>, u32) {
        let mut bench = Bench::new(PortBuffer::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        let mut beats: Vec<(u8, bool)> = vec![];
        let mut drops = 0;
        let mut input: Vec<(u8, bool, bool)> = vec![];
        for o in offers {
            let n = o.bytes.len();
            for (i, b) in o.bytes.iter().enumerate() {
                input.push((*b, i + 1 == n, o.error && i + 1 == n));
            }
        }
        let mut next = 0;
        let mut wait = 0;
        let total = input.len() as u64 * (spacing + 1) + read_after + 200;
        for clock in 0..total {
            let offer = wait == 0 && next < input.len();
            let u = &mut bench.uut;
            u.sink.valid.next = offer;
            if offer {
                let (d, last, error) = input[next];
                u.sink.data.next = u64::from(d).into();
                u.sink.last.next = last;
                u.sink.error.next = error;
            }
            let r = clock >= read_after && ready[clock as usize % ready.len()];
            u.source.ready.next = r;
            bench.settle();
            let u = &bench.uut;
            assert!(u.sink.ready.val(), "the buffer input is always ready");
            if r && u.source.valid.val() {
                beats.push((u.source.data.val().to_u8(), u.source.last.val()));
            }
            drops += u32::from(u.events.val().to_u8() >> 1 & 1);
            assert_eq!(u.events.val().to_u8() & !2, 0);
            if offer {
                next += 1;
                wait = spacing;
            } else {
                wait = wait.saturating_sub(1);
            }
            bench.cycle();
        }
        let mut packets = vec![];
        let mut current = vec![];
        for (d, last) in beats {
            current.push(d);
            if last {
                assert_eq!(current.len(), OUTPUT_BEATS);
                packets.push((current[0], current[1..].to_vec()));
                current = vec![];
            }
        }
        assert!(current.is_empty());
        (packets, drops)
    }

    #[test]
    fn passes_packets_in_order_under_backpressure() {
        let offers: Vec<Offer> = (0..6).map(good).collect();
        for ready in [
            &[true][..],
            &[true, false],
            &[false, false, true],
            &[true, true, true, false],
        ] {
            let (out, drops) = run(&offers, 3, ready, 0);
            let expected: Vec<(u8, Vec<u8>)> =
                offers.iter().map(|o| (0, o.bytes.clone())).collect();
            assert_eq!(out, expected);
            assert_eq!(drops, 0);
        }
    }

    #[test]
    fn rejected_packets_vanish_and_flag_the_next() {
        let mut bad = good(9);
        bad.bytes.truncate(7);
        bad.error = true;
        let mut bad_full = good(10);
        bad_full.error = true;
        let offers = vec![good(1), bad, good(2), bad_full, good(3)];
        let (out, drops) = run(&offers, 0, &[true], 0);
        assert_eq!(
            out,
            vec![(0, good(1).bytes), (1, good(2).bytes), (1, good(3).bytes)]
        );
        assert_eq!(drops, 0);
    }

    #[test]
    fn overflow_drops_whole_packets_counts_them_and_flags_the_next() {
        // the reader sleeps until all five packets were offered: two fit, three drop
        let offers: Vec<Offer> = (0..5).map(good).collect();
        let (out, drops) = run(&offers, 0, &[true], 5 * STORED_BEATS as u64 + 10);
        assert_eq!(out, vec![(0, good(0).bytes), (0, good(1).bytes)]);
        assert_eq!(drops, 3);

        // after the drops, the next packet that fits carries the loss flag
        let mut offers: Vec<Offer> = (0..3).map(good).collect();
        offers.push(good(7));
        // one beat every two clocks: packet k starts at clock 48 k; packet 2 finds both
        // slots full, the reader wakes at 100 and frees one before packet 3 starts at 144
        let (out, drops) = run(&offers, 1, &[true], 100);
        assert_eq!(drops, 1);
        assert_eq!(out.len(), 3);
        assert_eq!(
            out[2],
            (1, good(7).bytes),
            "the packet after a drop is flagged"
        );
    }

    #[test]
    fn fill_and_drain_at_the_same_time() {
        let offers: Vec<Offer> = (0..40).map(good).collect();
        let (out, drops) = run(&offers, 0, &[true, true, false], 30);
        let sent: Vec<Vec<u8>> = out.iter().map(|o| o.1.clone()).collect();
        // every output is one of the offers, in order, and every offer is out or counted
        let mut expected = offers.iter().map(|o| o.bytes.clone());
        for s in &sent {
            assert!(
                expected.any(|e| &e == s),
                "out of order or corrupted: {s:?}"
            );
        }
        assert_eq!(sent.len() as u32 + drops, 40);
    }
}
