//! UartRx: receives 8N1 bytes from one asynchronous UART pin.
//!
//! - Two-flop synchroniser, then a falling-edge detector.
//! - Fractional baud generator: a 16-bit phase accumulator adds `2^16 * baud / clock` per
//!   clock (2097 for 4 Mbit/s at 125 MHz, 31.25 clocks per bit: an integer divider would
//!   be 0.8 % off before any cell clock error). Its carry marks the middle of each bit; the
//!   accumulator is kept a clock ahead with that carry in a register, so no carry chain
//!   feeds the receiver's decisions. It
//!   runs on while the line is idle, and `bit_count` counts the bit middles since the last
//!   start edge: 10 after the stop bit's, one more per idle bit time (so the deframer needs
//!   no idle timer of its own).
//! - At each bit middle, the majority of the last three synchronised samples is taken, so a
//!   single-sample spike inside a bit is absorbed.
//! - Start-bit validation: if the middle of the start bit reads high, the falling edge was a
//!   glitch (shorter than half a bit) and the receiver goes back to idle.
//! - Stop-bit check: a low stop bit sets `framing_error` with the byte.
//!
//! Outputs: `data` with a one-clock `strobe` at the middle of the stop bit, `framing_error`
//! with it, and a one-clock `start` when a start edge is detected, [`START_LATENCY_TICKS`]
//! after the first clock edge that sampled the start bit low (the true falling edge lies
//! within the tick before that edge): the deframer stamps its packets with that edge's tick
//! (`TimestampCounter::start_stamp`). The receiver keeps no time itself: the deframer captures it, once per packet. Baud
//! tolerance measured by the tests: +-4.75 % (8N1 with mid-bit sampling allows about 5 %).

use crate::hdl::*;

/// Fraction bits of the baud phase accumulator.
pub const PHASE_BITS: usize = 16;

/// Ticks from the first edge that samples the pin low to the detection of the edge (`start`):
/// the synchroniser's second flop.
pub const START_LATENCY_TICKS: u64 = 1;

/// Phase accumulator value right after a start edge is detected: half a bit, so the
/// accumulator carries near each bit middle (the detection latency of two clocks and the
/// majority window, centred one clock before the carry, cancel out; the tolerance tests
/// check that the window is centred).
pub const PHASE_START: u64 = 1 << (PHASE_BITS - 1);

/// Phase added per clock: `2^PHASE_BITS * baud / clock`, rounded (2097 for 4 Mbit/s at
/// 125 MHz).
pub fn phase_increment(clock_hz: u64, baud: u64) -> u64 {
    ((1u64 << PHASE_BITS) as f64 * baud as f64 / clock_hz as f64).round() as u64
}

/// `bit_count` after the stop bit's middle, and after a glitch's start-bit middle: idle bit
/// times count on from here.
pub const BIT_COUNT_AFTER_STOP: u64 = 10;

/// Largest `bit_count` (it wraps to 0 after it).
pub const BIT_COUNT_MAX: u64 = 31;

/// UART receiver for one pin.
#[derive(LogicBlock)]
pub struct UartRx {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// The UART pin, asynchronous, idle high.
    pub rx: Signal<In, Bit>,
    /// Received byte, valid with `strobe` (the shift register, which holds it until the
    /// next byte's first data bit).
    pub data: Signal<Out, Bits<8>>,
    /// High for one clock when a byte is complete.
    pub strobe: Signal<Out, Bit>,
    /// With `strobe`: the stop bit was low.
    pub framing_error: Signal<Out, Bit>,
    /// High for one clock when a start edge is detected, [`START_LATENCY_TICKS`] after
    /// the first edge that sampled the pin low.
    pub start: Signal<Out, Bit>,
    /// Bit middles since the last start edge: [`BIT_COUNT_AFTER_STOP`] after the stop bit
    /// (or a glitch), then one more per idle bit time, wrapping after [`BIT_COUNT_MAX`].
    pub bit_count: Signal<Out, Bits<5>>,
    phase_increment: Constant<Bits<17>>,
    phase_start_ahead: Constant<Bits<17>>,
    after_stop: Constant<Bits<5>>,
    sync_meta: DFF<Bit>,
    sync_stable: DFF<Bit>,
    sync_previous: DFF<Bit>,
    history: DFF<Bits<2>>,
    receiving: DFF<Bit>,
    /// The accumulator one clock ahead, with that addition's carry on top: bit 16 is the
    /// bit middle, straight from a register.
    phase_ahead: DFF<Bits<17>>,
    bit_index: DFF<Bits<5>>,
    shift: DFF<Bits<8>>,
    strobe_out: DFF<Bit>,
    framing_error_out: DFF<Bit>,
    start_edge: Signal<Local, Bit>,
    phase_sum: Signal<Local, Bits<17>>,
    majority: Signal<Local, Bit>,
    middle: Signal<Local, Bit>,
}

