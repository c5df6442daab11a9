//! Verilog output of the box and its lint check with Verilator.

use std::path::Path;
use std::process::Command;

/// Verilator warnings waived for rust-hdl's output, each for a reason that lies in the
/// generator, not in the design:
/// - `WIDTH`: rust-hdl writes every literal 32 bits wide (`32'd5` compared with a 6-bit
///   signal); the values always fit.
/// - `DECLFILENAME`: rust-hdl names submodules after their path, not their file.
/// - `UNUSEDSIGNAL`: the one stream interface carries `last` and `error` to every sink; the
///   framer counts record beats and never gets an erroneous record, so it reads neither.
/// - `UNUSEDPARAM`: rust-hdl emits a `localparam` for every state of a `LogicState` enum.
///
/// `UNOPTFLAT` is not waived: rust-hdl writes each module's logic as one `always @(*)`
/// block, so a block that drives a submodule's input and reads its output combinationally
/// looks like a loop to Verilator (which then settles it by iteration, slowly). The design
/// has none: the CRC works on a registered byte, the store's `ready` to each deframer is a
/// register bit, and its output `valid` is computed apart from the framer's `ready`.
pub const LINT_WAIVERS: &[&str] = &["WIDTH", "DECLFILENAME", "UNUSEDSIGNAL", "UNUSEDPARAM"];

/// What Verilator said.
#[derive(Debug, Clone)]
pub struct LintReport {
    /// No warning and no error.
    pub clean: bool,
    /// Verilator's messages.
    pub output: String,
}

/// Writes `verilog` to `dir/top.v` and runs `verilator --lint-only -Wall` on it with the
/// waivers. Fails when Verilator cannot be run.
pub fn lint(verilog: &str, dir: &Path) -> Result<LintReport, String> {
    let file = dir.join("top.v");
    std::fs::write(&file, verilog).map_err(|e| format!("writing {}: {e}", file.display()))?;
    let mut command = Command::new("verilator");
    command.args(["--lint-only", "-Wall", "--top-module", "top"]);
    for waiver in LINT_WAIVERS {
        command.arg(format!("-Wno-{waiver}"));
    }
    let out = command.arg(&file).output().map_err(|e| {
        format!("cannot run verilator ({e}): install it with 'apt-get install -y verilator' (scripts/test does)")
    })?;
    let output =
        String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    Ok(LintReport {
        clean: out.status.success() && !output.contains("%Warning"),
        output,
    })
}
