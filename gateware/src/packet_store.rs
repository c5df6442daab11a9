//! PacketStore: the ports' packet buffers and the reader that merges them into one record
//! stream: [`PortSlots`] (two slots per port in shared block RAM, written by a ring that
//! visits one port per clock) and [`RecordArbiter`] (a scan that grants one port at a
//! time and reads its packet out as a whole record, round robin). The slots tell the
//! reader which ports hold a packet and in which slot; the reader reads the slots' RAM and
//! frees a slot when its record is out. The tests here hold the two together to the
//! behaviour the rest of the box relies on: every good packet out once, in order per port,
//! whole-packet drops counted, the loss flag on the next record.

use crate::hdl::*;
use crate::port_slots::PortSlots;
pub use crate::port_slots::{
    group_onehot, visit_period, BANK_PORTS, GROUP_PORTS, MAX_PORTS, SLOTS, STORED_BEATS,
};
use crate::record_arbiter::RecordArbiter;
pub use crate::record_arbiter::RECORD_BEATS;
use crate::stream::{ByteStreamSink, ByteStreamSource};
pub use crate::stream_fifo::FIFO_DEPTH;

/// Packet buffers of N ports and their round-robin reader.
#[derive(LogicBlock)]
pub struct PacketStore {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset of the reader.
    pub reset: Signal<In, Bit>,
    /// Synchronous reset of the write side: empties every port and restarts the ring.
    pub port_reset: Signal<In, Bit>,
    /// Packets from the deframers, one stream per port (4 tick bytes, 20 cell bytes).
    pub ports: Vec<ByteStreamSink>,
    /// Records, port number first.
    pub records: ByteStreamSource,
    /// Per port, counter events, bit i = `skinbox_protocol::PortCounter` i (see
    /// [`PortSlots::events`]).
    pub events: Vec<Signal<Out, Bits<8>>>,
    slots: PortSlots,
    reader: RecordArbiter,
}

impl PacketStore {
    /// A store for `ports` ports (1 to 64).
    pub fn new(ports: usize) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "PacketStore: {ports} ports, must be 1 to {MAX_PORTS}"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            port_reset: Default::default(),
            ports: (0..ports).map(|_| Default::default()).collect(),
            records: Default::default(),
            events: (0..ports).map(|_| Default::default()).collect(),
            slots: PortSlots::new(ports),
            reader: RecordArbiter::new(ports),
        }
    }
}

