//! C3, batching: what the flush timeout costs in latency and buys in link capacity.
//!
//! The box itself batches: every load runs through the reference model
//! ([`skinbox_cosim::reference`], the cycle-exact shadow of the RTL that the regression
//! tests hold byte for byte to it), once per flush timeout, with that timeout in the
//! [`BoxConfig`]. Its frames come with their first cycle on GMII and their length, so the
//! end of each frame on the wire is known. The latency the box adds to a record is the time
//! from the end of its packet at the pin to the end of its frame's FCS on the wire (the host
//! can use a record only when the FCS has arrived). Status datagrams are sent as the box
//! sends them (one per status period) and share the link, but carry no records.
//!
//! The original box sends every packet as its own minimum-size frame: its latency is one
//! 86-byte frame time plus queueing behind the frames before it.

use super::rate_model::{
    capacity_records_per_s, original_capacity_records_per_s, original_frame_wire_bytes,
    LINK_BYTES_PER_S,
};
use super::{chart, Points, Progress, Section, Table};
use anyhow::Context;
use serde::{Deserialize, Serialize};
use skinbox_cells::{scenes_dir, GenerateOptions, Mode, Scene};
use skinbox_cosim::reference::run_reference;
use skinbox_cosim::sim::SimSpec;
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::cell::{PACKET_LEN, UART_BITS_PER_PACKET};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::TICK_NS;
use std::collections::VecDeque;

/// Latencies the box adds, and how it packed them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Batched {
    /// Per record delivered, ns, in the order the records left the box.
    pub latency_ns: Vec<f64>,
    /// Records datagrams sent.
    pub datagrams: usize,
    /// Records per records datagram, in sending order.
    pub records_per_frame: Vec<usize>,
    /// Packets put on the pins that came back in no record.
    pub lost: u64,
}

impl Batched {
    /// Mean records per datagram.
    pub fn records_per_datagram(&self) -> f64 {
        self.latency_ns.len() as f64 / self.datagrams.max(1) as f64
    }
}

const NS_PER_BYTE: f64 = 1e9 / LINK_BYTES_PER_S;

/// The box of `spec` (the reference model) with a flush timeout of `flush_timeout_ticks`:
/// every record's latency from the end of its packet at the pin to the end of its frame on
/// the wire. Records are matched to the packets of their port in order by their bytes, as
/// the co-simulation's analysis does; a record that matches no packet is an error.
pub fn run_box(spec: &SimSpec, flush_timeout_ticks: u64) -> anyhow::Result<Batched> {
    let spec = SimSpec {
        config: BoxConfig {
            flush_timeout_ticks,
            ..spec.config.clone()
        },
        ..spec.clone()
    };
    let run = run_reference(&spec).context("running the reference model")?;
    // each port's packets with the end of their last stop bit, to be matched in order
    let mut pending: Vec<VecDeque<(&[u8; PACKET_LEN], f64)>> = spec
        .ports
        .iter()
        .map(|packets| {
            packets
                .iter()
                .map(|p| {
                    (
                        &p.bytes,
                        p.start_ns + UART_BITS_PER_PACKET as f64 * p.bit_ns,
                    )
                })
                .collect()
        })
        .collect();
    let mut out = Batched::default();
    for (frame, datagram) in run.frames.iter().zip(&run.datagrams) {
        let DatagramBody::Records(records) = &datagram.body else {
            continue;
        };
        let end_ns = ((frame.first_cycle + frame.bytes.len() as u64) * TICK_NS) as f64;
        out.datagrams += 1;
        out.records_per_frame.push(records.len());
        for r in records {
            let queue = pending
                .get_mut(usize::from(r.port))
                .with_context(|| format!("a record of port {}, which the box lacks", r.port))?;
            let k = queue
                .iter()
                .position(|p| *p.0 == r.cell_packet)
                .with_context(|| format!("a record of port {} matches no packet", r.port))?;
            queue.drain(..k);
            let (_, ready_ns) = queue.pop_front().expect("found above");
            out.latency_ns.push(end_ns - ready_ns);
        }
    }
    out.lost = run.report.dropped;
    Ok(out)
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
        records_per_frame: vec![1; ready_ns.len()],
        lost: 0,
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

/// A load: its packets on the box's pins, one port per bus.
struct Load {
    spec: SimSpec,
    window_s: f64,
}

impl Load {
    /// Packets on the pins.
    fn packets(&self) -> usize {
        self.spec.ports.iter().map(Vec::len).sum()
    }

    /// End of every packet at its pin (last stop bit), ns, ascending.
    fn ready_ns(&self) -> Vec<f64> {
        let mut ready: Vec<f64> = self
            .spec
            .ports
            .iter()
            .flatten()
            .map(|p| p.start_ns + UART_BITS_PER_PACKET as f64 * p.bit_ns)
            .collect();
        ready.sort_by(f64::total_cmp);
        ready
    }
}

/// The packets of `scene` that reach a pin in `[from_s, from_s + window_s)`, on a box with
/// one port per bus.
fn load_from(scene: &Scene, from_s: f64, window_s: f64) -> Load {
    let mut scene = scene.clone();
    scene.config.scene.duration_s = from_s + window_s;
    scene.config.scene.warmup_s = from_s.min(scene.config.scene.duration_s * 0.5);
    let g = scene.generate(&GenerateOptions::default());
    let config = BoxConfig {
        ports: g.buses.len(),
        ..BoxConfig::default()
    };
    let ns = |s: f64| (s * 1e9).round() as u64;
    Load {
        spec: skinbox_cosim::scene::spec(&g, config, ns(from_s), ns(window_s)),
        window_s,
    }
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
        load_from(&light, 1.0, window * 2.0),
        load_from(&heavy, 0.1, window),
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
    /// Packets put on the pins that came back in no record.
    lost: u64,
}

impl Outcome {
    fn new(load: &Load, b: &Batched, capacity_cells: f64) -> Outcome {
        let q = |x| quantile(&b.latency_ns, x) / 1000.0;
        Outcome {
            records_per_s: load.packets() as f64 / load.window_s,
            records_per_datagram: b.records_per_datagram(),
            datagrams_per_s: b.datagrams as f64 / load.window_s,
            latency_us: [q(0.5), q(0.99), q(1.0)],
            capacity_cells,
            lost: b.lost,
        }
    }
}

/// Flush timeouts swept, us (whole ticks of 8 ns).
fn timeouts_us(quick: bool) -> Vec<f64> {
    if quick {
        vec![1.0, 10.0, 100.0, 1000.0]
    } else {
        vec![
            0.2, 0.4, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0,
        ]
    }
}

/// The flush timeout `t_us` in box ticks.
fn flush_timeout_ticks(t_us: f64) -> u64 {
    (t_us * 1000.0 / TICK_NS as f64).round() as u64
}

/// Steps [`study`] reports.
pub fn steps(quick: bool) -> u64 {
    1 + timeouts_us(quick).len() as u64
}

/// Cells at 250 Hz that `records_per_s` carries.
fn cells_250(records_per_s: f64) -> f64 {
    records_per_s / 250.0
}

/// One row of the table: a load through one box at one flush timeout.
fn outcome_row(table: &mut Table, load: &str, what: &str, t: &str, o: &Outcome) {
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
        o.lost.to_string(),
    ]);
}

