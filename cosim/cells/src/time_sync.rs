//! Cells that sample on the box's time grid (docs/time.md, method c): a model of the
//! time-sync command that the downlink will carry, at the level of the cell models.
//!
//! The box broadcasts a sync command down every bus every [`TimeSync::interval_s`], carrying
//! its send time `T`. It reaches the cell at position `h` (0 = the root) after
//! `processing + h * downlink_hop` ns. (`T` is when the packet is whole at the root: a
//! box's syncs are scheduled at their first start bit plus the packet's 50 us, with their
//! carried time advanced as much, as the cell firmware adds the packet's duration.) The cell learnt its one-way path latency from a round
//! trip through the box (the best of several, so no queueing in it) and takes half of it:
//! `(down + up) / 2`, exact only when the downlink's hops are as slow as the uplink's. On
//! receipt it sets its clock to `T + half round trip`, then lets the clock run at its own
//! rate (its drift, [`crate::CellClock::drift_ppm`]) and takes a sample each time its clock
//! passes a grid point `n / sample_rate_hz` of box time. A lost sync command leaves the
//! clock running from the previous one.
//!
//! So a cell's sample for grid point `g` falls at `g + e`, `e` being the half-round-trip
//! error plus the drift accumulated since the last sync it received. With
//! [`TimeSync::rate`] the cell also learns its rate from successive syncs ([`RateServo`]),
//! and what is left is how much its oscillator wanders ([`OscillatorNoise`]) over an
//! interval. Box time is scene time
//! here (the box's oscillator is the reference; the host maps it to its own clock, see
//! `skinbox_host::clock_map`).

use crate::config::BusConfig;
use crate::oscillator::{ClockWander, NoiseTrack, OscillatorNoise};
use crate::rng::Rng;

/// The time-sync command as the cells obey it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeSync {
    /// The box sends a sync command down every bus this often, s; the first at scene time 0.
    pub interval_s: f64,
    /// Probability that one cell misses one sync command (independent per cell and command,
    /// seeded by the scene seed).
    pub loss: f64,
    /// Relay delay per cell on the way down, ns; the uplink's is `[bus] hop_latency_ns`.
    /// Their difference halves into an error of the measured one-way latency per hop.
    pub downlink_hop_latency_ns: u64,
    /// The cells discipline their rate as well as their phase ([`RateServo`]); `false`:
    /// each sync only sets the phase.
    pub rate: bool,
}

impl TimeSync {
    /// A sync every `interval_s` on a downlink as fast as the uplink, none lost.
    pub fn every(interval_s: f64, bus: &BusConfig) -> TimeSync {
        TimeSync {
            interval_s,
            loss: 0.0,
            downlink_hop_latency_ns: bus.hop_latency_ns,
            rate: false,
        }
    }
}

/// The sample clock of one cell that obeys [`TimeSync`].
#[derive(Debug, Clone)]
pub struct SyncedClock {
    interval_s: f64,
    period_s: f64,
    drift: f64,
    /// Sync arrival after its send time, s.
    down_s: f64,
    /// What the cell believes that arrival delay to be (half its round trip), s.
    believed_down_s: f64,
    loss: f64,
    loss_rng: Rng,
    /// Index of the sync the clock runs from, and the next one not yet decided.
    current: Option<u64>,
    next: u64,
    /// Grid point of the cell's sample 0 (the first after the first sync arrives; moved
    /// when a sync brings a new time base, a box reset).
    first_grid: i64,
    /// Box time the cell believes at the first sync it takes, s.
    first_box_s: f64,
    /// The clock's drift wander and this cell's angle of it.
    wander: Option<(ClockWander, f64)>,
    /// The sync commands as a box sent them: (scene time the command left the box, s;
    /// the box time it carries, s). `None`: every `interval_s` from scene time 0, box
    /// time being scene time.
    schedule: Option<Vec<(f64, f64)>>,
    /// The rate servo (with [`TimeSync::rate`]) and, for the sync the clock runs from,
    /// (its arrival on the cell's counter, ns; the box time it set, ns).
    servo: Option<(RateServo, u64, i64)>,
    /// The oscillator's random wander and temperature steps.
    noise: Option<NoiseTrack>,
}

