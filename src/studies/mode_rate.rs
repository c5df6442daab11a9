//! C7, the papers' mode and rate experiment through the box: one skin, switched by host
//! commands between data and event mode and through 62.5, 125, 250 and 500 Hz while it
//! runs. The commands go from the host to the co-simulated box (the reference model) as
//! cell commands, down its UART pins to the cells, which obey at their next sample; what
//! the box sends is decoded by the host decoder. Per segment: packets per cell per second
//! at the host, and the host's CPU for decoding them (measured), beside the papers' curves.

use super::{chart, Points, Progress, Section, Table};
use skinbox_cells::calibration::{RateFit, FIG11_FITS};
use skinbox_cells::scene::{CommandConfig, Scene};
use skinbox_cells::{GenerateOptions, Mode};
use skinbox_cosim::reference::run_reference;
use skinbox_cosim::scene::{generate_with, plan_downlink, scene_ns_of_tick, spec};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_host::{DecodedRecord, Decoder, DecoderConfig, RecordSink, Sample};

/// The sample rates of the experiment, Hz (the papers' Fig. 11 range).
pub const RATES_HZ: [f64; 4] = [62.5, 125.0, 250.0, 500.0];

/// The scene: the papers' "stroking the arm" (its Fig. 11 fit spans the rates).
pub const SCENE: &str = "stroking_arm";

/// Buses of the skin's 260 cells: 8 (33 cells each carry data mode at 500 Hz, 16,250 of
/// a bus's 20,000 packets/s; on 4 buses of 65 cells data mode saturates them at 307
/// packets per cell per second).
pub const BUSES: usize = 8;

/// Time after each switch that is not counted, at least, s: the command's way down the
/// longest chain (65 cells, 3.4 ms), the next sample, and the burst a mode change causes
/// (every channel sent once). The rest of the segment is counted to a whole number of the
/// slowest rate's periods.
pub const SETTLE_S: f64 = 0.2;

/// The papers' host cost (the original driver, one core of an i7-4770): CPU % =
/// `a * ln(b * x + 1)`, `x` packets per second; data mode, then event mode.
pub const DRIVER_CPU_FITS: [(f64, f64); 2] = [(45.52, 5.453e-5), (32.65, 1.239e-4)];

/// The papers' measured data mode rate, packets per cell per second per Hz.
pub const DATA_MODE_MEASURED: f64 = 0.9435;

/// Seconds of each of the 8 segments.
fn segment_s(quick: bool) -> f64 {
    if quick {
        0.5
    } else {
        3.0
    }
}

/// Steps [`study`] reports.
pub fn steps(_quick: bool) -> u64 {
    1
}

/// The segments in order: (mode, sample rate): data mode at every rate, then event mode.
pub fn segments() -> Vec<(Mode, f64)> {
    [Mode::Data, Mode::Event]
        .into_iter()
        .flat_map(|m| RATES_HZ.map(|r| (m, r)))
        .collect()
}

/// The skin with its command schedule: data mode at 62.5 Hz from the start; at each
/// segment's start a rate command to every cell, and at the first event segment a mode
/// command before it.
pub fn experiment_scene(quick: bool) -> anyhow::Result<Scene> {
    let mut sc = super::scene(SCENE)?;
    let seg = segment_s(quick);
    let s = &mut sc.config.scene;
    s.mode = Mode::Data;
    s.buses = BUSES;
    s.sample_rate_hz = RATES_HZ[0];
    s.warmup_s = 0.0;
    s.duration_s = seg * segments().len() as f64;
    let command = |time_s: f64| CommandConfig {
        time_s,
        port: None,
        cell: None,
        mode: None,
        rate_hz: None,
        thresholds: None,
        enabled: None,
        time_sync: None,
        raw: None,
    };
    sc.config.commands.clear();
    for (k, (mode, rate)) in segments().into_iter().enumerate() {
        let t = k as f64 * seg;
        if k > 0 && mode != segments()[k - 1].0 {
            sc.config.commands.push(CommandConfig {
                mode: Some(mode),
                ..command(t)
            });
        }
        if k > 0 {
            sc.config.commands.push(CommandConfig {
                rate_hz: Some(rate),
                ..command(t + 0.001)
            });
        }
    }
    sc.check()?;
    Ok(sc)
}

/// Counts full samples as the host's converter makes them.
#[derive(Default)]
struct Samples(u64);

