//! Speed of the co-simulation: the full harness against the bare model loop and the
//! reference model, same design and traffic, measured in one run.

use crate::error::CosimError;
use crate::frames::assemble;
use crate::harness::play;
use crate::line::{back_to_back, transitions};
use crate::model::{default_cache_dir, Model};
use crate::reference::predict_frames;
use crate::run::RESET_CYCLES;
use crate::Dut;
use skinbox_gateware::interface_box::BoxConfig;
use std::time::Instant;

/// Figures of one `bench sim` run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SimBench {
    /// Ports of the box.
    pub ports: usize,
    /// Cycles of each measurement.
    pub cycles: u64,
    /// The harness: every port busy at line rate (pins driven bit by bit, frames out).
    pub rtl_cycles_per_second: f64,
    /// The bare model loop: the same design clocked with idle pins, nothing collected.
    pub bare_cycles_per_second: f64,
    /// Harness speed over bare speed.
    pub harness_fraction_of_bare: f64,
    /// GMII bytes the harness collected (the box was busy).
    pub gmii_bytes: u64,
    /// Line-rate run: packets whose last byte ended on a pin within the run.
    pub packets_sent: u64,
    /// Line-rate run: records in the frames the box sent within the run (the packets of
    /// the last flush timeout are still in the box at its end).
    pub packets_delivered: u64,
    /// The reference model on the same line-rate traffic, simulated cycles per second.
    pub line_rate_reference_cycles_per_second: f64,
    /// Reference speed over harness speed with every port at line rate (its worst case:
    /// its cost grows with the bytes on the pins, the RTL's does not).
    pub line_rate_reference_speedup: f64,
    /// The scene both models ran ([`SCENE`], its buses on the box's ports).
    pub scene: String,
    /// Ports of the scene's box.
    pub scene_ports: usize,
    /// Cycles of the scene run.
    pub scene_cycles: u64,
    /// RTL harness on the scene, cycles per second.
    pub scene_rtl_cycles_per_second: f64,
    /// Reference model on the scene, cycles per second.
    pub scene_reference_cycles_per_second: f64,
    /// Reference speed over RTL speed on the scene.
    pub reference_speedup: f64,
    /// The reference predicted exactly the frames the RTL sent, in both runs.
    pub reference_agrees: bool,
}

/// The scene of the reference comparison: the default job's scene, 20 ms after warm-up.
pub const SCENE: &str = "stroking_upper_arm";

/// Measures `cycles` clock cycles of an 8-port box each way, fastest of `rounds`.
pub fn bench_sim(ports: usize, cycles: u64, rounds: u32) -> Result<SimBench, CosimError> {
    let config = BoxConfig {
        ports,
        ..BoxConfig::default()
    };
    let model = Model::build(&config, false, &default_cache_dir())?;
    // every port busy: back-to-back bytes at 4 Mbit/s, the ports' clock errors spread
    // over -1 .. +1 %, well inside the receiver's +-4.75 %
    let bytes_needed = (cycles * 8 / 2_500 + 40) as usize;
    let mut packets_sent = 0u64;
    let end_ns = (cycles + RESET_CYCLES) as f64 * skinbox_protocol::TICK_NS as f64;
    let lines: Vec<_> = (0..ports)
        .map(|p| {
            let packet: Vec<u8> = skinbox_protocol::DataRepr {
                cell_id: p as u16 + 1,
                ..Default::default()
            }
            .to_bytes()
            .to_vec();
            let data: Vec<u8> = packet.iter().cycle().take(bytes_needed).copied().collect();
            let bit_ns = 250.0 / (1.0 + line_rate_clock_error(p, ports));
            let start_ns = 5_000.0 + p as f64 * 13.0;
            let packet_ns = (packet.len() * 10) as f64 * bit_ns;
            packets_sent += ((end_ns - start_ns) / packet_ns).floor().max(0.0) as u64;
            transitions(&back_to_back(&data, start_ns, bit_ns))
        })
        .collect();
    let mut frames = Vec::new();
    let (mut rtl, mut bare, mut reference, mut gmii) = (0.0f64, 0.0f64, 0.0f64, 0u64);
    let mut agrees = true;
    for _ in 0..rounds.max(1) {
        let mut dut = Dut::new(&model, None)?;
        let started = Instant::now();
        let out = play(&mut dut, &lines, RESET_CYCLES, cycles);
        rtl = rtl.max(cycles as f64 / started.elapsed().as_secs_f64());
        gmii = out.len() as u64;
        frames = assemble(&out).0;

        let started = Instant::now();
        let predicted = predict_frames(&config, &lines, cycles)?;
        reference = reference.max(cycles as f64 / started.elapsed().as_secs_f64());
        agrees &= predicted == frames;

        let mut dut = Dut::new(&model, None)?;
        dut.set_reset(true);
        dut.run(RESET_CYCLES, |_| {});
        dut.set_reset(false);
        let started = Instant::now();
        dut.run(cycles, |_| {});
        bare = bare.max(cycles as f64 / started.elapsed().as_secs_f64());
    }
    // every round sends the same frames (the model is deterministic)
    let packets_delivered = records_in(&frames)?;
    let scene = scene_speeds(rounds)?;
    Ok(SimBench {
        ports,
        cycles,
        rtl_cycles_per_second: rtl,
        bare_cycles_per_second: bare,
        harness_fraction_of_bare: rtl / bare,
        gmii_bytes: gmii,
        packets_sent,
        packets_delivered,
        line_rate_reference_cycles_per_second: reference,
        line_rate_reference_speedup: reference / rtl,
        scene: SCENE.to_string(),
        scene_ports: scene.ports,
        scene_cycles: scene.cycles,
        scene_rtl_cycles_per_second: scene.rtl,
        scene_reference_cycles_per_second: scene.reference,
        reference_speedup: scene.reference / scene.rtl,
        reference_agrees: agrees && scene.agrees,
    })
}

