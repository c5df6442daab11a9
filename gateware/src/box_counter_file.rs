//! BoxCounterFile: the box counters (`skinbox_protocol::box_counters::BoxCounter`) as
//! 32-bit words in block RAM.
//!
//! Every received frame raises `count` for one clock with its fate in `counter` (a
//! `BoxCounter` index other than `FramesReceived`); the file adds one to
//! `FramesReceived` and to that counter, each an increment of a [`CountingRam`] of 32
//! counters with two read ports (the reporter's and the reply builder's):
//! `FramesReceived` is offered in the clock of `count`, the fate's counter a clock later,
//! and each is written [`INCREMENT_WRITE_EDGE`] edges after it is offered.
//!
//! Limit: the last write of a count comes four clocks after `count`, so counts must be at
//! least [`COUNT_SPACING`] clocks apart (a received frame takes at least 72 clocks, so
//! the receive path needs at most one per frame). A count with `counter` 0
//! (`FramesReceived`) adds one to it, not two. After reset the file first clears
//! its RAMs ([`CLEAR_CLOCKS`] clocks) with `ready` low; counts in that time are lost.

use crate::counting_ram::{clear_clocks, CountingRam, INCREMENT_WRITE_EDGE};
use crate::hdl::*;
use skinbox_protocol::box_counters::BoxCounter;

/// Counters in the file (`BoxCounter::ALL`).
pub const COUNTERS: usize = BoxCounter::ALL.len();
/// Clocks the file spends clearing its memories after reset (`ready` low).
pub const CLEAR_CLOCKS: u64 = clear_clocks(ADDRESS_BITS);
/// Address bits of the file (`BoxCounter` indices).
pub const ADDRESS_BITS: usize = 5;
/// Clocks from a `count` (high in clock c) to the first clock whose read address sees
/// `FramesReceived` counted: read in clock c, written at the edge ending clock c + 3.
pub const FRAMES_RECEIVED_VISIBLE_AFTER: u64 = INCREMENT_WRITE_EDGE;
/// As [`FRAMES_RECEIVED_VISIBLE_AFTER`], for the fate's counter (read a clock later).
pub const FATE_VISIBLE_AFTER: u64 = INCREMENT_WRITE_EDGE + 1;

const _: () = assert!(COUNTERS <= 1 << ADDRESS_BITS);

/// Fewest clocks between two counts (the read-modify-writes of one count must be over
/// before the next reads).
pub const COUNT_SPACING: u64 = 5;

/// The box counters, counted by fate, with two read ports.
#[derive(LogicBlock)]
pub struct BoxCounterFile {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: clears every counter.
    pub reset: Signal<In, Bit>,
    /// One clock per received frame: count it in `FramesReceived` and in `counter`.
    pub count: Signal<In, Bit>,
    /// The frame's fate: a `BoxCounter` index, not `FramesReceived` (0).
    pub counter: Signal<In, Bits<5>>,
    /// Counter read by the status reporter (`BoxCounter` index).
    pub reporter_address: Signal<In, Bits<5>>,
    /// The counter at `reporter_address` two clocks ago.
    pub reporter_data: Signal<Out, Bits<32>>,
    /// Counter read by the reply builder (`BoxCounter` index).
    pub reply_address: Signal<In, Bits<5>>,
    /// The counter at `reply_address` two clocks ago.
    pub reply_data: Signal<Out, Bits<32>>,
    /// Counting: the clearing after reset is over.
    pub ready: Signal<Out, Bit>,
    // the fate's increment is offered a clock after the count
    fate_read: DFF<Bit>,
    fate_address: DFF<Bits<5>>,
    counters: CountingRam<ADDRESS_BITS>,
}

impl Default for BoxCounterFile {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            count: Default::default(),
            counter: Default::default(),
            reporter_address: Default::default(),
            reporter_data: Default::default(),
            reply_address: Default::default(),
            reply_data: Default::default(),
            ready: Default::default(),
            fate_read: Default::default(),
            fate_address: Default::default(),
            counters: CountingRam::new(2),
        }
    }
}

