//! The host subcommands as a user runs them: stats, decode, and replay into capture on
//! loopback, checked against the library's decoding of the same pcap.

use skinbox_cosim::synthetic::{self, SyntheticConfig};
use skinbox_host::pcap::{decode_pcap_file, PcapFrameWriter, PcapOptions};
use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

fn skinbox() -> Command {
    Command::new(env!("CARGO_BIN_EXE_skinbox"))
}

fn temp_path(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinbox-host-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A pcap of a synthetic scene; returns its path and the number of records.
fn scene_pcap(name: &str) -> (PathBuf, usize) {
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 50,
        samples_per_cell: 40,
        status_period_ticks: 2_500_000,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let path = temp_path(name);
    let file = std::fs::File::create(&path).unwrap();
    let mut w = PcapFrameWriter::new(std::io::BufWriter::new(file)).unwrap();
    let src: SocketAddr = "127.0.0.1:5000".parse().unwrap();
    let dst: SocketAddr = "127.0.0.1:6000".parse().unwrap();
    for (i, p) in capture.payloads().iter().enumerate() {
        w.write_udp(Duration::from_micros(200 * i as u64), src, dst, p)
            .unwrap();
    }
    w.finish().unwrap();
    (path, capture.cell_packets())
}

fn ok(out: &std::process::Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).unwrap()
}

#[test]
fn stats_json_reports_the_scene() {
    let (path, records) = scene_pcap("stats.pcap");
    let out = skinbox()
        .args(["stats", "--json"])
        .arg(&path)
        .output()
        .unwrap();
    let report: serde_json::Value = serde_json::from_str(&ok(&out)).unwrap();
    assert_eq!(report["records"], records as u64);
    assert_eq!(report["cells_active"], 50);
    assert_eq!(report["data_packets"], 25 * 40);
    assert_eq!(report["losses"]["datagrams_missing"], 0);
    assert_eq!(report["bad_input"]["total"], 0);
    assert!(report["host"]["cpu_ns_per_packet"].as_f64().unwrap() > 0.0);
    assert!(report["events_per_cell_per_second"]["acceleration"]
        .as_f64()
        .is_some());
    assert_eq!(report["boxes"].as_array().unwrap().len(), 1);
    assert_eq!(report["boxes"][0]["records"], records as u64);
    // The text report ends its last line.
    let text = ok(&skinbox().arg("stats").arg(&path).output().unwrap());
    assert!(text.ends_with('\n') && !text.ends_with("\n\n"), "{text:?}");
}

#[test]
fn decode_writes_one_row_per_packet() {
    let (path, records) = scene_pcap("decode.pcap");
    let out = skinbox()
        .args(["decode", "--jsonl"])
        .arg(&path)
        .output()
        .unwrap();
    let text = ok(&out);
    let rows: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), records);
    let data = rows.iter().find(|r| r["kind"] == "data").unwrap();
    assert_eq!(data["values"].as_object().unwrap().len(), 9);

    let out = skinbox()
        .args(["decode", "--csv", "--samples", "--cells-per-bus", "50"])
        .arg(&path)
        .output()
        .unwrap();
    let text = ok(&out);
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    assert!(
        header.starts_with("time_s,tick,box_id,source,cell_id,"),
        "{header}"
    );
    // 9 channels, then the sample's box time, method and bound, its host time, that
    // bound and the host time's source
    assert_eq!(header.split(',').count(), 8 + 9 + 6);
    assert!(
        header.ends_with(skinbox_host::output::TIME_COLUMNS),
        "{header}"
    );
    let rows: Vec<&str> = lines.collect();
    assert_eq!(rows.len(), records);
    // The pcap's receive times are the host clock: every row has a host time, without a
    // bound (receive timestamps give none), before the datagram's receive time.
    // (The first frame's timestamp is zero, which pcap readers take as none: its records
    // have no host time.)
    let mut mapped = 0;
    for row in &rows {
        let cells: Vec<&str> = row.split(',').collect();
        assert_eq!(cells[cells.len() - 2], "", "{row}");
        // a box that says nothing of time syncs: estimated, bounded by the bus's queueing
        assert_eq!(cells[cells.len() - 5], "estimated", "{row}");
        // (at least half the root queue's 1.6 ms: the estimate lies somewhere in it)
        let sample_bound: f64 = cells[cells.len() - 4].parse().unwrap();
        assert!(
            sample_bound.is_finite() && sample_bound >= 0.8e6,
            "sample time bound {sample_bound}: {row}"
        );
        match cells[cells.len() - 1] {
            "receive_stamps" => {
                let host_ns: f64 = cells[cells.len() - 3].parse().unwrap();
                // the sample was taken before its datagram arrived, the last at 200 us each
                assert!(host_ns <= 200e3 * records as f64, "{row}");
                mapped += 1;
            }
            "none" => assert_eq!(cells[cells.len() - 3], "", "{row}"),
            other => panic!("host time source {other}: {row}"),
        }
    }
    assert!(mapped >= records * 9 / 10, "{mapped} of {records}");
}

