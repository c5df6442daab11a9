//! C6, packet rate against sample rate: the five scenes of the papers' Fig. 11 at 62.5 to
//! 500 Hz in event mode, packets per cell per second beside the papers' fits
//! `a * ln(b * x + 1)`, and each scene's share of data mode (the worst case sizes a link).

use super::{chart, scene, Points, Progress, Section, Table};
use skinbox_cells::calibration::{RateFit, FIG11_FACTOR, FIG11_FITS, FIG11_RATES_HZ};
use skinbox_cells::GenerateOptions;

/// Cells and simulated seconds (the first one is warm-up).
fn size(quick: bool) -> (usize, f64) {
    if quick {
        (260, 3.0)
    } else {
        (260, 61.0)
    }
}

/// Steps [`study`] reports.
pub fn steps(_quick: bool) -> u64 {
    (FIG11_FITS.len() * FIG11_RATES_HZ.len()) as u64
}

/// Packets per cell per second and % of data mode of one scene at one rate.
fn point(fit: &RateFit, rate_hz: f64, quick: bool) -> anyhow::Result<[f64; 2]> {
    let (cells, duration_s) = size(quick);
    let mut sc = scene(fit.scene)?;
    sc.config.scene.cells = cells;
    sc.config.scene.duration_s = duration_s;
    sc.config.scene.sample_rate_hz = rate_hz;
    sc.check()?;
    let g = sc.generate(&GenerateOptions {
        keep_packets: false,
        ..Default::default()
    });
    let st = &g.stats;
    Ok([st.packets_per_cell_s(), st.packet_rate_pct()])
}

/// The study.
pub fn study(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    let (cells, duration_s) = size(quick);
    let mut table = Table::new(&[
        "scene",
        "sample rate (Hz)",
        "packets per cell per s",
        "Fig. 11 fit",
        "model / fit",
        "packets (% of data mode)",
    ]);
    let mut series = Vec::new();
    let mut worst_ratio = 1.0f64;
    let mut worst_share = (0.0f64, "", 0.0);
    let mut y_max = 0.0f64;
    for (i, fit) in FIG11_FITS.iter().enumerate() {
        let mut points = Vec::new();
        for rate in FIG11_RATES_HZ {
            progress.step(&format!("C6: {} at {rate} Hz", fit.scene));
            let [model, share] = grid.run(format!("C6/{}/{rate}", fit.scene), || {
                point(fit, rate, quick)
            })?;
            let expected = fit.packets_per_cell_s(rate);
            let ratio = model / expected;
            if ratio.ln().abs() > worst_ratio.ln().abs() {
                worst_ratio = ratio;
            }
            if share > worst_share.0 {
                worst_share = (share, fit.scene, rate);
            }
            y_max = y_max.max(model).max(expected);
            table.row(vec![
                fit.scene.to_string(),
                format!("{rate}"),
                format!("{model:.2}"),
                format!("{expected:.2}"),
                format!("{ratio:.3}"),
                format!("{share:.2}"),
            ]);
            points.push((rate, model));
        }
        let label = fit.scene.replace('_', " ");
        series.push(chart::Series {
            label: label.clone(),
            points,
            style: chart::Style::Points,
            color: i,
        });
        // the fit as a curve through 50 rates
        let (lo, hi) = (FIG11_RATES_HZ[0], FIG11_RATES_HZ[FIG11_RATES_HZ.len() - 1]);
        series.push(chart::Series {
            label: if i == 0 {
                "papers' fits a ln(bx + 1) (dashed)".into()
            } else {
                String::new()
            },
            points: (0..=50)
                .map(|k| {
                    let x = lo + (hi - lo) * f64::from(k) / 50.0;
                    (x, fit.packets_per_cell_s(x))
                })
                .collect(),
            style: chart::Style::Dashed,
            color: i,
        });
    }
    let chart = chart::Chart {
        name: "c6_sample_rate".into(),
        title: "C6 Packet rate against sample rate, beside the papers' Fig. 11".into(),
        x_label: "sample rate (Hz)".into(),
        y_label: "event packets per cell per second".into(),
        x_log: false,
        y_log: false,
        x_range: (0.0, FIG11_RATES_HZ[FIG11_RATES_HZ.len() - 1] * 1.05),
        y_range: (0.0, y_max * 1.1),
        series,
        marks: Vec::new(),
        legend: chart::Legend::UpperLeft,
    };
    let findings = vec![
        (
            "largest deviation from the fit (model / fit)".to_string(),
            format!("{worst_ratio:.3} (limit {FIG11_FACTOR} either way)"),
        ),
        (
            "worst-case share of data mode".to_string(),
            format!(
                "{:.1} % ({}, {} Hz)",
                worst_share.0, worst_share.1, worst_share.2
            ),
        ),
    ];
    Ok(Section {
        id: "C6",
        title: "Packet rate against sample rate (Fig. 11)".into(),
        text: format!(
            "The five scenes the papers fit in Fig. 11, {cells} cells in event mode at Table I \
             thresholds, {:.0} s after a 1 s warm-up at each sample rate, counted at the cells. \
             Dots: the cell models; dashed: the papers' fits `a * ln(b * x + 1)` (the moving \
             arm's fit is for all 260 cells together, shown per cell). Idle sits below its fit \
             at every rate: the papers' idle fit gives 6.76 packets per cell per second at \
             125 Hz where their Fig. 8 table gives 5.71, and the scenes follow the table. \
             `cosim/cells/tests/scenes.rs` asserts every point within a factor {FIG11_FACTOR}.",
            duration_s - 1.0
        ),
        findings,
        tables: vec![table],
        charts: vec![chart],
    })
}
