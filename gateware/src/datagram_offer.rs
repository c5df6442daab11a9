//! DatagramOffer: offers a closed datagram's descriptor until it is taken, then streams the
//! body out of its buffer, and counts what it sent.
//!
//! `close` (one clock) takes the descriptor's fields (`close_*`); from the next clock the
//! descriptor is offered on `datagrams` (`valid` is a register). The take (valid & ready at
//! an edge) starts a [`BodyReader`] on the buffer (`read_address`, `read_data`: a block RAM
//! with its two-clock read), whose beats are the body. `free` (no descriptor offered, no
//! body being read: the buffer and the descriptor may be used again) is two registers
//! ANDed. A clock after the take, the datagram and its entries are counted.

use crate::body_reader::{BodyReader, BODY_ADDRESS_BITS};
use crate::hdl::*;
use crate::stream::{DatagramSource, BODY_SUM_BITS};

/// A datagram's descriptor offered, then its body read.
#[derive(LogicBlock, Default)]
pub struct DatagramOffer {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: nothing offered, the counts 0.
    pub reset: Signal<In, Bit>,
    /// One clock, while `free`: a datagram closed with the `close_*` fields.
    pub close: Signal<In, Bit>,
    /// The datagram's kind (steady).
    pub kind: Signal<In, Bits<8>>,
    /// The closing datagram's header flags.
    pub close_flags: Signal<In, Bits<8>>,
    /// The closing datagram's entry count.
    pub close_entry_count: Signal<In, Bits<16>>,
    /// The closing datagram's base tick.
    pub close_base_tick: Signal<In, Bits<64>>,
    /// The closing datagram's body length, bytes.
    pub close_body_len: Signal<In, Bits<BODY_ADDRESS_BITS>>,
    /// The closing datagram's body sum ([`BODY_SUM_BITS`]).
    pub close_body_sum: Signal<In, Bits<BODY_SUM_BITS>>,
    /// The datagram: its descriptor, then its body.
    pub datagrams: DatagramSource,
    /// The body's address in the buffer.
    pub read_address: Signal<Out, Bits<BODY_ADDRESS_BITS>>,
    /// The buffer's data, two clocks after `read_address`.
    pub read_data: Signal<In, Bits<8>>,
    /// Nothing is offered or being read.
    pub free: Signal<Out, Bit>,
    /// Datagrams taken since reset.
    pub datagrams_sent: Signal<Out, Bits<32>>,
    /// Entries of the datagrams taken since reset.
    pub entries_sent: Signal<Out, Bits<32>>,
    reader: BodyReader,
    pending: DFF<Bit>,
    flags: DFF<Bits<8>>,
    entry_count: DFF<Bits<16>>,
    base_tick: DFF<Bits<64>>,
    body_len: DFF<Bits<BODY_ADDRESS_BITS>>,
    body_sum: DFF<Bits<BODY_SUM_BITS>>,
    // the descriptor was taken a clock ago
    counting: DFF<Bit>,
    datagram_count: DFF<Bits<32>>,
    entry_total: DFF<Bits<32>>,
    taken: Signal<Local, Bit>,
}

