//! DownlinkNextPosition: the refill's step for a visited port: whether it sends a byte
//! and from where, and its read position after the byte.
//!
//! A port's position word (the refill's position RAM): the next byte's index (bits 0-4),
//! the slot of its oldest packet (5), the packet on the line is a time sync (6) or a
//! generated one (7), the epoch of its last generated sync (8). At a visit
//! (`visit`, with the word as read) the port sends the generator's sync when one is under
//! way or due (at a packet boundary, byte index 0, when its epoch differs from the
//! generator's `epoch`; the new position takes that epoch), else the queue's byte when its
//! queue holds a packet (`nonempty`). The next position is a byte further; past a packet's
//! last byte (index 19) it is at byte 0, not a sync, and a queued packet's slot is the
//! other one (`freed`, a clock later). Whether a queued packet is a sync is known only from
//! its byte 3 (`check_sync`, for the refill to set bit 6 once the queue's byte is read).
//! The registered outputs come a clock after the visit. Cost: 12 flip-flops.

use crate::hdl::*;

/// The refill's step for the visited port.
#[derive(LogicBlock, Default)]
pub struct DownlinkNextPosition {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing sent, no slot freed.
    pub reset: Signal<In, Bit>,
    /// A port is visited: its position word is `position`.
    pub visit: Signal<In, Bit>,
    /// The visited port's position word.
    pub position: Signal<In, Bits<9>>,
    /// Its queue holds a packet.
    pub nonempty: Signal<In, Bit>,
    /// The sync generator's epoch.
    pub epoch: Signal<In, Bit>,
    /// The byte's index in its packet.
    pub index: Signal<Out, Bits<5>>,
    /// The queue slot of the port's oldest packet.
    pub slot: Signal<Out, Bit>,
    /// The byte is a sync's own (a generated sync, or bytes 4 to 11 of a queued sync).
    pub sync_byte: Signal<Out, Bit>,
    /// A clock after the visit: the port sends a byte (generated or queued).
    pub sends: Signal<Out, Bit>,
    /// A clock after the visit: the port's next position (bit 6 still to be set for a
    /// queued sync).
    pub next_position: Signal<Out, Bits<9>>,
    /// A clock after the visit: the queue's byte is a packet's byte 3, which says whether
    /// it is a sync.
    pub check_sync: Signal<Out, Bit>,
    /// A clock after the visit: the port's queue slot is free.
    pub freed: Signal<Out, Bit>,
    last_byte: Signal<Local, Bit>,
    pending: Signal<Local, Bit>,
    generated: Signal<Local, Bit>,
    from_queue: Signal<Local, Bit>,
    next_index: Signal<Local, Bits<5>>,
    next_epoch: Signal<Local, Bit>,
    next_generated: Signal<Local, Bit>,
    next_sync: Signal<Local, Bit>,
    next_slot: Signal<Local, Bit>,
    sends_byte: DFF<Bit>,
    position_after: DFF<Bits<9>>,
    byte_three: DFF<Bit>,
    slot_freed: DFF<Bit>,
}

