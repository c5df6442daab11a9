//! DownlinkFrameTimer: the one bit time and frame that every downlink pin shares.
//!
//! A phase accumulator (31.25 clocks a bit at 4 Mbit/s) carries at each bit's end
//! (`bit_end`, one clock); the frame counts [`frame_bits`] bits (start, eight data bits,
//! stop; a second stop bit above [`TEN_BIT_FRAME_PORTS`] ports). What the next bit is gets
//! decoded a clock after the bit changes (a bit lasts at least four clocks: the clock is
//! at least 4 x baud), so the pins' next values hang off registers; `take_start`,
//! `take_data` and `take_stop` are high in the clock after a bit's end, a clock ahead of
//! the pins, saying which kind of bit the pins take at that edge. Every pin of
//! [`crate::cell_downlink::CellDownlink`] changes at those edges ([`bit_start`]).

use crate::hdl::*;
use crate::uart_rx::{phase_increment, PHASE_BITS};

/// Most ports whose refill fits the two stop and start bit times of a 10-bit frame; more
/// ports get a second stop bit.
pub const TEN_BIT_FRAME_PORTS: usize = 56;

/// Bits of a frame on every pin: start, eight data, one stop bit (two above
/// [`TEN_BIT_FRAME_PORTS`] ports).
pub fn frame_bits(ports: usize) -> u64 {
    if ports <= TEN_BIT_FRAME_PORTS {
        10
    } else {
        11
    }
}

/// Clock edges from tick 0 to the start of bit `bit` of the shared frames (counting the
/// bits of every frame, from frame 0's start bit): `ceil((bit + 1) * 2^16 / increment)`,
/// where the accumulator carries. A pin changes at such an edge (it is seen from that
/// tick on).
pub fn bit_start(clock_hz: u64, baud: u64, bit: u64) -> u64 {
    ((bit + 1) << PHASE_BITS).div_ceil(phase_increment(clock_hz, baud)) + 1
}

/// The shared bit time and frame of a downlink of N ports.
#[derive(LogicBlock)]
pub struct DownlinkFrameTimer {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset: the frame restarts (its first bit is a start bit).
    pub reset: Signal<In, Bit>,
    /// High for one clock at each bit's end (the accumulator's carry).
    pub bit_end: Signal<Out, Bit>,
    /// The bit now ending is followed by a start bit: the pins take it at the next edge.
    pub take_start: Signal<Out, Bit>,
    /// ... by a data bit.
    pub take_data: Signal<Out, Bit>,
    /// ... by a stop bit.
    pub take_stop: Signal<Out, Bit>,
    /// The bit after the current one is a data bit.
    pub next_is_data: Signal<Out, Bit>,
    /// Which data bit it is (0 first).
    pub next_data_bit: Signal<Out, Bits<3>>,
    /// It is the last data bit.
    pub next_is_last_data: Signal<Out, Bit>,
    phase_increment: Constant<Bits<17>>,
    last_frame_bit: Constant<Bits<4>>,
    // the accumulator with its carry on top, and the bit on the pins
    phase: DFF<Bits<17>>,
    frame_bit: DFF<Bits<4>>,
    // decoded from `frame_bit` a clock after it changes: start bit or data bit, which data
    // bit, the last data bit
    next_is_start: DFF<Bit>,
    next_data: DFF<Bit>,
    next_data_index: DFF<Bits<3>>,
    next_last_data: DFF<Bit>,
    // the bit's end and what the pins take then, a clock ahead (from the accumulator's
    // sum as it is written)
    phase_sum: Signal<Local, Bits<17>>,
    pins_take_start: DFF<Bit>,
    pins_take_data: DFF<Bit>,
    pins_take_stop: DFF<Bit>,
    next_bit: Signal<Local, Bits<4>>,
    data_bit: Signal<Local, Bits<3>>,
}

impl DownlinkFrameTimer {
    /// The frame of `ports` pins at `baud` with a `clock_hz` box clock (at least 4 x baud).
    pub fn new(ports: usize, clock_hz: u64, baud: u64) -> Self {
        assert!(
            baud > 0 && clock_hz >= 4 * baud,
            "DownlinkFrameTimer: clock {clock_hz} Hz must be at least 4 x baud {baud}"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            bit_end: Default::default(),
            take_start: Default::default(),
            take_data: Default::default(),
            take_stop: Default::default(),
            next_is_data: Default::default(),
            next_data_bit: Default::default(),
            next_is_last_data: Default::default(),
            phase_increment: Constant::new(phase_increment(clock_hz, baud).into()),
            last_frame_bit: Constant::new((frame_bits(ports) - 1).into()),
            phase: Default::default(),
            frame_bit: Default::default(),
            next_is_start: Default::default(),
            next_data: Default::default(),
            next_data_index: Default::default(),
            next_last_data: Default::default(),
            phase_sum: Default::default(),
            pins_take_start: Default::default(),
            pins_take_data: Default::default(),
            pins_take_stop: Default::default(),
            next_bit: Default::default(),
            data_bit: Default::default(),
        }
    }
}

