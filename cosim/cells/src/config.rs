//! The scene file's schema: one struct per TOML table, with the defaults of the optional
//! tables and keys. [`crate::scene`] reads, checks and generates scenes from it.

use crate::bus::MAX_CELLS_PER_BUS;
use crate::cell::Mode;
use serde::Deserialize;
use skinbox_protocol::Channel;

/// `[scene]`: what runs, for how long, on how many cells.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneTable {
    /// Scene name (defaults to the file stem).
    #[serde(default)]
    pub name: String,
    /// Simulated duration, s.
    pub duration_s: f64,
    /// Start of the measurement window, s (the first samples send every channel).
    #[serde(default = "default_warmup_s")]
    pub warmup_s: f64,
    /// Seed of every random choice of the scene.
    pub seed: u64,
    /// Number of cells (ids 1..=cells).
    pub cells: usize,
    /// Number of buses; cells are dealt to them in contiguous runs.
    pub buses: usize,
    /// Data or event mode.
    pub mode: Mode,
    /// Nominal sample rate of every cell, Hz.
    pub sample_rate_hz: f64,
    /// Cells around the limb.
    #[serde(default = "default_columns")]
    pub columns: usize,
    /// Distance between cell centres, m.
    #[serde(default = "default_pitch_m")]
    pub cell_pitch_m: f64,
}

fn default_warmup_s() -> f64 {
    1.0
}
fn default_columns() -> usize {
    10
}
fn default_pitch_m() -> f64 {
    0.025
}

/// `[bus]`: relaying and UART.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BusConfig {
    /// From a sample to its packet ready in the cell, ns.
    pub processing_ns: u64,
    /// Store-and-forward delay per relaying cell, ns (one 50 us packet plus handling).
    pub hop_latency_ns: u64,
    /// Packets the root cell's FIFO holds, including the one on the wire.
    pub fifo_packets: usize,
    /// Largest UART clock error of a cell, ppm (each cell draws one in +-this).
    pub uart_error_ppm: f64,
    /// Largest sample clock drift of a cell, ppm (each cell draws one in +-this).
    pub clock_drift_ppm: f64,
    /// Most cells on one bus: the papers' 66 ([`MAX_CELLS_PER_BUS`]); studies of longer
    /// chains raise it.
    pub max_cells: usize,
}

impl Default for BusConfig {
    fn default() -> Self {
        BusConfig {
            processing_ns: 20_000,
            hop_latency_ns: 52_000,
            fifo_packets: 32,
            uart_error_ppm: 10_000.0,
            clock_drift_ppm: 100.0,
            max_cells: MAX_CELLS_PER_BUS,
        }
    }
}

/// `[thresholds]`: send-on-delta thresholds in host units and the enable mask.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ThresholdConfig {
    /// Acceleration threshold, g.
    pub accel_g: f64,
    /// Force threshold, normalised.
    pub force: f64,
    /// Proximity threshold, normalised.
    pub proximity: f64,
    /// Temperature threshold, C.
    pub temperature_c: f64,
    /// Channels enabled for events, by name (`accel_x` .. `temperature_2`).
    pub enabled: Vec<String>,
    /// Period of a full refresh in event mode, s: one data packet with every channel
    /// (see [`crate::cell::CellConfig::refresh_every_samples`]); 0 for none, as in the papers.
    pub refresh_s: f64,
}

impl ThresholdConfig {
    /// The same thresholds times `factor` (the enable mask and refresh unchanged); they are
    /// rounded down to whole raw steps when used, as Table I's are.
    pub fn scaled(&self, factor: f64) -> ThresholdConfig {
        ThresholdConfig {
            accel_g: self.accel_g * factor,
            force: self.force * factor,
            proximity: self.proximity * factor,
            temperature_c: self.temperature_c * factor,
            ..self.clone()
        }
    }
}

impl Default for ThresholdConfig {
    fn default() -> Self {
        ThresholdConfig {
            accel_g: 0.02,
            force: 0.001,
            proximity: 0.0001,
            temperature_c: 0.5,
            enabled: Channel::ALL.iter().map(|c| c.name().to_string()).collect(),
            refresh_s: 0.0,
        }
    }
}

/// `[noise]`: sensor noise (standard deviation) per modality, host units.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NoiseConfig {
    /// Accelerometer noise, g.
    pub accel_g: f64,
    /// Force noise, normalised.
    pub force: f64,
    /// Proximity noise, normalised.
    pub proximity: f64,
    /// Temperature noise, C.
    pub temperature_c: f64,
}

