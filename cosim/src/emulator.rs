//! A box without a board: the reference model of the box's uplink
//! ([`crate::reference::SlicedReference`]) and its control model
//! ([`skinbox_model::control::BoxControl`]) played together, free of I/O. `skinbox emulate` puts a
//! real UDP socket and a clock around it.
//!
//! A command payload from a UDP sender goes to the control model as what arrived on the
//! socket: an IPv4 header from the sender's address to the box's and a UDP datagram from
//! its port to the box's ([`deliver`]), which the model decides as the frame carrying them
//! would be; its effects change the reference model from that tick on: stream-to names where the datagrams go, set-flush-timeout and
//! set-status-period change the uplink's timing, status-now starts a report. Until a
//! stream-to claims the stream, the datagrams are counted but sent nowhere (the build-time
//! destination of a real box is a documentation address).

use crate::reference::{PreparedReference, SlicedReference};
use crate::run::TICK_ZERO_CYCLE;
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_model::control::{BoxControl, ControlConfig, Effect, Outcome, Reply};
use skinbox_protocol::command::Destination;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::link::{LinkConfig, IPV4_TTL, IP_PROTOCOL_UDP};
use skinbox_protocol::wire::{Ipv4Repr, UdpRepr};
use std::net::SocketAddrV4;

/// The MAC address the emulator gives every UDP sender: a socket shows none, and the
/// control model keeps one for each sender (stream-to's destination names it).
pub const SENDER_MAC: [u8; 6] = [0x02, 0x00, 0x00, 0x00, 0x00, 0x01];

/// What the emulated box did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct EmulatorStats {
    /// Records datagrams sent to the claimed destination.
    pub records_datagrams_sent: u64,
    /// Records (cell packets) in them.
    pub records_sent: u64,
    /// Status datagrams sent to the claimed destination.
    pub status_datagrams_sent: u64,
    /// Datagrams the box made before any stream-to claimed the stream: sent nowhere.
    pub datagrams_unclaimed: u64,
    /// Command payloads taken.
    pub commands_received: u64,
    /// Acknowledgements sent.
    pub acks_sent: u64,
}

/// A UDP payload to send, and where.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outgoing {
    /// The payload.
    pub payload: Vec<u8>,
    /// The destination's IPv4 address and UDP port.
    pub to: SocketAddrV4,
}

fn socket_of(d: &Destination) -> SocketAddrV4 {
    SocketAddrV4::new(d.ip.into(), d.port)
}

/// The emulated box.
pub struct EmulatedBox<'a> {
    reference: SlicedReference<'a>,
    control: BoxControl,
    claimed: bool,
    /// What it did so far.
    pub stats: EmulatorStats,
}

/// The control parameters of a box built with `config`.
pub fn control_config(config: &BoxConfig) -> ControlConfig {
    ControlConfig::of(config)
}

