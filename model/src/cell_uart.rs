//! The cells' side of the downlink: a UART receiver per bus root that decodes the box's
//! transmit pins ([`PinChange`]s, box ticks) into 20-byte cell command packets, as a cell's
//! UART does: a fall from idle starts a byte, every bit is sampled once in its middle
//! (measured from the start edge with the nominal bit time), the stop bit must be high.
//!
//! Bytes follow each other into a packet while each starts within [`PACKET_GAP_BITS`] bit
//! times of the one before (the box sends a packet's bytes in consecutive frames); a longer
//! idle gap ends the packet. A byte whose start bit is no longer low in its middle (a
//! glitch) is ignored. A byte with a low stop bit is a framing error: the packet it is in is
//! discarded, and the receiver waits for the pin to idle [`IDLE_BITS`] before it takes a
//! start edge again (a packet sent right behind is lost with it). A packet cut short by a
//! gap is discarded too. Both are counted, never panicked on: the cells miss such a command.
//!
//! The receiver is fed the pin changes in tick order and told how far the pins are known
//! ([`CellUartReceiver::advance_to`]); it hands back each packet as soon as the middle of
//! its last stop bit is known, with the tick its first start bit began.

use crate::downlink::PinChange;
use skinbox_protocol::cell::PACKET_LEN;

/// Bit times from one byte's start to the next's beyond which a packet ends: a frame of
/// the box's downlink is 10 or 11 bits, so a byte of the same packet starts within 11.
pub const PACKET_GAP_BITS: f64 = 13.0;

/// Bit times the pin must stay high after a framing error before a byte starts again
/// (within a burst of bytes the pin is high for at most 9: a 0xFF and its stop bit).
pub const IDLE_BITS: f64 = 10.0;

/// A cell command packet received from a transmit pin.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReceivedPacket {
    /// The port (bus) whose pin carried it.
    pub port: usize,
    /// The box tick its first start bit began (the fall of the pin).
    pub tick: u64,
    /// The 20 bytes.
    pub bytes: [u8; PACKET_LEN],
}

/// What the receivers rejected, summed over ports.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ReceiverCounts {
    /// Packets received whole.
    pub packets: u64,
    /// Bytes whose stop bit was low.
    pub framing_errors: u64,
    /// Packets discarded: a framing error in them, or cut short by an idle gap.
    pub packets_discarded: u64,
}

/// One port's receiver.
#[derive(Debug, Clone)]
struct Port {
    /// The pin's level after the changes taken so far (idle high).
    level: bool,
    /// Changes from the current byte's start edge on, not yet sampled past.
    changes: Vec<(u64, bool)>,
    /// The start edge of the byte being received.
    byte_start: Option<u64>,
    /// The packet so far: its first start edge and bytes.
    packet_start: u64,
    bytes: Vec<u8>,
    /// The start of the last byte received (for the idle gap).
    last_byte_start: Option<u64>,
    /// The tick the pin last went high.
    high_since: u64,
    /// After a framing error: no byte starts until the pin was idle for [`IDLE_BITS`].
    discarding: bool,
}

/// The cells' UART receivers on every transmit pin of a box.
#[derive(Debug, Clone)]
pub struct CellUartReceiver {
    bit_ticks: f64,
    ports: Vec<Port>,
    counts: ReceiverCounts,
}

impl CellUartReceiver {
    /// Receivers for `ports` pins at `baud` on a `clock_hz` box clock, the pins idle.
    pub fn new(ports: usize, clock_hz: u64, baud: u64) -> CellUartReceiver {
        let port = Port {
            level: true,
            changes: Vec::new(),
            byte_start: None,
            packet_start: 0,
            bytes: Vec::with_capacity(PACKET_LEN),
            last_byte_start: None,
            high_since: 0,
            discarding: false,
        };
        CellUartReceiver {
            bit_ticks: clock_hz as f64 / baud as f64,
            ports: vec![port; ports],
            counts: ReceiverCounts::default(),
        }
    }

    /// Takes one pin change (in tick order per port; a port the box does not have panics:
    /// a harness bug).
    pub fn push(&mut self, change: &PinChange) {
        let idle_ticks = (IDLE_BITS * self.bit_ticks) as u64;
        let port = &mut self.ports[change.port];
        if port.byte_start.is_some() {
            port.changes.push((change.tick, change.level));
            return;
        }
        if port.level && !change.level {
            if port.discarding && change.tick >= port.high_since + idle_ticks {
                port.discarding = false;
            }
            if !port.discarding {
                port.byte_start = Some(change.tick);
                port.changes.push((change.tick, change.level));
                return;
            }
        }
        if !port.level && change.level {
            port.high_since = change.tick;
        }
        port.level = change.level;
    }

    /// The pins are known up to (not including) tick `tick`: the packets whose last stop
    /// bit's middle is before it, in port order, each port's in order.
    pub fn advance_to(&mut self, tick: u64) -> Vec<ReceivedPacket> {
        let mut out = Vec::new();
        for p in 0..self.ports.len() {
            while let Some(start) = self.ports[p].byte_start {
                let stop_middle = self.middle(start, 9);
                if stop_middle >= tick {
                    break;
                }
                self.take_byte(p, start, &mut out);
            }
        }
        out
    }

    /// What was received and rejected so far.
    pub fn counts(&self) -> ReceiverCounts {
        self.counts
    }

    /// The tick of bit `bit`'s middle in the byte starting at `start`.
    fn middle(&self, start: u64, bit: u32) -> u64 {
        start + ((f64::from(bit) + 0.5) * self.bit_ticks) as u64
    }

