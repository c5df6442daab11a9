//! `skinbox emulate`: a box on a UDP socket, without a board: the box's reference model
//! playing a scene in real time and its control model answering commands.

use super::sim::load_scene;
use anyhow::Context;
use skinbox_cosim::emulator::{EmulatedBox, Outgoing};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::link::LinkConfig;
use std::net::{SocketAddr, SocketAddrV4, UdpSocket};
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
    /// The host subnet commands are taken from (IPv4 address/prefix length).
    #[arg(long, default_value = "127.0.0.0/8")]
    host_subnet: String,
    /// Box id.
    #[arg(long, default_value_t = 1)]
    box_id: u16,
    /// Stop after this much wall-clock time, ms (default: at Ctrl-C); then print a summary.
    #[arg(long)]
    run_ms: Option<u64>,
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
    wall_s: f64,
    box_ticks: u64,
    #[serde(flatten)]
    stats: skinbox_cosim::emulator::EmulatorStats,
    box_counters: skinbox_host::report::BoxCountersReport,
    send_errors: u64,
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
    let (host_subnet, host_subnet_prefix_len) = parse_subnet(&args.host_subnet)?;
    let mut scene = load_scene(args.scene.as_deref())?;
    if let Some(b) = args.buses {
        scene.config.scene.buses = b;
    }
    if let Some(c) = args.cells {
        scene.config.scene.cells = c;
    }
    scene.check()?;
    let generated =
        skinbox_cosim::scene::generate(&scene, (args.from_ms + args.duration_ms) * 1e-3)?;
    let ports = generated.buses.len();
    anyhow::ensure!(
        (1..=64).contains(&ports),
        "the scene has {ports} buses; the box has 1 to 64 ports"
    );
    let socket =
        UdpSocket::bind(args.listen).with_context(|| format!("binding {}", args.listen))?;
    let config = BoxConfig {
        ports,
        flush_timeout_ticks: (args.flush_timeout_us * 125.0).round() as u64,
        status_period_ticks: (args.status_period_ms * 125_000.0).round() as u64,
        box_id: args.box_id,
        link: LinkConfig {
            box_ip: args.listen.ip().octets(),
            box_port: args.listen.port(),
            host_subnet,
            host_subnet_prefix_len,
            ..LinkConfig::DEFAULT
        },
        ..BoxConfig::default()
    };
    config.validate()?;
    let spec = skinbox_cosim::scene::spec(
        &generated,
        config.clone(),
        (args.from_ms * 1e6) as u64,
        (args.duration_ms * 1e6) as u64,
    );
    let (lines, _) = skinbox_cosim::run::lines(&spec);
    let prepared =
        skinbox_cosim::reference::prepare(&config, &lines, skinbox_cosim::run::cycles(&spec))?;
    let mut emulated = EmulatedBox::new(&prepared, &config);
    eprintln!(
        "emulating box {} ({ports} ports, scene {}) on {}: commands from {}",
        args.box_id,
        scene.name(),
        socket.local_addr()?,
        args.host_subnet
    );
    let started = Instant::now();
    let tick_now = |at: Instant| -> u64 {
        (at.duration_since(started).as_secs_f64()
            * args.speed
            * skinbox_protocol::TICKS_PER_SECOND as f64) as u64
    };
    let mut send_errors = 0u64;
    let send =
        |socket: &UdpSocket, o: &Outgoing| u64::from(socket.send_to(&o.payload, o.to).is_err());
    let deadline = args.run_ms.map(|ms| started + Duration::from_millis(ms));
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
    let mut buf = vec![0u8; 65536];
    loop {
        let now = Instant::now();
        if deadline.is_some_and(|d| now >= d)
            || interrupted.load(std::sync::atomic::Ordering::Relaxed)
        {
            break;
        }
        for o in emulated.advance(tick_now(now)) {
            send_errors += send(&socket, &o);
        }
        socket.set_read_timeout(Some(Duration::from_micros(500)))?;
        match socket.recv_from(&mut buf) {
            Ok((n, SocketAddr::V4(from))) => {
                let tick = tick_now(Instant::now());
                for o in emulated.advance(tick) {
                    send_errors += send(&socket, &o);
                }
                if let Some(ack) =
                    emulated.command(from, &buf[..n], tick, || tick_now(Instant::now()))
                {
                    send_errors += send(&socket, &ack);
                }
            }
            // IPv6 senders cannot reach an IPv4 box
            Ok((_, SocketAddr::V6(_))) => {}
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) => {}
            // an ICMP port unreachable of an earlier send shows up here on Linux
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => send_errors += 1,
            Err(e) => return Err(e).context("receiving commands"),
        }
    }
    let summary = Summary {
        listen: args.listen,
        scene: scene.name().to_string(),
        ports,
        wall_s: started.elapsed().as_secs_f64(),
        box_ticks: tick_now(Instant::now()),
        stats: emulated.stats,
        box_counters: (&emulated.control().counters).into(),
        send_errors,
    };
    if json {
        super::print_json(&summary)
    } else {
        println!(
            "emulated box {} for {:.1} s: {} records and {} status datagrams sent, {} before any claim; {} commands, {} acknowledgements; {} send errors",
            args.box_id,
            summary.wall_s,
            summary.stats.records_datagrams_sent,
            summary.stats.status_datagrams_sent,
            summary.stats.datagrams_unclaimed,
            summary.stats.commands_received,
            summary.stats.acks_sent,
            send_errors
        );
        println!("box counters: {}", emulated.control().counters);
        Ok(())
    }
}