impl<'a> EmulatedBox<'a> {
    /// The box of `config` leaving reset, its pins as `prepared` has them.
    pub fn new(prepared: &'a PreparedReference, config: &BoxConfig) -> EmulatedBox<'a> {
        let mut control = BoxControl::new(control_config(config));
        // an emulated PHY: up, speed not known
        control.counters.link_speed = skinbox_protocol::box_counters::LinkSpeed::Unknown;
        EmulatedBox {
            reference: prepared.start(),
            control,
            claimed: false,
            stats: EmulatorStats::default(),
        }
    }

    /// The control state (destination, timing, counters).
    pub fn control(&self) -> &BoxControl {
        &self.control
    }

    /// Runs the box up to box tick `tick`; returns the datagrams it sent meanwhile, to the
    /// claimed destination (none before a claim; they are counted).
    pub fn advance(&mut self, tick: u64) -> Vec<Outgoing> {
        let sent = self.reference.run_until(TICK_ZERO_CYCLE + tick);
        let mut out = Vec::with_capacity(sent.len());
        for s in sent {
            if !self.claimed {
                self.stats.datagrams_unclaimed += 1;
                continue;
            }
            let payload = match &s.datagram.body {
                DatagramBody::Status(_) => {
                    self.stats.status_datagrams_sent += 1;
                    s.datagram
                        .to_bytes_with_box_counters(&self.control.counters)
                }
                DatagramBody::Records(records) => {
                    self.stats.records_datagrams_sent += 1;
                    self.stats.records_sent += records.len() as u64;
                    s.datagram.to_bytes()
                }
            };
            out.push(Outgoing {
                payload,
                to: socket_of(&self.control.destination),
            });
        }
        out
    }

    /// Takes a UDP payload from `from` at box tick `tick` (run the box there first with
    /// [`EmulatedBox::advance`]): the acknowledgement, with `send_tick()` as its send tick,
    /// if the control model answers.
    pub fn command(
        &mut self,
        from: SocketAddrV4,
        payload: &[u8],
        tick: u64,
        send_tick: impl FnOnce() -> u64,
    ) -> Option<Outgoing> {
        self.stats.commands_received += 1;
        let outcome = deliver(&mut self.control, from, payload, tick);
        // the pins of an emulated box go nowhere
        self.control.downlink.take_changes();
        match outcome.effect {
            Some(Effect::StreamTo(_)) => self.claimed = true,
            Some(Effect::SetFlushTimeout(t)) => self.reference.set_flush_timeout_ticks(t.into()),
            Some(Effect::SetStatusPeriod(t)) => self.reference.set_status_period_ticks(t.into()),
            Some(Effect::StatusNow) => self.reference.request_status(),
            None => {}
        }
        match outcome.reply {
            Some(reply @ Reply::Ack { .. }) => {
                let (payload, to) = reply.ack_payload(send_tick())?;
                self.stats.acks_sent += 1;
                Some(Outgoing {
                    payload,
                    to: socket_of(&to),
                })
            }
            _ => None,
        }
    }
}

/// Hands `control` a UDP payload that arrived on the box's socket from `from` at box tick
/// `tick`: the IPv4 header (from `from`'s address to the box's, UDP; the socket shows no
/// other field, so they are those of a plain unfragmented packet: TTL 64, don't fragment)
/// and the UDP datagram (from `from`'s port to the box's), from [`SENDER_MAC`].
pub fn deliver(control: &mut BoxControl, from: SocketAddrV4, payload: &[u8], tick: u64) -> Outcome {
    let link = control.config().link;
    let udp = UdpRepr {
        source_port: from.port(),
        destination_port: link.box_port,
        payload,
    };
    let ip = Ipv4Repr {
        source: from.ip().octets(),
        destination: link.box_ip,
        protocol: IP_PROTOCOL_UDP,
        payload_len: udp.buffer_len(),
        dscp_ecn: 0,
        identification: 0,
        dont_fragment: true,
        ttl: IPV4_TTL,
    };
    control.receive_udp(SENDER_MAC, &ip, &udp, tick)
}

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
            host_subnet: ([127, 0, 0, 0], 8),
            box_id: 1,
        }
    }
}

