//! Minimal signal models: the true physical value of each channel of each cell over time,
//! and the sensor noise added on top of it.
//!
//! Each scene switches on only the components it needs (docs/design.md section 7); `docs/scenes.md`
//! says per scene what is modelled and why that is enough. Everything is a function of the
//! scene seed, the cell's index and time, so cells are generated one after the other.
//!
//! The cells lie on the limb as a grid: `columns` cells around it, rows along it, `pitch`
//! apart. A region is a range of row fractions (0 = shoulder, 1 = end effector).

use crate::config::{ForceStandConfig, HammerConfig, MotionConfig, SceneConfig, StrokeConfig};
use crate::rng::Rng;
use core::f64::consts::{PI, TAU};
use skinbox_protocol::Channel;

const AX: usize = Channel::AccelX.index();
const F1: usize = Channel::Force1.index();
const PROX: usize = Channel::Proximity.index();
const T1: usize = Channel::Temperature1.index();

/// Where a cell sits on the limb.
#[derive(Debug, Clone, Copy)]
pub struct CellPlace {
    /// Position along the limb, m.
    pub x_m: f64,
    /// Position around the limb (unrolled), m.
    pub y_m: f64,
    /// Row fraction along the limb, 0..1.
    pub row_fraction: f64,
}

/// Scene-wide precomputed stimulus: stroke lanes and hammer blow times.
#[derive(Debug, Clone)]
pub struct SignalModel {
    config: SceneConfig,
    rows: usize,
    /// Per hand, the lateral lane (m) of each stroke pass.
    stroke_lanes_m: Vec<Vec<f64>>,
    /// Hammer blow times, s, ascending.
    blow_times_s: Vec<f64>,
}

/// A damped oscillation `a * exp(-(t - t0) / tau) * sin(w (t - t0) + phi)` evaluated at
/// increasing times. A cell samples at a fixed period, so the step from one call to the next
/// is nearly always the same: then one complex multiplication advances it instead of a sine
/// and an exponential.
#[derive(Debug, Clone, Copy)]
struct Phasor {
    re: f64,
    im: f64,
    last_s: f64,
    decay_per_s: f64,
    omega: f64,
    step_s: f64,
    step_re: f64,
    step_im: f64,
}

impl Phasor {
    fn new(amplitude: f64, frequency_hz: f64, phase: f64, decay_per_s: f64, start_s: f64) -> Self {
        let (s, c) = phase.sin_cos();
        Phasor {
            re: amplitude * c,
            im: amplitude * s,
            last_s: start_s,
            decay_per_s,
            omega: TAU * frequency_hz,
            // No step yet: time never runs backwards, so the first call computes one.
            step_s: -1.0,
            step_re: 0.0,
            step_im: 0.0,
        }
    }

    /// The value at `t_s` (not before the last call).
    fn at(&mut self, t_s: f64) -> f64 {
        let dt = t_s - self.last_s;
        if dt != 0.0 {
            if (dt - self.step_s).abs() > 1e-12 {
                let (s, c) = (self.omega * dt).sin_cos();
                let g = (-self.decay_per_s * dt).exp();
                self.step_s = dt;
                self.step_re = g * c;
                self.step_im = g * s;
            }
            let re = self.re * self.step_re - self.im * self.step_im;
            self.im = self.re * self.step_im + self.im * self.step_re;
            self.re = re;
            self.last_s = t_s;
        }
        self.im
    }
}

#[derive(Debug, Clone, Copy)]
struct Ringing {
    start_s: f64,
    axes: [Phasor; 3],
}

/// Per-cell state of the signal model: its place, static offsets and random stream.
#[derive(Debug, Clone)]
pub struct CellSignal {
    place: CellPlace,
    rng: Rng,
    rest: [f64; Channel::COUNT],
    motion_axis: [f64; 3],
    temperature_drift: Option<Phasor>,
    next_blow: usize,
    ringing: Vec<Ringing>,
}