impl Logic for PacketStore {
    #[hdl_gen]
    fn update(&mut self) {
        self.slots.clock.next = self.clock.val();
        self.slots.port_reset.next = self.port_reset.val();
        self.reader.clock.next = self.clock.val();
        self.reader.reset.next = self.reset.val();
        for i in 0..self.ports.len() {
            self.slots.ports[i].data.next = self.ports[i].data.val();
            self.slots.ports[i].valid.next = self.ports[i].valid.val();
            self.slots.ports[i].last.next = self.ports[i].last.val();
            self.slots.ports[i].error.next = self.ports[i].error.val();
            self.ports[i].ready.next = self.slots.ports[i].ready.val();
            self.events[i].next = self.slots.events[i].val();
        }
        self.reader.occupied_ports.next = self.slots.occupied_ports.val();
        self.reader.read_slots.next = self.slots.read_slots.val();
        self.slots.read_address.next = self.reader.read_address.val();
        for b in 0..self.reader.bank_data.len() {
            self.reader.bank_data[b].next = self.slots.bank_data[b].val();
        }
        self.slots.free_slot.next = self.reader.free_slot.val();
        self.slots.free_port.next = self.reader.free_port.val();
        self.records.valid.next = self.reader.records.valid.val();
        self.records.data.next = self.reader.records.data.val();
        self.records.last.next = self.reader.records.last.val();
        self.records.error.next = self.reader.records.error.val();
        self.reader.records.ready.next = self.records.ready.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;
    use std::collections::VecDeque;

    /// A packet a deframer offers: its 24 stored bytes, cut to `bytes.len()` beats and
    /// ended with `error` when it is rejected.
    #[derive(Clone, Debug, PartialEq)]
    struct Offer {
        bytes: Vec<u8>,
        error: bool,
    }

    fn good(port: usize, k: usize) -> Offer {
        Offer {
            bytes: (0..STORED_BEATS)
                .map(|i| (port * 53 + k * 31 + i) as u8)
                .collect(),
            error: false,
        }
    }

    fn rejected(port: usize, k: usize, beats: usize) -> Offer {
        let mut o = good(port, k);
        o.bytes.truncate(beats);
        o.error = true;
        o
    }

    /// A record as it leaves the store: port, flags, stored bytes.
    type Record = (u8, u8, Vec<u8>);

    struct Run {
        records: Vec<Record>,
        /// Clock of each record's first beat.
        record_clocks: Vec<u64>,
        drops: Vec<u32>,
    }

    /// Offers each port's packets beat by beat (a new beat `gap` clocks after the previous
    /// one moved, the stream contract: a beat stays offered until taken) while the record
    /// sink takes beats per `ready` from clock `read_after` on.
    fn run(
        queues: Vec<VecDeque<Offer>>,
        gap: u64,
        ready: &[bool],
        read_after: u64,
        clocks: u64,
    ) -> Run {
        let n = queues.len();
        let mut queues = queues;
        let mut bench = Bench::new(PacketStore::new(n), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.uut.port_reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        bench.uut.port_reset.next = false;
        let mut position = vec![0usize; n];
        let mut wait = vec![0u64; n];
        let mut beats: Vec<(u8, bool, u64)> = vec![];
        let mut drops = vec![0u32; n];
        for clock in 0..clocks {
            for p in 0..n {
                let beat = queues[p].front().filter(|_| wait[p] == 0).map(|o| {
                    (
                        o.bytes[position[p]],
                        position[p] + 1 == o.bytes.len(),
                        o.error,
                    )
                });
                let s = &mut bench.uut.ports[p];
                s.valid.next = beat.is_some();
                if let Some((d, last, error)) = beat {
                    s.data.next = u64::from(d).into();
                    s.last.next = last;
                    s.error.next = error && last;
                }
            }
            let r = clock >= read_after && ready[clock as usize % ready.len()];
            bench.uut.records.ready.next = r;
            bench.settle();
            let u = &bench.uut;
            for p in 0..n {
                wait[p] = wait[p].saturating_sub(1);
                if u.ports[p].ready.val() && u.ports[p].valid.val() {
                    position[p] += 1;
                    wait[p] = gap;
                    if position[p] == queues[p][0].bytes.len() {
                        queues[p].pop_front();
                        position[p] = 0;
                    }
                }
                let events = u.events[p].val().to_u8();
                assert_eq!(events & !2, 0, "only the dropped-overflow event");
                drops[p] += u32::from(events >> 1);
            }
            assert!(!u.records.error.val());
            if r && u.records.valid.val() {
                beats.push((u.records.data.val().to_u8(), u.records.last.val(), clock));
            }
            bench.cycle();
        }
        assert!(
            queues.iter().all(|q| q.is_empty()),
            "offers left: {:?}",
            queues.iter().map(|q| q.len()).collect::<Vec<_>>()
        );
        let mut records = vec![];
        let mut record_clocks = vec![];
        let mut current = vec![];
        for (d, last, clock) in beats {
            if current.is_empty() {
                record_clocks.push(clock);
            }
            current.push(d);
            if last {
                assert_eq!(current.len(), RECORD_BEATS, "record length: {current:?}");
                records.push((current[0], current[1], current[2..].to_vec()));
                current.clear();
            }
        }
        assert!(current.is_empty(), "unfinished record {current:?}");
        Run {
            records,
            record_clocks,
            drops,
        }
    }

    fn queues(n: usize, per_port: usize) -> Vec<VecDeque<Offer>> {
        (0..n)
            .map(|p| (0..per_port).map(|k| good(p, k)).collect())
            .collect()
    }

    #[test]
    fn every_port_busy_gets_one_grant_per_round() {
        for n in [1, 3, 8] {
            // beats every 12 clocks: each port has a packet ready in every round
            let out = run(
                queues(n, 4),
                12,
                &[true],
                0,
                4 * 24 * 13 + 60 * n as u64 + 200,
            );
            assert_eq!(out.records.len(), 4 * n, "{n} ports");
            assert_eq!(out.drops.iter().sum::<u32>(), 0);
            let mut seen = vec![0usize; n];
            for (i, (port, flags, bytes)) in out.records.iter().enumerate() {
                let p = *port as usize;
                assert_eq!(flags, &0);
                assert_eq!(
                    bytes,
                    &good(p, seen[p]).bytes,
                    "port {p} packet {}",
                    seen[p]
                );
                seen[p] += 1;
                if i > 0 {
                    // every port always has a packet: the grants go round in port order
                    let previous = out.records[i - 1].0 as usize;
                    assert_eq!(p, (previous + 1) % n, "record {i}: round robin");
                }
            }
        }
    }

    #[test]
    fn two_banks_carry_every_port() {
        // 40 ports: bank 0 holds 32, bank 1 holds 8; both rings run with period 32
        let n = 40;
        assert_eq!(visit_period(n), 32);
        let out = run(queues(n, 2), 0, &[true], 0, 5000);
        every_port_in_order(&out.records, n, 2);
    }

    /// Each of `n` ports' records are its `per_port` good packets, in order, unflagged.
    fn every_port_in_order(records: &[Record], n: usize, per_port: usize) {
        assert_eq!(records.len(), per_port * n);
        for p in 0..n {
            let got: Vec<(u8, &Vec<u8>)> = records
                .iter()
                .filter(|r| r.0 as usize == p)
                .map(|r| (r.1, &r.2))
                .collect();
            let want: Vec<Vec<u8>> = (0..per_port).map(|k| good(p, k).bytes).collect();
            assert_eq!(
                got,
                want.iter().map(|w| (0, w)).collect::<Vec<_>>(),
                "port {p}"
            );
        }
    }

    #[test]
    fn records_survive_any_backpressure() {
        let n = 5;
        for ready in [
            &[true, false][..],
            &[false, false, true],
            &[true, true, false, true, false, false, false, true],
        ] {
            let out = run(queues(n, 3), 30, ready, 0, 20_000);
            every_port_in_order(&out.records, n, 3);
        }
    }

    #[test]
    fn rejected_packets_vanish_and_flag_the_next() {
        let q: VecDeque<Offer> = vec![
            good(0, 1),
            rejected(0, 9, 7),
            good(0, 2),
            rejected(0, 10, STORED_BEATS),
            good(0, 3),
        ]
        .into();
        // the reader keeps up: nothing drops
        let out = run(vec![VecDeque::new(), q], 3, &[true], 0, 2000);
        let got: Vec<(u8, u8, Vec<u8>)> = out.records;
        assert_eq!(
            got,
            vec![
                (1, 0, good(0, 1).bytes),
                (1, 1, good(0, 2).bytes),
                (1, 1, good(0, 3).bytes)
            ]
        );
        assert_eq!(out.drops, vec![0, 0]);
    }

    #[test]
    fn overflow_drops_whole_packets_counts_them_and_flags_the_next() {
        // the reader sleeps until all five packets were offered: two fit, three drop
        let n = 3;
        let mut qs: Vec<VecDeque<Offer>> = vec![VecDeque::new(); n];
        qs[2] = (0..5).map(|k| good(2, k)).collect();
        let out = run(qs, 0, &[true], 5 * 24 * 3 + 20, 1200);
        let got: Vec<&Vec<u8>> = out.records.iter().map(|r| &r.2).collect();
        assert_eq!(got, vec![&good(2, 0).bytes, &good(2, 1).bytes]);
        assert_eq!(out.drops, vec![0, 0, 3]);

        // a packet after drops carries the loss flag
        let mut qs: Vec<VecDeque<Offer>> = vec![VecDeque::new(); n];
        qs[0] = (0..4).map(|k| good(0, k)).collect();
        // a beat 7 clocks after the previous one moved, taken at the next visit (every 3
        // clocks): a packet takes 24 x 9 = 216 clocks. Packet 2 starts at about 432 and
        // finds both slots full; the reader wakes at 540 and frees a slot before packet 3
        // starts at about 648
        let out = run(qs, 7, &[true], 540, 1500);
        assert_eq!(out.drops, vec![1, 0, 0]);
        let got: Vec<(u8, u8, Vec<u8>)> = out.records;
        assert_eq!(
            got,
            vec![
                (0, 0, good(0, 0).bytes),
                (0, 0, good(0, 1).bytes),
                (0, 1, good(0, 3).bytes)
            ]
        );
    }

    #[test]
    fn a_lone_port_is_found_wherever_the_scan_is() {
        let n = 8;
        let mut qs: Vec<VecDeque<Offer>> = vec![VecDeque::new(); n];
        qs[6] = (0..3).map(|k| good(6, k)).collect();
        qs[2] = (0..1).map(|k| good(2, k)).collect();
        let out = run(qs, 0, &[true], 0, 1500);
        let ports: Vec<u8> = out.records.iter().map(|r| r.0).collect();
        assert_eq!(ports, vec![2, 6, 6, 6]);
    }

    #[test]
    fn a_record_streams_one_beat_per_clock() {
        // one port, the reader free: the 26 beats of a record leave on 26 clocks in a row
        let out = run(queues(1, 2), 0, &[true], 0, 400);
        assert_eq!(out.records.len(), 2);
        let gap = out.record_clocks[1] - out.record_clocks[0];
        assert!(
            gap >= RECORD_BEATS as u64,
            "records overlap: {:?}",
            out.record_clocks
        );
    }

    #[test]
    #[should_panic(expected = "65 ports")]
    fn more_than_64_ports_is_refused() {
        PacketStore::new(65);
    }
}
