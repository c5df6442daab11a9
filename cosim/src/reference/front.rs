//! The ports' front end, per port and without a clock loop: which bytes the UART receiver
//! decodes from the pin's transitions, and which packets, beats and counter events the
//! deframer makes of them.
//!
//! Cycle `c` below is the clock period after edge `c` (the harness's edge numbering):
//! registers hold what edge `c` stored, and what they compute is stored by edge `c + 1`.
//! `level(e)` is what the synchroniser's first flop captured at edge `e`.

use crate::line::Transition;
use skinbox_gateware::cell_deframer::INPUT_REGISTER_CLOCKS;
use skinbox_protocol::cell::{CellFraming, PACKET_LEN};
use skinbox_protocol::status::PortCounter;
use std::cell::Cell;

/// Fixed numbers of the UART receiver and deframer.
#[derive(Debug, Clone, Copy)]
pub(super) struct FrontTiming {
    /// Phase accumulator increment per clock.
    pub phase_increment: u64,
    /// Accumulator value after a start edge.
    pub phase_start: u64,
    /// Idle bit times inside a packet that truncate it.
    pub idle_gap_bits: u64,
    /// Header and end bytes.
    pub framing: CellFraming,
    /// Last cycle the ports are held in reset: the synchroniser reads high up to its edge.
    pub port_reset_until: u64,
    /// Tick of cycle `c` is `c - tick_offset`.
    pub tick_offset: u64,
}

impl FrontTiming {
    /// Cycles from the start detection's reference (the first low sample) to the middle
    /// of bit `b` (0 start, 1..=8 data, 9 stop, then idle bit times: the accumulator runs
    /// on): the accumulator, loaded two clocks after the first low sample, carries there.
    fn middle(&self, b: u64) -> u64 {
        let target = (b + 1) << crate::reference::PHASE_BITS;
        2 + (target - self.phase_start).div_ceil(self.phase_increment) - 1
    }
}

/// A packet the deframer started (header seen), good or rejected.
#[derive(Debug, Clone)]
pub(super) struct StartedPacket {
    /// Cycle its first beat (the first tick byte) is offered to the packet store.
    pub first_beat: u64,
    /// Cycle of its last beat (the 20th byte, or the error beat of a rejected packet).
    pub last_beat: u64,
    /// Complete with the right end byte.
    pub good: bool,
    /// Tick of the first low sample of its header's start bit.
    pub stamp: u64,
    /// The 20 bytes (meaningful when good).
    pub bytes: [u8; PACKET_LEN],
}

/// One port's front-end output.
#[derive(Debug, Default)]
pub(super) struct PortFront {
    /// Packets in order.
    pub packets: Vec<StartedPacket>,
    /// Counter events: (cycle the event is on the counter file's input, counter bits).
    pub events: Vec<(u64, u8)>,
}

/// The synchronised pin of one port. Queries move forward in time with small steps back,
/// so a cursor finds the transition in a few comparisons.
struct Pin<'a> {
    transitions: &'a [Transition],
    reset_until: u64,
    /// Number of transitions due by the last edge asked for.
    cursor: Cell<usize>,
}

impl Pin<'_> {
    /// Transitions due by edge `e` (with an edge at or before `e`).
    fn due(&self, e: u64) -> usize {
        let t = self.transitions;
        let mut i = self.cursor.get();
        while i < t.len() && t[i].edge <= e {
            i += 1;
        }
        while i > 0 && t[i - 1].edge > e {
            i -= 1;
        }
        self.cursor.set(i);
        i
    }

    /// Level captured at edge `e`: the last transition due by then; high in reset.
    fn level(&self, e: u64) -> bool {
        if e <= self.reset_until {
            return true;
        }
        let i = self.due(e);
        i == 0 || self.transitions[i - 1].level
    }

    /// Majority of the three samples the receiver holds in cycle `k`.
    fn majority(&self, k: u64) -> bool {
        let votes = (1..=3).filter(|d| self.level(k - d)).count();
        votes >= 2
    }

    /// First `m >= from` with a high sample at `m - 1` and a low one at `m`.
    fn next_fall(&self, from: u64) -> Option<u64> {
        let from = from.max(self.reset_until + 1);
        if !self.level(from) && self.level(from - 1) {
            return Some(from);
        }
        let mut i = self.due(from);
        while i < self.transitions.len() {
            let e = self.transitions[i].edge;
            let mut j = i;
            while j + 1 < self.transitions.len() && self.transitions[j + 1].edge == e {
                j += 1;
            }
            if !self.transitions[j].level && self.level(e - 1) {
                return Some(e);
            }
            i = j + 1;
        }
        None
    }
}

/// A byte the receiver delivered.
struct Byte {
    value: u8,
    framing_error: bool,
    /// Cycle its strobe is high at the deframer (after its input register).
    strobe: u64,
    /// Tick of the first low sample of its start bit.
    stamp: u64,
}

/// A busy stretch of the receiver: from `busy_from` (the first cycle the deframer sees
/// its bit count restarted), the cycle the deframer sees the idle gap after it when no
/// reception comes first (`gap_at`), and the byte, if one came.
struct Reception {
    busy_from: u64,
    gap_at: u64,
    byte: Option<Byte>,
}