impl UartRx {
    /// A receiver for `baud` with a `clock_hz` box clock. Panics when the clock is below
    /// four times the baud rate (the majority window would span most of a bit).
    pub fn new(clock_hz: u64, baud: u64) -> Self {
        assert!(
            baud > 0 && clock_hz >= 4 * baud,
            "UartRx: clock {clock_hz} Hz must be at least 4 x baud {baud}"
        );
        let increment = phase_increment(clock_hz, baud);
        let start = PHASE_START;
        Self {
            clock: Default::default(),
            reset: Default::default(),
            rx: Default::default(),
            data: Default::default(),
            strobe: Default::default(),
            framing_error: Default::default(),
            start: Default::default(),
            bit_count: Default::default(),
            phase_increment: Constant::new(increment.into()),
            phase_start_ahead: Constant::new((start + increment).into()),
            after_stop: Constant::new(BIT_COUNT_AFTER_STOP.into()),
            sync_meta: Default::default(),
            sync_stable: Default::default(),
            sync_previous: Default::default(),
            history: Default::default(),
            receiving: Default::default(),
            phase_ahead: Default::default(),
            bit_index: Default::default(),
            shift: Default::default(),
            strobe_out: Default::default(),
            framing_error_out: Default::default(),
            start_edge: Default::default(),
            phase_sum: Default::default(),
            majority: Default::default(),
            middle: Default::default(),
        }
    }
}

