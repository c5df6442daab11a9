//! A scene of the cell models on the box's pins: one bus per port.

use crate::line::Jitter;
use crate::run::{HostFrame, SentPacket, SimSpec, TICK_ZERO_CYCLE};
use skinbox_cells::bus::DOWNLINK_PACKET_NS;
use skinbox_cells::scene::{BusDownlink, BusStream, GenerateOptions, Generated, Scene};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_model::control::{udp_frame, BoxControl, ControlConfig};
use skinbox_model::downlink::{generated_sync, PacketStart, PinChange};
use skinbox_model::timing::RECEIVE_TICK_LAG;
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::cell_command::{CellCommand, CellCommandRepr};
use skinbox_protocol::command::{CommandRepr, Destination, Request, ALL_PORTS};
use skinbox_protocol::link::{LinkConfig, PREAMBLE_LEN};
use skinbox_protocol::TICK_NS;

/// Idle clocks between two frames the host sends back to back (12 bytes).
const INTER_FRAME_GAP: u64 = 12;

/// Time the box gets after the scene's last packet, besides one status period: the flush
/// timeout and the frames out.
pub const DRAIN_NS: u64 = 2_000_000;

/// Time from the simulation's start until the box's ports see their pins
/// ([`crate::run::PORTS_READY_CYCLE`]): reset, the reset register, the counters' clearing.
pub const PORTS_READY_NS: u64 = crate::run::PORTS_READY_CYCLE * TICK_NS;

/// The packets of `generated` from scene time `from_ns` on, as a simulation of `config`
/// (whose port count must equal the scene's bus count): bus `i` drives port `i`, each packet
/// with the bit period of the bus's root cell. The simulation starts [`PORTS_READY_NS`]
/// before `from_ns`, so the ports are out of reset when the window's first packet begins.
/// Packets that start before `from_ns` or end after `from_ns + duration_ns` are left out.
/// The simulation runs one status period and [`DRAIN_NS`] longer, so the last status report
/// counts every packet.
pub fn spec(generated: &Generated, config: BoxConfig, from_ns: u64, duration_ns: u64) -> SimSpec {
    assert_eq!(config.ports, generated.buses.len(), "one port per bus");
    let ports = generated
        .buses
        .iter()
        .map(|bus| sent_packets(bus, from_ns, duration_ns))
        .collect();
    SimSpec {
        duration_ns: sim_duration_ns(&config, duration_ns),
        config,
        ports,
        pcap: None,
        vcd: None,
        jitter: Jitter::NONE,
        host_frames: vec![],
    }
}

/// The simulated time of a window of `duration_ns` on a box of `config`: the ports' reset
/// before it, one status period and [`DRAIN_NS`] after it, in whole ticks.
pub fn sim_duration_ns(config: &BoxConfig, duration_ns: u64) -> u64 {
    (PORTS_READY_NS + duration_ns + config.status_period_ticks * TICK_NS + DRAIN_NS)
        .div_ceil(TICK_NS)
        * TICK_NS
}

/// The packets of `bus` on its box pin in a simulation of the window from scene time
/// `from_ns` for `duration_ns` (as [`spec`] takes them).
pub fn sent_packets(bus: &BusStream, from_ns: u64, duration_ns: u64) -> Vec<SentPacket> {
    let lead_ns = PORTS_READY_NS as f64;
    bus.packets
        .iter()
        .filter(|p| p.pin_edge_ps >= from_ns * 1000)
        .filter(|p| p.pin_end_ps() / 1000 <= from_ns + duration_ns)
        .map(|p| SentPacket {
            bytes: p.bytes,
            start_ns: p.pin_edge_ps as f64 / 1000.0 - from_ns as f64 + lead_ns,
            bit_ns: f64::from(p.bit_period_ps) / 1000.0,
        })
        .collect()
}

/// Generates `scene` for `duration_s` (overriding its own duration) and keeps the packets.
/// The scene's statistics window then covers the whole run (no warm-up): the box sees the
/// start-up burst of the cells too.
pub fn generate(
    scene: &Scene,
    duration_s: f64,
) -> Result<Generated, skinbox_cells::scene::SceneError> {
    generate_with(scene, duration_s, &GenerateOptions::default())
}

