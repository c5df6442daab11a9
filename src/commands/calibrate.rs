//! `skinbox calibrate`: the cell models' scenes against the papers' Fig. 8 table, and the
//! reconstruction error of every channel.

use skinbox_cells::calibration::{calibrate, FACTOR};
use std::path::PathBuf;

/// Arguments of `skinbox calibrate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Directory of the scene files (default: the project's cosim/scenes).
    #[arg(long)]
    pub scenes: Option<PathBuf>,
}

/// Generates the six seed scenes (260 cells, 125 Hz, event mode) and prints every figure.
pub fn run(args: Args, json: bool) -> anyhow::Result<()> {
    let dir = args.scenes.unwrap_or_else(skinbox_cells::scenes_dir);
    let figures = calibrate(&dir)?;
    if json {
        return super::print_json(&figures);
    }
    println!(
        "{:24} {:36} {:>9} {:>9} {:>6}",
        "scene", "quantity", "seed", "model", "ratio"
    );
    let mut outside = 0;
    for f in &figures {
        match f.ratio() {
            Some(ratio) => {
                let ok = (1.0 / FACTOR..=FACTOR).contains(&ratio);
                outside += usize::from(!ok);
                println!(
                    "{:24} {:36} {:9.3} {:9.3} {:6.3}{}",
                    f.scene,
                    f.quantity,
                    f.seed.unwrap_or_default(),
                    f.model,
                    ratio,
                    if ok { "" } else { "  outside" }
                );
            }
            None => println!(
                "{:24} {:36} {:>9} {:9.3}",
                f.scene, f.quantity, "-", f.model
            ),
        }
    }
    println!("{outside} of the seed figures outside a factor {FACTOR}");
    Ok(())
}