impl SyncedClock {
    /// The clock of the cell at chain position `position` (0 = root), with sample clock
    /// drift `drift_ppm`, on a grid of `sample_rate_hz`; `seed` and `stream` draw its lost
    /// sync commands.
    pub fn new(
        sync: &TimeSync,
        bus: &BusConfig,
        position: usize,
        drift_ppm: f64,
        sample_rate_hz: f64,
        seed: u64,
        stream: u64,
    ) -> SyncedClock {
        Self::build(
            sync,
            bus,
            position,
            (drift_ppm, sample_rate_hz),
            (seed, stream),
            None,
        )
        .expect("a sync every interval reaches every cell")
    }

    /// The clock of a cell that obeys the sync commands a box sent, `schedule`: (scene
    /// time each left the box, s; the box time it carries, s), in order. `None` when none
    /// of them reaches the cell (all lost): it keeps its free-running clock.
    pub fn scheduled(
        sync: &TimeSync,
        bus: &BusConfig,
        position: usize,
        (drift_ppm, sample_rate_hz): (f64, f64),
        (seed, stream): (u64, u64),
        schedule: Vec<(f64, f64)>,
    ) -> Option<SyncedClock> {
        Self::build(
            sync,
            bus,
            position,
            (drift_ppm, sample_rate_hz),
            (seed, stream),
            Some(schedule),
        )
    }

    fn build(
        sync: &TimeSync,
        bus: &BusConfig,
        position: usize,
        (drift_ppm, sample_rate_hz): (f64, f64),
        (seed, stream): (u64, u64),
        schedule: Option<Vec<(f64, f64)>>,
    ) -> Option<SyncedClock> {
        let hops = position as f64;
        let down_ns = bus.processing_ns as f64 + hops * sync.downlink_hop_latency_ns as f64;
        let up_ns = bus.processing_ns as f64 + hops * bus.hop_latency_ns as f64;
        let period_s = 1.0 / sample_rate_hz;
        let mut clock = SyncedClock {
            interval_s: sync.interval_s,
            period_s,
            drift: drift_ppm * 1e-6,
            down_s: down_ns * 1e-9,
            believed_down_s: (down_ns + up_ns) * 0.5e-9,
            loss: sync.loss,
            loss_rng: Rng::for_stream(seed ^ 0x5F9C, stream),
            current: None,
            next: 0,
            first_grid: 0,
            first_box_s: 0.0,
            wander: None,
            schedule,
            servo: sync.rate.then_some((RateServo::default(), 0, 0)),
            noise: None,
        };
        // The cell starts sampling on the grid after the first sync it receives.
        while clock.current.is_none() {
            if let Some(s) = &clock.schedule {
                if clock.next as usize >= s.len() {
                    return None;
                }
            }
            clock.advance();
        }
        // (box time: the first sync's arrival, as the cell believes it)
        let first = clock.current.unwrap_or(0);
        let first_box_s = match clock.schedule {
            Some(_) => clock.sent_box_s(first) + clock.believed_down_s,
            None => clock.arrival_s(first),
        };
        clock.first_grid = (first_box_s / period_s).ceil() as i64;
        clock.first_box_s = first_box_s;
        Some(clock)
    }

    /// The box time sync `j` carries, s.
    fn sent_box_s(&self, j: u64) -> f64 {
        match &self.schedule {
            Some(s) => s.get(j as usize).map_or(f64::INFINITY, |e| e.1),
            None => j as f64 * self.interval_s,
        }
    }

    /// The same clock with its drift wandering ([`ClockWander`], this cell's `angle`).
    pub fn with_wander(mut self, wander: ClockWander, angle: f64) -> SyncedClock {
        self.wander = Some((wander, angle));
        self
    }

