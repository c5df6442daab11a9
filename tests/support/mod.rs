//! What the tshark tests share: a directory per test, the plugin `skinbox wireshark`
//! writes, and tshark run with it.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The `skinbox` command of this build.
pub fn skinbox() -> Command {
    Command::new(env!("CARGO_BIN_EXE_skinbox"))
}

/// A fresh directory for `test` in the system's temp directory.
pub fn temp_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("skinbox-wireshark-{}-{test}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes the plugin into `dir` with `skinbox wireshark --output`.
pub fn plugin(dir: &Path) -> PathBuf {
    let path = dir.join("skinbox.lua");
    let out = skinbox()
        .arg("wireshark")
        .arg("-o")
        .arg(&path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    path
}

/// tshark with the plugin, on a pcap; returns stdout. Lua errors fail the test.
pub fn tshark(plugin: &Path, pcap: &Path, args: &[&str]) -> String {
    let out = Command::new("tshark")
        .arg("-X")
        .arg(format!("lua_script:{}", plugin.display()))
        .args(["-n", "-r"])
        .arg(pcap)
        .args(args)
        .output()
        .expect("run tshark (scripts/test installs it)");
    let stdout = String::from_utf8(out.stdout).unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "tshark failed: {stderr}");
    assert!(
        !stdout.contains("Lua Error") && !stderr.contains("Lua Error"),
        "{stderr}\n{stdout}"
    );
    stdout
}
