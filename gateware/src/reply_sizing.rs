//! ReplySizing: the reply builder's frame length: the reply's kind registered at the
//! start, its body length a clock later (no path from the start's decision into the length
//! register).
//!
//! At a start (`start`, with the `start_*` and `accepted_*` of its clock) the kind is
//! registered, with the echo request's end (`frame_end`: the Ethernet header and the IPv4
//! total length; padding is written from there) and whether it is below the minimum frame
//! (from the total length, so no compare sits between `frame_end` and the length). A clock
//! later the body length is set: 60 bytes for an ARP reply, the request's length (at
//! least the minimum frame) for an echo reply, the acknowledgement's length by its reply.
//! Latency: `body_len` is final [`SIZING_CLOCKS`] clocks after the start, `frame_end` one.
//! Cost: the 11-bit end and length, six flags.

use crate::body_reader::BODY_ADDRESS_BITS;
use crate::hdl::*;
use skinbox_protocol::box_counters::BOX_COUNTERS_LEN;
use skinbox_protocol::command::{self, ACK_FIXED_LEN, DESTINATION_LEN};
use skinbox_protocol::link::{ETHERNET_HEADER_LEN, MIN_FRAME_LEN, PAYLOAD_AT};

/// The reply an acknowledgement carries after its fixed body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AckReplyKind {
    /// Nothing.
    None,
    /// Stream-to ok: the destination now in effect.
    Destination,
    /// Status-now ok: the box counter block.
    Counters,
}

impl AckReplyKind {
    /// Bytes after the fixed body.
    pub fn len(self) -> usize {
        match self {
            AckReplyKind::None => 0,
            AckReplyKind::Destination => DESTINATION_LEN,
            AckReplyKind::Counters => BOX_COUNTERS_LEN,
        }
    }

    /// Whether no bytes follow the fixed body.
    pub fn is_empty(self) -> bool {
        self == AckReplyKind::None
    }

    /// UDP payload length of the acknowledgement.
    pub fn payload_len(self) -> usize {
        command::HEADER_LEN + ACK_FIXED_LEN + self.len()
    }

    /// Frame length of the acknowledgement, destination MAC to the last payload byte.
    pub fn frame_len(self) -> usize {
        PAYLOAD_AT + self.payload_len()
    }
}

/// Clocks from the start to the final body length.
pub const SIZING_CLOCKS: u64 = 2;

/// The reply's length.
#[derive(LogicBlock)]
pub struct ReplySizing {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// A reply starts in this clock.
    pub start: Signal<In, Bit>,
    /// It is an ARP reply.
    pub start_arp: Signal<In, Bit>,
    /// It is an echo reply.
    pub start_echo: Signal<In, Bit>,
    /// The command was an accepted stream-to (the acknowledgement carries the destination).
    pub accepted_stream_to: Signal<In, Bit>,
    /// The command was an accepted status-now (the acknowledgement carries the counters).
    pub accepted_status_now: Signal<In, Bit>,
    /// The echo request's IPv4 total length.
    pub ip_total_length: Signal<In, Bits<16>>,
    /// The echo request's end, from the start's next clock on.
    pub frame_end: Signal<Out, Bits<BODY_ADDRESS_BITS>>,
    /// The reply's frame length.
    pub body_len: Signal<Out, Bits<BODY_ADDRESS_BITS>>,
    arp_len: Constant<Bits<BODY_ADDRESS_BITS>>,
    ack_none_len: Constant<Bits<BODY_ADDRESS_BITS>>,
    ack_destination_len: Constant<Bits<BODY_ADDRESS_BITS>>,
    ack_counters_len: Constant<Bits<BODY_ADDRESS_BITS>>,
    min_frame_len: Constant<Bits<BODY_ADDRESS_BITS>>,
    ethernet_header_len: Constant<Bits<BODY_ADDRESS_BITS>>,
    // an IPv4 total length below this makes a frame below the minimum
    min_ip_total_len: Constant<Bits<16>>,
    length: DFF<Bits<BODY_ADDRESS_BITS>>,
    request_end: DFF<Bits<BODY_ADDRESS_BITS>>,
    // the clock after a start, and the reply it started
    sizing: DFF<Bit>,
    sizing_echo: DFF<Bit>,
    start_was_arp: DFF<Bit>,
    start_was_stream_to: DFF<Bit>,
    start_was_status_now: DFF<Bit>,
    echo_short: DFF<Bit>,
}