impl Logic for DownlinkNextPosition {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            sends_byte,
            position_after,
            byte_three,
            slot_freed
        );
        self.index.next = self.position.val().get_bits::<5>(0);
        self.slot.next = self.position.val().get_bit(5);
        self.last_byte.next = self.index.val() == 19;
        self.pending.next = !self.position.val().get_bit(7)
            & (self.index.val() == 0)
            & (self.position.val().get_bit(8) != self.epoch.val());
        self.generated.next =
            self.visit.val() & (self.position.val().get_bit(7) | self.pending.val());
        self.from_queue.next = !self.generated.val() & self.nonempty.val();
        self.sync_byte.next = self.generated.val()
            | (self.position.val().get_bit(6) & (self.index.val() >= 4) & (self.index.val() <= 11));
        // the next position: epoch, generated, sync, slot, index
        self.next_index.next = self.index.val() + 1;
        self.next_epoch.next = self.position.val().get_bit(8);
        self.next_generated.next = self.generated.val();
        self.next_sync.next = self.position.val().get_bit(6);
        self.next_slot.next = self.position.val().get_bit(5);
        if self.pending.val() {
            self.next_epoch.next = self.epoch.val();
        }
        if self.last_byte.val() {
            // past the packet: not a sync; a queued packet's slot is free
            self.next_index.next = 0.into();
            self.next_generated.next = false;
            self.next_sync.next = false;
            self.next_slot.next = self.position.val().get_bit(5) ^ self.from_queue.val();
        }
        self.position_after.d.next = (bit_cast::<9, 1>(self.next_epoch.val().into()) << 8)
            | (bit_cast::<9, 1>(self.next_generated.val().into()) << 7)
            | (bit_cast::<9, 1>(self.next_sync.val().into()) << 6)
            | (bit_cast::<9, 1>(self.next_slot.val().into()) << 5)
            | bit_cast::<9, 5>(self.next_index.val());
        self.byte_three.d.next = self.from_queue.val() & (self.index.val() == 3);
        self.sends_byte.d.next = self.generated.val() | self.from_queue.val();
        self.slot_freed.d.next = self.from_queue.val() & self.last_byte.val();
        if self.reset.val() {
            self.sends_byte.d.next = false;
            self.slot_freed.d.next = false;
        }
        self.sends.next = self.sends_byte.q.val();
        self.next_position.next = self.position_after.q.val();
        self.check_sync.next = self.byte_three.q.val();
        self.freed.next = self.slot_freed.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Every position word, with and without a visit, a packet in the queue and either
    /// epoch: the outputs are the rule written out here (the registered ones a clock
    /// later).
    #[test]
    fn each_position_steps_to_the_next_byte_or_packet() {
        let mut bench = Bench::new(DownlinkNextPosition::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0xD0C5);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        // (sends, next position, check sync, freed) expected after the edge
        let mut expected: Option<(bool, u64, bool, bool)> = None;
        let mut generated_seen = [0u32; 2];
        for round in 0..40_000u64 {
            let bits = rng.next_u64();
            // indices 0 to 19 (a packet's bytes) most of the time
            let index = if bits & 7 == 0 {
                bits >> 3 & 31
            } else {
                (bits >> 3) % 20
            };
            let position = index | (bits >> 8 & 0xF) << 5;
            let (visit, nonempty, epoch) = (
                bits >> 12 & 1 == 1,
                bits >> 13 & 1 == 1,
                bits >> 14 & 1 == 1,
            );
            let u = &mut bench.uut;
            u.visit.next = visit;
            u.position.next = position.into();
            u.nonempty.next = nonempty;
            u.epoch.next = epoch;
            bench.settle();
            let u = &bench.uut;
            if let Some((sends, next, check, freed)) = expected {
                assert_eq!(u.sends.val(), sends, "round {round}");
                assert_eq!(u.next_position.val().to_u64(), next, "round {round}");
                assert_eq!(u.check_sync.val(), check, "round {round}");
                assert_eq!(u.freed.val(), freed, "round {round}");
            }
            let bit = |k: u32| position >> k & 1 == 1;
            let pending = !bit(7) && index == 0 && bit(8) != epoch;
            let generated = visit && (bit(7) || pending);
            let from_queue = !generated && nonempty;
            generated_seen[usize::from(pending)] += u32::from(generated);
            assert_eq!(u.index.val().to_u64(), index);
            assert_eq!(u.slot.val(), bit(5));
            assert_eq!(
                u.sync_byte.val(),
                generated || (bit(6) && (4..=11).contains(&index)),
                "round {round}"
            );
            let next_epoch = if pending { epoch } else { bit(8) };
            let next = if index == 19 {
                u64::from(next_epoch) << 8 | u64::from(bit(5) ^ from_queue) << 5
            } else {
                u64::from(next_epoch) << 8
                    | u64::from(generated) << 7
                    | u64::from(bit(6)) << 6
                    | u64::from(bit(5)) << 5
                    | (index + 1) & 31
            };
            expected = Some((
                generated || from_queue,
                next,
                from_queue && index == 3,
                from_queue && index == 19,
            ));
            bench.cycle();
        }
        assert!(
            generated_seen.iter().all(|&n| n > 100),
            "{generated_seen:?}"
        );
    }
}
