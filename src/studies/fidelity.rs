//! C2, simulation fidelity: wall time per simulated second against the error relative to
//! the RTL, for each level of docs/design.md section 6 that is here, across skin sizes from one
//! bus to 5,742 cells:
//! 1. RTL: the verilated box, every clock, UART pins driven bit by bit (the truth);
//! 2. the packet-level reference model (`skinbox_cosim::reference`), compared frame by
//!    frame with the RTL where both run, and alone up to the 64-port box;
//! 3. the closed-form [`rate_model`](super::rate_model).
//!
//! The skin is the stroking-upper-arm scene (event mode, 125 Hz) with 66 cells a bus. The
//! RTL runs where it is affordable (1 and 4 buses; 4 in the quick run); the rate model runs
//! at every size. Errors relative to the RTL: records delivered and datagrams sent in the
//! window, in percent of the RTL's count.

use super::rate_model::{predict, RateInputs};
use super::{chart, scene, Points, Progress, Section, Table};
use serde::{Deserialize, Serialize};
use skinbox_cells::calibration::SEED_TABLE;
use skinbox_cosim::reference::run_reference;
use skinbox_cosim::sim::{run_rtl, SimSpec};
use skinbox_gateware::interface_box::BoxConfig;
use std::time::Instant;

const SCENE: &str = "stroking_upper_arm";
const CELLS_PER_BUS: usize = 66;
/// Box flush timeout and status period of the RTL runs (those of `tests/sim.rs`, so the
/// verilated 4-port model is shared).
const FLUSH_TICKS: u64 = 12_500;
const STATUS_TICKS: u64 = 250_000;

fn rtl_buses(quick: bool) -> Vec<usize> {
    if quick {
        vec![4]
    } else {
        vec![1, 4]
    }
}

/// Skin sizes in buses of 66 cells (87 buses: 5,742 cells, the original box's limit).
fn sizes() -> Vec<usize> {
    vec![1, 4, 8, 16, 32, 64, 87]
}

fn window_s(quick: bool) -> f64 {
    if quick {
        0.01
    } else {
        0.05
    }
}

/// Skin sizes the reference model runs alone (the box has at most 64 ports).
fn reference_only_buses(quick: bool) -> Vec<usize> {
    if quick {
        vec![]
    } else {
        vec![8, 16, 32, 64]
    }
}

