//! UdpFramer: batches records into box datagrams and sends them as Ethernet frames.
//!
//! Records arrive as 26-beat stream packets from the packet store (port, flags, the low 32 bits
//! of the start tick, 20 cell bytes). The framer writes them into one of two 2 KB payload
//! buffers: the first record of a datagram sets its base tick (the full 64-bit tick,
//! rebuilt from the current time), every record's tick is rewritten as a signed offset
//! from it (the input pauses 4 clocks for that), and the ones'-complement sum of the body
//! grows with every byte. A datagram closes when it holds 55 records (1454 bytes) or when
//! its first record has waited `flush_timeout_ticks` (one clock later, as the deadline test
//! is registered, and after a record on its way in is complete); it then goes to the
//! [`FrameTransmitter`] while the other buffer fills (double buffering). A datagram due to
//! close takes no more records: while the other buffer is still busy the input is not
//! ready and records wait upstream, none is lost here.
//!
//! Status datagrams come from the status block's own memory through the `status_*`
//! ports and share the transmitter; a waiting records datagram goes first.

use crate::block_ram::BlockRam;
use crate::frame_transmitter::FrameTransmitter;
use crate::hdl::*;
use crate::stream::ByteStreamSink;
use skinbox_protocol::datagram::MAX_RECORDS;
use skinbox_protocol::LinkConfig;

/// Parameters of the framer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramerConfig {
    /// Addresses and ports.
    pub link: LinkConfig,
    /// Box id in every datagram header.
    pub box_id: u16,
    /// Port count in every datagram header.
    pub port_count: u8,
    /// A datagram is sent when its first record has waited this long.
    pub flush_timeout_ticks: u64,
}

/// Batches records into datagrams and sends them on GMII.
#[derive(LogicBlock)]
pub struct UdpFramer {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// Records from the packet store.
    pub records: ByteStreamSink,
    /// Box time.
    pub tick: Signal<In, Bits<64>>,
    /// A status body is ready in the status memory.
    pub status_request: Signal<In, Bit>,
    /// Port counter blocks in the status body.
    pub status_entry_count: Signal<In, Bits<16>>,
    /// Length of the status body.
    pub status_body_len: Signal<In, Bits<11>>,
    /// Sum of the status body's 16-bit words.
    pub status_body_sum: Signal<In, Bits<32>>,
    /// Time of the status report.
    pub status_tick: Signal<In, Bits<64>>,
    /// One clock: the status datagram was taken; its memory is read from now until
    /// `status_sending` falls.
    pub status_taken: Signal<Out, Bit>,
    /// The transmitter is reading the status memory.
    pub status_sending: Signal<Out, Bit>,
    /// Status memory byte to read (its data due two clocks later on `status_data`, from
    /// the memory's output register).
    pub status_address: Signal<Out, Bits<11>>,
    /// Status memory byte.
    pub status_data: Signal<In, Bits<8>>,
    /// Records datagrams sent since reset.
    pub datagrams_sent: Signal<Out, Bits<32>>,
    /// Records sent since reset.
    pub records_sent: Signal<Out, Bits<32>>,
    /// GMII transmit data.
    pub gmii_txd: Signal<Out, Bits<8>>,
    /// GMII transmit enable.
    pub gmii_tx_en: Signal<Out, Bit>,
    /// GMII transmit error.
    pub gmii_tx_er: Signal<Out, Bit>,
    transmitter: FrameTransmitter,
    memory: BlockRam<8, 12>,
    last_fill_less_one: Constant<Bits<6>>,
    flush_timeout_less_two: Constant<Bits<32>>,
    // a timeout of 1 or 2 ticks has passed a clock after the deadline is set
    short_timeout: Constant<Bit>,
    fill_buffer: DFF<Bit>,
    fill_count: DFF<Bits<6>>,
    fill_offset: DFF<Bits<11>>,
    fill_sum: DFF<Bits<32>>,
    fill_base_tick: DFF<Bits<64>>,
    // the flush deadline less one (low 32 bits of the tick)
    fill_deadline_less_one: DFF<Bits<32>>,
    // the first record's age (now - its tick, low 32 bits), for the base tick and the
    // deadline, which are set a clock later (off the accept path)
    first_age: DFF<Bits<32>>,
    first_seen: DFF<Bit>,
    // the next clock's tick is at or past the deadline: the deadline test a clock ahead
    // (the tick counts one per clock), so `close_due` takes no carry chain
    deadline_passed_next: DFF<Bit>,
    // beat == 0, offset_left == 0, fill_count == max and != 0, kept in registers
    beat_zero: DFF<Bit>,
    // beat == 5 (the record's last tick byte), set and cleared as the beat moves
    beat_five: DFF<Bit>,
    // beat == 25 (the record's last beat), and fill_count == the last record's index
    beat_last: DFF<Bit>,
    fill_at_last: DFF<Bit>,
    offset_idle: DFF<Bit>,
    fill_full: DFF<Bit>,
    fill_nonzero: DFF<Bit>,
    beat: DFF<Bits<5>>,
    tick_low: DFF<Bits<32>>,
    offset_bytes: DFF<Bits<32>>,
    offset_left: DFF<Bits<3>>,
    pending: DFF<Bit>,
    pending_count: DFF<Bits<6>>,
    pending_len: DFF<Bits<11>>,
    pending_sum: DFF<Bits<32>>,
    pending_base_tick: DFF<Bits<64>>,
    pending_flags: DFF<Bits<8>>,
    sending_records: DFF<Bit>,
    sending_status: DFF<Bit>,
    status_taken_pulse: DFF<Bit>,
    datagram_count: DFF<Bits<32>>,
    record_count: DFF<Bits<32>>,
    record_tick: Signal<Local, Bits<32>>,
    write: Signal<Local, Bit>,
    // the payload memory's write port, a clock after the decision (off the accept path)
    memory_write: DFF<Bit>,
    memory_write_address: DFF<Bits<12>>,
    memory_write_data: DFF<Bits<8>>,
    write_data: Signal<Local, Bits<8>>,
    fill_sum_next: Signal<Local, Bits<32>>,
    // a datagram is due to close (full, or its time is up) at a record boundary: a
    // register, its next value from registers (at the end of the kernel)
    close_due: DFF<Bit>,
    can_close: Signal<Local, Bit>,
    accept: Signal<Local, Bit>,
    start_records: Signal<Local, Bit>,
    start_status: Signal<Local, Bit>,
    deadline_delta: Signal<Local, Bits<32>>,
}

