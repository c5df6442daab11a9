//! C4, failure boundaries, each found by a sweep:
//! - C4a UART baud mismatch, through the RTL co-simulation: good, rejected and
//!   corrupted-but-delivered packets (the boundary test: `cosim/tests/baud_mismatch.rs`);
//! - C4b cells per bus: loss against cell count;
//! - C4c sensor noise: packet rate against noise, up to the event storm above data mode;
//! - C4d event loss: reconstruction error against loss, with and without a periodic full
//!   refresh, and the refresh policy chosen from it.
//!
//! The tests of C4b-d are in `cosim/cells/tests/boundaries.rs`.

use super::{chart, mean_error_pct, scene, Points, Progress, Section, Table};
use skinbox_cells::{GenerateOptions, Mode, Scene};
use skinbox_cosim::line::Jitter;
use skinbox_cosim::sim::{run_rtl, SentPacket, SimSpec};
use skinbox_cosim::traffic::random_data_packets;
use skinbox_protocol::cell::PACKET_LEN;

fn baud_errors_pct(quick: bool) -> Vec<f64> {
    if quick {
        vec![-6.0, -4.0, 0.0, 4.0, 6.0]
    } else {
        let mut e: Vec<f64> = (-16..=16).map(|k| f64::from(k) * 0.5).collect();
        // the edge of the receiver's tolerance, +-4.75 %
        e.extend([-4.7, 4.7]);
        e.sort_by(f64::total_cmp);
        e
    }
}

fn cell_counts(quick: bool) -> Vec<usize> {
    if quick {
        vec![40, 66, 100, 160]
    } else {
        (2..=24).map(|k| k * 10).chain([66, 79, 81]).collect()
    }
}

fn noise_factors(quick: bool) -> Vec<f64> {
    if quick {
        vec![1.0, 2.0, 6.0, 16.0]
    } else {
        vec![
            0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 5.0, 6.0, 8.0, 12.0, 16.0, 32.0,
        ]
    }
}

fn losses(quick: bool) -> Vec<f64> {
    if quick {
        vec![0.001, 0.03, 0.1]
    } else {
        vec![0.0001, 0.0003, 0.001, 0.003, 0.01, 0.03, 0.1, 0.3]
    }
}

/// Full-refresh periods tried, s (0: none).
fn refreshes(quick: bool) -> Vec<f64> {
    if quick {
        vec![0.0, 1.0]
    } else {
        vec![0.0, 5.0, 1.0, 0.25]
    }
}

const LOSS_SCENES: [&str; 2] = ["idle", "stroking_upper_arm"];
const BUS_SERIES: [(&str, Mode, f64); 3] = [
    ("data mode, 250 Hz", Mode::Data, 250.0),
    ("data mode, 125 Hz", Mode::Data, 125.0),
    ("moving arm, event mode, 125 Hz", Mode::Event, 125.0),
];
const NOISE_SCENES: [&str; 2] = ["idle", "moving_arm"];
/// The papers' bound on the reconstruction error, % of full range.
pub const ERROR_BOUND_PCT: f64 = 0.5;

/// Steps [`study`] reports.
pub fn steps(quick: bool) -> u64 {
    (baud_errors_pct(quick).len()
        + cell_counts(quick).len() * BUS_SERIES.len()
        + noise_factors(quick).len() * NOISE_SCENES.len()
        + (losses(quick).len() + 1) * refreshes(quick).len() * LOSS_SCENES.len()) as u64
}

/// The four studies.
pub fn study(
    quick: bool,
    progress: &mut Progress,
    grid: &mut Points,
) -> anyhow::Result<Vec<Section>> {
    Ok(vec![
        baud(quick, progress, grid)?,
        bus(quick, progress, grid)?,
        noise(quick, progress, grid)?,
        loss(quick, progress, grid)?,
    ])
}

