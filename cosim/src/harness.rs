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
    let mut player = Player::new(dut, lines.to_vec(), reset_cycles);
    let mut out = vec![];
    while player.cycle() < cycles {
        let to = (player.cycle() + PROGRESS_STEP).min(cycles);
        out.extend(player.run_to(to));
        progress(player.cycle());
    }
    out
}

/// Plays the lines into a [`Dut`] in steps, as far as asked each time; a line's transitions
/// not yet driven can be replaced between steps ([`Player::replace_line`]), so pins can be
/// driven by cells that react to what the box sent.
pub struct Player<'a> {
    dut: &'a mut Dut,
    lines: Vec<Vec<Transition>>,
    /// Per line, the index of its next transition not yet driven.
    next: Vec<usize>,
    /// Next transition of every line, earliest first.
    heap: BinaryHeap<Reverse<(u64, usize, usize)>>,
    /// GMII bytes not yet handed back (of the reset).
    out: Vec<GmiiByte>,
}

impl<'a> Player<'a> {
    /// Holds the box in reset for `reset_cycles`, ready to play `lines` (one per port, in edge order).
    pub fn new(dut: &'a mut Dut, lines: Vec<Vec<Transition>>, reset_cycles: u64) -> Player<'a> {
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
        let mut player = Player {
            dut,
            next: vec![0; lines.len()],
            lines,
            heap: BinaryHeap::new(),
            out,
        };
        player.rebuild_heap();
        player
    }

    /// Rising clock edges so far.
    pub fn cycle(&self) -> u64 {
        self.dut.cycle()
    }

    /// The box.
    pub fn dut(&mut self) -> &mut Dut {
        self.dut
    }

    fn rebuild_heap(&mut self) {
        self.heap = self
            .lines
            .iter()
            .enumerate()
            .filter_map(|(port, l)| {
                l.get(self.next[port])
                    .map(|t| Reverse((t.edge, port, self.next[port])))
            })
            .collect();
    }

    /// Runs until `cycles` edges have run, driving every transition due by then; returns
    /// the GMII bytes.
    pub fn run_to(&mut self, cycles: u64) -> Vec<GmiiByte> {
        let mut out = std::mem::take(&mut self.out);
        while let Some(&Reverse((edge, port, index))) = self.heap.peek() {
            // the level must be on the pin before edge `edge` runs
            let due = edge.saturating_sub(1);
            if due >= cycles {
                break;
            }
            self.heap.pop();
            if due > self.dut.cycle() {
                self.dut.run(due - self.dut.cycle(), |b| out.push(b));
            }
            self.dut.set_rx(port, self.lines[port][index].level);
            self.next[port] = index + 1;
            if let Some(next) = self.lines[port].get(index + 1) {
                self.heap.push(Reverse((next.edge, port, index + 1)));
            }
        }
        if cycles > self.dut.cycle() {
            self.dut.run(cycles - self.dut.cycle(), |b| out.push(b));
        }
        out
    }

    /// Replaces line `port` by `line` (in edge order); the transitions already driven must
    /// be `line`'s too (the new line differs only where the pin has not been driven yet:
    /// panics otherwise, a caller's bug).
    pub fn replace_line(&mut self, port: usize, line: Vec<Transition>) {
        assert!(is_ordered(&line), "line transitions must be in edge order");
        let driven = self.next[port];
        assert!(
            line.len() >= driven && line[..driven] == self.lines[port][..driven],
            "port {port}: the new line differs in transitions already driven (cycle {})",
            self.dut.cycle()
        );
        assert!(
            line.get(driven).is_none_or(|t| t.edge > self.dut.cycle()),
            "port {port}: a new transition at edge {} is already due (cycle {})",
            line[driven].edge,
            self.dut.cycle()
        );
        self.lines[port] = line;
        self.rebuild_heap();
    }
}

/// Whether a [`Transition`] list is in edge order, as [`play`] needs.
pub fn is_ordered(line: &[Transition]) -> bool {
    line.windows(2).all(|w| w[0].edge <= w[1].edge)
}
