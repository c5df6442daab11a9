//! Box time to host time: maps the box's 8 ns ticks (since the box's reset) to a host clock,
//! with the mapping's own error bound (docs/time.md).
//!
//! [`ClockMap`] learns from NTP-style exchanges with the box's "read tick" command
//! ([`TimeExchange`]: host send time, box receive and send ticks, host receive time). One
//! exchange says that, at the box's midpoint, host time minus box time lies within half the
//! exchange's round trip (less the box's turnaround) of the midpoint offset, whatever the
//! path's asymmetry (RFC 5905 section 8). Over many exchanges the map fits the offset as a
//! line in box time (the slope is the box oscillator's drift against the host clock, by
//! least squares over the exchanges with the shortest round trips), through the best of the
//! latest exchanges, and bounds its error by the worst of those exchanges' half round trips
//! plus their distance from the line; beyond them the bound grows with the slope's own
//! uncertainty.
//!
//! [`ReceiveStampMap`] is the fallback without a command path: the kernel's receive
//! timestamps of the datagrams (SO_TIMESTAMPNS on the live socket, the pcap's timestamps)
//! against their records' ticks. A datagram leaves the box some time after its records
//! were stamped and needs time to arrive, never less, so the lower envelope of host receive
//! time minus box time is the offset plus the shortest such delay: the map is late by that
//! delay, which one-way stamps cannot show, so it has no error bound.
//!
//! A box reset (a new boot id; for the fallback, box time jumping back by more than a
//! second) starts either map over.

use std::collections::VecDeque;

/// Nanoseconds per box tick.
const TICK_NS: f64 = skinbox_protocol::TICK_NS as f64;
/// Exchanges a [`ClockMap`] keeps.
pub const EXCHANGES: usize = 64;
/// The latest exchanges among which [`ClockMap`]'s line takes its anchor (the shortest
/// round trip of them).
pub const RECENT: usize = 8;
/// Largest drift between the box's oscillator and a host clock assumed before the map has
/// measured it, ppm (a crystal of +-50 ppm on each side, doubled).
pub const ASSUMED_DRIFT_PPM: f64 = 200.0;

/// One exchange of the box's "read tick" command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimeExchange {
    /// Host clock when the command was sent, ns.
    pub host_send_ns: u64,
    /// Box tick when the command arrived.
    pub box_receive_tick: u64,
    /// Box tick when the answer left.
    pub box_send_tick: u64,
    /// Host clock when the answer arrived, ns.
    pub host_receive_ns: u64,
}

/// An exchange that cannot be true.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ExchangeError {
    /// The answer arrived before the command left.
    #[error("host receive time {receive_ns} ns is before its send time {send_ns} ns")]
    HostTimeBackwards {
        /// Host send time, ns.
        send_ns: u64,
        /// Host receive time, ns.
        receive_ns: u64,
    },
    /// The box answered before it received.
    #[error("box send tick {send_tick} is before its receive tick {receive_tick}")]
    BoxTimeBackwards {
        /// Box receive tick.
        receive_tick: u64,
        /// Box send tick.
        send_tick: u64,
    },
    /// The box held the command longer than the host waited.
    #[error("the box held the command {box_ns} ns, longer than the round trip of {host_ns} ns")]
    TurnaroundTooLong {
        /// Box turnaround, ns.
        box_ns: u64,
        /// Host round trip, ns.
        host_ns: u64,
    },
}

impl TimeExchange {
    /// Box time of the exchange's midpoint, ns.
    pub fn box_mid_ns(&self) -> f64 {
        (self.box_receive_tick + self.box_send_tick) as f64 * TICK_NS / 2.0
    }

    /// Host minus box time at the midpoint, ns (exact when the path is symmetric).
    pub fn offset_ns(&self) -> f64 {
        (self.host_send_ns as f64 + self.host_receive_ns as f64) / 2.0 - self.box_mid_ns()
    }

    /// Round trip less the box's turnaround, ns: the true offset lies within half of it of
    /// [`TimeExchange::offset_ns`].
    pub fn delay_ns(&self) -> f64 {
        (self.host_receive_ns - self.host_send_ns) as f64
            - (self.box_send_tick - self.box_receive_tick) as f64 * TICK_NS
    }

