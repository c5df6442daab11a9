//! Subcommands of `skinbox`: argument parsing here, the work in the library crates.

mod bench;
mod calibrate;
mod capture;
mod ctl;
mod decode;
mod emulate;
mod examples;
mod replay;
mod report;
mod ros;
mod sim;
mod stats;
mod synth;
mod verilog;
mod wireshark;

use clap::{Parser, Subcommand};

/// Gateware, co-simulation and host client of the skin interface box.
#[derive(Debug, Parser)]
#[command(name = "skinbox", version, about, long_about = None)]
pub struct Cli {
    /// Print results as JSON (one document on stdout) for scripts.
    #[arg(long, global = true)]
    pub json: bool,
    #[command(subcommand)]
    pub command: Command,
}

/// What to do.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Show example cell packets and box datagrams, as bytes and decoded.
    Examples,
    /// Write the interface box's Verilog (top module `top`).
    Verilog(verilog::Args),
    /// Play a scene through the co-simulated box (Verilator) to a pcap and a decoded report.
    Sim(sim::Args),
    /// Receive the box's datagrams live on a UDP socket; optionally record a pcap.
    Capture(capture::CaptureArgs),
    /// Command a box: status, stream-to, set, time, ping (waits for the acknowledgement).
    Ctl(ctl::Args),
    /// A box on a UDP socket without a board: the reference model plays a scene in real
    /// time and answers commands as the box does.
    Emulate(emulate::Args),
    /// Send the UDP payloads of a pcap to a socket, at a rate or as recorded.
    Replay(replay::ReplayArgs),
    /// Decode a pcap to cell packets or full samples (CSV or JSON lines).
    Decode(decode::DecodeArgs),
    /// Report rates, losses, box counters and host cost of a pcap.
    Stats(stats::StatsArgs),
    /// Benchmarks: `skinbox bench <what>`.
    #[command(subcommand)]
    Bench(bench::BenchCommand),
    /// Check the cell models' scenes against the papers' event rates (Fig. 8).
    Calibrate(calibrate::Args),
    /// Run the studies (speed against accuracy, failure boundaries): charts and a summary.
    Report(report::Args),
    /// Synthesise the box for an ECP5 board: resources, Fmax and a bitstream.
    Synth(synth::Args),
    /// Write the Wireshark dissector of every skinbox datagram (Lua), or install it.
    Wireshark(wireshark::Args),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Examples => examples::run(cli.json),
        Command::Verilog(args) => verilog::run(&args, cli.json),
        Command::Sim(args) => sim::run(&args, cli.json),
        Command::Capture(args) => capture::run(args, cli.json),
        Command::Ctl(args) => ctl::run(&args, cli.json),
        Command::Emulate(args) => emulate::run(&args, cli.json),
        Command::Replay(args) => replay::run(args, cli.json),
        Command::Decode(args) => decode::run(args, cli.json),
        Command::Stats(args) => stats::run(args, cli.json),
        Command::Bench(what) => bench::run(what, cli.json),
        Command::Calibrate(args) => calibrate::run(args, cli.json),
        Command::Report(args) => report::run_report(&args, cli.json),
        Command::Synth(args) => synth::run(&args, cli.json),
        Command::Wireshark(args) => wireshark::run(&args, cli.json),
    }
}

/// Writes `value` as pretty JSON on stdout.
pub fn print_json<T: serde::Serialize>(value: &T) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string_pretty(value)?);
    Ok(())
}

/// Refuses a `--sample-rate-hz` that no cell runs at.
pub(crate) fn check_sample_rate(rate: Option<f64>) -> anyhow::Result<()> {
    if let Some(rate) = rate {
        anyhow::ensure!(
            rate.is_finite() && rate > 0.0 && rate <= 10_000.0,
            "--sample-rate-hz {rate} must be above 0 and at most 10000"
        );
    }
    Ok(())
}

