//! PacketStore: the ports' packet buffers and the reader that merges them into one record
//! stream: [`PortSlots`] (two slots per port in shared block RAM, written by the deframing
//! engine) and [`RecordArbiter`] (a scan that grants one port at a time and reads its
//! packet out as a whole record, round robin). The slots tell the reader which ports hold
//! a packet and in which slot; the reader reads the slots' RAM and frees a slot when its
//! record is out. The tests here hold the two together to the behaviour the rest of the
//! box relies on: every committed packet out once, in order per port, round robin.

use crate::geometry::MAX_PORTS;
use crate::hdl::*;
use crate::port_slots::PortSlots;
use crate::record_arbiter::RecordArbiter;
pub use crate::record_arbiter::RECORD_BEATS;
use crate::stream::ByteStreamSource;
pub use crate::stream_fifo::FIFO_DEPTH;

/// Packet buffers of N ports and their round-robin reader.
#[derive(LogicBlock)]
pub struct PacketStore {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset of the reader.
    pub reset: Signal<In, Bit>,
    /// Synchronous reset of the slots: empties every port.
    pub port_reset: Signal<In, Bit>,
    /// Write a word (the deframing engine's registers).
    pub write: Signal<In, Bit>,
    /// Port of the word.
    pub write_port: Signal<In, Bits<6>>,
    /// Slot of the word.
    pub write_slot: Signal<In, Bit>,
    /// Word in the slot: 0-3 start tick, 4-23 cell bytes.
    pub write_word: Signal<In, Bits<5>>,
    /// The word: byte and loss flag (bit 8).
    pub write_data: Signal<In, Bits<9>>,
    /// Bit i: port i's packet is complete in its write slot (one clock).
    pub commit_ports: Signal<In, Bits<64>>,
    /// Bit i: both of port i's slots hold a packet.
    pub full_ports: Signal<Out, Bits<64>>,
    /// Records, port number first.
    pub records: ByteStreamSource,
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
            write: Default::default(),
            write_port: Default::default(),
            write_slot: Default::default(),
            write_word: Default::default(),
            write_data: Default::default(),
            commit_ports: Default::default(),
            full_ports: Default::default(),
            records: Default::default(),
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
        self.slots.write.next = self.write.val();
        self.slots.write_port.next = self.write_port.val();
        self.slots.write_slot.next = self.write_slot.val();
        self.slots.write_word.next = self.write_word.val();
        self.slots.write_data.next = self.write_data.val();
        self.slots.commit_ports.next = self.commit_ports.val();
        self.full_ports.next = self.slots.full_ports.val();
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
    use crate::geometry::STORED_BEATS;
    use crate::testbench::Bench;
    use std::collections::VecDeque;

    fn good(port: usize, k: usize) -> Vec<u8> {
        (0..STORED_BEATS)
            .map(|i| (port * 53 + k * 31 + i) as u8)
            .collect()
    }

    /// A record as it leaves the store: port, flags, stored bytes.
    type Record = (u8, u8, Vec<u8>);

    struct Run {
        records: Vec<Record>,
        /// Clock of each record's first beat.
        record_clocks: Vec<u64>,
    }

    /// Writes each port's packets as the engine does (one word per clock, the ports in
    /// turn, a word of a port at most every `gap` clocks; a packet only into a free slot,
    /// committed with its last word) while the record sink takes beats per `ready`.
    fn run(queues: Vec<VecDeque<Vec<u8>>>, gap: u64, ready: &[bool], clocks: u64) -> Run {
        let n = queues.len();
        let mut queues = queues;
        let mut bench = Bench::new(PacketStore::new(n), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.uut.port_reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        bench.uut.port_reset.next = false;
        let mut position = vec![0usize; n];
        let mut slot = vec![0usize; n];
        let mut next_write = vec![0u64; n];
        let mut beats: Vec<(u8, bool, u64)> = vec![];
        for clock in 0..clocks {
            bench.settle();
            let p = clock as usize % n;
            let full = bench.uut.full_ports.val().get_bit(p);
            bench.uut.write.next = false;
            bench.uut.commit_ports.next = 0.into();
            if let Some(packet) = queues[p].front() {
                if clock >= next_write[p] && (position[p] > 0 || !full) {
                    let w = position[p];
                    bench.uut.write.next = true;
                    bench.uut.write_port.next = (p as u64).into();
                    bench.uut.write_slot.next = slot[p] == 1;
                    bench.uut.write_word.next = (w as u64).into();
                    bench.uut.write_data.next = u64::from(packet[w]).into();
                    position[p] += 1;
                    next_write[p] = clock + gap;
                    if position[p] == STORED_BEATS {
                        bench.uut.commit_ports.next = (1u64 << p).into();
                        position[p] = 0;
                        slot[p] ^= 1;
                        queues[p].pop_front();
                    }
                }
            }
            let r = ready[clock as usize % ready.len()];
            bench.uut.records.ready.next = r;
            bench.settle();
            let u = &bench.uut;
            assert!(!u.records.error.val());
            if r && u.records.valid.val() {
                beats.push((u.records.data.val().to_u8(), u.records.last.val(), clock));
            }
            bench.cycle();
        }
        assert!(
            queues.iter().all(|q| q.is_empty()),
            "packets left: {:?}",
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
        }
    }

    fn queues(n: usize, per_port: usize) -> Vec<VecDeque<Vec<u8>>> {
        (0..n)
            .map(|p| (0..per_port).map(|k| good(p, k)).collect())
            .collect()
    }

    #[test]
    fn every_port_busy_gets_one_grant_per_round() {
        for n in [1, 3, 8] {
            let out = run(queues(n, 4), 12, &[true], 4 * 24 * 13 * n as u64 + 400);
            assert_eq!(out.records.len(), 4 * n, "{n} ports");
            let mut seen = vec![0usize; n];
            for (i, (port, flags, bytes)) in out.records.iter().enumerate() {
                let p = *port as usize;
                assert_eq!(flags, &0);
                assert_eq!(bytes, &good(p, seen[p]), "port {p} packet {}", seen[p]);
                seen[p] += 1;
                if i > 0 && i < 3 * n {
                    // every port always has a packet: the grants go round in port order
                    let previous = out.records[i - 1].0 as usize;
                    assert_eq!(p, (previous + 1) % n, "record {i}: round robin");
                }
            }
        }
    }

    #[test]
    fn two_banks_carry_every_port() {
        // 40 ports: bank 0 holds 32, bank 1 holds 8
        let n = 40;
        let out = run(queues(n, 2), 0, &[true], 8000);
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
            let want: Vec<Vec<u8>> = (0..per_port).map(|k| good(p, k)).collect();
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
            let out = run(queues(n, 3), 30, ready, 20_000);
            every_port_in_order(&out.records, n, 3);
        }
    }

    #[test]
    fn a_lone_port_is_found_wherever_the_scan_is() {
        let n = 8;
        let mut qs: Vec<VecDeque<Vec<u8>>> = vec![VecDeque::new(); n];
        qs[6] = (0..3).map(|k| good(6, k)).collect();
        qs[2] = (0..1).map(|k| good(2, k)).collect();
        let out = run(qs, 0, &[true], 3000);
        let ports: Vec<u8> = out.records.iter().map(|r| r.0).collect();
        assert_eq!(ports, vec![2, 6, 6, 6]);
    }

    #[test]
    fn a_record_streams_one_beat_per_clock() {
        // one port, the reader free: the 26 beats of a record leave on 26 clocks in a row
        let out = run(queues(1, 2), 0, &[true], 400);
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