#[test]
fn replay_into_capture_on_loopback_gives_the_same_records() {
    let (path, records) = scene_pcap("replay-in.pcap");
    let recorded = temp_path("replay-out.pcap");
    let datagrams = decode_pcap_file(&path, &PcapOptions::default())
        .unwrap()
        .report
        .frames
        .udp_payloads;
    let rows = temp_path("replay-rows.csv");
    let mut capture = skinbox()
        .args(["capture", "--listen", "127.0.0.1:0", "--json"])
        .args(["--sample-rate-hz", "250", "--rows"])
        .arg(&rows)
        .args(["--count", &datagrams.to_string()])
        // Only a fallback if datagrams were lost: the comparison below then fails.
        .args(["--duration-ms", "30000"])
        .arg("--pcap")
        .arg(&recorded)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stderr = BufReader::new(capture.stderr.take().unwrap());
    let mut first = String::new();
    stderr.read_line(&mut first).unwrap();
    let addr = first
        .strip_prefix("listening on ")
        .and_then(|s| s.split_whitespace().next())
        .unwrap_or_else(|| panic!("{first}"))
        .to_string();
    let sent = skinbox()
        .args(["replay", "--json", "--rate", "20000", "--to", &addr])
        .arg(&path)
        .output()
        .unwrap();
    let sent: serde_json::Value = serde_json::from_str(&ok(&sent)).unwrap();
    assert_eq!(sent["replay"]["datagrams"], datagrams);
    let out = capture.wait_with_output().unwrap();
    let summary: serde_json::Value = serde_json::from_str(&ok(&out)).unwrap();
    assert_eq!(summary["capture"]["datagrams"], datagrams);
    assert_eq!(summary["report"]["records"], records as u64);
    // Every record as a row with its host time: the kernel's receive time (CLOCK_REALTIME)
    // mapped, within this test's run.
    let text = std::fs::read_to_string(&rows).unwrap();
    let mut lines = text.lines();
    assert!(lines
        .next()
        .unwrap()
        .ends_with(skinbox_host::output::TIME_COLUMNS));
    let now_ns = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos() as f64;
    let mut n = 0;
    for row in lines {
        let cells: Vec<&str> = row.split(',').collect();
        assert_eq!(cells[cells.len() - 1], "receive_stamps", "{row}");
        let host_ns: f64 = cells[cells.len() - 3].parse().unwrap();
        assert!(
            host_ns < now_ns && now_ns - host_ns < 120e9,
            "{row} now {now_ns}"
        );
        n += 1;
    }
    assert_eq!(n, records);

    let original = decode_pcap_file(&path, &PcapOptions::default()).unwrap();
    let captured = decode_pcap_file(&recorded, &PcapOptions::default()).unwrap();
    // The recording keeps each datagram's receive time (the kernel's, SO_TIMESTAMPNS):
    // within this test's run, in arrival order.
    let (frames, _) =
        skinbox_host::pcap::udp_payloads(&std::fs::read(&recorded).unwrap(), None).unwrap();
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap();
    assert!(frames
        .iter()
        .all(|f| f.timestamp <= now && now - f.timestamp < std::time::Duration::from_secs(120)));
    assert!(frames.windows(2).all(|w| w[0].timestamp <= w[1].timestamp));
    assert_eq!(captured.records.len(), original.records.len());
    // the same records, from the replaying socket's address instead of the pcap's
    for (a, b) in captured.records.iter().zip(&original.records) {
        assert_eq!(a.source.map(|s| s.ip()), Some([127, 0, 0, 1].into()));
        let a = skinbox_host::DecodedRecord {
            source: b.source,
            ..*a
        };
        assert_eq!(&a, b);
    }
    assert_eq!(captured.report.losses, original.report.losses);
}

