//! One co-simulation run: packets on the box's UART pins, frames out, everything checked.
//! The spec and the analysis are in [`crate::run`] (re-exported here); this module runs the
//! verilated box and chooses between it and the reference model.

use crate::error::CosimError;
use crate::frames::assemble;
use crate::harness::play_with_progress;
use crate::model::{default_cache_dir, Model};
use crate::run::analyse;
pub use crate::run::{
    cycles, lines, HostFrame, SentPacket, SimReport, SimRun, SimSpec, RESET_CYCLES, TICK_ZERO_CYCLE,
};
use crate::Dut;
use skinbox_model::downlink::PinChange;
use std::time::Instant;

/// Runs `spec` on the verilated box.
pub fn run_rtl(spec: &SimSpec) -> Result<SimRun, CosimError> {
    run_rtl_with_progress(spec, &mut |_, _| {})
}

/// Which model of the box runs a [`SimSpec`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Fidelity {
    /// The verilated gateware, every clock: the truth.
    #[default]
    Rtl,
    /// The packet-level reference model ([`crate::reference`]).
    Reference,
}

/// Runs `spec` at the chosen fidelity, calling `progress(cycles done, cycles in all)`.
pub fn run_with_progress(
    spec: &SimSpec,
    fidelity: Fidelity,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<SimRun, CosimError> {
    match fidelity {
        Fidelity::Rtl => run_rtl_with_progress(spec, progress),
        Fidelity::Reference => crate::reference::run_reference_with_progress(spec, progress),
    }
}

/// As [`run_rtl`], calling `progress(cycles done, cycles in all)` as it goes.
pub fn run_rtl_with_progress(
    spec: &SimSpec,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<SimRun, CosimError> {
    let model = Model::build(&spec.config, spec.vcd.is_some(), &default_cache_dir())?;
    let mut dut = Dut::new(&model, spec.vcd.as_deref())?;
    let (lines, true_starts) = lines(spec);
    let cycles = cycles(spec);
    for f in &spec.host_frames {
        dut.queue_rx_frame(f.edge, &f.wire())
            .map_err(CosimError::HostFrames)?;
    }
    let started = Instant::now();
    let out = play_with_progress(&mut dut, &lines, RESET_CYCLES, cycles, &mut |done| {
        progress(done, cycles)
    });
    let wall = started.elapsed().as_secs_f64();
    let (frames, _) = assemble(&out);
    let mut run = analyse(spec, &frames, &true_starts, wall)?;
    run.uart_tx = uart_tx_changes(&mut dut);
    Ok(run)
}

/// The box's transmit pin changes as box ticks (the pins going high at reset left out),
/// in tick order, ties by port.
pub(crate) fn uart_tx_changes(dut: &mut Dut) -> Vec<PinChange> {
    let mut changes: Vec<PinChange> = dut
        .take_uart_tx_edges()
        .into_iter()
        .filter(|e| e.edge >= TICK_ZERO_CYCLE)
        .map(|e| PinChange {
            tick: e.edge - TICK_ZERO_CYCLE,
            port: e.port,
            level: e.level,
        })
        .collect();
    changes.sort_by_key(|c| (c.tick, c.port));
    changes
}
