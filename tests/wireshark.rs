//! The Wireshark dissector (`skinbox wireshark`) in tshark: on the reference box's pcaps,
//! on synthetic captures of data and event packets, on datagrams written by hand from
//! docs/wire-format.md, and on malformed ones. Its fields must equal `skinbox decode`'s
//! record for record, and its expert infos must sit exactly where gaps and resets were put.
//! tshark comes from Debian (scripts/test installs it); the ADwin heuristic stays on.

use serde_json::Value;
use skinbox_cosim::synthetic::{self, SyntheticConfig};
use skinbox_host::pcap::PcapFrameWriter;
use skinbox_protocol::{Channel, DatagramRepr};
use std::collections::BTreeMap;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

mod support;

use support::{plugin, skinbox, temp_dir, tshark};

/// The skinbox layer of every frame (tshark -T json), in frame order.
fn layers(plugin: &Path, pcap: &Path) -> Vec<Value> {
    let text = tshark(plugin, pcap, &["-T", "json", "--no-duplicate-keys"]);
    let frames: Vec<Value> = serde_json::from_str(&text).unwrap();
    frames
        .iter()
        .map(|f| {
            let layers = &f["_source"]["layers"];
            let protocols = layers["frame"]["frame.protocols"].as_str().unwrap();
            assert!(
                protocols.ends_with(":udp:skinbox"),
                "frame {}: {protocols}",
                layers["frame"]["frame.number"]
            );
            layers["skinbox"].clone()
        })
        .collect()
}

/// One element or an array of them (tshark merges repeated keys into arrays).
fn many(v: &Value) -> Vec<&Value> {
    match v {
        Value::Array(items) => items.iter().collect(),
        Value::Null => vec![],
        one => vec![one],
    }
}

fn num(v: &Value) -> u64 {
    let s = v
        .as_str()
        .unwrap_or_else(|| panic!("not a field value: {v}"));
    match s.strip_prefix("0x") {
        Some(hex) => u64::from_str_radix(hex, 16).unwrap(),
        None => s.parse().unwrap(),
    }
}

fn float(v: &Value) -> f64 {
    v.as_str().unwrap().parse().unwrap()
}

/// A record as both sides report it.
#[derive(Debug, Clone, PartialEq)]
struct Row {
    box_id: u64,
    datagram_sequence: u64,
    port: u64,
    flags: u64,
    tick: u64,
    cell_id: u64,
    kind: &'static str,
    event_sequence: Option<u64>,
    second_part: bool,
    missing_before: u64,
    values: BTreeMap<String, f64>,
}

fn dissected_rows(layers: &[Value]) -> Vec<Row> {
    let mut rows = vec![];
    for l in layers {
        for r in many(&l["skinbox.record"]) {
            let cell = &r["skinbox.record.cell_packet_tree"];
            let kind = match num(&cell["skinbox.cell.header"]) {
                0xA1 => "data",
                0xA2 => "event",
                other => panic!("header {other:#x}"),
            };
            let values = Channel::ALL
                .iter()
                .filter(|c| !cell[format!("skinbox.{}", c.name())].is_null())
                .map(|c| {
                    (
                        c.name().to_string(),
                        float(&cell[format!("skinbox.{}", c.name())]),
                    )
                })
                .collect();
            let event = kind == "event";
            rows.push(Row {
                box_id: num(&l["skinbox.box_id"]),
                datagram_sequence: num(&l["skinbox.sequence"]),
                port: num(&r["skinbox.record.port"]),
                flags: num(&r["skinbox.record.flags"]),
                tick: num(&r["skinbox.record.tick"]),
                cell_id: num(&cell["skinbox.cell.cell_id"]),
                kind,
                event_sequence: event.then(|| num(&cell["skinbox.event.sequence"])),
                second_part: event && num(&cell["skinbox.event.second_part"]) == 1,
                missing_before: if event {
                    num(&cell["skinbox.event.missing_before"])
                } else {
                    0
                },
                values,
            });
        }
    }
    rows
}

