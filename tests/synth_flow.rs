//! The whole synthesis flow for a 2-port box on the Colorlight i5: yosys, nextpnr-ecp5,
//! ecppack. Takes minutes (more on the first run, which installs and compiles the tools),
//! so it runs only with the `synth-flow` feature:
//!
//! ```sh
//! scripts/synth-test    # = cargo test -p skinbox --features synth-flow --test synth_flow
//! ```

use std::process::Command;

const PORTS: usize = 2;

#[test]
fn two_port_box_synthesises_places_routes_and_meets_125_mhz() {
    let dir = std::env::temp_dir().join(format!("skinbox-synth-flow-{}", std::process::id()));
    let out = Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args([
            "synth",
            "--json",
            "--ports",
            &PORTS.to_string(),
            "--out-dir",
        ])
        .arg(&dir)
        .output()
        .expect("run skinbox synth");
    let stderr = String::from_utf8_lossy(&out.stderr);
    let report: serde_json::Value = serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("no JSON report ({e}); stderr:\n{stderr}"));

    // The report parses and its figures are plausible.
    assert_eq!(report["board"], "colorlight-i5");
    assert_eq!(report["ports"], PORTS);
    let count = |key: &str| {
        report[key]
            .as_u64()
            .unwrap_or_else(|| panic!("{key} missing"))
    };
    assert!(count("lut4") > 0);
    assert!(count("ff") > 0);
    assert!(
        count("bram") > 0,
        "the framer's payload buffers are block RAM"
    );
    assert!(count("lut4_sites") <= count("lut4_sites_available"));
    // clk25, the UART pins, TX clock, TX_CTL, 4 TX data, PHY reset, LED.
    assert_eq!(count("io"), PORTS as u64 + 9);
    assert_eq!(count("pll"), 1);
    assert_eq!(report["target_mhz"], 125.0);
    let fmax = report["fmax_mhz"].as_f64().expect("fmax_mhz");
    assert!(fmax > 1.0 && fmax < 1000.0, "{fmax}");
    assert!(!report["critical_paths"].as_array().unwrap().is_empty());

    // The bitstream is an ECP5 bitstream: a comment block, then the preamble.
    let bitstream = report["bitstream"].as_str().expect("bitstream path");
    let bits = std::fs::read(bitstream).expect("bitstream written");
    assert_eq!(&bits[..2], &[0xFF, 0x00], "comment block start");
    let preamble = [0xFF, 0xFF, 0xBD, 0xB3];
    assert!(
        bits.windows(4).take(4096).any(|w| w == preamble),
        "no ECP5 preamble FF FF BD B3 in the first 4 KiB"
    );
    // VERIFY_ID (0xE2) with the JTAG IDCODE of the LFE5U-25F, 0x41111043.
    let verify_id = [0xE2, 0x00, 0x00, 0x00, 0x41, 0x11, 0x10, 0x43];
    assert!(
        bits.windows(8).take(4096).any(|w| w == verify_id),
        "no VERIFY_ID 0x41111043 (LFE5U-25F)"
    );
    assert!(bits.len() > 100_000, "{} bytes", bits.len());

    // The issue's target: 125 MHz met, and the command says so with its exit status.
    assert!(
        report["timing_met"] == true && fmax >= 125.0,
        "125 MHz not met: Fmax {fmax:.1} MHz; critical paths: {:#}",
        report["critical_paths"]
    );
    assert!(out.status.success(), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}