/// (good, rejected, corrupted) fractions of `packets` sent back to back on one port whose
/// UART runs `error_pct` fast, through the verilated box.
fn baud_point(error_pct: f64, packets: &[[u8; PACKET_LEN]]) -> anyhow::Result<[f64; 3]> {
    // The configuration of cosim/tests/baud_mismatch.rs: one verilated model serves both.
    let config = skinbox_cosim::line::baud_sweep_config();
    let bit_ns = 250.0 / (1.0 + error_pct / 100.0);
    let sent: Vec<SentPacket> = packets
        .iter()
        .enumerate()
        .map(|(i, p)| SentPacket {
            bytes: *p,
            start_ns: 10_000.0 + i as f64 * 200.0 * bit_ns,
            bit_ns,
        })
        .collect();
    let end_ns = 10_000.0 + packets.len() as f64 * 200.0 * bit_ns;
    anyhow::ensure!(
        (end_ns / 8.0) as u64 + 10_000 < skinbox_cosim::line::BAUD_SWEEP_STATUS_TICKS,
        "{packets} packets at {error_pct} % do not end before the sweep's status report",
        packets = packets.len()
    );
    let spec = SimSpec {
        duration_ns: skinbox_cosim::line::BAUD_SWEEP_CYCLES * 8,
        config,
        ports: vec![sent],
        pcap: None,
        vcd: None,
        jitter: Jitter::NONE,
        host_frames: vec![],
    };
    let r = run_rtl(&spec)?.report;
    let n = r.packets_sent.max(1) as f64;
    // a packet with the right bytes but a wrong time is as corrupt as one with wrong bytes
    Ok([
        (r.packets_delivered - r.records_mistimed) as f64 / n,
        r.dropped as f64 / n,
        (r.records_corrupted + r.records_mistimed) as f64 / n,
    ])
}

fn baud(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    let packets = random_data_packets(if quick { 40 } else { 150 });
    let mut table = Table::new(&[
        "baud error (%)",
        "good (%)",
        "rejected (%)",
        "corrupted or mistimed but delivered (%)",
    ]);
    let mut pts = [Vec::new(), Vec::new(), Vec::new()];
    for e in baud_errors_pct(quick) {
        progress.step(&format!("C4a: baud error {e:+} % through the RTL"));
        let f: [f64; 3] = grid.run(format!("C4a/{e:+}"), || baud_point(e, &packets))?;
        table.row(vec![
            format!("{e:+.1}"),
            format!("{:.1}", 100.0 * f[0]),
            format!("{:.1}", 100.0 * f[1]),
            format!("{:.1}", 100.0 * f[2]),
        ]);
        for k in 0..3 {
            pts[k].push((e, 100.0 * f[k]));
        }
    }
    // The widest band around 0 in which every packet arrived, and the first points outside.
    let good = &pts[0];
    let zero = good.iter().position(|p| p.0 == 0.0).expect("0 % is swept");
    let all_good = |p: &(f64, f64)| p.1 >= 100.0 - 1e-9;
    let mut lo = zero;
    while lo > 0 && all_good(&good[lo - 1]) {
        lo -= 1;
    }
    let mut hi = zero;
    while hi + 1 < good.len() && all_good(&good[hi + 1]) {
        hi += 1;
    }
    let corrupted_max = pts[2].iter().map(|p| p.1).fold(0.0f64, f64::max);
    let findings = vec![
        (
            "every packet delivered from .. to (baud error, %)".to_string(),
            format!("{:+.1} .. {:+.1}", good[lo].0, good[hi].0),
        ),
        (
            "first failing points (%)".to_string(),
            format!(
                "{} and {}",
                good.get(lo.wrapping_sub(1))
                    .map_or("none".into(), |p| format!("{:+.1}", p.0)),
                good.get(hi + 1)
                    .map_or("none".into(), |p| format!("{:+.1}", p.0))
            ),
        ),
        (
            "largest share corrupted or mistimed but delivered (%)".to_string(),
            format!("{corrupted_max:.1}"),
        ),
    ];
    let names = [
        "good",
        "rejected (counted by the box)",
        "corrupted or mistimed but delivered",
    ];
    let chart = chart::Chart {
        name: "c4a_baud_mismatch".into(),
        title: "C4a UART baud mismatch through the RTL: the receiver fails safe".into(),
        x_label: "cell UART clock error (%)".into(),
        y_label: "packets sent (%)".into(),
        x_log: false,
        y_log: false,
        x_range: (
            baud_errors_pct(quick)[0] - 0.5,
            *baud_errors_pct(quick).last().expect("swept") + 0.5,
        ),
        y_range: (-2.0, 170.0),
        series: pts
            .into_iter()
            .zip(names)
            .enumerate()
            .map(|(i, (points, label))| chart::Series {
                label: label.into(),
                points,
                style: chart::Style::Line,
                color: i,
            })
            .chain([-4.0, 4.0].map(|x| chart::Series {
                label: if x < 0.0 {
                    "+-4 % (requirement, docs/design.md section 4)".into()
                } else {
                    String::new()
                },
                points: vec![(x, -2.0), (x, 170.0)],
                style: chart::Style::Dashed,
                color: 6,
            }))
            .collect(),
        marks: Vec::new(),
        legend: chart::Legend::UpperRight,
    };
    Ok(Section {
        id: "C4a",
        title: "UART baud mismatch (RTL co-simulation)".into(),
        text: format!(
            "{} random full-range data packets back to back on one port of the verilated box, \
             the sending UART's clock off by the error on the x axis. Good: delivered \
             byte for byte; rejected: not delivered, counted by the box's status counters; \
             corrupted: delivered with bytes that were never sent, or mistimed: with the \
             sent bytes but a stamp more than one tick from the packet's true start edge \
             (from +4.6 % on the box once stamped back-to-back packets a byte time late; the \
             packet checks alone could not see it). Both sides of the boundary \
             are asserted by `cosim/tests/baud_mismatch.rs`.",
            packets.len()
        ),
        findings,
        tables: vec![table],
        charts: vec![chart],
    })
}