/// Clock error of port `p` of `ports` in the line-rate run: spread evenly over -1 .. +1 %.
pub fn line_rate_clock_error(p: usize, ports: usize) -> f64 {
    if ports < 2 {
        return 0.0;
    }
    (p as f64 / (ports - 1) as f64 - 0.5) * 0.02
}

/// Records in the records datagrams of `frames` (each frame checked on the way; the last
/// one may have been cut by the end of the run).
fn records_in(frames: &[crate::frames::Frame]) -> Result<u64, CosimError> {
    let mut records = 0;
    for (i, f) in frames.iter().enumerate() {
        let payload = match crate::frames::check(&f.bytes) {
            Ok((_, payload)) => payload,
            Err(_) if i + 1 == frames.len() => break,
            Err(source) => {
                return Err(CosimError::Frame {
                    step: "checking a bench frame",
                    source,
                })
            }
        };
        let datagram = skinbox_protocol::DatagramRepr::parse(payload)?;
        if let skinbox_protocol::datagram::DatagramBody::Records(r) = datagram.body {
            records += r.len() as u64;
        }
    }
    Ok(records)
}

struct SceneSpeeds {
    ports: usize,
    cycles: u64,
    rtl: f64,
    reference: f64,
    agrees: bool,
}

/// RTL and reference on [`SCENE`], fastest of `rounds`.
fn scene_speeds(rounds: u32) -> Result<SceneSpeeds, CosimError> {
    let spec = crate::scene::builtin_spec(SCENE, 1_000_000_000, 20_000_000, 625_000)?;
    let (lines, _) = crate::run::lines(&spec);
    let cycles = crate::run::cycles(&spec);
    let model = Model::build(&spec.config, false, &default_cache_dir())?;
    let (mut rtl, mut reference, mut agrees) = (0.0f64, 0.0f64, true);
    for _ in 0..rounds.max(1) {
        let mut dut = Dut::new(&model, None)?;
        let started = Instant::now();
        let out = play(&mut dut, &lines, RESET_CYCLES, cycles);
        rtl = rtl.max(cycles as f64 / started.elapsed().as_secs_f64());
        let started = Instant::now();
        let predicted = predict_frames(&spec.config, &lines, cycles)?;
        reference = reference.max(cycles as f64 / started.elapsed().as_secs_f64());
        agrees &= predicted == assemble(&out).0;
    }
    Ok(SceneSpeeds {
        ports: spec.config.ports,
        cycles,
        rtl,
        reference,
        agrees,
    })
}