/// `skinbox decode FILE --jsonl`, one row per record.
fn decoded_rows(pcap: &Path) -> Vec<Row> {
    let out = skinbox()
        .arg("decode")
        .arg(pcap)
        .arg("--jsonl")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|line| {
            let v: Value = serde_json::from_str(line).unwrap();
            let kind = match v["kind"].as_str().unwrap() {
                "data" => "data",
                "event" => "event",
                other => panic!("kind {other}"),
            };
            Row {
                box_id: v["box_id"].as_u64().unwrap(),
                datagram_sequence: v["datagram_sequence"].as_u64().unwrap(),
                port: v["port"].as_u64().unwrap(),
                flags: v["flags"].as_u64().unwrap(),
                tick: v["tick"].as_u64().unwrap(),
                cell_id: v["cell_id"].as_u64().unwrap(),
                kind,
                event_sequence: v["event_sequence"].as_u64(),
                second_part: v["second_part"].as_bool().unwrap(),
                missing_before: v["event_packets_missing_before"].as_u64().unwrap(),
                values: v["values"]
                    .as_object()
                    .unwrap()
                    .iter()
                    .map(|(k, x)| (k.clone(), x.as_f64().unwrap()))
                    .collect(),
            }
        })
        .collect()
}

fn assert_rows_equal(dissected: &[Row], decoded: &[Row]) {
    assert_eq!(dissected.len(), decoded.len(), "record counts");
    for (i, (a, b)) in dissected.iter().zip(decoded).enumerate() {
        let mut a = a.clone();
        // tshark prints doubles with 17 significant digits at most: equal within 1e-12
        for (name, v) in &b.values {
            let got = a.values.get(name).copied();
            assert!(
                got.is_some_and(|g| (g - v).abs() <= 1e-12 * v.abs().max(1.0)),
                "record {i}: {name} {got:?} against {v}"
            );
        }
        assert_eq!(
            a.values.keys().collect::<Vec<_>>(),
            b.values.keys().collect::<Vec<_>>(),
            "record {i}: channels"
        );
        a.values = b.values.clone();
        assert_eq!(&a, b, "record {i}");
    }
}

fn cell_id_of(record: &skinbox_protocol::RecordRepr) -> u16 {
    skinbox_protocol::CellRepr::parse(&record.cell_packet, &Default::default())
        .unwrap()
        .cell_id()
}

fn write_pcap(path: &Path, payloads: &[Vec<u8>], src: SocketAddr, dst: SocketAddr) {
    let file = std::fs::File::create(path).unwrap();
    let mut w = PcapFrameWriter::new(std::io::BufWriter::new(file)).unwrap();
    for (i, p) in payloads.iter().enumerate() {
        w.write_udp(Duration::from_micros(100 * i as u64), src, dst, p)
            .unwrap();
    }
    w.finish().unwrap();
}

fn box_addresses() -> (SocketAddr, SocketAddr) {
    (
        "192.0.2.10:54091".parse().unwrap(),
        "192.0.2.1:54091".parse().unwrap(),
    )
}

/// Frame numbers (1-based) that carry an expert info, from a display filter.
fn frames_with(plugin: &Path, pcap: &Path, filter: &str, field: &str) -> Vec<(u64, String)> {
    // (tshark leaves the first of two equal -e fields empty: ask for frame.number once)
    let mut args = vec!["-Y", filter, "-T", "fields", "-e", "frame.number"];
    if field != "frame.number" {
        args.extend(["-e", field]);
    }
    tshark(plugin, pcap, &args)
        .lines()
        .map(|l| {
            let (n, v) = l.split_once('\t').unwrap_or((l, ""));
            (n.parse().unwrap(), v.to_string())
        })
        .collect()
}

/// Frame numbers that match a display filter.
fn frame_numbers(plugin: &Path, pcap: &Path, filter: &str) -> Vec<u64> {
    frames_with(plugin, pcap, filter, "frame.number")
        .into_iter()
        .map(|(n, _)| n)
        .collect()
}

