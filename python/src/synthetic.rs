//! Synthetic captures with their truth, for tests and benchmarks: the box's reference
//! model batching cells' packets into datagrams (`skinbox_cosim::synthetic`), written to a pcap.

use crate::errors::value_error;
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use skinbox_cosim::synthetic::{self, SyntheticConfig};
use skinbox_host::pcap::PcapFrameWriter;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{CellFraming, CellRepr, Channel, DatagramRepr, TICK_NS};
use std::net::SocketAddr;
use std::time::Duration;

/// Receive time of the datagrams of a synthetic capture: the latest stamp in it plus a
/// delivery delay, on a host clock that started at this many seconds after the epoch.
const HOST_EPOCH_S: u64 = 1_764_000_000;
const DELIVERY_NS: u64 = 30_000;

fn receive_time(d: &DatagramRepr) -> Duration {
    let latest = match &d.body {
        DatagramBody::Records(records) => records
            .iter()
            .map(|r| r.tick(d.base_tick))
            .max()
            .unwrap_or(d.base_tick),
        DatagramBody::Status(_) => d.base_tick,
    };
    Duration::from_secs(HOST_EPOCH_S) + Duration::from_nanos(latest * TICK_NS + DELIVERY_NS)
}

/// Writes a pcap of `boxes` synthetic boxes (box ids `box_id`, `box_id + 1`, ..., or all
/// `box_id` with `shared_box_id`; each from its own address 10.0.0.2, 10.0.0.3, ... and
/// seed, datagrams interleaved) and returns the truth of every record written, in order, as
/// columns: box_id, source_ip (the IPv4 address as an integer), source_port, datagram
/// sequence, tick, port, cell_id, kind (0 data, 1 event), mask, event_sequence (-1 for
/// data) and raw (the nine raw channel values, 0 where absent). Every `drop_every`-th
/// records datagram of each box (0: none) is left out, with its records.
#[pyfunction]
#[pyo3(signature = (path, cells=64, ports=8, sample_rate_hz=125.0, samples_per_cell=50, event_every=2, seed=1, box_id=1, boxes=1, first_sequence=0, walk_scale=1, flush_timeout_ticks=12_500, drop_every=0, shared_box_id=false))]
#[allow(clippy::too_many_arguments)]
pub fn write_synthetic_capture<'py>(
    py: Python<'py>,
    path: std::path::PathBuf,
    cells: u16,
    ports: u8,
    sample_rate_hz: f64,
    samples_per_cell: u32,
    event_every: u16,
    seed: u64,
    box_id: u16,
    boxes: u16,
    first_sequence: u32,
    walk_scale: i32,
    flush_timeout_ticks: u64,
    drop_every: u64,
    shared_box_id: bool,
) -> PyResult<Bound<'py, PyDict>> {
    if boxes == 0 || boxes > 200 {
        return Err(value_error("boxes: 1 to 200"));
    }
    let mut captures = Vec::new();
    for k in 0..boxes {
        let config = SyntheticConfig {
            cells,
            ports,
            sample_rate_hz,
            samples_per_cell,
            event_every,
            seed: seed + u64::from(k),
            box_id: if shared_box_id {
                box_id
            } else {
                box_id
                    .checked_add(k)
                    .ok_or_else(|| value_error("box_id + boxes - 1 must fit 16 bits"))?
            },
            first_sequence,
            walk_scale,
            flush_timeout_ticks,
            ..SyntheticConfig::default()
        };
        let capture = py
            .detach(|| synthetic::generate(&config))
            .map_err(|e| value_error(e.to_string()))?;
        let source = SocketAddr::from(([10, 0, 0, 2 + k as u8], 54091));
        captures.push((config.box_id, source, capture));
    }
    let host = SocketAddr::from(([10, 0, 0, 1], 54091));
    let file = std::fs::File::create(&path)
        .map_err(|e| value_error(format!("{}: {e}", path.display())))?;
    let mut writer = PcapFrameWriter::new(std::io::BufWriter::new(file))
        .map_err(|e| value_error(e.to_string()))?;
    let mut truth_box = Vec::new();
    let mut truth_ip = Vec::new();
    let mut truth_source_port = Vec::new();
    let mut truth_sequence = Vec::new();
    let mut truth_tick = Vec::new();
    let mut truth_port = Vec::new();
    let mut truth_cell = Vec::new();
    let mut truth_kind = Vec::new();
    let mut truth_mask = Vec::new();
    let mut truth_event_sequence = Vec::new();
    let mut truth_raw: Vec<Vec<i32>> = Vec::new();
    let longest = captures
        .iter()
        .map(|c| c.2.datagrams.len())
        .max()
        .unwrap_or(0);
    let mut records_seen = vec![0u64; captures.len()];
    for i in 0..longest {
        for (b, (id, source, capture)) in captures.iter().enumerate() {
            let Some(d) = capture.datagrams.get(i) else {
                continue;
            };
            if let DatagramBody::Records(records) = &d.body {
                records_seen[b] += 1;
                if drop_every > 0 && records_seen[b] % drop_every == 0 {
                    continue;
                }
                for r in records {
                    let cell = CellRepr::parse(&r.cell_packet, &CellFraming::DEFAULT)
                        .map_err(|e| value_error(format!("generated packet: {e}")))?;
                    let mut raw = vec![0i32; Channel::COUNT];
                    let (kind, mask, sequence) = match &cell {
                        CellRepr::Data(data) => {
                            for c in Channel::ALL {
                                raw[c.index()] = data.raw(c);
                            }
                            (0u8, 0x1FFu16, -1i32)
                        }
                        CellRepr::Event(e) => {
                            for (c, v) in e.events() {
                                raw[c.index()] = v;
                            }
                            (1, e.channels.bits(), i32::from(e.sequence))
                        }
                    };
                    truth_box.push(*id);
                    let (ip, source_port) = skinbox_host::rows::source_fields(Some(*source));
                    truth_ip.push(ip);
                    truth_source_port.push(source_port);
                    truth_sequence.push(d.sequence);
                    truth_tick.push(r.tick(d.base_tick));
                    truth_port.push(r.port);
                    truth_cell.push(cell.cell_id());
                    truth_kind.push(kind);
                    truth_mask.push(mask);
                    truth_event_sequence.push(sequence);
                    truth_raw.push(raw);
                }
            }
            writer
                .write_udp(receive_time(d), *source, host, &d.to_bytes())
                .map_err(|e| value_error(e.to_string()))?;
        }
    }
    use std::io::Write;
    writer
        .finish()
        .and_then(|mut w| {
            w.flush()
                .map_err(|e| skinbox_host::pcap::PcapError::Write(e.to_string()))
        })
        .map_err(|e| value_error(e.to_string()))?;
    let truth = PyDict::new(py);
    truth.set_item("box_id", PyArray1::from_vec(py, truth_box))?;
    truth.set_item("source_ip", PyArray1::from_vec(py, truth_ip))?;
    truth.set_item("source_port", PyArray1::from_vec(py, truth_source_port))?;
    truth.set_item("datagram_sequence", PyArray1::from_vec(py, truth_sequence))?;
    truth.set_item("tick", PyArray1::from_vec(py, truth_tick))?;
    truth.set_item("port", PyArray1::from_vec(py, truth_port))?;
    truth.set_item("cell_id", PyArray1::from_vec(py, truth_cell))?;
    truth.set_item("kind", PyArray1::from_vec(py, truth_kind))?;
    truth.set_item("mask", PyArray1::from_vec(py, truth_mask))?;
    truth.set_item(
        "event_sequence",
        PyArray1::from_vec(py, truth_event_sequence),
    )?;
    truth.set_item(
        "raw",
        numpy::PyArray2::from_vec2(py, &truth_raw).map_err(|e| value_error(e.to_string()))?,
    )?;
    Ok(truth)
}