    /// Decides whether the next sync command arrives; takes it if it does.
    fn advance(&mut self) {
        let j = self.next;
        self.next += 1;
        if !(self.loss > 0.0 && self.loss_rng.uniform() < self.loss) {
            self.current = Some(j);
            if self.servo.is_some() {
                let local = (self.local_s(self.arrival_s(j)) * 1e9).round() as u64;
                let set_to = ((self.sent_box_s(j) + self.believed_down_s) * 1e9).round() as i64;
                if let Some((servo, l, b)) = &mut self.servo {
                    servo.on_sync(local, set_to);
                    (*l, *b) = (local, set_to);
                }
            }
        }
    }

    /// The same clock with its oscillator wandering at random ([`OscillatorNoise`]);
    /// `seed` and `stream` draw the wander.
    pub fn with_noise(mut self, noise: OscillatorNoise, seed: u64, stream: u64) -> SyncedClock {
        self.noise = Some(NoiseTrack::new(
            noise,
            Rng::for_stream(seed ^ 0x7E4F, stream),
        ));
        self
    }

    /// The cell's own counter (its oscillator's time) at true time `t_s`, s: steady drift,
    /// the sinusoidal wander and the random one integrated from time 0.
    fn local_s(&mut self, t_s: f64) -> f64 {
        let mut ppm_s = self.drift * 1e6 * t_s;
        if let Some((w, angle)) = self.wander {
            let omega = std::f64::consts::TAU / w.period_s.max(1e-9);
            ppm_s += w.amplitude_ppm * ((angle).cos() - (omega * t_s + angle).cos()) / omega;
        }
        if let Some(n) = &mut self.noise {
            ppm_s += n.integral_ppm_s(t_s);
        }
        t_s + ppm_s * 1e-6
    }

    /// Under the rate servo: the true time the cell's counter reaches grid point
    /// `grid_s` (box time), counted from the sync it runs from.
    fn time_under_servo(&mut self, j: u64, grid_s: f64) -> f64 {
        let Some((servo, local, set_to)) = self.servo else {
            unreachable!("called with a servo")
        };
        let target = local as i64 + servo.local_elapsed_ns((grid_s * 1e9).round() as i64 - set_to);
        let target_s = target as f64 * 1e-9;
        // the counter runs at 1 + drift, drift well under 1e-3: each step gains three digits
        let mut t = self.arrival_s(j) + (target - local as i64) as f64 * 1e-9;
        for _ in 0..4 {
            t -= self.local_s(t) - target_s;
        }
        t
    }

    fn arrival_s(&self, j: u64) -> f64 {
        match &self.schedule {
            Some(s) => s.get(j as usize).map_or(f64::INFINITY, |e| e.0) + self.down_s,
            None => j as f64 * self.interval_s + self.down_s,
        }
    }

    /// True time of the sample for grid point `first + n` under sync `j`.
    fn time_under(&mut self, j: u64, grid_s: f64) -> f64 {
        if self.servo.is_some() {
            return self.time_under_servo(j, grid_s);
        }
        let set_to_s = self.sent_box_s(j) + self.believed_down_s;
        // A wandering drift, taken at the middle of the stretch since the sync (its mean
        // there, to second order).
        let drift = match self.wander {
            Some((w, angle)) => {
                w.drift_ppm(self.drift * 1e6, angle, (self.arrival_s(j) + grid_s) / 2.0) * 1e-6
            }
            None => self.drift,
        };
        let a = self.arrival_s(j);
        let noise = match &mut self.noise {
            Some(n) => n.mean_ppm(a, grid_s.max(a)) * 1e-6,
            None => 0.0,
        };
        a + (grid_s - set_to_s) / (1.0 + drift + noise)
    }

    /// After taking sync `new` (under `old` until then) before sample `n`: a clock set
    /// more than half a period from where it ran is a new time base (the box was reset),
    /// and the cell's next sample is the first grid point after it.
    fn rebase(&mut self, old: u64, new: u64, n: u64) {
        let arrival = self.arrival_s(new);
        let ran_to = self.sent_box_s(old)
            + self.believed_down_s
            + (arrival - self.arrival_s(old)) * (1.0 + self.drift);
        let set_to = self.sent_box_s(new) + self.believed_down_s;
        if (ran_to - set_to).abs() > self.period_s / 2.0 {
            self.first_grid = (set_to / self.period_s).ceil() as i64 - n as i64;
        }
    }

