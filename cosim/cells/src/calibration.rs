//! Calibration of the scenes to the source papers: event rates per cell per second of each
//! modality and the packet rate in percent of data mode, at 125 Hz with 260 cells in event
//! mode (Bergner et al., 2nd paper, Fig. 8), and the reconstruction error per channel.

use crate::scene::{GenerateOptions, Scene, SceneError, SceneStats};
use skinbox_protocol::{Channel, Modality};

/// One scene's row of the seed table: events per cell per second (acceleration, force,
/// proximity, temperature) and packets in percent of data mode.
#[derive(Debug, Clone, Copy)]
pub struct SeedRow {
    /// Scene file stem.
    pub scene: &'static str,
    /// Events per cell per second, in [`Modality::ALL`] order.
    pub events_per_cell_s: [f64; 4],
    /// Event packets in percent of data mode.
    pub packet_rate_pct: f64,
}

/// The papers' Fig. 8 (2nd paper), as the issue on cell models gives it.
pub const SEED_TABLE: [SeedRow; 6] = [
    SeedRow {
        scene: "idle",
        events_per_cell_s: [1.23, 0.21, 4.17, 0.15],
        packet_rate_pct: 4.57,
    },
    SeedRow {
        scene: "stroking_upper_arm",
        events_per_cell_s: [9.33, 1.95, 17.9, 0.20],
        packet_rate_pct: 20.1,
    },
    SeedRow {
        scene: "stroking_arm",
        events_per_cell_s: [14.6, 3.09, 26.2, 0.20],
        packet_rate_pct: 29.9,
    },
    SeedRow {
        scene: "hammering_end_effector",
        events_per_cell_s: [137.0, 0.57, 5.69, 0.29],
        packet_rate_pct: 71.7,
    },
    SeedRow {
        scene: "moving_arm",
        events_per_cell_s: [174.0, 1.85, 4.65, 0.36],
        packet_rate_pct: 76.6,
    },
    SeedRow {
        scene: "reactive_control",
        events_per_cell_s: [86.0, 3.66, 8.60, 0.27],
        packet_rate_pct: 51.8,
    },
];

/// The papers' fit of the event packet rate against the sample rate (2nd paper, Fig. 11):
/// `a * ln(b * x + 1)` packets per second at `x` Hz, per cell, or for the whole skin of
/// `per_cells` cells (the moving arm's fit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RateFit {
    /// Scene file stem.
    pub scene: &'static str,
    /// Scale, packets per second.
    pub a: f64,
    /// Rate coefficient, per Hz.
    pub b: f64,
    /// Cells the fitted rate is for (1: per cell).
    pub per_cells: f64,
}

impl RateFit {
    /// Packets per cell per second the fit gives at `sample_rate_hz`.
    pub fn packets_per_cell_s(&self, sample_rate_hz: f64) -> f64 {
        self.a * (self.b * sample_rate_hz + 1.0).ln() / self.per_cells
    }
}

/// Fig. 11's fits, fitted by the papers from 62.5 to 500 Hz (docs/design.md section 2).
pub const FIG11_FITS: [RateFit; 5] = [
    RateFit {
        scene: "idle",
        a: 243.8846,
        b: 2.248e-4,
        per_cells: 1.0,
    },
    RateFit {
        scene: "stroking_upper_arm",
        a: 85.0385,
        b: 3.215e-3,
        per_cells: 1.0,
    },
    RateFit {
        scene: "stroking_arm",
        a: 74.2308,
        b: 6.154e-3,
        per_cells: 1.0,
    },
    RateFit {
        scene: "hammering_end_effector",
        a: 330.2692,
        b: 2.512e-3,
        per_cells: 1.0,
    },
    RateFit {
        scene: "moving_arm",
        a: 1.214e7,
        b: 1.687e-5,
        per_cells: 260.0,
    },
];

/// The sample rates Fig. 11 spans, Hz.
pub const FIG11_RATES_HZ: [f64; 4] = [62.5, 125.0, 250.0, 500.0];

