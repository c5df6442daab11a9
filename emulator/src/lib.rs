//! A box without a board on a real UDP socket (`skinbox emulate`): a scene's cells on the
//! pins of the box's models ([`skinbox_model::emulator::EmulatedBox`]), played in real
//! time; commands from the socket are decided at their kernel receive timestamps.
//!
//! The loop is closed as in `skinbox sim` ([`skinbox_cosim::closed_loop`]): the cells are
//! generated ahead while no cell command is in flight; each cell command packet their
//! receivers decode from the emulated box's transmit pins joins their bus's downlink, they
//! are generated again (checked causal), and the ports whose packets changed read the new
//! ones from the uplink's cycle on.

use skinbox_cells::bus::DOWNLINK_PACKET_NS;
use skinbox_cosim::closed_loop::{Cells, ClosedLoopSpec};
use skinbox_cosim::CosimError;
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_model::cell_uart::ReceivedPacket;
use skinbox_model::emulator::{EmulatedBox, EmulatorStats, Outgoing};
use skinbox_model::reference::PreparedReference;
use skinbox_protocol::link::LinkConfig;
use std::net::SocketAddrV4;

/// What an emulated box on a socket plays and how it starts (the settings of `skinbox
/// emulate`).
#[derive(Debug, Clone, PartialEq)]
pub struct EmulatorSettings {
    /// A built-in scene's name or a scene file (`None`: stroking_upper_arm).
    pub scene: Option<String>,
    /// Scene time at which the box starts to listen, ms (after the warm-up by default).
    pub from_ms: f64,
    /// Scene time the cells send, ms; after it the box goes on with status reports only.
    pub duration_ms: f64,
    /// Number of buses, one box port each (overrides the scene).
    pub buses: Option<usize>,
    /// Number of cells (overrides the scene).
    pub cells: Option<usize>,
    /// Flush timeout after reset, us.
    pub flush_timeout_us: f64,
    /// Status period after reset, ms.
    pub status_period_ms: f64,
    /// Sync period after reset, ms (0, the default: the box sends no time syncs of its
    /// own; the cells are generated again at each sync they hear).
    pub sync_period_ms: f64,
    /// The host subnet commands are taken from: address and prefix length.
    pub host_subnet: ([u8; 4], u8),
    /// Box id.
    pub box_id: u16,
}

impl Default for EmulatorSettings {
    fn default() -> Self {
        EmulatorSettings {
            scene: None,
            from_ms: 1000.0,
            duration_ms: 10_000.0,
            buses: None,
            cells: None,
            flush_timeout_us: 100.0,
            status_period_ms: 100.0,
            sync_period_ms: 0.0,
            host_subnet: ([127, 0, 0, 0], 8),
            box_id: 1,
        }
    }
}

/// A scene played through the reference model, ready for [`serve`].
pub struct PreparedEmulator {
    prepared: PreparedReference,
    cells: Cells,
    /// The box's configuration (its address is the listening address).
    pub config: BoxConfig,
    /// The scene's name.
    pub scene: String,
    /// The box's ports (the scene's buses).
    pub ports: usize,
}

/// Loads and generates the scene of `settings` and prepares the box listening on `listen`.
pub fn prepare(
    settings: &EmulatorSettings,
    listen: SocketAddrV4,
) -> Result<PreparedEmulator, CosimError> {
    let mut scene = skinbox_cells::scene::Scene::find(settings.scene.as_deref())?;
    if let Some(b) = settings.buses {
        scene.config.scene.buses = b;
    }
    if let Some(c) = settings.cells {
        scene.config.scene.cells = c;
    }
    scene.check()?;
    let ports = scene.config.scene.buses;
    if !(1..=64).contains(&ports) {
        return Err(CosimError::Ports(ports));
    }
    let (host_subnet, host_subnet_prefix_len) = settings.host_subnet;
    let config = BoxConfig {
        ports,
        flush_timeout_ticks: (settings.flush_timeout_us * 125.0).round() as u64,
        status_period_ticks: (settings.status_period_ms * 125_000.0).round() as u64,
        sync_period_ticks: (settings.sync_period_ms * 125_000.0).round() as u64,
        box_id: settings.box_id,
        link: LinkConfig {
            box_ip: listen.ip().octets(),
            box_port: listen.port(),
            host_subnet,
            host_subnet_prefix_len,
            ..LinkConfig::DEFAULT
        },
        ..BoxConfig::default()
    };
    config.validate()?;
    // the host is the socket's: the scene's own commands reach the cells before the window
    // only
    let mut spec = ClosedLoopSpec::new(
        &scene,
        config.clone(),
        (settings.from_ms * 1e6) as u64,
        (settings.duration_ms * 1e6) as u64,
    );
    spec.sim.host_frames.clear();
    let cells = Cells::new(&spec)?;
    let lines: Vec<_> = (0..ports).map(|p| cells.transitions(p).to_vec()).collect();
    let prepared =
        skinbox_model::reference::prepare(&config, &lines, skinbox_cosim::run::cycles(&spec.sim))?;
    Ok(PreparedEmulator {
        prepared,
        cells,
        config,
        scene: scene.name().to_string(),
        ports,
    })
}