impl NoiseConfig {
    /// Every noise level times `factor`.
    pub fn scaled(&self, factor: f64) -> NoiseConfig {
        NoiseConfig {
            accel_g: self.accel_g * factor,
            force: self.force * factor,
            proximity: self.proximity * factor,
            temperature_c: self.temperature_c * factor,
        }
    }
}

/// `[temperature]`: slow drift of the first temperature sensor.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TemperatureConfig {
    /// Drift amplitude, C.
    pub drift_c: f64,
    /// Drift period, s.
    pub drift_period_s: f64,
}

/// `[motion]`: the arm moves point to point with smooth accelerations.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionConfig {
    /// Row fractions of the moving links.
    pub region: [f64; 2],
    /// Peak acceleration at the end effector, g.
    pub accel_g: f64,
    /// Duration of one move, s.
    pub move_s: f64,
    /// Rest between moves, s.
    pub rest_s: f64,
    /// Structural vibration while moving, g (standard deviation at full speed).
    pub vibration_g: f64,
}

/// `[hammer]`: blows on the end effector, each a spike with decaying ringing.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HammerConfig {
    /// Mean blows per second.
    pub blows_per_s: f64,
    /// Ringing amplitude at the end effector, g.
    pub peak_g: f64,
    /// Range of ringing frequencies, Hz.
    pub ring_hz: [f64; 2],
    /// Decay time constant of the ringing, s.
    pub decay_s: f64,
    /// Amplitude decay along the limb away from the end effector, 1/m.
    pub attenuation_per_m: f64,
    /// Proximity the hammer head and hand cause at the end effector as they swing in,
    /// normalised (0 for none).
    #[serde(default)]
    pub proximity: f64,
    /// Impact force each blow puts on the force sensors at the end effector, normalised
    /// (0 for none); it fades within 20 ms and over 5 cm of skin.
    #[serde(default)]
    pub force: f64,
}

/// `[stroke]`: hands stroking a region: a contact patch moving along the limb.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StrokeConfig {
    /// Row fractions stroked.
    pub region: [f64; 2],
    /// Hands stroking at once (evenly out of phase).
    pub hands: usize,
    /// Stroke speed, m/s (1-10 cm/s).
    pub speed_m_per_s: f64,
    /// Return speed in the air, as a multiple of the stroke speed.
    pub return_speed_factor: f64,
    /// Time to lower the hand onto the skin (and to lift it), s.
    pub lower_s: f64,
    /// Height of the hand in the air, m.
    pub lift_height_m: f64,
    /// Radius of the contact patch, m.
    pub hand_radius_m: f64,
    /// Peak pressure on a force sensor under the patch, normalised.
    pub force: f64,
    /// Proximity under the hand, normalised.
    pub proximity: f64,
    /// Decay length of proximity with distance, m.
    pub proximity_range_m: f64,
    /// Vibration of the stroked region while a hand touches it, g (standard deviation).
    pub vibration_g: f64,
    /// Time the hand stays away (no proximity) after each stroke, s.
    #[serde(default)]
    pub pause_s: f64,
    /// Frequency at which the pressure swings between half and full while in contact (a hand
    /// following an arm that yields), Hz; 0 for none.
    #[serde(default)]
    pub pressure_hz: f64,
}

/// `[crosstalk]`: inertial response of the capacitive sensors to acceleration.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CrosstalkConfig {
    /// Force reading per g of dynamic acceleration.
    pub force_per_g: f64,
    /// Proximity reading per g of dynamic acceleration.
    pub proximity_per_g: f64,
}

/// `[force_stand]`: a test stand presses a probe with a sinusoidal force.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceStandConfig {
    /// Row fractions under the probe.
    pub region: [f64; 2],
    /// Peak force, N (0 to peak).
    pub amplitude_n: f64,
    /// Frequency, Hz.
    pub frequency_hz: f64,
    /// Normalised force per newton (the cell's sensitivity).
    pub force_per_n: f64,
    /// Proximity with the probe on the cell, normalised.
    pub proximity: f64,
}