impl Default for ReplySizing {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            start: Default::default(),
            start_arp: Default::default(),
            start_echo: Default::default(),
            accepted_stream_to: Default::default(),
            accepted_status_now: Default::default(),
            ip_total_length: Default::default(),
            frame_end: Default::default(),
            body_len: Default::default(),
            arp_len: constant(MIN_FRAME_LEN as u64),
            ack_none_len: constant(AckReplyKind::None.frame_len() as u64),
            ack_destination_len: constant(AckReplyKind::Destination.frame_len() as u64),
            ack_counters_len: constant(AckReplyKind::Counters.frame_len() as u64),
            min_frame_len: constant(MIN_FRAME_LEN as u64),
            ethernet_header_len: constant(ETHERNET_HEADER_LEN as u64),
            min_ip_total_len: constant((MIN_FRAME_LEN - ETHERNET_HEADER_LEN) as u64),
            length: Default::default(),
            request_end: Default::default(),
            sizing: Default::default(),
            sizing_echo: Default::default(),
            start_was_arp: Default::default(),
            start_was_stream_to: Default::default(),
            start_was_status_now: Default::default(),
            echo_short: Default::default(),
        }
    }
}

impl Logic for ReplySizing {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            length,
            request_end,
            sizing,
            sizing_echo,
            start_was_arp,
            start_was_stream_to,
            start_was_status_now,
            echo_short
        );
        self.sizing_echo.d.next = false;
        self.sizing.d.next = false;
        if self.start.val() {
            self.sizing.d.next = true;
            self.sizing_echo.d.next = self.start_echo.val();
            self.request_end.d.next = self.ip_total_length.val().get_bits::<BODY_ADDRESS_BITS>(0)
                + self.ethernet_header_len.val();
            // (the parser's total length is within its frame, at most 1,504: the sum above
            // does not wrap)
            self.echo_short.d.next = self.ip_total_length.val() < self.min_ip_total_len.val();
            self.start_was_arp.d.next = self.start_arp.val();
            self.start_was_stream_to.d.next = self.accepted_stream_to.val();
            self.start_was_status_now.d.next = self.accepted_status_now.val();
        }
        if self.sizing.q.val() {
            if self.start_was_arp.q.val() {
                self.length.d.next = self.arp_len.val();
            } else if self.sizing_echo.q.val() {
                self.length.d.next = self.request_end.q.val();
                if self.echo_short.q.val() {
                    self.length.d.next = self.min_frame_len.val();
                }
            } else if self.start_was_stream_to.q.val() {
                self.length.d.next = self.ack_destination_len.val();
            } else if self.start_was_status_now.q.val() {
                self.length.d.next = self.ack_counters_len.val();
            } else {
                self.length.d.next = self.ack_none_len.val();
            }
        }
        if self.reset.val() {
            self.sizing_echo.d.next = false;
            self.sizing.d.next = false;
        }
        self.frame_end.next = self.request_end.q.val();
        self.body_len.next = self.length.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Starts of every kind, echo requests of random lengths: the length is the reply's
    /// frame (ARP 60 bytes, an echo reply the request's frame or 60, an acknowledgement its
    /// header, fixed body and reply), and it holds until the next start.
    #[test]
    fn the_length_is_the_replys() {
        let mut rng = TestRng::new(0x512);
        let mut bench = Bench::new(ReplySizing::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for round in 0..200 {
            let kind = rng.next_u64() % 5;
            let total_len = 28 + rng.next_u64() % 1477;
            let u = &mut bench.uut;
            u.start.next = true;
            u.start_arp.next = kind == 0;
            u.start_echo.next = kind == 1;
            u.accepted_stream_to.next = kind == 3;
            u.accepted_status_now.next = kind == 4;
            u.ip_total_length.next = total_len.into();
            bench.cycle();
            let u = &mut bench.uut;
            u.start.next = false;
            u.ip_total_length.next = 0.into();
            assert_eq!(u.frame_end.val().to_u64(), 14 + total_len, "round {round}");
            bench.cycles(SIZING_CLOCKS - 1);
            let want = match kind {
                0 => 60,
                1 => (14 + total_len).max(60),
                2 => AckReplyKind::None.frame_len() as u64,
                3 => AckReplyKind::Destination.frame_len() as u64,
                _ => AckReplyKind::Counters.frame_len() as u64,
            };
            for _ in 0..3 {
                assert_eq!(bench.uut.body_len.val().to_u64(), want, "round {round}");
                bench.cycle();
            }
        }
    }
}
