//! When was a packet sampled? The host's estimate from the box's stamps alone, with no
//! change to the cells (docs/time.md, method b).
//!
//! The box stamps the first start bit of a packet at its pin; the cell sampled earlier by
//! its processing time, one relay hop per cell between it and the bus root, and the time it
//! queued at the root. A cell samples on its own periodic clock (period `P`, off nominal by
//! its drift), so its stamps are `phase + k * P + path + queue_k`: the sample index `k` of
//! each packet follows from the stamps, and since queueing only ever adds, the stamps' lower
//! envelope is the line `phase + path + k * P`. Better still, a packet whose first start bit
//! came more than one packet's length after the previous packet's on the same port found
//! the root's line idle and did not queue at all: its stamp lies exactly on the line
//! ([`SampleTimer`] tells those apart per port). [`SampleClockEstimator`] fits the line per
//! cell through such unqueued packets where it has them (least squares over the recent
//! ones), else through the lowest points of a sliding window, and subtracts the path
//! latency, which the stamps cannot show (only differences of stamps are observable): the
//! [`PathModel`] gives it from the cell's position on its chain.
//!
//! Where it fails (the study C5 of `skinbox report` charts each): a wrong per-hop latency
//! (the error grows with the hop count); cells colliding at the root, whose packets keep
//! queueing behind each other for seconds when their clocks differ by a few ppm (none of
//! them unqueued, the estimate carries the queue); a root queue that never empties; and a
//! cell silent for so long that its drift moves the grid by more than half a period before
//! its period is learnt (the sample index is then wrong by one).

use crate::box_map::BoxMap;
use crate::decoder::BoxKey;
use std::collections::HashMap;

/// The bus model's processing time in a cell before its packet leaves, ns (docs/design.md
/// section 7).
pub const PROCESSING_NS: u64 = 20_000;
/// The bus model's relay delay per cell, ns: one 50 us packet plus handling.
pub const HOP_LATENCY_NS: u64 = 52_000;

/// Stamps kept per cell for the fit.
pub const WINDOW: usize = 256;
/// The fit is redone after this many new stamps (between fits only the offset follows).
const REFIT_EVERY: u32 = 16;
/// Unqueued packets kept per cell for the fit (the older ones thinned out, so they span a
/// growing stretch of samples).
pub const ANCHORS: usize = 32;
/// Oldest unqueued packet the line is fitted through, ns of box time: a straight line holds
/// a wandering drift only so long (docs/time.md).
pub const MAX_ANCHOR_AGE_NS: f64 = 4e9;
/// Longest time between two packets' first start bits that can still be back to back on a
/// port, ns: 200 bits at 4 Mbit/s, on a root UART up to 2 % slow.
pub const BACK_TO_BACK_NS: u64 = skinbox_protocol::cell::UART_BITS_PER_PACKET * 1_000_000_000
    / skinbox_protocol::cell::UART_BAUD
    * 102
    / 100;
/// How far a packet may lie below the fitted line, or an unqueued one off it, before the
/// line is taken as wrong, ns: well above the tick and the fit's drift between refits.
const RESTART_NS: f64 = 10_000.0;
/// Sample indices a window must span before its period replaces the nominal one.
const MIN_SPAN: i64 = 64;
/// Sample indices unqueued packets must span before their period is used: they lie on the
/// line to the tick, so 8 samples give the period to 2 ns.
const MIN_ANCHOR_SPAN: i64 = 8;
/// Largest sample clock error a fitted period may show, relative: cells' clocks are
/// specified to +-100 ppm (docs/design.md section 7); a fit beyond five times that is noise.
const MAX_PERIOD_ERROR: f64 = 500e-6;

/// Where each cell sits on its chain, and the latency of its path to the box pin.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PathModel {
    /// Processing in the cell before its packet leaves, ns.
    pub processing_ns: u64,
    /// Relay delay per cell between it and the root, ns.
    pub hop_latency_ns: u64,
    /// Hops of each cell (0 = the root), by cell id.
    pub hops: Positions,
}

/// The chain position of each cell.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Positions {
    /// Unknown: every cell counted as the root (the path latency is the processing only).
    Unknown,
    /// Cells numbered from 1 along the chains, root first, this many per bus (the scenes'
    /// layout): cell `id` sits `(id - 1) % cells_per_bus` hops from its root.
    Numbered {
        /// Cells per bus.
        cells_per_bus: u16,
    },
    /// Hops of each cell by id, as the skin's initialisation enumerated them; cells not in
    /// it count as the root.
    Listed(HashMap<u16, u16>),
}

impl PathModel {
    /// The bus model's latencies with these positions.
    pub fn bus_model(hops: Positions) -> PathModel {
        PathModel {
            processing_ns: PROCESSING_NS,
            hop_latency_ns: HOP_LATENCY_NS,
            hops,
        }
    }

    /// Hops between `cell_id` and its root.
    pub fn hops(&self, cell_id: u16) -> u16 {
        match &self.hops {
            Positions::Unknown => 0,
            Positions::Numbered { cells_per_bus } => {
                cell_id.saturating_sub(1) % (*cells_per_bus).max(1)
            }
            Positions::Listed(map) => map.get(&cell_id).copied().unwrap_or(0),
        }
    }

    /// Latency from `cell_id`'s sample to its first start bit at the pin with no queue, ns.
    pub fn latency_ns(&self, cell_id: u16) -> u64 {
        self.processing_ns + u64::from(self.hops(cell_id)) * self.hop_latency_ns
    }
}

/// One cell's sample clock, learnt from the stamps of its packets.
///
/// Its state is in three parts: [`CellClock`], what every packet reads and writes (one
/// cache line); the unqueued packets' points, which a packet touches when it is one or the
/// line is refitted (640 bytes); and the window of recent points, touched only until the
/// line goes through unqueued packets (4 kB). [`SampleTimer`] keeps each part of all its
/// cells in an array of its own.
#[derive(Debug, Clone)]
pub struct SampleClockEstimator {
    clock: CellClock,
    unqueued: Box<Anchors>,
    window: Box<Window>,
}

