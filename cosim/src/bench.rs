//! Speed of the co-simulation: the full harness against the bare model loop, same design,
//! measured in one run.

use crate::harness::play;
use crate::line::{back_to_back, transitions};
use crate::model::{default_cache_dir, CosimError, Model};
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
}

/// Measures `cycles` clock cycles of an 8-port box each way, fastest of `rounds`.
pub fn bench_sim(ports: usize, cycles: u64, rounds: u32) -> Result<SimBench, CosimError> {
    let config = BoxConfig {
        ports,
        ..BoxConfig::default()
    };
    let model = Model::build(&config, false, &default_cache_dir())?;
    // every port busy: back-to-back bytes at 4 Mbit/s with per-port clock errors
    let bytes_needed = (cycles * 8 / 2_500 + 40) as usize;
    let lines: Vec<_> = (0..ports)
        .map(|p| {
            let packet: Vec<u8> = skinbox_protocol::DataRepr {
                cell_id: p as u16 + 1,
                ..Default::default()
            }
            .to_bytes()
            .to_vec();
            let data: Vec<u8> = packet.iter().cycle().take(bytes_needed).copied().collect();
            let bit_ns = 250.0 / (1.0 + (p as f64 - 3.5) * 0.002);
            transitions(&back_to_back(&data, 5_000.0 + p as f64 * 13.0, bit_ns))
        })
        .collect();
    let (mut rtl, mut bare, mut gmii) = (0.0f64, 0.0f64, 0u64);
    for _ in 0..rounds.max(1) {
        let mut dut = Dut::new(&model, None)?;
        let started = Instant::now();
        let out = play(&mut dut, &lines, 4, cycles);
        rtl = rtl.max(cycles as f64 / started.elapsed().as_secs_f64());
        gmii = out.len() as u64;

        let mut dut = Dut::new(&model, None)?;
        dut.set_reset(true);
        dut.run(4, |_| {});
        dut.set_reset(false);
        let started = Instant::now();
        dut.run(cycles, |_| {});
        bare = bare.max(cycles as f64 / started.elapsed().as_secs_f64());
    }
    Ok(SimBench {
        ports,
        cycles,
        rtl_cycles_per_second: rtl,
        bare_cycles_per_second: bare,
        harness_fraction_of_bare: rtl / bare,
        gmii_bytes: gmii,
    })
}