    /// Checks that the exchange can be true.
    pub fn check(&self) -> Result<(), ExchangeError> {
        if self.host_receive_ns < self.host_send_ns {
            return Err(ExchangeError::HostTimeBackwards {
                send_ns: self.host_send_ns,
                receive_ns: self.host_receive_ns,
            });
        }
        if self.box_send_tick < self.box_receive_tick {
            return Err(ExchangeError::BoxTimeBackwards {
                receive_tick: self.box_receive_tick,
                send_tick: self.box_send_tick,
            });
        }
        let box_ns = (self.box_send_tick - self.box_receive_tick) * skinbox_protocol::TICK_NS;
        let host_ns = self.host_receive_ns - self.host_send_ns;
        if box_ns > host_ns {
            return Err(ExchangeError::TurnaroundTooLong { box_ns, host_ns });
        }
        Ok(())
    }
}

/// A box tick in host time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HostTime {
    /// Host clock, ns.
    pub host_ns: f64,
    /// The mapping's error bound, ns; `None` where it has none (the receive-stamp
    /// fallback is late by an unknown delay).
    pub error_bound_ns: Option<f64>,
}

/// Offset line: host - box = `offset_ns + slope * (box_ns - x0_ns)`.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Line {
    x0_ns: f64,
    offset_ns: f64,
    slope: f64,
    /// Largest error at the fitted exchanges, ns.
    bound_ns: f64,
    /// Uncertainty of the slope (ns per ns).
    slope_bound: f64,
    /// Box time span of the fitted exchanges, ns.
    first_ns: f64,
    last_ns: f64,
}

impl Line {
    fn at(&self, box_ns: f64) -> HostTime {
        let outside = if box_ns > self.last_ns {
            box_ns - self.last_ns
        } else if box_ns < self.first_ns {
            self.first_ns - box_ns
        } else {
            0.0
        };
        HostTime {
            host_ns: box_ns + self.offset_ns + self.slope * (box_ns - self.x0_ns),
            error_bound_ns: Some(self.bound_ns + self.slope_bound * outside),
        }
    }
}

/// Box ticks to a host clock from [`TimeExchange`]s; see the module documentation.
#[derive(Debug, Clone, Default)]
pub struct ClockMap {
    boot_id: Option<u32>,
    exchanges: VecDeque<TimeExchange>,
    line: Option<Line>,
    restarts: u64,
}

impl ClockMap {
    /// An empty map.
    pub fn new() -> ClockMap {
        ClockMap::default()
    }

    /// Takes one exchange with the box of boot id `boot_id`; a new boot id, or box time
    /// before the last exchange's, starts the map over (the box was reset).
    pub fn push(&mut self, boot_id: u32, exchange: TimeExchange) -> Result<(), ExchangeError> {
        exchange.check()?;
        let went_back = self
            .exchanges
            .back()
            .is_some_and(|last| exchange.box_receive_tick < last.box_send_tick);
        if self.boot_id.is_some_and(|b| b != boot_id) || went_back {
            self.exchanges.clear();
            self.line = None;
            self.restarts += 1;
        }
        self.boot_id = Some(boot_id);
        if self.exchanges.len() == EXCHANGES {
            self.exchanges.pop_front();
        }
        self.exchanges.push_back(exchange);
        self.fit();
        Ok(())
    }

    /// Times the map started over on a box reset.
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// Boot id of the box the map is for.
    pub fn boot_id(&self) -> Option<u32> {
        self.boot_id
    }

    /// The box oscillator's drift against the host clock, ppm (positive: the box is slow,
    /// host time passes faster), once measured.
    pub fn drift_ppm(&self) -> Option<f64> {
        self.line
            .filter(|l| l.last_ns > l.first_ns)
            .map(|l| l.slope * 1e6)
    }

    /// Bound of [`ClockMap::drift_ppm`]'s error, ppm.
    pub fn drift_bound_ppm(&self) -> Option<f64> {
        self.line
            .filter(|l| l.last_ns > l.first_ns)
            .map(|l| l.slope_bound * 1e6)
    }

