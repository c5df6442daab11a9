//! `skinbox synth`: the box with its board top through yosys, nextpnr-ecp5 and ecppack.

use skinbox::studies::Shard;
use skinbox_gateware::board::Board;
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_synth::{Event, FlowOptions, SeedShard, Stage, SynthReport, Toolchain};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `skinbox synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Board: colorlight-i5 (LFE5U-25F) or colorlight-i9 (LFE5U-45F, same pinout).
    #[arg(long, default_value = "colorlight-i5", value_parser = parse_board)]
    board: Board,
    /// UART ports of the box (1 to 64).
    #[arg(long, default_value_t = BoxConfig::default().ports)]
    ports: usize,
    /// nextpnr placer seed (the first, with --seeds).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Place and route with this many seeds (--seed and up) and keep the fastest
    /// placement; every seed's Fmax is reported.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u64).range(1..=64))]
    seeds: u64,
    /// Directory for the run's files (default: build/synth/BOARD-Np).
    #[arg(long)]
    out_dir: Option<PathBuf>,
    /// The venv with the tools; created and filled with pip when missing.
    #[arg(long)]
    venv: Option<PathBuf>,
    /// Python interpreter that creates the venv.
    #[arg(long, default_value = "python3")]
    python: String,
    /// Place and route only share K of N of the --seeds sweep (seeds --seed + i with
    /// i % N = K - 1) and write their Fmax to OUT_DIR/seeds-K-of-N.json, for --merge.
    #[arg(long, value_name = "K/N", conflicts_with = "merge")]
    shard: Option<Shard>,
    /// Merge the shards of a seed sweep from these directories (each a shard's --out-dir):
    /// the fastest placement is packed and reported, with every seed's Fmax.
    #[arg(long, value_name = "DIR", num_args = 1..,
          conflicts_with_all = ["board", "ports", "seed", "seeds"])]
    merge: Vec<PathBuf>,
    /// Then simulate the synthesised netlist (Verilator, yosys' ECP5 cell models) under a
    /// short scene and compare its RGMII frames with the RTL co-simulation's byte for byte;
    /// also checks the PHY reset, the LED and the MDIO sequence.
    #[arg(long, conflicts_with = "shard")]
    sim: bool,
    /// Instead of the flow: yosys alone with each of the box's blocks kept apart, and each
    /// block's LUT4, carry, flip-flop and block RAM cells printed with the network part's
    /// sum (no placement; OUT_DIR/blocks-stat.json).
    #[arg(long, conflicts_with_all = ["shard", "merge", "sim", "seeds"])]
    blocks: bool,
    /// Scene window of --sim, ms.
    #[arg(long, default_value_t = skinbox_synth::netlist_sim::DEFAULT_WINDOW_NS as f64 / 1e6,
          requires = "sim")]
    sim_window_ms: f64,
}

fn parse_board(name: &str) -> Result<Board, String> {
    Board::from_name(name).ok_or_else(|| {
        let names: Vec<_> = Board::ALL.iter().map(|b| b.name()).collect();
        format!("unknown board {name:?}; boards: {}", names.join(", "))
    })
}

/// `$SKINBOX_BUILD_DIR`, else `build/` in the workspace (as the co-simulation's cache).
fn build_dir() -> PathBuf {
    std::env::var_os("SKINBOX_BUILD_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("build"))
}

/// The flow's options from the arguments, refused before any tool runs; the shards to merge.
fn flow_options(
    args: &Args,
    build: &Path,
) -> anyhow::Result<(FlowOptions, Vec<(PathBuf, SeedShard)>)> {
    let config = BoxConfig {
        ports: args.ports,
        ..BoxConfig::default()
    };
    config.validate().map_err(anyhow::Error::msg)?;
    // refused before any tool runs
    if !(args.sim_window_ms > 0.0 && args.sim_window_ms <= 1000.0) {
        anyhow::bail!(
            "--sim-window-ms {} must be above 0 and at most 1000",
            args.sim_window_ms
        );
    }
    let default_out =
        |board: &str, ports: usize| build.join("synth").join(format!("{board}-{ports}p"));
    let shards = if args.merge.is_empty() {
        Vec::new()
    } else {
        skinbox_synth::read_seed_shards(&args.merge)?
    };
    let options = FlowOptions {
        board: args.board,
        config,
        out_dir: args
            .out_dir
            .clone()
            .unwrap_or_else(|| match shards.first() {
                Some((_, s)) => default_out(&s.board, s.ports),
                None => default_out(args.board.name(), args.ports),
            }),
        seed: args.seed,
        seeds: args.seeds,
    };
    if let Some(shard) = args.shard {
        if u64::from(shard.count) > args.seeds {
            anyhow::bail!(
                "--shard {shard} of --seeds {}: at most {} shards, one seed each",
                args.seeds,
                args.seeds
            );
        }
    }
    Ok((options, shards))
}

/// The spinner that shows the flow's stage and its latest tool line.
fn spinner() -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new_spinner();
    bar.set_style(
        indicatif::ProgressStyle::with_template("{spinner} {prefix} [{elapsed}] {wide_msg}")
            .expect("valid template"),
    );
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    bar
}

/// With `--sim`: the netlist of the report simulated against the RTL.
fn simulate_netlist(
    args: &Args,
    toolchain: &Toolchain,
    report: &SynthReport,
) -> anyhow::Result<Option<skinbox_synth::netlist_sim::NetlistSimReport>> {
    if !args.sim {
        return Ok(None);
    }
    let board = Board::from_name(&report.board)
        .ok_or_else(|| anyhow::anyhow!("unknown board {}", report.board))?;
    let config = BoxConfig {
        ports: report.ports,
        ..BoxConfig::default()
    };
    let spec =
        skinbox_synth::netlist_sim::scene_spec(config, (args.sim_window_ms * 1e6).round() as u64)?;
    eprintln!(
        "skinbox synth: simulating the netlist (Verilator build, then {:.1} ms of PHY reset and scene) and the RTL",
        (skinbox_gateware::board::PHY_RESET_CLOCKS as f64 * 8e-6) + spec.duration_ns as f64 * 1e-6
    );
    Ok(Some(skinbox_synth::netlist_sim::simulate(
        toolchain,
        board,
        &spec,
        &report.out_dir,
    )?))
}

/// Prints the report (and the netlist simulation); fails when the netlist or the clock does
/// not hold.
fn finish(
    report: &SynthReport,
    netlist_sim: Option<&skinbox_synth::netlist_sim::NetlistSimReport>,
    json: bool,
) -> anyhow::Result<()> {
    if json {
        let mut value = serde_json::to_value(report)?;
        if let Some(sim) = netlist_sim {
            value["netlist_matches_rtl"] = sim.netlist_matches_rtl.into();
            value["frames_compared"] = sim.frames_compared.into();
            value["simulated_ms"] = sim.simulated_ms.into();
            value["netlist_sim"] = serde_json::to_value(sim)?;
        }
        super::print_json(&value)?;
    } else {
        print_report(report);
        if let Some(sim) = netlist_sim {
            print_netlist_sim(sim);
        }
    }
    if let Some(sim) = netlist_sim {
        if !sim.netlist_matches_rtl {
            anyhow::bail!(
                "the netlist does not behave as the RTL: {} of {} frames differ ({}); PHY reset {}, LED {}, MDIO {} (files in {})",
                sim.frames_differing,
                sim.frames_compared,
                sim.first_difference.as_deref().unwrap_or("frames equal"),
                ok(sim.phy_reset_ok),
                ok(sim.led_ok),
                ok(sim.mdio_ok),
                sim.dir.display()
            );
        }
    }
    if !report.timing_met {
        anyhow::bail!(
            "timing not met: the {} MHz box clock reaches {:.1} MHz, the PHY receive clock \
             {:?} MHz after place and route (bitstream written anyway; critical paths in {})",
            report.target_mhz,
            report.fmax_mhz,
            report.rx_clock_fmax_mhz,
            report.out_dir.join("report.json").display()
        );
    }
    Ok(())
}

/// Runs the flow; fails after printing the report when the box clock is not met.
pub fn run(args: &Args, json: bool) -> anyhow::Result<()> {
    let build = build_dir();
    let (options, shards) = flow_options(args, &build)?;
    let toolchain = Toolchain::at(args.venv.clone().unwrap_or(build.join("synth-venv")));

    let bar = spinner();
    let mut stage_started = Instant::now();
    let mut progress = |event: Event<'_>| match event {
        Event::Stage(stage) => {
            let since = stage_started.elapsed().as_secs_f64();
            stage_started = Instant::now();
            bar.suspend(|| eprintln!("skinbox synth: {} (+{since:.0} s)", stage.describe()));
            bar.set_prefix(stage.describe());
            bar.set_message("");
            bar.reset_elapsed();
        }
        Event::Line(line) => bar.set_message(line.trim().to_string()),
    };

    if !toolchain.is_installed() {
        progress(Event::Stage(Stage::Install));
        let started = Instant::now();
        toolchain
            .install(&args.python, &mut |line| progress(Event::Line(line)))
            .map_err(anyhow::Error::new)?;
        bar.suspend(|| {
            eprintln!(
                "skinbox synth: tools installed into {} in {:.0} s",
                toolchain.venv().display(),
                started.elapsed().as_secs_f64()
            )
        });
    }
    if args.blocks {
        let blocks = skinbox_synth::blocks::run(&toolchain, &options, &mut progress);
        bar.finish_and_clear();
        return print_blocks(&blocks?, json);
    }
    let report = match args.shard {
        Some(shard) => {
            let result = skinbox_synth::run_shard(
                &toolchain,
                &options,
                shard.index,
                shard.count,
                &mut progress,
            );
            bar.finish_and_clear();
            return print_shard(&result?, &options.out_dir, json);
        }
        None if !shards.is_empty() => {
            skinbox_synth::merge(&toolchain, &shards, &options.out_dir, &mut progress)
        }
        None => skinbox_synth::run(&toolchain, &options, &mut progress),
    };
    bar.finish_and_clear();
    let report = report.map_err(anyhow::Error::new)?;
    let netlist_sim = simulate_netlist(args, &toolchain, &report)?;
    finish(&report, netlist_sim.as_ref(), json)
}

fn print_shard(shard: &SeedShard, dir: &Path, json: bool) -> anyhow::Result<()> {
    if json {
        return super::print_json(shard);
    }
    let each: Vec<String> = shard
        .tried
        .iter()
        .map(|s| format!("{}: {:.1}", s.seed, s.fmax_mhz))
        .collect();
    println!(
        "shard {}/{} of seeds {} to {}: {} MHz; wrote {} (merge with --merge)",
        shard.shard,
        shard.shards,
        shard.first_seed,
        shard.first_seed + shard.seeds - 1,
        each.join(", "),
        dir.join(SeedShard::file_name(shard.shard, shard.shards))
            .display()
    );
    Ok(())
}

fn ok(good: bool) -> &'static str {
    if good {
        "as designed"
    } else {
        "WRONG"
    }
}

fn print_netlist_sim(s: &skinbox_synth::netlist_sim::NetlistSimReport) {
    println!(
        "  netlist {} of {} frames equal to the RTL's ({} from the netlist), {:.2} ms simulated ({} clocks): {}",
        s.frames_compared - s.frames_differing.min(s.frames_compared),
        s.frames_compared,
        s.frames_netlist,
        s.simulated_ms,
        s.clocks,
        if s.netlist_matches_rtl { "matches" } else { "DIFFERS" }
    );
    println!(
        "          PHY reset {} clocks ({}), LED {}, MDIO {} ({} writes, {} reads)",
        s.phy_reset_clocks,
        ok(s.phy_reset_ok),
        ok(s.led_ok),
        ok(s.mdio_ok),
        s.mdio_writes.len(),
        s.mdio_reads.len()
    );
    println!(
        "          wall: Verilator build {:.0} s, netlist {:.1} s, RTL {:.1} s",
        s.build_seconds, s.netlist_seconds, s.rtl_seconds
    );
}

fn percent(used: u64, available: u64) -> f64 {
    if available == 0 {
        0.0
    } else {
        100.0 * used as f64 / available as f64
    }
}

fn print_report(r: &SynthReport) {
    println!("{} ({}), {} ports", r.board, r.part, r.ports);
    println!(
        "  LUT4    {} logic LUT4 + {} CCU2C + {} DPR16X4; {} of {} LUT4 sites ({:.1} %)",
        r.lut4,
        r.ccu2c,
        r.dpram16x4,
        r.lut4_sites,
        r.lut4_sites_available,
        percent(r.lut4_sites, r.lut4_sites_available)
    );
    println!(
        "  FF      {} of {} ({:.1} %)",
        r.ff,
        r.ff_available,
        percent(r.ff, r.ff_available)
    );
    println!("  BRAM    {} of {} DP16KD", r.bram, r.bram_available);
    println!("  IO      {} of {}", r.io, r.io_available);
    println!(
        "  Fmax    {:.1} MHz for the {} MHz box clock: {}",
        r.fmax_mhz,
        r.target_mhz,
        if r.timing_met { "met" } else { "NOT MET" }
    );
    if let Some(rx) = r.rx_clock_fmax_mhz {
        println!("  Fmax    {rx:.1} MHz for the 125 MHz PHY receive clock");
    }
    for path in &r.critical_paths {
        println!(
            "  path    {:.2} ns ({:.2} ns routing, {} logic levels) {} -> {}: {}",
            path.delay_ns,
            path.routing_ns,
            path.logic_levels,
            path.from_clock,
            path.to_clock,
            path.blocks.join(" -> ")
        );
    }
    if r.seeds.len() > 1 {
        let each: Vec<String> = r
            .seeds
            .iter()
            .map(|s| format!("{}: {:.1}", s.seed, s.fmax_mhz))
            .collect();
        println!("  seeds   {} MHz; kept seed {}", each.join(", "), r.seed);
    }
    let statically: Vec<String> = r
        .seeds
        .iter()
        .filter(|s| s.placer == skinbox_synth::Placer::Static)
        .map(|s| s.seed.to_string())
        .collect();
    if !statically.is_empty() {
        println!(
            "  placer  static for seed {} (HeAP's legaliser found no legal placement)",
            statically.join(", ")
        );
    }
    println!("  bits    {}", r.bitstream.display());
    println!(
        "  time    yosys {:.0} s, nextpnr {:.0} s, ecppack {:.0} s, total {:.0} s",
        r.seconds.yosys, r.seconds.nextpnr, r.seconds.ecppack, r.seconds.total
    );
}

/// Prints `skinbox synth --blocks`: a table, or JSON with the network part's sum.
fn print_blocks(blocks: &[skinbox_synth::blocks::BlockUse], json: bool) -> anyhow::Result<()> {
    use skinbox_synth::blocks::{BlockUse, NETWORK_BLOCKS};
    let network = BlockUse::total(
        "network part",
        blocks
            .iter()
            .filter(|b| NETWORK_BLOCKS.contains(&b.block.as_str())),
    );
    let all = BlockUse::total("all blocks", blocks);
    if json {
        let value = serde_json::json!({ "blocks": blocks, "network": network, "all": all });
        println!("{}", serde_json::to_string_pretty(&value)?);
        return Ok(());
    }
    println!(
        "{:<24} {:>6} {:>6} {:>6} {:>7} {:>6}",
        "block", "LUT4", "CCU2C", "FF", "DP16KD", "DPRAM"
    );
    for b in blocks.iter().chain([&network, &all]) {
        let mark = if NETWORK_BLOCKS.contains(&b.block.as_str()) {
            "*"
        } else {
            " "
        };
        println!(
            "{:<24} {:>6} {:>6} {:>6} {:>7} {:>6}",
            format!("{}{mark}", b.block),
            b.lut4,
            b.ccu2c,
            b.ff,
            b.dp16kd,
            b.dpram
        );
    }
    println!("(* the network part; each block optimised on its own)");
    Ok(())
}