fn bus(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    let mut table = Table::new(&[
        "series",
        "cells on the bus",
        "offered (packets/s)",
        "dropped (%)",
        "closed form (%)",
    ]);
    let mut series = Vec::new();
    let mut findings = Vec::new();
    let base = scene("moving_arm")?;
    let duration_s = if quick { 1.5 } else { 3.0 };
    let mut counts = cell_counts(quick);
    counts.sort_unstable();
    counts.dedup();
    for (i, (name, mode, rate_hz)) in BUS_SERIES.iter().enumerate() {
        let mut points = Vec::new();
        let mut last_lossless = None;
        for &cells in &counts {
            progress.step(&format!("C4b: {name}, {cells} cells on one bus"));
            let mut sc = base.clone();
            let s = &mut sc.config.scene;
            s.cells = cells;
            s.buses = 1;
            s.mode = *mode;
            s.sample_rate_hz = *rate_hz;
            s.duration_s = duration_s;
            s.warmup_s = 1.0;
            sc.config.bus.max_cells = cells;
            sc.config.bus.uart_error_ppm = 0.0;
            sc.check()?;
            let (offered, dropped): (u64, u64) = grid.run(format!("C4b/{name}/{cells}"), || {
                let g = sc.generate(&GenerateOptions::default());
                let b = &g.buses[0].stats;
                Ok((b.offered, b.dropped))
            })?;
            let loss = 100.0 * dropped as f64 / offered.max(1) as f64;
            let offered_per_s = offered as f64 / duration_s;
            let closed =
                100.0 * (1.0 - super::rate_model::BUS_PACKETS_PER_S / offered_per_s).max(0.0);
            table.row(vec![
                name.to_string(),
                cells.to_string(),
                format!("{offered_per_s:.0}"),
                format!("{loss:.2}"),
                format!("{closed:.2}"),
            ]);
            if dropped == 0 {
                last_lossless = Some(cells);
            }
            points.push((cells as f64, loss));
        }
        findings.push((
            format!("{name}: most cells without loss (swept)"),
            last_lossless.map_or("none".into(), |c| c.to_string()),
        ));
        series.push(chart::Series {
            label: name.to_string(),
            points,
            style: chart::Style::Line,
            color: i,
        });
    }
    let x_max = *counts.last().expect("swept") as f64 + 10.0;
    Ok(Section {
        id: "C4b",
        title: "Cells per bus: loss against cell count".into(),
        text: format!(
            "One bus, cells added to it, root UART on an exact clock, {duration_s} s \
             (packets counted from the start, so event mode's start-up burst is in). Loss: \
             packets the root cell's 32-packet FIFO drops, in percent of those offered. The \
             closed form is 1 - 20,000 / offered. The seed: 66 cells and 16,000 packets/s a bus \
             (the papers)."
        ),
        findings,
        tables: vec![table],
        charts: vec![chart::Chart {
            name: "c4b_cells_per_bus".into(),
            title: "C4b Cells per bus: root FIFO loss against cell count".into(),
            x_label: "cells on one bus".into(),
            y_label: "packets dropped (% of offered)".into(),
            x_log: false,
            y_log: false,
            x_range: (0.0, x_max),
            y_range: (-1.0, 70.0),
            series,
            marks: vec![chart::Mark {
                at: (66.0, 0.0),
                text: "seed: 66 cells, 16,000 packets/s".into(),
            }],
            legend: chart::Legend::UpperLeft,
        }],
    })
}