/// As [`generate`], with `options` (a box's downlink, say). The scene's `[[commands]]` at
/// or after `duration_s` are left out: the cells would act on them after the end of what
/// is generated (`skinbox sim mode_switch`'s window ends at 1.1 s, its command is at 1.5 s).
pub fn generate_with(
    scene: &Scene,
    duration_s: f64,
    options: &GenerateOptions,
) -> Result<Generated, skinbox_cells::scene::SceneError> {
    let mut scene = scene.clone();
    scene.config.scene.duration_s = duration_s;
    scene.config.commands.retain(|c| c.time_s < duration_s);
    scene.config.scene.warmup_s = 0.0;
    scene.check()?;
    Ok(scene.generate(options))
}

/// The built-in scene `name` (a file in `skinbox_cells::scenes_dir()`) from scene time
/// `from_ns` for `duration_ns`, on a box with one port per bus and the given status period
/// (other parameters default).
pub fn builtin_spec(
    name: &str,
    from_ns: u64,
    duration_ns: u64,
    status_period_ticks: u64,
) -> Result<SimSpec, skinbox_cells::scene::SceneError> {
    let scene = Scene::load(&skinbox_cells::scenes_dir().join(format!("{name}.toml")))?;
    let generated = generate(&scene, (from_ns + duration_ns) as f64 * 1e-9)?;
    let config = BoxConfig {
        ports: generated.buses.len(),
        status_period_ticks,
        ..BoxConfig::default()
    };
    Ok(spec(&generated, config, from_ns, duration_ns))
}

/// A scene's `[[commands]]` sent by the host to the co-simulated box, and the downlink they
/// make: what the cells receive.
#[derive(Debug, Clone, Default)]
pub struct DownlinkPlan {
    /// The command frames on GMII receive (those inside the simulated window).
    pub host_frames: Vec<HostFrame>,
    /// Per bus, (scene time the first start bit leaves the box, ns; the bytes): the cell
    /// command packets the bus's root receives (before the window each at its own time,
    /// as without a box).
    pub per_bus: Vec<BusDownlink>,
    /// Commands the box queued.
    pub accepted: usize,
    /// Commands the box refused (`downlink_full`).
    pub refused: usize,
    /// Every change of the box's transmit pins, box ticks.
    pub pin_changes: Vec<PinChange>,
    /// Every packet the box's pins send, box ticks.
    pub starts: Vec<PacketStart>,
}

/// The scene time of box tick `tick` in a simulation of the window from `from_ns`.
pub fn scene_ns_of_tick(tick: u64, from_ns: u64) -> u64 {
    ((tick + TICK_ZERO_CYCLE) * TICK_NS + from_ns).saturating_sub(PORTS_READY_NS)
}

/// The box tick at scene time `scene_ns` in a simulation of the window from `from_ns`
/// (the inverse of [`scene_ns_of_tick`], rounded down): negative before the simulated box
/// counts, where a box that had been running since scene time 0 would have counted on the
/// same base.
pub fn box_tick_of_scene_ns(scene_ns: u64, from_ns: u64) -> i64 {
    (scene_ns as i64 + PORTS_READY_NS as i64 - from_ns as i64).div_euclid(TICK_NS as i64)
        - TICK_ZERO_CYCLE as i64
}

