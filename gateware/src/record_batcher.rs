//! RecordBatcher: batches records into records datagrams.
//!
//! Records arrive as 26-beat stream packets from the packet store (port, flags, the low 32 bits
//! of the start tick, 20 cell bytes). The framer writes them into one of two 2 KB payload
//! buffers: the first record of a datagram sets its base tick (the full 64-bit tick,
//! rebuilt from the current time), every record's tick is rewritten as a signed offset
//! from it (the input pauses 4 clocks for that), and the ones'-complement sum of the body
//! grows with every byte. A datagram closes when it holds 55 records (1454 bytes) or when
//! its first record has waited `flush_timeout_ticks` (one clock later, as the deadline test
//! is registered, and after a record on its way in is complete); its descriptor is then
//! offered on `datagrams` and, once taken, its body streams out of its buffer
//! ([`BodyReader`]) while the other buffer fills (double buffering). A datagram due to
//! close takes no more records: while the other buffer is still being read the input is
//! not ready and records wait upstream, none is lost here.

use crate::batch_close::BatchClose;
use crate::block_ram::BlockRam;
use crate::datagram_offer::DatagramOffer;
use crate::flush_deadline::FlushDeadline;
use crate::hdl::*;
use crate::payload_writer::PayloadWriter;
use crate::record_position::RecordPosition;
use crate::stream::{ByteStreamSink, DatagramSource};
use skinbox_protocol::datagram::{DatagramKind, FLAG_FLUSH_TIMEOUT};

/// Batches records into datagrams.
#[derive(LogicBlock)]
pub struct RecordBatcher {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// Records from the packet store.
    pub records: ByteStreamSink,
    /// Box time.
    pub tick: Signal<In, Bits<64>>,
    /// Flush timeout in ticks, 1 to 2^31 - 1 (run-time configuration): a datagram whose
    /// first record is seen two clocks after a change or later closes after the new one.
    pub flush_timeout_ticks: Signal<In, Bits<32>>,
    /// The records datagrams.
    pub datagrams: DatagramSource,
    /// Records datagrams taken since reset.
    pub datagrams_sent: Signal<Out, Bits<32>>,
    /// Records taken since reset.
    pub records_sent: Signal<Out, Bits<32>>,
    // the closed datagram: its descriptor until taken, then its body
    offer: DatagramOffer,
    memory: BlockRam<8, 12>,
    records_kind: Constant<Bits<8>>,
    flush_timeout_flag: Constant<Bits<8>>,
    fill_buffer: DFF<Bit>,
    // the beat within the record and the records in the filling datagram, with their tests
    position: RecordPosition,
    // the payload's write port, offset and sum
    payload: PayloadWriter,
    // the base tick and the flush deadline of the filling datagram
    deadline: FlushDeadline,
    // the first record's age (now - its tick, low 32 bits), for the base tick and the
    // deadline, which are set a clock later (off the accept path)
    first_age: DFF<Bits<32>>,
    first_seen: DFF<Bit>,
    // offset_left == 0, kept in a register
    offset_idle: DFF<Bit>,
    tick_low: DFF<Bits<32>>,
    offset_bytes: DFF<Bits<32>>,
    offset_left: DFF<Bits<3>>,
    record_tick: Signal<Local, Bits<32>>,
    write: Signal<Local, Bit>,
    write_data: Signal<Local, Bits<8>>,
    // a datagram is due to close (full, or its time is up) at a record boundary
    close: BatchClose,
    can_close: Signal<Local, Bit>,
    accept: Signal<Local, Bit>,
}

impl Default for RecordBatcher {
    fn default() -> Self {
        Self::new()
    }
}

impl RecordBatcher {
    /// A batcher that closes a datagram `flush_timeout_ticks` (its input) after its first
    /// record's tick.
    pub fn new() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            records: Default::default(),
            tick: Default::default(),
            flush_timeout_ticks: Default::default(),
            datagrams: Default::default(),
            datagrams_sent: Default::default(),
            records_sent: Default::default(),
            offer: Default::default(),
            deadline: Default::default(),
            memory: Default::default(),
            records_kind: Constant::new((DatagramKind::Records as u64).into()),
            flush_timeout_flag: Constant::new(u64::from(FLAG_FLUSH_TIMEOUT).into()),
            fill_buffer: Default::default(),
            position: Default::default(),
            payload: Default::default(),
            first_age: Default::default(),
            first_seen: Default::default(),
            offset_idle: Default::default(),
            tick_low: Default::default(),
            offset_bytes: Default::default(),
            offset_left: Default::default(),
            record_tick: Default::default(),
            write: Default::default(),
            write_data: Default::default(),
            close: Default::default(),
            can_close: Default::default(),
            accept: Default::default(),
        }
    }
}

