//! The sample clock's incremental fits (running sums, O(1) a record) against the batch
//! least squares (every fit recomputed from its points), on captures of the box: scenes
//! through the reference model (queueing at the bus roots, data and event mode, drifting
//! cell clocks) and the capture of `skinbox bench decode`. Every record's sample index
//! and host-time source must be equal, its sample and host times within a nanosecond.

use skinbox_host::pcap::{decode_pcap_with, read_file, PcapOptions};
use skinbox_host::rows::{RecordRow, RowWriter};
use skinbox_host::sample_clock::{PathModel, Positions};
use skinbox_host::timing::Timing;
use std::path::Path;
use std::process::Command;

/// Every record of the pcap `bytes` as a row, timed at `rate_hz` (incremental or batch).
fn rows(bytes: &[u8], rate_hz: f64, cells_per_bus: u16, batch: bool) -> Vec<RecordRow> {
    let timing = Timing::new(
        rate_hz,
        PathModel::bus_model(Positions::Numbered { cells_per_bus }),
    );
    let timing = if batch { timing.batch() } else { timing };
    let mut rows = vec![RecordRow::default(); skinbox_host::rows::max_records(bytes.len())];
    let mut writer = RowWriter::new(&mut rows, Some(timing));
    decode_pcap_with(bytes, &PcapOptions::default(), &mut writer).unwrap();
    let written = writer.written();
    assert_eq!(writer.beyond(), 0);
    rows.truncate(written);
    rows
}

/// Compares the two timings of the capture; returns the records compared.
fn compare(name: &str, bytes: &[u8], rate_hz: f64, cells_per_bus: u16) -> usize {
    let fast = rows(bytes, rate_hz, cells_per_bus, false);
    let batch = rows(bytes, rate_hz, cells_per_bus, true);
    assert_eq!(fast.len(), batch.len());
    let (mut worst_sample, mut worst_host) = (0.0f64, 0i64);
    for (i, (f, b)) in fast.iter().zip(&batch).enumerate() {
        assert_eq!(
            (f.tick, f.cell_id, f.sample_index, f.host_time_source),
            (b.tick, b.cell_id, b.sample_index, b.host_time_source),
            "{name}: record {i}"
        );
        worst_sample = worst_sample.max((f.sample_box_time_ns - b.sample_box_time_ns).abs());
        worst_host = worst_host.max((f.host_time_ns - b.host_time_ns).abs());
    }
    assert!(
        worst_sample < 1.0,
        "{name}: sample times {worst_sample} ns apart"
    );
    // host times are rounded to the ns: a difference below one may round apart by one
    assert!(worst_host <= 1, "{name}: host times {worst_host} ns apart");
    fast.len()
}

fn simulate(dir: &Path, name: &str, args: &[&str]) -> Vec<u8> {
    let pcap = dir.join(format!("{name}.pcap"));
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(["sim", "--fidelity", "reference", "--json", "--pcap"])
        .arg(&pcap)
        .args(args)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    read_file(&pcap).unwrap()
}

#[test]
fn incremental_fits_time_every_record_as_the_batch_fits_do() {
    let dir = std::env::temp_dir().join(format!("skinbox-fits-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut compared = 0;
    // 260 cells on 4 buses (65 a bus: long chains, packets queueing at the roots), data
    // mode at 250 Hz and event mode at 125 Hz; 2 s, past the 256-packet window
    for (name, mode, rate) in [("data", "data", "250"), ("event", "event", "125")] {
        let bytes = simulate(
            &dir,
            name,
            &[
                "stroking_upper_arm",
                "--mode",
                mode,
                "--sample-rate-hz",
                rate,
                "--buses",
                "4",
                "--duration-ms",
                "2000",
            ],
        );
        compared += compare(name, &bytes, rate.parse().unwrap(), 65);
    }
    // the bench capture: 2,000 cells on 32 ports, half data, half event
    let bench = skinbox_cosim::synthetic::bench_capture(1_000_000, 1).unwrap();
    let mut writer = skinbox_host::pcap::PcapFrameWriter::new(Vec::new()).unwrap();
    let (from, to) = (
        std::net::SocketAddr::from(([10, 0, 0, 2], 54091)),
        std::net::SocketAddr::from(([10, 0, 0, 1], 54091)),
    );
    for (i, p) in bench.payloads().iter().enumerate() {
        let at = std::time::Duration::from_nanos(1_000_000_000 + i as u64 * 12_200);
        writer.write_udp(at, from, to, p).unwrap();
    }
    compared += compare("bench", &writer.finish().unwrap(), 125.0, 63);
    assert!(compared > 1_000_000, "{compared} records");
    std::fs::remove_dir_all(&dir).ok();
}
