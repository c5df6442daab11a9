//! C3, batching: what the flush timeout costs in latency and buys in link capacity.
//!
//! [`FramerModel`] is a packet-level model of the box's record batcher and transmitter
//! (`gateware/src/record_batcher.rs`, `frame_transmitter.rs`): records are written into the
//! filling datagram one after the other, 30 clocks each; a datagram closes when it holds 55
//! records or its first record has waited the flush timeout, but not before the previous
//! records datagram has left the wire (two buffers: one fills while the other is sent; the
//! gateware frees the buffer with the body's last byte, 16 clocks before the wire is free,
//! which this model leaves out), so under load a due datagram keeps taking
//! records; a full one that cannot close stops the input. The latency the box adds to a
//! record is the time from the end of its packet at the pin to the end of its datagram on
//! the wire (the host can use a record only when the frame's FCS has arrived). Status
//! datagrams (one per status period) are left out.
//!
//! The original box sends every packet as its own minimum-size frame: its latency is one
//! 86-byte frame time plus queueing behind the frames before it.

use super::rate_model::{
    capacity_records_per_s, original_capacity_records_per_s, original_frame_wire_bytes,
    records_frame_wire_bytes, CLOCK_HZ, LINK_BYTES_PER_S, RECORD_WRITE_CLOCKS,
};
use super::{chart, Points, Progress, Section, Table};
use serde::{Deserialize, Serialize};
use skinbox_cells::{scenes_dir, GenerateOptions, Mode, Scene};
use skinbox_protocol::datagram::MAX_RECORDS;

/// The framer, packet level.
#[derive(Debug, Clone, Copy)]
pub struct FramerModel {
    /// Flush timeout, ns.
    pub flush_timeout_ns: f64,
}

/// Latencies the box adds, and how it packed them.
#[derive(Debug, Clone, PartialEq)]
pub struct Batched {
    /// Per record, ns, in input order.
    pub latency_ns: Vec<f64>,
    /// Records datagrams sent.
    pub datagrams: usize,
}

impl Batched {
    /// Mean records per datagram.
    pub fn records_per_datagram(&self) -> f64 {
        self.latency_ns.len() as f64 / self.datagrams.max(1) as f64
    }
}

const NS_PER_BYTE: f64 = 1e9 / LINK_BYTES_PER_S;

impl FramerModel {
    /// Runs records that reach the framer at `ready_ns` (ascending) through it.
    pub fn run(&self, ready_ns: &[f64]) -> Batched {
        let write_ns = RECORD_WRITE_CLOCKS * 1e9 / CLOCK_HZ;
        let mut latency_ns = Vec::with_capacity(ready_ns.len());
        let mut datagrams = 0;
        let (mut previous_end_ns, mut write_free_ns) = (0.0f64, 0.0f64);
        let mut i = 0;
        while i < ready_ns.len() {
            let mut written_ns = ready_ns[i].max(write_free_ns) + write_ns;
            let deadline_ns = written_ns + self.flush_timeout_ns;
            let mut j = i + 1;
            let close_ns = loop {
                let full = j - i == MAX_RECORDS;
                let close = if full {
                    written_ns.max(previous_end_ns)
                } else {
                    deadline_ns.max(previous_end_ns).max(written_ns)
                };
                if full || j == ready_ns.len() {
                    break close;
                }
                let start = ready_ns[j].max(written_ns);
                if start >= close {
                    break close;
                }
                written_ns = start + write_ns;
                j += 1;
            };
            let end_ns = close_ns + records_frame_wire_bytes((j - i) as f64) * NS_PER_BYTE;
            latency_ns.extend(ready_ns[i..j].iter().map(|r| end_ns - r));
            datagrams += 1;
            previous_end_ns = end_ns;
            write_free_ns = written_ns.max(close_ns);
            i = j;
        }
        Batched {
            latency_ns,
            datagrams,
        }
    }
}

/// The original box: one minimum frame per packet, back to back at best.
pub fn original_box(ready_ns: &[f64]) -> Batched {
    let frame_ns = original_frame_wire_bytes() * NS_PER_BYTE;
    let mut free_ns = 0.0f64;
    let latency_ns = ready_ns
        .iter()
        .map(|&r| {
            free_ns = free_ns.max(r) + frame_ns;
            free_ns - r
        })
        .collect();
    Batched {
        latency_ns,
        datagrams: ready_ns.len(),
    }
}

