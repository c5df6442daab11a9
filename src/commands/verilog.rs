//! `skinbox verilog`: the box as Verilog, optionally linted with Verilator.

use anyhow::Context;
use serde::Serialize;
use skinbox_gateware::interface_box::{verilog, BoxConfig};
use std::path::PathBuf;

/// Arguments of `skinbox verilog`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// UART ports of the box (1 to 64).
    #[arg(long, default_value_t = BoxConfig::default().ports)]
    ports: usize,
    /// Flush timeout in 8 ns ticks.
    #[arg(long, default_value_t = BoxConfig::default().flush_timeout_ticks)]
    flush_timeout_ticks: u64,
    /// Status period in 8 ns ticks.
    #[arg(long, default_value_t = BoxConfig::default().status_period_ticks)]
    status_period_ticks: u64,
    /// Box id written in every datagram.
    #[arg(long, default_value_t = BoxConfig::default().box_id)]
    box_id: u16,
    /// Output file (standard output when absent).
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Also run `verilator --lint-only -Wall` with the documented waivers.
    #[arg(long)]
    lint: bool,
}

#[derive(Serialize)]
struct Report {
    ports: usize,
    lines: usize,
    bytes: usize,
    output: Option<PathBuf>,
    lint_clean: Option<bool>,
    lint_waivers: &'static [&'static str],
}

/// Writes the Verilog.
pub fn run(args: &Args, json: bool) -> anyhow::Result<()> {
    let config = BoxConfig {
        ports: args.ports,
        flush_timeout_ticks: args.flush_timeout_ticks,
        status_period_ticks: args.status_period_ticks,
        box_id: args.box_id,
        ..BoxConfig::default()
    };
    let text = verilog(&config)?;
    if let Some(path) = &args.output {
        std::fs::write(path, &text).with_context(|| format!("writing {}", path.display()))?;
    } else if !json {
        print!("{text}");
    }
    let lint_clean = if args.lint {
        let dir = tempfile_dir()?;
        let report = skinbox_gateware::verilog::lint(&text, &dir).map_err(anyhow::Error::msg)?;
        std::fs::remove_dir_all(&dir).ok();
        if !report.clean {
            eprint!("{}", report.output);
            anyhow::bail!(
                "verilator lint found problems in the {}-port box",
                args.ports
            );
        }
        Some(true)
    } else {
        None
    };
    let report = Report {
        ports: args.ports,
        lines: text.lines().count(),
        bytes: text.len(),
        output: args.output.clone(),
        lint_clean,
        lint_waivers: skinbox_gateware::verilog::LINT_WAIVERS,
    };
    if json {
        super::print_json(&report)?;
    } else if args.output.is_some() || args.lint {
        eprintln!(
            "skinbox verilog: {} ports, {} lines{}",
            report.ports,
            report.lines,
            if args.lint { ", lint clean" } else { "" }
        );
    }
    Ok(())
}

fn tempfile_dir() -> anyhow::Result<PathBuf> {
    let dir = std::env::temp_dir().join(format!("skinbox-verilog-{}", std::process::id()));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    Ok(dir)
}