    /// A sample-rate command taken at sample `n` (the sample stays where it is): from the
    /// next sample on the cell samples at `hz` on the box's grid, at the first grid point
    /// of the new period after sample `n`'s.
    pub fn set_rate(&mut self, hz: f64, n: u64) {
        let at_s = self.grid_s(n);
        self.period_s = 1.0 / hz;
        // the grid point after `at_s` (a grid point of the new period too, to the ns, is not
        // taken again)
        let next = (at_s / self.period_s + 1e-6).floor() as i64 + 1;
        self.first_grid = next - (n as i64 + 1);
    }

    /// A sample-rate command taken while the cell still runs free: it starts on the grid
    /// of `hz`, at its first point after the first sync.
    pub fn set_rate_before_first_sync(&mut self, hz: f64) {
        self.period_s = 1.0 / hz;
        self.first_grid = (self.first_box_s / self.period_s).ceil() as i64;
    }

    /// The true time the first sync the cell takes reaches it, s (a cell runs free until
    /// then).
    pub fn first_sync_arrival_s(&self) -> f64 {
        self.arrival_s(self.current.unwrap_or(0))
    }

    /// The grid point (box time, s) of the cell's sample `n` (0 = its first).
    pub fn grid_s(&self, n: u64) -> f64 {
        (self.first_grid + n as i64) as f64 * self.period_s
    }

    /// The true time of the cell's sample `n` (0 = its first), s; call with `n` rising.
    pub fn sample_time_s(&mut self, n: u64) -> f64 {
        loop {
            let j = self.current.unwrap_or(0);
            let t = self.time_under(j, self.grid_s(n));
            // A sync arriving before this sample resets the clock first.
            if self.arrival_s(self.next) <= t {
                let before = self.current;
                self.advance();
                if let (Some(old), Some(new)) = (before, self.current) {
                    self.rebase(old, new, n);
                }
                continue;
            }
            return t;
        }
    }
}

/// The frequency half of a PTP-like servo, as a cell's firmware runs it (docs/time.md,
/// "The rate servo"): integers only, 12 bytes of state, one 64/32 division per sync and
/// one 32 x 32 multiplication per sample.
///
/// At each sync the cell takes its counter `L` at the sync's arrival and the box time `B`
/// the sync sets (its tick plus the path latency from the hop count). Over the stretch
/// since the previous sync its counter ran `dl = L - L'` against the box's `db = B - B'`;
/// its rate correction is `c = (dl - db) * 2^32 / db` (Q32: counter ticks gained per box
/// tick). It then schedules the sample for grid point `g` at counter
/// `L + (g - B) + ((g - B) * c >> 32)`. A stretch over 2^32 ns or off by more than
/// 1/1024 (a box reset, a new time base) leaves `c` as it was. A sync less than
/// [`RateServo::MIN_STRETCH_NS`] after the previous one (the box's and a host's back to
/// back) sets the phase only: the rate is learnt from the earlier to the next.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RateServo {
    /// The previous sync: (counter at its arrival, ns; the box time it set, ns).
    last: Option<(u64, i64)>,
    /// The rate correction, Q32.
    correction_q32: i32,
}

impl RateServo {
    /// The shortest stretch a rate is learnt over, ns (2^24, 16.8 ms): over 50 us (two
    /// syncs one after the other on a bus) a count's rounding alone is 20 ppm.
    pub const MIN_STRETCH_NS: i64 = 1 << 24;