fn noise(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    let (cells, duration_s) = if quick { (40, 3.0) } else { (260, 6.0) };
    let mut table = Table::new(&["scene", "noise (x calibrated)", "packets (% of data mode)"]);
    let mut series = Vec::new();
    let mut findings = Vec::new();
    let factors = noise_factors(quick);
    for (i, name) in NOISE_SCENES.iter().enumerate() {
        let base = scene(name)?;
        let mut points = Vec::new();
        for &f in &factors {
            progress.step(&format!("C4c: {name}, noise x{f}"));
            let mut sc = base.clone();
            sc.config.scene.cells = cells;
            sc.config.scene.duration_s = duration_s;
            sc.config.noise = sc.config.noise.scaled(f);
            sc.check()?;
            let rate: f64 = grid.run(format!("C4c/{name}/{f}"), || {
                let g = sc.generate(&GenerateOptions {
                    keep_packets: false,
                    ..Default::default()
                });
                Ok(g.stats.packet_rate_pct())
            })?;
            table.row(vec![name.to_string(), format!("{f}"), format!("{rate:.2}")]);
            points.push((f, rate));
        }
        findings.push((
            format!("{name}: noise where event packets pass data mode (x calibrated)"),
            crossing(&points, 100.0).map_or("not reached".into(), |x| format!("{x:.2}")),
        ));
        series.push(chart::Series {
            label: name.replace('_', " "),
            points,
            style: chart::Style::Line,
            color: i,
        });
    }
    let (x0, x1) = (factors[0], *factors.last().expect("swept"));
    series.push(chart::Series {
        label: "data mode (100 %)".into(),
        points: vec![(x0, 100.0), (x1, 100.0)],
        style: chart::Style::Dashed,
        color: 6,
    });
    Ok(Section {
        id: "C4c",
        title: "Sensor noise: where send-on-delta becomes an event storm".into(),
        text: format!(
            "Scenes at {cells} cells, {duration_s} s, every noise level (accelerometer, force, \
             proximity, temperature) times a factor of the calibrated levels (idle: 5.1 mg, \
             0.25 and 0.033 thousandths of full scale, 0.11 C), Table I thresholds. Above data \
             mode a sample fires seven or more channels and Algorithm 1 sends two packets."
        ),
        findings,
        tables: vec![table],
        charts: vec![chart::Chart {
            name: "c4c_sensor_noise".into(),
            title: "C4c Sensor noise: send-on-delta packet rate".into(),
            x_label: "sensor noise (times the calibrated level)".into(),
            y_label: "packets (% of data mode)".into(),
            x_log: true,
            y_log: false,
            x_range: (x0 * 0.9, x1 * 1.1),
            y_range: (0.0, 200.0),
            series,
            marks: Vec::new(),
            legend: chart::Legend::UpperLeft,
        }],
    })
}

/// Where a piecewise-linear curve first reaches `level` (x interpolated), if it does.
pub fn crossing(points: &[(f64, f64)], level: f64) -> Option<f64> {
    if points.first()?.1 >= level {
        return Some(points[0].0);
    }
    points.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        (y0 < level && y1 >= level).then(|| x0 + (x1 - x0) * (level - y0) / (y1 - y0))
    })
}