/// Per bus, `scene`'s cell commands before the window from scene time `from_ns` (when no
/// box is simulated yet): each at its own time, one after the other on each bus. The box
/// is taken to have run since scene time 0 on the simulated box's time base, so a time
/// sync carries the tick at which it leaves on that base ([`box_tick_of_scene_ns`],
/// negative before the window, wrapping as a cell's counter arithmetic does) and the
/// window's syncs continue the cells' time base instead of restarting it. A box of
/// `config` with its sync generator on has sent its own syncs too, every sync period back
/// from the simulated box's first (the clock after its reset), so its cells are in time
/// (their rate learnt) when the window starts.
pub fn downlink_before(scene: &Scene, config: &BoxConfig, from_ns: u64) -> Vec<BusDownlink> {
    let mut commands: Vec<(u64, Option<usize>, [u8; PACKET_LEN], bool)> = scene
        .command_packets()
        .iter()
        .filter(|c| c.0 < from_ns)
        .copied()
        .collect();
    // the simulated generator's origin, the clock after reset (box tick 1)
    let origin_ns = scene_ns_of_tick(1, from_ns);
    let period_ns = config.sync_period_ticks * TICK_NS;
    if let Some(periods) = origin_ns.checked_div(period_ns) {
        let syncs = (1..=periods).map(|k| {
            let time_ns = origin_ns - k * period_ns;
            (time_ns, None, generated_sync(0), true)
        });
        commands.extend(syncs);
        // (stable: a sync at a command's time goes after it)
        commands.sort_by_key(|c| c.0);
    }
    let mut per_bus: Vec<BusDownlink> = vec![vec![]; config.ports];
    for &(time_ns, port, bytes, sync) in &commands {
        for (bus, list) in per_bus.iter_mut().enumerate() {
            if port.is_none_or(|p| p == bus) {
                let free = list.last().map_or(0, |l| l.0 + DOWNLINK_PACKET_NS);
                let leave_ns = time_ns.max(free);
                let mut bytes = bytes;
                if sync {
                    set_sync_tick(&mut bytes, box_tick_of_scene_ns(leave_ns, from_ns) as u64);
                }
                list.push((leave_ns, bytes));
            }
        }
    }
    per_bus
}

/// Plans `scene`'s cell commands through a box of `config` simulated from scene time
/// `from_ns` for `duration_ns`: each command inside the window becomes a command frame
/// from the host (the link's host address, sequence numbers from 1) at its time on GMII
/// receive; the box's rules and downlink (the control model with its clock model of the
/// downlink, [`skinbox_model::downlink`]) say which it queues and when each packet leaves which
/// pin. A time sync carries the tick at which its packet's first start bit leaves the box.
/// Commands before the window reach the cells at their own time.
pub fn plan_downlink(
    scene: &Scene,
    config: &BoxConfig,
    from_ns: u64,
    duration_ns: u64,
) -> DownlinkPlan {
    let commands = scene.command_packets();
    let ports = config.ports;
    let mut per_bus = downlink_before(scene, config, from_ns);
    let window: Vec<_> = commands
        .iter()
        .filter(|c| (from_ns..from_ns + duration_ns).contains(&c.0))
        .collect();
    let mut packets: Vec<[u8; PACKET_LEN]> = window.iter().map(|c| c.2).collect();
    // twice: the time syncs' ticks come from the first pass (the timing does not depend
    // on the bytes)
    let mut plan = DownlinkPlan::default();
    for pass in 0..2 {
        let host_frames = command_frames(config, from_ns, &window, &packets);
        let mut control = BoxControl::new(ControlConfig::of(config));
        let (mut accepted, mut refused) = (0, 0);
        let mut queued: Vec<Vec<usize>> = vec![vec![]; ports];
        for (i, f) in host_frames.iter().enumerate() {
            let receive_tick = f.last_edge() + RECEIVE_TICK_LAG - TICK_ZERO_CYCLE;
            match control.receive(&f.frame, receive_tick).fate {
                BoxCounter::CommandsAccepted => {
                    accepted += 1;
                    for (p, q) in queued.iter_mut().enumerate() {
                        if window[i].1.is_none_or(|w| w == p) {
                            q.push(i);
                        }
                    }
                }
                _ => refused += 1,
            }
        }
        // (the box's own syncs over the whole simulated time, then the queues drained)
        let end_ns = sim_duration_ns(config, duration_ns).saturating_sub(PORTS_READY_NS);
        control.downlink.advance_to(end_ns / TICK_NS);
        control.downlink.drain();
        let starts = control.downlink.starts().to_vec();
        if pass == 0 {
            for (p, commands) in queued.iter().enumerate() {
                let on_port = starts.iter().filter(|s| s.port == p && !s.generated);
                for (&i, start) in commands.iter().zip(on_port) {
                    if window[i].3 {
                        let tick = start.tick.min(sync_tick(&packets[i]).unwrap_or(u64::MAX));
                        set_sync_tick(&mut packets[i], tick);
                    }
                }
            }
            continue;
        }
        for s in &starts {
            per_bus[s.port].push((scene_ns_of_tick(s.tick, from_ns), s.bytes));
        }
        plan = DownlinkPlan {
            host_frames,
            per_bus: per_bus.clone(),
            accepted,
            refused,
            pin_changes: control.downlink.changes().to_vec(),
            starts,
        };
    }
    plan
}