impl PreparedEmulator {
    /// The box leaving reset, its pins as the scene has them.
    pub fn start(&self) -> EmulatedBox<'_> {
        EmulatedBox::new(&self.prepared, &self.config)
    }

    /// The scene's cells as generated before any command from the socket.
    pub fn cells(&self) -> &Cells {
        &self.cells
    }
}

/// What a worker returns: the cells and the ports whose packets changed.
type Generation = (Cells, Result<Vec<usize>, CosimError>);

/// The cells beside the serving loop: the cell command packets their receivers decoded
/// from the emulated box's transmit pins go to a worker thread that generates the cells
/// again with them, while the loop goes on answering commands; the uplink waits at the
/// earliest tick such a packet can change what the cells send ([`Obeying::hold`]) until
/// the worker is done and the ports whose packets changed carry the new ones.
pub struct Obeying {
    idle: Option<Cells>,
    worker: Option<std::thread::JoinHandle<Generation>>,
    /// The packets the worker has, and those waiting for it.
    working: Vec<ReceivedPacket>,
    waiting: Vec<ReceivedPacket>,
}

impl Obeying {
    /// `cells` obeying.
    pub fn new(cells: Cells) -> Obeying {
        Obeying {
            idle: Some(cells),
            worker: None,
            working: vec![],
            waiting: vec![],
        }
    }

    /// The box tick the uplink may run to: the earliest at which a packet in flight can
    /// change the cells' packets on the pins (`u64::MAX` with none).
    pub fn hold(&self) -> u64 {
        self.working
            .iter()
            .chain(&self.waiting)
            .map(|p| p.tick + DOWNLINK_PACKET_NS / skinbox_protocol::TICK_NS)
            .min()
            .unwrap_or(u64::MAX)
    }

    /// Takes the packets `emulated`'s receivers decoded; the worker's cells, once it is
    /// done, go on `emulated`'s pins; the packets waiting go to the worker. With `wait`,
    /// waits for the worker. Fails when regeneration is not causal.
    pub fn step(&mut self, emulated: &mut EmulatedBox, wait: bool) -> Result<(), CosimError> {
        self.waiting.extend(emulated.take_received());
        if self
            .worker
            .as_ref()
            .is_some_and(|w| wait || w.is_finished())
        {
            let (cells, changed) = self.worker.take().expect("checked").join().map_err(|_| {
                CosimError::ClosedLoop("the cells' generation panicked".to_string())
            })?;
            for port in changed? {
                emulated
                    .replace_port(port, cells.transitions(port))
                    .map_err(CosimError::ClosedLoop)?;
            }
            self.idle = Some(cells);
            self.working.clear();
        }
        if self.worker.is_none() && !self.waiting.is_empty() {
            let mut cells = self.idle.take().expect("no worker: the cells are idle");
            self.working = std::mem::take(&mut self.waiting);
            let (packets, cycle) = (self.working.clone(), emulated.cycle());
            self.worker = Some(std::thread::spawn(move || {
                let changed = cells.receive(&packets, cycle);
                (cells, changed)
            }));
            if wait {
                return self.step(emulated, true);
            }
        }
        Ok(())
    }
}

/// What [`serve`] did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ServeSummary {
    /// Wall-clock time served, s.
    pub wall_s: f64,
    /// Box ticks reached.
    pub box_ticks: u64,
    /// What the box did.
    #[serde(flatten)]
    pub stats: EmulatorStats,
    /// The box's counters at the end.
    pub box_counters: skinbox_host::report::BoxCountersReport,
    /// The same as the box keeps them.
    #[serde(skip)]
    pub counters: skinbox_protocol::box_counters::BoxCounters,
    /// Datagrams the socket could not send.
    pub send_errors: u64,
}

/// The start on both clocks: the loop's (monotonic) and the kernel's receive stamps' (the
/// wall clock, since the Unix epoch), read close together (a read between two wall clock
/// reads at most 5 us apart, taken at their middle).
fn start_on_both_clocks() -> (std::time::Instant, std::time::Duration) {
    use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
    let wall = || {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
    };
    let mut best = None;
    for _ in 0..20 {
        let (before, at, after) = (wall(), Instant::now(), wall());
        let spread = after.saturating_sub(before);
        if best.is_none_or(|(s, _, _)| spread < s) {
            best = Some((spread, at, before + spread / 2));
        }
        if spread < Duration::from_micros(5) {
            break;
        }
    }
    best.map_or_else(|| (Instant::now(), wall()), |(_, at, w)| (at, w))
}