impl RecordSink for Samples {
    fn record(&mut self, _record: &DecodedRecord) {}
    fn wants_samples(&self) -> bool {
        true
    }
    fn sample(&mut self, _sample: &Sample) {
        self.0 += 1;
    }
}

/// One segment's figures.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Segment {
    /// Packets per cell per second delivered to the host (after the settling time).
    pub packets_per_cell_s: f64,
    /// The host's CPU to decode them, % of one core (measured, this machine).
    pub host_cpu_pct: f64,
    /// Host CPU per packet, ns.
    pub cpu_ns_per_packet: f64,
}

/// Runs the experiment through the box; one [`Segment`] per entry of [`segments`].
pub fn run(quick: bool) -> anyhow::Result<Vec<Segment>> {
    let sc = experiment_scene(quick)?;
    let seg_ns = (segment_s(quick) * 1e9) as u64;
    let total_ns = seg_ns * segments().len() as u64;
    let config = BoxConfig {
        ports: sc.config.scene.buses,
        ..BoxConfig::default()
    };
    let plan = plan_downlink(&sc, &config, 0, total_ns);
    anyhow::ensure!(
        plan.refused == 0 && plan.accepted == sc.config.commands.len(),
        "the box took {} of {} commands",
        plan.accepted,
        sc.config.commands.len()
    );
    let generated = generate_with(
        &sc,
        total_ns as f64 * 1e-9,
        &GenerateOptions {
            downlink: Some(plan.per_bus.clone()),
            ..Default::default()
        },
    )?;
    let mut sim = spec(&generated, config, 0, total_ns);
    sim.host_frames = plan.host_frames.clone();
    let run = run_reference(&sim)?;
    // the datagrams as the host receives them, split by segment on their first record's
    // stamp; each segment's decoded and timed on its own
    let cells = sc.config.scene.cells as f64;
    // counted from the settling time on, over a whole number of the slowest rate's periods:
    // every cell sends as many samples in it whatever its phase (the cells on the box's
    // grid all have one phase, so a part period would count a sample more or less for all)
    let slowest_period_ns = (1e9 / RATES_HZ.iter().copied().fold(f64::MAX, f64::min)) as u64;
    let counted_ns = (seg_ns - (SETTLE_S * 1e9) as u64) / slowest_period_ns * slowest_period_ns;
    let settle_ns = seg_ns - counted_ns;
    let mut per_segment: Vec<Vec<Vec<u8>>> = vec![Vec::new(); segments().len()];
    let mut counted = vec![0u64; segments().len()];
    for d in &run.datagrams {
        let skinbox_protocol::datagram::DatagramBody::Records(records) = &d.body else {
            continue;
        };
        let Some(first) = records.first() else {
            continue;
        };
        let at = |offset: i32| scene_ns_of_tick((d.base_tick as i64 + offset as i64) as u64, 0);
        let k = (at(first.tick_offset) / seg_ns) as usize;
        if k >= segments().len() {
            continue;
        }
        for r in records {
            let t = at(r.tick_offset);
            if t / seg_ns == k as u64 && t % seg_ns >= settle_ns {
                counted[k] += 1;
            }
        }
        per_segment[k].push(d.to_bytes());
    }
    let counted_s = counted_ns as f64 * 1e-9;
    let out = per_segment
        .iter()
        .zip(&counted)
        .map(|(datagrams, &n)| {
            let mut decoder = Decoder::new(DecoderConfig::default());
            let mut sink = Samples::default();
            let cpu = skinbox_host::thread_cpu_ns();
            for d in datagrams {
                decoder.push_datagram(d, &mut sink);
            }
            let cpu_ns = skinbox_host::thread_cpu_ns().saturating_sub(cpu) as f64;
            let records = decoder.records().max(1) as f64;
            let per_packet = cpu_ns / records;
            let packets_per_s = n as f64 / counted_s;
            Segment {
                packets_per_cell_s: packets_per_s / cells,
                host_cpu_pct: per_packet * packets_per_s / 1e9 * 100.0,
                cpu_ns_per_packet: per_packet,
            }
        })
        .collect();
    Ok(out)
}

/// The papers' driver CPU %, data (`0`) or event (`1`) mode, at `packets_per_s`.
pub fn driver_cpu_pct(mode: usize, packets_per_s: f64) -> f64 {
    let (a, b) = DRIVER_CPU_FITS[mode];
    a * (b * packets_per_s + 1.0).ln()
}

