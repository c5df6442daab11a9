//! UartTx: sends 8N1 bytes on one UART pin, back to back.
//!
//! - The fractional baud generator of [`crate::uart_rx`]: a 16-bit phase accumulator adds
//!   [`phase_increment`] per clock, and its carry, kept in a register, ends the bit on the
//!   pin. A burst of bytes keeps one accumulator running, so the bit times do not drift from
//!   the baud rate (31.25 clocks per bit at 4 Mbit/s and 125 MHz: 31 or 32 clocks each).
//! - The pin is a register: a byte taken at a clock edge puts its start bit on the pin at
//!   that same edge ([`START_BIT_DELAY_CLOCKS`]).
//! - `bytes.ready` is high while idle and in the last clock of a stop bit, so a byte waiting
//!   goes out with no idle time after the previous one.
//!
//! [`bit_edges`] gives the clock edge of every bit of a burst, for reference models.
//! Cost (yosys `synth_ecp5` of the block alone): 69 LUT4, 9 CCU2C, 32 FF.

use crate::hdl::*;
use crate::stream::ByteStreamSink;
use crate::uart_rx::{phase_increment, PHASE_BITS};

/// Clock edges from the edge that takes a byte to the edge that puts its start bit on the
/// pin: the same edge.
pub const START_BIT_DELAY_CLOCKS: u64 = 0;

/// Bits per 8N1 frame: start, eight data bits, stop.
pub const FRAME_BITS: u64 = 10;

/// Clock edges from the start of a burst to the start of its bit `bit` (counting the bits of
/// all its frames, 10 per byte): `ceil(bit * 2^16 / increment)`.
pub fn bit_offset(increment: u64, bit: u64) -> u64 {
    (bit << PHASE_BITS).div_ceil(increment)
}

/// The pin of a burst of `bytes` whose first byte was taken at clock edge `taken` while the
/// transmitter was idle (each next byte offered before the previous stop bit ends): the
/// (edge, level) of every bit, start bits included, and the edge at which the last stop
/// bit ends (the next byte's start bit, if one is offered then, or idle).
pub fn bit_edges(clock_hz: u64, baud: u64, taken: u64, bytes: &[u8]) -> (Vec<(u64, bool)>, u64) {
    let increment = phase_increment(clock_hz, baud);
    let start = taken + START_BIT_DELAY_CLOCKS;
    let mut edges = Vec::with_capacity(bytes.len() * FRAME_BITS as usize);
    for (b, byte) in bytes.iter().enumerate() {
        let first = b as u64 * FRAME_BITS;
        let levels = std::iter::once(false)
            .chain((0..8).map(|i| byte >> i & 1 == 1))
            .chain(std::iter::once(true));
        for (i, level) in levels.enumerate() {
            edges.push((start + bit_offset(increment, first + i as u64), level));
        }
    }
    let end = start + bit_offset(increment, bytes.len() as u64 * FRAME_BITS);
    (edges, end)
}

/// UART transmitter for one pin.
#[derive(LogicBlock)]
pub struct UartTx {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the pin goes idle at once, a byte in flight is cut.
    pub reset: Signal<In, Bit>,
    /// Bytes to send (`last` and `error` are not used: every byte offered is sent).
    pub bytes: ByteStreamSink,
    /// The UART pin, idle high.
    pub tx: Signal<Out, Bit>,
    /// A frame is on the pin.
    pub busy: Signal<Out, Bit>,
    phase_increment: Constant<Bits<17>>,
    /// The accumulator with the carry of its last addition on top: bit 16 ends a bit.
    phase: DFF<Bits<17>>,
    sending: DFF<Bit>,
    /// The bit on the pin: 0 start, 1 to 8 data, 9 stop.
    bit_index: DFF<Bits<4>>,
    /// The bits still to send, LSB next, the stop bit on top.
    shift: DFF<Bits<9>>,
    pin: DFF<Bit>,
    bit_end: Signal<Local, Bit>,
    take: Signal<Local, Bit>,
}

impl UartTx {
    /// A transmitter for `baud` with a `clock_hz` box clock. Panics when the clock is below
    /// four times the baud rate.
    pub fn new(clock_hz: u64, baud: u64) -> Self {
        assert!(
            baud > 0 && clock_hz >= 4 * baud,
            "UartTx: clock {clock_hz} Hz must be at least 4 x baud {baud}"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            bytes: Default::default(),
            tx: Default::default(),
            busy: Default::default(),
            phase_increment: Constant::new(phase_increment(clock_hz, baud).into()),
            phase: Default::default(),
            sending: Default::default(),
            bit_index: Default::default(),
            shift: Default::default(),
            pin: Default::default(),
            bit_end: Default::default(),
            take: Default::default(),
        }
    }
}

