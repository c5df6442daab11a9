//! `skinbox ctl`: command a box (or `skinbox emulate`) and print its acknowledgement.

use anyhow::Context;
use skinbox_host::control::BoxClient;
use skinbox_protocol::cell_command::{
    CellCommand, CellCommandRepr, CellMode, ModalityThresholds, SampleRate, ALL_CELLS,
};
use skinbox_protocol::command::{AckResult, Destination, Request, ALL_PORTS};
use skinbox_protocol::{Channel, ChannelMask, TICKS_PER_SECOND};
use std::net::{SocketAddr, SocketAddrV4, ToSocketAddrs, UdpSocket};
use std::time::Duration;

/// Arguments of `skinbox ctl`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The box's command address, e.g. 192.0.2.10:54091 or 127.0.0.1:PORT of `skinbox emulate`.
    #[arg(long = "box")]
    box_addr: String,
    /// Local address to send from (default: any address, a free port).
    #[arg(long, default_value = "0.0.0.0:0")]
    bind: SocketAddr,
    /// Box id to address (default: any box).
    #[arg(long)]
    box_id: Option<u16>,
    /// Wait for each acknowledgement, ms.
    #[arg(long, default_value_t = 250)]
    timeout_ms: u64,
    /// Retries after the first attempt.
    #[arg(long, default_value_t = 3)]
    retries: u32,
    #[command(subcommand)]
    command: CtlCommand,
}

/// What to ask the box.
#[derive(Debug, clap::Subcommand)]
pub enum CtlCommand {
    /// A status report now; prints the box counters from the acknowledgement.
    Status,
    /// Send the box's datagrams to an address (default: to this command's own socket,
    /// see --bind).
    StreamTo {
        /// IPv4 address and UDP port to stream to.
        #[arg(long)]
        to: Option<SocketAddrV4>,
        /// Destination MAC address with --to (default ff:ff:ff:ff:ff:ff: the box has no
        /// ARP client, so a given IP needs its MAC or broadcast).
        #[arg(long, default_value = "ff:ff:ff:ff:ff:ff")]
        mac: String,
    },
    /// Set a run-time parameter: `flush-timeout-us N`, `status-period-ms N` or
    /// `sync-period-ms N` (the box's time syncs to every cell; 0: none).
    Set {
        /// `flush-timeout-us`, `status-period-ms` or `sync-period-ms`.
        parameter: String,
        /// The value.
        value: f64,
    },
    /// Read the box's tick: host send ns, box receive tick, box send tick, host receive ns.
    Time,
    /// Round trip of a status-now command, with its time.
    Ping {
        /// Round trips.
        #[arg(long, default_value_t = 4)]
        count: u32,
    },
    /// Pass a 20-byte cell-network command (hex) to one port or all.
    CellCommand {
        /// Port, or none for all ports.
        #[arg(long)]
        port: Option<u8>,
        /// The 20-byte cell command packet, 40 hex digits.
        packet: String,
    },
    /// Command the cells through the box's downlink (a cell command packet,
    /// docs/wire-format.md): mode, sample rate, thresholds, enabled channels, time sync.
    Cells {
        /// Box port (bus) to send on; default all ports.
        #[arg(long, global = true)]
        port: Option<u8>,
        /// Cell id to address (1..=16382); default every cell.
        #[arg(long, global = true)]
        cell: Option<u16>,
        #[command(subcommand)]
        command: CellsCommand,
    },
}

/// What to ask the cells.
#[derive(Debug, clap::Subcommand)]
pub enum CellsCommand {
    /// Data mode (a data packet per sample) or event mode (send-on-delta).
    Mode {
        /// `data` or `event`.
        mode: ModeArg,
    },
    /// Sample rate: 62.5, 125, 250, 500 or 1000 Hz.
    Rate {
        /// Hz.
        hz: f64,
    },
    /// Send-on-delta thresholds per modality in host units (default: Table I).
    Thresholds {
        /// Acceleration, g.
        #[arg(long, default_value_t = 0.02)]
        accel_g: f64,
        /// Force, normalised.
        #[arg(long, default_value_t = 0.001)]
        force: f64,
        /// Proximity, normalised.
        #[arg(long, default_value_t = 0.0001)]
        proximity: f64,
        /// Temperature, C.
        #[arg(long, default_value_t = 0.5)]
        temperature_c: f64,
    },
    /// Channels that send events, by name (accel_x .. temperature_2); none: no channel.
    Enable {
        /// Channel names.
        channels: Vec<String>,
    },
    /// Time sync: the box writes into it the box tick at which the packet leaves the box.
    Sync {
        /// Box tick (8 ns); the box overwrites it (send 0).
        tick: u64,
    },
}

