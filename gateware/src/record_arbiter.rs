//! RecordArbiter: reads the ports' stored packets out of [`PortSlots`] as records, one whole
//! record at a time, round robin.
//!
//! A scan visits one port per clock while nothing is read; the occupancy bit of the scanned
//! port is registered (`hit`), and a hit grants that port the next clock. A grant is held
//! for the whole record (packet-atomic); the scan then resumes at the next port, so with
//! every port busy the grants cycle 0, 1, .., N-1 (starvation-free). A record is 26
//! issues: the port number, the flags byte (the stored loss flag), the 24 stored bytes;
//! each issue reads the RAM (two clocks) into a [`StreamFifo`], and an issue happens only
//! when the FIFO has room for everything in flight, so the record stream's `ready` reaches
//! nothing but the FIFO; the slot is freed a clock after the last issue. With `ready` high a
//! record takes 30 clocks plus the scan distance.
//!
//! Output records: the layout of `skinbox_protocol::record` with the absolute low 32 tick
//! bits where the datagram has its tick offset.
//!
//! [`PortSlots`]: crate::port_slots::PortSlots

use crate::block_ram::READ_LATENCY;
use crate::geometry::{MAX_PORTS, SLOT_BANK_ADDRESS_BITS, STORED_BEATS};
use crate::hdl::*;
use crate::stream::ByteStreamSource;
use crate::stream_fifo::{StreamFifo, FIFO_DEPTH};
use skinbox_protocol::record::{field, RECORD_LEN};

/// Beats of an output record: port, flags, tick and cell bytes.
pub const RECORD_BEATS: usize = 2 + STORED_BEATS;
const _: () = assert!(RECORD_BEATS == RECORD_LEN && field::PORT == 0 && field::FLAGS == 1);
// The read pipeline below is two registers deep.
const _: () = assert!(READ_LATENCY == 2);

/// Round-robin reader of N ports' slots.
#[derive(LogicBlock)]
pub struct RecordArbiter {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// Bit i: port i holds a packet.
    pub occupied_ports: Signal<In, Bits<64>>,
    /// Bit i: the slot of port i's next packet.
    pub read_slots: Signal<In, Bits<64>>,
    /// Word to read (port within its bank, slot, word).
    pub read_address: Signal<Out, Bits<SLOT_BANK_ADDRESS_BITS>>,
    /// Each bank's word, two clocks after the address.
    pub bank_data: Vec<Signal<In, Bits<9>>>,
    /// Free the slot just read of port `free_port`.
    pub free_slot: Signal<Out, Bit>,
    /// The port whose slot is freed.
    pub free_port: Signal<Out, Bits<6>>,
    /// Records, port number first.
    pub records: ByteStreamSource,
    fifo: StreamFifo,
    fifo_depth: Constant<Bits<3>>,
    last_issue: Constant<Bits<5>>,
    // bit 0 set: the first position of the scan
    bit_zero: Constant<Bits<64>>,
    scan_wrap: Constant<Bits<64>>,
    scan: DFF<Bits<6>>,
    scan_onehot: DFF<Bits<64>>,
    hit: DFF<Bit>,
    hit_port: DFF<Bits<6>>,
    hit_slot: DFF<Bit>,
    reading: DFF<Bit>,
    port: DFF<Bits<6>>,
    slot: DFF<Bit>,
    issue_index: DFF<Bits<5>>,
    word: DFF<Bits<5>>,
    issue: Signal<Local, Bit>,
    finishing: Signal<Local, Bit>,
    // the record's last issue was a clock ago: its slot is freed now
    freeing: DFF<Bit>,
    // the read pipeline: a read in flight, whether it is the record's port number, its
    // flags or its last beat
    read_1: DFF<Bit>,
    read_1_port: DFF<Bit>,
    read_1_flags: DFF<Bit>,
    read_1_last: DFF<Bit>,
    read_2: DFF<Bit>,
    read_2_port: DFF<Bit>,
    read_2_flags: DFF<Bit>,
    read_2_last: DFF<Bit>,
    read_word: Signal<Local, Bits<9>>,
    beat: Signal<Local, Bits<8>>,
}

