//! Clock stepping for block tests: drives `simulate()` directly, one edge at a time, which
//! is far faster than rust-hdl's threaded `simple_sim!`.

use crate::hdl::*;

/// A block under test with its clock input.
pub struct Bench<B: Block> {
    /// The block; set inputs with `.next`, read outputs with `.val()`.
    pub uut: B,
    clock: fn(&mut B) -> &mut Signal<In, Clock>,
    /// Rising edges so far.
    pub cycles: u64,
}

impl<B: Block> Bench<B> {
    /// Connects the block and settles it with the clock low.
    pub fn new(mut uut: B, clock: fn(&mut B) -> &mut Signal<In, Clock>) -> Self {
        uut.connect_all();
        let mut bench = Bench {
            uut,
            clock,
            cycles: 0,
        };
        (bench.clock)(&mut bench.uut).next = false.into();
        bench.settle();
        bench
    }

    /// Propagates input changes through the combinational logic.
    pub fn settle(&mut self) {
        assert!(simulate(&mut self.uut, 1000), "logic did not settle");
    }

    /// One full clock cycle: rising edge, then falling edge. Outputs read afterwards show
    /// the state after the rising edge.
    pub fn cycle(&mut self) {
        self.settle();
        (self.clock)(&mut self.uut).next = true.into();
        self.settle();
        (self.clock)(&mut self.uut).next = false.into();
        self.settle();
        self.cycles += 1;
    }

    /// `n` clock cycles.
    pub fn cycles(&mut self, n: u64) {
        for _ in 0..n {
            self.cycle();
        }
    }
}

/// One UART line as the pin level at each integer clock edge, from exact transition times.
///
/// Edge `e` happens at time `e` (in clock periods); a transition at time `t` is first seen
/// by edge `ceil(t)`. Frames are 8N1, LSB first, idle high.
#[derive(Debug, Clone, Default)]
pub struct UartLine {
    /// (start time, end time, level) of every low or high interval that is not idle.
    bits: Vec<(f64, f64, bool)>,
    /// Start-bit falling edge time of every frame.
    pub frame_starts: Vec<f64>,
}

impl UartLine {
    /// Appends one 8N1 frame of `byte` starting at `start` with `bit_period` clocks per bit;
    /// `stop_level` false makes a framing error. Returns the frame's end time.
    pub fn frame(&mut self, byte: u8, start: f64, bit_period: f64, stop_level: bool) -> f64 {
        self.frame_starts.push(start);
        let mut levels = vec![false];
        levels.extend((0..8).map(|i| byte >> i & 1 == 1));
        levels.push(stop_level);
        for (i, level) in levels.into_iter().enumerate() {
            let from = start + i as f64 * bit_period;
            self.bits.push((from, from + bit_period, level));
        }
        start + 10.0 * bit_period
    }

    /// Appends back-to-back frames of `bytes` from `start`; returns the end time.
    pub fn bytes(&mut self, bytes: &[u8], start: f64, bit_period: f64) -> f64 {
        bytes
            .iter()
            .fold(start, |t, b| self.frame(*b, t, bit_period, true))
    }

    /// Forces `level` on `[from, to)`, on top of the frames (glitches and spikes).
    pub fn force(&mut self, from: f64, to: f64, level: bool) {
        self.bits.push((from, to, level));
    }

    /// Pin level seen by each edge `0..edges`: an interval `[from, to)` covers the edges
    /// `ceil(from)..ceil(to)`, and the last interval pushed wins.
    pub fn levels(&self, edges: u64) -> Vec<bool> {
        let mut levels = vec![true; edges as usize];
        for &(from, to, level) in &self.bits {
            let from = (from.ceil().max(0.0) as usize).min(levels.len());
            let to = (to.ceil().max(0.0) as usize).min(levels.len());
            levels[from..to].fill(level);
        }
        levels
    }

    /// Time of the end of the last interval.
    pub fn end(&self) -> f64 {
        self.bits.iter().map(|b| b.1).fold(0.0, f64::max)
    }
}

/// Clocks per UART bit at a baud error in parts per million (positive = cell clock fast).
pub fn bit_period(error_ppm: f64) -> f64 {
    crate::CLOCK_HZ as f64 / crate::CELL_BAUD as f64 / (1.0 + error_ppm * 1e-6)
}

/// An independent line model: finds each falling edge, then reads the pin in the middle
/// of each bit from the exact bit period (31.25 clocks); returns (start edge, byte, stop
/// bit high).
pub fn decode_uart_line(levels: &[bool]) -> Vec<(u64, u8, bool)> {
    let period = bit_period(0.0);
    let mut out = vec![];
    let mut e = 1;
    while e < levels.len() {
        if levels[e - 1] && !levels[e] {
            let at = |bit: f64| levels[(e as f64 + (bit + 0.5) * period) as usize];
            assert!(!at(0.0), "start bit low in its middle at edge {e}");
            let byte = (0..8).fold(0u8, |b, i| b | (at(1.0 + i as f64) as u8) << i);
            out.push((e as u64, byte, at(9.0)));
            e = (e as f64 + 9.5 * period) as usize;
        } else {
            e += 1;
        }
    }
    out
}