#[test]
fn reference_box_pcap_dissects_like_the_host_decodes() {
    let dir = temp_dir("reference");
    let plugin = plugin(&dir);
    let pcap = dir.join("scene.pcap");
    let out = skinbox()
        .args([
            "sim",
            "--fidelity",
            "reference",
            "--duration-ms",
            "40",
            "--pcap",
        ])
        .arg(&pcap)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let layers = layers(&plugin, &pcap);
    let dissected = dissected_rows(&layers);
    assert!(dissected.len() > 100, "{} records", dissected.len());
    assert_rows_equal(&dissected, &decoded_rows(&pcap));
    // a clean capture: no expert info of any kind
    assert_eq!(
        frames_with(&plugin, &pcap, "_ws.expert", "_ws.expert.message"),
        vec![]
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn synthetic_data_and_event_capture_on_another_port_is_found_by_the_heuristic() {
    let dir = temp_dir("synthetic");
    let plugin = plugin(&dir);
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 40,
        samples_per_cell: 30,
        status_period_ticks: 2_500_000,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let pcap = dir.join("synthetic.pcap");
    // not the box's port: only the heuristic (on the magic and the length) can claim these
    write_pcap(
        &pcap,
        &capture.payloads(),
        "127.0.0.1:5000".parse().unwrap(),
        "127.0.0.1:6000".parse().unwrap(),
    );
    let layers = layers(&plugin, &pcap);
    assert_eq!(layers.len(), capture.datagrams.len());
    let dissected = dissected_rows(&layers);
    assert_eq!(dissected.len(), capture.truth.len());
    assert!(dissected.iter().any(|r| r.kind == "data"));
    assert!(dissected.iter().any(|r| r.kind == "event"));
    for (row, truth) in dissected.iter().zip(&capture.truth) {
        assert_eq!(row.tick, truth.tick);
        assert_eq!(row.port, u64::from(truth.record.port));
        assert_eq!(row.cell_id, u64::from(cell_id_of(&truth.record)));
    }
    assert_rows_equal(&dissected, &decoded_rows(&pcap));
    // status datagrams: every counter named, ports numbered from first_port
    let status: Vec<&Value> = layers
        .iter()
        .filter(|l| num(&l["skinbox.kind"]) == 2)
        .collect();
    assert!(!status.is_empty());
    for s in status {
        let blocks = many(&s["skinbox.port_counters"]);
        assert_eq!(blocks.len() as u64, num(&s["skinbox.entry_count"]));
        for (i, b) in blocks.iter().enumerate() {
            assert_eq!(num(&b["skinbox.port_counters.port"]), i as u64);
            for c in skinbox_protocol::PortCounter::ALL {
                assert!(
                    !b[format!("skinbox.port_counters.{}", c.name())].is_null(),
                    "{}",
                    c.name()
                );
            }
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// Cell 0x0123: accel (3, -2, 256), force (1, 1024, 0), proximity 450, temperature 61, 0.
const DATA: [u8; 20] = [
    0xA1, 0x01, 0x23, 0x00, 0x03, 0xFF, 0xFE, 0x01, 0x00, 0x00, 0x01, 0x04, 0x00, 0x00, 0x00, 0x01,
    0xC2, 0x3D, 0x00, 0x55,
];
/// Cell 0x3FFE: accel x -6, accel z 262, force 1 3, proximity 2048, temperature 1 62,
/// temperature 2 1; sequence 0xFFFF.
const EVENT_6: [u8; 20] = [
    0xA2, 0x3F, 0xFE, 0x01, 0xCD, 0xFF, 0xFA, 0x01, 0x06, 0x00, 0x03, 0x08, 0x00, 0x00, 0x3E, 0x00,
    0x01, 0xFF, 0xFF, 0x55,
];
/// Cell 0x3FFE, the second packet of a sample: force 2 = 9, sequence 0 (0xFFFF + 1).
const EVENT_SECOND: [u8; 20] = [
    0xA2, 0x3F, 0xFE, 0x80, 0x10, 0x00, 0x09, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x00, 0x55,
];

/// Datagrams written by hand from docs/wire-format.md (not with the protocol crate).
fn hand_written() -> Vec<Vec<u8>> {
    let mut records = vec![
        b'S', b'K', 1, 1, // magic, version 1, kind records
        0x01, 0x02, 8, 0x01, // box 0x0102, 8 ports, flushed by timeout
        0x01, 0x02, 0x03, 0x04, // sequence 0x01020304
        0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x00, // base tick 2^32
        0x00, 0x03, 0x00, 0x00, // 3 records, reserved
        3, 0x00, 0x00, 0x00, 0x00, 0x00, // port 3, no flags, offset 0
    ];
    records.extend_from_slice(&DATA);
    records.extend_from_slice(&[7, 0x01, 0xFF, 0xFF, 0xFF, 0xFB]); // port 7, loss before, -5
    records.extend_from_slice(&EVENT_6);
    records.extend_from_slice(&[7, 0x00, 0x00, 0x00, 0x18, 0x6A]); // port 7, +6250
    records.extend_from_slice(&EVENT_SECOND);
    let mut status = vec![
        b'S', b'K', 1, 2, // magic, version 1, kind status
        0x01, 0x02, 8, 0x00, // box 0x0102, 8 ports
        0x01, 0x02, 0x03, 0x05, // sequence: the next one
        0x00, 0x00, 0x00, 0x01, 0x07, 0x73, 0x59, 0x40, // tick 2^32 + 125,000,000
        0x00, 0x02, 0x00, 0x00, // 2 port blocks, reserved
        0xDE, 0xAD, 0xBE, 0xEF, // boot id
        0x00, 0x00, 0x00, 0x0A, // 10 records datagrams sent
        0x00, 0x00, 0x02, 0x26, // 550 records sent
        6, 0, 0, 0, // first port 6, reserved
    ];
    for port in 0..2u32 {
        for counter in 0..8u32 {
            status.extend_from_slice(&(1000 * port + counter).to_be_bytes());
        }
    }
    vec![records, status]
}

#[test]
fn hand_written_datagrams_show_every_field() {
    let dir = temp_dir("golden");
    let plugin = plugin(&dir);
    let pcap = dir.join("golden.pcap");
    let (src, dst) = box_addresses();
    write_pcap(&pcap, &hand_written(), src, dst);
    let layers = layers(&plugin, &pcap);
    let rec = &layers[0];
    assert_eq!(rec["skinbox.magic"], "SK");
    assert_eq!(num(&rec["skinbox.box_id"]), 0x0102);
    assert_eq!(num(&rec["skinbox.port_count"]), 8);
    assert_eq!(
        num(&rec["skinbox.flags_tree"]["skinbox.flags.flush_timeout"]),
        1
    );
    assert_eq!(num(&rec["skinbox.sequence"]), 0x0102_0304);
    assert_eq!(num(&rec["skinbox.base_tick"]), 1 << 32);
    let records = many(&rec["skinbox.record"]);
    assert_eq!(records.len(), 3);

    let data = &records[0]["skinbox.record.cell_packet_tree"];
    assert_eq!(num(&records[0]["skinbox.record.port"]), 3);
    assert_eq!(num(&records[0]["skinbox.record.tick"]), 1 << 32);
    assert_eq!(num(&data["skinbox.cell.cell_id"]), 0x0123);
    let raw = [3.0, -2.0, 256.0, 1.0, 1024.0, 0.0, 450.0, 61.0, 0.0];
    let units = [
        3.0 / 256.0,
        -2.0 / 256.0,
        1.0,
        1.0 / 1024.0,
        1.0,
        0.0,
        450.0 / 65536.0,
        30.5,
        0.0,
    ];
    for (i, c) in Channel::ALL.iter().enumerate() {
        assert_eq!(float(&data[format!("skinbox.{}.raw", c.name())]), raw[i]);
        assert_eq!(float(&data[format!("skinbox.{}", c.name())]), units[i]);
    }

    let event = &records[1]["skinbox.record.cell_packet_tree"];
    assert_eq!(num(&records[1]["skinbox.record.port"]), 7);
    assert_eq!(
        num(&records[1]["skinbox.record.flags_tree"]["skinbox.record.flags.loss_before"]),
        1
    );
    assert_eq!(records[1]["skinbox.record.tick_offset"], "-5");
    assert_eq!(num(&records[1]["skinbox.record.tick"]), (1 << 32) - 5);
    assert_eq!(num(&event["skinbox.cell.cell_id"]), 0x3FFE);
    assert_eq!(num(&event["skinbox.event.sequence"]), 0xFFFF);
    let mask = &event["skinbox.event.mask_tree"];
    for (name, set) in [
        ("accel_x", 1),
        ("accel_y", 0),
        ("accel_z", 1),
        ("force_1", 1),
        ("proximity", 1),
        ("temperature_1", 1),
        ("temperature_2", 1),
        ("second_part", 0),
    ] {
        assert_eq!(
            num(&mask[format!("skinbox.event.mask.{name}")]),
            set,
            "{name}"
        );
    }
    for (name, raw) in [
        ("accel_x", -6.0),
        ("accel_z", 262.0),
        ("force_1", 3.0),
        ("proximity", 2048.0),
        ("temperature_1", 62.0),
        ("temperature_2", 1.0),
    ] {
        assert_eq!(float(&event[format!("skinbox.{name}.raw")]), raw, "{name}");
    }
    assert!(event["skinbox.accel_y"].is_null());

    let second = &records[2]["skinbox.record.cell_packet_tree"];
    assert_eq!(num(&records[2]["skinbox.record.tick"]), (1 << 32) + 6250);
    assert_eq!(num(&second["skinbox.event.second_part"]), 1);
    assert_eq!(num(&second["skinbox.event.sequence"]), 0);
    assert_eq!(num(&second["skinbox.event.missing_before"]), 0);
    assert_eq!(float(&second["skinbox.force_2"]), 9.0 / 1024.0);

    let status = &layers[1];
    assert_eq!(num(&status["skinbox.kind"]), 2);
    let fixed = &status["skinbox.status"];
    assert_eq!(num(&fixed["skinbox.status.boot_id"]), 0xDEAD_BEEF);
    assert_eq!(num(&fixed["skinbox.status.datagrams_sent"]), 10);
    assert_eq!(num(&fixed["skinbox.status.records_sent"]), 550);
    let blocks = many(&status["skinbox.port_counters"]);
    assert_eq!(blocks.len(), 2);
    for (i, b) in blocks.iter().enumerate() {
        assert_eq!(num(&b["skinbox.port_counters.port"]), 6 + i as u64);
        for (k, name) in [
            "packets_good",
            "dropped_overflow",
            "rejected_end_byte",
            "rejected_framing",
            "rejected_truncated",
            "garbage_bytes",
            "framing_errors",
            "resyncs",
        ]
        .iter()
        .enumerate()
        {
            assert_eq!(
                num(&b[format!("skinbox.port_counters.{name}")]),
                1000 * i as u64 + k as u64
            );
        }
    }
    assert_rows_equal(&dissected_rows(&layers), &decoded_rows(&pcap));
    let info = tshark(&plugin, &pcap, &["-T", "fields", "-e", "_ws.col.Info"]);
    assert_eq!(
        info.lines().collect::<Vec<_>>(),
        [
            "box 258: 3 records, ports 3-7, seq 16909060, flush timeout",
            "box 258: status, seq 16909061, ports 6-7, boot 0xdeadbeef",
        ]
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn malformed_datagrams_are_flagged_not_misread() {
    let dir = temp_dir("malformed");
    let plugin = plugin(&dir);
    let good = hand_written().remove(0);
    let mut cases: Vec<(Vec<u8>, &str)> = vec![];
    cases.push((good[..20].to_vec(), "skinbox.expert.malformed"));
    let mut v2 = good.clone();
    v2[2] = 2;
    cases.push((v2, "skinbox.expert.unknown_version"));
    let mut kind = good.clone();
    kind[3] = 9;
    cases.push((kind, "skinbox.expert.malformed"));
    cases.push((good[..good.len() - 1].to_vec(), "skinbox.expert.malformed"));
    let mut end = good.clone();
    end[24 + 26 - 1] = 0x54;
    cases.push((end, "skinbox.expert.bad_end_byte"));
    let mut header = good.clone();
    header[24 + 6] = 0xA3;
    cases.push((header, "skinbox.expert.malformed"));
    let mut port = good.clone();
    port[24] = 8;
    cases.push((port, "skinbox.expert.malformed"));
    let mut reserved = good.clone();
    reserved[24 + 26 + 6 + 3] |= 0x02; // mask bit 9
    cases.push((reserved, "skinbox.expert.malformed"));
    // a good datagram after them all, numbered on from the first
    let mut after = good.clone();
    after[11] = 0x05;
    let payloads: Vec<Vec<u8>> = cases
        .iter()
        .map(|(p, _)| p.clone())
        .chain([after])
        .collect();
    let pcap = dir.join("malformed.pcap");
    let (src, dst) = box_addresses();
    write_pcap(&pcap, &payloads, src, dst);
    let text = tshark(
        &plugin,
        &pcap,
        &[
            "-T",
            "fields",
            "-e",
            "frame.number",
            "-e",
            "_ws.expert",
            "-E",
            "occurrence=a",
        ],
    );
    assert_eq!(text.lines().count(), payloads.len());
    for (i, (_, expert)) in cases.iter().enumerate() {
        let frame = (i + 1).to_string();
        let found = frame_numbers(&plugin, &pcap, expert);
        assert!(
            found.iter().any(|n| n.to_string() == frame),
            "case {i}: {expert} not on frame {frame}: {found:?}"
        );
    }
    // only the malformed frames carry malformed-group expert infos
    let flagged = frame_numbers(
        &plugin,
        &pcap,
        "skinbox.expert.malformed || skinbox.expert.unknown_version || skinbox.expert.bad_end_byte",
    );
    assert_eq!(flagged, (1..=cases.len() as u64).collect::<Vec<_>>());
    std::fs::remove_dir_all(&dir).ok();
}

/// Which frames open a datagram gap (with its size) and which records open an event gap,
/// when some datagrams of a synthetic capture are taken out: computed from the capture's
/// truth, not from any sequence logic.
#[test]
fn expert_infos_mark_exactly_the_injected_gaps() {
    let dir = temp_dir("gaps");
    let plugin = plugin(&dir);
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 40,
        samples_per_cell: 200,
        event_every: 1,
        status_period_ticks: 2_500_000,
        first_sequence: u32::MAX - 20,
        ..SyntheticConfig::default()
    })
    .unwrap();
    // around the wrap of the numbering (at datagram 21), and from the middle on, where
    // every event cell has sent before
    assert!(capture.datagrams.len() > 200);
    let middle = capture.datagrams.len() / 2;
    let removed = [
        3usize,
        10,
        11,
        12,
        20,
        21,
        40,
        middle,
        middle + 7,
        middle + 8,
        middle + 9,
    ];
    let kept: Vec<&DatagramRepr> = capture
        .datagrams
        .iter()
        .enumerate()
        .filter(|(i, _)| !removed.contains(i))
        .map(|(_, d)| d)
        .collect();
    let payloads: Vec<Vec<u8>> = kept.iter().map(|d| d.to_bytes()).collect();
    let pcap = dir.join("gaps.pcap");
    let (src, dst) = box_addresses();
    write_pcap(&pcap, &payloads, src, dst);

    // datagram gaps: the frame after each run of removed datagrams, with the run's length
    let mut expected_gaps = vec![];
    let mut run = 0;
    let mut frame = 0u64;
    for i in 0..capture.datagrams.len() {
        if removed.contains(&i) {
            run += 1;
            continue;
        }
        frame += 1;
        if run > 0 {
            expected_gaps.push((frame, run.to_string()));
        }
        run = 0;
    }
    let gaps = frames_with(
        &plugin,
        &pcap,
        "skinbox.expert.sequence_gap",
        "skinbox.missing_before",
    );
    assert_eq!(gaps, expected_gaps);

    // event gaps: a kept event record whose cell lost packets in removed datagrams since
    // its previous kept record
    let removed_sequences: Vec<u32> = removed
        .iter()
        .map(|&i| capture.datagrams[i].sequence)
        .collect();
    let mut lost_per_cell: BTreeMap<u16, u64> = BTreeMap::new();
    let mut expected_missing = vec![];
    for t in &capture.truth {
        let cell = cell_id_of(&t.record);
        if removed_sequences.contains(&t.datagram_sequence) {
            *lost_per_cell.entry(cell).or_default() += 1;
        } else {
            expected_missing.push(lost_per_cell.remove(&cell).unwrap_or(0));
        }
    }
    // a cell whose first packets were lost has no earlier packet to count from
    let layers = layers(&plugin, &pcap);
    let dissected = dissected_rows(&layers);
    let mut seen = std::collections::HashSet::new();
    for (row, expected) in dissected.iter().zip(&mut expected_missing) {
        if seen.insert(row.cell_id) {
            *expected = 0;
        }
    }
    let got: Vec<u64> = dissected.iter().map(|r| r.missing_before).collect();
    assert_eq!(got, expected_missing);
    assert!(got.iter().filter(|&&m| m > 0).count() >= 10);
    let event_gap_frames = frame_numbers(&plugin, &pcap, "skinbox.expert.event_gap");
    // ...and the expert sits on exactly the frames holding such a record
    let mut record = 0;
    let mut expected_frames = vec![];
    for (i, l) in layers.iter().enumerate() {
        let n = many(&l["skinbox.record"]).len();
        if expected_missing[record..record + n].iter().any(|&m| m > 0) {
            expected_frames.push(i as u64 + 1);
        }
        record += n;
    }
    assert_eq!(event_gap_frames, expected_frames);
    assert_rows_equal(&dissected, &decoded_rows(&pcap));
    // nothing else: no restart, reset, late or duplicate datagram
    assert_eq!(
        frame_numbers(
            &plugin,
            &pcap,
            "skinbox.expert.sequence_restart || skinbox.expert.box_reset || skinbox.expert.sequence_late || skinbox.expert.sequence_duplicate",
        ),
        Vec::<u64>::new()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn expert_infos_mark_a_box_reset_a_late_and_a_duplicate_datagram() {
    let dir = temp_dir("reset");
    let plugin = plugin(&dir);
    let before = synthetic::generate(&SyntheticConfig {
        cells: 20,
        samples_per_cell: 20,
        status_period_ticks: 2_500_000,
        first_sequence: 100_000,
        ..SyntheticConfig::default()
    })
    .unwrap();
    // the box restarts: a new boot id, the numbering from 0, ticks from near 0
    let after = synthetic::generate(&SyntheticConfig {
        cells: 20,
        samples_per_cell: 150,
        status_period_ticks: 2_500_000,
        first_sequence: 0,
        boot_id: 0x5eed_0002,
        start_tick: 1000,
        seed: 2,
        ..SyntheticConfig::default()
    })
    .unwrap();
    // then its clock alone restarts: numbering goes on, base ticks fall 1.2 s back (a box
    // whose status reports were lost); its boot id stays the same
    let last = after.datagrams.last().unwrap().sequence;
    let again = synthetic::generate(&SyntheticConfig {
        cells: 20,
        samples_per_cell: 5,
        status_period_ticks: 0,
        first_sequence: last.wrapping_add(1),
        boot_id: 0x5eed_0002,
        start_tick: 1000,
        seed: 3,
        ..SyntheticConfig::default()
    })
    .unwrap();
    // the box reports at reset; this one's reporter is late (an edit of the box's capture):
    // its first report goes after its first three records datagrams, the four numbered in
    // that order, so the numbering restarts before the new boot id arrives
    let mut after_datagrams = after.datagrams.clone();
    assert_eq!(
        after_datagrams[0].kind(),
        skinbox_protocol::DatagramKind::Status
    );
    after_datagrams[..4].rotate_left(1);
    for (n, d) in after_datagrams[..4].iter_mut().enumerate() {
        d.sequence = n as u32;
    }
    let mut payloads = before.payloads();
    // the third datagram arrives after the fourth, and the fifth twice
    payloads.swap(2, 3);
    payloads.insert(5, payloads[4].clone());
    let restart_frame = payloads.len() as u64 + 1;
    let first_status_after = after_datagrams
        .iter()
        .position(|d| d.kind() == skinbox_protocol::DatagramKind::Status)
        .unwrap() as u64
        + restart_frame;
    payloads.extend(after_datagrams.iter().map(|d| d.to_bytes()));
    let clock_restart_frame = payloads.len() as u64 + 1;
    payloads.extend(again.payloads());
    let pcap = dir.join("reset.pcap");
    let (src, dst) = box_addresses();
    write_pcap(&pcap, &payloads, src, dst);
    let frames = |filter: &str| frame_numbers(&plugin, &pcap, filter);
    assert_eq!(frames("skinbox.expert.sequence_late"), [4]);
    assert_eq!(frames("skinbox.expert.sequence_duplicate"), [6]);
    assert_eq!(
        frames("skinbox.expert.sequence_restart"),
        [restart_frame, clock_restart_frame]
    );
    assert_eq!(frames("skinbox.expert.box_reset"), [first_status_after]);
    // the late datagram closed the gap it opened: one gap expert, at the fourth datagram
    assert_eq!(frames("skinbox.expert.sequence_gap"), [3]);
    // the host decoder counts the same restarts and resets
    let decoded = skinbox_host::decode_pcap_file(&pcap, &Default::default()).unwrap();
    let report = serde_json::to_value(&decoded.report).unwrap();
    let losses = &report["losses"];
    assert_eq!(losses["sequence_restarts"].as_u64(), Some(2), "{losses}");
    assert_eq!(losses["box_resets"].as_u64(), Some(1), "{losses}");
    assert_eq!(losses["datagrams_duplicate"].as_u64(), Some(1), "{losses}");
    assert_eq!(losses["datagrams_reordered"].as_u64(), Some(1), "{losses}");
    assert_eq!(losses["datagrams_missing"].as_u64(), Some(0), "{losses}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn install_puts_the_plugin_where_tshark_loads_it() {
    let dir = temp_dir("install");
    let home = dir.join("home");
    std::fs::create_dir_all(&home).unwrap();
    let out = skinbox()
        .args(["wireshark", "--install", "--json"])
        .env("HOME", &home)
        .env_remove("XDG_CONFIG_HOME")
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let written: Value = serde_json::from_slice(&out.stdout).unwrap();
    let path = PathBuf::from(written["path"].as_str().unwrap());
    assert_eq!(
        path,
        home.join(".local/lib/wireshark/plugins")
            .join(skinbox_host::wireshark::PLUGIN_FILE)
    );
    // tshark started with that home loads it without -X and dissects a capture
    let pcap = dir.join("golden.pcap");
    let (src, dst) = box_addresses();
    write_pcap(&pcap, &hand_written(), src, dst);
    let run = |home: &Path| {
        let out = Command::new("tshark")
            .env("HOME", home)
            .args(["-n", "-r"])
            .arg(&pcap)
            .args(["-T", "fields", "-e", "skinbox.sequence"])
            .output()
            .unwrap();
        (
            out.status.success(),
            String::from_utf8(out.stdout).unwrap(),
            String::from_utf8_lossy(&out.stderr).into_owned(),
        )
    };
    let (ok, stdout, stderr) = run(&home);
    assert!(ok, "{stderr}");
    assert_eq!(stdout, "16909060\n16909061\n");
    // and without it, tshark knows no skinbox field
    let empty = dir.join("empty-home");
    std::fs::create_dir_all(&empty).unwrap();
    let (ok, _, stderr) = run(&empty);
    assert!(!ok && stderr.contains("skinbox.sequence"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Every length a datagram can have, on a port that is not the box's: the heuristic claims
/// each before Wireshark's ADwin heuristic (which takes some payload lengths on any port).
#[test]
fn every_datagram_length_is_claimed_on_any_port() {
    let dir = temp_dir("lengths");
    let plugin = plugin(&dir);
    let [records, status] = <[Vec<u8>; 2]>::try_from(hand_written()).unwrap();
    let (record_len, block_len) = (26, 32);
    let mut payloads = vec![];
    for n in 0..=55usize {
        let mut p = records[..24].to_vec();
        p[20..22].copy_from_slice(&(n as u16).to_be_bytes());
        for _ in 0..n {
            p.extend_from_slice(&records[24..24 + record_len]);
        }
        payloads.push(p);
    }
    for n in 0..=44usize {
        let mut p = status[..24 + 16].to_vec();
        p[20..22].copy_from_slice(&(n as u16).to_be_bytes());
        p[24 + 12] = 0; // first port 0
        for _ in 0..n {
            p.extend_from_slice(&status[40..40 + block_len]);
        }
        payloads.push(p);
    }
    let pcap = dir.join("lengths.pcap");
    write_pcap(
        &pcap,
        &payloads,
        "10.0.0.2:4000".parse().unwrap(),
        "10.0.0.1:4001".parse().unwrap(),
    );
    let layers = layers(&plugin, &pcap);
    assert_eq!(layers.len(), payloads.len());
    for (l, p) in layers.iter().zip(&payloads) {
        assert_eq!(
            num(&l["skinbox.entry_count"]),
            u64::from(u16::from_be_bytes([p[20], p[21]]))
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