/// Measured packets, host CPU and the papers' driver CPU by sample rate, one per mode.
#[derive(Default)]
struct ModeSeries {
    packets: [Vec<(f64, f64)>; 2],
    cpu: [Vec<(f64, f64)>; 2],
    driver: [Vec<(f64, f64)>; 2],
    /// The largest ratio of this host's CPU to the papers' driver's.
    ratio_max: f64,
}

/// The table of every segment beside the papers' figures, and the series for the charts.
fn tabulate(result: &[Segment], fit: &RateFit) -> (Table, ModeSeries) {
    let cells = 260.0;
    let mut table = Table::new(&[
        "mode",
        "sample rate (Hz)",
        "packets per cell per s",
        "papers (data: 0.9435 x; event: Fig. 11 fit)",
        "host CPU (ns/packet)",
        "host CPU (% of a core)",
        "papers' driver CPU (%) at this packet rate",
    ]);
    let mut s_out = ModeSeries::default();
    for ((mode, rate), s) in segments().into_iter().zip(result) {
        let m = usize::from(mode == Mode::Event);
        let papers = match mode {
            Mode::Data => DATA_MODE_MEASURED * rate,
            Mode::Event => fit.packets_per_cell_s(rate),
        };
        let driver = driver_cpu_pct(m, s.packets_per_cell_s * cells);
        if driver > 0.0 {
            s_out.ratio_max = s_out.ratio_max.max(s.host_cpu_pct / driver);
        }
        table.row(vec![
            format!("{mode:?}").to_lowercase(),
            format!("{rate}"),
            format!("{:.2}", s.packets_per_cell_s),
            format!("{papers:.2}"),
            format!("{:.0}", s.cpu_ns_per_packet),
            format!("{:.3}", s.host_cpu_pct),
            format!("{driver:.1}"),
        ]);
        s_out.packets[m].push((rate, s.packets_per_cell_s));
        s_out.cpu[m].push((rate, s.host_cpu_pct));
        s_out.driver[m].push((rate, driver));
    }
    (table, s_out)
}

/// The chart of packets per cell through the box against the papers' data and event rates.
fn packets_chart(packet_series: &[Vec<(f64, f64)>; 2], fit: &RateFit) -> chart::Chart {
    let (lo, hi) = (RATES_HZ[0], RATES_HZ[RATES_HZ.len() - 1]);
    let curve = |f: &dyn Fn(f64) -> f64| -> Vec<(f64, f64)> {
        (0..=50)
            .map(|k| {
                let x = lo + (hi - lo) * f64::from(k) / 50.0;
                (x, f(x))
            })
            .collect()
    };
    let mut series = Vec::new();
    for (m, name) in MODE_NAMES.iter().enumerate() {
        series.push(chart::Series {
            label: format!("{} through the box", name),
            points: packet_series[m].clone(),
            style: chart::Style::Points,
            color: m,
        });
    }
    series.push(chart::Series {
        label: "papers: data 0.9435 x (dashed)".into(),
        points: curve(&|x| DATA_MODE_MEASURED * x),
        style: chart::Style::Dashed,
        color: 0,
    });
    series.push(chart::Series {
        label: "papers: event, Fig. 11 fit of stroking the arm (dashed)".into(),
        points: curve(&|x| fit.packets_per_cell_s(x)),
        style: chart::Style::Dashed,
        color: 1,
    });
    let y_max = packet_series
        .iter()
        .flatten()
        .map(|p| p.1)
        .fold(hi, f64::max);
    chart::Chart {
        name: "c7_mode_rate_packets".into(),
        title: "C7 One skin switched by host commands: packets per cell".into(),
        x_label: "sample rate (Hz)".into(),
        y_label: "packets per cell per second at the host".into(),
        x_log: false,
        y_log: false,
        x_range: (0.0, hi * 1.05),
        y_range: (0.0, y_max * 1.1),
        series,
        marks: Vec::new(),
        legend: chart::Legend::UpperLeft,
    }
}

