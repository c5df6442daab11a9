//! `skinbox replay`: send the UDP payloads of a pcap to a socket.

use clap::Args;
use skinbox_host::pcap;
use skinbox_host::replay::{self, Pacing};
use std::net::{SocketAddr, UdpSocket};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// Arguments of `skinbox replay`.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The pcap to replay.
    pub file: PathBuf,
    /// Where to send the payloads.
    #[arg(long)]
    pub to: SocketAddr,
    /// Datagrams per second, evenly spaced (default: as recorded).
    #[arg(long, conflicts_with_all = ["speed", "unpaced"])]
    pub rate: Option<f64>,
    /// Speed factor of the recorded timing (2 = twice as fast).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Send as fast as possible.
    #[arg(long)]
    pub unpaced: bool,
    /// Only UDP datagrams from or to this port.
    #[arg(long)]
    pub port: Option<u16>,
}

/// Replays the file and prints what was sent.
pub fn run(args: ReplayArgs, json: bool) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.rate.is_none_or(|r| r > 0.0) && args.speed > 0.0,
        "--rate and --speed must be positive"
    );
    let bytes = pcap::read_file(&args.file)?;
    let (payloads, scan) = pcap::udp_payloads(&bytes, args.port)?;
    let pacing = match (args.rate, args.unpaced) {
        (Some(r), _) => Pacing::Rate {
            datagrams_per_second: r,
        },
        (None, true) => Pacing::Unpaced,
        (None, false) => Pacing::AsRecorded { speed: args.speed },
    };
    let bind: SocketAddr = if args.to.is_ipv4() {
        ([0, 0, 0, 0], 0).into()
    } else {
        (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
    };
    let socket = UdpSocket::bind(bind)?;
    let summary = replay::replay(
        &socket,
        args.to,
        payloads.iter().map(|p| (p.timestamp, p.payload.as_slice())),
        pacing,
        &AtomicBool::new(false),
    );
    if json {
        super::print_json(&serde_json::json!({
            "replay": summary,
            "frames": scan.frames,
            "bad_input": scan.bad,
            "other_traffic": scan.other,
        }))
    } else {
        println!(
            "sent {} datagrams ({} bytes) to {} in {:.3} s ({:.0}/s), {} send errors; skipped: bad input {}, other traffic {}",
            summary.datagrams,
            summary.bytes,
            args.to,
            summary.wall_s,
            summary.datagrams_per_second,
            summary.send_errors,
            scan.bad,
            scan.other
        );
        Ok(())
    }
}