fn loss_run(base: &Scene, quick: bool, loss: f64, refresh_s: f64) -> anyhow::Result<(f64, f64)> {
    let mut sc = base.clone();
    sc.config.scene.duration_s = if quick { 6.0 } else { 11.0 };
    sc.config.thresholds.refresh_s = refresh_s;
    sc.check()?;
    let g = sc.generate(&GenerateOptions {
        keep_packets: false,
        packet_loss: loss,
        ..Default::default()
    });
    Ok((mean_error_pct(&g.stats), g.stats.packet_rate_pct()))
}

/// The event loss sweep: its table and chart series, filled scene by scene.
struct LossSweep<'a, 'p> {
    quick: bool,
    losses: &'a [f64],
    table: Table,
    series: Vec<chart::Series>,
    progress: &'a mut Progress<'p>,
    grid: &'a mut Points,
}

impl LossSweep<'_, '_> {
    /// Sweeps the losses on scene `s` at one refresh (the `r`th), raising `worst` at each
    /// loss; the extra packets the refresh costs the scene (None: no refresh).
    fn scene(
        &mut self,
        s: usize,
        name: &str,
        r: usize,
        refresh: f64,
        worst: &mut [f64],
    ) -> anyhow::Result<Option<f64>> {
        let quick = self.quick;
        let base = scene(name)?;
        self.progress
            .step(&format!("C4d: {name}, refresh {refresh} s, no loss"));
        let (lossless, rate) = self.grid.run(format!("C4d/{name}/{refresh}/0"), || {
            loss_run(&base, quick, 0.0, refresh)
        })?;
        let refresh_label = if refresh > 0.0 {
            format!("{refresh}")
        } else {
            "never".into()
        };
        self.table.row(vec![
            name.to_string(),
            refresh_label.clone(),
            "0".into(),
            format!("{lossless:.4}"),
            format!("{rate:.2}"),
        ]);
        let mut extra = None;
        if refresh > 0.0 {
            let (_, without) = self
                .grid
                .run(format!("C4d/{name}/{refresh}/0 without refresh"), || {
                    loss_run(&base, quick, 0.0, 0.0)
                })?;
            extra = Some(rate - without);
        }
        let mut points = Vec::new();
        for (k, &loss) in self.losses.iter().enumerate() {
            self.progress
                .step(&format!("C4d: {name}, refresh {refresh} s, loss {loss}"));
            let (error, rate) = self.grid.run(format!("C4d/{name}/{refresh}/{loss}"), || {
                loss_run(&base, quick, loss, refresh)
            })?;
            self.table.row(vec![
                name.to_string(),
                refresh_label.clone(),
                format!("{}", 100.0 * loss),
                format!("{error:.4}"),
                format!("{rate:.2}"),
            ]);
            worst[k] = worst[k].max(error);
            points.push((100.0 * loss, error));
        }
        self.series.push(chart::Series {
            label: format!(
                "{}{}, {}",
                name.replace('_', " "),
                if s == 0 { "" } else { " (dashed)" },
                if refresh > 0.0 {
                    format!("refresh every {refresh} s")
                } else {
                    "no refresh".into()
                }
            ),
            points,
            style: if s == 0 {
                chart::Style::Line
            } else {
                chart::Style::Dashed
            },
            color: r,
        });
        Ok(extra)
    }
}