impl Logic for DownlinkFrameTimer {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            phase,
            frame_bit,
            next_is_start,
            next_data,
            next_data_index,
            next_last_data,
            pins_take_start,
            pins_take_data,
            pins_take_stop
        );
        self.bit_end.next = self.phase.q.val().get_bit(16);
        self.phase_sum.next =
            bit_cast::<17, 16>(self.phase.q.val().get_bits::<16>(0)) + self.phase_increment.val();
        self.phase.d.next = self.phase_sum.val();
        // (the decodes are those of the bit now: they change two clocks after a bit's end)
        self.pins_take_start.d.next = self.phase_sum.val().get_bit(16) & self.next_is_start.q.val();
        self.pins_take_data.d.next = self.phase_sum.val().get_bit(16) & self.next_data.q.val();
        self.pins_take_stop.d.next = self.phase_sum.val().get_bit(16)
            & !self.next_is_start.q.val()
            & !self.next_data.q.val();
        self.next_bit.next = self.frame_bit.q.val() + 1;
        if self.frame_bit.q.val() == self.last_frame_bit.val() {
            self.next_bit.next = 0.into();
        }
        self.data_bit.next = self.next_bit.val().get_bits::<3>(0) - 1;
        self.next_is_start.d.next = self.next_bit.val() == 0;
        self.next_data.d.next = (self.next_bit.val() != 0) & (self.next_bit.val() <= 8);
        self.next_data_index.d.next = self.data_bit.val();
        self.next_last_data.d.next = self.next_bit.val() == 8;
        if self.phase.q.val().get_bit(16) {
            self.frame_bit.d.next = self.next_bit.val();
        }
        self.take_start.next = self.pins_take_start.q.val();
        self.take_data.next = self.pins_take_data.q.val();
        self.take_stop.next = self.pins_take_stop.q.val();
        self.next_is_data.next = self.next_data.q.val();
        self.next_data_bit.next = self.next_data_index.q.val();
        self.next_is_last_data.next = self.next_last_data.q.val();
        if self.reset.val() {
            self.phase.d.next = 0.into();
            self.pins_take_start.d.next = false;
            self.pins_take_data.d.next = false;
            self.pins_take_stop.d.next = false;
            self.frame_bit.d.next = self.last_frame_bit.val();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::Bench;
    use crate::{CELL_BAUD, CLOCK_HZ};

    /// The takes come as far apart as the bits' starts [`bit_start`] names, in the
    /// frame's order: a start bit, eight data bits (numbered 0 to 7), the stop bits.
    #[test]
    fn bits_start_at_the_named_edges_in_frame_order() {
        for ports in [8, 64] {
            let mut bench = Bench::new(DownlinkFrameTimer::new(ports, CLOCK_HZ, CELL_BAUD), |b| {
                &mut b.clock
            });
            bench.uut.reset.next = true;
            bench.cycle();
            bench.uut.reset.next = false;
            let mut first_take = None;
            let bits = frame_bits(ports);
            let mut bit = 0;
            let mut data_bit = 0u64;
            while bit < 3 * bits {
                bench.cycle();
                let uut = &bench.uut;
                let takes = [
                    uut.take_start.val(),
                    uut.take_data.val(),
                    uut.take_stop.val(),
                ];
                if !takes.contains(&true) {
                    continue;
                }
                assert_eq!(takes.iter().filter(|&&t| t).count(), 1, "one kind of bit");
                // bit after bit, the takes are as far apart as the bits' starts
                let first = *first_take.get_or_insert(bench.cycles);
                assert_eq!(
                    bench.cycles - first,
                    bit_start(CLOCK_HZ, CELL_BAUD, bit) - bit_start(CLOCK_HZ, CELL_BAUD, 0),
                    "{ports} ports: bit {bit}"
                );
                let in_frame = bit % bits;
                let kind = match in_frame {
                    0 => 0,
                    1..=8 => 1,
                    _ => 2,
                };
                assert!(takes[kind], "{ports} ports: bit {in_frame} of the frame");
                if kind == 1 {
                    data_bit += 1;
                }
                bit += 1;
            }
            assert_eq!(data_bit, 3 * 8);
        }
    }
}