/// The part of a cell's sample clock that every packet reads and writes: the line in use,
/// the last packet, and how many points its [`Anchors`] and [`Window`] hold.
#[derive(Debug, Clone, Copy)]
#[repr(align(64))]
struct CellClock {
    path_latency_ns: f64,
    nominal_period_ns: f64,
    period_ns: f64,
    /// Time of sample index 0 plus the path latency, ns after `anchor_ns`.
    offset_ns: f64,
    anchor_ns: u64,
    /// Sample index and stamp of the last packet, if `has_last`.
    last_index: i64,
    last_stamp_ns: u64,
    /// Points in the window and the unqueued packets' points.
    window_len: u16,
    unqueued_len: u8,
    /// Packets since the last full fit (at most [`REFIT_EVERY`]).
    since_fit: u8,
    has_last: bool,
    period_learnt: bool,
    /// Recompute every fit from its points instead ([`SampleClockEstimator::batch`]).
    batch: bool,
}

// Every packet touches one cache line of its cell.
const _: () = assert!(std::mem::size_of::<CellClock>() == 64);
const _: () = assert!(WINDOW <= u16::MAX as usize && ANCHORS <= u8::MAX as usize);
const _: () = assert!(REFIT_EVERY <= u8::MAX as u32);

/// (sample index, stamp - anchor) of a cell's unqueued packets, kept however old: dense
/// recently, thinned further back.
type Anchors = Ring<ANCHORS>;
/// (sample index, stamp - anchor) of a cell's recent packets.
type Window = Ring<WINDOW>;

/// A point `(k, r)`: a packet's sample index and its stamp less the anchor, ns.
type Point = (i64, i64);

/// At most `N` points `(k, r)` in a fixed array used as a ring buffer, oldest first, and
/// their running sums (their least-squares line and mean offset in O(1) at each packet).
/// The counts and sums come first: a packet that adds a point touches the first two cache
/// lines and the points' own.
#[derive(Debug, Clone)]
#[repr(C, align(64))]
struct Ring<const N: usize> {
    /// The oldest point's position in `points`.
    head: u16,
    len: u16,
    sums: LineSums,
    points: [Point; N],
}

impl<const N: usize> Ring<N> {
    fn new() -> Ring<N> {
        Ring {
            head: 0,
            len: 0,
            sums: LineSums::default(),
            points: [(0, 0); N],
        }
    }

    fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Forgets every point.
    fn clear(&mut self) {
        self.head = 0;
        self.len = 0;
        self.sums = LineSums::default();
    }

    /// Position in `points` of the `i`th oldest point (`i` below `N`).
    fn slot(&self, i: usize) -> usize {
        let at = usize::from(self.head) + i;
        if at >= N {
            at - N
        } else {
            at
        }
    }

    fn front(&self) -> Option<(i64, i64)> {
        (self.len > 0).then(|| self.points[usize::from(self.head)])
    }

    fn back(&self) -> Option<(i64, i64)> {
        (self.len > 0).then(|| self.points[self.slot(self.len() - 1)])
    }

    /// Adds `point` as the newest; the ring must not be full.
    fn push_back(&mut self, point: Point) {
        debug_assert!(self.len() < N);
        let at = self.slot(self.len());
        self.points[at] = point;
        self.len += 1;
        self.sums.add(point);
    }

    /// Removes the oldest point.
    fn pop_front(&mut self) {
        if let Some(point) = self.front() {
            self.head = self.slot(1) as u16;
            self.len -= 1;
            self.sums.remove(point);
        }
    }

    /// Keeps the points `keep` is true of, in their order; `keep` sees each once, oldest
    /// first.
    fn retain(&mut self, mut keep: impl FnMut(&Point) -> bool) {
        let mut kept = 0;
        for i in 0..self.len() {
            let point = self.points[self.slot(i)];
            if keep(&point) {
                let to = self.slot(kept);
                self.points[to] = point;
                kept += 1;
            } else {
                self.sums.remove(point);
            }
        }
        self.len = kept as u16;
    }

    /// The points oldest first, in two runs of the array.
    fn as_slices(&self) -> (&[Point], &[Point]) {
        let head = usize::from(self.head);
        let first = (N - head).min(self.len());
        (
            &self.points[head..head + first],
            &self.points[..self.len() - first],
        )
    }

    /// The points oldest first.
    fn iter(&self) -> impl Iterator<Item = &(i64, i64)> {
        let (a, b) = self.as_slices();
        a.iter().chain(b)
    }
}

/// Sums of points `(k, r)` for their least-squares line, exact in integers: a point is
/// added and removed in O(1), and the line is the same whatever the order.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct LineSums {
    n: i64,
    k: i128,
    r: i128,
    kk: i128,
    kr: i128,
}

impl LineSums {
    fn add(&mut self, (k, r): (i64, i64)) {
        let (k, r) = (i128::from(k), i128::from(r));
        self.n += 1;
        self.k = self.k.wrapping_add(k);
        self.r = self.r.wrapping_add(r);
        self.kk = self.kk.wrapping_add(k.wrapping_mul(k));
        self.kr = self.kr.wrapping_add(k.wrapping_mul(r));
    }

    fn remove(&mut self, (k, r): (i64, i64)) {
        let (k, r) = (i128::from(k), i128::from(r));
        self.n -= 1;
        self.k = self.k.wrapping_sub(k);
        self.r = self.r.wrapping_sub(r);
        self.kk = self.kk.wrapping_sub(k.wrapping_mul(k));
        self.kr = self.kr.wrapping_sub(k.wrapping_mul(r));
    }

    /// Slope of `r` over `k` by least squares: `(n Σkr - Σk Σr) / (n Σk² - (Σk)²)`, both
    /// exact, divided once; `None` for fewer than two distinct `k`.
    fn slope(&self) -> Option<f64> {
        let n = i128::from(self.n);
        let den = n
            .wrapping_mul(self.kk)
            .wrapping_sub(self.k.wrapping_mul(self.k));
        let num = n
            .wrapping_mul(self.kr)
            .wrapping_sub(self.k.wrapping_mul(self.r));
        let slope = to_f64(num) / to_f64(den);
        (den > 0 && slope.is_finite()).then_some(slope)
    }