    /// Error bound at the last exchange's box time, ns.
    pub fn last_bound_ns(&self) -> Option<f64> {
        let last = self.exchanges.back()?;
        self.ns_to_host(last.box_mid_ns())?.error_bound_ns
    }

    /// Host time of box tick `tick`, with its error bound; `None` before any exchange.
    pub fn to_host(&self, tick: u64) -> Option<HostTime> {
        self.line.map(|l| l.at(tick as f64 * TICK_NS))
    }

    /// Host time of box time `box_ns` (ns since the box's reset).
    pub fn ns_to_host(&self, box_ns: f64) -> Option<HostTime> {
        self.line.map(|l| l.at(box_ns))
    }

    fn fit(&mut self) {
        // The exchanges with the shortest round trips (the least room for asymmetry): the
        // best quarter, at least one.
        let mut delays: Vec<f64> = self.exchanges.iter().map(|e| e.delay_ns()).collect();
        delays.sort_by(f64::total_cmp);
        let cut = delays[(delays.len() - 1) / 4];
        let kept: Vec<&TimeExchange> = self
            .exchanges
            .iter()
            .filter(|e| e.delay_ns() <= cut)
            .collect();
        let n = kept.len() as f64;
        let x0_ns = kept.iter().map(|e| e.box_mid_ns()).sum::<f64>() / n;
        let mean_offset = kept.iter().map(|e| e.offset_ns()).sum::<f64>() / n;
        let first_ns = kept
            .iter()
            .map(|e| e.box_mid_ns())
            .fold(f64::INFINITY, f64::min);
        let last_ns = kept
            .iter()
            .map(|e| e.box_mid_ns())
            .fold(f64::NEG_INFINITY, f64::max);
        let (sxy, sxx) = kept.iter().fold((0.0, 0.0), |(a, b), e| {
            let dx = e.box_mid_ns() - x0_ns;
            (a + dx * (e.offset_ns() - mean_offset), b + dx * dx)
        });
        // The slope needs a span (below a millisecond the offset alone is fitted), and no
        // oscillator drifts beyond the assumed.
        let max_slope = ASSUMED_DRIFT_PPM * 1e-6;
        let slope = if last_ns - first_ns > 1e6 && sxx > 0.0 {
            (sxy / sxx).clamp(-max_slope, max_slope)
        } else {
            0.0
        };
        // The line passes through the best of the latest exchanges: host times are mostly
        // wanted now, where the slope's error then matters least.
        // (if one of them is among the best quarter; else through the kept ones' centre).
        let recent = self.exchanges.len().saturating_sub(RECENT);
        let anchor = self
            .exchanges
            .range(recent..)
            .filter(|e| e.delay_ns() <= cut)
            .min_by(|a, b| a.delay_ns().total_cmp(&b.delay_ns()));
        let (x0_ns, mean_offset) = match anchor {
            Some(a) => (a.box_mid_ns(), a.offset_ns()),
            None => (x0_ns, mean_offset),
        };
        let span = last_ns - first_ns;
        let line = |x: f64| mean_offset + slope * (x - x0_ns);
        let bound_ns = kept
            .iter()
            .map(|e| (e.offset_ns() - line(e.box_mid_ns())).abs() + e.delay_ns() / 2.0)
            .fold(0.0, f64::max);
        let slope_bound = if span > 1e6 {
            // Both ends may be off by the bound in opposite directions.
            (2.0 * bound_ns / span).max(1e-9)
        } else {
            max_slope
        };
        self.line = Some(Line {
            x0_ns,
            offset_ns: mean_offset,
            slope,
            bound_ns,
            slope_bound,
            first_ns,
            last_ns,
        });
    }
}

/// Box ticks to a host clock from the kernel's receive timestamps of datagrams (the
/// fallback without a command path); see the module documentation.
#[derive(Debug, Clone, Default)]
pub struct ReceiveStampMap {
    /// (box ns, host receive ns - box ns): the lowest point of each [`BUCKET_NS`] of box
    /// time, the last [`BUCKETS`] of them.
    points: VecDeque<(f64, f64)>,
    last_box_ns: Option<f64>,
    line: Option<(f64, f64, f64)>,
    since_fit: u32,
    restarts: u64,
}

