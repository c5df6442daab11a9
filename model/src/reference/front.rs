//! The ports' front end, per port and without a clock loop: which bytes the UART receiver
//! decodes from the pin's transitions, and which packets and counter events the deframing
//! engine makes of them at its visits of the port (it visits each port on a fixed
//! schedule, so a port's outcome depends on its own pin and, for drops, on the store's
//! occupancy alone).
//!
//! Cycle `c` below is the clock period after edge `c` (the harness's edge numbering):
//! registers hold what edge `c` stored, and what they compute is stored by edge `c + 1`.
//! `level(e)` is what the synchroniser's first flop captured at edge `e`.

use crate::pins::Transition;
use skinbox_protocol::cell::{CellFraming, PACKET_LEN};
use skinbox_protocol::status::PortCounter;
use std::cell::Cell;

/// Fixed numbers of the UART receivers and the deframing engine.
#[derive(Debug, Clone, Copy)]
pub(super) struct FrontTiming {
    /// Cycles from the first low sample of a start bit to the sample of each bit
    /// ([`crate::timing::bit_middles`]).
    pub middles: [u64; 10],
    /// The engine's scan period: port `p` is visited in the cycles `c` with
    /// `(c - scan_origin - p) mod scan_period = 0`.
    pub scan_period: u64,
    /// Cycle in which the scan visits port 0 first.
    pub scan_origin: u64,
    /// Clocks after a byte's strobe at which a packet without a next byte is truncated.
    pub truncation: u64,
    /// Header and end bytes.
    pub framing: CellFraming,
    /// Last cycle the ports are held in reset: the synchroniser reads high up to its edge.
    pub port_reset_until: u64,
    /// Tick of cycle `c` is `c - tick_offset`.
    pub tick_offset: u64,
}

impl FrontTiming {
    /// The first cycle at or after `c` in which the engine visits `port`.
    fn visit(&self, port: usize, c: u64) -> u64 {
        let phase = (c as i128 - self.scan_origin as i128 - port as i128)
            .rem_euclid(self.scan_period as i128) as u64;
        c + (self.scan_period - phase) % self.scan_period
    }
}

/// A packet the engine started (header seen), good or rejected.
#[derive(Debug, Clone)]
pub(super) struct StartedPacket {
    /// Cycle of its header's visit: the store's occupancy the engine sees is this cycle's.
    pub check: u64,
    /// Cycle of the decision on its header (the loss flag it carries is taken then).
    pub start: u64,
    /// Cycle of the decision that ends it (its 20th byte, or its rejection).
    pub end: u64,
    /// Complete with the right end byte.
    pub good: bool,
    /// Tick of the first low sample of its header's start bit.
    pub stamp: u64,
    /// The 20 bytes (meaningful when good).
    pub bytes: [u8; PACKET_LEN],
}

/// One port's front-end output.
#[derive(Debug, Default, Clone)]
pub(super) struct PortFront {
    /// Packets in order.
    pub packets: Vec<StartedPacket>,
    /// Counter events: (decision cycle, counter bits), in order.
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
    /// Cycle its stop bit is sampled (the receiver holds it from the next cycle on).
    strobe: u64,
}

/// Every byte the receiver completes on this pin, in order, up to `end`.
fn receive(pin: &Pin, t: &FrontTiming, end: u64) -> Vec<Byte> {
    let middles = t.middles;
    let mut out = vec![];
    let mut from = 0;
    while let Some(m) = pin.next_fall(from) {
        if m >= end {
            break;
        }
        let k0 = m + middles[0];
        if pin.majority(k0) {
            // a glitch: back to idle after the start bit's middle
            from = k0;
            continue;
        }
        let mut value = 0u8;
        for (b, middle) in middles.iter().enumerate().take(9).skip(1) {
            value |= u8::from(pin.majority(m + middle)) << (b - 1);
        }
        let k9 = m + middles[9];
        out.push(Byte {
            value,
            framing_error: !pin.majority(k9),
            strobe: k9,
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

/// Clocks from a visit to the engine's decision about it.
const DECISION: u64 = crate::timing::DEFRAMER_DECISION_CLOCKS;

/// The deframing engine on port `port`'s pin: packets and counter events up to `end`.
pub(super) fn port_front(
    transitions: &[Transition],
    port: usize,
    t: &FrontTiming,
    end: u64,
) -> PortFront {
    let pin = Pin {
        transitions,
        reset_until: t.port_reset_until,
        cursor: Cell::new(0),
    };
    let mut out = PortFront::default();
    let mut aligned = false;
    // the packet being collected and its bytes so far; the strobe of the last byte
    let mut current: Option<(StartedPacket, usize)> = None;
    let mut last_strobe = 0u64;
    for byte in receive(&pin, t, end) {
        let visit = t.visit(port, byte.strobe + 1);
        let decision = visit + DECISION;
        let mut events = 0u8;
        if current.is_some() {
            // the first visit whose decision sees the limit passed since the last strobe
            let due = t.visit(port, last_strobe + t.truncation - DECISION);
            let truncated_before = due < visit;
            let truncated_now = due == visit && byte.strobe - last_strobe >= t.truncation;
            if truncated_before || truncated_now {
                let (mut p, _) = current.take().expect("checked");
                p.end = due + DECISION;
                out.packets.push(p);
                aligned = false;
                if truncated_before {
                    out.events.push((due + DECISION, TRUNCATED | RESYNC));
                } else {
                    events |= TRUNCATED | RESYNC;
                }
            }
        }
        last_strobe = byte.strobe;
        if byte.framing_error {
            events |= FRAMING_ERROR;
        }
        match current.take() {
            None => {
                let header = !byte.framing_error
                    && (byte.value == t.framing.data_header
                        || byte.value == t.framing.event_header);
                if header {
                    let mut bytes = [0; PACKET_LEN];
                    bytes[0] = byte.value;
                    let packet = StartedPacket {
                        check: visit,
                        start: decision,
                        end: 0,
                        good: false,
                        stamp: byte.strobe - t.middles[9] - t.tick_offset,
                        bytes,
                    };
                    current = Some((packet, 1));
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
                    p.end = decision;
                    out.packets.push(p);
                    aligned = false;
                    events |= FRAMING | RESYNC;
                } else if n == PACKET_LEN - 1 {
                    p.end = decision;
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
            out.events.push((decision, events));
        }
    }
    if let Some((mut p, _)) = current {
        let due = t.visit(port, last_strobe + t.truncation - DECISION);
        if due + DECISION < end {
            p.end = due + DECISION;
            out.packets.push(p);
            out.events.push((due + DECISION, TRUNCATED | RESYNC));
        }
    }
    out
}