    /// Mean of `r - period * k` over the points, taken about the point `(k0, r0)` (one of
    /// them, or near them): the sums less `n` times it are small and exact, so the mean is
    /// as precise as a sum of the points' own offsets.
    fn mean_offset(&self, period: f64, (k0, r0): (i64, i64)) -> f64 {
        let n = i128::from(self.n.max(1));
        let dk = self.k.wrapping_sub(n.wrapping_mul(i128::from(k0)));
        let dr = self.r.wrapping_sub(n.wrapping_mul(i128::from(r0)));
        (r0 as f64 - period * k0 as f64) + (to_f64(dr) - period * to_f64(dk)) / n as f64
    }
}

/// A packet's estimated sample time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleTime {
    /// Estimated sample time, ns of box time.
    pub sample_time_ns: f64,
    /// The cell's sample index (0 = its first packet's sample since the estimator began).
    pub index: i64,
    /// Whether the cell's own period was learnt (else the nominal one is used).
    pub period_learnt: bool,
}

impl SampleClockEstimator {
    /// An estimator for a cell sampling nominally every `nominal_period_ns` whose packets
    /// need `path_latency_ns` from the sample to the pin with no queue.
    pub fn new(nominal_period_ns: f64, path_latency_ns: u64) -> SampleClockEstimator {
        SampleClockEstimator {
            clock: CellClock::new(nominal_period_ns, path_latency_ns),
            unqueued: Box::new(Ring::new()),
            window: Box::new(Ring::new()),
        }
    }

    /// The same estimator recomputing every least-squares fit and mean from all its points
    /// (O([`WINDOW`]) per packet) instead of from running sums: the reference the
    /// incremental fits are checked against.
    pub fn batch(mut self) -> SampleClockEstimator {
        self.clock.batch = true;
        self
    }

    /// The period in use, ns.
    pub fn period_ns(&self) -> f64 {
        self.clock.period_ns
    }

    /// Starts over (a box reset: the stamps restart).
    pub fn reset(&mut self) {
        self.clock.reset(&mut self.unqueued, &mut self.window);
    }

    /// Takes the stamp of the cell's next packet (box time of its first start bit, ns, in
    /// arrival order) and returns its estimated sample time; `unqueued`: the packet found
    /// the root's line idle (see [`SampleTimer`]), so its stamp is its sample time plus the
    /// path latency exactly. A stamp before the previous one (the box was reset) starts the
    /// estimator over.
    pub fn push(&mut self, stamp_ns: u64, unqueued: bool) -> SampleTime {
        self.clock
            .push(&mut self.unqueued, &mut self.window, stamp_ns, unqueued)
    }
}

impl CellClock {
    fn new(nominal_period_ns: f64, path_latency_ns: u64) -> CellClock {
        CellClock {
            path_latency_ns: path_latency_ns as f64,
            nominal_period_ns,
            period_ns: nominal_period_ns,
            offset_ns: 0.0,
            anchor_ns: 0,
            last_index: 0,
            last_stamp_ns: 0,
            window_len: 0,
            unqueued_len: 0,
            since_fit: 0,
            has_last: false,
            period_learnt: false,
            batch: false,
        }
    }

    /// Starts over, as new but for the batch setting; `anchors` and `window` are the
    /// cell's points.
    fn reset(&mut self, anchors: &mut Anchors, window: &mut Window) {
        *self = CellClock {
            batch: self.batch,
            ..CellClock::new(self.nominal_period_ns, self.path_latency_ns.round() as u64)
        };
        anchors.clear();
        window.clear();
    }

    /// [`SampleClockEstimator::push`]; `anchors` and `window` are the cell's points.
    fn push(
        &mut self,
        anchors: &mut Anchors,
        window: &mut Window,
        stamp_ns: u64,
        unqueued: bool,
    ) -> SampleTime {
        if self.has_last && stamp_ns < self.last_stamp_ns {
            self.reset(anchors, window);
        }
        let index = if self.has_last {
            let rel = (stamp_ns - self.anchor_ns) as f64;
            // Queueing only delays: once the offset sits on the lower envelope, the
            // index whose grid point lies at most 7/8 of a period before the stamp (up
            // to 1/8 after, for the fit's own error); before that, the nearest.
            let margin = if usize::from(self.window_len) < 2 * REFIT_EVERY as usize {
                0.5
            } else {
                0.125
            };
            floor_i64((rel - self.offset_ns + margin * self.period_ns) / self.period_ns)
                .max(self.last_index)
        } else {
            self.anchor_ns = stamp_ns;
            self.offset_ns = 0.0;
            0
        };
        let rel = (stamp_ns - self.anchor_ns) as i64;
        // Unqueued packets lie on the line, none below it: when one is off, or any packet
        // below, the line is wrong (a sample index slipped, e.g. in the start-up burst's
        // long queues), and the estimator starts over from this packet.
        if self.unqueued_len > 0 {
            let residual = rel as f64 - self.offset_ns - self.period_ns * index as f64;
            // Before the period is learnt the nominal one drifts off: only a gross miss.
            let limit = if self.period_learnt {
                RESTART_NS
            } else {
                self.period_ns / 8.0
            };
            if residual < -limit || (unqueued && residual > limit) {
                self.reset(anchors, window);
                return self.push(anchors, window, stamp_ns, unqueued);
            }
        }
        // Once the period is learnt and an unqueued packet is kept, every fit goes through
        // the unqueued packets until a reset (neither changes back): past the first
        // 2 * REFIT_EVERY stamps, the window, which only its length is then read of, is
        // left as it is (and its points not touched).
        let anchored = self.period_learnt
            && self.unqueued_len > 0
            && usize::from(self.window_len) >= 2 * REFIT_EVERY as usize;
        if !anchored {
            if window.len() == WINDOW {
                window.pop_front();
            }
            window.push_back((index, rel));
            self.window_len = window.len() as u16;
        }
        self.has_last = true;
        (self.last_index, self.last_stamp_ns) = (index, stamp_ns);
        self.since_fit += 1;
        if unqueued {
            if anchors.len() == ANCHORS {
                // Thin the older half to every other one: the kept ones span ever more
                // samples (the period's precision grows with it), the newest stay dense.
                let mut i = 0;
                anchors.retain(|_| {
                    i += 1;
                    i > ANCHORS / 2 || i % 2 == 1
                });
            }
            anchors.push_back((index, rel));
            // A cell's drift wanders (temperature): the line holds only over a while.
            while anchors
                .front()
                .is_some_and(|(_, r)| (rel - r) as f64 > MAX_ANCHOR_AGE_NS)
            {
                anchors.pop_front();
            }
            self.unqueued_len = anchors.len() as u8;
        }
        if u32::from(self.since_fit) >= REFIT_EVERY
            || usize::from(self.window_len) < 2 * REFIT_EVERY as usize
            || (unqueued && self.unqueued_len <= 2)
        {
            self.fit(anchors, window);
        } else if unqueued {
            self.fit_anchors(anchors);
        } else if self.unqueued_len == 0 {
            let residual = rel as f64 - self.period_ns * index as f64;
            self.offset_ns = self.offset_ns.min(residual);
        }
        SampleTime {
            sample_time_ns: self.anchor_ns as f64 + self.offset_ns + self.period_ns * index as f64
                - self.path_latency_ns,
            index,
            period_learnt: self.period_learnt,
        }
    }