/// Steps [`study`] reports.
pub fn steps(quick: bool) -> u64 {
    (rtl_buses(quick).len() + reference_only_buses(quick).len() + 1) as u64
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct ReferencePoint {
    buses: usize,
    wall_per_sim_s: f64,
    records: u64,
    datagrams: u64,
    /// Frames that differ from the RTL's (None: no RTL run).
    frames_differing: Option<usize>,
    ts_max_ticks: f64,
}

/// The spec of the stroking skin with `buses` buses of 66 cells, and the cell models'
/// wall time per simulated second.
fn skin_spec(
    base: &skinbox_cells::scene::Scene,
    buses: usize,
    window: f64,
) -> anyhow::Result<(SimSpec, f64)> {
    let mut sc = base.clone();
    sc.config.scene.cells = buses * CELLS_PER_BUS;
    sc.config.scene.buses = buses;
    let from_s = 1.0;
    let started = Instant::now();
    let generated = skinbox_cosim::scene::generate(&sc, from_s + window)?;
    let generate_s = started.elapsed().as_secs_f64();
    let config = BoxConfig {
        ports: buses,
        flush_timeout_ticks: FLUSH_TICKS,
        status_period_ticks: STATUS_TICKS,
        ..BoxConfig::default()
    };
    let spec = skinbox_cosim::scene::spec(
        &generated,
        config,
        (from_s * 1e9) as u64,
        (window * 1e9) as u64,
    );
    Ok((spec, generate_s / (from_s + window)))
}

#[derive(Debug, Default, Serialize, Deserialize)]
struct RtlPoint {
    buses: usize,
    wall_per_sim_s: f64,
    generate_per_sim_s: f64,
    records: u64,
    datagrams: u64,
    sim_s: f64,
    ts_max_ticks: f64,
}

fn rate_inputs(buses: usize) -> RateInputs {
    let fraction = SEED_TABLE
        .iter()
        .find(|r| r.scene == SCENE)
        .expect("a seed scene")
        .packet_rate_pct
        / 100.0;
    RateInputs {
        cells_per_bus: vec![CELLS_PER_BUS; buses],
        sample_rate_hz: 125.0,
        packets_per_sample: fraction,
        flush_timeout_s: FLUSH_TICKS as f64 * 8e-9,
        status_period_s: STATUS_TICKS as f64 * 8e-9,
    }
}

/// Wall time of one evaluation of the rate model, s (mean of many).
fn rate_model_wall_s(buses: usize) -> f64 {
    let inputs = rate_inputs(buses);
    let reps = 10_000;
    let started = Instant::now();
    let mut sink = 0.0;
    for _ in 0..reps {
        sink += std::hint::black_box(predict(std::hint::black_box(&inputs))).datagrams_per_s;
    }
    std::hint::black_box(sink);
    started.elapsed().as_secs_f64() / f64::from(reps)
}

/// One RTL co-simulation of the stroking skin and the reference model on the same input.
fn rtl_and_reference(
    base: &skinbox_cells::Scene,
    buses: usize,
    window: f64,
) -> anyhow::Result<(RtlPoint, ReferencePoint)> {
    let (spec, generate_per_sim_s) = skin_spec(base, buses, window)?;
    let run = run_rtl(&spec)?;
    let r = &run.report;
    anyhow::ensure!(
        r.records_corrupted == 0 && r.packets_delivered == r.packets_sent,
        "the RTL lost or corrupted packets of the stroking scene: {r:?}"
    );
    let rtl = RtlPoint {
        buses,
        wall_per_sim_s: r.wall_seconds / r.sim_seconds,
        generate_per_sim_s,
        records: r.records,
        datagrams: r.frames,
        sim_s: r.sim_seconds,
        ts_max_ticks: r.ts_error_max_ticks,
    };
    let m = run_reference(&spec)?;
    let differing = run
        .frames
        .iter()
        .zip(&m.frames)
        .filter(|(a, b)| a != b)
        .count()
        + run.frames.len().abs_diff(m.frames.len());
    let reference = ReferencePoint {
        buses,
        wall_per_sim_s: m.report.wall_seconds / m.report.sim_seconds,
        records: m.report.records,
        datagrams: m.report.frames,
        frames_differing: Some(differing),
        ts_max_ticks: m.report.ts_error_max_ticks,
    };
    Ok((rtl, reference))
}

/// The RTL runs (each with its reference run), then the reference model alone on larger skins.
fn measure(
    quick: bool,
    base: &skinbox_cells::Scene,
    window: f64,
    progress: &mut Progress,
    grid: &mut Points,
) -> anyhow::Result<(Vec<RtlPoint>, Vec<ReferencePoint>)> {
    let mut rtl = Vec::new();
    let mut reference = Vec::new();
    for buses in rtl_buses(quick) {
        progress.step(&format!(
            "C2: RTL co-simulation and reference model, {buses} buses"
        ));
        let (rtl_point, reference_point) = grid
            .run(format!("C2/RTL and reference/{buses}"), || {
                rtl_and_reference(base, buses, window)
            })?;
        rtl.push(rtl_point);
        reference.push(reference_point);
    }
    for buses in reference_only_buses(quick) {
        progress.step(&format!("C2: reference model, {buses} buses"));
        reference.push(grid.run(format!("C2/reference/{buses}"), || {
            let (spec, _) = skin_spec(base, buses, window)?;
            let m = run_reference(&spec)?;
            Ok(ReferencePoint {
                buses,
                wall_per_sim_s: m.report.wall_seconds / m.report.sim_seconds,
                records: m.report.records,
                datagrams: m.report.frames,
                frames_differing: None,
                ts_max_ticks: m.report.ts_error_max_ticks,
            })
        })?);
    }
    Ok((rtl, reference))
}

/// The table, findings and chart points of the three levels, filled level by level.
struct Tally {
    table: Table,
    findings: Vec<(String, String)>,
    error_points_rtl: Vec<(f64, f64)>,
    error_points_reference: Vec<(f64, f64)>,
    error_points_rate: Vec<(f64, f64)>,
    speed_rtl: Vec<(f64, f64)>,
    speed_cells: Vec<(f64, f64)>,
    speed_reference: Vec<(f64, f64)>,
    speed_rate: Vec<(f64, f64)>,
}

impl Tally {
    /// An empty table with its header.
    fn new() -> Tally {
        Tally {
            table: Table::new(&[
                "level",
                "buses",
                "cells",
                "wall time per simulated s (s)",
                "records in the window",
                "datagrams",
                "records error vs RTL (%)",
                "datagrams error vs RTL (%)",
                "stamp - true edge, max (ticks)",
            ]),
            findings: Vec::new(),
            error_points_rtl: Vec::new(),
            error_points_reference: Vec::new(),
            error_points_rate: Vec::new(),
            speed_rtl: Vec::new(),
            speed_cells: Vec::new(),
            speed_reference: Vec::new(),
            speed_rate: Vec::new(),
        }
    }

    /// The RTL's rows and those of the cell models that fed it.
    fn rtl(&mut self, rtl: &[RtlPoint]) {
        for p in rtl {
            self.table.row(vec![
                "RTL (Verilator)".into(),
                p.buses.to_string(),
                (p.buses * CELLS_PER_BUS).to_string(),
                format!("{:.3}", p.wall_per_sim_s),
                p.records.to_string(),
                p.datagrams.to_string(),
                "0".into(),
                "0".into(),
                format!("{:.3}", p.ts_max_ticks),
            ]);
            self.table.row(vec![
                "cell models (the RTL's input)".into(),
                p.buses.to_string(),
                (p.buses * CELLS_PER_BUS).to_string(),
                format!("{:.4}", p.generate_per_sim_s),
                "-".into(),
                "-".into(),
                "-".into(),
                "-".into(),
                "-".into(),
            ]);
            self.error_points_rtl.push((p.wall_per_sim_s, 0.0));
            self.speed_rtl
                .push(((p.buses * CELLS_PER_BUS) as f64, p.wall_per_sim_s));
            self.speed_cells
                .push(((p.buses * CELLS_PER_BUS) as f64, p.generate_per_sim_s));
        }
    }

    /// The reference model's rows, compared with the RTL where it ran.
    fn reference(&mut self, reference: &[ReferencePoint], rtl: &[RtlPoint]) {
        for p in reference {
            let frames = match p.frames_differing {
                Some(d) => {
                    let pct = 100.0 * d as f64 / p.datagrams.max(1) as f64;
                    self.error_points_reference.push((p.wall_per_sim_s, pct));
                    self.findings.push((
                        format!("reference model against RTL, {} buses", p.buses),
                        format!(
                            "{d} of {} frames differ; {:.0} x faster",
                            p.datagrams,
                            rtl.iter()
                                .find(|r| r.buses == p.buses)
                                .map_or(0.0, |r| r.wall_per_sim_s / p.wall_per_sim_s)
                        ),
                    ));
                    (format!("{pct:.1}"), format!("{pct:.1}"))
                }
                None => ("no RTL run".into(), "no RTL run".into()),
            };
            self.speed_reference
                .push(((p.buses * CELLS_PER_BUS) as f64, p.wall_per_sim_s));
            self.table.row(vec![
                "reference model (packet level)".into(),
                p.buses.to_string(),
                (p.buses * CELLS_PER_BUS).to_string(),
                format!("{:.4}", p.wall_per_sim_s),
                p.records.to_string(),
                p.datagrams.to_string(),
                frames.0,
                frames.1,
                format!("{:.3}", p.ts_max_ticks),
            ]);
        }
        if let Some(p) = reference.iter().max_by_key(|p| p.buses) {
            self.findings.push((
                format!(
                    "reference model wall time per simulated s, {} buses ({} cells)",
                    p.buses,
                    p.buses * CELLS_PER_BUS
                ),
                format!("{:.3} s", p.wall_per_sim_s),
            ));
        }
    }

    /// The rate model's rows, timed, compared with the RTL where it ran.
    fn rate(&mut self, window: f64, rtl: &[RtlPoint], grid: &mut Points) -> anyhow::Result<()> {
        for buses in sizes() {
            let wall: f64 = grid.run(format!("C2/rate model wall time/{buses}"), || {
                Ok(rate_model_wall_s(buses))
            })?;
            let pred = predict(&rate_inputs(buses));
            let cells = buses * CELLS_PER_BUS;
            self.speed_rate.push((cells as f64, wall));
            let against = rtl.iter().find(|p| p.buses == buses);
            let (records, datagrams, e_rec, e_dg) = match against {
                Some(p) => {
                    let records = pred.delivered_per_s * window;
                    let record_datagrams = records / pred.records_per_datagram;
                    let status = (p.sim_s / (STATUS_TICKS as f64 * 8e-9)).floor()
                        * buses.div_ceil(skinbox_protocol::datagram::MAX_STATUS_PORTS) as f64;
                    let datagrams = record_datagrams + status;
                    let e_rec = 100.0 * (records - p.records as f64) / p.records as f64;
                    let e_dg = 100.0 * (datagrams - p.datagrams as f64) / p.datagrams as f64;
                    self.error_points_rate
                        .push((wall, e_rec.abs().max(e_dg.abs())));
                    self.findings.push((
                        format!("rate model against RTL, {buses} buses"),
                        format!("records {e_rec:+.1} %, datagrams {e_dg:+.1} %"),
                    ));
                    (
                        format!("{records:.0}"),
                        format!("{datagrams:.0}"),
                        format!("{e_rec:+.1}"),
                        format!("{e_dg:+.1}"),
                    )
                }
                None => (
                    format!("{:.0}", pred.delivered_per_s * window),
                    format!("{:.0}", pred.datagrams_per_s * window),
                    "no RTL run".into(),
                    "no RTL run".into(),
                ),
            };
            self.table.row(vec![
                "rate model (closed form)".into(),
                buses.to_string(),
                cells.to_string(),
                format!("{wall:.2e}"),
                records,
                datagrams,
                e_rec,
                e_dg,
                "-".into(),
            ]);
        }
        Ok(())
    }

    /// The RTL's wall time at its largest run, and extrapolated to the largest skin.
    fn rtl_findings(&mut self, rtl: &[RtlPoint]) {
        if let Some(p) = rtl.iter().max_by_key(|p| p.buses) {
            self.findings.push((
                format!("RTL wall time per simulated s, {} buses", p.buses),
                format!("{:.2} s", p.wall_per_sim_s),
            ));
            // Every port adds its UART receiver and deframer to each clock: the per-port cost
            // scales the RTL to the largest skin.
            let per_bus = p.wall_per_sim_s / p.buses as f64;
            self.findings.push((
                "RTL at 5,742 cells (87 buses), extrapolated per bus".into(),
                format!("about {:.0} s per simulated s (not run)", per_bus * 87.0),
            ));
        }
    }

    /// The two charts: error against speed, and speed by skin size.
    fn charts(
        error_points_rtl: Vec<(f64, f64)>,
        error_points_reference: Vec<(f64, f64)>,
        error_points_rate: Vec<(f64, f64)>,
        speed: [Vec<(f64, f64)>; 4],
    ) -> Vec<chart::Chart> {
        let [speed_rtl, speed_cells, speed_reference, speed_rate] = speed;
        let rtl_label = "RTL (Verilator), every clock";
        let rate_label = "rate model (closed form)";
        let reference_label = "reference model (packet level)";
        let cells_label = "cell models (packets for RTL)";
        let all_walls = speed_rtl
            .iter()
            .chain(&speed_rate)
            .chain(&speed_reference)
            .chain(&speed_cells)
            .map(|p| p.1);
        let (w_min, w_max) = all_walls.fold((f64::MAX, 0.0f64), |(a, b), w| (a.min(w), b.max(w)));
        let err_max = error_points_rate
            .iter()
            .map(|p| p.1)
            .fold(10.0f64, f64::max);
        let series = |label: &str, points: Vec<(f64, f64)>, style: chart::Style, color: usize| {
            chart::Series {
                label: label.into(),
                points,
                style,
                color,
            }
        };
        let (dot, line) = (chart::Style::Points, chart::Style::Line);
        vec![
            chart::Chart {
                name: "c2_fidelity".into(),
                title: "C2 Fidelity: speed against error relative to RTL".into(),
                x_label: "wall time per simulated second (s)".into(),
                y_label: "largest error vs RTL: records, datagrams (%)".into(),
                x_log: true,
                y_log: false,
                x_range: (w_min / 3.0, w_max * 3.0),
                y_range: (-1.0, err_max * 1.3),
                series: vec![
                    series(rtl_label, error_points_rtl, dot, 0),
                    series(reference_label, error_points_reference, dot, 3),
                    series(rate_label, error_points_rate, dot, 2),
                ],
                marks: Vec::new(),
                legend: chart::Legend::UpperRight,
            },
            chart::Chart {
                name: "c2_speed".into(),
                title: "C2 Fidelity: wall time per simulated second by skin size".into(),
                x_label: "cells (66 a bus)".into(),
                y_label: "wall time per simulated second (s)".into(),
                x_log: true,
                y_log: true,
                x_range: (40.0, 10_000.0),
                y_range: (w_min / 3.0, w_max * 3.0),
                series: vec![
                    series(rtl_label, speed_rtl, line, 0),
                    series(cells_label, speed_cells, line, 1),
                    series(reference_label, speed_reference, line, 3),
                    series(rate_label, speed_rate, line, 2),
                ],
                marks: Vec::new(),
                legend: chart::Legend::UpperRight,
            },
        ]
    }
}

/// The study.
pub fn study(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    let base = scene(SCENE)?;
    let window = window_s(quick);
    let (rtl, reference) = measure(quick, &base, window, progress, grid)?;
    progress.step("C2: rate model");
    let mut t = Tally::new();
    t.rtl(&rtl);
    t.reference(&reference, &rtl);
    t.rate(window, &rtl, grid)?;
    t.rtl_findings(&rtl);
    let charts = Tally::charts(
        t.error_points_rtl,
        t.error_points_reference,
        t.error_points_rate,
        [t.speed_rtl, t.speed_cells, t.speed_reference, t.speed_rate],
    );
    Ok(Section {
        id: "C2",
        title: "Simulation fidelity: wall time against error relative to the RTL".into(),
        text: format!(
            "The stroking-upper-arm scene (event mode, 125 Hz, 66 cells a bus) from 1 s on, a \
             {:.0} ms window. RTL: the verilated box (clock loop only; its input comes from the \
             cell models, timed on their own row). Reference model: the packet-level prediction \
             from the same pin transitions, compared frame by frame with the RTL (its error is \
             the share of frames that differ), and run alone up to the 64-port box. Rate \
             model: the closed form, with the \
             scene's calibrated packet rate (20.1 % of data mode), compared with the RTL's \
             records and datagrams in the same window. The calibrated rate is the mean of the \
             260-cell skin; a smaller skin puts its cells closer to the stroking hand, which is \
             the rate model's error there: it knows means, not where a scene is busy. Which \
             level a question needs: the gateware's own behaviour (timing, stamps, counters) \
             needs the RTL once per change; every frame of a scene of thousands of cells, the \
             reference model; loads and capacities of whole skins, the rate model.",
            window * 1e3
        ),
        findings: t.findings,
        tables: vec![t.table],
        charts,
    })
}
