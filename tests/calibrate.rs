//! `skinbox calibrate`: the cell models against the papers' Fig. 8 table.

use std::process::Command;

#[test]
fn calibrate_json_gives_30_seed_figures_within_the_factor_and_the_rms_errors() {
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(["calibrate", "--json"])
        .output()
        .expect("run skinbox");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let rows: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let rows = rows.as_array().unwrap();
    let seeded: Vec<_> = rows.iter().filter(|r| !r["seed"].is_null()).collect();
    assert_eq!(seeded.len(), 30);
    for r in &seeded {
        let ratio = r["model"].as_f64().unwrap() / r["seed"].as_f64().unwrap();
        assert!((0.8..=1.25).contains(&ratio), "{r}");
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