    /// Samples the byte starting at `start` on port `p` (its stop bit's middle is known),
    /// then looks for the next start edge among the changes after that middle.
    fn take_byte(&mut self, p: usize, start: u64, out: &mut Vec<ReceivedPacket>) {
        let samples: Vec<u64> = (0..10).map(|b| self.middle(start, b)).collect();
        let gap = (PACKET_GAP_BITS * self.bit_ticks) as u64;
        let port = &mut self.ports[p];
        let level_at = |t: u64| {
            port.changes
                .iter()
                .take_while(|c| c.0 <= t)
                .last()
                .map_or(port.level, |c| c.1)
        };
        let levels: Vec<bool> = samples.iter().map(|&t| level_at(t)).collect();
        let stop_level = levels[9];
        // the changes after the stop bit's middle stay; the level there is the line's
        let keep = port.changes.partition_point(|c| c.0 <= samples[9]);
        if let Some(rise) = port.changes[..keep].iter().rev().find(|c| c.1) {
            port.high_since = rise.0;
        }
        let rest = port.changes.split_off(keep);
        port.level = stop_level;
        port.changes.clear();
        port.byte_start = None;
        if port.last_byte_start.is_some_and(|last| start > last + gap) && !port.bytes.is_empty() {
            // an idle gap: the packet so far ends short
            self.counts.packets_discarded += 1;
            port.bytes.clear();
        }
        if !levels[0] {
            port.last_byte_start = Some(start);
            if !stop_level {
                self.counts.framing_errors += 1;
                self.counts.packets_discarded += 1;
                port.bytes.clear();
                port.discarding = true;
            } else {
                if port.bytes.is_empty() {
                    port.packet_start = start;
                }
                let byte = (1..9).fold(0u8, |b, i| b | u8::from(levels[i]) << (i - 1));
                port.bytes.push(byte);
                if port.bytes.len() == PACKET_LEN {
                    let mut bytes = [0; PACKET_LEN];
                    bytes.copy_from_slice(&port.bytes);
                    port.bytes.clear();
                    self.counts.packets += 1;
                    out.push(ReceivedPacket {
                        port: p,
                        tick: port.packet_start,
                        bytes,
                    });
                }
            }
        }
        for (tick, level) in rest {
            self.push(&PinChange {
                tick,
                port: p,
                level,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::downlink::DownlinkModel;
    use skinbox_protocol::command::ALL_PORTS;

    const CLOCK_HZ: u64 = 125_000_000;
    const BAUD: u64 = 4_000_000;

    fn packet(n: u8) -> [u8; PACKET_LEN] {
        std::array::from_fn(|i| (i as u8).wrapping_mul(37) ^ n)
    }

    /// The downlink model's pins after three offers (one to every port).
    fn downlink(ports: usize) -> DownlinkModel {
        let mut d = DownlinkModel::new(ports, CLOCK_HZ, BAUD);
        assert!(d.offer(1_000, 1, packet(1)));
        assert!(d.offer(1_100, ALL_PORTS, packet(2)));
        assert!(d.offer(40_000, 0, packet(0xFF)));
        d.drain();
        d
    }

    #[test]
    fn the_packets_on_the_pins_are_the_packets_the_downlink_started() {
        for ports in [2, 8, 64] {
            let d = downlink(ports);
            let mut rx = CellUartReceiver::new(ports, CLOCK_HZ, BAUD);
            // fed in slices of 1,000 ticks, as a stepped simulation does
            let mut got = vec![];
            let mut changes = d.changes().iter().peekable();
            let end = d.changes().last().unwrap().tick + 1_000;
            for until in (0..end).step_by(1_000) {
                while let Some(c) = changes.next_if(|c| c.tick < until) {
                    rx.push(c);
                }
                got.extend(rx.advance_to(until));
            }
            got.sort_by_key(|p| (p.tick, p.port));
            let started: Vec<ReceivedPacket> = d
                .starts()
                .iter()
                .map(|s| ReceivedPacket {
                    port: s.port,
                    tick: s.tick,
                    bytes: s.bytes,
                })
                .collect();
            assert_eq!(got, started, "{ports} ports");
            assert_eq!(
                rx.counts(),
                ReceiverCounts {
                    packets: ports as u64 + 2,
                    ..Default::default()
                }
            );
        }
    }

    #[test]
    fn a_low_stop_bit_loses_its_packet_and_is_counted() {
        let d = downlink(8);
        let bit = CLOCK_HZ as f64 / BAUD as f64;
        // port 1's first packet: its first byte's stop bit held low
        let first = *d.starts().iter().find(|s| s.port == 1).unwrap();
        assert_eq!(first.bytes, packet(1));
        let (from, to) = (
            first.tick + (9.0 * bit) as u64,
            first.tick + (10.0 * bit) as u64,
        );
        let mut rx = CellUartReceiver::new(8, CLOCK_HZ, BAUD);
        let mut changes: Vec<PinChange> = d.changes().to_vec();
        changes.retain(|c| c.port != 1 || !(from..to).contains(&c.tick));
        changes.push(PinChange {
            tick: from,
            port: 1,
            level: false,
        });
        changes.sort_by_key(|c| (c.tick, c.port));
        for c in &changes {
            rx.push(c);
        }
        let got = rx.advance_to(u64::MAX);
        // port 1's second packet followed right behind: lost with it
        assert!(got.iter().all(|p| p.port != 1 || p.tick > to));
        let on_1 = d.starts().iter().filter(|s| s.port == 1).count();
        assert_eq!(on_1, 2);
        assert_eq!(got.len(), d.starts().len() - on_1);
        let counts = rx.counts();
        assert_eq!(counts.framing_errors, 1, "{counts:?}");
        assert_eq!(counts.packets_discarded, 1, "{counts:?}");
    }
}