/// Everything the receiver does on this pin, in order, up to `end`.
fn receive(pin: &Pin, t: &FrontTiming, end: u64) -> Vec<Reception> {
    let middles: Vec<u64> = (0..10).map(|b| t.middle(b)).collect();
    // the bit count is BIT_COUNT_AFTER_STOP from the stop bit's middle (9) or a glitch's
    // start-bit middle (0) on and reaches the gap's end `idle_gap_bits` middles later; the
    // deframer's register sees it a clock after that middle
    let gap_middle = |from: u64| t.middle(from + t.idle_gap_bits) + 1;
    let gap_after_stop = gap_middle(9);
    let gap_after_glitch = gap_middle(0);
    let mut out = vec![];
    let mut from = 0;
    while let Some(m) = pin.next_fall(from) {
        if m >= end {
            break;
        }
        // as the deframer sees them: through its input register
        let seen = INPUT_REGISTER_CLOCKS;
        let busy_from = m + 2 + seen;
        let k0 = m + middles[0];
        if pin.majority(k0) {
            // a glitch: back to idle after the start bit's middle
            out.push(Reception {
                busy_from,
                gap_at: m + gap_after_glitch + seen,
                byte: None,
            });
            from = k0;
            continue;
        }
        let mut value = 0u8;
        for (b, middle) in middles.iter().enumerate().take(9).skip(1) {
            value |= u8::from(pin.majority(m + middle)) << (b - 1);
        }
        let k9 = m + middles[9];
        out.push(Reception {
            busy_from,
            gap_at: m + gap_after_stop + seen,
            byte: Some(Byte {
                value,
                framing_error: !pin.majority(k9),
                strobe: k9 + 1 + seen,
                stamp: m - t.tick_offset,
            }),
        });
        from = k9;
    }
    out
}

const GOOD: u8 = 1 << PortCounter::PacketsGood as u8;
const END_BYTE: u8 = 1 << PortCounter::RejectedEndByte as u8;
const FRAMING: u8 = 1 << PortCounter::RejectedFraming as u8;
const TRUNCATED: u8 = 1 << PortCounter::RejectedTruncated as u8;
const GARBAGE: u8 = 1 << PortCounter::GarbageBytes as u8;
const FRAMING_ERROR: u8 = 1 << PortCounter::FramingErrors as u8;
const RESYNC: u8 = 1 << PortCounter::Resyncs as u8;

/// The deframer on one port's pin: packets and counter events up to cycle `end`.
pub(super) fn port_front(transitions: &[Transition], t: &FrontTiming, end: u64) -> PortFront {
    let pin = Pin {
        transitions,
        reset_until: t.port_reset_until,
        cursor: Cell::new(0),
    };
    let receptions = receive(&pin, t, end);
    let mut out = PortFront::default();
    let mut aligned = false;
    // the packet being collected: its bytes so far
    let mut current: Option<(StartedPacket, usize)> = None;
    // the deframer sees the idle gap here unless a reception restarts the bit count first
    let mut gap_at = 0u64;
    for r in &receptions {
        // truncation: the bit count reached the gap before this reception restarted it
        if current.is_some() {
            let fire = gap_at;
            if fire < r.busy_from {
                let (mut p, _) = current.take().expect("checked");
                p.last_beat = fire + 1;
                out.packets.push(p);
                out.events.push((fire + 1, TRUNCATED | RESYNC));
                aligned = false;
            }
        }
        let Some(byte) = &r.byte else {
            gap_at = r.gap_at;
            continue;
        };
        let at = byte.strobe + 1;
        let mut events = if byte.framing_error { FRAMING_ERROR } else { 0 };
        match current.take() {
            None => {
                let header = !byte.framing_error
                    && (byte.value == t.framing.data_header
                        || byte.value == t.framing.event_header);
                if header {
                    let mut bytes = [0; PACKET_LEN];
                    bytes[0] = byte.value;
                    current = Some((
                        StartedPacket {
                            first_beat: at,
                            last_beat: 0,
                            good: false,
                            stamp: byte.stamp,
                            bytes,
                        },
                        1,
                    ));
                } else {
                    events |= GARBAGE;
                    if aligned {
                        aligned = false;
                        events |= RESYNC;
                    }
                }
            }
            Some((mut p, n)) => {
                p.bytes[n] = byte.value;
                if byte.framing_error {
                    p.last_beat = at;
                    out.packets.push(p);
                    aligned = false;
                    events |= FRAMING | RESYNC;
                } else if n == PACKET_LEN - 1 {
                    p.last_beat = at;
                    p.good = byte.value == t.framing.end_of_packet;
                    aligned = p.good;
                    events |= if p.good { GOOD } else { END_BYTE | RESYNC };
                    out.packets.push(p);
                } else {
                    current = Some((p, n + 1));
                }
            }
        }
        if events != 0 {
            out.events.push((at, events));
        }
        gap_at = r.gap_at;
    }
    if let Some((mut p, _)) = current {
        let fire = gap_at;
        if fire + 1 < end {
            p.last_beat = fire + 1;
            out.packets.push(p);
            out.events.push((fire + 1, TRUNCATED | RESYNC));
        }
    }
    out
}
