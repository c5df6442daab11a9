//! RegisterSlice: cuts a byte stream's combinational paths, both ways, at full throughput.
//!
//! A two-entry skid buffer: the output beat comes from a register (`valid`, `data`, `last`,
//! `error` are flip-flop outputs) and the input's `ready` is a flip-flop output too (room
//! in the skid register), so neither `valid` nor `ready` passes through combinationally.
//! A beat offered while the output stalls goes to the skid register and leaves first when
//! the output moves again; one beat per clock flows when the consumer is always ready.
//! Latency: one clock. Cost: two beats of registers.

use crate::stream::{ByteStreamSink, ByteStreamSource};
use rust_hdl::prelude::*;

/// Two-entry register slice on a byte stream.
#[derive(LogicBlock, Default)]
pub struct RegisterSlice {
    /// The clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: both entries empty.
    pub reset: Signal<In, Bit>,
    /// Beats in.
    pub sink: ByteStreamSink,
    /// Beats out, one clock later (or as the output moves).
    pub source: ByteStreamSource,
    main_valid: DFF<Bit>,
    main_data: DFF<Bits<8>>,
    main_last: DFF<Bit>,
    main_error: DFF<Bit>,
    skid_valid: DFF<Bit>,
    skid_data: DFF<Bits<8>>,
    skid_last: DFF<Bit>,
    skid_error: DFF<Bit>,
    take_in: Signal<Local, Bit>,
    main_free: Signal<Local, Bit>,
}

impl Logic for RegisterSlice {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self, clock, main_valid, main_data, main_last, main_error, skid_valid, skid_data,
            skid_last, skid_error
        );
        self.sink.ready.next = !self.skid_valid.q.val();
        self.take_in.next = self.sink.valid.val() & !self.skid_valid.q.val();
        self.main_free.next = !self.main_valid.q.val() | self.source.ready.val();
        if self.main_free.val() {
            if self.skid_valid.q.val() {
                self.main_valid.d.next = true;
                self.main_data.d.next = self.skid_data.q.val();
                self.main_last.d.next = self.skid_last.q.val();
                self.main_error.d.next = self.skid_error.q.val();
                self.skid_valid.d.next = false;
            } else {
                self.main_valid.d.next = self.take_in.val();
                self.main_data.d.next = self.sink.data.val();
                self.main_last.d.next = self.sink.last.val();
                self.main_error.d.next = self.sink.error.val();
            }
        } else if self.take_in.val() {
            self.skid_valid.d.next = true;
            self.skid_data.d.next = self.sink.data.val();
            self.skid_last.d.next = self.sink.last.val();
            self.skid_error.d.next = self.sink.error.val();
        }
        if self.reset.val() {
            self.main_valid.d.next = false;
            self.skid_valid.d.next = false;
        }
        self.source.valid.next = self.main_valid.q.val();
        self.source.data.next = self.main_data.q.val();
        self.source.last.next = self.main_last.q.val();
        self.source.error.next = self.main_error.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    /// Offers `beats` in order (offering per the `offer` pattern, holding an offered beat
    /// until it moves), takes output per the `take` pattern; returns what came out and the
    /// clocks it took.
    fn run(beats: &[(u8, bool)], offer: &[bool], take: &[bool]) -> (Vec<(u8, bool)>, u64) {
        let mut bench = Bench::new(RegisterSlice::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        let (mut next, mut offered, mut out) = (0, false, vec![]);
        let mut clock = 0usize;
        while out.len() < beats.len() {
            assert!(clock < 100_000, "stuck after {out:?}");
            offered |= offer[clock % offer.len()] && next < beats.len();
            let u = &mut bench.uut;
            u.sink.valid.next = offered;
            if let Some((d, last)) = beats.get(next) {
                u.sink.data.next = u64::from(*d).into();
                u.sink.last.next = *last;
            }
            u.sink.error.next = false;
            u.source.ready.next = take[clock % take.len()];
            bench.settle();
            let u = &bench.uut;
            if u.sink.valid.val() && u.sink.ready.val() {
                next += 1;
                offered = false;
            }
            if u.source.valid.val() && u.source.ready.val() {
                out.push((u.source.data.val().to_u8(), u.source.last.val()));
            }
            bench.cycle();
            clock += 1;
        }
        (out, clock as u64)
    }

    fn beats(n: usize) -> Vec<(u8, bool)> {
        (0..n).map(|i| ((i * 37 + 5) as u8, i % 7 == 6)).collect()
    }

    #[test]
    fn passes_one_beat_per_clock_with_one_clock_of_latency() {
        let b = beats(200);
        let (out, clocks) = run(&b, &[true], &[true]);
        assert_eq!(out, b);
        assert_eq!(clocks, 201, "one clock of latency, then one beat per clock");
    }

    #[test]
    fn keeps_order_and_loses_nothing_under_any_stall_pattern() {
        let b = beats(300);
        let patterns: [&[bool]; 5] = [
            &[true],
            &[true, false],
            &[false, false, true],
            &[true, true, true, false, true, false, false],
            &[false, true, true, true, true, true, true, true, true, false],
        ];
        for offer in patterns {
            for take in patterns {
                let (out, _) = run(&b, offer, take);
                assert_eq!(out, b, "offer {offer:?} take {take:?}");
            }
        }
    }

    #[test]
    fn ready_and_valid_do_not_follow_the_other_side_in_the_same_clock() {
        let mut bench = Bench::new(RegisterSlice::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        // fill both entries with the output stalled
        bench.uut.source.ready.next = false;
        bench.uut.sink.valid.next = true;
        bench.cycles(2);
        bench.uut.sink.valid.next = false;
        bench.settle();
        assert!(!bench.uut.sink.ready.val(), "full: not ready");
        // the consumer becomes ready: the input's ready changes only after the edge
        bench.uut.source.ready.next = true;
        bench.settle();
        assert!(!bench.uut.sink.ready.val(), "ready is registered");
        bench.cycle();
        assert!(bench.uut.sink.ready.val());
        // an offered beat does not appear at the output before the edge
        let mut bench = Bench::new(RegisterSlice::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        bench.uut.sink.valid.next = true;
        bench.uut.source.ready.next = true;
        bench.settle();
        assert!(!bench.uut.source.valid.val(), "valid is registered");
        bench.cycle();
        assert!(bench.uut.source.valid.val());
    }
}