    /// Takes a sync that arrived at counter `local_ns` and set box time `box_ns`.
    pub fn on_sync(&mut self, local_ns: u64, box_ns: i64) {
        if let Some((l, b)) = self.last {
            let dl = local_ns.wrapping_sub(l) as i64;
            let db = box_ns - b;
            if (0..Self::MIN_STRETCH_NS).contains(&db) {
                return;
            }
            if db > 0 && db < 1 << 32 && (dl - db).abs() * 1024 < db {
                self.correction_q32 = (((dl - db) << 32) / db) as i32;
            }
        }
        self.last = Some((local_ns, box_ns));
    }

    /// The rate correction, counter ticks gained per box tick.
    pub fn correction(&self) -> f64 {
        self.correction_q32 as f64 / (1u64 << 32) as f64
    }

    /// Counter ticks for `box_ns` of box time.
    pub fn local_elapsed_ns(&self, box_ns: i64) -> i64 {
        box_ns + ((box_ns as i128 * self.correction_q32 as i128) >> 32) as i64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bus() -> BusConfig {
        BusConfig::default()
    }

    #[test]
    fn a_symmetric_bus_without_drift_samples_on_the_grid() {
        let sync = TimeSync::every(0.1, &bus());
        for position in [0, 10, 65] {
            let mut clock = SyncedClock::new(&sync, &bus(), position, 0.0, 250.0, 1, 2);
            for n in 0..1_000 {
                let t = clock.sample_time_s(n);
                assert!((t - clock.grid_s(n)).abs() < 1e-12, "{position} {n}");
            }
        }
    }

    #[test]
    fn drift_accumulates_between_syncs_and_resets_at_each() {
        // 100 ppm fast, sync every 0.1 s: the clock gains up to 10 us before the next sync
        // (sample times come early), then starts over.
        let sync = TimeSync::every(0.1, &bus());
        let mut clock = SyncedClock::new(&sync, &bus(), 0, 100.0, 500.0, 1, 2);
        let mut worst = 0.0f64;
        for n in 0..2_000 {
            let e = clock.sample_time_s(n) - clock.grid_s(n);
            assert!(e <= 1e-12, "a fast clock samples early, {e}");
            worst = worst.min(e);
        }
        assert!((worst + 10e-6).abs() < 0.1e-6, "worst {worst}");
    }

    #[test]
    fn an_asymmetric_downlink_halves_into_the_error() {
        // Down 2 us per hop slower than up: half a round trip is 1 us per hop short of the
        // way down, so the cell's clock runs 1 us per hop behind and samples late.
        let b = bus();
        let sync = TimeSync {
            downlink_hop_latency_ns: b.hop_latency_ns + 2_000,
            ..TimeSync::every(0.1, &b)
        };
        let mut clock = SyncedClock::new(&sync, &b, 40, 0.0, 125.0, 1, 2);
        let e = clock.sample_time_s(100) - clock.grid_s(100);
        assert!((e - 40e-6).abs() < 1e-12, "{e}");
    }

    #[test]
    fn lost_syncs_let_the_drift_grow() {
        let b = bus();
        let sync = TimeSync {
            loss: 0.5,
            ..TimeSync::every(0.1, &b)
        };
        let mut clock = SyncedClock::new(&sync, &b, 0, -100.0, 500.0, 7, 3);
        let worst = (0..5_000)
            .map(|n| clock.sample_time_s(n) - clock.grid_s(n))
            .fold(0.0f64, f64::max);
        // slow clock: late; with half the syncs lost some gaps are several intervals
        assert!(worst > 20e-6, "worst {worst}");
    }
}

#[cfg(test)]
mod scheduled_tests {
    use super::*;

