//! Drives the pins of a [`Dut`] from exact-time line transitions and collects its output.

use crate::line::Transition;
use crate::{Dut, GmiiByte};
use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The link state the harness gives the box: no PHY, so not up and of unknown speed, as the
/// models assume it.
pub use skinbox_model::inputs::{LINK_SPEED, LINK_UP};

/// Holds the box in reset for `reset_cycles`, then plays every port's transitions (one
/// list per port, in edge order) until `cycles` edges have run. Returns the GMII bytes.
pub fn play(
    dut: &mut Dut,
    lines: &[Vec<Transition>],
    reset_cycles: u64,
    cycles: u64,
) -> Vec<GmiiByte> {
    play_with_progress(dut, lines, reset_cycles, cycles, &mut |_| {})
}

/// Cycles between progress calls.
pub const PROGRESS_STEP: u64 = 1 << 20;

/// As [`play`], calling `progress` with the cycles run about every [`PROGRESS_STEP`].
pub fn play_with_progress(
    dut: &mut Dut,
    lines: &[Vec<Transition>],
    reset_cycles: u64,
    cycles: u64,
    progress: &mut dyn FnMut(u64),
) -> Vec<GmiiByte> {
    let mut next_report = PROGRESS_STEP;
    assert!(
        lines.iter().all(|l| is_ordered(l)),
        "line transitions must be in edge order"
    );
    assert!(
        lines.len() <= dut.ports(),
        "{} lines for a {}-port box",
        lines.len(),
        dut.ports()
    );
    let mut out = vec![];
    dut.set_reset(true);
    dut.run(reset_cycles, |b| out.push(b));
    dut.set_reset(false);
    // next transition of every line, earliest first
    let mut heap: BinaryHeap<Reverse<(u64, usize, usize)>> = lines
        .iter()
        .enumerate()
        .filter_map(|(port, l)| l.first().map(|t| Reverse((t.edge, port, 0))))
        .collect();
    while let Some(Reverse((edge, port, index))) = heap.pop() {
        if edge > cycles {
            break;
        }
        // the level must be on the pin before edge `edge` runs
        let due = edge.saturating_sub(1);
        if due > dut.cycle() {
            dut.run(due - dut.cycle(), |b| out.push(b));
        }
        if dut.cycle() >= next_report {
            progress(dut.cycle());
            next_report = dut.cycle() + PROGRESS_STEP;
        }
        dut.set_rx(port, lines[port][index].level);
        if let Some(next) = lines[port].get(index + 1) {
            heap.push(Reverse((next.edge, port, index + 1)));
        }
    }
    while cycles > dut.cycle() {
        let step = (cycles - dut.cycle()).min(PROGRESS_STEP);
        dut.run(step, |b| out.push(b));
        progress(dut.cycle());
    }
    out
}

/// Whether a [`Transition`] list is in edge order, as [`play`] needs.
pub fn is_ordered(line: &[Transition]) -> bool {
    line.windows(2).all(|w| w[0].edge <= w[1].edge)
}