/// Where each refresh's worst error passes the bound, and the refresh policy chosen.
fn loss_findings(losses: &[f64], per_refresh: &[(f64, Vec<f64>, f64)]) -> Vec<(String, String)> {
    // The policy: the cheapest refresh (fewest extra packets) that keeps the error inside
    // the papers' 0.5 % at every loss up to 10 %.
    let tolerable = |worst: &[f64]| {
        losses
            .iter()
            .zip(worst)
            .filter(|(l, _)| **l <= 0.1)
            .all(|(_, e)| *e < ERROR_BOUND_PCT)
    };
    let break_loss = |worst: &[f64]| {
        let pts: Vec<(f64, f64)> = losses
            .iter()
            .map(|l| 100.0 * l)
            .zip(worst.iter().copied())
            .collect();
        crossing(&pts, ERROR_BOUND_PCT)
            .map_or("beyond the sweep".into(), |x| format!("{x:.2} % loss"))
    };
    let mut findings = Vec::new();
    for (refresh, worst, extra) in per_refresh {
        findings.push((
            if *refresh > 0.0 {
                format!("refresh every {refresh} s: error passes 0.5 % at (worst scene)")
            } else {
                "no refresh: error passes 0.5 % at (worst scene)".into()
            },
            format!(
                "{}; costs {extra:.2} points of data mode",
                break_loss(worst)
            ),
        ));
    }
    let chosen = per_refresh
        .iter()
        .filter(|(r, w, _)| *r > 0.0 && tolerable(w))
        .min_by(|a, b| a.2.total_cmp(&b.2));
    findings.push((
        "refresh policy chosen (cheapest that holds 0.5 % up to 10 % loss)".into(),
        chosen.map_or("none of those tried".into(), |(r, _, extra)| {
            format!("a full refresh every {r} s ({extra:.2} points of data mode)")
        }),
    ));
    findings
}

fn loss(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    let losses = losses(quick);
    let mut sweep = LossSweep {
        quick,
        losses: &losses,
        table: Table::new(&[
            "scene",
            "full refresh every (s)",
            "packet loss (%)",
            "RMS error, mean of 8 channels (% FS)",
            "packets (% of data mode)",
        ]),
        series: Vec::new(),
        progress,
        grid,
    };
    // per refresh: (worst error over the scenes at each loss, extra packets)
    let mut per_refresh: Vec<(f64, Vec<f64>, f64)> = Vec::new();
    for (r, &refresh) in refreshes(quick).iter().enumerate() {
        let mut worst = vec![0.0f64; losses.len()];
        let mut extra = 0.0f64;
        for (s, name) in LOSS_SCENES.iter().enumerate() {
            if let Some(e) = sweep.scene(s, name, r, refresh, &mut worst)? {
                extra = extra.max(e);
            }
        }
        per_refresh.push((refresh, worst, extra));
    }
    let (table, mut series) = (sweep.table, sweep.series);
    let findings = loss_findings(&losses, &per_refresh);
    let (x0, x1) = (100.0 * losses[0], 100.0 * losses.last().expect("swept"));
    series.push(chart::Series {
        label: "0.5 % (the papers' error)".into(),
        points: vec![(x0, ERROR_BOUND_PCT), (x1, ERROR_BOUND_PCT)],
        style: chart::Style::Dashed,
        color: 7,
    });
    let y_max = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .fold(1.0f64, f64::max);
    Ok(Section {
        id: "C4d",
        title: "Event loss: reconstruction error with and without a periodic full refresh".into(),
        text: format!(
            "260 cells, {} s (1 s warm-up), Table I thresholds; every packet lost on its way \
             to the host with the probability on the x axis (independent, seeded). The host \
             holds the last value it received; a channel it never received reads 0 until the \
             channel fires. A refresh is one data packet with every channel. Solid: idle; \
             dashed: stroking upper arm.",
            if quick { 5 } else { 10 }
        ),
        findings,
        tables: vec![table],
        charts: vec![chart::Chart {
            name: "c4d_event_loss".into(),
            title: "C4d Event loss: reconstruction error, with and without refresh".into(),
            x_label: "packets lost on the way to the host (%)".into(),
            y_label: "RMS error, mean of 8 channels (% of full range)".into(),
            x_log: true,
            y_log: true,
            x_range: (x0 * 0.8, x1 * 1.25),
            y_range: (0.05, y_max * 6.0),
            series,
            marks: Vec::new(),
            legend: chart::Legend::UpperLeft,
        }],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crossing_interpolates_the_first_passage() {
        let pts = [(1.0, 10.0), (2.0, 90.0), (4.0, 110.0), (8.0, 50.0)];
        assert_eq!(crossing(&pts, 100.0), Some(3.0));
        assert_eq!(crossing(&pts, 5.0), Some(1.0));
        assert_eq!(crossing(&pts, 200.0), None);
    }
}
