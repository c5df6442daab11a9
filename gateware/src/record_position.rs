//! RecordPosition: where the record batcher is: the beat within the record coming in and
//! the records in the filling datagram, with the tests the batcher needs each kept in a
//! register (set and cleared as the counts move, so no compare is on the batcher's paths).
//!
//! A record is [`RECORD_LEN`] beats (port, flags, tick, cell bytes); a datagram holds at
//! most [`MAX_RECORDS`]. `advance` moves a beat; the record's last beat counts the record.
//! `clear` (the datagram closes) empties the datagram. Cost: 11 counter bits and 7 flags.

use crate::hdl::*;
use skinbox_protocol::datagram::MAX_RECORDS;
use skinbox_protocol::record::{field, RECORD_LEN};

/// Beat of a record that carries the tick's last byte.
pub const LAST_TICK_BEAT: usize = field::TICK_OFFSET.end - 1;

/// The beat and the record count of the record batcher.
#[derive(LogicBlock)]
pub struct RecordPosition {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: beat 0, no record.
    pub reset: Signal<In, Bit>,
    /// A beat of the record moves in.
    pub advance: Signal<In, Bit>,
    /// The filling datagram closes: no record in it.
    pub clear: Signal<In, Bit>,
    /// The next beat's index in its record.
    pub beat: Signal<Out, Bits<5>>,
    /// The next beat is a record's first.
    pub beat_zero: Signal<Out, Bit>,
    /// The next beat is the record's last tick byte.
    pub beat_at_last_tick: Signal<Out, Bit>,
    /// The next beat is the record's last.
    pub beat_last: Signal<Out, Bit>,
    /// Records in the filling datagram.
    pub fill_count: Signal<Out, Bits<6>>,
    /// It holds [`MAX_RECORDS`].
    pub fill_full: Signal<Out, Bit>,
    /// It holds one record less: the record coming in fills it.
    pub fill_at_last: Signal<Out, Bit>,
    /// It holds a record.
    pub fill_nonzero: Signal<Out, Bit>,
    last_tick_beat_less_one: Constant<Bits<5>>,
    record_last_beat_less_one: Constant<Bits<5>>,
    last_fill_less_one: Constant<Bits<6>>,
    beat_count: DFF<Bits<5>>,
    at_zero: DFF<Bit>,
    at_last_tick: DFF<Bit>,
    at_last: DFF<Bit>,
    count: DFF<Bits<6>>,
    full: DFF<Bit>,
    count_at_last: DFF<Bit>,
    nonzero: DFF<Bit>,
}

impl Default for RecordPosition {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            advance: Default::default(),
            clear: Default::default(),
            beat: Default::default(),
            beat_zero: Default::default(),
            beat_at_last_tick: Default::default(),
            beat_last: Default::default(),
            fill_count: Default::default(),
            fill_full: Default::default(),
            fill_at_last: Default::default(),
            fill_nonzero: Default::default(),
            last_tick_beat_less_one: Constant::new((LAST_TICK_BEAT as u64 - 1).into()),
            record_last_beat_less_one: Constant::new((RECORD_LEN as u64 - 2).into()),
            last_fill_less_one: Constant::new((MAX_RECORDS as u64 - 2).into()),
            beat_count: Default::default(),
            at_zero: Default::default(),
            at_last_tick: Default::default(),
            at_last: Default::default(),
            count: Default::default(),
            full: Default::default(),
            count_at_last: Default::default(),
            nonzero: Default::default(),
        }
    }
}

impl Logic for RecordPosition {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            beat_count,
            at_zero,
            at_last_tick,
            at_last,
            count,
            full,
            count_at_last,
            nonzero
        );
        if self.advance.val() {
            self.beat_count.d.next = self.beat_count.q.val() + 1;
            self.at_zero.d.next = false;
            self.at_last_tick.d.next =
                self.beat_count.q.val() == self.last_tick_beat_less_one.val();
            self.at_last.d.next = self.beat_count.q.val() == self.record_last_beat_less_one.val();
            if self.at_last.q.val() {
                self.beat_count.d.next = 0.into();
                self.at_zero.d.next = true;
                self.count.d.next = self.count.q.val() + 1;
                self.full.d.next = self.count_at_last.q.val();
                self.count_at_last.d.next = self.count.q.val() == self.last_fill_less_one.val();
                self.nonzero.d.next = true;
            }
        }
        if self.clear.val() {
            self.count.d.next = 0.into();
            self.full.d.next = false;
            self.count_at_last.d.next = false;
            self.nonzero.d.next = false;
        }
        if self.reset.val() {
            self.beat_count.d.next = 0.into();
            self.at_zero.d.next = true;
            self.at_last_tick.d.next = false;
            self.at_last.d.next = false;
            self.count.d.next = 0.into();
            self.full.d.next = false;
            self.count_at_last.d.next = false;
            self.nonzero.d.next = false;
        }
        self.beat.next = self.beat_count.q.val();
        self.beat_zero.next = self.at_zero.q.val();
        self.beat_at_last_tick.next = self.at_last_tick.q.val();
        self.beat_last.next = self.at_last.q.val();
        self.fill_count.next = self.count.q.val();
        self.fill_full.next = self.full.q.val();
        self.fill_at_last.next = self.count_at_last.q.val();
        self.fill_nonzero.next = self.nonzero.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Beats moved at random, datagrams closed at random (never in a clock a beat moves, as
    /// in the batcher): every output is the count written out here.
    #[test]
    fn beats_and_records_are_counted_with_their_flags() {
        let mut bench = Bench::new(RecordPosition::default(), |b| &mut b.clock);
        let mut rng = TestRng::new(0x2EC0);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let (mut beat, mut records) = (0usize, 0usize);
        for round in 0..200_000 {
            let r = rng.next_u64() % 100;
            // mostly beats; a close now and then, rarer once records are in
            let clear = r < 2 || (records == MAX_RECORDS && beat == 0 && r < 60);
            let advance = !clear && r < 90 && records < MAX_RECORDS || (!clear && beat != 0);
            bench.uut.advance.next = advance;
            bench.uut.clear.next = clear;
            bench.settle();
            let u = &bench.uut;
            let at = format!("round {round}: beat {beat}, records {records}");
            assert_eq!(u.beat.val().to_u64(), beat as u64, "{at}");
            assert_eq!(u.beat_zero.val(), beat == 0, "{at}");
            assert_eq!(u.beat_at_last_tick.val(), beat == LAST_TICK_BEAT, "{at}");
            assert_eq!(u.beat_last.val(), beat == RECORD_LEN - 1, "{at}");
            assert_eq!(u.fill_count.val().to_u64(), records as u64, "{at}");
            assert_eq!(u.fill_full.val(), records == MAX_RECORDS, "{at}");
            assert_eq!(u.fill_at_last.val(), records == MAX_RECORDS - 1, "{at}");
            assert_eq!(u.fill_nonzero.val(), records != 0, "{at}");
            if advance {
                beat += 1;
                if beat == RECORD_LEN {
                    beat = 0;
                    records += 1;
                }
            }
            if clear {
                records = 0;
            }
            bench.cycle();
        }
    }
}