/// Runs the box of `prepared` on `socket` in real time (`speed`: scene time per wall-clock
/// time) until `stop` is set or `deadline`: it sends its datagrams once a stream-to claims
/// them and answers every command. `progress` sees the box's counts after each step.
///
/// Each command is decided at its arrival: the kernel's receive timestamp of its datagram
/// (SO_TIMESTAMPNS) on the box's time line, as the box decides at the tick the frame's last
/// byte arrived, so downlink queues fill and drain at the spacing the commands came with,
/// not at the pace this loop reads them. The datagrams waiting are all taken, in arrival
/// order, before the uplink runs on to the present. docs/control.md ("The emulator") says
/// where this can still differ from the box.
pub fn serve(
    prepared: &PreparedEmulator,
    socket: &std::net::UdpSocket,
    speed: f64,
    stop: &std::sync::atomic::AtomicBool,
    deadline: Option<std::time::Instant>,
    progress: &mut dyn FnMut(&EmulatorStats),
) -> std::io::Result<ServeSummary> {
    use std::net::SocketAddr;
    use std::time::{Duration, Instant};
    // Without kernel stamps each command is decided when it is read.
    let stamped = skinbox_host::live::enable_receive_timestamps(socket).is_ok();
    let mut emulated = prepared.start();
    let mut cells = Obeying::new(prepared.cells.clone());
    let (started, started_realtime) = start_on_both_clocks();
    let ticks = |elapsed: Duration| -> u64 {
        (elapsed.as_secs_f64() * speed * skinbox_protocol::TICKS_PER_SECOND as f64) as u64
    };
    let tick_now = |at: Instant| -> u64 { ticks(at.duration_since(started)) };
    let mut send_errors = 0u64;
    let send = |socket: &std::net::UdpSocket, o: &Outgoing| {
        u64::from(socket.send_to(&o.payload, o.to).is_err())
    };
    socket.set_read_timeout(Some(Duration::from_micros(500)))?;
    let mut buf = vec![0u8; 65536];
    // the last command's tick: the box's decisions never go back in time
    let mut last_command = 0u64;
    // a datagram was just taken: take every other one waiting before the uplink runs on
    let mut draining = false;
    loop {
        let now = Instant::now();
        if deadline.is_some_and(|d| now >= d) || stop.load(std::sync::atomic::Ordering::Relaxed) {
            break;
        }
        if !draining {
            // the box's own syncs that start by now, heard before the uplink runs there
            emulated.hear_downlink(tick_now(now));
        }
        cells
            .step(&mut emulated, false)
            .map_err(std::io::Error::other)?;
        if !draining {
            for o in emulated.advance(tick_now(now).min(cells.hold())) {
                send_errors += send(socket, &o);
            }
        }
        match skinbox_host::live::recv_stamped(socket, &mut buf, draining) {
            Ok((n, Some(SocketAddr::V4(from)), stamp)) => {
                draining = true;
                let read = tick_now(Instant::now());
                // the arrival on the box's time line; a stamp from before the start or
                // more than a millisecond after the read (the wall clock stepped) is
                // taken as the read
                let late = ticks(Duration::from_millis(1));
                let arrival = stamp
                    .filter(|_| stamped)
                    .and_then(|s| s.checked_sub(started_realtime))
                    .map(ticks)
                    .filter(|&t| t <= read + late)
                    .unwrap_or(read)
                    .max(last_command);
                last_command = arrival;
                emulated.hear_downlink(arrival);
                cells
                    .step(&mut emulated, false)
                    .map_err(std::io::Error::other)?;
                for o in emulated.advance(arrival.min(cells.hold())) {
                    send_errors += send(socket, &o);
                }
                if let Some(ack) = emulated.command(from, &buf[..n], arrival, || {
                    tick_now(Instant::now()).max(arrival)
                }) {
                    send_errors += send(socket, &ack);
                }
                cells
                    .step(&mut emulated, false)
                    .map_err(std::io::Error::other)?;
            }
            // IPv6 senders cannot reach an IPv4 box
            Ok(_) => draining = true,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                draining = false
            }
            // an ICMP port unreachable of an earlier send shows up here on Linux
            Err(e) if e.kind() == std::io::ErrorKind::ConnectionRefused => send_errors += 1,
            Err(e) => return Err(e),
        }
        progress(&emulated.stats);
    }
    Ok(ServeSummary {
        wall_s: started.elapsed().as_secs_f64(),
        box_ticks: tick_now(Instant::now()),
        stats: emulated.stats,
        box_counters: (&emulated.control().counters).into(),
        counters: emulated.control().counters,
        send_errors,
    })
}