impl CellSignal {
    /// The cell's place on the limb.
    pub fn place(&self) -> CellPlace {
        self.place
    }
}

fn in_region(region: [f64; 2], f: f64) -> bool {
    f >= region[0] && f <= region[1]
}

/// Smooth 0..1 step (raised cosine).
fn smooth_step(u: f64) -> f64 {
    let u = u.clamp(0.0, 1.0);
    0.5 - 0.5 * (PI * u).cos()
}

struct HandState {
    x_m: f64,
    y_m: f64,
    height_m: f64,
    /// Share of the peak pressure (0..1): it builds up and eases off over a stroke.
    pressure: f64,
}

impl SignalModel {
    /// Precomputes the scene-wide stimulus from the scene seed.
    pub fn new(config: &SceneConfig) -> SignalModel {
        let s = &config.scene;
        let rows = s.cells.div_ceil(s.columns.max(1)).max(1);
        let mut rng = Rng::for_stream(s.seed, u64::MAX);
        let mut stroke_lanes_m = Vec::new();
        if let Some(st) = &config.stroke {
            let width = s.columns as f64 * s.cell_pitch_m;
            let period = stroke_period_s(st, rows, s.cell_pitch_m);
            let passes = (s.duration_s / period).ceil() as usize + 2;
            for _ in 0..st.hands {
                stroke_lanes_m.push((0..passes).map(|_| rng.range(0.0, width)).collect());
            }
        }
        let mut blow_times_s = Vec::new();
        if let Some(h) = &config.hammer {
            if h.blows_per_s > 0.0 {
                let interval = 1.0 / h.blows_per_s;
                let mut t = rng.range(0.0, interval);
                while t < s.duration_s {
                    blow_times_s.push(t);
                    t += interval * rng.range(0.7, 1.3);
                }
            }
        }
        SignalModel {
            config: config.clone(),
            rows,
            stroke_lanes_m,
            blow_times_s,
        }
    }

    /// The per-cell state of the cell at `index` (0-based position in the scene).
    pub fn cell(&self, index: usize) -> CellSignal {
        let s = &self.config.scene;
        let columns = s.columns.max(1);
        let row = index / columns;
        let place = CellPlace {
            x_m: row as f64 * s.cell_pitch_m,
            y_m: (index % columns) as f64 * s.cell_pitch_m,
            row_fraction: (row as f64 + 0.5) / self.rows as f64,
        };
        let mut rng = Rng::for_stream(s.seed, index as u64);
        // Resting values seen from the real driver (docs/design.md section 2): accel z
        // 0.996..1.074 g, force 0..2 steps, proximity 0..450 counts, temperature 29..32 C;
        // the second temperature channel reads 0.
        let mut rest = [0.0; Channel::COUNT];
        rest[AX] = 0.04 * rng.normal();
        rest[AX + 1] = 0.04 * rng.normal();
        rest[AX + 2] = rng.range(0.996, 1.074);
        for k in 0..3 {
            rest[F1 + k] = rng.range(0.0, 2.0) / 1024.0;
        }
        rest[PROX] = rng.range(0.0, 450.0) / 65536.0;
        rest[T1] = rng.range(29.0, 32.0);
        let mut motion_axis = [rng.normal(), rng.normal(), rng.normal()];
        let norm = motion_axis
            .iter()
            .map(|a| a * a)
            .sum::<f64>()
            .sqrt()
            .max(1e-9);
        for a in &mut motion_axis {
            *a /= norm;
        }
        let temperature_phase = rng.range(0.0, TAU);
        let temperature_drift = self.config.temperature.as_ref().map(|t| {
            Phasor::new(
                t.drift_c,
                1.0 / t.drift_period_s,
                temperature_phase,
                0.0,
                0.0,
            )
        });
        CellSignal {
            place,
            temperature_drift,
            rng,
            rest,
            motion_axis,
            next_blow: 0,
            ringing: Vec::new(),
        }
    }

