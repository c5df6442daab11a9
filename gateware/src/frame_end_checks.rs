//! FrameEndChecks: the frame parser's checks at a frame's end, staged for the rule table.
//!
//! At the registered last beat (`beat_valid & beat_last`) its error flags, whether the frame
//! was stored and whether the IPv4 packet fit the frame (the IPv4 layer's `fits`) are
//! held (they are the outputs); a clock later the two compares of the IPv4 total length
//! are registered (at least the IPv4 and transport headers, at least up to the command's
//! arguments), and `check` is high for that one clock: [`CHECK_LATENCY`] clocks after the
//! registered last beat. The flags hold until the next frame's end, the compares until
//! the next frame's total length. Cost: eight flip-flops and two 16-bit compares.

use crate::hdl::*;
use skinbox_protocol::command::ARGUMENTS_AT;
use skinbox_protocol::link::{IPV4_AT, PAYLOAD_AT};

/// Clocks from the registered last beat to `check`.
pub const CHECK_LATENCY: u64 = 2;

/// The checks of a frame's end.
#[derive(LogicBlock)]
pub struct FrameEndChecks {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: no check.
    pub reset: Signal<In, Bit>,
    /// The registered beat is valid.
    pub beat_valid: Signal<In, Bit>,
    /// It is its frame's last.
    pub beat_last: Signal<In, Bit>,
    /// Its FCS error flag.
    pub beat_error: Signal<In, Bit>,
    /// Its length error flag.
    pub beat_length_error: Signal<In, Bit>,
    /// The frame is stored.
    pub stored: Signal<In, Bit>,
    /// The IPv4 packet fits the frame (valid with the last beat).
    pub fits: Signal<In, Bit>,
    /// The IPv4 total length (valid a clock after the last beat).
    pub total_length: Signal<In, Bits<16>>,
    /// The checks below are the frame's (one clock).
    pub check: Signal<Out, Bit>,
    /// The frame's length was wrong.
    pub bad_length: Signal<Out, Bit>,
    /// The frame's FCS was wrong.
    pub bad_fcs: Signal<Out, Bit>,
    /// The frame was stored (from a clock before `check`).
    pub end_stored: Signal<Out, Bit>,
    /// The IPv4 packet fit the frame.
    pub packet_fits: Signal<Out, Bit>,
    /// The total length covers the IPv4 and transport headers.
    pub total_from_28: Signal<Out, Bit>,
    /// The total length covers the command's header up to its arguments.
    pub total_from_52: Signal<Out, Bit>,
    ip_and_transport_header_len: Constant<Bits<16>>,
    ip_to_arguments_len: Constant<Bits<16>>,
    // end of frame
    end_length_error: DFF<Bit>,
    end_error: DFF<Bit>,
    stored_at_end: DFF<Bit>,
    end_fits: DFF<Bit>,
    // stage 1: compares
    p1: DFF<Bit>,
    p2: DFF<Bit>,
    s1_total_from_28: DFF<Bit>,
    s1_total_from_52: DFF<Bit>,
}

impl Default for FrameEndChecks {
    fn default() -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            beat_valid: Default::default(),
            beat_last: Default::default(),
            beat_error: Default::default(),
            beat_length_error: Default::default(),
            stored: Default::default(),
            fits: Default::default(),
            total_length: Default::default(),
            check: Default::default(),
            bad_length: Default::default(),
            bad_fcs: Default::default(),
            end_stored: Default::default(),
            packet_fits: Default::default(),
            total_from_28: Default::default(),
            total_from_52: Default::default(),
            ip_and_transport_header_len: constant((PAYLOAD_AT - IPV4_AT) as u64),
            ip_to_arguments_len: constant((ARGUMENTS_AT - IPV4_AT) as u64),
            end_length_error: Default::default(),
            end_error: Default::default(),
            stored_at_end: Default::default(),
            end_fits: Default::default(),
            p1: Default::default(),
            p2: Default::default(),
            s1_total_from_28: Default::default(),
            s1_total_from_52: Default::default(),
        }
    }
}

impl Logic for FrameEndChecks {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            end_length_error,
            end_error,
            stored_at_end,
            end_fits,
            p1,
            p2,
            s1_total_from_28,
            s1_total_from_52
        );
        if self.beat_valid.val() & self.beat_last.val() {
            self.end_length_error.d.next = self.beat_length_error.val();
            self.end_error.d.next = self.beat_error.val();
            self.stored_at_end.d.next = self.stored.val();
            self.end_fits.d.next = self.fits.val();
        }
        // stage 1 (the clock after the last beat was registered): compares
        self.p1.d.next = self.beat_valid.val() & self.beat_last.val();
        self.p2.d.next = self.p1.q.val();
        self.s1_total_from_28.d.next =
            self.total_length.val() >= self.ip_and_transport_header_len.val();
        self.s1_total_from_52.d.next = self.total_length.val() >= self.ip_to_arguments_len.val();
        if self.reset.val() {
            self.p1.d.next = false;
            self.p2.d.next = false;
        }
        self.check.next = self.p2.q.val();
        self.bad_length.next = self.end_length_error.q.val();
        self.bad_fcs.next = self.end_error.q.val();
        self.end_stored.next = self.stored_at_end.q.val();
        self.packet_fits.next = self.end_fits.q.val();
        self.total_from_28.next = self.s1_total_from_28.q.val();
        self.total_from_52.next = self.s1_total_from_52.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};

    /// Frame ends with random flags and total lengths: `check` comes [`CHECK_LATENCY`]
    /// clocks after the last beat, for one clock, with the frame's flags and compares.
    #[test]
    fn checks_stand_at_check_with_the_frames_flags() {
        let mut rng = TestRng::new(0xE9D);
        let mut bench = Bench::new(FrameEndChecks::default(), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        for round in 0..200 {
            let flags: [bool; 4] = std::array::from_fn(|_| rng.chance(0.5));
            let total_length = rng.next_u64() % 80;
            let u = &mut bench.uut;
            u.beat_valid.next = true;
            u.beat_last.next = true;
            u.beat_length_error.next = flags[0];
            u.beat_error.next = flags[1];
            u.stored.next = flags[2];
            u.fits.next = flags[3];
            bench.cycle();
            let u = &mut bench.uut;
            u.beat_valid.next = false;
            u.beat_last.next = false;
            u.beat_length_error.next = !flags[0];
            u.beat_error.next = !flags[1];
            u.stored.next = !flags[2];
            u.fits.next = !flags[3];
            u.total_length.next = total_length.into();
            assert!(!u.check.val());
            bench.cycles(CHECK_LATENCY - 1);
            let u = &bench.uut;
            assert!(u.check.val(), "round {round}");
            assert_eq!(u.bad_length.val(), flags[0], "round {round}");
            assert_eq!(u.bad_fcs.val(), flags[1], "round {round}");
            assert_eq!(u.end_stored.val(), flags[2], "round {round}");
            assert_eq!(u.packet_fits.val(), flags[3], "round {round}");
            assert_eq!(u.total_from_28.val(), total_length >= 28, "round {round}");
            assert_eq!(u.total_from_52.val(), total_length >= 52, "round {round}");
            bench.cycle();
            assert!(!bench.uut.check.val(), "round {round}");
        }
    }
}
