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
    /// Also run each seed scene through the box's reference model and the host decoder,
    /// and give the host's rate figures beside the cells', with verdicts.
    #[arg(long)]
    pub through_box: bool,
    /// Seconds of each scene the box listens to after its warm-up (default: the scene's
    /// whole window, as the cells' figures count it).
    #[arg(long)]
    pub box_window_s: Option<f64>,
}

/// What the host decoded of one seed scene run through the box.
struct HostFigures {
    /// Events per cell per second by modality name, over the scene's cells.
    events_per_cell_s: std::collections::BTreeMap<&'static str, f64>,
    /// Event packets in % of data mode, over the scene's cells.
    packet_rate_pct: f64,
}

/// Runs the seed scene `name` from `dir` through the reference model of the box (the
/// loop closed: the cells hear its syncs, as in `skinbox sim`) and the host decoder (told
/// the scene's cells and sample rate).
fn through_box(
    dir: &std::path::Path,
    name: &str,
    window_s: Option<f64>,
) -> anyhow::Result<HostFigures> {
    use skinbox_cosim::closed_loop::{run_closed_loop, ClosedLoopSpec};
    use skinbox_cosim::sim::Fidelity;
    let scene = skinbox_cells::scene::Scene::load(&dir.join(format!("{name}.toml")))?;
    let s = &scene.config.scene;
    let window_s = window_s.unwrap_or(s.duration_s - s.warmup_s);
    anyhow::ensure!(
        window_s > 0.0 && window_s <= 3600.0,
        "--box-window-s {window_s} must be above 0 and at most 3600"
    );
    let config = skinbox_gateware::interface_box::BoxConfig {
        ports: s.buses,
        ..Default::default()
    };
    let spec = ClosedLoopSpec::new(
        &scene,
        config,
        (s.warmup_s * 1e9) as u64,
        (window_s * 1e9) as u64,
    );
    let run = run_closed_loop(&spec, Fidelity::Reference, &mut |_, _| {})?.run;
    let mut decoder = skinbox_host::Decoder::new(skinbox_host::DecoderConfig {
        sample_rate_hz: Some(s.sample_rate_hz),
        cells: Some(s.cells as u64),
        ..Default::default()
    });
    for d in &run.datagrams {
        decoder.push_datagram(&d.to_bytes(), &mut ());
    }
    let report = decoder.report();
    Ok(HostFigures {
        events_per_cell_s: report
            .events_per_cell_per_second
            .iter()
            .map(|(m, r)| (m.name(), *r))
            .collect(),
        packet_rate_pct: report.event_packet_rate_percent_of_data_mode,
    })
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
    /// With `--through-box`: the host's value of the same figure, decoded from the box's
    /// datagrams.
    #[serde(skip_serializing_if = "Option::is_none")]
    host: Option<f64>,
    /// The host's value over the papers' value.
    #[serde(skip_serializing_if = "Option::is_none")]
    host_ratio: Option<f64>,
    /// The host's value within the tolerance.
    #[serde(skip_serializing_if = "Option::is_none")]
    host_pass: Option<bool>,
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
    let mut host = std::collections::BTreeMap::new();
    if args.through_box {
        for row in &skinbox_cells::calibration::SEED_TABLE {
            host.insert(row.scene, through_box(&dir, row.scene, args.box_window_s)?);
        }
    }
    let verdicts: Vec<Verdict> = figures
        .iter()
        .map(|f| {
            let h = host.get(f.scene.as_str()).and_then(|h| {
                if f.quantity == "packet_rate_pct" {
                    Some(h.packet_rate_pct)
                } else {
                    let m = f.quantity.strip_prefix("events_per_cell_s_")?;
                    h.events_per_cell_s.get(m).copied()
                }
            });
            // the host's value judged as the cells' is
            let host_figure = h.map(|model| Figure { model, ..f.clone() });
            Verdict {
                figure: f,
                ratio: f.ratio(),
                pass: f.pass(),
                host: h,
                host_ratio: host_figure.as_ref().and_then(Figure::ratio),
                host_pass: host_figure.as_ref().and_then(Figure::pass),
            }
        })
        .collect();
    let compared = verdicts.iter().filter(|v| v.pass.is_some()).count()
        + verdicts.iter().filter(|v| v.host_pass.is_some()).count();
    let outside = verdicts.iter().filter(|v| v.pass == Some(false)).count()
        + verdicts
            .iter()
            .filter(|v| v.host_pass == Some(false))
            .count();
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
        let verdict = |pass: bool| if pass { "pass" } else { "FAIL" };
        for v in &out.figures {
            let f = v.figure;
            let host = match (v.host, v.host_ratio, v.host_pass) {
                (Some(h), Some(r), Some(pass)) => {
                    format!("   host {h:9.3} {r:6.3}  {}", verdict(pass))
                }
                _ => String::new(),
            };
            match (v.ratio, v.pass) {
                (Some(ratio), Some(pass)) => println!(
                    "{:24} {:36} {:9.3} {:9.3} {:6.3}  {}{host}",
                    f.scene,
                    f.quantity,
                    f.seed.unwrap_or_default(),
                    f.model,
                    ratio,
                    verdict(pass)
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
