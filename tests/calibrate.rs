//! `skinbox calibrate`: the cell models against the papers' Fig. 8 table.

use std::process::Command;

#[test]
fn calibrate_json_gives_30_seed_figures_within_3_percent_and_the_rms_errors() {
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(["calibrate", "--json"])
        .output()
        .expect("run skinbox");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(doc["pass"], true);
    assert_eq!(doc["compared"].as_u64(), Some(30));
    assert_eq!(doc["outside"].as_u64(), Some(0));
    let rows = doc["figures"].as_array().unwrap();
    let seeded: Vec<_> = rows.iter().filter(|r| !r["seed"].is_null()).collect();
    assert_eq!(seeded.len(), 30);
    for r in &seeded {
        let ratio = r["model"].as_f64().unwrap() / r["seed"].as_f64().unwrap();
        assert!((0.97..=1.03).contains(&ratio), "{r}");
        assert!((r["ratio"].as_f64().unwrap() - ratio).abs() < 1e-12, "{r}");
        assert_eq!(r["pass"], true);
    }
    let idle_prox = seeded
        .iter()
        .find(|r| r["scene"] == "idle" && r["quantity"] == "events_per_cell_s_proximity")
        .unwrap();
    assert_eq!(idle_prox["seed"].as_f64(), Some(4.17));
    let rms: Vec<_> = rows
        .iter()
        .filter(|r| {
            r["quantity"]
                .as_str()
                .unwrap()
                .starts_with("rms_error_pct_")
        })
        .collect();
    assert_eq!(rms.len(), 6 * 9);
    assert!(rms.iter().all(|r| r["seed"].is_null()));
    assert!(rms.iter().all(|r| r["model"].as_f64().unwrap() < 0.5));
    let text = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(["calibrate", "--scenes", "no/such/dir"])
        .output()
        .unwrap();
    assert!(!text.status.success());
    let err = String::from_utf8_lossy(&text.stderr);
    assert!(err.contains("no/such/dir/idle.toml: cannot read"), "{err}");
}

/// A copy of the scenes with `edit` applied to one file.
fn scenes_with(name: &str, edit: impl Fn(String) -> String) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("skinbox-calibrate-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let source = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("cosim/scenes");
    for entry in std::fs::read_dir(&source).unwrap() {
        let path = entry.unwrap().path();
        let mut text = std::fs::read_to_string(&path).unwrap();
        if path.file_stem().unwrap() == "idle" {
            text = edit(text);
        }
        std::fs::write(dir.join(path.file_name().unwrap()), text).unwrap();
    }
    dir
}

fn calibrate_in(dir: &std::path::Path) -> (bool, serde_json::Value, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(["calibrate", "--json", "--scenes"])
        .arg(dir)
        .output()
        .unwrap();
    (
        out.status.success(),
        serde_json::from_slice(&out.stdout).unwrap_or_default(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_scene_pushed_outside_its_band_fails_and_one_at_another_rate_is_refused() {
    // the same files pass
    let same = scenes_with("same", |t| t);
    let (ok, doc, err) = calibrate_in(&same);
    assert!(ok && doc["pass"] == true, "{err}");
    // idle's proximity threshold halved: its proximity events and packets rise
    let pushed = scenes_with("pushed", |t| {
        t.replace("proximity = 0.0001", "proximity = 0.00005")
    });
    let (ok, doc, err) = calibrate_in(&pushed);
    assert!(!ok, "a scene outside its band must fail");
    assert_eq!(doc["pass"], false);
    assert!(err.contains("outside 3 % of Fig. 8"), "{err}");
    let failed: Vec<&str> = doc["figures"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|f| f["pass"] == false)
        .map(|f| f["quantity"].as_str().unwrap())
        .collect();
    assert!(
        failed.contains(&"events_per_cell_s_proximity"),
        "{failed:?}"
    );
    assert!(
        doc["figures"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|f| f["pass"] == false)
            .all(|f| f["scene"] == "idle"),
        "{doc}"
    );
    // a scene at 250 Hz cannot be compared with the 125 Hz table
    let fast = scenes_with("fast", |t| {
        t.replace("sample_rate_hz = 125.0", "sample_rate_hz = 250.0")
    });
    let (ok, _, err) = calibrate_in(&fast);
    assert!(!ok);
    assert!(
        err.contains("idle runs at 250 Hz") && err.contains("125 Hz, event mode, 260 cells"),
        "{err}"
    );
    for dir in [same, pushed, fast] {
        std::fs::remove_dir_all(dir).ok();
    }
}

/// `--through-box`: each seed scene through the box's reference model and the host
/// decoder. Over a 1 s window the host's figures are those `skinbox sim` decodes of the
/// same window, beside the cells' figures, each with its own verdict.
#[test]
fn through_box_gives_the_hosts_figures_beside_the_cells() {
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args([
            "calibrate",
            "--json",
            "--through-box",
            "--box-window-s",
            "1",
        ])
        .output()
        .unwrap();
    let doc: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = doc["figures"].as_array().unwrap();
    let with_host: Vec<_> = rows.iter().filter(|r| !r["host"].is_null()).collect();
    assert_eq!(with_host.len(), 30);
    let mut outside = 0;
    for r in &with_host {
        let ratio = r["host"].as_f64().unwrap() / r["seed"].as_f64().unwrap();
        assert!(
            (r["host_ratio"].as_f64().unwrap() - ratio).abs() < 1e-12,
            "{r}"
        );
        let pass = (ratio - 1.0).abs() <= 0.03;
        assert_eq!(r["host_pass"], pass, "{r}");
        outside += usize::from(!pass);
        // the cells' own verdict is still there
        assert_eq!(r["pass"], true, "{r}");
    }
    assert_eq!(doc["compared"], 60);
    assert_eq!(doc["outside"], outside);
    assert_eq!(out.status.success(), outside == 0);

    // The same window through `skinbox sim`: the same host figures.
    let pcap = std::env::temp_dir().join(format!("skinbox-calibrate-{}.pcap", std::process::id()));
    let sim = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args([
            "sim",
            "idle",
            "--fidelity",
            "reference",
            "--from-ms",
            "1000",
        ])
        .args(["--duration-ms", "1000", "--json", "--pcap"])
        .arg(&pcap)
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let sim: serde_json::Value = serde_json::from_slice(&sim.stdout).unwrap();
    let host = &sim["host"];
    let figure = |q: &str| {
        with_host
            .iter()
            .find(|r| r["scene"] == "idle" && r["quantity"] == q)
            .unwrap()["host"]
            .as_f64()
            .unwrap()
    };
    for m in ["acceleration", "force", "proximity", "temperature"] {
        let want = host["events_per_cell_per_second"][m].as_f64().unwrap();
        assert!(
            (figure(&format!("events_per_cell_s_{m}")) - want).abs() < 1e-9,
            "{m}"
        );
    }
    let want = host["event_packet_rate_percent_of_data_mode"]
        .as_f64()
        .unwrap();
    assert!((figure("packet_rate_pct") - want).abs() < 1e-9);
}