impl Logic for BoxCounterFile {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, fate_read, fate_address);
        self.counters.clock.next = self.clock.val();
        self.counters.reset.next = self.reset.val();
        // FramesReceived is offered in the clock of the count, the fate's counter a clock
        // later.
        self.fate_read.d.next = self.count.val() & self.counters.ready.val();
        self.fate_address.d.next = self.counter.val();
        self.counters.increment.next = self.count.val() | self.fate_read.q.val();
        self.counters.increment_address.next = 0.into();
        if self.fate_read.q.val() {
            self.counters.increment_address.next = self.fate_address.q.val();
        }
        self.counters.read_address[0].next = self.reporter_address.val();
        self.reporter_data.next = self.counters.read_data[0].val();
        self.counters.read_address[1].next = self.reply_address.val();
        self.reply_data.next = self.counters.read_data[1].val();
        self.ready.next = self.counters.ready.val();
        if self.reset.val() {
            self.fate_read.d.next = false;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::block_ram::READ_LATENCY;
    use crate::testbench::{Bench, TestRng};
    use std::collections::HashMap;

    fn reset(bench: &mut Bench<BoxCounterFile>) {
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let start = bench.cycles;
        while !bench.uut.ready.val() {
            bench.cycle();
        }
        assert_eq!(
            bench.cycles - start,
            CLEAR_CLOCKS,
            "clearing takes 32 clocks"
        );
    }

    /// Both read ports, each at a different counter, two clocks after the address.
    fn read_both(bench: &mut Bench<BoxCounterFile>, reporter: usize, reply: usize) -> (u32, u32) {
        bench.uut.reporter_address.next = (reporter as u64).into();
        bench.uut.reply_address.next = (reply as u64).into();
        bench.cycles(2);
        (
            bench.uut.reporter_data.val().to_u32(),
            bench.uut.reply_data.val().to_u32(),
        )
    }

    #[test]
    fn counts_random_fates_while_both_ports_read() {
        let mut bench = Bench::new(BoxCounterFile::default(), |b| &mut b.clock);
        reset(&mut bench);
        let mut rng = TestRng::new(17);
        let mut expected: HashMap<usize, u32> = HashMap::new();
        let mut gap = 0;
        for clock in 0..40_000u64 {
            // the read ports sweep all the time; counting must not care
            bench.uut.reporter_address.next = (clock % COUNTERS as u64).into();
            bench.uut.reply_address.next = ((clock * 7) % COUNTERS as u64).into();
            let count = gap == 0;
            if count {
                let fate = 1 + (rng.next_u64() % (COUNTERS as u64 - 1)) as usize;
                *expected.entry(fate).or_default() += 1;
                *expected
                    .entry(BoxCounter::FramesReceived as usize)
                    .or_default() += 1;
                bench.uut.counter.next = (fate as u64).into();
                gap = COUNT_SPACING - 1 + rng.next_u64() % 12;
            } else {
                gap -= 1;
                bench.uut.counter.next = (rng.next_u64() % 32).into();
            }
            bench.uut.count.next = count;
            bench.cycle();
        }
        bench.uut.count.next = false;
        bench.cycles(8);
        let frames = expected[&(BoxCounter::FramesReceived as usize)];
        assert!(frames > 2_000, "{frames} counts");
        for c in 0..COUNTERS {
            let want = expected.get(&c).copied().unwrap_or(0);
            let (reporter, reply) = read_both(&mut bench, c, COUNTERS - 1 - c);
            assert_eq!(reporter, want, "counter {c} on the reporter port");
            let other = expected.get(&(COUNTERS - 1 - c)).copied().unwrap_or(0);
            assert_eq!(
                reply,
                other,
                "counter {} on the reply port",
                COUNTERS - 1 - c
            );
        }
    }

    /// The first clock whose read address sees a count is the one the reference model
    /// uses: read data comes two clocks after its address.
    #[test]
    fn a_count_is_visible_after_the_named_clocks() {
        for (counter, after) in [
            (BoxCounter::FramesReceived, FRAMES_RECEIVED_VISIBLE_AFTER),
            (BoxCounter::BadFcs, FATE_VISIBLE_AFTER),
        ] {
            let mut bench = Bench::new(BoxCounterFile::default(), |b| &mut b.clock);
            reset(&mut bench);
            let mut first = None;
            for clock in 0..16u64 {
                bench.uut.count.next = clock == 0;
                bench.uut.counter.next = (BoxCounter::BadFcs as u64).into();
                bench.uut.reporter_address.next = (counter as u64).into();
                bench.cycle();
                // after this clock's edge: the data of the next clock, which answers the
                // address of READ_LATENCY clocks before it
                if first.is_none() && bench.uut.reporter_data.val().to_u64() == 1 {
                    first = Some(clock + 1 - READ_LATENCY);
                }
            }
            assert_eq!(first, Some(after), "{counter:?}");
        }
    }

    #[test]
    fn counts_at_the_closest_spacing() {
        let mut bench = Bench::new(BoxCounterFile::default(), |b| &mut b.clock);
        reset(&mut bench);
        let fates = [
            BoxCounter::BadFcs,
            BoxCounter::BadFcs,
            BoxCounter::ReplyBusy,
            BoxCounter::CommandsAccepted,
            BoxCounter::BadFcs,
        ];
        for fate in fates {
            bench.uut.count.next = true;
            bench.uut.counter.next = (fate as u64).into();
            bench.cycle();
            bench.uut.count.next = false;
            bench.cycles(COUNT_SPACING - 1);
        }
        bench.cycles(8);
        let counts = [
            (BoxCounter::FramesReceived, 5),
            (BoxCounter::BadFcs, 3),
            (BoxCounter::ReplyBusy, 1),
            (BoxCounter::CommandsAccepted, 1),
            (BoxCounter::NotForUs, 0),
        ];
        for (counter, want) in counts {
            let (reporter, reply) = read_both(&mut bench, counter as usize, counter as usize);
            assert_eq!((reporter, reply), (want, want), "{counter:?}");
        }
    }

    #[test]
    fn reset_clears_the_counters() {
        let mut bench = Bench::new(BoxCounterFile::default(), |b| &mut b.clock);
        reset(&mut bench);
        for _ in 0..3 {
            bench.uut.count.next = true;
            bench.uut.counter.next = (BoxCounter::NotForUs as u64).into();
            bench.cycle();
            bench.uut.count.next = false;
            bench.cycles(10);
        }
        let notforus = BoxCounter::NotForUs as usize;
        assert_eq!(read_both(&mut bench, 0, notforus), (3, 3));
        reset(&mut bench);
        assert_eq!(read_both(&mut bench, 0, notforus), (0, 0));
        for c in 0..COUNTERS {
            assert_eq!(read_both(&mut bench, c, c), (0, 0), "counter {c}");
        }
    }

    #[test]
    fn verilog_lints_clean() {
        let mut uut = BoxCounterFile::default();
        uut.connect_all();
        let text = generate_verilog(&uut);
        let dir = std::env::temp_dir().join(format!(
            "skinbox-lint-box-counter-file-{}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&text, &dir).unwrap_or_else(|e| panic!("{e}"));
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}
