//! A scene of the cell models on the box's pins: one bus per port.

use crate::line::Jitter;
use crate::run::{SentPacket, SimSpec};
use skinbox_cells::scene::{GenerateOptions, Generated, Scene};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::TICK_NS;

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
    let lead_ns = PORTS_READY_NS as f64;
    let ports = generated
        .buses
        .iter()
        .map(|bus| {
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
        })
        .collect();
    SimSpec {
        duration_ns: (PORTS_READY_NS
            + duration_ns
            + config.status_period_ticks * TICK_NS
            + DRAIN_NS)
            .div_ceil(TICK_NS)
            * TICK_NS,
        config,
        ports,
        pcap: None,
        vcd: None,
        jitter: Jitter::NONE,
        host_frames: vec![],
    }
}

/// Generates `scene` for `duration_s` (overriding its own duration) and keeps the packets.
/// The scene's statistics window then covers the whole run (no warm-up): the box sees the
/// start-up burst of the cells too.
pub fn generate(
    scene: &Scene,
    duration_s: f64,
) -> Result<Generated, skinbox_cells::scene::SceneError> {
    let mut scene = scene.clone();
    scene.config.scene.duration_s = duration_s;
    scene.config.scene.warmup_s = 0.0;
    scene.check()?;
    Ok(scene.generate(&GenerateOptions::default()))
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
