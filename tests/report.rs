//! `skinbox report --quick`: every study runs, the summary holds the numbers behind each
//! chart, and every chart is a readable PNG and SVG.

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

/// The markdown tables of one `## <id> ...` section: each a list of rows, each row a map
/// from column header to cell.
fn tables(summary: &str, id: &str) -> Vec<Vec<HashMap<String, String>>> {
    let heading = format!("## {id} ");
    let start = summary
        .find(&heading)
        .unwrap_or_else(|| panic!("no section {id}"));
    let body = &summary[start + heading.len()..];
    let body = &body[..body.find("\n## ").unwrap_or(body.len())];
    let mut out = Vec::new();
    let mut lines = body.lines().peekable();
    while let Some(line) = lines.next() {
        if !line.starts_with('|') {
            continue;
        }
        let cells = |l: &str| -> Vec<String> {
            l.trim()
                .trim_matches('|')
                .split(" | ")
                .map(|c| c.trim().to_string())
                .collect()
        };
        let headers = cells(line);
        lines.next(); // |---|
        let mut rows = Vec::new();
        while let Some(l) = lines.peek().filter(|l| l.starts_with('|')) {
            let r = cells(l);
            assert_eq!(r.len(), headers.len(), "{l}");
            rows.push(headers.iter().cloned().zip(r).collect());
            lines.next();
        }
        out.push(rows);
    }
    out
}

fn num(row: &HashMap<String, String>, column: &str) -> f64 {
    let v = row
        .get(column)
        .unwrap_or_else(|| panic!("no column {column}: {row:?}"));
    v.trim_start_matches('+')
        .parse()
        .unwrap_or_else(|_| panic!("{column}: {v} is not a number"))
}

fn finding<'a>(rows: &'a [HashMap<String, String>], starts: &str) -> &'a str {
    &rows
        .iter()
        .find(|r| r["finding"].starts_with(starts))
        .unwrap_or_else(|| panic!("no finding {starts}"))["value"]
}

/// A PNG by its signature and IHDR (width, height), and some non-white pixels to show that
/// something (text, lines) was drawn.
fn check_png(path: &Path) {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
    assert_eq!(&bytes[12..16], b"IHDR");
    let width = u32::from_be_bytes(bytes[16..20].try_into().unwrap());
    let height = u32::from_be_bytes(bytes[20..24].try_into().unwrap());
    assert_eq!((width, height), (800, 500), "{}", path.display());
    assert!(bytes.len() > 20_000, "{}: almost empty", path.display());
}

fn check_svg(path: &Path, title: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.trim_start().starts_with("<svg"), "{}", path.display());
    assert!(text.trim_end().ends_with("</svg>"), "{}", path.display());
    assert!(text.contains(title), "{}: no title {title}", path.display());
    assert!(
        text.matches("<text").count() > 10,
        "{}: no labels",
        path.display()
    );
}