#[test]
fn capture_stops_after_its_duration_in_milliseconds() {
    let start = std::time::Instant::now();
    let out = skinbox()
        .args([
            "capture",
            "--listen",
            "127.0.0.1:0",
            "--json",
            "--duration-ms",
            "300",
        ])
        .output()
        .unwrap();
    let elapsed = start.elapsed();
    let summary: serde_json::Value = serde_json::from_str(&ok(&out)).unwrap();
    assert_eq!(summary["capture"]["datagrams"], 0);
    let wall = summary["capture"]["wall_s"].as_f64().unwrap();
    assert!((0.29..5.0).contains(&wall), "{wall}");
    assert!(
        elapsed >= std::time::Duration::from_millis(300),
        "{elapsed:?}"
    );
    let bad = skinbox()
        .args(["capture", "--listen", "127.0.0.1:0", "--duration-ms", "0"])
        .output()
        .unwrap();
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--duration-ms"));
}

#[test]
fn a_missing_file_is_named_once_with_its_os_error() {
    for command in ["stats", "decode"] {
        let out = skinbox()
            .args([command, "/nonexistent/skinbox-missing.pcap"])
            .output()
            .unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.matches("(os error 2)").count(), 1, "{err}");
        assert!(err.contains("/nonexistent/skinbox-missing.pcap"), "{err}");
    }
}

#[test]
fn capture_warns_once_when_the_kernel_grants_less_buffer() {
    let rmem_max: usize = std::fs::read_to_string("/proc/sys/net/core/rmem_max")
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let asked = (4 * rmem_max).to_string();
    let args = [
        "capture",
        "--listen",
        "127.0.0.1:0",
        "--duration-ms",
        "100",
        "--recv-buffer",
        &asked,
    ];
    // Root passes the limit with SO_RCVBUFFORCE (CAP_NET_ADMIN): drop that capability.
    let root = String::from_utf8(Command::new("id").arg("-u").output().unwrap().stdout)
        .unwrap()
        .trim()
        == "0";
    let out = if root {
        Command::new("setpriv")
            .args(["--inh-caps=-net_admin", "--bounding-set=-net_admin"])
            .arg(env!("CARGO_BIN_EXE_skinbox"))
            .args(args)
            .output()
            .unwrap()
    } else {
        skinbox().args(args).output().unwrap()
    };
    ok(&out);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("warning: asked for").count(), 1, "{err}");
    assert!(err.contains(&format!("net.core.rmem_max={asked}")), "{err}");
}

#[test]
fn stats_names_its_denominators_and_refuses_bad_ones() {
    let (path, _) = scene_pcap("denominators.pcap");
    let out = skinbox()
        .args(["stats", "--cells", "64"])
        .arg(&path)
        .output()
        .unwrap();
    let text = ok(&out);
    assert!(
        text.contains("sample rate: 125 Hz, learned from the stamps"),
        "{text}"
    );
    assert!(text.contains("over 64 cells (given)"), "{text}");
    for bad in [["--cells", "0"], ["--sample-rate-hz", "0"]] {
        let out = skinbox()
            .arg("stats")
            .args(bad)
            .arg(&path)
            .output()
            .unwrap();
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(bad[0]) && err.contains("must be"), "{err}");
    }
}