/// `[[commands]]`: a cell command the box sends down a bus at a time. Exactly one of
/// `mode`, `rate_hz`, `thresholds`, `enabled`, `time_sync` and `raw`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CommandConfig {
    /// When the box sends it, s from the scene start.
    pub time_s: f64,
    /// Box port (bus) it is sent on; omitted: every bus.
    pub port: Option<usize>,
    /// Cell id it addresses; omitted: every cell.
    pub cell: Option<u16>,
    /// `"data"` or `"event"`.
    pub mode: Option<Mode>,
    /// Sample rate: 62.5, 125, 250, 500 or 1000 Hz.
    pub rate_hz: Option<f64>,
    /// Send-on-delta thresholds in host units, as `[thresholds]` (keys left out: Table I).
    pub thresholds: Option<CommandThresholds>,
    /// Channels enabled for events, by name.
    pub enabled: Option<Vec<String>>,
    /// `true`: a time-sync command carrying the box tick at which it leaves the box.
    pub time_sync: Option<bool>,
    /// The 20 packet bytes as 40 hex digits, sent as they are (to test the cells with
    /// malformed or unknown commands).
    pub raw: Option<String>,
}

/// The thresholds of a `[[commands]]` entry, host units; Table I for keys left out.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CommandThresholds {
    /// Acceleration, g.
    pub accel_g: f64,
    /// Force, normalised.
    pub force: f64,
    /// Proximity, normalised.
    pub proximity: f64,
    /// Temperature, C.
    pub temperature_c: f64,
}

impl Default for CommandThresholds {
    fn default() -> Self {
        CommandThresholds {
            accel_g: 0.02,
            force: 0.001,
            proximity: 0.0001,
            temperature_c: 0.5,
        }
    }
}

/// A whole scene file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneConfig {
    /// `[scene]`.
    pub scene: SceneTable,
    /// `[bus]`.
    #[serde(default)]
    pub bus: BusConfig,
    /// `[thresholds]`.
    #[serde(default)]
    pub thresholds: ThresholdConfig,
    /// `[noise]`.
    pub noise: NoiseConfig,
    /// `[temperature]`.
    pub temperature: Option<TemperatureConfig>,
    /// `[motion]`.
    pub motion: Option<MotionConfig>,
    /// `[hammer]`.
    pub hammer: Option<HammerConfig>,
    /// `[stroke]`.
    pub stroke: Option<StrokeConfig>,
    /// `[crosstalk]`.
    pub crosstalk: Option<CrosstalkConfig>,
    /// `[force_stand]`.
    pub force_stand: Option<ForceStandConfig>,
    /// `[[commands]]`, in any order.
    #[serde(default)]
    pub commands: Vec<CommandConfig>,
    /// `[time_sync]`: the box sends a time-sync command down every bus periodically and the
    /// cells sample on its time grid.
    pub time_sync: Option<TimeSyncConfig>,
    /// `[oscillator]`: the cells' oscillators wander at random around their drift.
    pub oscillator: Option<OscillatorConfig>,
}

/// `[oscillator]`: each cell's oscillator wanders at random
/// ([`crate::oscillator::OscillatorNoise`]); a key left out takes the realistic default
/// ([`crate::oscillator::OscillatorNoise::realistic`]).
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OscillatorConfig {
    /// Random walk of the frequency: its standard deviation over 1 s, ppm.
    pub random_walk_ppm: Option<f64>,
    /// Temperature steps of the frequency, ppm, either way.
    pub step_ppm: Option<f64>,
    /// Time between temperature steps, s (0: none).
    pub step_interval_s: Option<f64>,
}

impl OscillatorConfig {
    /// The wander this table asks for.
    pub fn noise(&self) -> crate::oscillator::OscillatorNoise {
        let d = crate::oscillator::OscillatorNoise::realistic();
        crate::oscillator::OscillatorNoise {
            random_walk_ppm: self.random_walk_ppm.unwrap_or(d.random_walk_ppm),
            step_ppm: self.step_ppm.unwrap_or(d.step_ppm),
            step_interval_s: self.step_interval_s.unwrap_or(d.step_interval_s),
        }
    }
}

/// `[time_sync]`: a time-sync command to every cell of every bus every `interval_s`, the
/// first at `start_s` (docs/time.md, method c).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeSyncConfig {
    /// Time between sync commands, s.
    pub interval_s: f64,
    /// The first one, s from the scene start.
    #[serde(default)]
    pub start_s: f64,
    /// The cells discipline their rate as well as their phase (the rate servo, the
    /// default); `false`: phase only.
    #[serde(default = "rate_servo_default")]
    pub rate: bool,
}

/// The cells' firmware runs the rate servo (docs/time.md) unless a scene says not.
fn rate_servo_default() -> bool {
    true
}