/// Writes the capture `skinbox bench decode` decodes (2,000 cells on 32 ports, half in
/// data mode, half in event mode, nearly every datagram full) with at least `packets` cell
/// packets to a pcap; returns the cell packets written.
#[pyfunction]
#[pyo3(signature = (path, packets=1_000_000, seed=1))]
pub fn write_bench_capture(
    py: Python<'_>,
    path: std::path::PathBuf,
    packets: usize,
    seed: u64,
) -> PyResult<u64> {
    py.detach(|| {
        let capture = synthetic::bench_capture(packets, seed).map_err(|e| e.to_string())?;
        let file = std::fs::File::create(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let mut writer =
            PcapFrameWriter::new(std::io::BufWriter::new(file)).map_err(|e| e.to_string())?;
        let source = SocketAddr::from(([10, 0, 0, 2], 54091));
        let host = SocketAddr::from(([10, 0, 0, 1], 54091));
        for (i, payload) in capture.payloads().iter().enumerate() {
            // 12.2 us apart: a full link's datagram rate
            let at = Duration::from_secs(HOST_EPOCH_S) + Duration::from_nanos(i as u64 * 12_200);
            writer
                .write_udp(at, source, host, payload)
                .map_err(|e| e.to_string())?;
        }
        use std::io::Write;
        writer
            .finish()
            .map_err(|e| e.to_string())?
            .flush()
            .map_err(|e| e.to_string())?;
        Ok::<u64, String>(capture.data_packets + capture.event_packets)
    })
    .map_err(value_error)
}

/// Sends the UDP payloads of the pcap at `path` to `to` from 127.0.0.1 at
/// `datagrams_per_second` on average, `burst` back to back (as `skinbox bench live`
/// paces them), without the GIL; returns what the sender did as JSON text.
#[pyfunction]
#[pyo3(signature = (path, to, datagrams_per_second, burst=32))]
pub fn replay_capture(
    py: Python<'_>,
    path: std::path::PathBuf,
    to: &str,
    datagrams_per_second: f64,
    burst: usize,
) -> PyResult<String> {
    use skinbox_host::replay::{replay, Pacing};
    let to: SocketAddr = to
        .parse()
        .map_err(|e| value_error(format!("to {to}: {e}")))?;
    py.detach(|| {
        let bytes = skinbox_host::pcap::read_file(&path).map_err(|e| e.to_string())?;
        let (payloads, _) =
            skinbox_host::pcap::udp_payloads(&bytes, None).map_err(|e| e.to_string())?;
        let socket = std::net::UdpSocket::bind(SocketAddr::from(([127, 0, 0, 1], 0)))
            .map_err(|e| e.to_string())?;
        let stop = std::sync::atomic::AtomicBool::new(false);
        let summary = replay(
            &socket,
            to,
            payloads
                .iter()
                .map(|p| (Duration::ZERO, p.payload.as_slice())),
            Pacing::Bursts {
                datagrams_per_second,
                burst: burst.max(1),
            },
            &stop,
        );
        serde_json::to_string(&summary).map_err(|e| e.to_string())
    })
    .map_err(value_error)
}
