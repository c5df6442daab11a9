//! HostTable: the command unit's table of the hosts whose commands it took, each with the
//! last sequence number accepted from it (docs/control.md, step 18).
//!
//! `HOST_SLOTS` slots, each an IPv4 address and a sequence number in two [`LutRam`]s (one
//! word per slot in each), a valid bit and an age rank in registers (rank 0: taken last,
//! `HOST_SLOTS - 1`: taken longest ago; the empty slots are always the oldest). The table
//! looks `peer_ip` up by scanning its slots' addresses, one per clock, all the time: a
//! slot's address is read, its bytes compared with `peer_ip`'s into registers, and a clock
//! later the slot's match bit is set or cleared. The slot a take would write (`peer_ip`'s
//! slot if known, else the oldest) is registered, and the sequence RAM is read there:
//! `last_sequence` is a wire from it. So `known`, `last_sequence` and the target slot are
//! right [`LOOKUP_CLOCKS`] clocks after `peer_ip` last changed or the table was last
//! written, and stay so while neither happens. The sender of a command is steady long
//! before the command is decided (from its IPv4 header to the frame's end, at least 30
//! clocks), so a scan costs the command no clock, and one 32-bit compare and one read port
//! replace a compare per slot and a flip-flop per stored bit.
//!
//! `take` (one clock) writes `peer_ip` and `take_sequence` into the target slot, makes it
//! the newest and ages the slots that were newer than it.

use crate::hdl::*;
use crate::lut_ram::LutRam;
use skinbox_protocol::command::HOST_SLOTS;

/// Address bits of a slot.
const SLOT_BITS: usize = 2;
const _: () = assert!(HOST_SLOTS == 1 << SLOT_BITS);

/// Clocks from the last change of `peer_ip` or the last `take` to the clock in which
/// `known`, `last_sequence` and the target slot are right: a full scan (each slot's
/// compare registered), the match bits, the target's register. (`lookups_and_takes_follow_the_model`
/// fails with one clock less.)
pub const LOOKUP_CLOCKS: u64 = HOST_SLOTS as u64 + 2;

/// The host table.
#[derive(LogicBlock)]
pub struct HostTable {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: forgets every host.
    pub reset: Signal<In, Bit>,
    /// The host looked up, and written by `take`.
    pub peer_ip: Signal<In, Bits<32>>,
    /// One clock: `peer_ip` took `take_sequence`; write it into the target slot.
    pub take: Signal<In, Bit>,
    /// The sequence number written by `take`.
    pub take_sequence: Signal<In, Bits<32>>,
    /// `peer_ip` is in the table.
    pub known: Signal<Out, Bit>,
    /// The last sequence number taken from `peer_ip` when it is `known` (else a slot's
    /// word: not defined).
    pub last_sequence: Signal<Out, Bits<32>>,
    /// `last_sequence` when `peer_ip` is known, else 0.
    pub known_sequence: Signal<Out, Bits<32>>,
    // slot i's address, and its sequence number
    addresses: LutRam<32, SLOT_BITS>,
    sequences: LutRam<32, SLOT_BITS>,
    valid: DFF<Bits<HOST_SLOTS>>,
    ranks: Vec<DFF<Bits<SLOT_BITS>>>,
    initial_ranks: Vec<Constant<Bits<SLOT_BITS>>>,
    oldest_rank: Constant<Bits<SLOT_BITS>>,
    // slot i as a number and as its bit
    slot_number: Vec<Constant<Bits<SLOT_BITS>>>,
    slot_bit: Vec<Constant<Bits<HOST_SLOTS>>>,
    // the slot read now, and (one-hot) the one whose compares are in the registers below
    scan: DFF<Bits<SLOT_BITS>>,
    compared: DFF<Bits<HOST_SLOTS>>,
    // the compared address's bytes each equal `peer_ip`'s (a byte's compare is one level
    // of LUTs after the RAM's read)
    byte_3_equal: DFF<Bit>,
    byte_2_equal: DFF<Bit>,
    byte_1_equal: DFF<Bit>,
    byte_0_equal: DFF<Bit>,
    // slot i holds `peer_ip`
    holds_peer: DFF<Bits<HOST_SLOTS>>,
    // the slot a take writes (one-hot, and its number) and its rank
    target: DFF<Bits<HOST_SLOTS>>,
    target_number: DFF<Bits<SLOT_BITS>>,
    target_rank: DFF<Bits<SLOT_BITS>>,
    compared_matches: Signal<Local, Bit>,
    next_target: Signal<Local, Bits<HOST_SLOTS>>,
    next_target_number: Signal<Local, Bits<SLOT_BITS>>,
    next_target_rank: Signal<Local, Bits<SLOT_BITS>>,
}