impl UdpFramer {
    /// A framer with these parameters.
    pub fn new(config: &FramerConfig) -> Self {
        assert!(
            config.flush_timeout_ticks > 0 && config.flush_timeout_ticks < 1 << 31,
            "UdpFramer: flush timeout of {} ticks must be 1 to 2^31 - 1",
            config.flush_timeout_ticks
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            records: Default::default(),
            tick: Default::default(),
            status_request: Default::default(),
            status_entry_count: Default::default(),
            status_body_len: Default::default(),
            status_body_sum: Default::default(),
            status_tick: Default::default(),
            status_taken: Default::default(),
            status_sending: Default::default(),
            status_address: Default::default(),
            status_data: Default::default(),
            datagrams_sent: Default::default(),
            records_sent: Default::default(),
            gmii_txd: Default::default(),
            gmii_tx_en: Default::default(),
            gmii_tx_er: Default::default(),
            transmitter: FrameTransmitter::new(&config.link, config.box_id, config.port_count),
            memory: Default::default(),
            last_fill_less_one: Constant::new((MAX_RECORDS as u64 - 2).into()),
            flush_timeout_less_two: Constant::new(
                (config.flush_timeout_ticks.wrapping_sub(2) & 0xFFFF_FFFF).into(),
            ),
            short_timeout: Constant::new(config.flush_timeout_ticks <= 2),
            fill_buffer: Default::default(),
            fill_count: Default::default(),
            fill_offset: Default::default(),
            fill_sum: Default::default(),
            fill_base_tick: Default::default(),
            fill_deadline_less_one: Default::default(),
            first_age: Default::default(),
            first_seen: Default::default(),
            deadline_passed_next: Default::default(),
            beat_zero: Default::default(),
            beat_five: Default::default(),
            beat_last: Default::default(),
            fill_at_last: Default::default(),
            offset_idle: Default::default(),
            fill_full: Default::default(),
            fill_nonzero: Default::default(),
            beat: Default::default(),
            tick_low: Default::default(),
            offset_bytes: Default::default(),
            offset_left: Default::default(),
            pending: Default::default(),
            pending_count: Default::default(),
            pending_len: Default::default(),
            pending_sum: Default::default(),
            pending_base_tick: Default::default(),
            pending_flags: Default::default(),
            sending_records: Default::default(),
            sending_status: Default::default(),
            status_taken_pulse: Default::default(),
            datagram_count: Default::default(),
            record_count: Default::default(),
            record_tick: Default::default(),
            write: Default::default(),
            memory_write: Default::default(),
            memory_write_address: Default::default(),
            memory_write_data: Default::default(),
            write_data: Default::default(),
            fill_sum_next: Default::default(),
            close_due: Default::default(),
            can_close: Default::default(),
            accept: Default::default(),
            start_records: Default::default(),
            start_status: Default::default(),
            deadline_delta: Default::default(),
        }
    }
}