// Record beats: 0 port, 1 flags, 2..=5 tick (not written; replaced by the 4 offset bytes),
// 6..=25 cell bytes.
impl Logic for RecordBatcher {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            fill_buffer,
            first_age,
            first_seen,
            offset_idle,
            tick_low,
            offset_bytes,
            offset_left
        );
        self.offer.clock.next = self.clock.val();
        self.offer.reset.next = self.reset.val();
        self.memory.clock.next = self.clock.val();

        // The first record's base tick and its flush deadline, a clock after its tick was
        // complete.
        self.deadline.clock.next = self.clock.val();
        self.deadline.tick.next = self.tick.val();
        self.deadline.flush_timeout_ticks.next = self.flush_timeout_ticks.val();
        self.deadline.first_seen.next = self.first_seen.q.val();
        self.deadline.first_age.next = self.first_age.q.val();
        // Close the filling datagram at a record boundary when full or due (`close_due`,
        // set at the end from the tests of beat, offset_left, fill_count and the deadline,
        // each set and cleared by the events that change what it tests, below).
        self.can_close.next = self.offer.free.val();
        // No beat moves while a datagram is due to close: in the clock it closes (the beat
        // would land in the old buffer) and while it waits for the other buffer (a full one
        // and one whose time is up alike). Whether the other buffer is free stays off the
        // input's ready.
        self.accept.next = self.offset_idle.q.val() & !self.close.due.val();
        self.records.ready.next = self.accept.val();

        // Write one byte per clock: offset bytes while they are pending, else stream beats.
        self.position.clock.next = self.clock.val();
        self.position.reset.next = self.reset.val();
        self.position.advance.next = false;
        self.write.next = false;
        self.write_data.next = self.records.data.val();
        self.record_tick.next =
            (self.tick_low.q.val() << 8) | bit_cast::<32, 8>(self.records.data.val());
        if !self.offset_idle.q.val() {
            self.write.next = true;
            self.write_data.next = self.offset_bytes.q.val().get_bits::<8>(24);
            self.offset_bytes.d.next = self.offset_bytes.q.val() << 8;
            self.offset_left.d.next = self.offset_left.q.val() - 1;
            self.offset_idle.d.next = self.offset_left.q.val() == 1;
        } else if self.records.valid.val() & self.accept.val() {
            self.position.advance.next = true;
            // beats 2..=5 (the tick bytes), from the beat's bits: 0b000_1x or 0b001_0x
            if (self.position.beat.val().get_bits::<2>(3) == 0)
                & (self.position.beat.val().get_bit(2) != self.position.beat.val().get_bit(1))
            {
                self.tick_low.d.next = self.record_tick.val();
            } else {
                self.write.next = true;
            }
            if self.position.beat_at_last_tick.val() {
                self.offset_left.d.next = 4.into();
                self.offset_idle.d.next = false;
            }
        }
        // The tick of a record is complete at its beat 5: the first record's age (its tick
        // is the base, rebuilt to 64 bits from now) or a later record's offset is taken in
        // every clock in which beat 5 is the next beat, offered or not, not only when it
        // moves, so the value of the clock it moves is the last one taken and neither
        // `valid` nor `accept` reaches the enables of the two 32-bit subtractions (both
        // are read only after beat 5 moved).
        // The first record's beat 5 moved: one expression (set and cleared in branches, the
        // flip-flop would get a reset net of its own, a LUT level on the path)
        self.first_seen.d.next = self.records.valid.val()
            & self.accept.val()
            & self.position.beat_at_last_tick.val()
            & !self.position.fill_nonzero.val()
            & !self.reset.val();
        if self.offset_idle.q.val() & self.position.beat_at_last_tick.val() {
            if !self.position.fill_nonzero.val() {
                self.offset_bytes.d.next = 0.into();
                self.first_age.d.next = self.tick.val().get_bits::<32>(0) - self.record_tick.val();
            } else {
                self.offset_bytes.d.next =
                    self.record_tick.val() - self.deadline.base_tick.val().get_bits::<32>(0);
            }
        }
        // the byte goes into the filling buffer a clock later, the body's sum with it
        self.payload.clock.next = self.clock.val();
        self.payload.reset.next = self.reset.val();
        self.payload.write.next = self.write.val();
        self.payload.write_data.next = self.write_data.val();
        self.payload.buffer.next = self.fill_buffer.q.val();
        self.payload.clear.next = self.close.due.val() & self.can_close.val();
        self.memory.write_enable.next = self.payload.memory_write.val();
        self.memory.write_data.next = self.payload.memory_data.val();
        self.memory.write_address.next = self.payload.memory_address.val();

        // Hand the full buffer over, start filling the other.
        self.offer.close.next = self.close.due.val() & self.can_close.val();
        self.offer.kind.next = self.records_kind.val();
        self.offer.close_entry_count.next = bit_cast::<16, 6>(self.position.fill_count.val());
        self.offer.close_body_len.next = self.payload.offset.val();
        self.offer.close_body_sum.next = self.payload.body_sum_next.val();
        self.offer.close_base_tick.next = self.deadline.base_tick.val();
        self.offer.close_flags.next = 0.into();
        if !self.position.fill_full.val() {
            self.offer.close_flags.next = self.flush_timeout_flag.val();
        }
        self.position.clear.next = self.close.due.val() & self.can_close.val();
        if self.close.due.val() & self.can_close.val() {
            self.fill_buffer.d.next = !self.fill_buffer.q.val();
        }

        // The closed datagram, read from the buffer that is not filling.
        DatagramSource::link(&mut self.datagrams, &mut self.offer.datagrams);
        self.memory.read_address.next = (bit_cast::<12, 1>((!self.fill_buffer.q.val()).into())
            << 11)
            | bit_cast::<12, 11>(self.offer.read_address.val());
        self.offer.read_data.next = self.memory.read_data.val();

        if self.reset.val() {
            self.fill_buffer.d.next = false;
            self.offset_idle.d.next = true;
            self.offset_left.d.next = 0.into();
        }
        // whether the filling datagram is due to close, a clock ahead, from registers
        self.close.clock.next = self.clock.val();
        self.close.reset.next = self.reset.val();
        self.close.can_close.next = self.can_close.val();
        self.close.beat_valid.next = self.records.valid.val();
        self.close.offset_idle.next = self.offset_idle.q.val();
        self.close.beat_zero.next = self.position.beat_zero.val();
        self.close.beat_last.next = self.position.beat_last.val();
        self.close.fill_at_last.next = self.position.fill_at_last.val();
        self.close.fill_full.next = self.position.fill_full.val();
        self.close.fill_nonzero.next = self.position.fill_nonzero.val();
        self.close.deadline_passed_next.next = self.deadline.passed_next.val();
        self.datagrams_sent.next = self.offer.datagrams_sent.val();
        self.records_sent.next = self.offer.entries_sent.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{is_body_sum_of, Bench, TestRng};
    use skinbox_protocol::datagram::MAX_RECORDS;
    use skinbox_protocol::record::RECORD_LEN;
    use skinbox_protocol::{DataRepr, RecordRepr};

    const TIMEOUT: u64 = 3000;

    /// A record as the packet store sends it: the tick field holds the absolute low 32 bits.
    fn record(i: usize, tick: u32) -> RecordRepr {
        RecordRepr {
            port: (i % 8) as u8,
            flags: i.is_multiple_of(5) as u8,
            tick_offset: tick as i32,
            cell_packet: DataRepr::from_raw(
                i as u16 % 0x3FFF,
                [i as i32 % 500, 2, 3, 4, 5, 6, 7, 8, 9],
            )
            .unwrap()
            .to_bytes(),
        }
    }

    /// A datagram as it left the batcher.
    #[derive(Debug)]
    struct Batch {
        /// Clock its descriptor was first offered.
        offered: u64,
        flags: u8,
        base_tick: u64,
        records: Vec<RecordRepr>,
    }

    /// How the sink takes datagrams: descriptors from `hold_until` on, each descriptor
    /// and body beat with probability `take_p`.
    #[derive(Clone, Copy)]
    struct Sink {
        hold_until: u64,
        take_p: f64,
    }

    const EAGER: Sink = Sink {
        hold_until: 0,
        take_p: 1.0,
    };

    struct Run {
        batches: Vec<Batch>,
        /// Clock each record's first beat was taken.
        taken: Vec<u64>,
    }

    /// Offers each record from its clock on, at most one beat per clock, with the box
    /// time starting at `epoch`; checks every descriptor against its body.
    fn run(epoch: u64, records: &[(u64, RecordRepr)], sink: Sink, clocks: u64) -> Run {
        let mut bench = Bench::new(RecordBatcher::new(), |b| &mut b.clock);
        bench.uut.flush_timeout_ticks.next = TIMEOUT.into();
        let mut rng = TestRng::new(epoch ^ clocks);
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        let beats: Vec<Vec<u8>> = records
            .iter()
            .map(|(_, r)| {
                let mut b = vec![0; RECORD_LEN];
                r.emit(&mut b);
                b
            })
            .collect();
        let (mut next, mut beat) = (0, 0);
        let mut taken = vec![];
        let mut out: Vec<Batch> = vec![];
        let mut offered_since: Option<u64> = None;
        // clocks the descriptors were taken: each is counted from two clocks later on
        // (the reference model's status words rely on that clock)
        let mut take_clocks: Vec<u64> = vec![];
        // descriptor taken: (entries, length, sum, body so far)
        let mut open: Option<(usize, usize, u64, Vec<u8>)> = None;
        for clock in 0..clocks {
            let offer = next < records.len() && clock >= records[next].0;
            let take = clock >= sink.hold_until && rng.chance(sink.take_p);
            let take_body = rng.chance(sink.take_p);
            let u = &mut bench.uut;
            u.tick.next = (epoch + clock).into();
            u.records.valid.next = offer;
            if offer {
                u.records.data.next = u64::from(beats[next][beat]).into();
                u.records.last.next = beat == RECORD_LEN - 1;
            }
            u.datagrams.ready.next = take && open.is_none();
            u.datagrams.body.ready.next = take_body;
            bench.settle();
            let u = &bench.uut;
            let counted = take_clocks.iter().filter(|&&t| t + 2 <= clock).count();
            assert_eq!(u.datagrams_sent.val().index(), counted, "clock {clock}");
            if offer && u.records.ready.val() {
                if beat == 0 {
                    taken.push(clock);
                }
                beat += 1;
                if beat == RECORD_LEN {
                    beat = 0;
                    next += 1;
                }
            }
            if let Some((entries, len, sum, body)) = &mut open {
                if take_body && u.datagrams.body.valid.val() {
                    body.push(u.datagrams.body.data.val().to_u8());
                    assert_eq!(u.datagrams.body.last.val(), body.len() == *len);
                    if body.len() == *len {
                        assert!(is_body_sum_of(*sum, body), "body sum {sum:#x}");
                        let records: Vec<RecordRepr> = body
                            .chunks(RECORD_LEN)
                            .map(|r| RecordRepr::parse(r).unwrap())
                            .collect();
                        assert_eq!(records.len(), *entries);
                        out.last_mut().unwrap().records = records;
                        open = None;
                    }
                }
            } else {
                assert!(
                    !u.datagrams.body.valid.val(),
                    "no body before its descriptor"
                );
                if u.datagrams.valid.val() {
                    let offered = *offered_since.get_or_insert(clock);
                    if take {
                        assert_eq!(u.datagrams.kind.val().to_u8(), DatagramKind::Records as u8);
                        let entries = u.datagrams.entry_count.val().index();
                        let len = u.datagrams.body_len.val().index();
                        assert_eq!(len, entries * RECORD_LEN);
                        open = Some((entries, len, u.datagrams.body_sum.val().to_u64(), vec![]));
                        out.push(Batch {
                            offered,
                            flags: u.datagrams.flags.val().to_u8(),
                            base_tick: u.datagrams.base_tick.val().to_u64(),
                            records: vec![],
                        });
                        offered_since = None;
                        take_clocks.push(clock);
                    }
                }
            }
            bench.cycle();
        }
        assert_eq!(next, records.len(), "records not taken");
        assert!(open.is_none(), "a body left unfinished");
        let records_out = out.iter().map(|b| b.records.len() as u32).sum::<u32>();
        assert_eq!(bench.uut.records_sent.val().to_u32(), records_out);
        assert_eq!(bench.uut.datagrams_sent.val().to_u32(), out.len() as u32);
        Run {
            batches: out,
            taken,
        }
    }

    /// Every record once, in order, with its tick rebuilt from its datagram's base.
    fn assert_all_delivered(out: &[Batch], input: &[(u64, RecordRepr)]) {
        let got: Vec<(u64, &RecordRepr)> = out
            .iter()
            .flat_map(|b| b.records.iter().map(|r| (r.tick(b.base_tick), r)))
            .collect();
        assert_eq!(got.len(), input.len());
        for (i, ((tick, r), (_, sent))) in got.iter().zip(input).enumerate() {
            assert_eq!(
                (r.port, r.flags, r.cell_packet),
                (sent.port, sent.flags, sent.cell_packet),
                "record {i}"
            );
            assert_eq!(*tick as u32, sent.tick_offset as u32, "record {i}");
        }
    }

    #[test]
    fn full_datagram_then_timeout_with_exact_offsets() {
        let input: Vec<(u64, RecordRepr)> = (0..60)
            .map(|i| (2000, record(i, 1000 + 7 * i as u32)))
            .collect();
        let run = run(0, &input, EAGER, 2000 + 60 * 32 + TIMEOUT + 3000);
        let out = &run.batches;
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].flags, 0, "closed because full");
        assert_eq!(out[1].flags, FLAG_FLUSH_TIMEOUT);
        assert_eq!(out[0].records.len(), MAX_RECORDS);
        assert_eq!((out[0].base_tick, out[1].base_tick), (1000, 1000 + 7 * 55));
        assert_all_delivered(out, &input);
        // the second datagram closed when its first record had waited the flush timeout
        // (from its arrival here, plus its beats up to its tick)
        let due = run.taken[55] + TIMEOUT;
        assert!(
            (due..=due + 10).contains(&out[1].offered),
            "closed at {}, due at {due}",
            out[1].offered
        );
    }

    #[test]
    fn offsets_are_signed_and_base_is_rebuilt_to_64_bits() {
        // box time crosses 5 * 2^32 between the records' start edges and their arrival
        let epoch = (5u64 << 32) - 5005;
        let at = |t: u64| (epoch + t) as u32;
        let input = vec![
            (6000, record(0, at(5000))),
            (6030, record(1, at(4990))),
            (6060, record(2, at(5010))),
        ];
        let out = run(epoch, &input, EAGER, 7000 + TIMEOUT).batches;
        assert_eq!(out.len(), 1);
        let offsets: Vec<i32> = out[0].records.iter().map(|r| r.tick_offset).collect();
        assert_eq!(offsets, vec![0, -10, 10]);
        assert_eq!(out[0].base_tick, epoch + 5000);
    }

    #[test]
    fn every_record_arrives_once_in_order_under_random_backpressure() {
        let input: Vec<(u64, RecordRepr)> = (0..300).map(|i| (10, record(i, i as u32))).collect();
        for take_p in [1.0, 0.5, 0.2] {
            let sink = Sink {
                hold_until: 0,
                take_p,
            };
            let out = run(0, &input, sink, 120_000).batches;
            assert_all_delivered(&out, &input);
            assert!(out[..out.len() - 1]
                .iter()
                .all(|d| d.records.len() == MAX_RECORDS));
        }
    }

    #[test]
    fn records_wait_upstream_while_no_datagram_is_taken() {
        // nothing is taken for 8 timeouts: one datagram closes and waits, the next fills
        // and closes, the input stops; then everything leaves, in order, none lost
        let input: Vec<(u64, RecordRepr)> = (0..150)
            .map(|i| (100 + 200 * i as u64, record(i, 100 + 200 * i as u32)))
            .collect();
        let sink = Sink {
            hold_until: 8 * TIMEOUT,
            take_p: 1.0,
        };
        let run = run(0, &input, sink, 150 * 200 + 4 * TIMEOUT);
        let out = &run.batches;
        assert_all_delivered(out, &input);
        // the first closed at its timeout (at the end of the record then coming in) and
        // waited; the second filled and waited too, holding the records upstream
        let due = run.taken[0] + TIMEOUT;
        assert!(
            (due..due + 40).contains(&out[0].offered),
            "{}",
            out[0].offered
        );
        assert_eq!(out[0].flags, FLAG_FLUSH_TIMEOUT);
        let held = run.taken.iter().filter(|&&t| t > sink.hold_until).count();
        let late = input.iter().filter(|(at, _)| *at > sink.hold_until).count();
        assert!(
            held > late,
            "records were held upstream ({held} taken late, {late} offered late)"
        );
    }
}