impl Default for HostTable {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            peer_ip: Default::default(),
            take: Default::default(),
            take_sequence: Default::default(),
            known: Default::default(),
            last_sequence: Default::default(),
            known_sequence: Default::default(),
            addresses: Default::default(),
            sequences: Default::default(),
            valid: Default::default(),
            ranks: each(HOST_SLOTS),
            initial_ranks: (0..HOST_SLOTS)
                .map(|i| constant((HOST_SLOTS - 1 - i) as u64))
                .collect(),
            oldest_rank: constant(HOST_SLOTS as u64 - 1),
            slot_number: (0..HOST_SLOTS).map(|i| constant(i as u64)).collect(),
            slot_bit: (0..HOST_SLOTS).map(|i| constant(1 << i)).collect(),
            scan: Default::default(),
            compared: Default::default(),
            byte_3_equal: Default::default(),
            byte_2_equal: Default::default(),
            byte_1_equal: Default::default(),
            byte_0_equal: Default::default(),
            holds_peer: Default::default(),
            target: Default::default(),
            target_number: Default::default(),
            target_rank: Default::default(),
            compared_matches: Default::default(),
            next_target: Default::default(),
            next_target_number: Default::default(),
            next_target_rank: Default::default(),
        }
    }
}

impl Logic for HostTable {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            valid,
            scan,
            compared,
            byte_3_equal,
            byte_2_equal,
            byte_1_equal,
            byte_0_equal,
            holds_peer,
            target,
            target_number,
            target_rank
        );
        for i in 0..self.ranks.len() {
            self.ranks[i].clock.next = self.clock.val();
            self.ranks[i].d.next = self.ranks[i].q.val();
        }
        // The scan: read a slot and compare its address, then set or clear its match bit.
        self.scan.d.next = self.scan.q.val() + 1;
        self.addresses.clock.next = self.clock.val();
        self.addresses.read_address.next = self.scan.q.val();
        self.compared.d.next = 0.into();
        for i in 0..self.slot_bit.len() {
            if self.scan.q.val() == self.slot_number[i].val() {
                self.compared.d.next = self.slot_bit[i].val();
            }
        }
        self.byte_3_equal.d.next = self.addresses.read_data.val().get_bits::<8>(24)
            == self.peer_ip.val().get_bits::<8>(24);
        self.byte_2_equal.d.next = self.addresses.read_data.val().get_bits::<8>(16)
            == self.peer_ip.val().get_bits::<8>(16);
        self.byte_1_equal.d.next =
            self.addresses.read_data.val().get_bits::<8>(8) == self.peer_ip.val().get_bits::<8>(8);
        self.byte_0_equal.d.next =
            self.addresses.read_data.val().get_bits::<8>(0) == self.peer_ip.val().get_bits::<8>(0);
        self.compared_matches.next = self.byte_3_equal.q.val()
            & self.byte_2_equal.q.val()
            & self.byte_1_equal.q.val()
            & self.byte_0_equal.q.val()
            & ((self.valid.q.val() & self.compared.q.val()) != 0);
        if self.compared_matches.val() {
            self.holds_peer.d.next = self.holds_peer.q.val() | self.compared.q.val();
        } else {
            self.holds_peer.d.next = self.holds_peer.q.val() & !self.compared.q.val();
        }
        self.known.next = self.holds_peer.q.val() != 0;
        // (the target is the sender's slot when it is known)
        self.sequences.clock.next = self.clock.val();
        self.sequences.read_address.next = self.target_number.q.val();
        self.last_sequence.next = self.sequences.read_data.val();
        self.known_sequence.next = 0.into();
        if self.holds_peer.q.val() != 0 {
            self.known_sequence.next = self.sequences.read_data.val();
        }

        // The slot a take writes: the sender's, else the oldest; registered.
        self.next_target.next = self.holds_peer.q.val();
        if self.holds_peer.q.val() == 0 {
            for i in 0..self.ranks.len() {
                if self.ranks[i].q.val() == self.oldest_rank.val() {
                    self.next_target.next = self.slot_bit[i].val();
                }
            }
        }
        self.next_target_number.next = 0.into();
        self.next_target_rank.next = 0.into();
        for i in 0..self.ranks.len() {
            if self.next_target.val().get_bit(i) {
                self.next_target_number.next = self.slot_number[i].val();
                self.next_target_rank.next = self.ranks[i].q.val();
            }
        }
        self.target.d.next = self.next_target.val();
        self.target_number.d.next = self.next_target_number.val();
        self.target_rank.d.next = self.next_target_rank.val();

        // The take: the words, the valid bit, the ranks.
        self.addresses.write_enable.next = self.take.val();
        self.addresses.write_address.next = self.target_number.q.val();
        self.addresses.write_data.next = self.peer_ip.val();
        self.sequences.write_enable.next = self.take.val();
        self.sequences.write_address.next = self.target_number.q.val();
        self.sequences.write_data.next = self.take_sequence.val();
        if self.take.val() {
            self.valid.d.next = self.valid.q.val() | self.target.q.val();
            for i in 0..self.ranks.len() {
                if self.target.q.val().get_bit(i) {
                    self.ranks[i].d.next = 0.into();
                } else if self.ranks[i].q.val() < self.target_rank.q.val() {
                    self.ranks[i].d.next = self.ranks[i].q.val() + 1;
                }
            }
        }
        if self.reset.val() {
            self.valid.d.next = 0.into();
            self.holds_peer.d.next = 0.into();
            for i in 0..self.ranks.len() {
                self.ranks[i].d.next = self.initial_ranks[i].val();
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// The table as docs/control.md states it: hosts in the order they were taken, the one
    /// taken longest ago first; a new host replaces it when the table is full.
    #[derive(Default)]
    struct Model {
        hosts: Vec<(u32, u32)>,
    }

    impl Model {
        fn lookup(&self, ip: u32) -> Option<u32> {
            self.hosts.iter().find(|h| h.0 == ip).map(|h| h.1)
        }

        fn take(&mut self, ip: u32, sequence: u32) {
            if let Some(i) = self.hosts.iter().position(|h| h.0 == ip) {
                self.hosts.remove(i);
            } else if self.hosts.len() == HOST_SLOTS {
                self.hosts.remove(0);
            }
            self.hosts.push((ip, sequence));
        }
    }

    fn check(bench: &Bench<HostTable>, model: &Model, ip: u32, at: &str) {
        let want = model.lookup(ip);
        assert_eq!(bench.uut.known.val(), want.is_some(), "{ip:#x} known, {at}");
        if let Some(sequence) = want {
            assert_eq!(
                bench.uut.last_sequence.val().to_u32(),
                sequence,
                "{ip:#x} last sequence, {at}"
            );
        }
        assert_eq!(
            bench.uut.known_sequence.val().to_u32(),
            want.unwrap_or(0),
            "{ip:#x} known sequence, {at}"
        );
    }

    #[test]
    fn lookups_and_takes_follow_the_model() {
        let mut bench = Bench::new(HostTable::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(35);
        let mut model = Model::default();
        let mut evictions = 0;
        // six hosts for four slots, two of them differing in one half of the address only
        let pool = [
            0x0A00_0001u32,
            0x0A00_0002,
            0x0A01_0001,
            0xC0A8_0101,
            0xC0A8_0102,
            0x0A00_0003,
        ];
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for step in 0..600 {
            let ip = pool[rng.next_u64() as usize % pool.len()];
            bench.uut.peer_ip.next = u64::from(ip).into();
            // a random scan phase, then exactly the lookup's clocks
            bench.cycles(rng.next_u64() % 4);
            bench.cycles(LOOKUP_CLOCKS);
            check(&bench, &model, ip, &format!("step {step}"));
            if rng.chance(0.6) {
                // a new sequence number, or sometimes 0 or the top bit set
                let sequence = match rng.next_u64() % 4 {
                    0 => 0,
                    1 => 0x8000_0000 | rng.next_u64() as u32,
                    _ => rng.next_u64() as u32 & 0xFFFF,
                };
                bench.uut.take.next = true;
                bench.uut.take_sequence.next = u64::from(sequence).into();
                bench.cycle();
                bench.uut.take.next = false;
                if model.lookup(ip).is_none() && model.hosts.len() == HOST_SLOTS {
                    evictions += 1;
                }
                model.take(ip, sequence);
                bench.cycles(LOOKUP_CLOCKS);
                check(
                    &bench,
                    &model,
                    ip,
                    &format!("after the take at step {step}"),
                );
            }
            if step % 200 == 199 {
                bench.uut.reset.next = true;
                bench.cycle();
                bench.uut.reset.next = false;
                model = Model::default();
                bench.cycles(LOOKUP_CLOCKS);
                check(&bench, &model, ip, "after a reset");
            }
        }
        assert!(evictions > 20, "{evictions} takes replaced the oldest host");
    }

    #[test]
    fn a_host_is_found_in_any_slot_and_an_empty_table_knows_none() {
        let mut bench = Bench::new(HostTable::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut model = Model::default();
        // an address of all zeros holds_peer the power-up contents of no valid slot
        for ip in [0u32, 1, 2, 3, 4] {
            bench.uut.peer_ip.next = u64::from(ip).into();
            bench.cycles(LOOKUP_CLOCKS);
            check(&bench, &model, ip, "before its take");
            bench.uut.take.next = true;
            bench.uut.take_sequence.next = u64::from(100 + ip).into();
            bench.cycle();
            bench.uut.take.next = false;
            model.take(ip, 100 + ip);
        }
        // 0 was taken longest ago and is gone; 1..=4 are in the four slots
        for ip in [0u32, 1, 2, 3, 4] {
            bench.uut.peer_ip.next = u64::from(ip).into();
            bench.cycles(LOOKUP_CLOCKS);
            check(&bench, &model, ip, "after five takes");
        }
        assert_eq!(model.lookup(0), None);
    }
}