impl RecordArbiter {
    /// A reader of `ports` ports (1 to 64).
    pub fn new(ports: usize) -> Self {
        assert!(
            (1..=MAX_PORTS).contains(&ports),
            "RecordArbiter: {ports} ports, must be 1 to {MAX_PORTS}"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            occupied_ports: Default::default(),
            read_slots: Default::default(),
            read_address: Default::default(),
            bank_data: (0..ports.div_ceil(32))
                .map(|_| Default::default())
                .collect(),
            free_slot: Default::default(),
            free_port: Default::default(),
            records: Default::default(),
            fifo: Default::default(),
            fifo_depth: Constant::new((FIFO_DEPTH as u64).into()),
            last_issue: Constant::new((RECORD_BEATS as u64 - 1).into()),
            bit_zero: Constant::new(1u64.into()),
            scan_wrap: Constant::new((1u64 << (ports - 1)).into()),
            scan: Default::default(),
            scan_onehot: Default::default(),
            hit: Default::default(),
            hit_port: Default::default(),
            hit_slot: Default::default(),
            reading: Default::default(),
            port: Default::default(),
            slot: Default::default(),
            issue_index: Default::default(),
            word: Default::default(),
            issue: Default::default(),
            finishing: Default::default(),
            freeing: Default::default(),
            read_1: Default::default(),
            read_1_port: Default::default(),
            read_1_flags: Default::default(),
            read_1_last: Default::default(),
            read_2: Default::default(),
            read_2_port: Default::default(),
            read_2_flags: Default::default(),
            read_2_last: Default::default(),
            read_word: Default::default(),
            beat: Default::default(),
        }
    }
}