/// Two boxes in one pcap, reset 7 s apart (their ticks differ by 7 s for the same host
/// time), their datagrams received 40 us after each one's latest record: `decode
/// --by-host-time` maps each box's ticks on its own and merges the rows on the pcap's clock.
#[test]
fn decode_merges_two_boxes_on_one_host_time_line() {
    use skinbox_protocol::datagram::DatagramBody;
    use skinbox_protocol::DatagramRepr;
    let path = temp_path("two-boxes-time.pcap");
    let mut w = PcapFrameWriter::new(std::io::BufWriter::new(
        std::fs::File::create(&path).unwrap(),
    ))
    .unwrap();
    let dst: SocketAddr = "127.0.0.1:6000".parse().unwrap();
    // host time = box time + offset; box 2 was reset 7 s after box 1, and a second box of
    // id 1 (another address) 0.5 s after it
    let boxes = [
        (1u16, 20_000_000_000u64, "127.0.0.1:5000"),
        (2, 27_000_000_000, "127.0.0.2:5000"),
        (1, 20_500_000_000, "127.0.0.3:5000"),
    ];
    let mut frames = Vec::new();
    for (k, (box_id, offset_ns, address)) in boxes.into_iter().enumerate() {
        let capture = synthetic::generate(&SyntheticConfig {
            cells: 20,
            samples_per_cell: 60,
            box_id,
            seed: k as u64 + 1,
            ..SyntheticConfig::default()
        })
        .unwrap();
        let src: SocketAddr = address.parse().unwrap();
        for p in capture.payloads() {
            let d = DatagramRepr::parse(&p).unwrap();
            let latest = match &d.body {
                DatagramBody::Records(r) => r.iter().map(|r| r.tick(d.base_tick)).max().unwrap(),
                DatagramBody::Status(_) => d.base_tick,
            };
            frames.push((latest * 8 + offset_ns + 40_000, src, p));
        }
    }
    // In one pcap the frames are in receive order.
    frames.sort_by_key(|f| f.0);
    let mut records = 0;
    for (ts, src, p) in &frames {
        let d = DatagramRepr::parse(p).unwrap();
        if let DatagramBody::Records(r) = &d.body {
            records += r.len();
        }
        w.write_udp(Duration::from_nanos(*ts), *src, dst, p)
            .unwrap();
    }
    w.finish().unwrap();

    let out = skinbox()
        .args(["decode", "--jsonl", "--by-host-time"])
        .arg(&path)
        .output()
        .unwrap();
    let text = ok(&out);
    let rows: Vec<serde_json::Value> = text
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), records);
    let host: Vec<f64> = rows
        .iter()
        .map(|r| r["sample_host_time_ns"].as_f64().unwrap())
        .collect();
    assert!(
        host.windows(2).all(|w| w[0] <= w[1]),
        "not in host time order"
    );
    for r in &rows {
        // every row names its box: id and source address
        let box_id = r["box_id"].as_u64().unwrap() as u16;
        let source = r["source"].as_str().unwrap();
        let offset = boxes
            .iter()
            .find(|b| b.0 == box_id && b.2 == source)
            .unwrap()
            .1 as f64;
        // each box's envelope: its offset plus the 40 us delivery
        let expected = r["sample_box_time_s"].as_f64().unwrap() * 1e9 + offset + 40_000.0;
        let got = r["sample_host_time_ns"].as_f64().unwrap();
        assert!((got - expected).abs() < 2.0, "{r}: {got} vs {expected}");
        assert_eq!(r["host_time_source"], "receive_stamps");
    }
    let stderr = String::from_utf8_lossy(&out.stderr);
    for (box_id, _, address) in boxes {
        let line = format!("box {box_id} at {address} from receive_stamps");
        assert!(stderr.contains(&line), "{stderr}");
    }
}