/// Box time over which a [`ReceiveStampMap`] keeps only the lowest point, ns.
pub const BUCKET_NS: f64 = 100e6;
/// Buckets a [`ReceiveStampMap`] keeps: a minute of box time.
pub const BUCKETS: usize = 600;
/// Box time the kept points must span before the envelope's slope counts as drift, ns.
pub const MIN_DRIFT_SPAN_NS: f64 = 1e9;
/// How far box time must jump back for [`ReceiveStampMap`] to take it as a box reset, ns.
pub const RESET_JUMP_NS: f64 = 1e9;

impl ReceiveStampMap {
    /// An empty map.
    pub fn new() -> ReceiveStampMap {
        ReceiveStampMap::default()
    }

    /// Takes a record stamped at box tick `tick` whose datagram was received at
    /// `host_receive_ns` on the host clock; box time more than [`RESET_JUMP_NS`] before the
    /// last starts over (the records of one datagram, from several ports, are not in tick
    /// order, but within the flush timeout).
    pub fn push(&mut self, tick: u64, host_receive_ns: u64) {
        let box_ns = tick as f64 * TICK_NS;
        if self
            .last_box_ns
            .is_some_and(|last| box_ns < last - RESET_JUMP_NS)
        {
            self.points.clear();
            self.line = None;
            self.last_box_ns = None;
            self.restarts += 1;
        }
        self.last_box_ns = Some(self.last_box_ns.map_or(box_ns, |l| l.max(box_ns)));
        let offset = host_receive_ns as f64 - box_ns;
        let bucket = (box_ns / BUCKET_NS).floor();
        match self.points.back_mut() {
            Some(last) if (last.0 / BUCKET_NS).floor() == bucket => {
                if offset < last.1 {
                    *last = (box_ns, offset);
                }
            }
            _ => {
                if self.points.len() == BUCKETS {
                    self.points.pop_front();
                }
                self.points.push_back((box_ns, offset));
            }
        }
        self.since_fit += 1;
        match &mut self.line {
            Some((x0, o0, slope)) if self.since_fit < 64 => {
                // Between fits only the envelope follows a lower point.
                let predicted = *o0 + *slope * (box_ns - *x0);
                if offset < predicted {
                    *o0 -= predicted - offset;
                }
            }
            _ => self.fit(),
        }
    }

    /// Times the map started over on a box reset.
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// The box oscillator's drift against the host clock from the envelope's slope, ppm
    /// (positive: the box is slow), once the kept points span [`MIN_DRIFT_SPAN_NS`].
    pub fn drift_ppm(&self) -> Option<f64> {
        let span = match (self.points.front(), self.points.back()) {
            (Some(a), Some(b)) => b.0 - a.0,
            _ => 0.0,
        };
        self.line
            .filter(|_| span >= MIN_DRIFT_SPAN_NS)
            .map(|(_, _, slope)| slope * 1e6)
    }

    /// Host time of box tick `tick` (late by the shortest delay from a record to its
    /// datagram's arrival; no bound).
    pub fn to_host(&self, tick: u64) -> Option<HostTime> {
        let box_ns = tick as f64 * TICK_NS;
        self.line.map(|(x0, o0, slope)| HostTime {
            host_ns: box_ns + o0 + slope * (box_ns - x0),
            error_bound_ns: None,
        })
    }

