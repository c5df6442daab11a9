//! A cell's oscillator beyond its steady drift (docs/time.md, "The oscillator"): its random
//! wander (a random walk of its frequency and temperature steps) and a sinusoidal drift
//! wander for the failure studies.

use crate::rng::Rng;

/// A cell oscillator's random wander on top of its steady drift: a random walk of its
/// frequency and temperature steps (docs/time.md, "The oscillator").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OscillatorNoise {
    /// The random walk: standard deviation of the frequency's change over 1 s, ppm
    /// (growing with the square root of time).
    pub random_walk_ppm: f64,
    /// A temperature step: the frequency moves by this much, ppm, either way at random.
    pub step_ppm: f64,
    /// Time between temperature steps, s (0: none).
    pub step_interval_s: f64,
}

impl OscillatorNoise {
    /// A crystal cell oscillator on a robot's skin (docs/time.md): 0.05 ppm over 1 s of
    /// random walk, and a 1 ppm step (a few degrees C) every 2 s.
    pub fn realistic() -> OscillatorNoise {
        OscillatorNoise {
            random_walk_ppm: 0.05,
            step_ppm: 1.0,
            step_interval_s: 2.0,
        }
    }
}

/// The drawn wander of one oscillator: its frequency offset at knots [`NoiseTrack::KNOT_S`]
/// apart, linear in between (a step takes one knot), and the offset's integral.
#[derive(Debug, Clone)]
pub(crate) struct NoiseTrack {
    noise: OscillatorNoise,
    rng: Rng,
    /// The offset at each knot, ppm, and its integral from time 0 there, ppm s.
    offset_ppm: Vec<f64>,
    integral: Vec<f64>,
}

impl NoiseTrack {
    const KNOT_S: f64 = 0.01;

    pub(crate) fn new(noise: OscillatorNoise, rng: Rng) -> NoiseTrack {
        NoiseTrack {
            noise,
            rng,
            offset_ppm: vec![0.0],
            integral: vec![0.0],
        }
    }

    fn extend_to(&mut self, k: usize) {
        while self.offset_ppm.len() <= k + 1 {
            let i = self.offset_ppm.len();
            let mut next = self.offset_ppm[i - 1]
                + self.noise.random_walk_ppm * Self::KNOT_S.sqrt() * self.rng.normal();
            let every = self.noise.step_interval_s;
            if every > 0.0
                && ((i as f64 * Self::KNOT_S) / every).floor()
                    > (((i - 1) as f64 * Self::KNOT_S) / every).floor()
            {
                next += if self.rng.uniform() < 0.5 { -1.0 } else { 1.0 } * self.noise.step_ppm;
            }
            let area = (self.offset_ppm[i - 1] + next) * 0.5 * Self::KNOT_S;
            self.integral.push(self.integral[i - 1] + area);
            self.offset_ppm.push(next);
        }
    }

    /// The offset's integral from time 0 to `t_s`, ppm s.
    pub(crate) fn integral_ppm_s(&mut self, t_s: f64) -> f64 {
        let x = (t_s.max(0.0)) / Self::KNOT_S;
        let k = x.floor() as usize;
        self.extend_to(k);
        let f = x - k as f64;
        let (a, b) = (self.offset_ppm[k], self.offset_ppm[k + 1]);
        self.integral[k] + (a * f + (b - a) * f * f * 0.5) * Self::KNOT_S
    }

    /// The mean offset over `[a_s, b_s]`, ppm.
    pub(crate) fn mean_ppm(&mut self, a_s: f64, b_s: f64) -> f64 {
        if b_s - a_s < 1e-9 {
            let x = a_s.max(0.0) / Self::KNOT_S;
            self.extend_to(x as usize);
            return self.offset_ppm[x as usize];
        }
        (self.integral_ppm_s(b_s) - self.integral_ppm_s(a_s)) / (b_s - a_s)
    }
}

/// A sample clock whose drift wanders: `drift + amplitude * sin(2 pi t / period + angle)`,
/// each cell with its own angle (drawn from the scene seed).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClockWander {
    /// Amplitude of the wander, ppm.
    pub amplitude_ppm: f64,
    /// Period of the wander, s.
    pub period_s: f64,
}

impl ClockWander {
    /// The drift at time `t_s` of a cell whose steady drift is `drift_ppm`, ppm.
    pub fn drift_ppm(&self, drift_ppm: f64, angle: f64, t_s: f64) -> f64 {
        drift_ppm
            + self.amplitude_ppm
                * (std::f64::consts::TAU * t_s / self.period_s.max(1e-9) + angle).sin()
    }
}
