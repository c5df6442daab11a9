//! Subcommands of `skinbox`: argument parsing here, the work in the library crates.

mod calibrate;
mod examples;

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
    /// Check the cell models' scenes against the papers' event rates (Fig. 8).
    Calibrate(calibrate::Args),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Examples => examples::run(cli.json),
        Command::Calibrate(args) => calibrate::run(args, cli.json),
    }
}

/// Writes `value` as pretty JSON on stdout.
pub fn print_json<T: serde::Serialize>(value: &T) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string_pretty(value)?);
    Ok(())
}