    /// The lower envelope: the line through the lowest point of each half of the kept
    /// points (one point: flat through it), lowered to pass under every point.
    fn fit(&mut self) {
        self.since_fit = 0;
        let lowest = |from: usize, to: usize| {
            self.points
                .range(from..to)
                .copied()
                .min_by(|a, b| a.1.total_cmp(&b.1))
        };
        let half = self.points.len() / 2;
        // A drift beyond any oscillator's is no box running in real time (a replay, say):
        // clamped to the largest assumed.
        let max_slope = ASSUMED_DRIFT_PPM * 1e-6;
        let (x0, o0, slope) = match (lowest(0, half), lowest(half, self.points.len())) {
            (Some(a), Some(b)) if b.0 - a.0 >= MIN_DRIFT_SPAN_NS / 2.0 => (
                a.0,
                a.1,
                ((b.1 - a.1) / (b.0 - a.0)).clamp(-max_slope, max_slope),
            ),
            _ => match lowest(0, self.points.len()) {
                Some(p) => (p.0, p.1, 0.0),
                None => return,
            },
        };
        let below = self
            .points
            .iter()
            .map(|&(x, o)| o - (o0 + slope * (x - x0)))
            .fold(0.0, f64::min);
        self.line = Some((x0, o0 + below, slope));
    }
}

/// The host's clocks: CLOCK_MONOTONIC and CLOCK_REALTIME in ns.
pub mod host_clock {
    fn read(clock: libc::clockid_t) -> u64 {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: clock_gettime writes one timespec through a valid pointer.
        let rc = unsafe { libc::clock_gettime(clock, &mut ts) };
        if rc != 0 {
            return 0;
        }
        ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
    }

    /// CLOCK_MONOTONIC, ns.
    pub fn monotonic_ns() -> u64 {
        read(libc::CLOCK_MONOTONIC)
    }

    /// CLOCK_REALTIME, ns since the Unix epoch.
    pub fn realtime_ns() -> u64 {
        read(libc::CLOCK_REALTIME)
    }

    /// CLOCK_REALTIME minus CLOCK_MONOTONIC now, ns, read between two monotonic readings
    /// (their midpoint): adds to a monotonic time to give wall-clock time.
    pub fn realtime_minus_monotonic_ns() -> i128 {
        let a = monotonic_ns();
        let r = realtime_ns();
        let b = monotonic_ns();
        i128::from(r) - (i128::from(a) + i128::from(b)) / 2
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box clock: ticks since its reset at host time `reset_ns`, running `drift_ppm` fast.
    #[derive(Clone, Copy)]
    struct BoxClock {
        reset_ns: f64,
        drift_ppm: f64,
    }

    impl BoxClock {
        fn tick_at(&self, host_ns: f64) -> u64 {
            ((host_ns - self.reset_ns) * (1.0 + self.drift_ppm * 1e-6) / TICK_NS).floor() as u64
        }
        /// True host time of the start of box tick `tick`.
        fn host_of(&self, tick: u64) -> f64 {
            self.reset_ns + tick as f64 * TICK_NS / (1.0 + self.drift_ppm * 1e-6)
        }
    }

    /// An exchange with delays `up_ns` to the box, `turn_ns` in it, `down_ns` back.
    fn exchange(
        clock: BoxClock,
        at_ns: f64,
        up_ns: f64,
        turn_ns: f64,
        down_ns: f64,
    ) -> TimeExchange {
        TimeExchange {
            host_send_ns: at_ns as u64,
            box_receive_tick: clock.tick_at(at_ns + up_ns),
            box_send_tick: clock.tick_at(at_ns + up_ns + turn_ns),
            host_receive_ns: (at_ns + up_ns + turn_ns + down_ns) as u64,
        }
    }

    #[test]
    fn asymmetric_delays_and_drift_stay_within_the_bound() {
        let clock = BoxClock {
            reset_ns: 5e9,
            drift_ppm: 73.0,
        };
        let mut map = ClockMap::new();
        // xorshift for the delays: 20 to 500 us each way, independently.
        let mut x = 0x1234_5678_9ABC_DEF1u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64
        };
        for i in 0..200 {
            let at = 6e9 + f64::from(i) * 50e6;
            let (up, down) = (20e3 + next() * 480e3, 20e3 + next() * 480e3);
            map.push(1, exchange(clock, at, up, 3e3, down)).unwrap();
            for probe in [at - 1e9, at, at + 10e6] {
                let tick = clock.tick_at(probe);
                let mapped = map.to_host(tick).unwrap();
                let err = (mapped.host_ns - clock.host_of(tick)).abs();
                let bound = mapped.error_bound_ns.unwrap();
                assert!(
                    err <= bound + TICK_NS,
                    "exchange {i}: error {err} > bound {bound}"
                );
            }
        }
        let (drift, bound) = (map.drift_ppm().unwrap(), map.drift_bound_ppm().unwrap());
        // Host time per box time: 1 / (1 + 73e-6) - 1 = -73 ppm.
        assert!(
            (drift + 73.0).abs() <= bound,
            "drift {drift} +- {bound} ppm"
        );
    }

