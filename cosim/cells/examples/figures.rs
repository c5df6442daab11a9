//! Prints the calibration figures of the seed scenes (model against seed).

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let figures = skinbox_cells::calibration::calibrate(&skinbox_cells::scenes_dir())?;
    for f in figures {
        match f.seed {
            Some(seed) => println!(
                "{:24} {:36} seed {:8.2} model {:8.2} ratio {:5.2}",
                f.scene, f.quantity, seed, f.model, f.model / seed
            ),
            None if f.model > 0.05 => {
                println!("{:24} {:36} model {:8.3}", f.scene, f.quantity, f.model)
            }
            None => {}
        }
    }
    Ok(())
}