impl Logic for UartRx {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            sync_meta,
            sync_stable,
            sync_previous,
            history,
            receiving,
            phase_ahead,
            bit_index,
            shift,
            strobe_out,
            framing_error_out
        );
        self.sync_meta.d.next = self.rx.val();
        self.sync_stable.d.next = self.sync_meta.q.val();
        self.sync_previous.d.next = self.sync_stable.q.val();
        self.history.d.next =
            (self.history.q.val() << 1) | bit_cast::<2, 1>(self.sync_stable.q.val().into());
        self.majority.next = (self.sync_stable.q.val() & self.history.q.val().get_bit(0))
            | (self.sync_stable.q.val() & self.history.q.val().get_bit(1))
            | (self.history.q.val().get_bit(0) & self.history.q.val().get_bit(1));
        // the accumulator runs on when idle: its carries count idle bit times
        self.middle.next = self.phase_ahead.q.val().get_bit(16);
        self.phase_sum.next = bit_cast::<17, 16>(self.phase_ahead.q.val().get_bits::<16>(0))
            + self.phase_increment.val();
        self.phase_ahead.d.next = self.phase_sum.val();
        if self.middle.val() {
            self.bit_index.d.next = self.bit_index.q.val() + 1;
        }
        self.start_edge.next =
            !self.receiving.q.val() & self.sync_previous.q.val() & !self.sync_stable.q.val();
        if self.start_edge.val() {
            self.receiving.d.next = true;
            self.phase_ahead.d.next = self.phase_start_ahead.val();
            self.bit_index.d.next = 0.into();
        }
        if self.middle.val() & self.receiving.q.val() {
            if self.bit_index.q.val() == 0 {
                // a start bit that reads high in its middle was a glitch: idle from here
                if self.majority.val() {
                    self.receiving.d.next = false;
                    self.bit_index.d.next = self.after_stop.val();
                }
            } else if self.bit_index.q.val() == 9 {
                self.receiving.d.next = false;
                self.framing_error_out.d.next = !self.majority.val();
            } else {
                self.shift.d.next = (self.shift.q.val() >> 1).replace_bit(7, self.majority.val());
            }
        }
        if self.reset.val() {
            self.receiving.d.next = false;
            self.sync_meta.d.next = true;
            self.sync_stable.d.next = true;
            self.sync_previous.d.next = true;
        }
        // the stop bit's middle, as one expression: a chain of ifs setting and clearing the
        // bit maps to a flip-flop with its own reset net (one per port), which crowds the
        // placement of a 64-port box
        self.strobe_out.d.next = self.middle.val()
            & self.receiving.q.val()
            & (self.bit_index.q.val() == 9)
            & !self.reset.val();
        self.data.next = self.shift.q.val();
        self.strobe.next = self.strobe_out.q.val();
        self.framing_error.next = self.framing_error_out.q.val();
        self.start.next = self.start_edge.val();
        self.bit_count.next = self.bit_index.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{bit_period, Bench, UartLine};
    use crate::{CELL_BAUD, CLOCK_HZ};

    /// What the receiver delivered: (byte, framing error, start tick).
    type Received = Vec<(u8, bool, u64)>;

    fn receive(line: &UartLine) -> Received {
        let mut bench = Bench::new(UartRx::new(CLOCK_HZ, CELL_BAUD), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.uut.rx.next = true;
        bench.cycles(4);
        bench.uut.reset.next = false;
        let mut out = vec![];
        // from here on edge e of the line is the bench's edge number e
        let first = bench.cycles;
        let levels = line.levels(line.end().ceil() as u64 + 100);
        // the stamp a deframer keeps: `start` is high after edge e - 1, which is
        // START_LATENCY_TICKS after the first edge that sampled the start bit low
        let mut start_tick = None;
        for e in 1..levels.len() as u64 {
            bench.uut.rx.next = levels[e as usize];
            if bench.uut.start.val() {
                start_tick = Some(e.wrapping_sub(1 + START_LATENCY_TICKS) & 0xFFFF_FFFF);
            }
            bench.cycle();
            assert_eq!(bench.cycles - first, e);
            if bench.uut.strobe.val() {
                let tick = start_tick.take().expect("a byte without a start edge");
                out.push((
                    bench.uut.data.val().to_u8(),
                    bench.uut.framing_error.val(),
                    tick,
                ));
            }
        }
        out
    }

    fn stream(bytes: &[u8], error_ppm: f64, start: f64) -> (UartLine, Received) {
        let mut line = UartLine::default();
        line.bytes(bytes, start, bit_period(error_ppm));
        let rx = receive(&line);
        (line, rx)
    }

    fn all_bytes() -> Vec<u8> {
        (0..=255).collect()
    }

    #[test]
    fn every_byte_at_exact_baud_with_its_start_tick() {
        for start in [10.0, 10.25, 10.5, 10.999] {
            let (line, rx) = stream(&all_bytes(), 0.0, start);
            let bytes: Vec<u8> = rx.iter().map(|r| r.0).collect();
            assert_eq!(bytes, all_bytes(), "start {start}");
            assert!(rx.iter().all(|r| !r.1), "no framing error");
            for (r, t) in rx.iter().zip(&line.frame_starts) {
                // the first edge at or after the true falling edge
                assert_eq!(r.2, t.ceil() as u64, "start tick of the frame at {t}");
            }
        }
    }

    #[test]
    fn baud_mismatch_within_4_percent_is_error_free() {
        for percent in [-4.0, -3.0, -1.0, 1.0, 3.0, 4.0] {
            for start in [20.0, 20.5] {
                let (_, rx) = stream(&all_bytes(), percent * 1e4, start);
                let bytes: Vec<u8> = rx.iter().map(|r| r.0).collect();
                assert_eq!(bytes, all_bytes(), "{percent} % start {start}");
                assert!(rx.iter().all(|r| !r.1), "{percent} %: framing error");
            }
        }
    }

    /// The largest error (in 0.25 % steps from 3.5 %) at which every byte arrives intact.
    fn tolerance(sign: f64) -> f64 {
        // the bytes that stress bit timing most: long runs and every single-bit change
        let bytes: Vec<u8> = [0x00, 0xFF, 0x55, 0xAA, 0x0F, 0xF0]
            .into_iter()
            .chain((0..8).map(|i| 1 << i))
            .chain((0..8).map(|i| !(1 << i)))
            .collect();
        let mut ok = 0.0;
        for step in 14..=40 {
            let percent = step as f64 * 0.25;
            let clean = [0.0, 0.3, 0.6].iter().all(|start| {
                let (_, rx) = stream(&bytes, sign * percent * 1e4, 30.0 + start);
                rx.len() == bytes.len() && rx.iter().zip(&bytes).all(|(r, b)| r.0 == *b && !r.1)
            });
            if !clean {
                break;
            }
            ok = percent;
        }
        ok
    }

    #[test]
    fn baud_tolerance_is_symmetric_and_beyond_4_percent() {
        let (fast, slow) = (tolerance(1.0), tolerance(-1.0));
        eprintln!("UartRx tolerance: +{fast} % / -{slow} %");
        assert!(fast >= 4.0 && slow >= 4.0, "+{fast} % / -{slow} %");
        assert!((fast - slow).abs() <= 0.5, "centred: +{fast} % / -{slow} %");
        assert!(fast < 7.0 && slow < 7.0, "8N1 cannot exceed ~5 %");
    }

    #[test]
    fn far_beyond_tolerance_bytes_are_flagged_not_silently_wrong_in_bulk() {
        // at 8 % slow, the stop bit of most bytes is sampled in the next start bit
        let (_, rx) = stream(&[0x00; 64], -8e4, 10.0);
        let flagged = rx.iter().filter(|r| r.1).count();
        assert!(flagged * 2 > rx.len(), "{flagged} of {} flagged", rx.len());
    }

    #[test]
    fn bit_count_counts_idle_bit_times_after_the_stop_bit_and_a_glitch() {
        let p = bit_period(0.0);
        let mut line = UartLine::default();
        let end = line.bytes(&[0x5A], 20.0, p);
        // a glitch (high again before the start bit's middle) long after the byte
        let glitch = end + 40.0 * p;
        line.force(glitch, glitch + 5.0, false);
        let mut bench = Bench::new(UartRx::new(CLOCK_HZ, CELL_BAUD), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.uut.rx.next = true;
        bench.cycles(4);
        bench.uut.reset.next = false;
        let first = bench.cycles;
        let levels = line.levels((glitch + 20.0 * p) as u64);
        // (edge, bit count) at every change of the count
        let mut changes = vec![];
        let mut count = bench.uut.bit_count.val().to_u64();
        for (e, level) in levels.iter().enumerate().skip(1) {
            bench.uut.rx.next = *level;
            bench.cycle();
            assert_eq!(bench.cycles - first, e as u64);
            let now = bench.uut.bit_count.val().to_u64();
            if now != count {
                changes.push((e as f64, now));
                count = now;
            }
        }
        let stop = changes
            .iter()
            .position(|c| c.1 == BIT_COUNT_AFTER_STOP)
            .expect("the stop bit's middle");
        // 9.5 bits after the start edge, then one more per bit time, wrapping after 31
        assert!(
            (changes[stop].0 - (20.0 + 9.5 * p)).abs() < 3.0,
            "{changes:?}"
        );
        for (k, c) in changes[stop + 1..].iter().take(30).enumerate() {
            let k = k as u64 + 1;
            assert_eq!(
                c.1,
                (BIT_COUNT_AFTER_STOP + k) % (BIT_COUNT_MAX + 1),
                "{changes:?}"
            );
            let at = 20.0 + (9.5 + k as f64) * p;
            assert!(
                (c.0 - at).abs() < 3.0,
                "idle bit {k} at {}: {changes:?}",
                c.0
            );
        }
        // the glitch restarts the count (0 at its edge), then sets it to the stop value at
        // its start bit's middle, from where idle bit times count on
        let restart = changes.iter().rposition(|c| c.1 == 0).expect("restart");
        assert!((changes[restart].0 - glitch).abs() < 4.0, "{changes:?}");
        assert_eq!(changes[restart + 1].1, BIT_COUNT_AFTER_STOP, "{changes:?}");
        assert!((changes[restart + 1].0 - (glitch + 0.5 * p)).abs() < 3.0);
        assert_eq!(
            changes[restart + 2].1,
            BIT_COUNT_AFTER_STOP + 1,
            "{changes:?}"
        );
        assert!((changes[restart + 2].0 - (glitch + 1.5 * p)).abs() < 3.0);
    }

    #[test]
    fn low_stop_bit_is_a_framing_error() {
        let mut line = UartLine::default();
        let p = bit_period(0.0);
        let t = line.frame(0xA1, 10.0, p, false);
        line.frame(0x55, t + 2.0 * p, p, true);
        let rx = receive(&line);
        assert_eq!(rx.len(), 2);
        assert_eq!((rx[0].0, rx[0].1), (0xA1, true));
        assert_eq!((rx[1].0, rx[1].1), (0x55, false));
    }

    #[test]
    fn glitch_on_idle_line_shorter_than_half_a_bit_starts_no_byte() {
        let p = bit_period(0.0);
        let mut line = UartLine::default();
        for (i, width) in [1.0, 3.0, 8.0, 0.45 * p].iter().enumerate() {
            let at = 100.0 + i as f64 * 3.0 * p;
            line.force(at, at + width, false);
        }
        let t = 100.0 + 12.0 * p;
        line.bytes(&[0x3C], t, p);
        let rx = receive(&line);
        assert_eq!(rx.iter().map(|r| r.0).collect::<Vec<_>>(), vec![0x3C]);
        assert_eq!(rx[0].2, t.ceil() as u64);
    }

    #[test]
    fn single_sample_spikes_inside_bits_are_absorbed() {
        let p = bit_period(0.0);
        for byte in [0x00u8, 0xFF, 0xA5, 0x5A] {
            let mut line = UartLine::default();
            line.bytes(&[byte], 50.0, p);
            // a one-clock spike of the opposite level in the middle of every data bit
            for bit in 0..8 {
                let middle = (50.0 + (1.5 + bit as f64) * p).round();
                let level = byte >> bit & 1 == 0;
                line.force(middle - 0.5, middle + 0.5, level);
            }
            let rx = receive(&line);
            assert_eq!(rx.len(), 1, "byte {byte:#04x}");
            assert_eq!((rx[0].0, rx[0].1), (byte, false), "byte {byte:#04x}");
        }
    }
}
