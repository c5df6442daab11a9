//! `skinbox stats`: what the papers report about a pcap, every loss, and the host's cost.

use clap::Args;
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
    /// The cells' sample rate, for rates in % of data mode (2nd paper, Fig. 8: 125 Hz).
    #[arg(long, default_value_t = 125.0)]
    pub sample_rate_hz: f64,
    /// Also list every cell (text output; JSON always has them).
    #[arg(long)]
    pub cells: bool,
}

/// Decodes the file and prints the report.
pub fn run(args: StatsArgs, json: bool) -> anyhow::Result<()> {
    let bytes = pcap::read_file(&args.file)?;
    let options = PcapOptions {
        decoder: DecoderConfig {
            sample_rate_hz: args.sample_rate_hz,
            ..DecoderConfig::default()
        },
        udp_port: args.port,
    };
    let report = pcap::decode_pcap_with(&bytes, &options, &mut ())?;
    if json {
        return super::print_json(&report);
    }
    print!("{}", report.summary());
    if args.cells {
        for c in &report.cells {
            let rates: Vec<String> = c
                .events_per_second
                .iter()
                .map(|(m, r)| format!("{} {r:.2}", m.name()))
                .collect();
            println!(
                "cell {:5} port {:2}: {} data, {} event packets, {:.2} % of data mode, {}; {} event packets missing",
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
