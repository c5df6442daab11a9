//! `skinbox emulate`: a box on a UDP socket, without a board: the box's reference model
//! playing a scene in real time, its control model answering commands, and the scene's
//! cells obeying the cell commands its downlink sends them.

use anyhow::Context;
use skinbox_emulator::{self as emulator, EmulatorSettings, ServeSummary};
use std::net::{SocketAddrV4, UdpSocket};
use std::time::{Duration, Instant};

/// Arguments of `skinbox emulate`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene: a built-in scene's name or a scene file (default stroking_upper_arm).
    scene: Option<String>,
    /// Address the box listens on for commands and sends from (IPv4), e.g. 127.0.0.1:54091.
    #[arg(long)]
    listen: SocketAddrV4,
    /// Scene time per wall-clock time (2 plays the scene twice as fast).
    #[arg(long, default_value_t = 1.0)]
    speed: f64,
    /// Scene time at which the box starts to listen, ms (default: after the warm-up).
    #[arg(long, default_value_t = 1000.0)]
    from_ms: f64,
    /// Scene time the cells send, ms; after it the box goes on with status reports only.
    #[arg(long, default_value_t = 10_000.0)]
    duration_ms: f64,
    /// Number of buses, one box port each (overrides the scene).
    #[arg(long)]
    buses: Option<usize>,
    /// Number of cells (overrides the scene).
    #[arg(long)]
    cells: Option<usize>,
    /// Flush timeout after reset, us.
    #[arg(long, default_value_t = 100.0)]
    flush_timeout_us: f64,
    /// Status period after reset, ms.
    #[arg(long, default_value_t = 100.0)]
    status_period_ms: f64,
    /// Sync period after reset, ms: the box's own time syncs to every cell (0, the
    /// default: none; else at least 1). The emulated cells are generated again over the
    /// whole scene at each sync they hear: at 100 ms a large scene falls behind real time.
    #[arg(long, default_value_t = 0.0)]
    sync_period_ms: f64,
    /// The host subnet commands are taken from (IPv4 address/prefix length).
    #[arg(long, default_value = "127.0.0.0/8")]
    host_subnet: String,
    /// Box id.
    #[arg(long, default_value_t = 1)]
    box_id: u16,
    /// Stop after this much wall-clock time, ms (default: at Ctrl-C); then print a summary.
    #[arg(long)]
    run_ms: Option<u64>,
    /// Watch the skin live: a capture in this process claims the box's stream and serves
    /// the ROS 2 topics to Foxglove on this address (ws://ADDR; docs/ros2.md).
    #[arg(long, value_name = "ADDR")]
    foxglove: Option<std::net::SocketAddr>,
    /// Publish the ROS 2 topics over DDS (a capture in this process claims the box's
    /// stream, as with --foxglove; domain ROS_DOMAIN_ID; docs/ros2.md).
    #[arg(long)]
    ros2: bool,
    /// With --ros2: the samples topic best effort (docs/ros2.md).
    #[arg(long, requires = "ros2")]
    ros2_best_effort: bool,
}

/// `ADDRESS/PREFIX` as address and prefix length.
fn parse_subnet(s: &str) -> anyhow::Result<([u8; 4], u8)> {
    let (ip, prefix) = s
        .split_once('/')
        .with_context(|| format!("--host-subnet {s}: expected ADDRESS/PREFIX, e.g. 127.0.0.0/8"))?;
    let ip: std::net::Ipv4Addr = ip
        .parse()
        .with_context(|| format!("--host-subnet {s}: {ip} is no IPv4 address"))?;
    let prefix: u8 = prefix
        .parse()
        .ok()
        .filter(|p| *p <= 32)
        .with_context(|| format!("--host-subnet {s}: prefix length {prefix} is not 0..=32"))?;
    Ok((ip.octets(), prefix))
}

#[derive(serde::Serialize)]
struct Summary {
    listen: SocketAddrV4,
    scene: String,
    ports: usize,
    #[serde(flatten)]
    served: ServeSummary,
}

