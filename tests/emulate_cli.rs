//! `skinbox emulate`, `skinbox ctl` and `skinbox capture` end to end on loopback: a box
//! without a board answers commands, streams a scene to whoever claimed it, changes its
//! flush timeout at run time, and refuses (and counts) replays and foreign hosts.

use skinbox_protocol::command::{AckRepr, AckResult, CommandRepr, Request};
use skinbox_protocol::datagram::{DatagramBody, FLAG_FLUSH_TIMEOUT};
use skinbox_protocol::DatagramRepr;
use std::io::{BufRead, BufReader};
use std::net::UdpSocket;
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

fn skinbox() -> Command {
    Command::new(env!("CARGO_BIN_EXE_skinbox"))
}

fn temp_path(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinbox-emulate-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A free UDP port on loopback (bound and released; the tests bind it right after).
fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// An emulator child process, killed when dropped.
struct Emulator {
    child: Option<Child>,
    addr: String,
}

impl Emulator {
    fn start(extra: &[&str], run_ms: u64) -> Emulator {
        let addr = format!("127.0.0.1:{}", free_port());
        let mut child = skinbox()
            .args([
                "--json",
                "emulate",
                "--listen",
                &addr,
                "--duration-ms",
                "6000",
            ])
            .args(["--run-ms", &run_ms.to_string()])
            .args(extra)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // ready when it says so on stderr
        let mut line = String::new();
        BufReader::new(child.stderr.as_mut().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.starts_with("emulating box"), "{line}");
        Emulator {
            child: Some(child),
            addr,
        }
    }

    /// Waits for the end of its `--run-ms` and returns its JSON summary.
    fn summary(mut self) -> serde_json::Value {
        let out = self.child.take().unwrap().wait_with_output().unwrap();
        serde_json::from_str(&ok(&out)).unwrap()
    }
}

impl Drop for Emulator {
    fn drop(&mut self) {
        if let Some(child) = &mut self.child {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

fn ok(out: &Output) -> String {
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout.clone()).unwrap()
}

fn ctl(addr: &str, args: &[&str]) -> Output {
    skinbox()
        .args(["--json", "ctl", "--box", addr])
        .args(args)
        .output()
        .unwrap()
}

fn json(out: &Output) -> serde_json::Value {
    serde_json::from_str(&ok(out)).unwrap()
}

/// Captures for `ms` on `port` to a pcap; returns the capture's JSON and the datagrams.
fn capture(port: u16, ms: u64, name: &str) -> (serde_json::Value, Vec<DatagramRepr>) {
    let pcap = temp_path(name);
    let out = skinbox()
        .args([
            "--json",
            "capture",
            "--listen",
            &format!("127.0.0.1:{port}"),
        ])
        .args(["--duration-ms", &ms.to_string(), "--pcap"])
        .arg(&pcap)
        .output()
        .unwrap();
    let report = json(&out);
    let bytes = std::fs::read(&pcap).unwrap();
    let (payloads, _) = skinbox_host::pcap::udp_payloads(&bytes, None).unwrap();
    let datagrams = payloads
        .iter()
        .map(|p| DatagramRepr::parse(&p.payload).expect("every captured datagram parses"))
        .collect();
    (report, datagrams)
}

/// Records datagrams closed by the flush timeout: their largest spread of record ticks.
fn flushed_spread_ticks(datagrams: &[DatagramRepr]) -> (usize, i64) {
    let spreads: Vec<i64> = datagrams
        .iter()
        .filter(|d| d.flags & FLAG_FLUSH_TIMEOUT != 0)
        .filter_map(|d| match &d.body {
            DatagramBody::Records(r) => {
                let max = r.iter().map(|r| i64::from(r.tick_offset)).max()?;
                let min = r.iter().map(|r| i64::from(r.tick_offset)).min()?;
                Some(max - min)
            }
            DatagramBody::Status(_) => None,
        })
        .collect();
    (spreads.len(), spreads.into_iter().max().unwrap_or(0))
}

#[test]
fn ctl_and_capture_against_the_emulator() {
    let emulator = Emulator::start(&["--speed", "1"], 30_000);
    let addr = emulator.addr.clone();

    // status answers, with the box counters
    let status = json(&ctl(&addr, &["status"]));
    assert_eq!(status["result"], "ok");
    assert_eq!(status["command"], "status_now");
    assert_eq!(status["box_counters"]["counters"]["commands_accepted"], 1);
    assert_eq!(status["box_counters"]["unaccounted_frames"], 0);
    assert_eq!(status["port_count"], 4);

    // time: the four times of a clock exchange, in order on each clock
    let time = json(&ctl(&addr, &["time"]));
    assert_eq!(time["command"], "read_tick");
    let n = |k: &str| time[k].as_u64().unwrap();
    assert!(n("host_send_ns") <= n("host_receive_ns"), "{time}");
    assert!(n("box_receive_tick") <= n("box_send_tick"), "{time}");
    assert!(n("box_receive_tick") > 0, "{time}");
    // ping: status-now round trips
    let ping = json(&ctl(&addr, &["ping", "--count", "3"]));
    assert_eq!(ping["exchanges"].as_array().unwrap().len(), 3, "{ping}");
    assert!(ping["rtt_us_max"].as_f64().unwrap() < 250_000.0, "{ping}");
    eprintln!(
        "ctl ping round trip on loopback: {:.0} to {:.0} us",
        ping["rtt_us_min"].as_f64().unwrap(),
        ping["rtt_us_max"].as_f64().unwrap()
    );

    // stream-to, then a capture on that address receives the scene's records
    let port = free_port();
    let to = format!("127.0.0.1:{port}");
    let claim = json(&ctl(&addr, &["stream-to", "--to", &to]));
    assert_eq!(claim["result"], "ok");
    assert_eq!(claim["streaming_to"]["port"], port);
    let (report, before) = capture(port, 700, "before.pcap");
    let records = report["report"]["records"].as_u64().unwrap();
    assert!(records > 50, "{report}");
    assert_eq!(report["report"]["bad_input"]["total"], 0, "{report}");
    assert!(before
        .iter()
        .any(|d| matches!(d.body, DatagramBody::Status(_))));

    // a shorter flush timeout shows in the datagrams flushed from then on
    let set = json(&ctl(&addr, &["set", "flush-timeout-us", "10"]));
    assert_eq!(set["result"], "ok");
    // only datagrams opened after the acknowledgement left: the emulator applies the
    // command where its uplink had run to (at or after the command's arrival, at or
    // before the acknowledgement), and one opened before, with the old timeout, may still
    // be sent after the capture starts when the emulator runs behind (it sends what one
    // step of the uplink made at the end of the step)
    let set_tick = set["box_send_tick"].as_u64().unwrap();
    let (_, mut after) = capture(port, 700, "after.pcap");
    after.retain(|d| d.base_tick > set_tick);
    let (n_before, spread_before) = flushed_spread_ticks(&before);
    let (n_after, spread_after) = flushed_spread_ticks(&after);
    assert!(n_before > 5 && n_after > 5, "{n_before} {n_after}");
    // 100 us = 12,500 ticks before, 10 us = 1,250 ticks after (plus the difference of
    // two packets' ways from pin to framer)
    assert!(
        spread_before > 2500 && spread_after < 2500,
        "largest spread of a flushed datagram: {spread_before} ticks before, {spread_after} after"
    );
    let mean = |d: &[DatagramRepr]| {
        let (n, r) = d.iter().fold((0, 0), |(n, r), d| match &d.body {
            DatagramBody::Records(x) => (n + 1, r + x.len()),
            DatagramBody::Status(_) => (n, r),
        });
        r as f64 / n as f64
    };
    assert!(
        mean(&after) < mean(&before),
        "{} {}",
        mean(&after),
        mean(&before)
    );
    eprintln!(
        "flushed datagrams: largest record tick spread {spread_before} -> {spread_after} ticks, \
         records per datagram {:.2} -> {:.2}",
        mean(&before),
        mean(&after)
    );

    // a replayed command is refused, answered and counted (from another loopback address:
    // the box keeps the last sequence number per host)
    let socket = UdpSocket::bind("127.0.0.2:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_secs(2)))
        .unwrap();
    let command = CommandRepr {
        box_id: 1,
        sequence: 0x7000_0000,
        host_time: 42,
        request: Request::ReadTick,
    }
    .to_bytes();
    let mut buf = [0u8; 2048];
    let mut results = Vec::new();
    for _ in 0..2 {
        socket.send_to(&command, &addr).unwrap();
        let n = socket.recv(&mut buf).unwrap();
        results.push(AckRepr::parse(&buf[..n]).unwrap());
    }
    assert_eq!(results[0].result, AckResult::Ok);
    assert_eq!(results[1].result, AckResult::Replay);
    assert_eq!(results[1].last_accepted, 0x7000_0000);
    // a cell-network command: queued on port 2's downlink
    let cell = ctl(&addr, &["cell-command", "--port", "2", &"A5".repeat(20)]);
    assert!(
        cell.status.success(),
        "{}",
        String::from_utf8_lossy(&cell.stderr)
    );
    let status = json(&ctl(&addr, &["status"]));
    assert_eq!(status["box_counters"]["counters"]["refused_replay"], 1);
    assert_eq!(
        status["box_counters"]["counters"]["refused_downlink_full"],
        0
    );

    // the claim of a capture: the stream comes to the capture's own socket
    let out = skinbox()
        .args([
            "--json",
            "capture",
            "--listen",
            "127.0.0.1:0",
            "--claim",
            &addr,
        ])
        .args(["--duration-ms", "500"])
        .output()
        .unwrap();
    let claimed = json(&out);
    assert_eq!(claimed["claim"]["result"], "ok");
    assert!(
        claimed["report"]["records"].as_u64().unwrap() > 20,
        "{claimed}"
    );
}

/// A claiming capture sends read-tick commands as it runs; their acknowledgements map the
/// box's time to the host's, so the rows' host times come from exchanges, with a bound.
#[test]
fn a_claiming_capture_maps_box_time_by_read_tick_exchanges() {
    let emulator = Emulator::start(&[], 5000);
    let dir = std::env::temp_dir().join(format!("skinbox-exchanges-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let rows = dir.join("rows.csv");
    let out = skinbox()
        .args(["--json", "capture", "--listen", "127.0.0.1:0", "--claim"])
        .arg(&emulator.addr)
        .args([
            "--duration-ms",
            "1500",
            "--exchange-ms",
            "50",
            "--sample-rate-hz",
            "125",
            // the default scene's 65 cells a bus: each cell's path latency, so each bound
            "--cells-per-bus",
            "65",
        ])
        .arg("--rows")
        .arg(&rows)
        .output()
        .unwrap();
    let v = json(&out);
    let sent = v["read_ticks_sent"].as_u64().unwrap();
    assert!((15..=40).contains(&sent), "{v}");
    // the exchanges' send times are the kernel's send stamps; any that fell back to the
    // host's clock is counted with its reason
    let stamps = &v["exchange_stamps"];
    let kernel = stamps["kernel"].as_u64().unwrap();
    let user_space = stamps["user_space"].as_u64().unwrap();
    assert!(kernel > 0 && kernel >= user_space, "{stamps}");
    let fallbacks: u64 = stamps["fallbacks"]
        .as_object()
        .unwrap()
        .values()
        .map(|n| n.as_u64().unwrap())
        .sum();
    assert_eq!(fallbacks, user_space, "{stamps}");
    let times = &v["host_times"][0];
    assert_eq!(times["source"], "exchanges", "{v}");
    assert_eq!(times["restarts"], 0);
    let bound_ns = times["error_bound_ns"].as_f64().unwrap();
    assert!(bound_ns > 0.0 && bound_ns < 2e6, "{times}");
    // the emulator counted the commands: every read tick answered
    let status = json(&ctl(&emulator.addr, &["status"]));
    let accepted = status["box_counters"]["counters"]["commands_accepted"]
        .as_u64()
        .unwrap();
    assert!(
        accepted > sent,
        "{accepted} accepted, {sent} read ticks and the claim"
    );
    // the last rows are mapped by the exchanges, with their bound
    let text = std::fs::read_to_string(&rows).unwrap();
    let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|c| *c == name).unwrap();
    let last: Vec<&str> = text.lines().last().unwrap().split(',').collect();
    assert_eq!(last[column("host_time_source")], "exchanges");
    let bound: f64 = last[column("host_time_bound_ns")].parse().unwrap();
    assert!(bound > 0.0 && bound < 2e6, "{bound}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_host_outside_the_subnet_is_refused_and_counted() {
    let emulator = Emulator::start(&["--host-subnet", "192.0.2.0/24"], 3000);
    let out = ctl(
        &emulator.addr,
        &["--timeout-ms", "100", "--retries", "1", "status"],
    );
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no acknowledgement"), "{err}");
    let summary = emulator.summary();
    assert_eq!(
        summary["box_counters"]["counters"]["refused_foreign_subnet"],
        2
    );
    assert_eq!(summary["box_counters"]["counters"]["commands_accepted"], 0);
    assert_eq!(summary["acks_sent"], 0);
}

#[test]
fn cells_commands_build_cell_command_packets_the_box_queues() {
    let emulator = Emulator::start(&[], 4000);
    let addr = emulator.addr.clone();
    // (arguments, the packet written by hand from docs/wire-format.md, the port)
    let cases: [(&[&str], &str, serde_json::Value); 5] = [
        (
            &["cells", "mode", "event", "--port", "1", "--cell", "7"],
            "A500070101000000000000000000000000000055",
            1.into(),
        ),
        (
            &["cells", "rate", "250"],
            "A53FFF0202000000000000000000000000000055",
            "all".into(),
        ),
        (
            &["cells", "--port", "0", "thresholds", "--accel-g", "0.04"],
            "A53FFF03000A0001000600010000000000000055",
            0.into(),
        ),
        (
            &["cells", "enable", "accel_x", "proximity"],
            "A53FFF0400410000000000000000000000000055",
            "all".into(),
        ),
        (
            &["cells", "sync", "4660"],
            "A53FFF0500000000000012340000000000000055",
            "all".into(),
        ),
    ];
    for (args, packet, port) in &cases {
        // (each ctl run takes milliseconds: the queues have drained in between)
        let out = ctl(&addr, args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["result"], "ok", "{args:?}");
        assert_eq!(v["command"], "cell_command");
        assert_eq!(v["cell_packet"], *packet, "{args:?}");
        assert_eq!(v["port"], *port, "{args:?}");
    }
    // bad arguments never reach the box
    for (args, says) in [
        (&["cells", "rate", "100"][..], "62.5, 125, 250, 500 or 1000"),
        (
            &["cells", "mode", "event", "--cell", "16383"][..],
            "1..=16382",
        ),
        (
            &["cells", "enable", "accel_w"][..],
            "unknown channel accel_w",
        ),
    ] {
        let out = ctl(&addr, args);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(says), "{args:?}: {err}");
    }
    let status = json(&ctl(&addr, &["status"]));
    assert_eq!(
        status["box_counters"]["counters"]["refused_downlink_full"],
        0
    );
    // the five cell commands and the status request
    assert_eq!(
        status["box_counters"]["counters"]["commands_accepted"],
        cases.len() + 1
    );
}

/// A record the box sent: the tick its cell packet's first start bit reached the box, and
/// the packet.
struct Heard {
    tick: i64,
    cell: u16,
    packet: skinbox_protocol::CellRepr,
}

/// Claims the stream of the emulator at `addr` for a new socket and reads its records
/// datagrams there until the returned flag is set.
fn claim_and_hear(
    addr: &str,
) -> (
    std::sync::Arc<std::sync::atomic::AtomicBool>,
    std::thread::JoinHandle<Vec<Heard>>,
) {
    let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let to = socket.local_addr().unwrap().to_string();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let reader = {
        let stop = stop.clone();
        std::thread::spawn(move || hear_records(socket, stop))
    };
    assert_eq!(
        json(&ctl(addr, &["stream-to", "--to", &to]))["result"],
        "ok"
    );
    (stop, reader)
}

/// Reads the box's records datagrams on `socket` until `stop` is set.
fn hear_records(
    socket: UdpSocket,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> Vec<Heard> {
    use skinbox_protocol::{CellFraming, CellRepr};
    socket
        .set_read_timeout(Some(Duration::from_millis(20)))
        .unwrap();
    let mut heard = vec![];
    let mut buf = [0u8; 2048];
    while !stop.load(std::sync::atomic::Ordering::Relaxed) {
        let Ok(n) = socket.recv(&mut buf) else {
            continue;
        };
        let d = DatagramRepr::parse(&buf[..n]).expect("every datagram parses");
        if let DatagramBody::Records(records) = d.body {
            for r in records {
                let packet = CellRepr::parse(&r.cell_packet, &CellFraming::DEFAULT)
                    .expect("the cells send valid packets");
                heard.push(Heard {
                    tick: d.base_tick as i64 + i64::from(r.tick_offset),
                    cell: packet.cell_id(),
                    packet,
                });
            }
        }
    }
    heard
}

/// Per cell, the median tick spacing of its consecutive records.
fn median_spacing(records: &[&Heard]) -> Vec<i64> {
    let mut cells: std::collections::BTreeMap<u16, Vec<i64>> = Default::default();
    for r in records {
        cells.entry(r.cell).or_default().push(r.tick);
    }
    cells
        .values()
        .map(|ticks| {
            let mut d: Vec<i64> = ticks.windows(2).map(|w| w[1] - w[0]).collect();
            d.sort();
            d[d.len() / 2]
        })
        .collect()
}

/// Every cell command kind sent with `skinbox ctl` to `skinbox emulate` goes through the box's
/// control and downlink models to the transmit pins, the cells' receivers decode it there,
/// and the stream the box sends changes as the command says from the cells' next sample on.
#[test]
fn emulated_cells_obey_the_cell_commands_the_box_sends_them() {
    use skinbox_protocol::{CellRepr, Channel};
    // 8 cells on 2 buses of the idle scene: event mode, 125 samples/s, noise only
    const CELLS: usize = 8;
    const PHASE: Duration = Duration::from_millis(300);
    let emulator = Emulator::start(&["idle", "--cells", "8", "--buses", "2"], 3500);
    let started = std::time::Instant::now();
    let addr = emulator.addr.clone();
    let (stop, reader) = claim_and_hear(&addr);
    std::thread::sleep(PHASE);
    let commands: [&[&str]; 6] = [
        &["cells", "thresholds", "--accel-g", "0.001"],
        &["cells", "enable", "accel_x"],
        &["cells", "mode", "data"],
        &["cells", "rate", "250"],
        &["cells", "rate", "125"],
        &["cells", "sync", "0"],
    ];
    // the box tick each command arrived at
    let mut at = vec![];
    for args in commands {
        let v = json(&ctl(&addr, args));
        assert_eq!(v["result"], "ok", "{args:?}: {v}");
        at.push(v["box_receive_tick"].as_i64().unwrap());
        std::thread::sleep(PHASE);
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let heard = reader.join().unwrap();
    eprintln!("commands sent in {:.2} s", started.elapsed().as_secs_f64());
    let summary = emulator.summary();
    // one packet per command per bus reached the cells' receivers
    assert_eq!(
        summary["cell_commands_heard"],
        2 * commands.len(),
        "{summary}"
    );
    // phase i: from the command before it (and every cell's next sample, 12 ms) to the next
    let settle = 1_500_000;
    let bounds: Vec<(i64, i64)> = std::iter::once(0)
        .chain(at.iter().map(|t| t + settle))
        .zip(at.iter().copied().chain([i64::MAX]))
        .collect();
    let phases: Vec<Vec<&Heard>> = bounds
        .iter()
        .map(|&(from, to)| {
            heard
                .iter()
                .filter(|h| (from..to).contains(&h.tick))
                .collect()
        })
        .collect();
    let seconds = |(from, to): (i64, i64), p: &[&Heard]| {
        let to = if to == i64::MAX {
            p.last().map_or(from, |h| h.tick)
        } else {
            to
        };
        (to - from) as f64 / 125e6
    };
    let events_of = |p: &[&Heard], channel: Channel| {
        p.iter()
            .filter(|h| match &h.packet {
                CellRepr::Event(e) => e.events().any(|(c, _)| c == channel),
                CellRepr::Data(_) => false,
            })
            .count() as f64
    };
    let per_cell_s = |i: usize, channel: Channel| {
        events_of(&phases[i], channel) / seconds(bounds[i], &phases[i]) / CELLS as f64
    };
    // thresholds: acceleration events from about 1 per cell and second (the scene's noise
    // against 0.02 g) to nearly every sample (against 0.001 g)
    let (before, after) = (
        per_cell_s(0, Channel::AccelY),
        per_cell_s(1, Channel::AccelY),
    );
    eprintln!("accel_y events per cell and s: {before:.1} -> {after:.1}");
    assert!(before < 10.0 && after > 60.0);
    // enable: from then on no event of another channel
    let others = |i: usize| {
        phases[i]
            .iter()
            .filter(|h| match &h.packet {
                CellRepr::Event(e) => e.events().any(|(c, _)| c != Channel::AccelX),
                CellRepr::Data(_) => true,
            })
            .count()
    };
    assert!(others(1) > 100, "{}", others(1));
    assert_eq!(others(2), 0);
    assert!(per_cell_s(2, Channel::AccelX) > 60.0);
    // mode data: every cell sends a data packet per sample (125 per s)
    let is_data = |h: &&&Heard| matches!(h.packet, CellRepr::Data(_));
    assert_eq!(phases[2].iter().filter(is_data).count(), 0);
    assert!(phases[3].iter().all(|h| is_data(&h)));
    let rate = phases[3].len() as f64 / seconds(bounds[3], &phases[3]) / CELLS as f64;
    assert!(
        (115.0..=135.0).contains(&rate),
        "{rate} data packets/cell/s"
    );
    // rate: the spacing of each cell's records, 8 ms, then 4 ms, then 8 ms again (the
    // clocks' drift is at most 100 ppm; the bus adds a few us of queueing)
    for (i, ticks) in [(3, 1_000_000), (4, 500_000), (5, 1_000_000)] {
        let spacing = median_spacing(&phases[i]);
        assert_eq!(spacing.len(), CELLS, "phase {i}");
        for s in spacing {
            assert!(
                (s - ticks).abs() < ticks / 200,
                "phase {i}: {s} ticks, not {ticks}"
            );
        }
    }
    // sync 0: the box writes the tick its first start bit leaves at into the packet, so
    // from then on the cells sample when the box's tick is a multiple of the 8 ms period:
    // every record within 500 us after such a grid point (the root's processing, the hops
    // and the queue on the bus); before it, the cells sampled on their own phases
    let on_grid = |p: &[&Heard]| {
        p.iter()
            .filter(|h| h.tick.rem_euclid(1_000_000) < 62_500)
            .count()
    };
    assert!(phases[6].len() > 100, "{}", phases[6].len());
    assert_eq!(on_grid(&phases[6]), phases[6].len());
    eprintln!(
        "records within 500 us after the grid: {} of {} before sync 0, {} of {} after",
        on_grid(&phases[5]),
        phases[5].len(),
        on_grid(&phases[6]),
        phases[6].len()
    );
    assert!(
        on_grid(&phases[5]) < phases[5].len() / 2,
        "{} of {} on the grid before",
        on_grid(&phases[5]),
        phases[5].len()
    );
}

/// `emulate --sync-period-ms 100`: the emulated box sends a time sync down each bus at
/// reset and every 0.1 s, the cells hear every one, and they sample on the box's 8 ms grid
/// from the first on (every record within 500 us after a grid point).
#[test]
fn the_emulated_boxs_own_syncs_keep_its_cells_on_its_grid() {
    let emulator = Emulator::start(
        &[
            "idle",
            "--cells",
            "8",
            "--buses",
            "2",
            "--sync-period-ms",
            "100",
        ],
        1500,
    );
    let (stop, reader) = claim_and_hear(&emulator.addr);
    std::thread::sleep(Duration::from_millis(1000));
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let heard = reader.join().unwrap();
    let summary = emulator.summary();
    // one sync per bus at reset and one each 0.1 s after (the last may still be under way)
    let periods = summary["box_ticks"].as_u64().unwrap() / 12_500_000;
    let syncs = summary["cell_commands_heard"].as_u64().unwrap();
    assert!(
        (2 * periods..=2 * (periods + 1)).contains(&syncs),
        "{syncs} syncs in {periods} periods: {summary}"
    );
    // (the idle scene's 8 cells send about 46 event packets a second)
    assert!(heard.len() > 20, "{}", heard.len());
    let off_grid: Vec<i64> = heard
        .iter()
        .map(|h| h.tick.rem_euclid(1_000_000))
        .filter(|&t| t >= 62_500)
        .collect();
    assert!(off_grid.is_empty(), "{off_grid:?}");
}
