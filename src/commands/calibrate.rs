//! `skinbox calibrate`: the cell models' scenes against the papers' Fig. 8 table, and the
//! reconstruction error of every channel, with a verdict per figure and overall.

use serde::Serialize;
use skinbox_cells::calibration::{calibrate, Figure, TOLERANCE};
use std::path::PathBuf;

/// Arguments of `skinbox calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory of the scene files (default: the project's cosim/scenes); each seed scene
    /// must run as the table was measured (125 Hz, event mode, 260 cells).
    #[arg(long)]
    pub scenes: Option<PathBuf>,
}

/// One figure with its verdict.
#[derive(Serialize)]
struct Verdict<'a> {
    #[serde(flatten)]
    figure: &'a Figure,
    /// Model over the papers' value.
    ratio: Option<f64>,
    /// Within the tolerance (only figures with a papers' value have a verdict).
    pass: Option<bool>,
}

#[derive(Serialize)]
struct Output<'a> {
    /// Largest relative deviation from the table that passes.
    tolerance: f64,
    /// Figures with a papers' value.
    compared: usize,
    /// Of them, outside the tolerance.
    outside: usize,
    /// Every compared figure within the tolerance.
    pass: bool,
    figures: Vec<Verdict<'a>>,
}

/// Generates the six seed scenes (260 cells, 125 Hz, event mode), prints every figure with
/// its verdict, and fails when a figure is outside the tolerance.
pub fn run(args: Args, json: bool) -> anyhow::Result<()> {
    let dir = args.scenes.unwrap_or_else(skinbox_cells::scenes_dir);
    let figures = calibrate(&dir)?;
    let verdicts: Vec<Verdict> = figures
        .iter()
        .map(|f| Verdict {
            figure: f,
            ratio: f.ratio(),
            pass: f.pass(),
        })
        .collect();
    let compared = verdicts.iter().filter(|v| v.pass.is_some()).count();
    let outside = verdicts.iter().filter(|v| v.pass == Some(false)).count();
    let out = Output {
        tolerance: TOLERANCE,
        compared,
        outside,
        pass: outside == 0,
        figures: verdicts,
    };
    if json {
        super::print_json(&out)?;
    } else {
        println!(
            "{:24} {:36} {:>9} {:>9} {:>6}",
            "scene", "quantity", "seed", "model", "ratio"
        );
        for v in &out.figures {
            let f = v.figure;
            match (v.ratio, v.pass) {
                (Some(ratio), Some(pass)) => println!(
                    "{:24} {:36} {:9.3} {:9.3} {:6.3}  {}",
                    f.scene,
                    f.quantity,
                    f.seed.unwrap_or_default(),
                    f.model,
                    ratio,
                    if pass { "pass" } else { "FAIL" }
                ),
                _ => println!(
                    "{:24} {:36} {:>9} {:9.3}",
                    f.scene, f.quantity, "-", f.model
                ),
            }
        }
        println!(
            "{} of {compared} figures within {:.0} % of Fig. 8{}",
            compared - outside,
            100.0 * TOLERANCE,
            if outside == 0 { ": pass" } else { "" }
        );
    }
    anyhow::ensure!(
        outside == 0,
        "{outside} of {compared} figures outside {:.0} % of Fig. 8",
        100.0 * TOLERANCE
    );
    Ok(())
}