/// Arguments of the sample-time estimate (docs/time.md), shared by `decode` and `capture`.
#[derive(Debug, Clone, clap::Args)]
pub struct TimingArgs {
    /// Cells per bus, numbered from 1 along the chains, root first (the scenes' layout):
    /// gives each cell's hops to its root, and so its path latency. Without it every cell
    /// counts as a root (path latency: the processing time only).
    #[arg(long)]
    pub cells_per_bus: Option<u16>,
    /// Relay delay per cell on the way to the root, ns (the bus model's 52 us).
    #[arg(long, default_value_t = skinbox_host::sample_clock::HOP_LATENCY_NS)]
    pub hop_latency_ns: u64,
    /// A cell's processing before its packet leaves, ns (the bus model's 20 us).
    #[arg(long, default_value_t = skinbox_host::sample_clock::PROCESSING_NS)]
    pub processing_ns: u64,
    /// Take every cell as sampling on the box's time grid (docs/time.md method c): a
    /// sample's time is the grid point its stamp less the path latency falls on. Without
    /// it, or `--estimated`, a box's records are synced once its status datagrams say it
    /// sends time syncs, and estimated from each cell's stamps (method b) otherwise.
    #[arg(long, conflicts_with = "estimated")]
    pub synced: bool,
    /// Estimate every sample time from the cells' stamps (method b), whatever the boxes
    /// say.
    #[arg(long)]
    pub estimated: bool,
}

impl TimingArgs {
    /// The timing of cells sampling at `sample_rate_hz`.
    pub fn timing(&self, sample_rate_hz: f64) -> anyhow::Result<skinbox_host::timing::Timing> {
        use skinbox_host::sample_clock::{PathModel, Positions};
        anyhow::ensure!(
            self.cells_per_bus != Some(0),
            "--cells-per-bus must be at least 1"
        );
        let hops = match self.cells_per_bus {
            Some(n) => Positions::Numbered { cells_per_bus: n },
            None => Positions::Unknown,
        };
        let timing = skinbox_host::timing::Timing::new(
            sample_rate_hz,
            PathModel {
                processing_ns: self.processing_ns,
                hop_latency_ns: self.hop_latency_ns,
                hops,
            },
        );
        use skinbox_host::timing::SampleTimeMode;
        Ok(timing.with_mode(if self.synced {
            SampleTimeMode::Synced
        } else if self.estimated {
            SampleTimeMode::Estimated
        } else {
            SampleTimeMode::Auto
        }))
    }
}

/// One line on how the records' sample times were found, with a note where a box's
/// status did not say it sends time syncs (the estimate, method b, is the fallback).
pub fn sample_method_line(counts: skinbox_host::timing::SampleMethodCounts) -> String {
    let mut line = format!(
        "{} synced to the box's grid (c, bound {:.1} us), {} estimated from stamps (b)",
        counts.synced,
        skinbox_host::timing::SYNCED_SAMPLE_BOUND_NS / 1e3,
        counts.estimated
    );
    if counts.estimated > 0 {
        line += "; note: estimated records are those of boxes that did not say they send time \
                 syncs (or before their first status datagram): their bounds are the bus's \
                 queueing, up to 1.6 ms";
    }
    line
}

/// One line on how each box's time was mapped to host time.
pub fn host_time_line(times: &[skinbox_host::timing::BoxTimeSummary]) -> String {
    if times.is_empty() {
        return "none (no receive timestamps, no exchanges)".into();
    }
    times
        .iter()
        .map(|t| {
            let at = t.address.map(|a| format!(" at {a}")).unwrap_or_default();
            let mut s = format!("box {}{at} from {}", t.box_id, t.source.name());
            if let Some(d) = t.drift_ppm {
                s += &format!(", drift {d:.1} ppm");
            }
            match t.error_bound_ns {
                Some(b) => s += &format!(", bound {:.1} us", b / 1e3),
                None => s += ", late by the shortest delivery delay (no bound)",
            }
            if t.restarts > 0 {
                s += &format!(", restarted {} times (box resets)", t.restarts);
            }
            s
        })
        .collect::<Vec<_>>()
        .join("; ")
}
