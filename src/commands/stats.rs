//! `skinbox stats`: what the papers report about a pcap, every loss, and the host's cost.

use clap::Args;
use skinbox_host::convert::CELL_IDS;
use skinbox_host::pcap::{self, PcapOptions};
use skinbox_host::DecoderConfig;
use std::path::PathBuf;

/// Arguments of `skinbox stats`.
#[derive(Debug, Args)]
pub struct StatsArgs {
    /// The pcap to read.
    pub file: PathBuf,
    /// Only UDP datagrams from or to this port.
    #[arg(long)]
    pub port: Option<u16>,
    /// The cells' sample rate, for rates in % of data mode (2nd paper, Fig. 8: 125 Hz);
    /// without it, learned from the stamps.
    #[arg(long)]
    pub sample_rate_hz: Option<f64>,
    /// The skin's cell count, the denominator of per-cell ratios; without it, the cells
    /// that sent a packet.
    #[arg(long)]
    pub cells: Option<u64>,
    /// Also list every cell (text output; JSON always has them).
    #[arg(long)]
    pub per_cell: bool,
}

/// Decodes the file and prints the report.
pub fn run(args: StatsArgs, json: bool) -> anyhow::Result<()> {
    super::check_sample_rate(args.sample_rate_hz)?;
    anyhow::ensure!(
        args.cells
            .is_none_or(|n| (1..=CELL_IDS as u64).contains(&n)),
        "--cells {} must be 1 to {CELL_IDS} (cell ids are 14 bits)",
        args.cells.unwrap_or(0)
    );
    let bytes = pcap::read_file(&args.file)?;
    let options = PcapOptions {
        decoder: DecoderConfig {
            sample_rate_hz: args.sample_rate_hz,
            cells: args.cells,
            ..DecoderConfig::default()
        },
        udp_port: args.port,
    };
    let report = pcap::decode_pcap_with(&bytes, &options, &mut ())?;
    if json {
        return super::print_json(&report);
    }
    print!("{}", report.summary());
    if args.per_cell {
        for c in &report.cells {
            let rates: Vec<String> = c
                .events_per_second
                .iter()
                .map(|(m, r)| format!("{} {r:.2}", m.name()))
                .collect();
            println!(
                "box {}{} cell {:5} port {:2}: {} data, {} event packets, {:.2} % of data mode, {}; {} event packets missing",
                c.box_id,
                c.source.map(|a| format!(" at {a}")).unwrap_or_default(),
                c.cell_id,
                c.port,
                c.data_packets,
                c.event_packets,
                c.packet_rate_percent_of_data_mode,
                rates.join(", "),
                c.event_packets_missing
            );
        }
    }
    Ok(())
}