impl Logic for RecordArbiter {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            scan,
            scan_onehot,
            hit,
            hit_port,
            hit_slot,
            reading,
            port,
            slot,
            issue_index,
            word,
            freeing,
            read_1,
            read_1_port,
            read_1_flags,
            read_1_last,
            read_2,
            read_2_port,
            read_2_flags,
            read_2_last
        );
        self.fifo.clock.next = self.clock.val();
        self.fifo.reset.next = self.reset.val();
        self.issue.next = self.reading.q.val()
            & ((bit_cast::<3, 1>(self.read_1.q.val().into())
                + bit_cast::<3, 1>(self.read_2.q.val().into())
                + self.fifo.count.val())
                < self.fifo_depth.val());
        self.finishing.next =
            self.issue.val() & (self.issue_index.q.val() == self.last_issue.val());
        self.hit.d.next = false;
        self.freeing.d.next = self.finishing.val();
        self.free_slot.next = self.freeing.q.val();
        // (`port` still holds the freed port: the next grant comes two clocks later)
        self.free_port.next = self.port.q.val();
        // while a slot is freed (a clock after the last issue) the scan waits, so it never
        // sees the freed port's occupancy before the free
        if !self.reading.q.val() & !self.freeing.q.val() {
            if self.hit.q.val() {
                // grant: the scan already stands on the next port and waits there
                self.reading.d.next = true;
                self.port.d.next = self.hit_port.q.val();
                self.slot.d.next = self.hit_slot.q.val();
                self.issue_index.d.next = 0.into();
                self.word.d.next = 0.into();
            } else {
                // (an AND and an OR tree of N bits, into registers)
                self.hit.d.next = (self.scan_onehot.q.val() & self.occupied_ports.val()) != 0;
                self.hit_port.d.next = self.scan.q.val();
                self.hit_slot.d.next = (self.scan_onehot.q.val() & self.read_slots.val()) != 0;
                if (self.scan_onehot.q.val() & self.scan_wrap.val()) != 0 {
                    self.scan.d.next = 0.into();
                    self.scan_onehot.d.next = self.bit_zero.val();
                } else {
                    self.scan.d.next = self.scan.q.val() + 1;
                    self.scan_onehot.d.next = self.scan_onehot.q.val() << 1;
                }
            }
        }
        if self.issue.val() {
            self.issue_index.d.next = self.issue_index.q.val() + 1;
            if self.issue_index.q.val() >= 2 {
                self.word.d.next = self.word.q.val() + 1;
            }
            if self.finishing.val() {
                self.reading.d.next = false;
            }
        }
        // (the port's bank bit drops out: each bank has its own RAM)
        self.read_address.next = (bit_cast::<SLOT_BANK_ADDRESS_BITS, 6>(self.port.q.val()) << 6)
            | (bit_cast::<SLOT_BANK_ADDRESS_BITS, 1>(self.slot.q.val().into()) << 5)
            | bit_cast::<SLOT_BANK_ADDRESS_BITS, 5>(self.word.q.val());
        self.read_1.d.next = self.issue.val();
        self.read_1_port.d.next = self.issue_index.q.val() == 0;
        self.read_1_flags.d.next = self.issue_index.q.val() == 1;
        self.read_1_last.d.next = self.finishing.val();
        self.read_2.d.next = self.read_1.q.val();
        self.read_2_port.d.next = self.read_1_port.q.val();
        self.read_2_flags.d.next = self.read_1_flags.q.val();
        self.read_2_last.d.next = self.read_1_last.q.val();

        // the word arriving from the RAM, and the beat it makes (`port` still holds the
        // record's port: the next grant comes after its last read arrived)
        self.read_word.next = self.bank_data[0].val();
        for b in 1..self.bank_data.len() {
            if self.port.q.val().get_bit(5) {
                self.read_word.next = self.bank_data[b].val();
            }
        }
        self.beat.next = self.read_word.val().get_bits::<8>(0);
        if self.read_2_port.q.val() {
            self.beat.next = bit_cast::<8, 6>(self.port.q.val());
        }
        if self.read_2_flags.q.val() {
            self.beat.next = bit_cast::<8, 1>(self.read_word.val().get_bit(8).into());
        }
        // the FIFO has room for every read in flight: the push never waits
        self.fifo.beats_in.valid.next = self.read_2.q.val();
        self.fifo.beats_in.data.next = self.beat.val();
        self.fifo.beats_in.last.next = self.read_2_last.q.val();
        self.fifo.beats_in.error.next = false;
        self.records.valid.next = self.fifo.beats_out.valid.val();
        self.records.data.next = self.fifo.beats_out.data.val();
        self.records.last.next = self.fifo.beats_out.last.val();
        self.records.error.next = self.fifo.beats_out.error.val();
        self.fifo.beats_out.ready.next = self.records.ready.val();
        if self.reset.val() {
            self.scan.d.next = 0.into();
            self.scan_onehot.d.next = self.bit_zero.val();
            self.hit.d.next = false;
            self.reading.d.next = false;
            self.freeing.d.next = false;
            self.read_1.d.next = false;
            self.read_2.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::port_slots::slot_address;
    use crate::testbench::{Bench, TestRng};
    use std::collections::{HashMap, VecDeque};

    /// A packet stored for port `port`: its loss flag and 24 bytes.
    fn stored(port: usize, k: usize) -> (bool, Vec<u8>) {
        (
            k % 3 == 1,
            (0..STORED_BEATS)
                .map(|i| (port * 41 + k * 7 + i) as u8)
                .collect(),
        )
    }

    /// Drives the arbiter from a model of the slots (each port's packets in a queue, the
    /// words in a RAM model with the block RAM's latency) under random `ready`; returns the
    /// records in the order they came out.
    fn run(ports: usize, per_port: &[usize], take_p: f64, seed: u64) -> Vec<(u8, u8, Vec<u8>)> {
        let mut rng = TestRng::new(seed);
        let mut bench = Bench::new(RecordArbiter::new(ports), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut queues: Vec<VecDeque<(usize, bool, Vec<u8>)>> = vec![VecDeque::new(); ports];
        let mut read_slot = vec![0usize; ports];
        let mut ram: HashMap<(usize, usize), u16> = HashMap::new();
        for (port, &n) in per_port.iter().enumerate() {
            for k in 0..n.min(SLOT_LIMIT) {
                let (loss, bytes) = stored(port, k);
                let slot = k % 2;
                for (w, b) in bytes.iter().enumerate() {
                    ram.insert(
                        (port / 32, slot_address(port, slot, w)),
                        u16::from(*b) | u16::from(loss) << 8,
                    );
                }
                queues[port].push_back((slot, loss, bytes));
            }
        }
        let total: usize = queues.iter().map(VecDeque::len).sum();
        let mut addresses = [0usize; 2];
        let (mut out, mut beats) = (vec![], vec![]);
        for _ in 0..200_000 {
            let take = rng.chance(take_p);
            let u = &mut bench.uut;
            let (mut occupied, mut slots) = (0u64, 0u64);
            for p in 0..ports {
                occupied |= u64::from(!queues[p].is_empty()) << p;
                slots |= (read_slot[p] as u64) << p;
            }
            u.occupied_ports.next = occupied.into();
            u.read_slots.next = slots.into();
            for b in 0..u.bank_data.len() {
                u.bank_data[b].next =
                    u64::from(*ram.get(&(b, addresses[0])).unwrap_or(&0x1EE)).into();
            }
            u.records.ready.next = take;
            bench.settle();
            let u = &bench.uut;
            if take && u.records.valid.val() {
                beats.push(u.records.data.val().to_u8());
                if u.records.last.val() {
                    assert_eq!(beats.len(), RECORD_BEATS);
                    out.push((beats[0], beats[1], beats.split_off(2)));
                    beats.clear();
                }
            }
            if u.free_slot.val() {
                let p = u.free_port.val().index();
                let (slot, ..) = queues[p].pop_front().expect("a free of an empty port");
                assert_eq!(slot, read_slot[p]);
                read_slot[p] ^= 1;
            }
            addresses = [addresses[1], u.read_address.val().index()];
            bench.cycle();
            if out.len() == total {
                break;
            }
        }
        assert_eq!(out.len(), total, "every record came out");
        assert!(queues.iter().all(VecDeque::is_empty), "every slot freed");
        out
    }

    // the model stores at most this many packets per port up front (no refill)
    const SLOT_LIMIT: usize = 2;

    #[test]
    fn every_busy_port_is_read_in_turn_as_whole_records() {
        for (seed, ports, take_p) in [(1, 3, 1.0), (2, 8, 0.6), (3, 40, 0.3), (4, 64, 0.9)] {
            let per_port = vec![2; ports];
            let out = run(ports, &per_port, take_p, seed);
            // two rounds in port order: all ports busy, the grants go round
            let order: Vec<usize> = out.iter().map(|r| r.0 as usize).collect();
            let expected: Vec<usize> = (0..2 * ports).map(|i| i % ports).collect();
            assert_eq!(order, expected, "seed {seed}");
            let mut k = vec![0; ports];
            for (port, flags, bytes) in &out {
                let p = *port as usize;
                let (loss, want) = stored(p, k[p]);
                assert_eq!(
                    (*flags, bytes),
                    (u8::from(loss), &want),
                    "port {p} packet {}",
                    k[p]
                );
                k[p] += 1;
            }
        }
    }

    #[test]
    fn lone_ports_are_found_wherever_the_scan_stands() {
        let mut per_port = vec![0; 8];
        per_port[6] = 2;
        per_port[2] = 1;
        let out = run(8, &per_port, 0.5, 7);
        let ports: Vec<u8> = out.iter().map(|r| r.0).collect();
        assert_eq!(ports, [2, 6, 6]);
    }
}