impl Logic for UartTx {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(self, clock, phase, sending, bit_index, shift, pin);
        self.bit_end.next = self.phase.q.val().get_bit(16);
        self.phase.d.next =
            bit_cast::<17, 16>(self.phase.q.val().get_bits::<16>(0)) + self.phase_increment.val();
        self.bytes.ready.next =
            !self.sending.q.val() | (self.bit_end.val() & (self.bit_index.q.val() == 9));
        self.take.next = self.bytes.ready.val() & self.bytes.valid.val();
        if self.sending.q.val() & self.bit_end.val() {
            if self.bit_index.q.val() == 9 {
                self.sending.d.next = false;
            } else {
                self.pin.d.next = self.shift.q.val().get_bit(0);
                self.shift.d.next = (self.shift.q.val() >> 1).replace_bit(8, true);
                self.bit_index.d.next = self.bit_index.q.val() + 1;
            }
        }
        if self.take.val() {
            // from idle the accumulator starts afresh; in a burst it runs on
            if !self.sending.q.val() {
                self.phase.d.next = self.phase_increment.val();
            }
            self.sending.d.next = true;
            self.pin.d.next = false;
            self.bit_index.d.next = 0.into();
            self.shift.d.next = bit_cast::<9, 8>(self.bytes.data.val()).replace_bit(8, true);
        }
        if self.reset.val() {
            self.sending.d.next = false;
            self.pin.d.next = true;
        }
        self.tx.next = self.pin.q.val();
        self.busy.next = self.sending.q.val();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{bit_period, decode_uart_line as decode, Bench, TestRng};
    use crate::uart_rx::UartRx;
    use crate::{CELL_BAUD, CLOCK_HZ};