    #[test]
    fn a_new_time_base_moves_the_samples_onto_its_grid_at_the_next_sync() {
        // syncs at scene 0, 0.1, 0.2 s; the third carries box time 0.0537 s (a box reset):
        // from its arrival on, samples fall on grid points of the new base, 8 ms apart
        let bus = BusConfig::default();
        let sync = TimeSync::every(0.1, &bus);
        let schedule = vec![(0.0, 0.0), (0.1, 0.1), (0.2, 0.0537)];
        let mut clock = SyncedClock::scheduled(&sync, &bus, 3, (0.0, 125.0), (1, 0), schedule)
            .expect("syncs reach the cell");
        let times: Vec<f64> = (0..40).map(|n| clock.sample_time_s(n)).collect();
        assert!(times.windows(2).all(|w| w[1] > w[0]), "{times:?}");
        let down = (bus.processing_ns + 3 * bus.hop_latency_ns) as f64 * 1e-9;
        let arrival = 0.2 + down;
        let after: Vec<f64> = times.iter().copied().filter(|t| *t > arrival).collect();
        assert!(after.len() >= 10, "{times:?}");
        for t in &after {
            // scene time t is box time t - 0.2 + 0.0537 (the same down, believed exactly)
            let box_s = t - 0.2 + 0.0537;
            let off_grid = (box_s / 0.008 - (box_s / 0.008).round()).abs() * 0.008;
            assert!(
                off_grid < 1e-9,
                "sample at {t}: {off_grid} s off the new grid"
            );
        }
        assert!((after[1] - after[0] - 0.008).abs() < 1e-9);
    }
}

#[cfg(test)]
mod servo_tests {
    use super::*;

    #[test]
    fn the_servo_learns_a_rate_in_q32_and_ignores_a_new_time_base() {
        let mut servo = RateServo::default();
        servo.on_sync(1_000, 0);
        assert_eq!(
            servo.local_elapsed_ns(8_000_000),
            8_000_000,
            "no rate before two syncs"
        );
        // 10 us gained over 0.1 s: 100 ppm, 429_496.7296 in Q32, truncated
        servo.on_sync(1_000 + 100_010_000, 100_000_000);
        assert_eq!(servo.correction_q32, 429_496);
        // 8 ms of box time: 800 ns more counter, less the truncation (799.9998)
        assert_eq!(servo.local_elapsed_ns(8_000_000), 8_000_799);
        // a stretch 0.2 % off is a reset: the rate stays
        servo.on_sync(1_000 + 200_010_000 + 200_000, 200_000_000);
        assert_eq!(servo.correction_q32, 429_496);
    }

    #[test]
    fn a_sync_right_after_another_sets_no_rate() {
        let mut servo = RateServo::default();
        servo.on_sync(0, 0);
        servo.on_sync(100_010_000, 100_000_000);
        assert_eq!(servo.correction_q32, 429_496);
        // 50 us later (the next packet on the bus), its count rounded 1 ns the wrong way:
        // over that stretch, 20 ppm off
        servo.on_sync(100_010_000 + 50_004, 100_050_000);
        assert_eq!(servo.correction_q32, 429_496);
        // the next is learnt from the sync before the close one: 50 ppm over 0.1 s
        servo.on_sync(100_010_000 + 100_005_000, 200_000_000);
        assert_eq!(servo.correction_q32, 214_748);
        // and a stretch just long enough counts
        let stretch = RateServo::MIN_STRETCH_NS;
        servo.on_sync(200_015_000 + stretch as u64, 200_000_000 + stretch);
        assert_eq!(servo.correction_q32, 0);
    }

    fn worst_us(rate: bool, noise: Option<OscillatorNoise>, rate_hz: f64, n: u64) -> f64 {
        let b = BusConfig::default();
        let sync = TimeSync {
            rate,
            ..TimeSync::every(0.1, &b)
        };
        let mut clock = SyncedClock::new(&sync, &b, 65, 100.0, rate_hz, 3, 4);
        if let Some(noise) = noise {
            clock = clock.with_noise(noise, 3, 4);
        }
        // from the third sync on (the rate is learnt from the first two)
        let from = (0.2 * rate_hz) as u64 + 1;
        (from..n)
            .map(|k| (clock.sample_time_s(k) - clock.grid_s(k)).abs() * 1e6)
            .fold(0.0, f64::max)
    }