    /// True values of all channels at time `t_s` (host units), and the sensor noise to add
    /// for the sample taken then. Calls for one cell must come in increasing time.
    pub fn sample(
        &self,
        cell: &mut CellSignal,
        t_s: f64,
    ) -> ([f64; Channel::COUNT], [f64; Channel::COUNT]) {
        let c = &self.config;
        let mut v = cell.rest;
        let f = cell.place.row_fraction;

        // Temperature: slow drift.
        if let Some(drift) = &mut cell.temperature_drift {
            v[T1] += drift.at(t_s);
        }

        // Accelerations that are physical (part of the truth): smooth arm motion, its
        // vibration, hammer ringing, vibration of a stroked limb.
        let mut dynamic = [0.0; 3];
        if let Some(m) = &c.motion {
            if in_region(m.region, f) {
                self.motion(m, cell, t_s, &mut dynamic);
            }
        }
        if let Some(h) = &c.hammer {
            self.hammer(h, cell, t_s, &mut dynamic);
            if h.proximity > 0.0 || h.force > 0.0 {
                self.hammer_near_end(h, cell, t_s, &mut v);
            }
        }
        if let Some(st) = &c.stroke {
            // The hand is felt a little beyond the region it strokes.
            let length_m = self.rows as f64 * c.scene.cell_pitch_m;
            let reach_m = st.hand_radius_m + c.scene.cell_pitch_m + 8.0 * st.proximity_range_m;
            let x = cell.place.x_m;
            if x >= st.region[0] * length_m - reach_m && x <= st.region[1] * length_m + reach_m {
                let contact = self.stroke(st, cell, t_s, &mut v);
                // The stroked limb shakes while a hand rubs it.
                if contact && in_region(st.region, f) && st.vibration_g > 0.0 {
                    for d in &mut dynamic {
                        *d += st.vibration_g * cell.rng.normal();
                    }
                }
            }
        }
        if let Some(fs) = &c.force_stand {
            self.force_stand(fs, cell, t_s, &mut v);
        }
        for k in 0..3 {
            v[AX + k] += dynamic[k];
        }
        // Inertial cross-talk of the capacitive force and proximity sensors.
        if let Some(x) = &c.crosstalk {
            let a = (dynamic[0] * dynamic[0] + dynamic[1] * dynamic[1] + dynamic[2] * dynamic[2])
                .sqrt();
            for k in 0..3 {
                v[F1 + k] += x.force_per_g * a;
            }
            v[PROX] += x.proximity_per_g * a;
        }

        let n = &c.noise;
        let mut noise = [0.0; Channel::COUNT];
        for k in 0..3 {
            noise[AX + k] = n.accel_g * cell.rng.normal();
            noise[F1 + k] = n.force * cell.rng.normal();
        }
        noise[PROX] = n.proximity * cell.rng.normal();
        noise[T1] = n.temperature_c * cell.rng.normal();
        (v, noise)
    }

    fn motion(&self, m: &MotionConfig, cell: &mut CellSignal, t_s: f64, dynamic: &mut [f64; 3]) {
        let cycle = m.move_s + m.rest_s;
        let u = (t_s.rem_euclid(cycle)) / m.move_s;
        if u >= 1.0 {
            return;
        }
        // Point-to-point move: acceleration one sine period, speed a raised sine
        // (sin 2x = 2 sin x cos x: one call for both).
        let (sin_half, cos_half) = (PI * u).sin_cos();
        let accel = m.accel_g * 2.0 * sin_half * cos_half;
        let speed = sin_half;
        let reach = 0.3 + 0.7 * cell.place.row_fraction;
        for (d, axis) in dynamic.iter_mut().zip(cell.motion_axis) {
            *d += reach * (accel * axis + m.vibration_g * speed * cell.rng.normal());
        }
    }