/// The chart of this host decoder's CPU against the papers' driver's, both modes.
fn cpu_chart(s: &ModeSeries) -> chart::Chart {
    let hi = RATES_HZ[RATES_HZ.len() - 1];
    let mut series = Vec::new();
    for (m, name) in MODE_NAMES.iter().enumerate() {
        series.push(chart::Series {
            label: format!("{}: this host decoder (measured)", name),
            points: s.cpu[m].clone(),
            style: chart::Style::Points,
            color: m,
        });
        series.push(chart::Series {
            label: format!("{}: the papers' driver, a ln(bx + 1) (dashed)", name),
            points: s.driver[m].clone(),
            style: chart::Style::Dashed,
            color: m,
        });
    }
    let all: Vec<f64> = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .collect();
    let (y_lo, y_hi) = (
        all.iter().copied().fold(f64::INFINITY, f64::min).max(1e-4),
        all.iter().copied().fold(0.0, f64::max),
    );
    chart::Chart {
        name: "c7_mode_rate_cpu".into(),
        title: "C7 Host CPU against sample rate, both modes".into(),
        x_label: "sample rate (Hz)".into(),
        y_label: "host CPU (% of one core)".into(),
        x_log: false,
        y_log: true,
        x_range: (0.0, hi * 1.05),
        y_range: (y_lo / 2.0, y_hi * 2.0),
        series,
        marks: Vec::new(),
        legend: chart::Legend::UpperLeft,
    }
}

/// The chart labels of data (`0`) and event (`1`) mode.
const MODE_NAMES: [&str; 2] = ["data mode", "event mode"];

/// The study.
pub fn study(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    progress.step("C7: the mode and rate experiment through the box");
    let mut result: Vec<Segment> = grid.run("C7/mode_rate", || run(quick))?;
    // (a shard that does not own the point has none: its section is not written)
    result.resize(segments().len(), Segment::default());
    let fit = FIG11_FITS
        .iter()
        .find(|f| f.scene == SCENE)
        .expect("the scene has a Fig. 11 fit");
    let (table, series) = tabulate(&result, fit);
    let packets_chart = packets_chart(&series.packets, fit);
    let cpu_chart = cpu_chart(&series);
    let ratio_max = series.ratio_max;
    let data_500 = result[3].packets_per_cell_s;
    let event_500 = result[7].packets_per_cell_s;
    let findings = vec![
        (
            "event mode at 500 Hz, % of data mode".to_string(),
            format!("{:.1} %", 100.0 * event_500 / data_500.max(1e-9)),
        ),
        (
            "host CPU of this decoder against the papers' driver (worst)".to_string(),
            format!("{:.4} of the driver's", ratio_max),
        ),
    ];
    Ok(Section {
        id: "C7",
        title: "The papers' mode and rate experiment, through the box".into(),
        text: format!(
            "One skin ({SCENE}, 260 cells on {BUSES} buses) runs {} s: data mode at 62.5, 125, \
             250 and 500 Hz, then event mode at the same rates, {} s each. The switches are \
             cell commands the host sends to the box (the reference model) as command \
             frames; the box's downlink sends them down every bus (`plan_downlink`) and \
             the cells obey at their next sample. Counted at the host from each segment's \
             datagrams, {SETTLE_S} s after each switch; the host CPU is this machine's \
             decoder (full samples made) timed on each segment's datagrams. Dashed: the \
             papers' data mode (0.9435 per Hz), their Fig. 11 fit of stroking the arm, and \
             their driver's CPU `a * ln(b * x + 1)` at the packet rate measured here.",
            segment_s(quick) * segments().len() as f64,
            segment_s(quick)
        ),
        findings,
        tables: vec![table],
        charts: vec![packets_chart, cpu_chart],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_experiment_switches_mode_and_rate_through_the_box() {
        let result = run(true).unwrap();
        assert_eq!(result.len(), 8);
        for (k, (mode, rate)) in segments().into_iter().enumerate() {
            let r = result[k].packets_per_cell_s;
            match mode {
                // every cell sends every sample
                Mode::Data => assert!((r / rate - 1.0).abs() < 0.02, "data at {rate}: {r}"),
                // fewer than in data mode
                Mode::Event => assert!(r < 0.8 * rate, "event at {rate}: {r}"),
            }
            assert!(result[k].host_cpu_pct > 0.0);
        }
        // event mode rises with the sample rate
        for k in 4..7 {
            assert!(result[k + 1].packets_per_cell_s > result[k].packets_per_cell_s);
        }
    }
}