// Record beats: 0 port, 1 flags, 2..=5 tick (not written; replaced by the 4 offset bytes),
// 6..=25 cell bytes.
impl Logic for UdpFramer {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            fill_buffer,
            close_due,
            fill_count,
            fill_offset,
            fill_sum,
            fill_base_tick,
            fill_deadline_less_one,
            first_age,
            first_seen,
            deadline_passed_next,
            beat_zero,
            beat_five,
            beat_last,
            fill_at_last,
            offset_idle,
            fill_full,
            fill_nonzero,
            beat,
            tick_low,
            offset_bytes,
            offset_left,
            pending,
            pending_count,
            pending_len,
            pending_sum,
            pending_base_tick,
            pending_flags,
            sending_records,
            sending_status,
            status_taken_pulse,
            datagram_count,
            record_count,
            memory_write,
            memory_write_address,
            memory_write_data
        );
        self.transmitter.clock.next = self.clock.val();
        self.transmitter.reset.next = self.reset.val();
        self.memory.clock.next = self.clock.val();

        // The flush deadline passed: a registered, wrap-safe 32-bit test (the timeout is far
        // below 2^31 ticks), taken a clock ahead: the next tick (now + 1) against the
        // deadline is now against the deadline less one.
        // (a bit of an expression is not Verilog: the difference gets its own signal)
        // The first record's base tick and deadline, a clock after its tick was complete:
        // base = (now - 1) - age = now + !age (sign-extended), deadline = now + timeout - 1.
        self.deadline_delta.next =
            self.tick.val().get_bits::<32>(0) - self.fill_deadline_less_one.q.val();
        self.deadline_passed_next.d.next = !self.deadline_delta.val().get_bit(31);
        if self.first_seen.q.val() {
            self.fill_base_tick.d.next = self.tick.val()
                + (bit_cast::<64, 32>(!self.first_age.q.val()) | 0xFFFF_FFFF_0000_0000_u64);
            self.fill_deadline_less_one.d.next =
                self.tick.val().get_bits::<32>(0) + self.flush_timeout_less_two.val();
            // (the next tick is now + 1: the deadline has passed if timeout - 1 <= 1)
            self.deadline_passed_next.d.next = self.short_timeout.val();
        }
        // Close the filling datagram at a record boundary when full or due (`close_due`,
        // set at the end from the tests of beat, offset_left, fill_count and the deadline,
        // each set and cleared by the events that change what it tests, below).
        self.can_close.next = !self.pending.q.val() & !self.sending_records.q.val();
        // No beat moves while a datagram is due to close: in the clock it closes (the beat
        // would land in the old buffer) and while it waits for the other buffer (a full one
        // and one whose time is up alike). Whether the other buffer is free stays off the
        // input's ready.
        self.accept.next = self.offset_idle.q.val() & !self.close_due.q.val();
        self.records.ready.next = self.accept.val();

        // Write one byte per clock: offset bytes while they are pending, else stream beats.
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
            self.beat.d.next = self.beat.q.val() + 1;
            self.beat_zero.d.next = false;
            self.beat_five.d.next = self.beat.q.val() == 4;
            self.beat_last.d.next = self.beat.q.val() == 24;
            if self.beat_last.q.val() {
                self.beat.d.next = 0.into();
                self.beat_zero.d.next = true;
                self.fill_count.d.next = self.fill_count.q.val() + 1;
                self.fill_full.d.next = self.fill_at_last.q.val();
                self.fill_at_last.d.next = self.fill_count.q.val() == self.last_fill_less_one.val();
                self.fill_nonzero.d.next = true;
            }
            // beats 2..=5 (the tick bytes), from the beat's bits: 0b000_1x or 0b001_0x
            if (self.beat.q.val().get_bits::<2>(3) == 0)
                & (self.beat.q.val().get_bit(2) != self.beat.q.val().get_bit(1))
            {
                self.tick_low.d.next = self.record_tick.val();
            } else {
                self.write.next = true;
            }
            if self.beat_five.q.val() {
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
            & self.beat_five.q.val()
            & !self.fill_nonzero.q.val()
            & !self.reset.val();
        if self.offset_idle.q.val() & self.beat_five.q.val() {
            if !self.fill_nonzero.q.val() {
                self.offset_bytes.d.next = 0.into();
                self.first_age.d.next = self.tick.val().get_bits::<32>(0) - self.record_tick.val();
            } else {
                self.offset_bytes.d.next =
                    self.record_tick.val() - self.fill_base_tick.q.val().get_bits::<32>(0);
            }
        }
        // the transmitter reads a buffer only after it closed, many clocks after its last
        // byte was written, so the write may land a clock late
        self.memory_write.d.next = self.write.val();
        self.memory_write_data.d.next = self.write_data.val();
        self.memory_write_address.d.next = (bit_cast::<12, 1>(self.fill_buffer.q.val().into())
            << 11)
            | bit_cast::<12, 11>(self.fill_offset.q.val());
        self.memory.write_enable.next = self.memory_write.q.val();
        self.memory.write_data.next = self.memory_write_data.q.val();
        self.memory.write_address.next = self.memory_write_address.q.val();
        if self.write.val() {
            self.fill_offset.d.next = self.fill_offset.q.val() + 1;
        }
        // the body's sum grows with the write register's byte (a clock after the decision,
        // from registers only); a datagram closing now takes the byte still on its way
        self.fill_sum_next.next = self.fill_sum.q.val();
        if self.memory_write.q.val() {
            if self.memory_write_address.q.val().get_bit(0) {
                self.fill_sum_next.next =
                    self.fill_sum.q.val() + bit_cast::<32, 8>(self.memory_write_data.q.val());
            } else {
                self.fill_sum_next.next = self.fill_sum.q.val()
                    + (bit_cast::<32, 8>(self.memory_write_data.q.val()) << 8);
            }
        }
        self.fill_sum.d.next = self.fill_sum_next.val();

        // Hand the full buffer over, start filling the other.
        if self.close_due.q.val() & self.can_close.val() {
            self.pending.d.next = true;
            self.pending_count.d.next = self.fill_count.q.val();
            self.pending_len.d.next = self.fill_offset.q.val();
            self.pending_sum.d.next = self.fill_sum_next.val();
            self.pending_base_tick.d.next = self.fill_base_tick.q.val();
            self.pending_flags.d.next = 0.into();
            if !self.fill_full.q.val() {
                self.pending_flags.d.next = 1.into();
            }
            self.fill_buffer.d.next = !self.fill_buffer.q.val();
            self.fill_count.d.next = 0.into();
            self.fill_full.d.next = false;
            self.fill_at_last.d.next = false;
            self.fill_nonzero.d.next = false;
            self.fill_offset.d.next = 0.into();
            self.fill_sum.d.next = 0.into();
        }

        // The transmitter: a waiting records datagram first, then a status datagram.
        self.start_records.next = self.transmitter.idle.val() & self.pending.q.val();
        self.start_status.next =
            self.transmitter.idle.val() & !self.pending.q.val() & self.status_request.val();
        self.transmitter.start.next = self.start_records.val() | self.start_status.val();
        self.transmitter.kind.next = 1.into();
        self.transmitter.flags.next = self.pending_flags.q.val();
        self.transmitter.entry_count.next = bit_cast::<16, 6>(self.pending_count.q.val());
        self.transmitter.base_tick.next = self.pending_base_tick.q.val();
        self.transmitter.body_len.next = self.pending_len.q.val();
        self.transmitter.body_sum.next = self.pending_sum.q.val();
        // the descriptor of what would start now (the transmitter takes it while idle)
        if !self.pending.q.val() & self.status_request.val() {
            self.transmitter.kind.next = 2.into();
            self.transmitter.flags.next = 0.into();
            self.transmitter.entry_count.next = self.status_entry_count.val();
            self.transmitter.base_tick.next = self.status_tick.val();
            self.transmitter.body_len.next = self.status_body_len.val();
            self.transmitter.body_sum.next = self.status_body_sum.val();
        }
        self.status_taken_pulse.d.next = self.start_status.val();
        // Each start names the memory the transmitter reads next; a start can come in the
        // very clock the previous frame (of either kind) ends.
        if self.start_records.val() {
            self.pending.d.next = false;
            self.sending_records.d.next = true;
            self.sending_status.d.next = false;
            self.datagram_count.d.next = self.datagram_count.q.val() + 1;
            self.record_count.d.next =
                self.record_count.q.val() + bit_cast::<32, 6>(self.pending_count.q.val());
        } else if self.start_status.val() {
            self.sending_status.d.next = true;
            self.sending_records.d.next = false;
        } else if self.transmitter.idle.val() {
            self.sending_records.d.next = false;
            self.sending_status.d.next = false;
        }
        // The body being sent is always the buffer that is not filling.
        self.memory.read_address.next = (bit_cast::<12, 1>((!self.fill_buffer.q.val()).into())
            << 11)
            | bit_cast::<12, 11>(self.transmitter.payload_address.val());
        // both memories answer two clocks after the address, from their output registers
        self.transmitter.payload_data.next = self.memory.read_data.val();
        if self.sending_status.q.val() {
            self.transmitter.payload_data.next = self.status_data.val();
        }
        self.status_address.next = self.transmitter.payload_address.val();

        if self.reset.val() {
            self.memory_write.d.next = false;
            self.fill_buffer.d.next = false;
            self.fill_count.d.next = 0.into();
            self.beat_zero.d.next = true;
            self.offset_idle.d.next = true;
            self.fill_full.d.next = false;
            self.fill_at_last.d.next = false;
            self.fill_nonzero.d.next = false;
            self.fill_offset.d.next = 0.into();
            self.fill_sum.d.next = 0.into();
            self.beat.d.next = 0.into();
            self.beat_five.d.next = false;
            self.beat_last.d.next = false;
            self.offset_left.d.next = 0.into();
            self.pending.d.next = false;
            self.sending_records.d.next = false;
            self.sending_status.d.next = false;
            self.status_taken_pulse.d.next = false;
            self.datagram_count.d.next = 0.into();
            self.record_count.d.next = 0.into();
        }
        // The next value of `close_due`, from registers: a datagram due to close stays due
        // until it closes (nothing moves meanwhile); otherwise it is due at the next record
        // boundary: at the end of this clock's beat if it is a record's last (full, or its
        // time up), or now already (at a boundary, full or time up). (Between a record's
        // beats 6 and 10, `offset_idle` low, no boundary is near.)
        if self.close_due.q.val() {
            self.close_due.d.next = !self.can_close.val();
        } else if self.records.valid.val() {
            self.close_due.d.next = self.offset_idle.q.val()
                & self.beat_last.q.val()
                & (self.fill_at_last.q.val() | self.deadline_passed_next.q.val());
        } else {
            self.close_due.d.next = self.offset_idle.q.val()
                & self.beat_zero.q.val()
                & (self.fill_full.q.val()
                    | (self.fill_nonzero.q.val() & self.deadline_passed_next.q.val()));
        }
        if self.reset.val() {
            self.close_due.d.next = false;
        }
        self.status_taken.next = self.status_taken_pulse.q.val();
        self.status_sending.next = self.sending_status.q.val();
        self.datagrams_sent.next = self.datagram_count.q.val();
        self.records_sent.next = self.record_count.q.val();
        self.gmii_txd.next = self.transmitter.gmii_txd.val();
        self.gmii_tx_en.next = self.transmitter.gmii_tx_en.val();
        self.gmii_tx_er.next = self.transmitter.gmii_tx_er.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{check_frame, Bench, GmiiCapture};
    use skinbox_protocol::datagram::{DatagramBody, FLAG_FLUSH_TIMEOUT};
    use skinbox_protocol::{DataRepr, DatagramRepr, PortCounters, RecordRepr, StatusRepr};

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

    struct Run {
        capture: GmiiCapture,
        /// Clock at which each record's first beat was taken.
        taken: Vec<u64>,
        status_taken: u32,
    }

    /// Offers each record from its clock on, at most one beat per clock, with the status
    /// body requested from `status_at`.
    fn run(
        records: &[(u64, RecordRepr)],
        status_at: Option<(u64, Vec<u8>, u16)>,
        clocks: u64,
    ) -> Run {
        run_from(0, records, status_at, clocks)
    }

    /// As [`run`], with the box time starting at `epoch`.
    fn run_from(
        epoch: u64,
        records: &[(u64, RecordRepr)],
        status_at: Option<(u64, Vec<u8>, u16)>,
        clocks: u64,
    ) -> Run {
        let config = FramerConfig {
            link: LinkConfig::DEFAULT,
            box_id: 3,
            port_count: 8,
            flush_timeout_ticks: TIMEOUT,
        };
        let mut bench = Bench::new(UdpFramer::new(&config), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        let beats: Vec<Vec<u8>> = records
            .iter()
            .map(|(_, r)| {
                let mut b = vec![0; 26];
                r.emit(&mut b);
                b
            })
            .collect();
        let (mut next, mut beat) = (0, 0);
        let mut run = Run {
            capture: GmiiCapture::default(),
            taken: vec![],
            status_taken: 0,
        };
        let mut status_pending = false;
        // the status memory's addresses of the last two clocks: it answers two clocks late
        let mut status_reads: [u64; 2] = [0; 2];
        for clock in 0..clocks {
            let offer = next < records.len() && clock >= records[next].0;
            let u = &mut bench.uut;
            u.tick.next = (epoch + clock).into();
            u.records.valid.next = offer;
            if offer {
                u.records.data.next = u64::from(beats[next][beat]).into();
                u.records.last.next = beat == 25;
            }
            if let Some((at, body, entries)) = &status_at {
                if clock == *at {
                    status_pending = true;
                }
                u.status_request.next = status_pending;
                u.status_entry_count.next = u64::from(*entries).into();
                u.status_body_len.next = (body.len() as u64).into();
                u.status_body_sum.next = crate::frame_transmitter::word_sum(body).into();
                u.status_tick.next = 777_777.into();
                u.status_data.next =
                    u64::from(*body.get(status_reads[1] as usize).unwrap_or(&0)).into();
            }
            bench.settle();
            let u = &bench.uut;
            if offer && u.records.ready.val() {
                if beat == 0 {
                    run.taken.push(clock);
                }
                beat += 1;
                if beat == 26 {
                    beat = 0;
                    next += 1;
                }
            }
            status_reads = [u.status_address.val().to_u64(), status_reads[0]];
            if u.status_taken.val() {
                run.status_taken += 1;
                status_pending = false;
            }
            run.capture.clock(
                clock,
                u.gmii_tx_en.val(),
                u.gmii_txd.val().to_u8(),
                u.gmii_tx_er.val(),
            );
            bench.cycle();
        }
        assert_eq!(next, records.len(), "records not taken");
        run
    }

    fn datagrams(capture: &GmiiCapture) -> Vec<DatagramRepr> {
        capture
            .frames
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let payload = check_frame(f).unwrap_or_else(|e| panic!("frame {i}: {e}"));
                DatagramRepr::parse(&payload).unwrap_or_else(|e| panic!("frame {i}: {e}"))
            })
            .collect()
    }

    fn records_of(d: &DatagramRepr) -> &[RecordRepr] {
        match &d.body {
            DatagramBody::Records(r) => r,
            DatagramBody::Status(_) => panic!("status datagram where records were expected"),
        }
    }

    #[test]
    fn full_datagram_then_timeout_with_exact_offsets() {
        let input: Vec<(u64, RecordRepr)> = (0..60)
            .map(|i| (2000, record(i, 1000 + 7 * i as u32)))
            .collect();
        let run = run(&input, None, 2000 + 60 * 32 + TIMEOUT + 3000);
        let got = datagrams(&run.capture);
        assert_eq!(got.len(), 2);
        assert_eq!((got[0].sequence, got[1].sequence), (0, 1));
        assert_eq!(got[0].flags, 0, "sent because full");
        assert_eq!(got[1].flags, FLAG_FLUSH_TIMEOUT);
        assert_eq!((got[0].box_id, got[0].port_count), (3, 8));
        for (d, range, base) in [(&got[0], 0..55, 1000u64), (&got[1], 55..60, 1000 + 7 * 55)] {
            assert_eq!(d.base_tick, base);
            let recs = records_of(d);
            assert_eq!(recs.len(), range.len());
            for (r, i) in recs.iter().zip(range) {
                let sent = &input[i].1;
                assert_eq!(
                    (r.port, r.flags, r.cell_packet),
                    (sent.port, sent.flags, sent.cell_packet)
                );
                assert_eq!(r.tick(d.base_tick), 1000 + 7 * i as u64, "record {i}");
            }
        }
        // the second datagram left when its first record had waited the flush timeout
        let first_of_second = run.taken[55];
        let start = run.capture.starts[1];
        assert!(
            start >= first_of_second + TIMEOUT,
            "{start} < {first_of_second} + {TIMEOUT}"
        );
        assert!(
            start <= first_of_second + TIMEOUT + 10,
            "late flush: {start}"
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
        let run = run_from(epoch, &input, None, 7000 + TIMEOUT);
        let got = datagrams(&run.capture);
        assert_eq!(got.len(), 1);
        let offsets: Vec<i32> = records_of(&got[0]).iter().map(|r| r.tick_offset).collect();
        assert_eq!(offsets, vec![0, -10, 10]);
        assert_eq!(got[0].base_tick, epoch + 5000);
    }

    #[test]
    fn every_record_arrives_once_in_order_at_full_input_rate() {
        let input: Vec<(u64, RecordRepr)> = (0..200).map(|i| (10, record(i, i as u32))).collect();
        let run = run(&input, None, 200 * 40 + TIMEOUT + 5000);
        let got = datagrams(&run.capture);
        let all: Vec<RecordRepr> = got.iter().flat_map(|d| records_of(d).to_vec()).collect();
        assert_eq!(all.len(), 200);
        for (i, (r, sent)) in all.iter().zip(&input).enumerate() {
            assert_eq!(r.cell_packet, sent.1.cell_packet, "record {i}");
        }
        let sequences: Vec<u32> = got.iter().map(|d| d.sequence).collect();
        assert_eq!(sequences, (0..got.len() as u32).collect::<Vec<_>>());
        assert!(got[..got.len() - 1]
            .iter()
            .all(|d| records_of(d).len() == 55));
    }

    #[test]
    fn records_waiting_behind_a_status_datagram_are_sent_from_their_own_buffer() {
        // the records close (timeout) while the status frame is on the wire, so they start
        // in the clock the status frame ends
        let status = StatusRepr {
            boot_id: 7,
            datagrams_sent: 0,
            records_sent: 0,
            first_port: 0,
            ports: vec![PortCounters([9; 8]); 8],
        };
        let whole = DatagramRepr {
            box_id: 3,
            port_count: 8,
            flags: 0,
            sequence: 0,
            base_tick: 777_777,
            body: DatagramBody::Status(status),
        };
        let body = whole.to_bytes()[24..].to_vec();
        let input: Vec<(u64, RecordRepr)> = (0..3).map(|i| (50, record(i, 40))).collect();
        let run = run(&input, Some((TIMEOUT, body, 8)), 4 * TIMEOUT);
        let got = datagrams(&run.capture);
        assert_eq!(got.len(), 2);
        assert_eq!(got[0], whole);
        let gap =
            run.capture.starts[1] - run.capture.starts[0] - run.capture.frames[0].len() as u64;
        assert!(
            gap <= 13,
            "the records left right after the status frame ({gap} clocks)"
        );
        let sent: Vec<[u8; 20]> = input.iter().map(|r| r.1.cell_packet).collect();
        let out: Vec<[u8; 20]> = records_of(&got[1]).iter().map(|r| r.cell_packet).collect();
        assert_eq!(out, sent);
    }

    #[test]
    fn status_datagram_shares_the_link() {
        let status = StatusRepr {
            boot_id: 0xABCD,
            datagrams_sent: 1,
            records_sent: 3,
            first_port: 0,
            ports: vec![PortCounters([1, 2, 3, 4, 5, 6, 7, 8]); 8],
        };
        let whole = DatagramRepr {
            box_id: 3,
            port_count: 8,
            flags: 0,
            sequence: 1,
            base_tick: 777_777,
            body: DatagramBody::Status(status),
        };
        let body = whole.to_bytes()[24..].to_vec();
        let input: Vec<(u64, RecordRepr)> = (0..3).map(|i| (50, record(i, 40))).collect();
        let run = run(&input, Some((60, body, 8)), 6000 + TIMEOUT);
        let got = datagrams(&run.capture);
        assert_eq!(run.status_taken, 1);
        assert_eq!(got.len(), 2);
        // the status went first: the records datagram waited for its timeout
        assert_eq!(
            got[0],
            DatagramRepr {
                sequence: 0,
                ..whole
            }
        );
        assert_eq!(records_of(&got[1]).len(), 3);
        assert_eq!(got[1].sequence, 1);
    }
}