#[test]
fn quick_report_writes_every_chart_and_the_numbers_behind_them() {
    let dir = std::env::temp_dir().join(format!("skinbox-report-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(["report", "--quick", "--json", "--out"])
        .arg(&dir)
        .output()
        .expect("run skinbox");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let written: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let summary = std::fs::read_to_string(dir.join("summary.md")).unwrap();

    // Every chart the summary shows exists as a PNG and an SVG.
    let charts = [
        ("c1_send_on_delta", "C1 Send-on-delta"),
        ("c2_fidelity", "C2 Fidelity"),
        ("c2_speed", "C2 Fidelity"),
        ("c3_batching", "C3 Batching"),
        ("c4a_baud_mismatch", "C4a UART baud mismatch"),
        ("c4b_cells_per_bus", "C4b Cells per bus"),
        ("c4c_sensor_noise", "C4c Sensor noise"),
        ("c4d_event_loss", "C4d Event loss"),
        (
            "c5a_sample_time_by_hop",
            "C5a Sample time error along a 66-cell bus",
        ),
        ("c5b_sample_time_cost", "C5b Sample time error against cost"),
        ("c5c_sample_time_boundaries", "C5c Where (b) and (c) fail"),
        (
            "c5d_sample_time_bus_load",
            "C5d Sample time error against bus load",
        ),
        ("c6_sample_rate", "C6 Packet rate against sample rate"),
        (
            "c7_mode_rate_packets",
            "C7 One skin switched by host commands",
        ),
        ("c7_mode_rate_cpu", "C7 Host CPU against sample rate"),
    ];
    assert_eq!(
        written["charts"].as_array().unwrap().len(),
        2 * charts.len()
    );
    for (name, title) in charts {
        assert!(summary.contains(&format!("({name}.png)")), "{name}");
        check_png(&dir.join(format!("{name}.png")));
        check_svg(&dir.join(format!("{name}.svg")), title);
    }

    // C1: Table I saves packets in every scene; data mode is 100 %; larger thresholds send
    // fewer packets.
    let c1 = &tables(&summary, "C1")[1];
    assert_eq!(c1.len(), 6 * 4);
    for r in c1 {
        let rate = num(r, "packets (% of data mode)");
        match r["threshold scale"].as_str() {
            "data mode" => assert_eq!(rate, 100.0),
            "1" => assert!(rate < 90.0, "{r:?}"),
            _ => {}
        }
        assert!(
            num(r, "RMS error, mean of 8 channels (% FS)") < 1.0,
            "{r:?}"
        );
    }
    let rate_of = |scene: &str, scale: &str| {
        num(
            c1.iter()
                .find(|r| r["scene"] == scene && r["threshold scale"] == scale)
                .unwrap(),
            "packets (% of data mode)",
        )
    };
    assert!(rate_of("moving_arm", "4") < rate_of("moving_arm", "1"));
    assert!(rate_of("moving_arm", "1") < rate_of("moving_arm", "0.25"));
    let idle = rate_of("idle", "1");
    assert!((3.0..7.0).contains(&idle), "idle at Table I: {idle} %");

    // C2: the RTL ran and delivered; the rate model stays within 25 % of it; the reference
    // model agrees with it frame for frame.
    let c2 = &tables(&summary, "C2")[1];
    let rtl = c2
        .iter()
        .find(|r| r["level"].starts_with("RTL"))
        .expect("an RTL row");
    assert!(num(rtl, "records in the window") > 20.0);
    assert!(num(rtl, "stamp - true edge, max (ticks)") < 1.0);
    let rate = c2
        .iter()
        .find(|r| r["level"].starts_with("rate model") && r["buses"] == rtl["buses"])
        .unwrap();
    assert!(
        num(rate, "records error vs RTL (%)").abs() < 25.0,
        "{rate:?}"
    );
    assert!(num(rate, "wall time per simulated s (s)") < 1e-3);
    assert!(c2.iter().any(|r| r["cells"] == "5742"));
    // the reference model sends the RTL's frames, faster
    let reference = c2
        .iter()
        .find(|r| r["level"].starts_with("reference") && r["buses"] == rtl["buses"])
        .expect("a reference row beside the RTL");
    assert_eq!(num(reference, "datagrams error vs RTL (%)"), 0.0);
    assert_eq!(
        reference["records in the window"],
        rtl["records in the window"]
    );
    assert!(
        num(reference, "wall time per simulated s (s)") * 20.0
            < num(rtl, "wall time per simulated s (s)"),
        "{reference:?} against {rtl:?}"
    );

    // C3: the latency grows with the flush timeout; a lone record waits about the timeout.
    let c3 = &tables(&summary, "C3")[0];
    let light = |t: &str| {
        c3.iter()
            .find(|r| r["load"].starts_with("260") && r["flush timeout (us)"] == t)
            .unwrap()
    };
    let p50_100 = num(light("100"), "latency p50 (us)");
    assert!((100.0..110.0).contains(&p50_100), "{p50_100}");
    assert!(num(light("1"), "latency p50 (us)") < num(light("10"), "latency p50 (us)"));
    let original = c3
        .iter()
        .find(|r| r["box"].starts_with("original") && r["load"].starts_with("260"))
        .unwrap();
    assert!(num(original, "latency p50 (us)") < 1.0);

    // C4a: +-4 % all good, +-6 % fails safe.
    let c4a = &tables(&summary, "C4a");
    assert_eq!(finding(&c4a[0], "every packet delivered"), "-4.0 .. +4.0");
    assert_eq!(finding(&c4a[0], "largest share corrupted"), "0.0");
    for r in &c4a[1] {
        assert_eq!(
            num(r, "corrupted or mistimed but delivered (%)"),
            0.0,
            "{r:?}"
        );
        let e = num(r, "baud error (%)");
        if e.abs() <= 4.0 {
            assert_eq!(num(r, "good (%)"), 100.0, "{r:?}");
        } else {
            assert!(num(r, "rejected (%)") > 0.0, "{r:?}");
        }
    }

    // C4b: 66 cells at 250 Hz lose nothing; 100 lose the excess over 20,000 packets/s.
    let c4b = &tables(&summary, "C4b")[1];
    for r in c4b.iter().filter(|r| r["series"] == "data mode, 250 Hz") {
        let cells = num(r, "cells on the bus");
        let loss = num(r, "dropped (%)");
        if cells <= 66.0 {
            assert_eq!(loss, 0.0, "{r:?}");
        } else {
            assert!((loss - num(r, "closed form (%)")).abs() < 2.0, "{r:?}");
            assert!(loss > 10.0, "{r:?}");
        }
    }

    // C4c: event storms above data mode at a few times the calibrated noise.
    let c4c = &tables(&summary, "C4c");
    let storm: f64 = finding(&c4c[0], "idle: noise where").parse().unwrap();
    assert!((2.0..8.0).contains(&storm), "{storm}");

    // C4d: at 3 % loss the error passes 0.5 % without refresh and stays below it with one.
    let c4d = &tables(&summary, "C4d");
    for r in c4d[1].iter().filter(|r| r["packet loss (%)"] == "3") {
        let e = num(r, "RMS error, mean of 8 channels (% FS)");
        if r["full refresh every (s)"] == "never" {
            assert!(e > 0.5, "{r:?}");
        } else {
            assert!(e < 0.5, "{r:?}");
        }
    }

    // C5: every method on every run of the grid; the arrival stamp is late by the path
    // (over 3 ms at the chain's end), the time sync within the goal everywhere, and with
    // the rate servo within a microsecond (the drift over 0.1 s, 10 us, is what the phase
    // alone leaves)
    let c5 = &tables(&summary, "C5");
    assert_eq!(c5[1].len(), 4 * 3 * 4);
    for r in &c5[1] {
        let worst = num(r, "worst cell p99 (us)");
        match r["method"].as_str() {
            "(a) arrival stamp" => assert!(worst > 3_000.0, "{r:?}"),
            "(c) time sync" => assert!(worst <= 20.0, "{r:?}"),
            "(c) time sync, rate servo (wandering oscillator)" => {
                assert!(worst <= 1.0, "{r:?}")
            }
            "(b) host estimate" => {}
            other => panic!("method {other}"),
        }
    }

    // C6: the five scenes of Fig. 11 at its four rates; the model against the papers' fit,
    // recomputed here from the fit's constants (docs/design.md section 2)
    let c6 = &tables(&summary, "C6")[1];
    assert_eq!(c6.len(), 5 * 4);
    let fits = [
        ("idle", 243.8846, 2.248e-4, 1.0),
        ("stroking_upper_arm", 85.0385, 3.215e-3, 1.0),
        ("stroking_arm", 74.2308, 6.154e-3, 1.0),
        ("hammering_end_effector", 330.2692, 2.512e-3, 1.0),
        ("moving_arm", 1.214e7, 1.687e-5, 260.0),
    ];
    for r in c6 {
        let (_, a, b, per) = fits.iter().find(|f| f.0 == r["scene"]).unwrap();
        let x = num(r, "sample rate (Hz)");
        let fit = a * (b * x + 1.0f64).ln() / per;
        assert!((num(r, "Fig. 11 fit") - fit).abs() < 0.006, "{r:?}");
        let ratio = num(r, "packets per cell per s") / num(r, "Fig. 11 fit");
        assert!((num(r, "model / fit") - ratio).abs() < 0.002, "{r:?}");
        // the quick run's 2 s windows are noisy: a looser band than the full run's 1.2
        assert!((0.7..1.4).contains(&ratio), "{r:?}");
    }
    // data mode is 100 %; faster sampling sends a smaller share of it for the stroking scenes
    let share = |scene: &str, rate: &str| {
        num(
            c6.iter()
                .find(|r| r["scene"] == scene && r["sample rate (Hz)"] == rate)
                .unwrap(),
            "packets (% of data mode)",
        )
    };
    assert!(share("stroking_arm", "500") < share("stroking_arm", "62.5"));

    // C7: one skin switched through data and event mode at the four rates by host commands
    // through the box; the papers' curves recomputed here (docs/design.md section 2)
    let c7 = &tables(&summary, "C7")[1];
    assert_eq!(c7.len(), 8);
    for r in c7 {
        let x = num(r, "sample rate (Hz)");
        let packets = num(r, "packets per cell per s");
        let papers = num(r, "papers (data: 0.9435 x; event: Fig. 11 fit)");
        let driver = num(r, "papers' driver CPU (%) at this packet rate");
        let total = packets * 260.0;
        match r["mode"].as_str() {
            "data" => {
                assert!((packets / x - 1.0).abs() < 0.01, "{r:?}");
                assert!((papers - 0.9435 * x).abs() < 0.006, "{r:?}");
                assert!(
                    (driver - 45.52 * (5.453e-5 * total + 1.0).ln()).abs() < 0.06,
                    "{r:?}"
                );
            }
            "event" => {
                assert!(packets < 0.8 * x, "{r:?}");
                let fit = 74.2308 * (6.154e-3 * x + 1.0f64).ln();
                assert!((papers - fit).abs() < 0.006, "{r:?}");
                assert!(
                    (driver - 32.65 * (1.239e-4 * total + 1.0).ln()).abs() < 0.06,
                    "{r:?}"
                );
            }
            m => panic!("mode {m}"),
        }
        assert!(num(r, "host CPU (% of a core)") < driver, "{r:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

/// The summary with the measured wall times masked: the first line (how and in how long
/// it was written), C2's "wall time per simulated s (s)" column and the C2 findings made
/// from those times (speed-ups, wall times, the extrapolation), and the host CPU columns
/// of C5 and C7 and C7's host CPU finding.
/// A merged report keeps the times each shard measured, which differ from run to run;
/// every other number must agree.
fn masked(summary: &str) -> String {
    const TIMING_COLUMN: &str = "wall time per simulated s (s)";
    const CPU_COLUMN: &str = "host CPU";
    const TIMING_FINDINGS: [&str; 3] = [
        "reference model wall time per simulated s",
        "RTL wall time per simulated s",
        "RTL at 5,742 cells",
    ];
    let mut out = Vec::new();
    let mut section = "";
    let mut masked_column = None;
    let mut cpu_columns: Vec<usize> = Vec::new();
    let mut in_table = false;
    for line in summary.lines() {
        if let Some(heading) = line.strip_prefix("## ") {
            section = heading.split(' ').next().unwrap_or("");
        }
        if line.starts_with("Written by `skinbox report") {
            out.push("(written by)".to_string());
            continue;
        }
        if !line.starts_with('|') {
            in_table = false;
            out.push(line.to_string());
            continue;
        }
        let mut cells: Vec<String> = line
            .trim_matches('|')
            .split(" | ")
            .map(|c| c.trim().to_string())
            .collect();
        if !in_table {
            in_table = true;
            masked_column = cells.iter().position(|c| c == TIMING_COLUMN);
            cpu_columns = (0..cells.len())
                .filter(|&k| cells[k].starts_with(CPU_COLUMN))
                .collect();
        } else if !cpu_columns.is_empty() {
            let n = cells.len();
            for &k in cpu_columns.iter().filter(|&&k| k < n) {
                cells[k] = "(time)".into();
            }
        } else if section == "C7" && cells.len() > 1 && cells[0].starts_with(CPU_COLUMN) {
            cells[1] = "(time)".into();
        } else if section == "C2" && cells.len() > 1 {
            if let Some(k) = masked_column.filter(|&k| k < cells.len()) {
                cells[k] = "(time)".into();
            }
            if TIMING_FINDINGS.iter().any(|f| cells[0].starts_with(f)) {
                cells[1] = "(time)".into();
            }
            if let Some((frames, _)) = cells[1]
                .split_once("; ")
                .filter(|(_, x)| x.ends_with(" x faster"))
            {
                cells[1] = format!("{frames}; (time) x faster");
            }
        }
        out.push(cells.join(" | "));
    }
    out.join("\n")
}

fn skinbox_report(args: &[&str], out: &Path) -> std::process::Child {
    Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .arg("report")
        .args(args)
        .args(["--json", "--out"])
        .arg(out)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("run skinbox")
}

fn finished(child: std::process::Child) -> serde_json::Value {
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

/// `report --quick` as three shards, run at once (as on three machines, here sharing the
/// model cache) and merged, equals the unsharded `--quick` run number for number; only the
/// measured wall times (see [`masked`]) and the charts drawn from them (C2, C5b) may differ.
/// Every other chart is the same file byte for byte.
#[test]
fn quick_report_in_three_shards_merges_into_the_unsharded_report() {
    let dir = std::env::temp_dir().join(format!("skinbox-report-shards-{}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    let whole = skinbox_report(&["--quick"], &dir.join("whole"));
    let shards: Vec<_> = (1..=3)
        .map(|k| {
            skinbox_report(
                &["--quick", "--shard", &format!("{k}/3")],
                &dir.join(format!("shard{k}")),
            )
        })
        .collect();
    let whole = finished(whole);
    let mut computed = 0;
    for (k, shard) in shards.into_iter().enumerate() {
        let written = finished(shard);
        assert!(written["summary"].is_null(), "{written}");
        assert!(written["charts"].as_array().unwrap().is_empty());
        let file = written["shard_file"].as_str().unwrap();
        assert!(
            file.ends_with(&format!("points-{}-of-3.jsonl", k + 1)),
            "{file}"
        );
        assert_eq!(written["points"], whole["points"]);
        computed += written["points_computed"].as_u64().unwrap();
    }
    assert_eq!(
        computed,
        whole["points"].as_u64().unwrap(),
        "every point once"
    );
    assert!(computed > 50, "{computed} points");

    let shard_dirs: Vec<_> = (1..=3).map(|k| dir.join(format!("shard{k}"))).collect();
    let merge = |dirs: &[std::path::PathBuf], out: &str| {
        Command::new(env!("CARGO_BIN_EXE_skinbox"))
            .args(["report", "--json", "--out"])
            .arg(dir.join(out))
            .arg("--merge")
            .args(dirs)
            .output()
            .unwrap()
    };
    let out = merge(&shard_dirs, "merged");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let merged: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(merged["points_computed"], 0, "a merge computes nothing");

    let summary = |d: &str| std::fs::read_to_string(dir.join(d).join("summary.md")).unwrap();
    let (whole_summary, merged_summary) = (summary("whole"), summary("merged"));
    assert!(merged_summary.contains("merged from 3 shards"));
    assert_eq!(masked(&merged_summary), masked(&whole_summary));
    // the mask hides the times and nothing else: the column in the 10 rows of the quick
    // C2 table (RTL, cell models, reference, rate model at 7 sizes) and 4 findings; C5's
    // host CPU in its 48 rows (4 scenes and modes, 3 rates, 4 methods) and 4 cost rows;
    // C7's two host CPU columns in its 8 segments and its CPU finding
    assert_eq!(
        masked(&whole_summary).matches("(time)").count(),
        10 + 4 + 48 + 4 + 8 * 2 + 1
    );

    let names = |v: &serde_json::Value| -> Vec<String> {
        v["charts"]
            .as_array()
            .unwrap()
            .iter()
            .map(|p| {
                Path::new(p.as_str().unwrap())
                    .file_name()
                    .unwrap()
                    .to_string_lossy()
                    .into_owned()
            })
            .collect()
    };
    assert_eq!(names(&merged), names(&whole));
    // (the C2 charts, C5's cost chart and C7's CPU chart draw measured times)
    for name in names(&whole).iter().filter(|n| {
        !n.starts_with("c2_") && !n.starts_with("c5b_") && !n.starts_with("c7_mode_rate_cpu")
    }) {
        let read = |d: &str| std::fs::read(dir.join(d).join(name)).unwrap();
        assert!(read("merged") == read("whole"), "{name} differs");
    }

    // an incomplete or doubled set of shards is refused, saying what is wrong
    let out = merge(&shard_dirs[..2], "incomplete");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(stderr.contains("shard 3/3 missing"), "{stderr}");
    let doubled = [shard_dirs.clone(), vec![shard_dirs[1].clone()]].concat();
    let out = merge(&doubled, "doubled");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("shard 2/3 given twice"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_shard_arguments_say_what_is_wrong() {
    let dir = std::env::temp_dir().join(format!("skinbox-report-bad-{}", std::process::id()));
    for (shard, says) in [
        ("0/3", "K is 0, outside 1 to 3 (shards count from 1)"),
        ("4/3", "K is 4, outside 1 to 3"),
        ("3", "expected K/N"),
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
            .args(["report", "--quick", "--shard", shard, "--out"])
            .arg(&dir)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{shard}");
        assert!(stderr.contains(says), "{shard}: {stderr}");
    }
    std::fs::create_dir_all(&dir).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(["report", "--merge"])
        .arg(&dir)
        .arg("--out")
        .arg(dir.join("out"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("no shard file (points-K-of-N.jsonl)"),
        "{stderr}"
    );
    std::fs::remove_dir_all(&dir).ok();
}