    fn hammer(&self, h: &HammerConfig, cell: &mut CellSignal, t_s: f64, dynamic: &mut [f64; 3]) {
        while cell.next_blow < self.blow_times_s.len() && self.blow_times_s[cell.next_blow] <= t_s {
            let start_s = self.blow_times_s[cell.next_blow];
            cell.next_blow += 1;
            let distance_m = self.distance_to_end_m(cell);
            let gain = h.peak_g * (-distance_m * h.attenuation_per_m).exp();
            let r = &mut cell.rng;
            let ringing = Ringing {
                start_s,
                axes: [0, 1, 2].map(|_| {
                    let amplitude_g = gain * r.normal();
                    let frequency_hz = r.range(h.ring_hz[0], h.ring_hz[1]);
                    let phase = r.range(0.0, TAU);
                    Phasor::new(amplitude_g, frequency_hz, phase, 1.0 / h.decay_s, start_s)
                }),
            };
            cell.ringing.push(ringing);
        }
        let horizon = 8.0 * h.decay_s;
        cell.ringing.retain(|r| t_s - r.start_s < horizon);
        for r in &mut cell.ringing {
            for (k, axis) in r.axes.iter_mut().enumerate() {
                dynamic[k] += axis.at(t_s);
            }
        }
    }

    /// Near the end effector the hammer is felt directly: its head swings in to each blow and
    /// out again (a proximity pulse 0.1 s wide) and the impact presses on the force sensors
    /// (a force step decaying in 20 ms). Both fade over 5 cm of skin.
    fn hammer_near_end(
        &self,
        h: &HammerConfig,
        cell: &CellSignal,
        t_s: f64,
        v: &mut [f64; Channel::COUNT],
    ) {
        const SWING_S: f64 = 0.1;
        const IMPACT_S: f64 = 0.02;
        const RANGE_M: f64 = 0.05;
        let distance_m = self.distance_to_end_m(cell);
        if distance_m > 10.0 * RANGE_M {
            return;
        }
        let reach = (-distance_m / RANGE_M).exp();
        let mut swing = 0.0;
        let mut impact = 0.0;
        for i in [cell.next_blow.wrapping_sub(1), cell.next_blow] {
            if let Some(&blow_s) = self.blow_times_s.get(i) {
                let u = (t_s - blow_s) / SWING_S;
                swing += (-u * u).exp();
                if t_s >= blow_s {
                    impact += (-(t_s - blow_s) / IMPACT_S).exp();
                }
            }
        }
        v[PROX] += h.proximity * reach * swing;
        for k in 0..3 {
            v[F1 + k] += h.force * reach * impact;
        }
    }

    fn distance_to_end_m(&self, cell: &CellSignal) -> f64 {
        (1.0 - cell.place.row_fraction).max(0.0) * self.rows as f64 * self.config.scene.cell_pitch_m
    }

    fn hand(&self, st: &StrokeConfig, hand: usize, t_s: f64) -> HandState {
        let s = &self.config.scene;
        let x0 = st.region[0] * self.rows as f64 * s.cell_pitch_m;
        let x1 = st.region[1] * self.rows as f64 * s.cell_pitch_m;
        let length = (x1 - x0).max(s.cell_pitch_m);
        let period = stroke_period_s(st, self.rows, s.cell_pitch_m);
        let t = t_s + hand as f64 * period / st.hands as f64;
        let pass = (t / period).floor().max(0.0) as usize;
        let lanes = &self.stroke_lanes_m[hand];
        let y_m = lanes[pass.min(lanes.len() - 1)];
        let mut u = t.rem_euclid(period);
        let contact_s = length / st.speed_m_per_s;
        let return_s = length / (st.speed_m_per_s * st.return_speed_factor);
        if u < st.lower_s {
            return HandState {
                x_m: x0,
                y_m,
                height_m: st.lift_height_m * (1.0 - smooth_step(u / st.lower_s)),
                pressure: 0.0,
            };
        }
        u -= st.lower_s;
        if u < contact_s {
            return HandState {
                x_m: x0 + st.speed_m_per_s * u,
                y_m,
                height_m: 0.0,
                pressure: (0.2 + 0.8 * (PI * u / contact_s).sin())
                    * if st.pressure_hz > 0.0 {
                        0.75 + 0.25 * (TAU * st.pressure_hz * t).sin()
                    } else {
                        1.0
                    },
            };
        }
        u -= contact_s;
        if u < st.lower_s {
            return HandState {
                x_m: x1,
                y_m,
                height_m: st.lift_height_m * smooth_step(u / st.lower_s),
                pressure: 0.0,
            };
        }
        u -= st.lower_s;
        if u < return_s {
            return HandState {
                x_m: x1 - length * (u / return_s),
                y_m,
                height_m: st.lift_height_m,
                pressure: 0.0,
            };
        }
        // Away: far enough for no proximity.
        HandState {
            x_m: x0,
            y_m,
            height_m: 1.0,
            pressure: 0.0,
        }
    }