/// `cells mode` values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ModeArg {
    /// One data packet per sample.
    Data,
    /// Send-on-delta event packets.
    Event,
}

/// The cell command packet of a `cells` command.
fn cell_command_of(cell: Option<u16>, command: &CellsCommand) -> anyhow::Result<CellCommandRepr> {
    let cell_id = match cell {
        None => ALL_CELLS,
        Some(id @ 1..=16_382) => id,
        Some(id) => anyhow::bail!("--cell {id}: cell ids are 1..=16382 (omit --cell for all)"),
    };
    let command = match command {
        CellsCommand::Mode {
            mode: ModeArg::Data,
        } => CellCommand::Mode(CellMode::Data),
        CellsCommand::Mode {
            mode: ModeArg::Event,
        } => CellCommand::Mode(CellMode::Event),
        CellsCommand::Rate { hz } => {
            CellCommand::SampleRate(SampleRate::from_hz(*hz).with_context(|| {
                format!("rate {hz} Hz: the cells run at 62.5, 125, 250, 500 or 1000 Hz")
            })?)
        }
        CellsCommand::Thresholds {
            accel_g,
            force,
            proximity,
            temperature_c,
        } => CellCommand::Thresholds(
            ModalityThresholds::from_units([*accel_g, *force, *proximity, *temperature_c])
                .context("thresholds: each must be >= 0 and at most 65535 raw steps")?,
        ),
        CellsCommand::Enable { channels } => {
            let mut mask = ChannelMask::EMPTY;
            for name in channels {
                let channel = Channel::ALL
                    .into_iter()
                    .find(|c| c.name() == name)
                    .with_context(|| {
                        format!(
                            "unknown channel {name}; channels are {}",
                            Channel::ALL.map(|c| c.name()).join(", ")
                        )
                    })?;
                mask.insert(channel);
            }
            CellCommand::EnableMask(mask)
        }
        CellsCommand::Sync { tick } => CellCommand::TimeSync { box_tick: *tick },
    };
    Ok(CellCommandRepr { cell_id, command })
}

fn parse_mac(s: &str) -> anyhow::Result<[u8; 6]> {
    let parts: Vec<&str> = s.split(':').collect();
    anyhow::ensure!(
        parts.len() == 6,
        "MAC address {s}: expected six hex bytes a:b:c:d:e:f"
    );
    let mut mac = [0u8; 6];
    for (m, p) in mac.iter_mut().zip(parts) {
        *m = u8::from_str_radix(p, 16)
            .with_context(|| format!("MAC address {s}: {p} is not a hex byte"))?;
    }
    Ok(mac)
}

fn request_of(command: &CtlCommand) -> anyhow::Result<Request> {
    Ok(match command {
        CtlCommand::Status | CtlCommand::Ping { .. } => Request::StatusNow,
        CtlCommand::Time => Request::ReadTick,
        CtlCommand::StreamTo { to: None, .. } => Request::StreamTo { to: None },
        CtlCommand::StreamTo { to: Some(to), mac } => Request::StreamTo {
            to: Some(Destination {
                mac: parse_mac(mac)?,
                ip: to.ip().octets(),
                port: to.port(),
            }),
        },
        CtlCommand::Set { parameter, value } => {
            skinbox_host::control::set_request(parameter, *value).map_err(anyhow::Error::msg)?
        }
        CtlCommand::CellCommand { port, packet } => {
            let hex = packet.trim();
            anyhow::ensure!(
                hex.len() == 40,
                "cell packet: 40 hex digits (20 bytes), got {}",
                hex.len()
            );
            let mut bytes = [0u8; 20];
            for (i, b) in bytes.iter_mut().enumerate() {
                *b = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).with_context(|| {
                    format!("cell packet: {} is not a hex byte", &hex[2 * i..2 * i + 2])
                })?;
            }
            Request::CellCommand {
                port: port.unwrap_or(ALL_PORTS),
                packet: bytes,
            }
        }
        CtlCommand::Cells {
            port,
            cell,
            command,
        } => Request::CellCommand {
            port: port.unwrap_or(ALL_PORTS),
            packet: cell_command_of(*cell, command)?.to_bytes(),
        },
    })
}

