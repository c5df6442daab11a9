//! TransmitSequence: the frame transmitter's phases: idle until a descriptor is valid,
//! then sending (the byte index counts up one per clock from 0 to the frame's last byte),
//! then the inter-frame gap, counted down before the next descriptor can be taken.
//!
//! A descriptor is taken in the clock it is `valid` while `ready` (a register of its own,
//! `!sending & gap over`, no gate between it and the arbiter's handshake); the next clock
//! is the frame's index 0. `frame_ends` is the registered test of the frame's last index
//! (`index == end_minus_one` a clock before, `end_minus_one` from the held descriptor); in
//! that clock the index goes back to 0 and the gap of `gap_clocks + 1` idle clocks
//! starts: `ready` is set again `gap_clocks + 1` clocks after the frame's last clock.
//! Latency: none from the registers to the outputs. Cost: the two phase bits, the 11-bit
//! index, the 4-bit gap counter and two flags (`ready`, `frame_ends`).

use crate::hdl::*;

/// The transmitter's phase. The gap is the first variant: the power-up state (both bits 0)
/// counts a gap out before the first frame, as a reset's idle state does not.
#[derive(Copy, Clone, Debug, PartialEq, LogicState)]
pub enum TransmitPhase {
    /// The inter-frame gap after a frame.
    Gap,
    /// A frame goes out, one byte per clock.
    Sending,
    /// Waiting for a descriptor (the reset state).
    Idle,
}

/// The transmitter's phases and its byte index.
#[derive(LogicBlock)]
pub struct TransmitSequence {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: idle, nothing sent.
    pub reset: Signal<In, Bit>,
    /// A descriptor is offered.
    pub valid: Signal<In, Bit>,
    /// The index before the frame's last one (valid from index 1 on).
    pub end_minus_one: Signal<In, Bits<11>>,
    /// A descriptor is taken in this clock if it is valid.
    pub ready: Signal<Out, Bit>,
    /// A frame goes out.
    pub sending: Signal<Out, Bit>,
    /// The index of the frame byte in this clock (0 between frames).
    pub index: Signal<Out, Bits<11>>,
    /// This clock is the frame's last.
    pub frame_ends: Signal<Out, Bit>,
    /// Sending, and not the frame's last clock: the next index is this one + 1.
    pub frame_goes_on: Signal<Out, Bit>,
    gap_clocks: Constant<Bits<4>>,
    phase: DFF<TransmitPhase>,
    byte_index: DFF<Bits<11>>,
    gap: DFF<Bits<4>>,
    idle: DFF<Bit>,
    last: DFF<Bit>,
}

impl TransmitSequence {
    /// A sequence whose gap is `gap_clocks + 1` clocks.
    pub fn new(gap_clocks: u64) -> Self {
        Self {
            clock: Default::default(),
            reset: Default::default(),
            valid: Default::default(),
            end_minus_one: Default::default(),
            ready: Default::default(),
            sending: Default::default(),
            index: Default::default(),
            frame_ends: Default::default(),
            frame_goes_on: Default::default(),
            gap_clocks: constant(gap_clocks),
            phase: Default::default(),
            byte_index: Default::default(),
            gap: Default::default(),
            idle: Default::default(),
            last: Default::default(),
        }
    }
}

impl Logic for TransmitSequence {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, phase, byte_index, gap, idle, last);
        self.sending.next = self.phase.q.val() == TransmitPhase::Sending;
        self.frame_goes_on.next = self.sending.val() & !self.last.q.val();
        self.last.d.next =
            self.sending.val() & (self.byte_index.q.val() == self.end_minus_one.val());
        // `ready` of the next clock: a frame goes on or ends (then the gap starts), the gap's
        // last clock, or idle and no descriptor taken
        self.idle.d.next = false;
        match self.phase.q.val() {
            TransmitPhase::Sending => {
                self.byte_index.d.next = self.byte_index.q.val() + 1;
                // the frame's last clock: the index is back at 0 for the next frame
                if self.last.q.val() {
                    self.phase.d.next = TransmitPhase::Gap;
                    self.byte_index.d.next = 0.into();
                    self.gap.d.next = self.gap_clocks.val();
                }
            }
            TransmitPhase::Gap => {
                self.gap.d.next = self.gap.q.val() - 1;
                self.idle.d.next = self.gap.q.val() == 1;
                if self.gap.q.val() == 1 {
                    self.phase.d.next = TransmitPhase::Idle;
                }
            }
            TransmitPhase::Idle => {
                self.idle.d.next = !self.valid.val();
                if self.valid.val() {
                    self.phase.d.next = TransmitPhase::Sending;
                }
            }
        }
        if self.reset.val() {
            self.idle.d.next = true;
            self.phase.d.next = TransmitPhase::Idle;
            self.last.d.next = false;
            self.gap.d.next = 0.into();
            self.byte_index.d.next = 0.into();
        }
        self.ready.next = self.idle.q.val();
        self.index.next = self.byte_index.q.val();
        self.frame_ends.next = self.last.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;

    /// Frames of random lengths, descriptors offered at random: each is taken while
    /// `ready`, its indices run 0 to its end, and `ready` comes back after the gap.
    #[test]
    fn frames_run_their_indices_and_the_gap_follows() {
        const GAP: u64 = 11;
        let mut bench = Bench::new(TransmitSequence::new(GAP), |b| &mut b.clock);
        let mut rng = crate::testbench::TestRng::new(0x5E9);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        let mut last_end: Option<u64> = None;
        for round in 0..50 {
            let len = 10 + rng.next_u64() % 200;
            // offered after a random wait
            let wait = rng.next_u64() % 4;
            let mut clock = 0u64;
            let mut ready_at = None;
            loop {
                let u = &mut bench.uut;
                u.valid.next = clock >= wait;
                u.end_minus_one.next = (len - 2).into();
                bench.settle();
                let u = &bench.uut;
                assert!(!u.sending.val(), "round {round}");
                assert_eq!(u.index.val().to_u64(), 0);
                if u.ready.val() && ready_at.is_none() {
                    ready_at = Some(clock);
                }
                let taken = u.ready.val() && u.valid.val();
                bench.cycle();
                clock += 1;
                if taken {
                    break;
                }
            }
            if let Some(gap) = last_end {
                assert_eq!(gap + ready_at.unwrap(), GAP + 1, "round {round}");
            }
            bench.uut.valid.next = false;
            for i in 0..len {
                bench.settle();
                let u = &bench.uut;
                assert!(u.sending.val() && !u.ready.val(), "round {round}");
                assert_eq!(u.index.val().to_u64(), i, "round {round}");
                assert_eq!(u.frame_ends.val(), i == len - 1, "round {round} index {i}");
                assert_eq!(u.frame_goes_on.val(), i != len - 1);
                bench.cycle();
            }
            // clocks of the gap already counted when the next descriptor is looked at
            last_end = Some(1);
        }
    }
}
