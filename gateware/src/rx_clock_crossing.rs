//! RxClockCrossing: the PHY's GMII receive signals, in the PHY's receive clock, into the
//! box clock, without bubbles inside a frame.
//!
//! The two clocks are both 125 MHz but from different crystals (up to +-100 ppm each by
//! IEEE 802.3), so the crossing is elastic: it may shorten or lengthen the idle gap
//! between frames, never a frame.
//!
//! Write side (receive clock): every byte of a carrier (`rx_dv`) goes into an
//! [`AsyncFifo`] as a word {end 0, `rx_er`, byte}; the clock after the carrier ends adds
//! an end word {end 1, broken, 0}. A word that finds the FIFO full is dropped and marks
//! the frame broken: its end word carries the mark (or, if the end word itself was
//! dropped, the next frame's end word does, since the two then run together).
//!
//! Read side (box clock): idle (`gmii_rx_dv` low) until [`START_LEVEL`] words are seen in
//! the FIFO, or words have waited [`START_WAIT`] clocks (a carrier shorter than
//! [`START_LEVEL`] bytes); then one word per clock: a byte word gives `gmii_rx_dv` with
//! its byte and `rx_er`; the end word gives a clock of `gmii_rx_dv` low (with a broken
//! mark: a clock of `gmii_rx_dv` and `gmii_rx_er` first) and back to idle. An empty FIFO
//! inside a frame (an underrun: the receive clock much slower than the box clock) gives a
//! clock of `gmii_rx_dv` and `gmii_rx_er` with data 0, and the frame goes on with the
//! next word; the MAC counts such a frame as bad. After [`STARVED_LIMIT`] such clocks in a
//! row (the receive clock stopped) the frame ends: `gmii_rx_dv` falls, and whatever of it
//! comes later arrives as a carrier of its own, which has no preamble and so no frame
//! (or, by chance, a frame with a bad FCS). With [`START_LEVEL`] words buffered a
//! frame of 1,526 bytes (preamble to FCS) cannot underrun until the receive clock is
//! slower by (START_LEVEL - 1) / 1526, 3,300 ppm, nor overrun the FIFO, and back-to-back
//! frames keep the FIFO from filling up as long as the 12-byte gap is longer than that
//! drift.
//!
//! The box clock's `reset` also resets the write side (through a two-flop synchroniser
//! into the receive clock). Outputs are registers in the box clock.

use crate::async_fifo::AsyncFifo;
use crate::hdl::*;

/// Words the read side waits for before it starts a frame.
pub const START_LEVEL: u64 = 6;
/// Clocks the read side waits for [`START_LEVEL`] words at most once a word is seen.
pub const START_WAIT: u64 = 12;

/// Underrun clocks in a row that end a frame (a receive clock that stopped).
pub const STARVED_LIMIT: u64 = 32;

/// Bits of a FIFO word: byte, rx_er (or broken, in an end word), end.
const WORD_BITS: usize = 10;

#[derive(Copy, Clone, Debug, PartialEq, LogicState)]
enum ReadState {
    /// Between frames (the first variant is the reset state).
    Idle,
    /// One word per clock until the end word.
    Frame,
}

/// The receive clock crossing (see the module documentation).
#[derive(LogicBlock)]
pub struct RxClockCrossing {
    /// The PHY's receive clock.
    pub rx_clock: Signal<In, Clock>,
    /// Receive data in the receive clock.
    pub rx_data: Signal<In, Bits<8>>,
    /// Receive data valid in the receive clock.
    pub rx_dv: Signal<In, Bit>,
    /// Receive error in the receive clock.
    pub rx_er: Signal<In, Bit>,
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset in the box clock (resets both sides).
    pub reset: Signal<In, Bit>,
    /// Receive data in the box clock.
    pub gmii_rxd: Signal<Out, Bits<8>>,
    /// Receive data valid in the box clock.
    pub gmii_rx_dv: Signal<Out, Bit>,
    /// Receive error in the box clock (also: an underrun or an overrun).
    pub gmii_rx_er: Signal<Out, Bit>,
    fifo: AsyncFifo<WORD_BITS>,
    // write side
    reset_meta: DFF<Bit>,
    rx_reset: DFF<Bit>,
    dv_before: DFF<Bit>,
    broken: DFF<Bit>,
    end_pending: DFF<Bit>,
    write_word: Signal<Local, Bits<WORD_BITS>>,
    write_request: Signal<Local, Bit>,
    // read side
    state: DFF<ReadState>,
    waited: DFF<Bits<5>>,
    starved: DFF<Bits<5>>,
    out_data: DFF<Bits<8>>,
    out_dv: DFF<Bit>,
    out_er: DFF<Bit>,
    start_level: Constant<Bits<5>>,
    start_wait: Constant<Bits<5>>,
}