/// Runs one `ctl` command; fails when the box refuses it or does not answer.
pub fn run(args: &Args, json: bool) -> anyhow::Result<()> {
    let box_addr = args
        .box_addr
        .to_socket_addrs()
        .with_context(|| format!("--box {}", args.box_addr))?
        .find(SocketAddr::is_ipv4)
        .with_context(|| format!("--box {}: no IPv4 address", args.box_addr))?;
    let socket = UdpSocket::bind(args.bind).with_context(|| format!("binding {}", args.bind))?;
    let mut client = BoxClient::new(&socket, box_addr);
    client.timeout = Duration::from_millis(args.timeout_ms.max(1));
    client.retries = args.retries;
    if let Some(id) = args.box_id {
        client.box_id = id;
    }
    let request = request_of(&args.command)?;
    let rounds = match args.command {
        CtlCommand::Ping { count } => count.max(1),
        _ => 1,
    };
    let mut exchanges = Vec::new();
    for _ in 0..rounds {
        exchanges.push(client.send(request)?);
    }
    let refused = exchanges.iter().find(|e| e.ack.result != AckResult::Ok);
    let cell_packet = match request {
        Request::CellCommand { port, packet } => Some((port, packet)),
        _ => None,
    };
    if json {
        let mut values: Vec<_> = exchanges
            .iter()
            .map(skinbox_host::control::exchange_json)
            .collect();
        if let (Some((port, packet)), [one]) = (cell_packet, values.as_mut_slice()) {
            one["cell_packet"] = packet
                .iter()
                .map(|b| format!("{b:02X}"))
                .collect::<String>()
                .into();
            one["port"] = if port == ALL_PORTS {
                "all".into()
            } else {
                port.into()
            };
        }
        if let [one] = values.as_slice() {
            super::print_json(one)?;
        } else {
            let rtts: Vec<f64> = exchanges.iter().map(|e| e.rtt_ns as f64 / 1000.0).collect();
            super::print_json(&serde_json::json!({
                "exchanges": values,
                "rtt_us_min": rtts.iter().copied().fold(f64::INFINITY, f64::min),
                "rtt_us_max": rtts.iter().copied().fold(0.0, f64::max),
            }))?;
        }
    } else {
        for e in &exchanges {
            match args.command {
                CtlCommand::Time => println!(
                    "host send {} ns, box receive tick {}, box send tick {}, host receive {} ns (box time {:.6} s, round trip {:.1} us)",
                    e.host_send_ns,
                    e.ack.receive_tick,
                    e.ack.send_tick,
                    e.host_receive_ns,
                    e.ack.receive_tick as f64 / TICKS_PER_SECOND as f64,
                    e.rtt_ns as f64 / 1000.0
                ),
                CtlCommand::Ping { .. } => println!(
                    "ack from {} seq {}: {} in {:.1} us ({} attempt{})",
                    client.box_addr(),
                    e.ack.sequence,
                    e.ack.result.name(),
                    e.rtt_ns as f64 / 1000.0,
                    e.attempts,
                    if e.attempts == 1 { "" } else { "s" }
                ),
                _ => println!("{}", e.ack),
            }
        }
        if let CtlCommand::Cells { .. } = args.command {
            if let Some((_, packet)) = cell_packet {
                if let Ok(repr) = CellCommandRepr::parse(&packet) {
                    println!("{repr}");
                }
            }
        }
    }
    if let Some(reason) = refused.and_then(skinbox_host::control::refusal) {
        anyhow::bail!(reason);
    }
    Ok(())
}
