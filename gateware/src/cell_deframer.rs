//! CellDeframer: finds 20-byte cell packets in one port's byte stream.
//!
//! Hunting, it discards every byte that is not a data or event header (`garbage`). After a
//! header it collects 19 more bytes; the packet is good when the 20th byte is the
//! end-of-packet value. It rejects a packet when a byte inside has a UART framing error,
//! when the line stays idle for `idle_gap_bits` bit times before the 20th byte
//! (truncation), or when the 20th byte is wrong; it then hunts again from the next byte.
//!
//! Output: one stream packet per header seen, 24 beats when complete: the packet's start
//! tick (the box time at the receiver's `start` of its header byte, low 32 bits, most
//! significant byte first), then the 20 cell bytes. The deframer keeps the one time
//! register of its port: it takes the time at every start edge while no tick beats go out,
//! so when a header arrives it holds the header's, even when that header started before
//! the previous packet's last byte was taken (a fast line); then it is shifted out as the
//! tick beats. A rejected packet ends early or on its 20th byte with
//! `last` and `error`, so a buffer that stored its beats discards them. The sink must take
//! each beat within one byte time (the [`crate::packet_store::PacketStore`] takes one
//! every round of its write ring, at most 32 clocks); the deframer has no room for more.
//!
//! Counter events (`events`, one clock each, bits in `skinbox_protocol::PortCounter`
//! order): good, rejected end byte, rejected framing, rejected truncated, garbage byte,
//! framing error, resync. Resync counts every loss of alignment: each rejected packet, and
//! the first garbage byte after a good packet. Counts are events, not cell packets: after a
//! framing error a header value inside the rest of the broken packet can start a false
//! packet that is rejected too.

use crate::counter_file::counter_bit;
use crate::hdl::*;
use crate::stream::ByteStreamSource;
use crate::uart_rx::{BIT_COUNT_AFTER_STOP, BIT_COUNT_MAX};
use skinbox_protocol::cell::{CellFraming, PACKET_LEN};
use skinbox_protocol::PortCounter;

/// Beats of the packet stream before the cell bytes: the 32-bit start tick.
pub const TICK_BEATS: usize = 4;

/// Longest idle gap: the receiver's bit count reaches it before it wraps.
pub const MAX_IDLE_GAP_BITS: u64 = BIT_COUNT_MAX - BIT_COUNT_AFTER_STOP;

/// Clocks between the receiver's outputs and the deframer's logic: its input register,
/// which lets the two sit apart on the chip (the start edge too: the box time it takes is
/// `TimestampCounter::start_stamp`, which lags by this and the receiver's latency).
pub const INPUT_REGISTER_CLOCKS: u64 = 1;