    #[test]
    fn a_steady_drift_is_learnt_to_the_nanosecond() {
        // phase only: 100 ppm over the last sample's distance from its sync, within one
        // 2 ms period of 0.1 s: 9.8 to 10 us; with the rate, what is left is the counter's
        // 1 ns rounding over a stretch (1e-8) and Q32's truncation
        let phase = worst_us(false, None, 500.0, 5_000);
        assert!(phase > 9.8 - 1e-6 && phase <= 10.0, "{phase}");
        let rate = worst_us(true, None, 500.0, 5_000);
        assert!(rate < 0.005, "{rate}");
    }

    #[test]
    fn a_temperature_step_costs_the_step_times_the_interval() {
        // a 1 ppm step (and nothing else) every 2 s: within the stretch of the step the
        // clock is off by at most 1 ppm x 0.1 s = 0.1 us, and the rate learnt across it is
        // off by at most the step, so the next stretch as much again
        let step = OscillatorNoise {
            random_walk_ppm: 0.0,
            step_ppm: 1.0,
            step_interval_s: 2.0,
        };
        let rate = worst_us(true, Some(step), 125.0, 1_250);
        assert!(rate > 0.02 && rate <= 0.1 + 0.005, "{rate}");
    }

    #[test]
    fn with_a_realistic_oscillator_the_rate_servo_holds_a_microsecond() {
        // the steps (1 ppm) bound the servo's error at 0.2 us (the test above); the random
        // walk adds 0.05 ppm x sqrt(0.1 s) x 0.1 s, a nanosecond or two. Phase only keeps
        // its 100 ppm x 0.1 s, give or take a step's 0.1 us.
        let realistic = Some(OscillatorNoise::realistic());
        let rate = worst_us(true, realistic, 500.0, 10_000);
        assert!(rate < 0.25, "{rate}");
        let phase = worst_us(false, realistic, 500.0, 10_000);
        assert!(phase > 9.7 && phase < 10.2, "{phase}");
    }

    /// Syncs every 0.1 s at 100 ppm, with the servo or phase only; the fifth carries a box time moved by
    /// `jump_s` (a box reset). The worst error against the new base from then on.
    fn after_reset_us(rate: bool, jump_s: f64) -> f64 {
        let b = BusConfig::default();
        let sync = TimeSync {
            rate,
            ..TimeSync::every(0.1, &b)
        };
        let schedule: Vec<(f64, f64)> = (0..20)
            .map(|j| {
                let t = j as f64 * 0.1;
                (t, if j >= 5 { t + jump_s } else { t })
            })
            .collect();
        let mut clock = SyncedClock::scheduled(&sync, &b, 0, (100.0, 125.0), (1, 0), schedule)
            .expect("syncs reach the cell");
        let down = b.processing_ns as f64 * 1e-9;
        let mut worst = 0.0f64;
        for n in 0..220 {
            let t = clock.sample_time_s(n);
            if t > 0.5 + down && t < 1.9 {
                // box time at true time t is t + jump_s; the sample's grid point is box time
                let box_s = t + jump_s;
                let off = (box_s * 125.0 - (box_s * 125.0).round()) / 125.0;
                worst = worst.max(off.abs() * 1e6);
            }
        }
        worst
    }

    #[test]
    fn the_servo_keeps_its_rate_across_a_box_reset_unless_the_jump_is_under_1_in_1024() {
        // A new time base seconds away (or 0.2 ms, over 1/1024 of the 0.1 s stretch) is
        // no rate: the servo keeps its 100 ppm and the samples fall on the new grid within
        // nanoseconds. A jump of 30 us over 0.1 s passes for a rate 300 ppm off, which
        // the stretch after it turns into up to 30 us, until the next sync learns again.
        assert!(after_reset_us(true, 3.0537) < 0.01);
        assert!(after_reset_us(true, 0.0002) < 0.01);
        let small = after_reset_us(true, 30e-6);
        assert!(small > 20.0 && small < 31.0, "{small}");
        // phase only takes every jump at the next sync and keeps its 100 ppm x 0.1 s
        for jump in [3.0537, 0.0002, 30e-6] {
            let phase = after_reset_us(false, jump);
            assert!(phase > 9.0 && phase <= 10.0, "{jump}: {phase}");
        }
    }
}