/// A capture of a lab network: the box's datagrams among ARP, TCP, LLDP, mDNS and IPv6
/// frames (built with etherparse). `stats` and `decode` report no bad input and the other
/// traffic by kind, in text and JSON.
#[test]
fn a_mixed_capture_reports_other_traffic_not_bad_input() {
    use etherparse::PacketBuilder;
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 10,
        samples_per_cell: 20,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let path = temp_path("mixed.pcap");
    let mut w = PcapFrameWriter::new(std::fs::File::create(&path).unwrap()).unwrap();
    let src: SocketAddr = "192.0.2.10:54091".parse().unwrap();
    let dst: SocketAddr = "192.0.2.1:54091".parse().unwrap();
    let mac = [2, 0, 0, 0, 0, 1];
    let mut others: Vec<Vec<u8>> = vec![];
    let mut f = Vec::new();
    PacketBuilder::ethernet2(mac, [0xFF; 6])
        .arp(
            etherparse::ArpPacket::new(
                etherparse::ArpHardwareId::ETHERNET,
                etherparse::EtherType::IPV4,
                etherparse::ArpOperation::REQUEST,
                &mac,
                &[192, 0, 2, 1],
                &[0; 6],
                &[192, 0, 2, 10],
            )
            .unwrap(),
        )
        .write(&mut f)
        .unwrap();
    others.push(f);
    let mut f = Vec::new();
    PacketBuilder::ethernet2(mac, mac)
        .ipv4([192, 0, 2, 1], [192, 0, 2, 2], 64)
        .tcp(40_000, 443, 7, 1000)
        .write(&mut f, b"hello")
        .unwrap();
    others.push(f);
    let mut lldp = vec![0x01, 0x80, 0xC2, 0, 0, 0x0E, 2, 0, 0, 0, 0, 9, 0x88, 0xCC];
    lldp.resize(60, 0);
    others.push(lldp);
    let mut f = Vec::new();
    PacketBuilder::ethernet2(mac, [0x01, 0, 0x5E, 0, 0, 0xFB])
        .ipv4([192, 0, 2, 1], [224, 0, 0, 251], 255)
        .udp(5353, 5353)
        .write(&mut f, &[0; 12])
        .unwrap();
    others.push(f);
    let mut f = Vec::new();
    PacketBuilder::ethernet2(mac, [0x33, 0x33, 0, 0, 0, 1])
        .ipv6([0xFE; 16], [0xFF; 16], 255)
        .icmpv6_echo_request(1, 1)
        .write(&mut f, &[0; 8])
        .unwrap();
    others.push(f);
    let mut t = 0;
    for p in capture.payloads() {
        for o in &others {
            w.write_frame(Duration::from_micros(t), o).unwrap();
            t += 10;
        }
        w.write_udp(Duration::from_micros(t), src, dst, &p).unwrap();
        t += 10;
    }
    w.finish().unwrap();
    let datagrams = capture.payloads().len() as u64;

    let out = skinbox()
        .args(["stats", "--json", "--port", "54091"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let r: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(r["bad_input"]["total"], 0, "{}", r["bad_input"]);
    assert_eq!(r["records"], capture.truth.len() as u64);
    let kinds = &r["other_traffic"]["by_kind"];
    for kind in ["ARP", "TCP", "LLDP", "UDP mDNS", "IPv6"] {
        assert_eq!(kinds[kind], datagrams, "{kind}: {kinds}");
    }
    assert_eq!(r["other_traffic"]["total"], 5 * datagrams);

    let out = skinbox().arg("stats").arg(&path).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("bad input: 0\n"), "{text}");
    assert!(
        text.contains(&format!(
            "other traffic: {} (ARP {datagrams}",
            5 * datagrams
        )),
        "{text}"
    );
    let out = skinbox()
        .args(["decode", "--csv"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad input 0;"), "{stderr}");
    assert!(
        stderr.contains(&format!("other traffic {}", 5 * datagrams)),
        "{stderr}"
    );
    // every row names its box
    let rows = String::from_utf8_lossy(&out.stdout);
    assert!(rows
        .lines()
        .skip(1)
        .all(|l| l.split(',').nth(3) == Some("192.0.2.10:54091")));
}