/// Largest ratio between a scene's packet rate and its Fig. 11 fit (either way).
pub const FIG11_FACTOR: f64 = 1.2;

/// Largest allowed ratio between model and seed (either way) of the scenes' own tests.
pub const FACTOR: f64 = 1.25;

/// How far a calibrated figure may be from the table, relative: `skinbox calibrate`'s limit.
pub const TOLERANCE: f64 = 0.03;

/// The conditions of the seed table (Fig. 8): sample rate, cells and mode of every scene.
pub const TABLE_SAMPLE_RATE_HZ: f64 = 125.0;
/// Cells of the papers' Fig. 8 skin.
pub const TABLE_CELLS: usize = 260;

/// One figure: the seed's value and the model's.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Figure {
    /// Scene file stem.
    pub scene: String,
    /// `events_per_cell_s_<modality>`, `packet_rate_pct` or `rms_error_pct_<channel>`.
    pub quantity: String,
    /// The papers' value, if they give one.
    pub seed: Option<f64>,
    /// The model's value.
    pub model: f64,
}

impl Figure {
    /// Model over seed, if there is a seed value.
    pub fn ratio(&self) -> Option<f64> {
        self.seed.map(|s| self.model / s)
    }

    /// Within [`TOLERANCE`] of the seed; `None` without a seed value.
    pub fn pass(&self) -> Option<bool> {
        self.ratio().map(|r| (r - 1.0).abs() <= TOLERANCE)
    }
}

/// Why a scene cannot be compared with the table.
pub fn table_mismatch(scene: &Scene) -> Option<String> {
    let s = &scene.config.scene;
    let mut wrong = vec![];
    if s.sample_rate_hz != TABLE_SAMPLE_RATE_HZ {
        wrong.push(format!("{} Hz", s.sample_rate_hz));
    }
    if s.mode != crate::Mode::Event {
        wrong.push("data mode".to_string());
    }
    if s.cells != TABLE_CELLS {
        wrong.push(format!("{} cells", s.cells));
    }
    (!wrong.is_empty()).then(|| {
        format!(
            "scene {} runs at {}; Fig. 8's table is {TABLE_SAMPLE_RATE_HZ} Hz, event mode, {TABLE_CELLS} cells",
            scene.name(),
            wrong.join(", ")
        )
    })
}

/// The figures of one generated scene: the 5 rate figures against `row`, then the RMS
/// reconstruction error of every channel.
pub fn figures(row: &SeedRow, stats: &SceneStats) -> Vec<Figure> {
    let mut out = Vec::new();
    for (i, m) in Modality::ALL.into_iter().enumerate() {
        out.push(Figure {
            scene: row.scene.to_string(),
            quantity: format!("events_per_cell_s_{}", m.name()),
            seed: Some(row.events_per_cell_s[i]),
            model: stats.events_per_cell_s(m),
        });
    }
    out.push(Figure {
        scene: row.scene.to_string(),
        quantity: "packet_rate_pct".to_string(),
        seed: Some(row.packet_rate_pct),
        model: stats.packet_rate_pct(),
    });
    for c in Channel::ALL {
        out.push(Figure {
            scene: row.scene.to_string(),
            quantity: format!("rms_error_pct_{}", c.name()),
            seed: None,
            model: stats.rms_error_pct(c),
        });
    }
    out
}

/// Loads each seed scene from `dir`, generates it (counting only) and returns its figures.
pub fn calibrate(dir: &std::path::Path) -> Result<Vec<Figure>, SceneError> {
    let mut out = Vec::new();
    for row in &SEED_TABLE {
        let scene = Scene::load(&dir.join(format!("{}.toml", row.scene)))?;
        if let Some(why) = table_mismatch(&scene) {
            return Err(SceneError {
                file: dir
                    .join(format!("{}.toml", row.scene))
                    .display()
                    .to_string(),
                line: None,
                message: why,
            });
        }
        let generated = scene.generate(&GenerateOptions {
            keep_packets: false,
            truth_cells: Vec::new(),
            ..Default::default()
        });
        out.extend(figures(row, &generated.stats));
    }
    Ok(out)
}