/// The tick a time-sync packet carries, if it is one and it was set.
fn sync_tick(packet: &[u8; PACKET_LEN]) -> Option<u64> {
    match CellCommandRepr::parse(packet).ok()?.command {
        CellCommand::TimeSync { box_tick } if box_tick != 0 => Some(box_tick),
        _ => None,
    }
}

fn set_sync_tick(packet: &mut [u8; PACKET_LEN], tick: u64) {
    if let Ok(mut repr) = CellCommandRepr::parse(packet) {
        if let CellCommand::TimeSync { box_tick } = &mut repr.command {
            *box_tick = tick;
            *packet = repr.to_bytes();
        }
    }
}

/// The host's command frames for `window` (scene time, port, _, _) with `packets`: from
/// the link's host address to the box, each at its time, or right after the frame before
/// it (an inter-frame gap later) when that one is still on the wire.
fn command_frames(
    config: &BoxConfig,
    from_ns: u64,
    window: &[&(u64, Option<usize>, [u8; PACKET_LEN], bool)],
    packets: &[[u8; PACKET_LEN]],
) -> Vec<HostFrame> {
    let link = &config.link;
    let host = LinkConfig {
        box_mac: link.host_mac,
        box_ip: link.host_ip,
        box_port: link.host_port,
        ..*link
    };
    let to_box = Destination {
        mac: link.box_mac,
        ip: link.box_ip,
        port: link.box_port,
    };
    let mut free_edge = 0;
    window
        .iter()
        .zip(packets)
        .enumerate()
        .map(|(i, (c, packet))| {
            let payload = CommandRepr {
                box_id: config.box_id,
                sequence: i as u32 + 1,
                host_time: 0,
                request: Request::CellCommand {
                    port: c.1.map_or(ALL_PORTS, |p| p as u8),
                    packet: *packet,
                },
            }
            .to_bytes();
            let wire = udp_frame(&host, &to_box, &payload);
            let edge = ((c.0 - from_ns + PORTS_READY_NS) / TICK_NS).max(free_edge);
            free_edge = edge + wire.len() as u64 + INTER_FRAME_GAP;
            HostFrame {
                edge,
                frame: wire[PREAMBLE_LEN..].to_vec(),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scene generated shorter than its file says, its command past the end: the
    /// packets are the first part of the whole scene's (the command has not happened yet).
    #[test]
    fn a_scene_generated_before_its_commands_is_the_start_of_the_whole_scene() {
        let mut scene = Scene::find(Some("mode_switch")).unwrap();
        scene.config.scene.cells = 12;
        assert_eq!(scene.config.commands.len(), 1);
        assert!(scene.config.commands[0].time_s > 1.1);
        let short = generate(&scene, 1.1).unwrap();
        let whole = generate(&scene, scene.config.scene.duration_s).unwrap();
        let end_ps = 1_100_000_000_000;
        for (s, w) in short.buses.iter().zip(&whole.buses) {
            let early: Vec<_> = w
                .packets
                .iter()
                .filter(|p| p.pin_end_ps() <= end_ps)
                .collect();
            let short_packets: Vec<_> = s
                .packets
                .iter()
                .filter(|p| p.pin_end_ps() <= end_ps)
                .collect();
            assert!(early.len() > 100, "{}", early.len());
            assert_eq!(short_packets.len(), early.len());
            for (a, b) in short_packets.iter().zip(&early) {
                assert_eq!((a.bytes, a.pin_edge_ps), (b.bytes, b.pin_edge_ps));
            }
        }
    }
}
