//! C1, send-on-delta: per scene, packets in percent of data mode against the reconstruction
//! error, sweeping every threshold from 0.25 to 4 times the papers' Table I (rounded down to
//! whole raw steps, as the cells do), with data mode as the zero-threshold end.

use super::{chart, mean_error_pct, scene, Points, Progress, Section, Table};
use skinbox_cells::calibration::SEED_TABLE;
use skinbox_cells::{GenerateOptions, Mode};
use skinbox_protocol::{Channel, Modality};

fn scales(quick: bool) -> Vec<f64> {
    if quick {
        vec![0.25, 1.0, 4.0]
    } else {
        vec![0.25, 0.35, 0.5, 0.71, 1.0, 1.41, 2.0, 2.83, 4.0]
    }
}

/// Cells and simulated seconds (the first one is warm-up).
fn size(quick: bool) -> (usize, f64) {
    if quick {
        (260, 2.5)
    } else {
        (260, 11.0)
    }
}

/// Steps [`study`] reports.
pub fn steps(quick: bool) -> u64 {
    SEED_TABLE.len() as u64 * (scales(quick).len() as u64 + 1)
}

/// The chart of packet rate against error, one curve per scene, Table I marked.
fn rate_error_chart(
    series: Vec<chart::Series>,
    marks: Vec<chart::Mark>,
    y_max: f64,
) -> chart::Chart {
    let x_max = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.0))
        .fold(0.0f64, f64::max);
    chart::Chart {
        name: "c1_send_on_delta".into(),
        title: "C1 Send-on-delta: packet rate against reconstruction error".into(),
        x_label: "RMS reconstruction error, mean of 8 channels (% of full range)".into(),
        y_label: "packets (% of data mode)".into(),
        x_log: false,
        y_log: false,
        x_range: (0.0, x_max * 1.1),
        y_range: (0.0, y_max * 1.05),
        series,
        marks,
        legend: chart::Legend::UpperRight,
    }
}

/// Packets (% of data mode), the mean error, then the error per modality (% FS) of one run.
fn rate_and_errors(sc: &skinbox_cells::Scene) -> [f64; 6] {
    let g = sc.generate(&GenerateOptions {
        keep_packets: false,
        ..Default::default()
    });
    let st = &g.stats;
    let modality_error = |m: Modality| {
        let chans: Vec<_> = Channel::ALL[..8]
            .iter()
            .filter(|c| c.modality() == m)
            .collect();
        chans.iter().map(|&&c| st.rms_error_pct(c)).sum::<f64>() / chans.len() as f64
    };
    [
        st.packet_rate_pct(),
        mean_error_pct(st),
        modality_error(Modality::Acceleration),
        modality_error(Modality::Force),
        modality_error(Modality::Proximity),
        modality_error(Modality::Temperature),
    ]
}

/// The study.
pub fn study(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    let (cells, duration_s) = size(quick);
    let mut table = Table::new(&[
        "scene",
        "threshold scale",
        "raw thresholds (accel, force, prox, temp)",
        "packets (% of data mode)",
        "RMS error, mean of 8 channels (% FS)",
        "accel RMS (% FS)",
        "force RMS (% FS)",
        "prox RMS (% FS)",
        "temp RMS (% FS)",
    ]);
    let mut series = Vec::new();
    let mut marks = Vec::new();
    let mut findings = Vec::new();
    let mut y_max = 100.0f64;
    for (i, row) in SEED_TABLE.iter().enumerate() {
        let base = scene(row.scene)?;
        let mut points = Vec::new();
        // data mode first: the curve runs from it through rising thresholds
        let runs = std::iter::once(None).chain(scales(quick).into_iter().map(Some));
        for scale in runs {
            progress.step(&format!(
                "C1: {} at {}",
                row.scene,
                scale.map_or("data mode".to_string(), |s| format!("{s} x Table I"))
            ));
            let mut sc = base.clone();
            sc.config.scene.cells = cells;
            sc.config.scene.duration_s = duration_s;
            match scale {
                Some(s) => sc.config.thresholds = sc.config.thresholds.scaled(s),
                None => sc.config.scene.mode = Mode::Data,
            }
            sc.check()?;
            let key = format!(
                "C1/{}/{}",
                row.scene,
                scale.map_or("data mode".to_string(), |s| s.to_string())
            );
            // rate, mean error, then the error per modality
            let [rate, error, accel, force, prox, temp]: [f64; 6] =
                grid.run(key, || Ok(rate_and_errors(&sc)))?;
            let raw = sc.thresholds().raw;
            y_max = y_max.max(rate);
            table.row(vec![
                row.scene.to_string(),
                scale.map_or("data mode".into(), |s| format!("{s}")),
                scale.map_or("-".into(), |_| {
                    format!("{}, {}, {}, {}", raw[0], raw[3], raw[6], raw[7])
                }),
                format!("{rate:.2}"),
                format!("{error:.4}"),
                format!("{accel:.4}"),
                format!("{force:.4}"),
                format!("{prox:.4}"),
                format!("{temp:.4}"),
            ]);
            points.push((error, rate));
            if scale == Some(1.0) {
                marks.push(chart::Mark {
                    at: (error, rate),
                    text: if i == 0 {
                        "Table I (seed)".into()
                    } else {
                        String::new()
                    },
                });
                findings.push((
                    format!("{}: Table I operating point", row.scene),
                    format!("{rate:.1} % of data mode at {error:.3} % RMS error"),
                ));
            }
        }
        series.push(chart::Series {
            label: row.scene.replace('_', " "),
            points,
            style: chart::Style::Line,
            color: i,
        });
    }
    let chart = rate_error_chart(series, marks, y_max);
    Ok(Section {
        id: "C1",
        title: "Send-on-delta: packet rate against reconstruction error".into(),
        text: format!(
            "Each scene of the papers' Fig. 8 ({cells} cells, 125 Hz, {:.0} s after a 1 s \
             warm-up), thresholds {} times Table I (0.02 g, 0.001, 0.0001, 0.5 C; rounded down \
             to whole raw steps), and data mode (every sample, the curve's left end). Error: \
             the host holds the last value received (Algorithm 2), compared at every sample \
             with the true signal (no noise, not quantised), RMS in percent of each channel's \
             full range, averaged over the 8 channels that carry a signal. Triangles: Table I.",
            duration_s - 1.0,
            scales(quick)
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ),
        findings,
        tables: vec![table],
        charts: vec![chart],
    })
}