/// A scene played through the reference model, ready for [`serve`].
pub struct PreparedEmulator {
    prepared: PreparedReference,
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
) -> Result<PreparedEmulator, crate::error::CosimError> {
    use crate::error::CosimError;
    let mut scene = skinbox_cells::scene::Scene::find(settings.scene.as_deref())?;
    if let Some(b) = settings.buses {
        scene.config.scene.buses = b;
    }
    if let Some(c) = settings.cells {
        scene.config.scene.cells = c;
    }
    scene.check()?;
    let generated =
        crate::scene::generate(&scene, (settings.from_ms + settings.duration_ms) * 1e-3)?;
    let ports = generated.buses.len();
    if !(1..=64).contains(&ports) {
        return Err(CosimError::Ports(ports));
    }
    let (host_subnet, host_subnet_prefix_len) = settings.host_subnet;
    let config = BoxConfig {
        ports,
        flush_timeout_ticks: (settings.flush_timeout_us * 125.0).round() as u64,
        status_period_ticks: (settings.status_period_ms * 125_000.0).round() as u64,
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
    let spec = crate::scene::spec(
        &generated,
        config.clone(),
        (settings.from_ms * 1e6) as u64,
        (settings.duration_ms * 1e6) as u64,
    );
    let (lines, _) = crate::run::lines(&spec);
    let prepared = crate::reference::prepare(&config, &lines, crate::run::cycles(&spec))?;
    Ok(PreparedEmulator {
        prepared,
        config,
        scene: scene.name().to_string(),
        ports,
    })
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
    use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
    // Without kernel stamps each command is decided when it is read.
    let stamped = skinbox_host::live::enable_receive_timestamps(socket).is_ok();
    let mut emulated = EmulatedBox::new(&prepared.prepared, &prepared.config);
    // the start on both clocks: the loop's (monotonic) and the kernel's receive stamps'
    // (the wall clock), read close together (a read between two wall clock reads at most
    // 5 us apart, taken at their middle)
    let wall = || {
        SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
    };
    let (started, started_realtime) = {
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
    };
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
            for o in emulated.advance(tick_now(now)) {
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
                for o in emulated.advance(arrival) {
                    send_errors += send(socket, &o);
                }
                if let Some(ack) = emulated.command(from, &buf[..n], arrival, || {
                    tick_now(Instant::now()).max(arrival)
                }) {
                    send_errors += send(socket, &ack);
                }
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

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_model::control::udp_frame;
    use skinbox_protocol::command::{CommandRepr, Request};
    use skinbox_protocol::link::PREAMBLE_LEN;

    /// What [`deliver`] hands the control model is decided exactly as the frame that
    /// would carry the datagram on the box's wire: same fate, reply, effect and counters.
    #[test]
    fn a_delivered_datagram_is_decided_as_its_frame_would_be() {
        let config = ControlConfig {
            link: LinkConfig::DEFAULT,
            box_id: 1,
            port_count: 4,
            flush_timeout_ticks: 12_500,
            status_period_ticks: 12_500_000,
            clock_hz: skinbox_gateware::CLOCK_HZ,
            cell_baud: skinbox_gateware::CELL_BAUD,
        };
        let (mut delivered, mut framed) = (BoxControl::new(config), BoxControl::new(config));
        let link = config.link;
        let to_box = Destination {
            mac: link.box_mac,
            ip: link.box_ip,
            port: link.box_port,
        };
        let command = |box_id, sequence, request| {
            CommandRepr {
                box_id,
                sequence,
                host_time: 7,
                request,
            }
            .to_bytes()
        };
        let host: SocketAddrV4 = "192.0.2.1:40000".parse().unwrap();
        let foreign: SocketAddrV4 = "198.51.100.7:40000".parse().unwrap();
        let cases = [
            (host, command(1, 1, Request::ReadTick)),
            (host, command(1, 2, Request::StreamTo { to: None })),
            (host, command(1, 2, Request::ReadTick)), // a replay
            (host, command(9, 3, Request::ReadTick)), // another box
            (
                host,
                command(1, 4, Request::SetFlushTimeout { ticks: 2_000 }),
            ),
            (host, command(1, 5, Request::StatusNow)),
            (host, vec![0x53, 0x4B, 1]), // malformed
            (host, vec![0; 1473]),       // more than one frame holds
            (foreign, command(1, 1, Request::ReadTick)),
        ];
        let mut fates = vec![];
        for (tick, (from, payload)) in (1_000u64..).step_by(1_000).zip(&cases) {
            let sender = LinkConfig {
                box_mac: SENDER_MAC,
                box_ip: from.ip().octets(),
                box_port: from.port(),
                ..link
            };
            let frame = udp_frame(&sender, &to_box, payload);
            let expected = framed.receive(&frame[PREAMBLE_LEN..], tick);
            let got = deliver(&mut delivered, *from, payload, tick);
            assert_eq!(got, expected, "{from}, {} bytes", payload.len());
            assert_eq!(delivered.counters, framed.counters);
            fates.push(got.fate);
        }
        use skinbox_protocol::box_counters::BoxCounter::*;
        assert_eq!(
            fates,
            [
                CommandsAccepted,
                CommandsAccepted,
                RefusedReplay,
                RefusedOtherBox,
                CommandsAccepted,
                CommandsAccepted,
                RefusedMalformed,
                BadLength,
                RefusedForeignSubnet,
            ]
        );
    }
}