impl Logic for DatagramOffer {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            pending,
            flags,
            entry_count,
            base_tick,
            body_len,
            body_sum,
            counting,
            datagram_count,
            entry_total
        );
        self.reader.clock.next = self.clock.val();
        self.reader.reset.next = self.reset.val();
        if self.close.val() {
            self.pending.d.next = true;
            self.flags.d.next = self.close_flags.val();
            self.entry_count.d.next = self.close_entry_count.val();
            self.base_tick.d.next = self.close_base_tick.val();
            self.body_len.d.next = self.close_body_len.val();
            self.body_sum.d.next = self.close_body_sum.val();
        }
        self.free.next = !self.pending.q.val() & !self.reader.busy.val();
        self.datagrams.valid.next = self.pending.q.val();
        self.datagrams.kind.next = self.kind.val();
        self.datagrams.flags.next = self.flags.q.val();
        self.datagrams.entry_count.next = self.entry_count.q.val();
        self.datagrams.base_tick.next = self.base_tick.q.val();
        self.datagrams.body_len.next = self.body_len.q.val();
        self.datagrams.body_sum.next = self.body_sum.q.val();
        self.taken.next = self.pending.q.val() & self.datagrams.ready.val();
        self.reader.start.next = self.taken.val();
        self.reader.length.next = self.body_len.q.val();
        if self.taken.val() {
            self.pending.d.next = false;
        }
        // counted a clock after the take (the entry count holds: no datagram closes while
        // the body is read), so the counters' enable comes from a register
        self.counting.d.next = self.taken.val();
        if self.counting.q.val() {
            self.datagram_count.d.next = self.datagram_count.q.val() + 1;
            self.entry_total.d.next =
                self.entry_total.q.val() + bit_cast::<32, 16>(self.entry_count.q.val());
        }
        self.read_address.next = self.reader.read_address.val();
        self.reader.read_data.next = self.read_data.val();
        self.datagrams.body.valid.next = self.reader.body.valid.val();
        self.datagrams.body.data.next = self.reader.body.data.val();
        self.datagrams.body.last.next = self.reader.body.last.val();
        self.datagrams.body.error.next = self.reader.body.error.val();
        self.reader.body.ready.next = self.datagrams.body.ready.val();
        self.datagrams_sent.next = self.datagram_count.q.val();
        self.entries_sent.next = self.entry_total.q.val();
        if self.reset.val() {
            self.pending.d.next = false;
            self.counting.d.next = false;
            self.datagram_count.d.next = 0.into();
            self.entry_total.d.next = 0.into();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::block_ram::READ_LATENCY;
    use crate::testbench::{Bench, TestRng};

    /// Closes datagrams of random lengths, takes them after random delays and reads their
    /// bodies with random back-pressure from a RAM model with the block RAM's read latency:
    /// every descriptor as closed, every body byte for byte, `free` exactly while nothing
    /// is offered or read, and the counts.
    #[test]
    fn datagrams_are_offered_read_and_counted() {
        let mut bench = Bench::new(DatagramOffer::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0x0FFE);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        bench.uut.kind.next = 7.into();
        let buffer: Vec<u8> = (0..2048).map(|_| rng.byte()).collect();
        // the addresses presented in the last clocks (the RAM answers READ_LATENCY later)
        let mut addresses = vec![0usize; READ_LATENCY as usize];
        let (mut datagrams, mut entries) = (0u64, 0u64);
        for round in 0..40 {
            assert!(bench.uut.free.val(), "free before round {round}");
            let len = 1 + rng.next_u64() % 300;
            let count = rng.next_u64() % 60;
            let (flags, tick, sum) = (rng.byte(), rng.next_u64(), rng.next_u64() as u32 & 0x1_FFFF);
            let u = &mut bench.uut;
            u.close.next = true;
            u.close_flags.next = u64::from(flags).into();
            u.close_entry_count.next = count.into();
            u.close_base_tick.next = tick.into();
            u.close_body_len.next = len.into();
            u.close_body_sum.next = u64::from(sum).into();
            bench.cycle();
            bench.uut.close.next = false;
            let mut body = Vec::new();
            let mut taken = false;
            let mut wait = rng.next_u64() % 5;
            for clock in 0..2000 {
                let u = &mut bench.uut;
                addresses.push(u.read_address.val().index());
                u.read_data.next = u64::from(buffer[addresses.remove(0)]).into();
                let take = !taken && wait == 0;
                wait = wait.saturating_sub(1);
                u.datagrams.ready.next = take;
                let ready = rng.chance(0.7);
                u.datagrams.body.ready.next = ready;
                bench.settle();
                let u = &bench.uut;
                assert!(!u.free.val(), "round {round}: busy at clock {clock}");
                if !taken {
                    assert!(u.datagrams.valid.val(), "round {round}: offered");
                    let d = &u.datagrams;
                    assert_eq!(d.kind.val().to_u64(), 7);
                    assert_eq!(d.flags.val().to_u64(), u64::from(flags));
                    assert_eq!(d.entry_count.val().to_u64(), count);
                    assert_eq!(d.base_tick.val().to_u64(), tick);
                    assert_eq!(d.body_len.val().to_u64(), len);
                    assert_eq!(d.body_sum.val().to_u64(), u64::from(sum));
                    assert!(!d.body.valid.val(), "no body before the take");
                }
                let beat = u.datagrams.body.valid.val() && ready;
                let last = u.datagrams.body.last.val();
                if beat {
                    body.push(u.datagrams.body.data.val().to_u64() as u8);
                }
                taken |= take;
                bench.cycle();
                if beat && last {
                    break;
                }
            }
            assert_eq!(body, buffer[..len as usize], "round {round}: the body");
            bench.uut.datagrams.body.ready.next = false;
            bench.settle();
            assert!(
                bench.uut.free.val(),
                "free after the last beat, round {round}"
            );
            datagrams += 1;
            entries += count;
            bench.cycle();
            assert_eq!(bench.uut.datagrams_sent.val().to_u64(), datagrams);
            assert_eq!(bench.uut.entries_sent.val().to_u64(), entries);
        }
    }
}