impl Default for RxClockCrossing {
    fn default() -> Self {
        Self {
            rx_clock: Default::default(),
            rx_data: Default::default(),
            rx_dv: Default::default(),
            rx_er: Default::default(),
            clock: Default::default(),
            reset: Default::default(),
            gmii_rxd: Default::default(),
            gmii_rx_dv: Default::default(),
            gmii_rx_er: Default::default(),
            fifo: Default::default(),
            reset_meta: Default::default(),
            rx_reset: Default::default(),
            dv_before: Default::default(),
            broken: Default::default(),
            end_pending: Default::default(),
            write_word: Default::default(),
            write_request: Default::default(),
            state: Default::default(),
            waited: Default::default(),
            starved: Default::default(),
            out_data: Default::default(),
            out_dv: Default::default(),
            out_er: Default::default(),
            start_level: Constant::new(START_LEVEL.into()),
            start_wait: Constant::new(START_WAIT.into()),
        }
    }
}

impl Logic for RxClockCrossing {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            rx_clock,
            reset_meta,
            rx_reset,
            dv_before,
            broken,
            end_pending
        );
        dff_setup!(self, clock, state, waited, starved, out_data, out_dv, out_er);
        self.fifo.write_clock.next = self.rx_clock.val();
        self.fifo.read_clock.next = self.clock.val();
        // write side
        self.reset_meta.d.next = self.reset.val();
        self.rx_reset.d.next = self.reset_meta.q.val();
        self.fifo.write_reset.next = self.rx_reset.q.val();
        self.dv_before.d.next = self.rx_dv.val();
        self.write_request.next =
            self.rx_dv.val() | self.dv_before.q.val() | self.end_pending.q.val();
        if self.rx_dv.val() {
            self.write_word.next = bit_cast::<10, 8>(self.rx_data.val())
                | (bit_cast::<10, 1>(self.rx_er.val().into()) << 8);
        } else {
            self.write_word.next = (bit_cast::<10, 1>(self.broken.q.val().into()) << 8)
                | (bit_cast::<10, 1>(true.into()) << 9);
        }
        self.fifo.write_data.next = self.write_word.val();
        self.fifo.write_enable.next =
            (self.rx_dv.val() | self.dv_before.q.val() | self.end_pending.q.val())
                & !self.rx_reset.q.val();
        if self.write_request.val() & self.fifo.full.val() {
            self.broken.d.next = true;
        } else if self.write_request.val() & !self.rx_dv.val() {
            // the end word went in with the mark
            self.broken.d.next = false;
        }
        // an end word that found the FIFO full is tried again
        self.end_pending.d.next =
            self.write_request.val() & !self.rx_dv.val() & self.fifo.full.val();
        if self.rx_reset.q.val() {
            self.broken.d.next = false;
            self.dv_before.d.next = false;
            self.end_pending.d.next = false;
        }
        // read side
        self.gmii_rxd.next = self.out_data.q.val();
        self.gmii_rx_dv.next = self.out_dv.q.val();
        self.gmii_rx_er.next = self.out_er.q.val();
        self.fifo.read_reset.next = self.reset.val();
        self.fifo.read_enable.next = false;
        self.out_data.d.next = 0.into();
        self.out_dv.d.next = false;
        self.out_er.d.next = false;
        match self.state.q.val() {
            ReadState::Idle => {
                if self.fifo.empty.val() {
                    self.waited.d.next = 0.into();
                } else {
                    self.waited.d.next = self.waited.q.val() + 1;
                }
                if (self.fifo.read_level.val() >= self.start_level.val())
                    | (self.waited.q.val() == self.start_wait.val())
                {
                    self.state.d.next = ReadState::Frame;
                    self.waited.d.next = 0.into();
                }
            }
            ReadState::Frame => {
                self.fifo.read_enable.next = true;
                self.starved.d.next = 0.into();
                if self.fifo.empty.val() {
                    // underrun inside the frame; a receive clock that stopped ends it
                    self.starved.d.next = self.starved.q.val() + 1;
                    self.out_dv.d.next = true;
                    self.out_er.d.next = true;
                    if self.starved.q.val().all() {
                        self.out_dv.d.next = false;
                        self.out_er.d.next = false;
                        self.state.d.next = ReadState::Idle;
                    }
                } else if self.fifo.read_data.val().get_bit(9) {
                    // end word: a broken frame ends with an error clock
                    self.out_dv.d.next = self.fifo.read_data.val().get_bit(8);
                    self.out_er.d.next = self.fifo.read_data.val().get_bit(8);
                    self.state.d.next = ReadState::Idle;
                } else {
                    self.out_data.d.next = self.fifo.read_data.val().get_bits::<8>(0);
                    self.out_dv.d.next = true;
                    self.out_er.d.next = self.fifo.read_data.val().get_bit(8);
                }
            }
            _ => {
                self.state.d.next = ReadState::Idle;
            }
        }
        if self.reset.val() {
            self.state.d.next = ReadState::Idle;
            self.waited.d.next = 0.into();
            self.starved.d.next = 0.into();
            self.out_dv.d.next = false;
        }
    }
}

