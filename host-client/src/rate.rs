//! The cells' sample rate, learned from the record stamps when nobody gave it.
//!
//! Each cell samples periodically, so the packets that begin a sample (data packets, and
//! event packets that are not a split sample's second) arrive at multiples of its period,
//! plus the jitter of bus queueing (up to a few hundred microseconds at normal loads).
//! The estimate takes the cluster of the shortest per-cell intervals as a first period,
//! then fits the period to every interval that lies near a multiple of it (so gaps and
//! samples without events still count), and names the nearest standard rate when close.

use serde::Serialize;
use skinbox_protocol::TICKS_PER_SECOND;

/// The sample rate taken when none is given and the stamps cannot tell, Hz (the papers'
/// event rate tables, 2nd paper Fig. 8, sample at 125 Hz).
pub const ASSUMED_SAMPLE_RATE_HZ: f64 = 125.0;

/// The standard sample rates of the cells, Hz.
pub const STANDARD_RATES_HZ: [f64; 5] = [62.5, 125.0, 250.0, 500.0, 1000.0];

/// How close (relative) an estimate must be to a standard rate to take it.
pub const STANDARD_TOLERANCE: f64 = 0.05;

/// Intervals shorter than this are not periods (0.25 ms: a quarter of the 1 kHz period).
const MIN_INTERVAL_TICKS: u64 = TICKS_PER_SECOND / 4_000;

/// Intervals longer than this are not counted (20 s).
const MAX_INTERVAL_TICKS: u64 = 20 * TICKS_PER_SECOND;

/// What the stamps say about the sample rate.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SampleRateEstimate {
    /// The rate fitted to the intervals, Hz.
    pub estimated_hz: f64,
    /// The nearest standard rate within [`STANDARD_TOLERANCE`], if any.
    pub standard_hz: Option<f64>,
    /// How far the estimate is from the nearest standard rate, in % of that rate.
    pub off_nearest_standard_percent: f64,
    /// The rate to use: the standard rate when close, else the estimate.
    pub rate_hz: f64,
    /// Per-cell intervals that fitted a multiple of the period.
    pub intervals_fitted: u64,
    /// Per-cell intervals looked at.
    pub intervals: u64,
}

/// The sample rate from per-cell intervals between packets that began a sample, in box
/// ticks; `None` when no interval is usable. Only the usable intervals are collected.
pub fn learn_sample_rate(intervals: impl IntoIterator<Item = u64>) -> Option<SampleRateEstimate> {
    let mut d: Vec<u64> = intervals
        .into_iter()
        .filter(|d| (MIN_INTERVAL_TICKS..=MAX_INTERVAL_TICKS).contains(d))
        .collect();
    if d.is_empty() {
        return None;
    }
    d.sort_unstable();
    // The shortest intervals are one period (give or take jitter): the median of the
    // cluster around the 0.5 % quantile.
    let q = d[d.len() / 200] as f64;
    let cluster: Vec<u64> = d
        .iter()
        .copied()
        .filter(|&x| (x as f64) >= 0.75 * q && (x as f64) <= 1.5 * q)
        .collect();
    let first = cluster[cluster.len() / 2] as f64;
    // Fit the period to every interval near a multiple of it.
    let (mut sum_d, mut sum_k, mut fitted) = (0.0, 0.0, 0u64);
    for &x in &d {
        let k = (x as f64 / first).round();
        if k >= 1.0 && (x as f64 - k * first).abs() <= 0.25 * first {
            sum_d += x as f64;
            sum_k += k;
            fitted += 1;
        }
    }
    let period = if sum_k > 0.0 { sum_d / sum_k } else { first };
    let estimated_hz = TICKS_PER_SECOND as f64 / period;
    let nearest = STANDARD_RATES_HZ
        .iter()
        .copied()
        .min_by(|a, b| {
            (estimated_hz / a - 1.0)
                .abs()
                .total_cmp(&(estimated_hz / b - 1.0).abs())
        })
        .unwrap_or(ASSUMED_SAMPLE_RATE_HZ);
    let off = estimated_hz / nearest - 1.0;
    let standard_hz = (off.abs() <= STANDARD_TOLERANCE).then_some(nearest);
    Some(SampleRateEstimate {
        estimated_hz,
        standard_hz,
        off_nearest_standard_percent: 100.0 * off,
        rate_hz: standard_hz.unwrap_or(estimated_hz),
        intervals_fitted: fitted,
        intervals: d.len() as u64,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn multiples_and_jitter_give_the_period() {
        // 250 Hz: 500,000 ticks; intervals of 1, 2 and 5 periods, +-30,000 ticks jitter.
        let p = 500_000u64;
        let mut v = Vec::new();
        for i in 0..300u64 {
            let k = [1, 2, 5][(i % 3) as usize];
            let jitter = (i * 7_919 % 60_001) as i64 - 30_000;
            v.push((k * p) as i64 + jitter);
        }
        let e = learn_sample_rate(v.iter().map(|&x| x as u64)).unwrap();
        assert!((e.estimated_hz - 250.0).abs() < 2.0, "{e:?}");
        assert_eq!(e.standard_hz, Some(250.0));
        assert_eq!(e.rate_hz, 250.0);
        assert_eq!(e.intervals_fitted, 300);
    }

    #[test]
    fn a_rate_far_from_the_standards_is_kept() {
        // 180 Hz is 28 % above 125 and 28 % below 250.
        let p = TICKS_PER_SECOND / 180;
        let e = learn_sample_rate([p; 50]).unwrap();
        assert_eq!(e.standard_hz, None);
        assert!((e.rate_hz - 180.0).abs() < 0.01, "{e:?}");
    }

    #[test]
    fn nothing_usable_gives_none() {
        assert_eq!(learn_sample_rate([]), None);
        assert_eq!(learn_sample_rate([10, 20]), None);
    }
}
