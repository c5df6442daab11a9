//! The reference model ([`skinbox_model::reference`]) run on a [`SimSpec`], its frames
//! checked and measured as the RTL's are ([`crate::run`]).

use crate::error::CosimError;
use crate::run::{analyse, cycles, lines, SimRun, SimSpec};
pub use skinbox_model::reference::*;
use std::time::Instant;

/// Runs `spec` on the reference model.
pub fn run_reference(spec: &SimSpec) -> Result<SimRun, CosimError> {
    run_reference_with_progress(spec, &mut |_, _| {})
}

/// As [`run_reference`], calling `progress(cycles done, cycles in all)` as it goes.
pub fn run_reference_with_progress(
    spec: &SimSpec,
    progress: &mut dyn FnMut(u64, u64),
) -> Result<SimRun, CosimError> {
    let started = Instant::now();
    let (lines, true_starts) = lines(spec);
    let (frames, uart_tx) = predict_with_host_frames(
        &spec.config,
        &lines,
        &spec.host_frames,
        cycles(spec),
        progress,
    )?;
    let wall = started.elapsed().as_secs_f64();
    let mut run = analyse(spec, &frames, &true_starts, wall)?;
    run.uart_tx = uart_tx;
    Ok(run)
}
