//! UART lines as pin transitions at exact times.
//!
//! A cell's UART sends 8N1 frames with its own bit period (its clock error) from exact
//! start times. The box samples the pin at its rising clock edges: edge `k` is at
//! `k x 8 ns` after the simulation starts, and a transition at time `t` is first seen by
//! edge `ceil(t / 8 ns)`. The box stamps a packet with the tick of that edge.

use skinbox_cells::rng::Rng;
use skinbox_protocol::TICK_NS;

/// The box of the UART clock-error sweeps (`cosim/tests/baud_mismatch.rs` and the report's
/// C4a): one port, a 5,000-tick flush timeout and status reports every
/// [`BAUD_SWEEP_STATUS_TICKS`], so one verilated model serves both.
pub fn baud_sweep_config() -> skinbox_gateware::interface_box::BoxConfig {
    skinbox_gateware::interface_box::BoxConfig {
        ports: 1,
        flush_timeout_ticks: 5_000,
        status_period_ticks: BAUD_SWEEP_STATUS_TICKS,
        ..Default::default()
    }
}

/// The sweeps' status period, ticks (8.8 ms): the first periodic report comes after the
/// last of 150 back-to-back packets on a line up to 8 % slow (8.2 ms) and counts them all.
pub const BAUD_SWEEP_STATUS_TICKS: u64 = 1_100_000;

/// Cycles a sweep runs: to its first periodic status report and that report's frame out.
pub const BAUD_SWEEP_CYCLES: u64 = BAUD_SWEEP_STATUS_TICKS + 5_000;

/// One byte on a line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct UartByte {
    /// Time of the start bit's falling edge, ns from the start of the simulation.
    pub start_ns: f64,
    /// Length of one bit on this line, ns (250 ns at 4 Mbit/s, less for a fast clock).
    pub bit_ns: f64,
    /// The byte.
    pub value: u8,
    /// Level of the stop bit (low makes a framing error).
    pub stop_level: bool,
}

impl UartByte {
    /// Time after the stop bit.
    pub fn end_ns(&self) -> f64 {
        self.start_ns + 10.0 * self.bit_ns
    }
}

pub use skinbox_model::pins::Transition;

/// The edge that first samples a change at `t_ns`.
pub fn first_edge(t_ns: f64) -> u64 {
    (t_ns / TICK_NS as f64).ceil().max(0.0) as u64
}

/// The transitions of a line sending `bytes` (in time order, not overlapping), idle high
/// before, between and after them. Transitions that no edge can see (shorter than a
/// clock) are kept; the later one wins at the edge.
pub fn transitions(bytes: &[UartByte]) -> Vec<Transition> {
    jittered_transitions(bytes, &Jitter::NONE).0
}

/// Random timing noise on a line's edges: each level change moves by an offset drawn
/// uniformly from `-peak_ns..=peak_ns`, independently per edge (seeded, repeatable).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Jitter {
    /// Largest offset of one edge, ns (at most a quarter bit, so edges keep their order).
    pub peak_ns: f64,
    /// Seed of the offsets.
    pub seed: u64,
}

impl Jitter {
    /// Exact edges.
    pub const NONE: Jitter = Jitter {
        peak_ns: 0.0,
        seed: 0,
    };
}

/// As [`transitions`], each edge moved by `jitter`; also returns the jittered time of
/// every byte's start-bit falling edge (the true edge the box should stamp).
pub fn jittered_transitions(bytes: &[UartByte], jitter: &Jitter) -> (Vec<Transition>, Vec<f64>) {
    let mut random = Rng::new(jitter.seed);
    let mut offset = move || {
        if jitter.peak_ns == 0.0 {
            return 0.0;
        }
        random.range(-jitter.peak_ns, jitter.peak_ns)
    };
    let mut starts = Vec::with_capacity(bytes.len());
    let mut out: Vec<Transition> = Vec::with_capacity(bytes.len() * 6);
    let mut level = true;
    let mut push = |t_ns: f64, new: bool, level: &mut bool| -> f64 {
        if new == *level {
            return t_ns;
        }
        let t = t_ns + offset();
        out.push(Transition {
            edge: first_edge(t),
            level: new,
        });
        *level = new;
        t
    };
    for b in bytes {
        assert!(
            jitter.peak_ns <= b.bit_ns / 4.0,
            "jitter {} ns is more than a quarter bit",
            jitter.peak_ns
        );
        // a start bit after a high stop bit is always a falling edge
        starts.push(push(b.start_ns, false, &mut level));
        for bit in 0..8 {
            push(
                b.start_ns + (1 + bit) as f64 * b.bit_ns,
                b.value >> bit & 1 == 1,
                &mut level,
            );
        }
        push(b.start_ns + 9.0 * b.bit_ns, b.stop_level, &mut level);
        push(b.end_ns(), true, &mut level);
    }
    (out, starts)
}

/// Back-to-back 8N1 bytes of one UART with bit length `bit_ns` from `start_ns`.
pub fn back_to_back(data: &[u8], start_ns: f64, bit_ns: f64) -> Vec<UartByte> {
    data.iter()
        .enumerate()
        .map(|(i, value)| UartByte {
            start_ns: start_ns + i as f64 * 10.0 * bit_ns,
            bit_ns,
            value: *value,
            stop_level: true,
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jitter_moves_every_edge_within_its_peak_and_keeps_the_order() {
        let bytes = back_to_back(&[0x55, 0xAA, 0x0F, 0x00, 0xFF], 1000.0, 250.0);
        let exact = transitions(&bytes);
        let jitter = Jitter {
            peak_ns: 20.0,
            seed: 7,
        };
        let (moved, starts) = jittered_transitions(&bytes, &jitter);
        assert_eq!(moved.len(), exact.len());
        let mut differ = 0;
        for (m, e) in moved.iter().zip(&exact) {
            assert_eq!(m.level, e.level);
            // 20 ns is 2.5 clocks: an edge moves by at most 3 clocks
            assert!(m.edge.abs_diff(e.edge) <= 3, "{m:?} vs {e:?}");
            differ += usize::from(m.edge != e.edge);
        }
        assert!(differ > exact.len() / 2, "the edges did move");
        assert!(moved.windows(2).all(|w| w[0].edge <= w[1].edge));
        for (s, b) in starts.iter().zip(&bytes) {
            assert!((s - b.start_ns).abs() <= 20.0);
        }
        assert_eq!(
            jittered_transitions(&bytes, &jitter),
            (moved, starts),
            "seeded"
        );
    }

    #[test]
    fn a_byte_is_start_data_lsb_first_and_stop() {
        // 0x35 = 0011_0101: LSB first 1,0,1,0,1,1,0,0
        let t = transitions(&back_to_back(&[0x35], 100.0, 250.0));
        let levels: Vec<(u64, bool)> = t.iter().map(|t| (t.edge, t.level)).collect();
        let at = |bits: f64| first_edge(100.0 + bits * 250.0);
        assert_eq!(
            levels,
            vec![
                (at(0.0), false),
                (at(1.0), true),
                (at(2.0), false),
                (at(3.0), true),
                (at(4.0), false),
                (at(5.0), true),
                (at(7.0), false),
                (at(9.0), true),
            ]
        );
        assert_eq!(
            first_edge(100.0),
            13,
            "100 ns is sampled by the edge at 104 ns"
        );
        assert_eq!(first_edge(104.0), 13);
    }
}