/// The chart of latency against link capacity, one curve per load, the original box marked.
fn latency_capacity_chart(curves: &[Vec<[f64; 4]>], original: &[[f64; 3]]) -> chart::Chart {
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
    chart::Chart {
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
    }
}

/// The section's text: what was measured and how.
fn study_text(quick: bool) -> String {
    format!(
        "Latency the box adds to a record (end of its packet at the pin to the end of its \
         frame on the wire), from the reference model of the box (cycle-exact, held byte for \
         byte to the RTL) fed with the cell models' packets, against the link capacity the datagram packing reached at that \
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
    )
}

/// The study: per load and flush timeout, latency quantiles and the capacity at the
/// packing reached.
pub fn study(quick: bool, progress: &mut Progress, grid: &mut Points) -> anyhow::Result<Section> {
    progress.step("C3: generating the loads");
    // generated once, by the first point this run computes (none in a merge)
    let mut generated: Option<[Load; 2]> = None;
    let mut with_loads = |f: &dyn Fn(&[Load; 2]) -> anyhow::Result<[Outcome; 2]>| {
        if generated.is_none() {
            generated = Some(loads(quick)?);
        }
        f(generated.as_ref().expect("generated"))
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
        "packets lost",
    ]);
    let mut curves: Vec<Vec<[f64; 4]>> = vec![Vec::new(); LOAD_NAMES.len()];
    for t_us in timeouts_us(quick) {
        progress.step(&format!("C3: flush timeout {t_us} us"));
        let ticks = flush_timeout_ticks(t_us);
        let outcomes = grid.run(format!("C3/flush timeout {t_us} us"), || {
            with_loads(&|loads| {
                let [light, heavy] = loads.each_ref().map(|load| -> anyhow::Result<Outcome> {
                    let b = run_box(&load.spec, ticks)?;
                    let cap = cells_250(capacity_records_per_s(b.records_per_datagram()));
                    Ok(Outcome::new(load, &b, cap))
                });
                Ok([light?, heavy?])
            })
        })?;
        for (l, o) in outcomes.iter().enumerate() {
            outcome_row(
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
            Ok(loads.each_ref().map(|load| {
                let cap = cells_250(original_capacity_records_per_s());
                Outcome::new(load, &original_box(&load.ready_ns()), cap)
            }))
        })
    })?;
    let mut original = Vec::new();
    for (l, o) in originals.iter().enumerate() {
        outcome_row(
            &mut table,
            LOAD_NAMES[l],
            "original (one packet per datagram)",
            "-",
            o,
        );
        original.push(o.latency_us);
    }
    let chart = latency_capacity_chart(&curves, &original);
    let text = study_text(quick);
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
    use skinbox_cosim::line::Jitter;
    use skinbox_cosim::scene::PORTS_READY_NS;
    use skinbox_cosim::sim::SentPacket;
    use skinbox_cosim::traffic::random_data_packets;
    use skinbox_protocol::datagram::{HEADER_LEN, MAX_RECORDS};
    use skinbox_protocol::link::{
        ETHERNET_HEADER_LEN, FCS_LEN, IPV4_HEADER_LEN, PREAMBLE_LEN, UDP_HEADER_LEN,
    };
    use skinbox_protocol::record::RECORD_LEN;

    const BIT_NS: f64 = 250.0;

    /// Frame bytes on GMII, preamble to FCS, of a records datagram of `records` records.
    fn frame_bytes(records: usize) -> f64 {
        (PREAMBLE_LEN
            + ETHERNET_HEADER_LEN
            + IPV4_HEADER_LEN
            + UDP_HEADER_LEN
            + HEADER_LEN
            + RECORD_LEN * records
            + FCS_LEN) as f64
    }

    /// `per_port` distinct data packets on each of the 8 ports of the default box, back to
    /// back from `first_ns` after the ports are ready.
    fn spec(per_port: usize, first_ns: f64) -> SimSpec {
        let packets = random_data_packets(8 * per_port);
        let packet_ns = UART_BITS_PER_PACKET as f64 * BIT_NS;
        let ports = (0..8)
            .map(|port| {
                (0..per_port)
                    .map(|k| SentPacket {
                        bytes: packets[port * per_port + k],
                        start_ns: PORTS_READY_NS as f64 + first_ns + k as f64 * packet_ns,
                        bit_ns: BIT_NS,
                    })
                    .collect()
            })
            .collect();
        let end_ns = PORTS_READY_NS as f64 + first_ns + per_port as f64 * packet_ns;
        SimSpec {
            config: BoxConfig::default(),
            ports,
            duration_ns: (end_ns as u64 + 2_000_000).div_ceil(TICK_NS) * TICK_NS,
            pcap: None,
            vcd: None,
            jitter: Jitter::NONE,
            host_frames: vec![],
        }
    }

    #[test]
    fn a_lone_record_waits_the_timeout_then_one_frame_time() {
        let mut one = spec(1, 1_000.0);
        for port in &mut one.ports[1..] {
            port.clear();
        }
        let timeout_ns = 100_000.0;
        let b = run_box(&one, flush_timeout_ticks(100.0)).unwrap();
        assert_eq!(
            (b.datagrams, b.records_per_frame.clone(), b.lost),
            (1, vec![1], 0)
        );
        // at least the timeout and the 104-byte frame, plus a few clocks of the pipeline
        // (receiver, store, framer): well under a microsecond
        let least = timeout_ns + frame_bytes(1) * NS_PER_BYTE;
        assert_eq!(frame_bytes(1), 104.0);
        let latency = b.latency_ns[0];
        assert!((least..least + 1_000.0).contains(&latency), "{latency}");
    }

    #[test]
    fn every_packet_comes_back_within_the_bounds_of_the_timeout_and_the_frame() {
        // 8 ports at the full 20,000 packets/s each for 5 ms: 800 records
        let load = spec(100, 0.0);
        let mut packing = Vec::new();
        for t_us in [1.0, 10.0, 100.0] {
            let b = run_box(&load, flush_timeout_ticks(t_us)).unwrap();
            assert_eq!(b.lost, 0, "{t_us} us");
            assert_eq!(b.latency_ns.len(), 800, "{t_us} us");
            assert_eq!(b.records_per_frame.iter().sum::<usize>(), 800);
            assert_eq!(b.records_per_frame.len(), b.datagrams);
            assert!(b
                .records_per_frame
                .iter()
                .all(|&n| (1..=MAX_RECORDS).contains(&n)));
            // never below one frame time; at most the timeout, a full frame ahead on the
            // wire, its own full frame and a microsecond of pipeline
            let floor = frame_bytes(1) * NS_PER_BYTE;
            let ceiling = t_us * 1000.0 + 2.0 * frame_bytes(MAX_RECORDS) * NS_PER_BYTE + 1_000.0;
            for &l in &b.latency_ns {
                assert!((floor..=ceiling).contains(&l), "{t_us} us: {l} ns");
            }
            packing.push(b.records_per_datagram());
        }
        // 160,000 records/s: a longer timeout packs more records into a datagram, up to
        // 1 + 160,000/s x 100 us = 17 in the steady state (the start may be later)
        assert!(
            packing[0] < packing[1] && packing[1] < packing[2],
            "{packing:?}"
        );
        assert!((12.0..=18.0).contains(&packing[2]), "{packing:?}");
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
