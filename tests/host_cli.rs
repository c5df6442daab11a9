//! The host subcommands as a user runs them: stats, decode, and replay into capture on
//! loopback, checked against the library's decoding of the same pcap.

use skinbox_cosim::synth::{self, SynthConfig};
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
    let capture = synth::generate(&SynthConfig {
        cells: 50,
        samples_per_cell: 40,
        status_period_ticks: 2_500_000,
        ..SynthConfig::default()
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
        .args(["decode", "--csv", "--samples"])
        .arg(&path)
        .output()
        .unwrap();
    let text = ok(&out);
    let mut lines = text.lines();
    let header = lines.next().unwrap();
    assert!(
        header.starts_with("time_s,tick,box_id,cell_id,"),
        "{header}"
    );
    assert_eq!(header.split(',').count(), 7 + 9);
    assert_eq!(lines.count(), records);
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
    let mut capture = skinbox()
        .args(["capture", "--listen", "127.0.0.1:0", "--json"])
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
    for (a, b) in captured.records.iter().zip(&original.records) {
        assert_eq!(a, b);
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