    /// Adds the hands' proximity and force to `v`; whether a hand touches the limb.
    fn stroke(
        &self,
        st: &StrokeConfig,
        cell: &CellSignal,
        t_s: f64,
        v: &mut [f64; Channel::COUNT],
    ) -> bool {
        let pitch = self.config.scene.cell_pitch_m;
        let circumference_m = self.config.scene.columns.max(1) as f64 * pitch;
        let mut contact = false;
        for hand in 0..st.hands {
            let h = self.hand(st, hand, t_s);
            contact |= h.height_m <= 0.0;
            let dx = cell.place.x_m - h.x_m;
            // Around the limb the distance wraps: the skin closes on itself.
            let dy = (cell.place.y_m - h.y_m + 0.5 * circumference_m).rem_euclid(circumference_m)
                - 0.5 * circumference_m;
            let lateral = (dx * dx + dy * dy).sqrt();
            let edge = (lateral - st.hand_radius_m).max(0.0);
            let distance = (edge * edge + h.height_m * h.height_m).sqrt();
            // Proximity rises as the hand comes near, before any force.
            v[PROX] += st.proximity * (-distance / st.proximity_range_m).exp();
            if h.height_m <= 0.0 && lateral < st.hand_radius_m + pitch {
                // The three force sensors sit 120 degrees apart, a quarter pitch from the
                // cell centre; each feels the pressure of the contact patch above it.
                for k in 0..3 {
                    let angle = PI / 2.0 + TAU * k as f64 / 3.0;
                    let sx = dx + 0.25 * pitch * angle.cos();
                    let sy = dy + 0.25 * pitch * angle.sin();
                    let d2 = (sx * sx + sy * sy) / (st.hand_radius_m * st.hand_radius_m);
                    if d2 < 1.0 {
                        v[F1 + k] += st.force * h.pressure * (1.0 - d2);
                    }
                }
            }
        }
        contact
    }

    fn force_stand(
        &self,
        fs: &ForceStandConfig,
        cell: &CellSignal,
        t_s: f64,
        v: &mut [f64; Channel::COUNT],
    ) {
        if !in_region(fs.region, cell.place.row_fraction) {
            return;
        }
        // The stand's probe presses with a force oscillating between 0 and the amplitude;
        // its tip stays on the cell, so proximity is saturated and steady.
        let newtons = 0.5 * fs.amplitude_n * (1.0 - (TAU * fs.frequency_hz * t_s).cos());
        for k in 0..3 {
            v[F1 + k] += newtons * fs.force_per_n / 3.0;
        }
        v[PROX] += fs.proximity;
    }
}

/// Duration of one stroke cycle: lower, stroke, lift, return.
fn stroke_period_s(st: &StrokeConfig, rows: usize, pitch_m: f64) -> f64 {
    let length = ((st.region[1] - st.region[0]) * rows as f64 * pitch_m).max(pitch_m);
    2.0 * st.lower_s
        + length / st.speed_m_per_s
        + length / (st.speed_m_per_s * st.return_speed_factor)
        + st.pause_s
}