    /// The pin after every edge while `bytes` are offered as fast as taken (or with the
    /// idle gaps of `gap`: clocks to wait after a byte before offering the next), from
    /// `first_offer` edges after reset; returns (pin levels by edge, edges that took a byte).
    fn transmit(
        bytes: &[u8],
        first_offer: u64,
        gap: impl Fn(usize) -> u64,
    ) -> (Vec<bool>, Vec<u64>) {
        let mut bench = Bench::new(UartTx::new(CLOCK_HZ, CELL_BAUD), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        // levels[e]: the pin after edge e, edge 0 being the reset edge
        let mut levels = vec![bench.uut.tx.val()];
        let mut taken = vec![];
        let mut next = 0;
        let mut offer_at = first_offer;
        let end = (bytes.len() as f64 * 10.0 * bit_period(0.0)) as u64
            + (0..bytes.len()).map(&gap).sum::<u64>()
            + first_offer
            + 400;
        for e in 1..end {
            let offer = next < bytes.len() && e >= offer_at;
            bench.uut.bytes.valid.next = offer;
            bench.uut.bytes.data.next = u64::from(bytes.get(next).copied().unwrap_or(0)).into();
            bench.settle();
            let took = offer && bench.uut.bytes.ready.val();
            bench.cycle();
            if took {
                taken.push(e);
                offer_at = e + 1 + gap(next);
                next += 1;
            }
            levels.push(bench.uut.tx.val());
        }
        assert_eq!(next, bytes.len(), "every byte taken");
        (levels, taken)
    }

    #[test]
    fn bytes_decode_on_the_line_model_back_to_back_at_the_exact_bit_times() {
        let mut rng = TestRng::new(7);
        let bytes: Vec<u8> = [0x00, 0xFF, 0x55, 0xAA, 0xA5, 0x01, 0x80]
            .into_iter()
            .chain((0..57).map(|_| rng.byte()))
            .collect();
        let (levels, taken) = transmit(&bytes, 5, |_| 0);
        let got = decode(&levels);
        assert_eq!(got.iter().map(|g| g.1).collect::<Vec<_>>(), bytes);
        assert!(got.iter().all(|g| g.2), "every stop bit high");
        // back to back: frame b starts 10 b exact bit times after the first, late by less
        // than a clock (the edge is the first clock at or after the accumulator's carry) plus
        // the rounding of the increment (2097 for 2097.152: 0.007 % slow)
        let period = bit_period(0.0);
        for (b, g) in got.iter().enumerate() {
            let exact = got[0].0 as f64 + b as f64 * 10.0 * period;
            let late = g.0 as f64 - exact;
            let rounding = b as f64 * 10.0 * period * 1e-4;
            assert!(
                (0.0..=1.0 + rounding).contains(&late),
                "frame {b} at {} not {exact}",
                g.0
            );
        }
        assert_eq!(got[0].0, taken[0] + START_BIT_DELAY_CLOCKS);
        // the reference of every edge: the pin, level by level
        let (edges, end) = bit_edges(CLOCK_HZ, CELL_BAUD, taken[0], &bytes);
        let mut predicted = vec![true; levels.len()];
        for (i, &(at, level)) in edges.iter().enumerate() {
            let until = edges.get(i + 1).map_or(end, |n| n.0);
            predicted[at as usize..until as usize].fill(level);
        }
        assert_eq!(levels, predicted, "pin equals the bit_edges reference");
    }

    #[test]
    fn idle_gaps_restart_the_baud_generator_and_the_pin_idles_high() {
        let mut rng = TestRng::new(11);
        let bytes: Vec<u8> = (0..24).map(|_| rng.byte()).collect();
        let gaps: Vec<u64> = (0..24).map(|_| rng.next_u64() % 700).collect();
        let (levels, taken) = transmit(&bytes, 3, |i| gaps[i]);
        let got = decode(&levels);
        assert_eq!(got.iter().map(|g| g.1).collect::<Vec<_>>(), bytes);
        assert!(got.iter().all(|g| g.2));
        // each burst is predicted from the edge that took its first byte
        let mut predicted = vec![true; levels.len()];
        let mut b = 0;
        while b < bytes.len() {
            let mut n = 1;
            loop {
                let (_, end) = bit_edges(CLOCK_HZ, CELL_BAUD, taken[b], &bytes[b..b + n]);
                if b + n < bytes.len() && taken[b + n] == end {
                    n += 1;
                } else {
                    break;
                }
            }
            let (edges, end) = bit_edges(CLOCK_HZ, CELL_BAUD, taken[b], &bytes[b..b + n]);
            for (i, &(at, level)) in edges.iter().enumerate() {
                let until = edges.get(i + 1).map_or(end, |x| x.0);
                predicted[at as usize..until as usize].fill(level);
            }
            b += n;
        }
        assert_eq!(levels, predicted);
    }

    #[test]
    fn loop_back_into_uart_rx_receives_every_byte() {
        let mut rng = TestRng::new(3);
        let bytes: Vec<u8> = (0..=255u8).chain((0..64).map(|_| rng.byte())).collect();
        let mut tx = Bench::new(UartTx::new(CLOCK_HZ, CELL_BAUD), |b| &mut b.clock);
        let mut rx = Bench::new(UartRx::new(CLOCK_HZ, CELL_BAUD), |b| &mut b.clock);
        tx.uut.reset.next = true;
        rx.uut.reset.next = true;
        rx.uut.rx.next = true;
        tx.cycle();
        rx.cycle();
        tx.uut.reset.next = false;
        rx.uut.reset.next = false;
        let mut next = 0;
        let mut received = vec![];
        for _ in 0..(bytes.len() as u64 * 313 + 500) {
            tx.uut.bytes.valid.next = next < bytes.len();
            tx.uut.bytes.data.next = u64::from(bytes.get(next).copied().unwrap_or(0)).into();
            tx.settle();
            if next < bytes.len() && tx.uut.bytes.ready.val() {
                next += 1;
            }
            rx.uut.rx.next = tx.uut.tx.val();
            tx.cycle();
            rx.cycle();
            if rx.uut.strobe.val() {
                assert!(!rx.uut.framing_error.val());
                received.push(rx.uut.data.val().to_u8());
            }
        }
        assert_eq!(received, bytes);
    }

    #[test]
    fn reset_idles_the_pin_and_verilog_passes_lint() {
        let mut bench = Bench::new(UartTx::new(CLOCK_HZ, CELL_BAUD), |b| &mut b.clock);
        bench.uut.bytes.valid.next = true;
        bench.cycles(40);
        assert!(bench.uut.busy.val());
        bench.uut.bytes.valid.next = false;
        bench.uut.reset.next = true;
        bench.cycle();
        assert!(bench.uut.tx.val() && !bench.uut.busy.val());
        let mut uut = UartTx::new(CLOCK_HZ, CELL_BAUD);
        uut.connect_all();
        let dir = std::env::temp_dir().join(format!("skinbox-uart-tx-lint-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&generate_verilog(&uut), &dir).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}