/// Packet finder for one port.
#[derive(LogicBlock)]
pub struct CellDeframer {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// Byte from the UART receiver.
    pub byte_data: Signal<In, Bits<8>>,
    /// A byte arrived (one clock).
    pub byte_strobe: Signal<In, Bit>,
    /// With `byte_strobe`: its stop bit was low.
    pub byte_framing_error: Signal<In, Bit>,
    /// The receiver detected a start edge (one clock, `UartRx::start`).
    pub byte_start: Signal<In, Bit>,
    /// Box time, low 32 bits, lagging by the receiver's latency and the input register
    /// (`TimestampCounter::start_stamp`): a clock after `byte_start`, the tick of the first
    /// edge that sampled the start bit low.
    pub tick: Signal<In, Bits<32>>,
    /// The receiver's bit middles since its last start edge (`UartRx::bit_count`): it
    /// counts idle bit times after a byte.
    pub byte_bit_count: Signal<In, Bits<5>>,
    /// Packets: 4 tick bytes and 20 cell bytes, `error` on `last` when rejected.
    pub packets: ByteStreamSource,
    /// Counter events this clock, bit i = `skinbox_protocol::PortCounter` i: good (0),
    /// rejected end byte (2), rejected framing (3), rejected truncated (4), garbage byte
    /// (5), framing error (6), resync (7).
    pub events: Signal<Out, Bits<8>>,
    data_header: Constant<Bits<8>>,
    event_header: Constant<Bits<8>>,
    end_of_packet: Constant<Bits<8>>,
    last_index: Constant<Bits<5>>,
    gap_end: Constant<Bits<5>>,
    input_data: DFF<Bits<8>>,
    input_strobe: DFF<Bit>,
    input_framing_error: DFF<Bit>,
    // the receiver's bit count says the idle gap is over
    input_gap: DFF<Bit>,
    input_start: DFF<Bit>,
    input_is_header: DFF<Bit>,
    out_valid: DFF<Bit>,
    in_packet: DFF<Bit>,
    aligned: DFF<Bit>,
    index: DFF<Bits<5>>,
    tick_shift: DFF<Bits<32>>,
    tick_beats: DFF<Bits<3>>,
    // tick_beats != 0, kept in a register (the output byte's select)
    tick_out: DFF<Bit>,
    pending: DFF<Bit>,
    pending_data: DFF<Bits<8>>,
    pending_last: DFF<Bit>,
    pending_error: DFF<Bit>,
    // the counter events of this clock, one bit each (`events`), from a register, each
    // set by its own test (no chain through the branches of the packet logic)
    event_bits: DFF<Bits<8>>,
    // each event's bit in `events`
    good_event: Constant<Bits<8>>,
    end_byte_event: Constant<Bits<8>>,
    framing_event: Constant<Bits<8>>,
    truncated_event: Constant<Bits<8>>,
    garbage_event: Constant<Bits<8>>,
    framing_error_event: Constant<Bits<8>>,
    resync_event: Constant<Bits<8>>,
    events_now: Signal<Local, Bits<8>>,
    // a packet's last byte arrives (no framing error), a framing error inside a packet,
    // a byte outside a packet that is not a header, a packet truncated at the idle gap
    packet_end: Signal<Local, Bit>,
    packet_framing_error: Signal<Local, Bit>,
    garbage: Signal<Local, Bit>,
    truncated: Signal<Local, Bit>,
    end_byte_good: Signal<Local, Bit>,
    tick_beats_next: Signal<Local, Bits<3>>,
    header_taken: Signal<Local, Bit>,
    pending_next: Signal<Local, Bit>,
}

impl CellDeframer {
    /// A deframer for `framing`; a packet is truncated after `idle_gap_bits` bit times of
    /// idle line (the box uses 10), 1 to [`MAX_IDLE_GAP_BITS`].
    pub fn new(framing: CellFraming, idle_gap_bits: u64) -> Self {
        assert!(
            framing.data_header != framing.event_header,
            "CellDeframer: data and event headers must differ"
        );
        assert!(
            (1..=MAX_IDLE_GAP_BITS).contains(&idle_gap_bits),
            "CellDeframer: idle gap of {idle_gap_bits} bits must be 1 to {MAX_IDLE_GAP_BITS}"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            byte_data: Default::default(),
            byte_strobe: Default::default(),
            byte_framing_error: Default::default(),
            byte_start: Default::default(),
            tick: Default::default(),
            byte_bit_count: Default::default(),
            packets: Default::default(),
            events: Default::default(),
            data_header: Constant::new(u64::from(framing.data_header).into()),
            event_header: Constant::new(u64::from(framing.event_header).into()),
            end_of_packet: Constant::new(u64::from(framing.end_of_packet).into()),
            last_index: Constant::new((PACKET_LEN as u64 - 1).into()),
            gap_end: Constant::new((BIT_COUNT_AFTER_STOP + idle_gap_bits).into()),
            input_data: Default::default(),
            input_strobe: Default::default(),
            input_framing_error: Default::default(),
            input_gap: Default::default(),
            input_start: Default::default(),
            input_is_header: Default::default(),
            out_valid: Default::default(),
            in_packet: Default::default(),
            aligned: Default::default(),
            index: Default::default(),
            tick_shift: Default::default(),
            tick_beats: Default::default(),
            tick_out: Default::default(),
            pending: Default::default(),
            pending_data: Default::default(),
            pending_last: Default::default(),
            pending_error: Default::default(),
            event_bits: Default::default(),
            good_event: counter_bit(PortCounter::PacketsGood),
            end_byte_event: counter_bit(PortCounter::RejectedEndByte),
            framing_event: counter_bit(PortCounter::RejectedFraming),
            truncated_event: counter_bit(PortCounter::RejectedTruncated),
            garbage_event: counter_bit(PortCounter::GarbageBytes),
            framing_error_event: counter_bit(PortCounter::FramingErrors),
            resync_event: counter_bit(PortCounter::Resyncs),
            events_now: Default::default(),
            packet_end: Default::default(),
            packet_framing_error: Default::default(),
            garbage: Default::default(),
            truncated: Default::default(),
            end_byte_good: Default::default(),
            tick_beats_next: Default::default(),
            header_taken: Default::default(),
            pending_next: Default::default(),
        }
    }
}

