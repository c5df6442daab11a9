//! The `skinbox` binary as a user runs it.

use std::process::Command;

fn skinbox(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_skinbox"))
        .args(args)
        .output()
        .expect("run skinbox")
}

fn unhex(text: &str) -> Vec<u8> {
    text.split(' ')
        .map(|b| u8::from_str_radix(b, 16).expect("hex byte"))
        .collect()
}

#[test]
fn help_lists_the_subcommands() {
    let out = skinbox(&["--help"]);
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("examples"), "{text}");
    assert!(text.contains("--json"), "{text}");
}

#[test]
fn examples_json_holds_bytes_that_decode_to_what_it_says() {
    let out = skinbox(&["examples", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let examples: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let examples = examples.as_array().unwrap();
    assert_eq!(examples.len(), 6);

    let data = unhex(examples[0]["hex"].as_str().unwrap());
    assert_eq!(data.len(), 20);
    assert_eq!((data[0], data[19]), (0xA1, 0x55));
    assert_eq!(examples[0]["decoded"]["kind"], "data");
    assert_eq!(examples[0]["decoded"]["cell_id"], 17);
    // accel z raw 258 = 0x0102 at bytes 7-8
    assert_eq!(&data[7..9], &[0x01, 0x02]);
    assert_eq!(examples[0]["decoded"]["accel"][2], 258);

    let datagram = unhex(examples[4]["hex"].as_str().unwrap());
    assert_eq!(&datagram[..4], b"SK\x01\x01");
    assert_eq!(datagram.len(), 24 + 4 * 26);
    // the first record carries the data packet unchanged
    assert_eq!(&datagram[24 + 6..24 + 26], &data[..]);
    let records = examples[4]["decoded"]["body"]["entries"]
        .as_array()
        .unwrap();
    assert_eq!(records.len(), 4);

    let status = &examples[5]["decoded"]["body"];
    assert_eq!(status["kind"], "status");
    assert_eq!(
        status["entries"]["ports"][1][1], 3,
        "dropped_overflow of port 3"
    );
}

#[test]
fn unknown_subcommand_fails_with_a_message() {
    let out = skinbox(&["frobnicate"]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("frobnicate"), "{err}");
}

#[test]
fn verilog_command_writes_a_linted_box() {
    let dir = std::env::temp_dir().join(format!("skinbox-cli-verilog-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("box.v");
    let out = skinbox(&[
        "verilog",
        "--ports",
        "3",
        "-o",
        file.to_str().unwrap(),
        "--lint",
        "--json",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let report: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(report["ports"], 3);
    assert_eq!(report["lint_clean"], true);
    let text = std::fs::read_to_string(&file).unwrap();
    assert!(text.contains("module top("));
    // one UART pin per port
    for p in 0..3 {
        assert!(text.contains(&format!("uart_rx${p}")), "pin {p}");
    }
    assert!(!text.contains("uart_rx$3"));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn verilog_command_refuses_impossible_port_counts() {
    let out = skinbox(&["verilog", "--ports", "65"]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert!(err.contains("ports = 65"), "{err}");
}

#[test]
fn synth_refuses_bad_arguments_and_a_missing_python_before_running_any_tool() {
    let out = skinbox(&["synth", "--board", "ulx3s"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("colorlight-i5"), "{stderr}");

    let venv = std::env::temp_dir().join(format!("skinbox-cli-venv-{}", std::process::id()));
    let venv = venv.to_str().unwrap();
    let out = skinbox(&["synth", "--ports", "0", "--venv", venv]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("ports = 0"), "{stderr}");

    let out = skinbox(&["synth", "--sim", "--sim-window-ms", "0", "--venv", venv]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--sim-window-ms 0 must be above 0"),
        "{stderr}"
    );

    let out = skinbox(&["synth", "--venv", venv, "--python", "/nonexistent/python3"]);
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("apt-get install -y python3 python3-venv"),
        "{stderr}"
    );
    assert!(!std::path::Path::new(venv).exists());
}