/// The crossing as a Verilog module called `name`, for a board top.
pub fn module_verilog(name: &str) -> String {
    let mut crossing = RxClockCrossing::default();
    crossing.connect_all();
    check_all(&crossing).expect("the crossing is a complete block");
    let mut defines = ModuleDefines::default();
    crossing.accept(name, &mut defines);
    defines.defines()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::TestRng;

    /// One receive clock of GMII.
    #[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
    struct Rx {
        dv: bool,
        er: bool,
        data: u8,
    }

    /// A carrier as seen in the box clock: its clocks in order.
    type Carrier = Vec<Rx>;

    /// Simulates the crossing with the box clock at 8 ns and the receive clock at
    /// `8 ns * (1 + rx_ppm * 1e-6)` (a positive error: the receive clock is slower),
    /// feeding `wire` one entry per receive clock; returns the carriers that came out in
    /// the box clock (runs of `gmii_rx_dv`).
    fn run(wire: &[Rx], rx_ppm: f64) -> Vec<Carrier> {
        let mut uut = RxClockCrossing::default();
        uut.connect_all();
        let box_period = 8000.0;
        let rx_period = box_period * (1.0 + rx_ppm * 1e-6);
        // edges: (time, is_box, rising); the receive clock starts at an odd phase
        let (mut box_edge, mut rx_edge) = (0u64, 0u64);
        let box_time = |e: u64| 1000.0 + e as f64 * box_period / 2.0;
        let rx_time = |e: u64| 3321.0 + e as f64 * rx_period / 2.0;
        let lead_in = 40u64; // receive clocks of idle first
        let rx_clocks = lead_in + wire.len() as u64 + 200;
        let (mut carriers, mut current): (Vec<Carrier>, Carrier) = (Vec::new(), Vec::new());
        uut.reset.next = true;
        assert!(simulate(&mut uut, 1000));
        while rx_edge < 2 * rx_clocks {
            if box_time(box_edge) <= rx_time(rx_edge) {
                let rising = box_edge % 2 == 0;
                uut.clock.next = rising.into();
                assert!(simulate(&mut uut, 1000));
                if rising {
                    uut.reset.next = box_edge < 2 * 10;
                    assert!(simulate(&mut uut, 1000));
                    if uut.gmii_rx_dv.val() {
                        current.push(Rx {
                            dv: true,
                            er: uut.gmii_rx_er.val(),
                            data: uut.gmii_rxd.val().to_u8(),
                        });
                    } else {
                        assert!(!uut.gmii_rx_er.val(), "rx_er without rx_dv");
                        if !current.is_empty() {
                            carriers.push(std::mem::take(&mut current));
                        }
                    }
                }
                box_edge += 1;
            } else {
                let rising = rx_edge % 2 == 0;
                uut.rx_clock.next = rising.into();
                assert!(simulate(&mut uut, 1000));
                if !rising {
                    // inputs change after the falling edge, for the next rising one
                    let clock = rx_edge / 2 + 1;
                    let rx = clock
                        .checked_sub(lead_in)
                        .and_then(|i| wire.get(i as usize))
                        .copied()
                        .unwrap_or_default();
                    uut.rx_dv.next = rx.dv;
                    uut.rx_er.next = rx.er;
                    uut.rx_data.next = u64::from(rx.data).into();
                    assert!(simulate(&mut uut, 1000));
                }
                rx_edge += 1;
            }
        }
        assert!(current.is_empty(), "a carrier still open at the end");
        carriers
    }

    fn carrier(bytes: &[u8]) -> Vec<Rx> {
        bytes
            .iter()
            .map(|&data| Rx {
                dv: true,
                er: false,
                data,
            })
            .collect()
    }

    /// Frames with preamble, SFD and random contents, `gap` idle clocks after each.
    fn frames(lengths: &[usize], gap: usize, seed: u64) -> (Vec<Rx>, Vec<Vec<u8>>) {
        let mut rng = TestRng::new(seed);
        let mut wire = Vec::new();
        let mut sent = Vec::new();
        for &len in lengths {
            let mut bytes = vec![0x55; 7];
            bytes.push(0xD5);
            bytes.extend((0..len).map(|_| rng.byte()));
            wire.extend(carrier(&bytes));
            wire.extend(vec![Rx::default(); gap]);
            sent.push(bytes);
        }
        (wire, sent)
    }

    fn assert_carried(carriers: &[Carrier], sent: &[Vec<u8>], what: &str) {
        assert_eq!(carriers.len(), sent.len(), "{what}: carriers");
        for (i, (got, bytes)) in carriers.iter().zip(sent).enumerate() {
            assert!(got.iter().all(|rx| !rx.er), "{what}: rx_er in carrier {i}");
            let got: Vec<u8> = got.iter().map(|rx| rx.data).collect();
            assert_eq!(&got, bytes, "{what}: carrier {i}");
        }
    }

    /// Every byte crosses once, in order, each carrier stays one run of rx_dv with no
    /// clock added or lost, at +-100 and +-500 ppm, with 1,518-byte frames back to back
    /// (the 12-clock gap) and short carriers (below START_LEVEL bytes) among them.
    #[test]
    fn frames_cross_whole_without_bubbles_at_100_and_500_ppm() {
        for (i, ppm) in [0.0, 100.0, -100.0, 500.0, -500.0].into_iter().enumerate() {
            let mut lengths = vec![1518; 6];
            lengths.extend([64, 1518]);
            let (mut wire, mut sent) = frames(&lengths, 12, i as u64);
            // carriers shorter than START_LEVEL: a lone SFD, three bytes
            for bytes in [vec![0xD5], vec![0x55, 0x55, 0xD5]] {
                wire.extend(carrier(&bytes));
                wire.extend(vec![Rx::default(); 12]);
                sent.push(bytes);
            }
            let (more, more_sent) = frames(&[1518, 1518, 100], 12, 10 + i as u64);
            wire.extend(more);
            sent.extend(more_sent);
            let carriers = run(&wire, ppm);
            assert_carried(&carriers, &sent, &format!("{ppm} ppm"));
        }
    }

    /// A receive clock 1 % slower than the box clock: the FIFO runs dry inside a long
    /// frame, so the carrier gets rx_er clocks, yet stays one run of rx_dv with every byte
    /// in order between them; a short frame still crosses clean.
    #[test]
    fn an_underrun_inside_a_frame_sets_rx_er() {
        let (wire, sent) = frames(&[1518, 20], 12, 7);
        let carriers = run(&wire, 10_000.0);
        assert_eq!(carriers.len(), 2);
        let long = &carriers[0];
        let errors = long.iter().filter(|rx| rx.er).count();
        assert!(errors > 0, "an underrun shows as rx_er");
        let bytes: Vec<u8> = long.iter().filter(|rx| !rx.er).map(|rx| rx.data).collect();
        assert_eq!(bytes, sent[0], "the bytes around the error clocks");
        assert_carried(&carriers[1..], &sent[1..], "after the underrun");
    }

    /// A receive clock 3 % faster: the FIFO overflows inside a long frame; the frame ends
    /// with an error clock (its bytes are not all there), and the next frame, after a
    /// long gap, crosses clean.
    #[test]
    fn an_overrun_inside_a_frame_ends_it_with_rx_er() {
        let (wire, sent) = frames(&[1518, 60], 200, 8);
        let carriers = run(&wire, -30_000.0);
        assert_eq!(carriers.len(), 2);
        let end = carriers[0].last().unwrap();
        assert!(end.er, "the broken frame ends with rx_er");
        assert!(carriers[0].len() < sent[0].len(), "bytes were dropped");
        assert_carried(&carriers[1..], &sent[1..], "after the overrun");
    }

    #[test]
    fn verilog_passes_lint() {
        let mut uut = RxClockCrossing::default();
        uut.connect_all();
        let dir = std::env::temp_dir().join(format!("skinbox-rxcc-lint-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let report = crate::verilog::lint(&generate_verilog(&uut), &dir).unwrap();
        std::fs::remove_dir_all(&dir).ok();
        assert!(report.clean, "{}", report.output);
    }
}