impl Logic for CellDeframer {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            input_data,
            input_strobe,
            input_framing_error,
            input_gap,
            input_start,
            input_is_header,
            out_valid,
            in_packet,
            aligned,
            index,
            tick_shift,
            tick_beats,
            tick_out,
            pending,
            pending_data,
            pending_last,
            pending_error,
            event_bits
        );
        self.input_data.d.next = self.byte_data.val();
        self.input_strobe.d.next = self.byte_strobe.val();
        self.input_framing_error.d.next = self.byte_framing_error.val();
        self.input_gap.d.next = self.byte_bit_count.val() == self.gap_end.val();
        self.input_start.d.next = self.byte_start.val();
        // the header test on the receiver's outputs, registered with the byte
        self.input_is_header.d.next = !self.byte_framing_error.val()
            & ((self.byte_data.val() == self.data_header.val())
                | (self.byte_data.val() == self.event_header.val()));
        // the next values of the output registers: `valid` is a register too
        self.tick_beats_next.next = self.tick_beats.q.val();
        self.pending_next.next = self.pending.q.val();

        // Output: the tick bytes first, then the pending cell byte.
        self.packets.valid.next = self.out_valid.q.val();
        self.packets.data.next = self.pending_data.q.val();
        self.packets.last.next = self.pending_last.q.val();
        self.packets.error.next = self.pending_error.q.val();
        if self.tick_out.q.val() {
            self.packets.data.next = self.tick_shift.q.val().get_bits::<8>(24);
            self.packets.last.next = false;
            self.packets.error.next = false;
            if self.packets.ready.val() {
                self.tick_beats_next.next = self.tick_beats.q.val() - 1;
                self.tick_shift.d.next = self.tick_shift.q.val() << 8;
            }
        } else if self.pending.q.val() & self.packets.ready.val() {
            self.pending_next.next = false;
        }
        // the time of every start edge while no tick beats go out: when a header's strobe
        // comes, it holds that header's start, since no start edge falls between a byte's
        // start and its strobe. Inside a packet or not: on a fast line the next packet's
        // header can start before the previous packet's last strobe has closed it. Not in
        // the clock a header is taken (the next start edge can come that very clock).
        self.header_taken.next =
            self.input_strobe.q.val() & !self.in_packet.q.val() & self.input_is_header.q.val();
        if self.input_start.q.val() & !self.tick_out.q.val() & !self.header_taken.val() {
            self.tick_shift.d.next = self.tick.val();
        }

        if self.input_strobe.q.val() {
            if !self.in_packet.q.val() {
                if self.input_is_header.q.val() {
                    self.in_packet.d.next = true;
                    self.index.d.next = 1.into();
                    self.tick_beats_next.next = 4.into();
                    self.pending_next.next = true;
                    self.pending_data.d.next = self.input_data.q.val();
                    self.pending_last.d.next = false;
                    self.pending_error.d.next = false;
                } else {
                    if self.aligned.q.val() {
                        self.aligned.d.next = false;
                    }
                }
            } else {
                self.pending_next.next = true;
                self.pending_data.d.next = self.input_data.q.val();
                self.pending_last.d.next = false;
                self.pending_error.d.next = false;
                self.index.d.next = self.index.q.val() + 1;
                if self.input_framing_error.q.val() {
                    self.in_packet.d.next = false;
                    self.aligned.d.next = false;
                    self.pending_last.d.next = true;
                    self.pending_error.d.next = true;
                } else if self.index.q.val() == self.last_index.val() {
                    self.in_packet.d.next = false;
                    self.pending_last.d.next = true;
                    if self.input_data.q.val() == self.end_of_packet.val() {
                        self.aligned.d.next = true;
                    } else {
                        self.aligned.d.next = false;
                        self.pending_error.d.next = true;
                    }
                }
            }
        } else if self.in_packet.q.val() & self.input_gap.q.val() {
            // truncated: close the packet with an error beat
            self.in_packet.d.next = false;
            self.aligned.d.next = false;
            self.pending_next.next = true;
            self.pending_data.d.next = 0.into();
            self.pending_last.d.next = true;
            self.pending_error.d.next = true;
        }

        if self.reset.val() {
            self.input_strobe.d.next = false;
            self.input_gap.d.next = false;
            self.input_start.d.next = false;
            self.in_packet.d.next = false;
            self.aligned.d.next = false;
            self.tick_beats_next.next = 0.into();
            self.pending_next.next = false;
        }
        self.tick_beats.d.next = self.tick_beats_next.val();
        self.tick_out.d.next = self.tick_beats_next.val() != 0;
        self.pending.d.next = self.pending_next.val();
        self.out_valid.d.next = (self.tick_beats_next.val() != 0) | self.pending_next.val();
        // the events (bit i = PortCounter i), as the branches above count them
        self.packet_end.next = self.input_strobe.q.val()
            & self.in_packet.q.val()
            & !self.input_framing_error.q.val()
            & (self.index.q.val() == self.last_index.val());
        self.end_byte_good.next = self.input_data.q.val() == self.end_of_packet.val();
        self.packet_framing_error.next =
            self.input_strobe.q.val() & self.in_packet.q.val() & self.input_framing_error.q.val();
        self.garbage.next =
            self.input_strobe.q.val() & !self.in_packet.q.val() & !self.input_is_header.q.val();
        self.truncated.next =
            !self.input_strobe.q.val() & self.in_packet.q.val() & self.input_gap.q.val();
        // (each event's bit from its `PortCounter`, ORed in: independent tests)
        self.events_now.next = 0.into();
        if self.packet_end.val() & self.end_byte_good.val() {
            self.events_now.next = self.events_now.val() | self.good_event.val();
        }
        if self.packet_end.val() & !self.end_byte_good.val() {
            self.events_now.next = self.events_now.val() | self.end_byte_event.val();
        }
        if self.packet_framing_error.val() {
            self.events_now.next = self.events_now.val() | self.framing_event.val();
        }
        if self.truncated.val() {
            self.events_now.next = self.events_now.val() | self.truncated_event.val();
        }
        if self.garbage.val() {
            self.events_now.next = self.events_now.val() | self.garbage_event.val();
        }
        if self.input_strobe.q.val() & self.input_framing_error.q.val() {
            self.events_now.next = self.events_now.val() | self.framing_error_event.val();
        }
        if (self.garbage.val() & self.aligned.q.val())
            | self.packet_framing_error.val()
            | (self.packet_end.val() & !self.end_byte_good.val())
            | self.truncated.val()
        {
            self.events_now.next = self.events_now.val() | self.resync_event.val();
        }
        self.event_bits.d.next = self.events_now.val();
        if self.reset.val() {
            self.event_bits.d.next = 0.into();
        }
        self.events.next = self.event_bits.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;
    use skinbox_protocol::{Channel, DataRepr, EventRepr};

    /// Idle gap of the tests, in bit times.
    const GAP_BITS: u64 = 10;
    /// Clocks per bit of the modelled receiver.
    const BIT: u64 = 31;

    /// What the test line delivers to the deframer.
    #[derive(Clone, Copy)]
    enum Input {
        /// A byte with its start tick.
        Byte(u8, u32),
        /// A byte whose stop bit was low.
        Broken(u8),
        /// Idle line for this many clocks.
        Idle(u64),
    }

    #[derive(Debug, Default, PartialEq)]
    struct Counts {
        good: u32,
        end_byte: u32,
        framing: u32,
        truncated: u32,
        garbage: u32,
        any_framing: u32,
        resync: u32,
    }

    /// A packet as the stream carried it: start tick, cell bytes, error flag.
    type Out = (u32, Vec<u8>, bool);

    fn run(inputs: &[Input], ready_pattern: &[bool]) -> (Vec<Out>, Counts) {
        run_with_tail(inputs, ready_pattern, 16)
    }

    /// `tail`: clocks from a byte's strobe to the next start edge the receiver can report
    /// (16 on a line at the nominal rate; 0, the same clock, on a line near the receiver's
    /// fast limit, where the stop bit's middle is sampled just before the next start edge).
    fn run_with_tail(inputs: &[Input], ready_pattern: &[bool], tail: u64) -> (Vec<Out>, Counts) {
        let framing = CellFraming::DEFAULT;
        let mut bench = Bench::new(CellDeframer::new(framing, GAP_BITS), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycles(2);
        bench.uut.reset.next = false;
        let mut counts = Counts::default();
        let mut beats: Vec<(u8, bool, bool)> = vec![];
        // the box time a clock after a start edge (the deframer registers the edge)
        let mut stamp_due: Option<u32> = None;
        // the receiver's bit count: 0 from a start edge, 10 at the stop bit's middle, one
        // more every BIT clocks after it
        let (mut bit_count, mut since_middle) = (0u64, 0u64);
        // one clock of the receiver's outputs: a start edge (and its stamp), a byte
        let mut step =
            |bench: &mut Bench<CellDeframer>, start: Option<u32>, strobe: Option<(u8, bool)>| {
                let ready = ready_pattern[bench.cycles as usize % ready_pattern.len()];
                since_middle += 1;
                if start.is_some() {
                    bit_count = 0;
                } else if strobe.is_some() {
                    (bit_count, since_middle) = (BIT_COUNT_AFTER_STOP, 0);
                } else if since_middle == BIT {
                    (bit_count, since_middle) = ((bit_count + 1) % (BIT_COUNT_MAX + 1), 0);
                }
                let u = &mut bench.uut;
                u.packets.ready.next = ready;
                u.byte_start.next = start.is_some();
                // the box time runs on; only its value a clock after a start edge matters
                u.tick.next = u64::from(stamp_due.take().unwrap_or(0xDEAD_BEEF)).into();
                stamp_due = start;
                u.byte_strobe.next = strobe.is_some();
                u.byte_bit_count.next = bit_count.into();
                if let Some((byte, broken)) = strobe {
                    u.byte_data.next = u64::from(byte).into();
                    u.byte_framing_error.next = broken;
                }
                bench.settle();
                let u = &bench.uut;
                if u.packets.valid.val() && ready {
                    beats.push((
                        u.packets.data.val().to_u8(),
                        u.packets.last.val(),
                        u.packets.error.val(),
                    ));
                }
                let events = u.events.val().to_u8();
                for (bit, count) in [
                    (0, &mut counts.good),
                    (2, &mut counts.end_byte),
                    (3, &mut counts.framing),
                    (4, &mut counts.truncated),
                    (5, &mut counts.garbage),
                    (6, &mut counts.any_framing),
                    (7, &mut counts.resync),
                ] {
                    *count += u32::from(events >> bit & 1);
                }
                assert_eq!(events & 2, 0, "the deframer drops nothing");
                bench.cycle();
            };
        // a strobe that falls in the clock of the next start edge (tail 0)
        let mut deferred: Option<(u8, bool)> = None;
        for input in inputs {
            // a byte: its start edge, 20 clocks of reception, the byte at the middle of the
            // stop bit, and the rest of the stop bit (the next start edge comes no earlier)
            let byte = match *input {
                Input::Byte(b, tick) => Some((tick, b, false)),
                Input::Broken(b) => Some((0, b, true)),
                Input::Idle(_) => None,
            };
            match *input {
                Input::Byte(..) | Input::Broken(_) => {
                    let (tick, b, broken) = byte.expect("a byte");
                    step(&mut bench, Some(tick), deferred.take());
                    for _ in 0..20 {
                        step(&mut bench, None, None);
                    }
                    if tail == 0 {
                        deferred = Some((b, broken));
                    } else {
                        step(&mut bench, None, Some((b, broken)));
                        for _ in 1..tail {
                            step(&mut bench, None, None);
                        }
                    }
                }
                Input::Idle(clocks) => {
                    if let Some(strobe) = deferred.take() {
                        step(&mut bench, None, Some(strobe));
                    }
                    for _ in 0..clocks {
                        step(&mut bench, None, None);
                    }
                }
            }
        }
        if let Some(strobe) = deferred.take() {
            step(&mut bench, None, Some(strobe));
        }
        for _ in 0..40 {
            step(&mut bench, None, None);
        }
        let mut packets = vec![];
        let mut current: Vec<u8> = vec![];
        for (data, last, error) in beats {
            current.push(data);
            if last {
                let tick = u32::from_be_bytes(current[..4].try_into().unwrap());
                packets.push((tick, current[4..].to_vec(), error));
                current.clear();
            }
        }
        assert!(current.is_empty(), "a packet without last: {current:?}");
        (packets, counts)
    }

    fn data_packet(id: u16) -> [u8; 20] {
        // payload bytes that look like headers and end bytes must not matter inside a packet
        DataRepr::from_raw(id, [0xA1, 0x55, -94, 0xA2A2, 0x55, 2, 0xA155, 0xA1, 0x55])
            .unwrap()
            .to_bytes()
    }

    fn event_packet(id: u16) -> [u8; 20] {
        EventRepr::new(id, 7, false, &[(Channel::Proximity, 0x55A1)])
            .unwrap()
            .to_bytes()
    }

    fn bytes(packet: &[u8], tick: u32) -> Vec<Input> {
        packet
            .iter()
            .enumerate()
            .map(|(i, b)| Input::Byte(*b, tick.wrapping_add(i as u32 * 313)))
            .collect()
    }

    #[test]
    fn back_to_back_packets_with_their_ticks() {
        let mut inputs = bytes(&data_packet(1), 1000);
        inputs.extend(bytes(&event_packet(2), 7000));
        inputs.extend(bytes(&data_packet(3), 0xFFFF_FFF0));
        for ready in [&[true][..], &[true, true, false], &[false, true]] {
            let (packets, counts) = run(&inputs, ready);
            assert_eq!(
                packets,
                vec![
                    (1000, data_packet(1).to_vec(), false),
                    (7000, event_packet(2).to_vec(), false),
                    (0xFFFF_FFF0, data_packet(3).to_vec(), false),
                ]
            );
            assert_eq!(
                counts,
                Counts {
                    good: 3,
                    ..Default::default()
                }
            );
        }
    }

    /// On a fast line the next header's start edge comes right at the previous packet's
    /// last strobe, before that strobe has closed the packet: the header keeps its own tick.
    #[test]
    fn a_header_starting_at_the_last_strobe_keeps_its_tick() {
        let mut inputs = bytes(&data_packet(1), 1000);
        inputs.extend(bytes(&event_packet(2), 7000));
        inputs.extend(bytes(&data_packet(3), 13000));
        for tail in [0, 1, 2, 3, 4] {
            for ready in [&[true][..], &[true, true, false], &[false, true]] {
                let (packets, counts) = run_with_tail(&inputs, ready, tail);
                assert_eq!(
                    packets,
                    vec![
                        (1000, data_packet(1).to_vec(), false),
                        (7000, event_packet(2).to_vec(), false),
                        (13000, data_packet(3).to_vec(), false),
                    ],
                    "tail {tail}, ready {ready:?}"
                );
                assert_eq!(counts.good, 3);
            }
        }
    }

    #[test]
    fn garbage_is_skipped_and_counted() {
        let mut inputs: Vec<Input> = [0x00, 0x55, 0xFF].map(|b| Input::Byte(b, 1)).to_vec();
        inputs.extend(bytes(&data_packet(9), 500));
        inputs.extend([0x13, 0x37].map(|b| Input::Byte(b, 2)));
        inputs.extend(bytes(&data_packet(10), 900));
        let (packets, counts) = run(&inputs, &[true]);
        assert_eq!(
            packets,
            vec![
                (500, data_packet(9).to_vec(), false),
                (900, data_packet(10).to_vec(), false)
            ]
        );
        // garbage before the first packet is not a loss of alignment; after a good one it is
        assert_eq!(
            counts,
            Counts {
                good: 2,
                garbage: 5,
                resync: 1,
                ..Default::default()
            }
        );
    }

    #[test]
    fn truncated_packet_is_rejected_on_an_idle_gap() {
        let mut inputs = bytes(&data_packet(4)[..11], 100);
        // with the rest of the stop bit: one bit time over the gap
        inputs.push(Input::Idle((GAP_BITS + 1) * BIT));
        inputs.extend(bytes(&data_packet(5), 20_000));
        let (packets, counts) = run(&inputs, &[true]);
        assert_eq!(packets.len(), 2);
        assert_eq!(packets[0].0, 100);
        assert!(packets[0].2, "the truncated packet ends with error");
        assert_eq!(&packets[0].1[..11], &data_packet(4)[..11]);
        assert_eq!(packets[1], (20_000, data_packet(5).to_vec(), false));
        assert_eq!(
            counts,
            Counts {
                good: 1,
                truncated: 1,
                resync: 1,
                ..Default::default()
            }
        );
    }

    #[test]
    fn idle_shorter_than_the_gap_keeps_the_packet() {
        let p = data_packet(6);
        let mut inputs = bytes(&p[..5], 100);
        // with the rest of the stop bit: more than one bit time short of the gap
        inputs.push(Input::Idle((GAP_BITS - 2) * BIT));
        inputs.extend(bytes(&p[5..], 5000));
        let (packets, counts) = run(&inputs, &[true]);
        assert_eq!(packets, vec![(100, p.to_vec(), false)]);
        assert_eq!(counts.good, 1);
    }

    #[test]
    fn framing_error_inside_a_packet_rejects_it() {
        // all-zero channels: the leftovers after the broken byte hold no header byte
        let p = DataRepr {
            cell_id: 7,
            ..Default::default()
        }
        .to_bytes();
        let mut inputs = bytes(&p[..8], 100);
        inputs.push(Input::Broken(p[8]));
        inputs.extend(bytes(&p[9..], 200)); // the rest is garbage now
        inputs.extend(bytes(&event_packet(8), 9000));
        let (packets, counts) = run(&inputs, &[true]);
        assert_eq!(packets.len(), 2);
        assert!(packets[0].2);
        assert_eq!(packets[1], (9000, event_packet(8).to_vec(), false));
        assert_eq!(counts.framing, 1);
        assert_eq!(counts.any_framing, 1);
        assert_eq!(counts.good, 1);
        assert_eq!(counts.resync, 1);
        // the 11 leftover bytes hold no header: 0xA1 and 0xA2 inside this packet come later?
        let leftover_headers = p[9..].iter().filter(|b| **b == 0xA1 || **b == 0xA2).count();
        assert_eq!(
            leftover_headers, 0,
            "test packet chosen so the leftovers are garbage"
        );
        assert_eq!(counts.garbage, 11);
    }

    #[test]
    fn wrong_end_byte_rejects_the_packet() {
        let mut p = data_packet(11);
        p[19] = 0x56;
        let mut inputs = bytes(&p, 100);
        inputs.extend(bytes(&data_packet(12), 8000));
        let (packets, counts) = run(&inputs, &[true]);
        assert_eq!(packets.len(), 2);
        assert_eq!((packets[0].1.len(), packets[0].2), (20, true));
        assert_eq!(packets[1], (8000, data_packet(12).to_vec(), false));
        assert_eq!(
            counts,
            Counts {
                good: 1,
                end_byte: 1,
                resync: 1,
                ..Default::default()
            }
        );
    }

    #[test]
    fn framing_error_while_hunting_is_garbage() {
        let mut inputs = vec![Input::Broken(0xA1)];
        inputs.extend(bytes(&data_packet(13), 50));
        let (packets, counts) = run(&inputs, &[true]);
        assert_eq!(packets, vec![(50, data_packet(13).to_vec(), false)]);
        assert_eq!(
            counts,
            Counts {
                good: 1,
                garbage: 1,
                any_framing: 1,
                ..Default::default()
            }
        );
    }
}