/// The `q` quantile (0..=1) of `values` (nearest rank).
pub fn quantile(values: &[f64], q: f64) -> f64 {
    if values.is_empty() {
        return f64::NAN;
    }
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

/// The loads' names, in the order [`loads`] returns them.
const LOAD_NAMES: [&str; 2] = [
    "260 cells, stroking upper arm, event mode",
    "1,260 cells (humanoid), data mode, 250 Hz",
];

/// A load: the times its records reach the box (end of each packet at a pin), ns.
struct Load {
    ready_ns: Vec<f64>,
    window_s: f64,
}

/// End times of every packet that reaches a pin in `[from_s, from_s + window_s)`.
fn load_from(scene: &Scene, from_s: f64, window_s: f64) -> Vec<f64> {
    let mut scene = scene.clone();
    scene.config.scene.duration_s = from_s + window_s;
    scene.config.scene.warmup_s = from_s.min(scene.config.scene.duration_s * 0.5);
    let g = scene.generate(&GenerateOptions::default());
    let from_ps = (from_s * 1e12) as u64;
    let mut ready: Vec<f64> = g
        .buses
        .iter()
        .flat_map(|b| b.packets.iter())
        .filter(|p| p.pin_edge_ps >= from_ps)
        .map(|p| (p.pin_end_ps() - from_ps) as f64 / 1000.0)
        .collect();
    ready.sort_by(f64::total_cmp);
    ready
}

/// The loads of [`LOAD_NAMES`].
fn loads(quick: bool) -> anyhow::Result<[Load; 2]> {
    let window = if quick { 0.1 } else { 0.5 };
    let light = Scene::load(&scenes_dir().join("stroking_upper_arm.toml"))?;
    let mut heavy = Scene::load(&scenes_dir().join("idle.toml"))?;
    let s = &mut heavy.config.scene;
    s.cells = 1_260;
    s.buses = 20;
    s.mode = Mode::Data;
    s.sample_rate_hz = 250.0;
    heavy.check()?;
    Ok([
        Load {
            ready_ns: load_from(&light, 1.0, window * 2.0),
            window_s: window * 2.0,
        },
        Load {
            ready_ns: load_from(&heavy, 0.1, window),
            window_s: window,
        },
    ])
}

/// What one load through one box (or framer setting) gives: a row of the table.
#[derive(Debug, Clone, Copy, Default, Serialize, Deserialize)]
struct Outcome {
    records_per_s: f64,
    records_per_datagram: f64,
    datagrams_per_s: f64,
    /// Latency quantiles p50, p99 and max, us.
    latency_us: [f64; 3],
    /// Capacity, cells at 250 Hz per link.
    capacity_cells: f64,
}

impl Outcome {
    fn new(load: &Load, b: &Batched, capacity_cells: f64) -> Outcome {
        let q = |x| quantile(&b.latency_ns, x) / 1000.0;
        Outcome {
            records_per_s: load.ready_ns.len() as f64 / load.window_s,
            records_per_datagram: b.records_per_datagram(),
            datagrams_per_s: b.datagrams as f64 / load.window_s,
            latency_us: [q(0.5), q(0.99), q(1.0)],
            capacity_cells,
        }
    }
}

/// Flush timeouts swept, us.
fn timeouts_us(quick: bool) -> Vec<f64> {
    if quick {
        vec![1.0, 10.0, 100.0, 1000.0]
    } else {
        vec![
            0.1, 0.3, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0,
        ]
    }
}

/// Steps [`study`] reports.
pub fn steps(quick: bool) -> u64 {
    1 + timeouts_us(quick).len() as u64
}

/// Cells at 250 Hz that `records_per_s` carries.
fn cells_250(records_per_s: f64) -> f64 {
    records_per_s / 250.0
}

/// The study: per load and flush timeout, latency quantiles and the capacity at the
/// packing reached.
pub fn study(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    progress.step("C3: generating the loads");
    // generated once, by the first point this run computes (none in a merge)
    let mut generated: Option<[Load; 2]> = None;
    let mut with_loads = |f: &dyn Fn(&[Load; 2]) -> [Outcome; 2]| -> anyhow::Result<[Outcome; 2]> {
        if generated.is_none() {
            generated = Some(loads(quick)?);
        }
        Ok(f(generated.as_ref().expect("generated")))
    };
    let mut table = Table::new(&[
        "load",
        "box",
        "flush timeout (us)",
        "records/s",
        "records per datagram",
        "datagrams/s",
        "latency p50 (us)",
        "latency p99 (us)",
        "latency max (us)",
        "capacity (cells at 250 Hz per link)",
    ]);
    let mut curves: Vec<Vec<[f64; 4]>> = vec![Vec::new(); LOAD_NAMES.len()];
    let add_row = |table: &mut Table, load: &str, what: &str, t: &str, o: &Outcome| {
        table.row(vec![
            load.to_string(),
            what.to_string(),
            t.to_string(),
            format!("{:.0}", o.records_per_s),
            format!("{:.2}", o.records_per_datagram),
            format!("{:.0}", o.datagrams_per_s),
            format!("{:.2}", o.latency_us[0]),
            format!("{:.2}", o.latency_us[1]),
            format!("{:.2}", o.latency_us[2]),
            format!("{:.0}", o.capacity_cells),
        ]);
    };
    for t_us in timeouts_us(quick) {
        progress.step(&format!("C3: flush timeout {t_us} us"));
        let model = FramerModel {
            flush_timeout_ns: t_us * 1000.0,
        };
        let outcomes = grid.run(format!("C3/flush timeout {t_us} us"), || {
            with_loads(&|loads| {
                loads.each_ref().map(|load| {
                    let b = model.run(&load.ready_ns);
                    let cap = cells_250(capacity_records_per_s(b.records_per_datagram()));
                    Outcome::new(load, &b, cap)
                })
            })
        })?;
        for (l, o) in outcomes.iter().enumerate() {
            add_row(
                &mut table,
                LOAD_NAMES[l],
                "batching",
                &chart::tick_label(t_us),
                o,
            );
            let [p50, p99, max] = o.latency_us;
            curves[l].push([o.capacity_cells, p50, p99, max]);
        }
    }
    let originals = grid.run("C3/original box", || {
        with_loads(&|loads| {
            loads.each_ref().map(|load| {
                let cap = cells_250(original_capacity_records_per_s());
                Outcome::new(load, &original_box(&load.ready_ns), cap)
            })
        })
    })?;
    let mut original = Vec::new();
    for (l, o) in originals.iter().enumerate() {
        add_row(
            &mut table,
            LOAD_NAMES[l],
            "original (one packet per datagram)",
            "-",
            o,
        );
        original.push(o.latency_us);
    }
    let heavy = &curves[1];
    let light = &curves[0];
    let series = |label: &str, c: &[[f64; 4]], k: usize, color| chart::Series {
        label: label.to_string(),
        points: c.iter().map(|p| (p[0], p[k])).collect(),
        style: chart::Style::Line,
        color,
    };
    let all_latencies = curves.iter().flatten().flat_map(|p| [p[1], p[3]]);
    let y_max = all_latencies.fold(1.0f64, f64::max) * 2.0;
    let seed_cells = 5_742.0;
    let chart = chart::Chart {
        name: "c3_batching".into(),
        title: "C3 Batching: latency added by the box against link capacity".into(),
        x_label: "link capacity at the packing reached (cells at 250 Hz per Gigabit link)".into(),
        y_label: "latency added by the box (us)".into(),
        x_log: false,
        y_log: true,
        x_range: (0.0, 18_000.0),
        y_range: (0.1, y_max),
        series: vec![
            series("humanoid (315 k records/s): p50", heavy, 1, 0),
            series("humanoid: p99", heavy, 2, 1),
            series("humanoid: max", heavy, 3, 2),
            series("260 cells stroking (event): p99", light, 2, 3),
        ],
        marks: vec![chart::Mark {
            at: (seed_cells, original[1][1].max(0.1)),
            text: "original box, 5,742 cells (seed)".into(),
        }],
        legend: chart::Legend::UpperLeft,
    };
    let text = format!(
        "Latency the box adds to a record (end of its packet at the pin to the end of its \
         datagram on the wire), from a packet-level model of the framer fed with the cell \
         models' packet times, against the link capacity the datagram packing reached at that \
         load (cells at 250 Hz per Gigabit link; the framer's own ceiling of {:.0} cells caps it). \
         Each point of a curve is one flush timeout ({} us). The original box sends one packet \
         per 86-byte frame: {:.0} cells by our wire arithmetic, 5,742 in the papers.",
        cells_250(super::rate_model::framer_records_per_s()),
        timeouts_us(quick)
            .iter()
            .map(|t| chart::tick_label(*t))
            .collect::<Vec<_>>()
            .join(", "),
        cells_250(original_capacity_records_per_s()),
    );
    Ok(Section {
        id: "C3",
        title: "Batching: flush timeout, latency and link capacity".into(),
        text,
        findings: Vec::new(),
        tables: vec![table],
        charts: vec![chart],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_lone_record_waits_the_timeout_then_one_frame_time() {
        let b = FramerModel {
            flush_timeout_ns: 100_000.0,
        }
        .run(&[1_000.0]);
        // 240 ns to write it, 100 us timeout, 116 wire bytes at 8 ns (66 of Ethernet,
        // IPv4, UDP, preamble and gap, 24 of datagram header, 26 of record).
        assert_eq!(records_frame_wire_bytes(1.0), 116.0);
        assert_eq!(b.latency_ns, vec![240.0 + 100_000.0 + 116.0 * 8.0]);
        assert_eq!(b.datagrams, 1);
    }

    #[test]
    fn records_inside_the_timeout_share_a_datagram_and_55_fill_one() {
        let model = FramerModel {
            flush_timeout_ns: 10_000.0,
        };
        // Three records 1 us apart, then one long after.
        let b = model.run(&[0.0, 1_000.0, 2_000.0, 100_000.0]);
        assert_eq!(b.datagrams, 2);
        let end = 240.0 + 10_000.0 + records_frame_wire_bytes(3.0) * 8.0;
        assert_eq!(&b.latency_ns[..3], &[end, end - 1_000.0, end - 2_000.0]);
        // 200 records at once: written back to back (13.2 us for 55) while the previous
        // datagram is on the wire (12.16 us); with a timeout longer than that each datagram
        // closes full.
        let b = FramerModel {
            flush_timeout_ns: 100_000.0,
        }
        .run(&[0.0; 200]);
        assert_eq!(b.datagrams, 4);
        let first_end = 55.0 * 240.0 + 1520.0 * 8.0;
        assert_eq!(b.latency_ns[0], first_end);
        assert_eq!(
            b.latency_ns[55],
            (110.0 * 240.0f64).max(first_end) + 1520.0 * 8.0
        );
        // With the 10 us timeout the first datagram is due at 10.24 us; the 43rd record,
        // begun at 10.08 us, is completed (at 10.32 us) before it closes. Later ones leave as
        // soon as the one before has left the wire.
        let b = model.run(&[0.0; 200]);
        assert_eq!(b.datagrams, 5);
        assert_eq!(
            b.latency_ns[0],
            43.0 * 240.0 + records_frame_wire_bytes(43.0) * 8.0
        );
        assert_eq!(b.latency_ns[42], b.latency_ns[0]);
        assert!(b.latency_ns[43] > b.latency_ns[0]);
    }

    #[test]
    fn the_original_box_queues_one_frame_per_packet() {
        let b = original_box(&[0.0, 0.0, 10_000.0]);
        assert_eq!(b.latency_ns, vec![688.0, 1376.0, 688.0]);
    }

    #[test]
    fn quantiles_by_nearest_rank() {
        let v: Vec<f64> = (1..=100).map(f64::from).collect();
        assert_eq!(quantile(&v, 0.5), 50.0);
        assert_eq!(quantile(&v, 0.99), 99.0);
        assert_eq!(quantile(&v, 1.0), 100.0);
    }
}