/// Runs the emulated box until `--run-ms` (or forever).
pub fn run(args: &Args, json: bool) -> anyhow::Result<()> {
    anyhow::ensure!(
        args.speed > 0.0 && args.speed.is_finite(),
        "--speed {} must be a positive number",
        args.speed
    );
    anyhow::ensure!(
        args.duration_ms > 0.0 && args.from_ms >= 0.0,
        "--duration-ms must be positive and --from-ms not negative"
    );
    anyhow::ensure!(
        args.sync_period_ms == 0.0 || (1.0..=34_359.0).contains(&args.sync_period_ms),
        "--sync-period-ms {} must be 0 (off) or 1 to 34359 (32 bits of 8 ns ticks)",
        args.sync_period_ms
    );
    let host_subnet = parse_subnet(&args.host_subnet)?;
    let settings = EmulatorSettings {
        scene: args.scene.clone(),
        from_ms: args.from_ms,
        duration_ms: args.duration_ms,
        buses: args.buses,
        cells: args.cells,
        flush_timeout_us: args.flush_timeout_us,
        status_period_ms: args.status_period_ms,
        sync_period_ms: args.sync_period_ms,
        host_subnet,
        box_id: args.box_id,
    };
    let prepared = emulator::prepare(&settings, args.listen)?;
    let socket =
        UdpSocket::bind(args.listen).with_context(|| format!("binding {}", args.listen))?;
    eprintln!(
        "emulating box {} ({} ports, scene {}) on {}: commands from {}",
        args.box_id,
        prepared.ports,
        prepared.scene,
        socket.local_addr()?,
        args.host_subnet
    );
    if args.foxglove.is_some() || args.ros2 {
        // `skinbox capture --claim` on loopback, in a thread: the same code path as a box
        let mut argv = vec![
            "skinbox".to_string(),
            "capture".into(),
            "--listen".into(),
            "127.0.0.1:0".into(),
            "--claim".into(),
            socket.local_addr()?.to_string(),
        ];
        if let Some(fx) = args.foxglove {
            argv.extend(["--foxglove".into(), fx.to_string()]);
        }
        if args.ros2 {
            argv.push("--ros2".into());
            if args.ros2_best_effort {
                argv.push("--ros2-best-effort".into());
            }
        }
        if let Some(ms) = args.run_ms {
            argv.extend(["--duration-ms".into(), ms.to_string()]);
        }
        let cli = <super::Cli as clap::Parser>::try_parse_from(argv)?;
        std::thread::spawn(move || {
            if let super::Command::Capture(c) = cli.command {
                if let Err(e) = super::capture::run(c, false) {
                    eprintln!("live view: {e:#}");
                }
            }
        });
    }
    let deadline = args
        .run_ms
        .map(|ms| Instant::now() + Duration::from_millis(ms));
    let interrupted = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    {
        let interrupted = interrupted.clone();
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()?;
        std::thread::spawn(move || {
            if runtime.block_on(tokio::signal::ctrl_c()).is_ok() {
                interrupted.store(true, std::sync::atomic::Ordering::Relaxed);
            }
        });
    }
    let served = emulator::serve(
        &prepared,
        &socket,
        args.speed,
        &interrupted,
        deadline,
        &mut |_| {},
    )
    .context("receiving commands")?;
    let summary = Summary {
        listen: args.listen,
        scene: prepared.scene.clone(),
        ports: prepared.ports,
        served,
    };
    if json {
        super::print_json(&summary)
    } else {
        let s = &summary.served;
        println!(
            "emulated box {} for {:.1} s: {} records and {} status datagrams sent, {} before any claim; {} commands, {} acknowledgements; {} send errors",
            args.box_id,
            s.wall_s,
            s.stats.records_datagrams_sent,
            s.stats.status_datagrams_sent,
            s.stats.datagrams_unclaimed,
            s.stats.commands_received,
            s.stats.acks_sent,
            s.send_errors
        );
        println!("box counters: {}", s.counters);
        Ok(())
    }
}