    /// Refits period and offset: through the unqueued packets where they span enough
    /// samples, else over the window.
    fn fit(&mut self, anchors: &Anchors, window: &Window) {
        self.since_fit = 0;
        fn span<const N: usize>(q: &Ring<N>) -> i64 {
            match (q.front(), q.back()) {
                (Some(a), Some(b)) => b.0 - a.0,
                _ => 0,
            }
        }
        let plausible =
            |period: f64| (period / self.nominal_period_ns - 1.0).abs() < MAX_PERIOD_ERROR;
        if span(anchors) >= MIN_ANCHOR_SPAN || (self.period_learnt && anchors.len() > 0) {
            // (Too few unqueued packets for a period: the one learnt before holds.)
            self.fit_anchors(anchors);
            return;
        }
        if span(window) >= MIN_SPAN {
            let ls = if self.batch {
                least_squares(window)
            } else {
                window.sums.slope()
            };
            if let Some(ls) = ls.filter(|&period| plausible(period)) {
                // Then the line through the lowest point of each half: packets that did
                // not queue lie exactly on the true line.
                let lowest = |from: usize, to: usize| lowest_under(window, from, to, ls);
                let half = window.len() / 2;
                let envelope = match (lowest(0, half), lowest(half, window.len())) {
                    (Some((ka, ra)), Some((kb, rb))) if kb - ka >= MIN_SPAN / 2 => {
                        ls + (rb - ra) / (kb - ka) as f64
                    }
                    _ => ls,
                };
                self.period_ns = if plausible(envelope) { envelope } else { ls };
                self.period_learnt = true;
            }
        }
        self.offset_ns = if anchors.len() == 0 {
            window
                .iter()
                .map(|&(k, r)| r as f64 - self.period_ns * k as f64)
                .fold(f64::INFINITY, f64::min)
        } else {
            self.anchored_offset(anchors)
        };
    }

    /// Period and offset through the unqueued packets alone (cheap: at most [`ANCHORS`]),
    /// the period only where they span enough samples.
    fn fit_anchors(&mut self, anchors: &Anchors) {
        if let (Some(a), Some(b)) = (anchors.front(), anchors.back()) {
            if b.0 - a.0 >= MIN_ANCHOR_SPAN {
                let slope = if self.batch {
                    least_squares(anchors)
                } else {
                    anchors.sums.slope()
                };
                if let Some(period) =
                    slope.filter(|&s| (s / self.nominal_period_ns - 1.0).abs() < MAX_PERIOD_ERROR)
                {
                    self.period_ns = period;
                    self.period_learnt = true;
                }
            }
        }
        self.offset_ns = self.anchored_offset(anchors);
    }

    /// The unqueued packets lie on the line, up to the tick: the mean of their offsets.
    fn anchored_offset(&self, anchors: &Anchors) -> f64 {
        match anchors.back() {
            Some(newest) if !self.batch => anchors.sums.mean_offset(self.period_ns, newest),
            _ => {
                anchors
                    .iter()
                    .map(|&(k, r)| r as f64 - self.period_ns * k as f64)
                    .sum::<f64>()
                    / anchors.len().max(1) as f64
            }
        }
    }
}

/// The first of `points[from..to]` (oldest first) lowest below the line of slope `slope`
/// through the origin: its sample index and `r - slope * k` (`None` for no points). The
/// points' offsets are finite and never -0, so `<` orders them as `f64::total_cmp` does.
fn lowest_under<const N: usize>(
    points: &Ring<N>,
    from: usize,
    to: usize,
    slope: f64,
) -> Option<(i64, f64)> {
    let (front, back) = points.as_slices();
    let split = front.len();
    let (mut best_k, mut best) = (None, f64::INFINITY);
    let parts = [
        front
            .get(from.min(split)..to.min(split))
            .unwrap_or_default(),
        back.get(from.saturating_sub(split)..to.saturating_sub(split))
            .unwrap_or_default(),
    ];
    for part in parts {
        for &(k, r) in part {
            let v = r as f64 - slope * k as f64;
            if v < best {
                (best_k, best) = (Some(k), v);
            }
        }
    }
    best_k.map(|k| (k, best))
}