    #[test]
    fn a_new_boot_id_starts_over_instead_of_bending_the_line() {
        let before = BoxClock {
            reset_ns: 0.0,
            drift_ppm: 10.0,
        };
        let after = BoxClock {
            reset_ns: 30e9,
            drift_ppm: 10.0,
        };
        let mut map = ClockMap::new();
        for i in 0..20 {
            map.push(
                7,
                exchange(before, 10e9 + f64::from(i) * 1e8, 50e3, 1e3, 50e3),
            )
            .unwrap();
        }
        // After the reset the ticks are small again, under a new boot id.
        let e = exchange(after, 31e9, 50e3, 1e3, 50e3);
        map.push(8, e).unwrap();
        assert_eq!(map.restarts(), 1);
        let tick = after.tick_at(31e9);
        let mapped = map.to_host(tick).unwrap();
        assert!(
            (mapped.host_ns - after.host_of(tick)).abs() <= mapped.error_bound_ns.unwrap() + 8.0
        );
        assert!((mapped.host_ns - after.host_of(tick)).abs() < 60e3);
    }

    #[test]
    fn impossible_exchanges_are_refused() {
        let ok = TimeExchange {
            host_send_ns: 100,
            box_receive_tick: 10,
            box_send_tick: 11,
            host_receive_ns: 200,
        };
        assert!(ok.check().is_ok());
        let mut map = ClockMap::new();
        assert!(matches!(
            map.push(
                1,
                TimeExchange {
                    host_receive_ns: 50,
                    ..ok
                }
            ),
            Err(ExchangeError::HostTimeBackwards { .. })
        ));
        assert!(matches!(
            map.push(
                1,
                TimeExchange {
                    box_send_tick: 9,
                    ..ok
                }
            ),
            Err(ExchangeError::BoxTimeBackwards { .. })
        ));
        assert!(matches!(
            map.push(
                1,
                TimeExchange {
                    box_send_tick: 30,
                    ..ok
                }
            ),
            Err(ExchangeError::TurnaroundTooLong { .. })
        ));
        assert!(map.to_host(10).is_none());
    }

    #[test]
    fn receive_stamps_give_the_envelope_late_by_the_shortest_delay() {
        let clock = BoxClock {
            reset_ns: 1e9,
            drift_ppm: -40.0,
        };
        let mut map = ReceiveStampMap::new();
        let mut x = 99u64;
        for i in 0..5_000u64 {
            x = x
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let jitter = (x >> 40) as f64 / (1u64 << 24) as f64 * 300e3;
            let first_record = 2e9 + i as f64 * 1e6;
            // 30 us at least from the first record to the kernel, plus up to 300 us.
            map.push(
                clock.tick_at(first_record),
                (first_record + 30e3 + jitter) as u64,
            );
        }
        let tick = clock.tick_at(6e9);
        let late = map.to_host(tick).unwrap().host_ns - clock.host_of(tick);
        assert!((late - 30e3).abs() < 2e3, "late by {late} ns");
        assert_eq!(map.to_host(tick).unwrap().error_bound_ns, None);
        // 40 ppm slow box: host time per box time 40 ppm more.
        let drift = map.drift_ppm().unwrap();
        assert!((drift - 40.0).abs() < 3.0, "drift {drift} ppm");
        // A reset: box time starts again, and goes on from there.
        map.push(5, 8e9 as u64);
        map.push(125_005, 8_001_000_000);
        assert_eq!(map.restarts(), 1);
        let h = map.to_host(125_005).unwrap().host_ns;
        assert!((h - 8_001_000_000.0).abs() < 1e3, "{h}");
        assert_eq!(map.restarts(), 1);
    }
}