/// Collects GMII bytes into frames: one frame per run of `tx_en`.
#[derive(Debug, Default)]
pub struct GmiiCapture {
    /// Complete frames, preamble to FCS.
    pub frames: Vec<Vec<u8>>,
    /// Clock of the first byte of each frame.
    pub starts: Vec<u64>,
    current: Vec<u8>,
    idle_run: u64,
    /// Shortest idle run seen between two frames.
    pub min_gap: Option<u64>,
}

impl GmiiCapture {
    /// Takes one clock's GMII outputs.
    pub fn clock(&mut self, clock: u64, tx_en: bool, txd: u8, tx_er: bool) {
        assert!(!tx_er, "tx_er set at clock {clock}");
        if tx_en {
            if self.current.is_empty() {
                self.starts.push(clock);
                if !self.frames.is_empty() {
                    self.min_gap =
                        Some(self.min_gap.map_or(self.idle_run, |g| g.min(self.idle_run)));
                }
            }
            self.current.push(txd);
            self.idle_run = 0;
        } else {
            if !self.current.is_empty() {
                self.frames.push(std::mem::take(&mut self.current));
            }
            self.idle_run += 1;
        }
    }
}

/// Checks one GMII frame with independent code (`skinbox_frame_check`) and returns its UDP
/// payload.
pub fn check_frame(frame: &[u8]) -> Result<Vec<u8>, String> {
    skinbox_frame_check::check(frame)
        .map(|(_, payload)| payload.to_vec())
        .map_err(|e| e.to_string())
}

/// A body sum ([`BODY_SUM_BITS`](crate::stream::BODY_SUM_BITS) bits) of `bytes`' 16-bit
/// words, as a datagram source may give it: their sum folded until it fits.
pub fn body_sum_of(bytes: &[u8]) -> u64 {
    let mut sum = crate::frame_transmitter::word_sum(bytes);
    while sum >= 1 << crate::stream::BODY_SUM_BITS {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    sum
}

/// `body_sum` is a body sum of `bytes`: it fits in
/// [`BODY_SUM_BITS`](crate::stream::BODY_SUM_BITS) and equals their words' sum modulo
/// 0xFFFF (a ones'-complement sum's value).
pub fn is_body_sum_of(body_sum: u64, bytes: &[u8]) -> bool {
    body_sum < 1 << crate::stream::BODY_SUM_BITS
        && body_sum % 0xFFFF == crate::frame_transmitter::word_sum(bytes) % 0xFFFF
}

/// A small seeded random source for valid/ready patterns (xorshift64*): fixed seeds make
/// every run of a test the same.
pub struct TestRng(u64);

impl TestRng {
    /// A generator from `seed` (any value).
    pub fn new(seed: u64) -> Self {
        TestRng(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// True with probability `p`.
    pub fn chance(&mut self, p: f64) -> bool {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64 <= p
    }

    /// A random byte.
    pub fn byte(&mut self) -> u8 {
        (self.next_u64() >> 56) as u8
    }
}

/// The 16-bit checksum word a frame's byte `i` contributes: even positions are high bytes.
pub fn frame_word(frame: &[u8], i: usize) -> u64 {
    let b = u64::from(frame[i]);
    if i.is_multiple_of(2) {
        b << 8
    } else {
        b
    }
}

/// Sends one frame to a block listening on [`crate::stream::FrameBeats`], as the frame
/// parser does: each byte arrives with its frame position (with a random idle clock before
/// it at chance `idle`) and is the registered beat a clock later, when `registered` sets
/// the block's other inputs for it (its position, or `None` for no registered beat). Ends
/// three clocks after the last byte was registered.
pub fn send_frame_beats<B: Block>(
    bench: &mut Bench<B>,
    rng: &mut TestRng,
    frame: &[u8],
    idle: f64,
    beats: fn(&mut B) -> &mut crate::stream::FrameBeats,
    registered: impl Fn(&mut B, Option<usize>),
) {
    let drive = |u: &mut B, r: Option<usize>| {
        let b = beats(u);
        b.beat_valid.next = r.is_some();
        b.beat_data.next = u64::from(r.map_or(0, |i| frame[i])).into();
        registered(u, r);
    };
    let mut last: Option<usize> = None;
    for i in 0..frame.len() {
        while rng.chance(idle) {
            beats(&mut bench.uut).next_valid.next = false;
            drive(&mut bench.uut, last);
            bench.cycle();
            last = None;
        }
        let b = beats(&mut bench.uut);
        b.next_valid.next = true;
        b.next_index.next = (i as u64).into();
        b.in_frame.next = i > 0;
        drive(&mut bench.uut, last);
        bench.cycle();
        last = Some(i);
    }
    let b = beats(&mut bench.uut);
    b.next_valid.next = false;
    b.next_index.next = 0.into();
    b.in_frame.next = false;
    drive(&mut bench.uut, last);
    bench.cycle();
    drive(&mut bench.uut, None);
    bench.cycles(3);
}