/// `x.floor() as i64` (saturating, NaN to 0) without the library call of `floor`.
fn floor_i64(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// `x` as the nearest `f64`, as `x as f64`, through the faster conversion of an `i64`
/// where it fits (the same integer rounds to the same `f64` either way).
fn to_f64(x: i128) -> f64 {
    match i64::try_from(x) {
        Ok(v) => v as f64,
        Err(_) => x as f64,
    }
}

/// Slope of stamps over sample indices by least squares, ns per sample, from every point
/// (the batch reference of [`LineSums::slope`]).
fn least_squares<const N: usize>(points: &Ring<N>) -> Option<f64> {
    let (k0, r0) = points.front()?;
    let n = points.len() as f64;
    let (mk, mr) = points.iter().fold((0.0, 0.0), |(a, b), &(k, r)| {
        (a + (k - k0) as f64 / n, b + (r - r0) as f64 / n)
    });
    let (sxy, sxx) = points.iter().fold((0.0, 0.0), |(a, b), &(k, r)| {
        let dk = (k - k0) as f64 - mk;
        (a + dk * ((r - r0) as f64 - mr), b + dk * dk)
    });
    let slope = sxy / sxx;
    slope.is_finite().then_some(slope)
}

/// Sample times of every cell of every box: one sample clock per (box, cell), as
/// [`SampleClockEstimator`], and per (box, port) the last stamp, to tell the packets that
/// found the root's line idle (more than [`BACK_TO_BACK_NS`] after the previous one on the
/// port; records of one port come in pin order).
#[derive(Debug, Clone)]
pub struct SampleTimer {
    nominal_period_ns: f64,
    paths: PathModel,
    /// The cells sample on the box's time grid (method c): no estimate, the grid point.
    on_box_grid: bool,
    /// The estimators recompute their fits from every point ([`SampleClockEstimator::batch`]).
    batch: bool,
    /// Each box's ports and cells.
    boxes: BoxMap<BoxClocks>,
}

/// The cells and ports of one box. A cell's clock is in three arrays, by the slot the cell
/// got when first seen: what every packet touches (a cache line a cell), the unqueued
/// packets' points and the window's (see [`SampleClockEstimator`]).
#[derive(Debug, Clone)]
struct BoxClocks {
    /// Stamp of the last packet on each port.
    last_on_port: Box<[Option<u64>; 256]>,
    /// Each cell's slot by cell id ([`NO_SLOT`]: none yet), up to the highest id seen.
    slots: Vec<u32>,
    clocks: Vec<CellClock>,
    anchors: Vec<Anchors>,
    windows: Vec<Window>,
}

/// The slot of a cell not seen yet.
const NO_SLOT: u32 = u32::MAX;

impl BoxClocks {
    fn new() -> BoxClocks {
        BoxClocks {
            last_on_port: Box::new([None; 256]),
            slots: Vec::new(),
            clocks: Vec::new(),
            anchors: Vec::new(),
            windows: Vec::new(),
        }
    }

    /// Forgets every cell and port.
    fn clear(&mut self) {
        *self.last_on_port = [None; 256];
        self.slots.clear();
        self.clocks.clear();
        self.anchors.clear();
        self.windows.clear();
    }
}

impl SampleTimer {
    /// Cells sampling nominally at `sample_rate_hz` on paths of `paths`.
    pub fn new(sample_rate_hz: f64, paths: PathModel) -> SampleTimer {
        SampleTimer {
            nominal_period_ns: 1e9 / sample_rate_hz,
            paths,
            on_box_grid: false,
            batch: false,
            boxes: BoxMap::default(),
        }
    }

    /// The same timer for cells that sample on the box's time grid, set by its time-sync
    /// commands (docs/time.md, method c): a packet's sample time is the grid point
    /// `n / sample_rate_hz` of box time that its stamp less the cell's path latency (its
    /// half round trip) falls on, allowing queueing at the root up to 7/8 of a period.
    pub fn on_box_grid(mut self) -> SampleTimer {
        self.on_box_grid = true;
        self
    }

    /// The same timer with every cell's fits recomputed from all their points
    /// ([`SampleClockEstimator::batch`]): the reference for the incremental fits.
    pub fn batch(mut self) -> SampleTimer {
        self.batch = true;
        self
    }

    /// The estimated sample time of a packet of `cell_id` on `port` of box `box_id` (its
    /// source address unknown) stamped at `stamp_ns` (box time); a port's packets in pin
    /// order.
    pub fn push(&mut self, box_id: u16, port: u8, cell_id: u16, stamp_ns: u64) -> SampleTime {
        let key = BoxKey {
            box_id,
            source: None,
        };
        self.push_for(key, port, cell_id, stamp_ns)
    }

    /// [`SampleTimer::push`] for the box `key` (box id and source address).
    pub fn push_for(&mut self, key: BoxKey, port: u8, cell_id: u16, stamp_ns: u64) -> SampleTime {
        let period = self.nominal_period_ns;
        if self.on_box_grid {
            return self.grid_point(cell_id, stamp_ns);
        }
        let clocks = self.boxes.get_or_insert_with(key, BoxClocks::new);
        // The port's first packet: whether the line was idle before it is unknown.
        let unqueued = clocks.last_on_port[usize::from(port)]
            .replace(stamp_ns)
            .is_some_and(|last| stamp_ns >= last && stamp_ns - last > BACK_TO_BACK_NS);
        let id = usize::from(cell_id);
        let slot = match clocks.slots.get(id) {
            Some(&slot) if slot != NO_SLOT => slot as usize,
            _ => {
                if clocks.slots.len() <= id {
                    clocks.slots.resize(id + 1, NO_SLOT);
                }
                let slot = clocks.clocks.len();
                clocks.slots[id] = slot as u32;
                let mut clock = CellClock::new(period, self.paths.latency_ns(cell_id));
                clock.batch = self.batch;
                clocks.clocks.push(clock);
                clocks.anchors.push(Ring::new());
                clocks.windows.push(Ring::new());
                slot
            }
        };
        clocks.clocks[slot].push(
            &mut clocks.anchors[slot],
            &mut clocks.windows[slot],
            stamp_ns,
            unqueued,
        )
    }

    /// The sample time of a packet of `cell_id` stamped at `stamp_ns` from a cell on the
    /// box's time grid ([`SampleTimer::on_box_grid`]): the grid point its stamp less the
    /// path latency falls on, allowing queueing up to 7/8 of a period. Keeps no state.
    pub fn grid_point(&self, cell_id: u16, stamp_ns: u64) -> SampleTime {
        let period = self.nominal_period_ns;
        let latency = self.paths.latency_ns(cell_id);
        let at = stamp_ns as f64 - latency as f64 + period / 8.0;
        let index = (at / period).floor();
        SampleTime {
            sample_time_ns: index * period,
            index: index as i64,
            period_learnt: false,
        }
    }

    /// The cells' path latencies.
    pub fn paths(&self) -> &PathModel {
        &self.paths
    }

    /// Starts every cell and port of `box_id` over (the box was reset), whatever its
    /// source address.
    pub fn reset_box(&mut self, box_id: u16) {
        for (_, b) in self.boxes.iter_mut().filter(|(k, _)| k.box_id == box_id) {
            b.clear();
        }
    }

    /// Cells followed (none on the box's grid).
    pub fn cells(&self) -> usize {
        self.boxes.iter().map(|(_, b)| b.clocks.len()).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// xorshift64*: the tests' own noise, independent of the code under test.
    struct Noise(u64);
    impl Noise {
        fn next(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    struct Cell {
        phase_ns: f64,
        period_ns: f64,
        latency_ns: u64,
    }

    impl Cell {
        fn sample_ns(&self, k: u64) -> f64 {
            self.phase_ns + k as f64 * self.period_ns
        }
        /// The box stamp: sample, path, queue, rounded down to the 8 ns tick.
        fn stamp_ns(&self, k: u64, queue_ns: f64) -> u64 {
            let t = self.sample_ns(k) + self.latency_ns as f64 + queue_ns;
            (t / 8.0).floor() as u64 * 8
        }
    }

    /// Errors of the estimates against the true sample times, ns, sorted by size.
    fn errors(cell: &Cell, samples: &[(u64, f64)], nominal_hz: f64) -> Vec<f64> {
        let mut est = SampleClockEstimator::new(1e9 / nominal_hz, cell.latency_ns);
        let mut e: Vec<f64> = samples
            .iter()
            .map(|&(k, q)| {
                (est.push(cell.stamp_ns(k, q), false).sample_time_ns - cell.sample_ns(k)).abs()
            })
            .collect();
        e.sort_by(f64::total_cmp);
        e
    }

    fn p99(e: &[f64]) -> f64 {
        e[(e.len() * 99 / 100).min(e.len() - 1)]
    }

    fn cell(drift_ppm: f64, rate_hz: f64, hops: u64) -> Cell {
        Cell {
            phase_ns: 1_234_567.0,
            period_ns: 1e9 / rate_hz / (1.0 + drift_ppm * 1e-6),
            latency_ns: PROCESSING_NS + hops * HOP_LATENCY_NS,
        }
    }

    #[test]
    fn data_mode_with_drift_and_queueing_is_within_a_microsecond_after_warm_up() {
        let mut noise = Noise(0x9E37_79B9_7F4A_7C15);
        for (drift, rate) in [(100.0, 125.0), (-100.0, 500.0), (37.0, 250.0)] {
            let c = cell(drift, rate, 65);
            // Most packets queue 0 to 800 us at the root; one in four finds it empty.
            let samples: Vec<(u64, f64)> = (0..5_000u64)
                .map(|k| {
                    let q = if noise.next() < 0.25 {
                        0.0
                    } else {
                        noise.next() * 800e3
                    };
                    (k, q)
                })
                .collect();
            let late: Vec<f64> = {
                let mut est = SampleClockEstimator::new(1e9 / rate, c.latency_ns);
                let mut v: Vec<f64> = samples
                    .iter()
                    .map(|&(k, q)| {
                        est.push(c.stamp_ns(k, q), false).sample_time_ns - c.sample_ns(k)
                    })
                    .skip(WINDOW)
                    .map(f64::abs)
                    .collect();
                v.sort_by(f64::total_cmp);
                v
            };
            assert!(
                p99(&late) < 1_000.0,
                "{drift} ppm {rate} Hz p99 {}",
                p99(&late)
            );
            assert!(
                late[late.len() - 1] < 5_000.0,
                "max {}",
                late[late.len() - 1]
            );
        }
    }

    #[test]
    fn event_mode_gaps_keep_the_sample_index() {
        // Silent stretches of up to 2 s between bursts; drift 100 ppm at 500 Hz moves the
        // grid 200 us per 2 s, within an eighth of a period (250 us) of the nominal one.
        let mut noise = Noise(42);
        let c = cell(100.0, 500.0, 30);
        let mut samples = Vec::new();
        let mut k = 0u64;
        while samples.len() < 3_000 {
            let burst = 1 + (noise.next() * 30.0) as u64;
            for _ in 0..burst {
                samples.push((k, noise.next() * 100e3));
                k += 1;
            }
            k += (noise.next() * 1_000.0) as u64; // up to 2 s silent
        }
        let mut est = SampleClockEstimator::new(2e6, c.latency_ns);
        let mut first = None;
        for &(k, q) in &samples {
            let s = est.push(c.stamp_ns(k, q), false);
            let k0 = *first.get_or_insert(k);
            assert_eq!(s.index as u64, k - k0, "sample index lost at {k}");
        }
        let e = errors(&c, &samples[200..], 500.0);
        assert!(p99(&e) < 20e3, "p99 {}", p99(&e));
    }

    #[test]
    fn a_silence_longer_than_the_drift_allows_before_the_period_is_learnt_loses_the_index() {
        // Both sides of the boundary: a second packet after a silence of `gap` periods at
        // 100 ppm off nominal. The grid moves 1e-4 * gap periods; beyond half a period
        // (gap > 5000, 10 s at 500 Hz) the nearest index is off by one.
        for (gap, kept) in [(4_500u64, true), (5_500, false)] {
            let c = cell(-100.0, 500.0, 0);
            let mut est = SampleClockEstimator::new(2e6, c.latency_ns);
            est.push(c.stamp_ns(0, 0.0), false);
            let s = est.push(c.stamp_ns(gap, 0.0), false);
            assert_eq!(s.index as u64 == gap, kept, "gap {gap}: index {}", s.index);
        }
    }

    #[test]
    fn a_wrong_hop_latency_shifts_every_sample_by_hops_times_the_error() {
        let c = cell(0.0, 250.0, 40);
        // The host believes 0.5 us less per hop than the cells take.
        let believed = PROCESSING_NS + 40 * (HOP_LATENCY_NS - 500);
        let mut est = SampleClockEstimator::new(4e6, believed);
        let mut last = 0.0;
        for k in 0..1_000 {
            last = est.push(c.stamp_ns(k, 0.0), false).sample_time_ns - c.sample_ns(k);
        }
        assert!((last - 20_000.0).abs() < 16.0, "{last}");
    }

    #[test]
    fn unqueued_packets_pin_the_line_through_long_queued_stretches() {
        // Data mode, 100 ppm off: 100 unqueued packets, then 2,000 queued by 100 to 120 us
        // (a collision at the root lasting 16 s), then unqueued again.
        let c = cell(100.0, 125.0, 50);
        let mut est = SampleClockEstimator::new(8e6, c.latency_ns);
        let mut worst = 0.0f64;
        for k in 0..3_000u64 {
            let queued = (100..2_100).contains(&k);
            let q = if queued {
                100e3 + (k % 7) as f64 * 3e3
            } else {
                0.0
            };
            let s = est.push(c.stamp_ns(k, q), !queued);
            if k >= 50 {
                worst = worst.max((s.sample_time_ns - c.sample_ns(k)).abs());
            }
        }
        assert!(worst < 100.0, "worst {worst} ns");
    }

    #[test]
    fn a_box_reset_starts_over() {
        let c = cell(0.0, 250.0, 2);
        let mut est = SampleClockEstimator::new(4e6, c.latency_ns);
        for k in 0..100 {
            est.push(c.stamp_ns(k + 1_000, 0.0), false);
        }
        let s = est.push(c.stamp_ns(3, 0.0), false);
        assert_eq!(s.index, 0);
        assert!((s.sample_time_ns - c.sample_ns(3)).abs() < 8.0);
    }

    #[test]
    fn the_timer_tells_unqueued_packets_by_the_idle_line_before_them() {
        // Port 0: cell 1 (root) and cell 2 (1 hop) at 250 Hz, cell 2 sampling 40 us before
        // cell 1: its packet reaches the root (72 us later) 12 us after cell 1's started
        // and waits 38 us behind it, back to back. Cell 3 on port 1 finds its line idle.
        let paths =
            PathModel::bus_model(Positions::Listed(HashMap::from([(1, 0), (2, 1), (3, 0)])));
        let mut timer = SampleTimer::new(250.0, paths);
        let (mut worst2, mut worst3) = (0.0f64, 0.0f64);
        for k in 0..500u64 {
            let t1 = 1_000_000 + k * 4_000_000;
            let s1 = t1 + PROCESSING_NS;
            let s2 = s1 + 50_000; // queued: starts when cell 1's packet ends
            let e1 = timer.push(7, 0, 1, s1).sample_time_ns - t1 as f64;
            let e2 = timer.push(7, 0, 2, s2).sample_time_ns - (t1 - 40_000) as f64;
            let e3 = timer.push(7, 1, 3, s1).sample_time_ns - t1 as f64;
            assert!(e1.abs() < 1.0, "cell 1 at {k}: {e1}");
            worst2 = worst2.max(e2.abs());
            worst3 = worst3.max(e3.abs());
        }
        // Cell 2 never shows its own clock: it carries its 38 us of queue.
        assert!((worst2 - 38_000.0).abs() < 1.0, "{worst2}");
        assert!(worst3 < 1.0, "{worst3}");
        assert_eq!(timer.cells(), 3);
        timer.reset_box(7);
        assert_eq!(timer.cells(), 0);
    }

    #[test]
    fn the_timer_gives_each_cell_what_an_estimator_of_its_own_gives() {
        // Cells with ids far apart and in no order, on four ports, interleaved: the timer
        // must keep every cell's clock apart, and tell the unqueued packets per port.
        let ids: [u16; 6] = [900, 3, 65_535, 41, 0, 7];
        let mut noise = Noise(11);
        let cells: Vec<Cell> = ids
            .iter()
            .enumerate()
            .map(|(i, _)| cell(-90.0 + 35.0 * i as f64, 250.0, 0))
            .collect();
        let paths = PathModel::bus_model(Positions::Unknown);
        let mut timer = SampleTimer::new(250.0, paths.clone());
        let mut own: Vec<SampleClockEstimator> = ids
            .iter()
            .map(|&id| SampleClockEstimator::new(4e6, paths.latency_ns(id)))
            .collect();
        let mut last_on_port = [None::<u64>; 4];
        for k in 0..3_000u64 {
            let mut packets = Vec::new();
            for (i, c) in cells.iter().enumerate() {
                if noise.next() < 0.9 {
                    let q = if noise.next() < 0.3 {
                        0.0
                    } else {
                        noise.next() * 300e3
                    };
                    packets.push((i, c.stamp_ns(k, q)));
                }
            }
            packets.sort_by_key(|&(i, stamp)| (stamp, i));
            for (i, stamp) in packets {
                let port = i % 4;
                let unqueued = last_on_port[port]
                    .replace(stamp)
                    .is_some_and(|last| stamp - last > BACK_TO_BACK_NS);
                let t = timer.push(2, port as u8, ids[i], stamp);
                assert_eq!(t, own[i].push(stamp, unqueued), "cell {} at {k}", ids[i]);
            }
        }
        assert_eq!(timer.cells(), ids.len());
    }

    /// Pushes `stamps` (stamp, unqueued) through an incremental and a batch estimator and
    /// returns the largest difference of their sample times, ns; the sample indices and
    /// whether the period was learnt must be equal at every packet.
    fn incremental_against_batch(nominal_ns: f64, latency: u64, stamps: &[(u64, bool)]) -> f64 {
        let mut fast = SampleClockEstimator::new(nominal_ns, latency);
        let mut batch = SampleClockEstimator::new(nominal_ns, latency).batch();
        let mut worst = 0.0f64;
        for (i, &(stamp, unqueued)) in stamps.iter().enumerate() {
            let (f, b) = (fast.push(stamp, unqueued), batch.push(stamp, unqueued));
            assert_eq!(
                (f.index, f.period_learnt),
                (b.index, b.period_learnt),
                "packet {i}"
            );
            worst = worst.max((f.sample_time_ns - b.sample_time_ns).abs());
        }
        worst
    }

    #[test]
    fn the_incremental_fits_give_the_batch_fits_sample_times_to_a_nanosecond() {
        let mut noise = Noise(7);
        // data mode, one in four unqueued; event mode with gaps, none flagged unqueued
        // (the window's envelope)
        let c = cell(80.0, 250.0, 12);
        let mut stamps: Vec<(u64, bool)> = (0..20_000u64)
            .map(|k| {
                let idle = noise.next() < 0.25;
                let q = if idle { 0.0 } else { noise.next() * 600e3 };
                (c.stamp_ns(k, q), idle)
            })
            .collect();
        let mut k = 0u64;
        let e = cell(-60.0, 500.0, 3);
        while stamps.len() < 40_000 {
            for _ in 0..1 + (noise.next() * 40.0) as u64 {
                stamps.push((e.stamp_ns(k, noise.next() * 90e3), false));
                k += 1;
            }
            k += (noise.next() * 600.0) as u64;
        }
        let worst = incremental_against_batch(2e6, e.latency_ns, &stamps[20_000..]);
        assert!(worst < 1.0, "event mode: {worst} ns");
        stamps.truncate(20_000);
        // hours in: the stamps' magnitude grows, the sums stay exact
        let late: Vec<(u64, bool)> = stamps
            .iter()
            .map(|&(s, u)| (s + 5 * 3_600_000_000_000, u))
            .collect();
        // then a box reset: the stamps start over
        let reset: Vec<(u64, bool)> = stamps[..3_000].to_vec();
        stamps.extend(late);
        stamps.extend(reset);
        let worst = incremental_against_batch(4e6, c.latency_ns, &stamps);
        assert!(worst < 1.0, "data mode: {worst} ns");
    }

    #[test]
    fn floor_i64_is_floor_as_i64() {
        for x in [
            0.0,
            -0.0,
            2.5,
            -2.5,
            -2.0,
            3.0,
            0.999_999,
            -1e-300,
            4.5e15 + 0.5,
            9.3e18,
            -9.3e18,
            1e300,
            -1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ] {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x}");
        }
    }

    #[test]
    fn line_sums_remove_what_they_added() {
        let mut sums = LineSums::default();
        let points = [
            (3, 12_000_000),
            (4, 16_000_008),
            (9, 36_000_016),
            (10, 40_000_040),
        ];
        for p in points {
            sums.add(p);
        }
        let all = sums;
        sums.add((1 << 40, i64::MAX / 4));
        sums.remove((1 << 40, i64::MAX / 4));
        assert_eq!(sums, all);
        // the slope by hand: n = 4, Σk = 26, Σk² = 206, Σr = 104,000,064,
        // Σkr = 3*12e6 + 4*16,000,008 + 9*36,000,016 + 10*40,000,040 = 824,000,576
        let expected = (4.0 * 824_000_576.0 - 26.0 * 104_000_064.0) / (4.0 * 206.0 - 676.0);
        assert_eq!(sums.slope(), Some(expected));
        let period = 4_000_001.0;
        let mean = points
            .iter()
            .map(|&(k, r)| r as f64 - period * k as f64)
            .sum::<f64>()
            / 4.0;
        assert!((sums.mean_offset(period, (10, 40_000_040)) - mean).abs() < 1e-6);
        let mut one = LineSums::default();
        one.add((5, 5));
        one.add((5, 9));
        assert_eq!(one.slope(), None, "one sample index: no slope");
    }

    #[test]
    fn positions_give_the_hops() {
        let numbered = PathModel::bus_model(Positions::Numbered { cells_per_bus: 65 });
        assert_eq!(numbered.hops(1), 0);
        assert_eq!(numbered.hops(65), 64);
        assert_eq!(numbered.hops(66), 0);
        assert_eq!(numbered.latency_ns(67), 20_000 + 52_000);
        let listed = PathModel::bus_model(Positions::Listed(HashMap::from([(9, 3)])));
        assert_eq!((listed.hops(9), listed.hops(10)), (3, 0));
        assert_eq!(
            PathModel::bus_model(Positions::Unknown).latency_ns(500),
            20_000
        );
    }

    #[test]
    fn on_the_box_grid_a_stamp_less_the_path_falls_on_its_sample() {
        // 250 Hz, cells numbered 66 to a bus: cell 66 sits 65 hops from its root
        let paths = PathModel::bus_model(Positions::Numbered { cells_per_bus: 66 });
        let mut timer = SampleTimer::new(250.0, paths.clone()).on_box_grid();
        let period = 4_000_000u64;
        for (cell, n, queued_ns) in [
            (1u16, 10u64, 0u64),
            (66, 11, 0),
            (66, 12, 3_400_000),
            (30, 13, 50_000),
        ] {
            let stamp = n * period + paths.latency_ns(cell) + queued_ns;
            let t = timer.push(1, 0, cell, stamp);
            assert_eq!(t.sample_time_ns, (n * period) as f64, "cell {cell}");
            assert_eq!(t.index, n as i64);
        }
        // queued beyond 7/8 of a period the grid point is the next one: the method's limit
        let stamp = 20 * period + paths.latency_ns(66) + period * 7 / 8 + 1;
        assert_eq!(timer.push(1, 0, 66, stamp).index, 21);
        assert_eq!(timer.cells(), 0);
    }
}
