//! The box's downlink to the cells: a model of the gateware's `CellDownlink`
//! (`gateware/src/cell_downlink.rs`) to the clock, so the reference model can say which
//! cell commands the box takes and when every bit of them is on which transmit pin.
//!
//! The gateware sends on every pin in one shared bit time and frame: after a frame's last
//! data bit a refill scan visits one port a clock and loads the next byte of its oldest
//! packet (or nothing) for the next frame. The model follows those visits and the copies of
//! accepted packets into the queues as events at their clocks, and writes each frame's
//! pins from the byte it loaded; ticks are box ticks (the tick counter and the downlink
//! leave reset together). An idle downlink costs nothing: frames without a queued packet
//! or a due time sync are skipped.
//!
//! Time syncs: every packet whose command byte is 5 leaves with bytes 4-11 = the tick of
//! its first start bit ([`PacketStart::tick`]), and the box's sync generator makes every
//! port send its own sync (cell id every cell) once a sync period, at the port's first
//! packet boundary whose refill sees the generator's epoch differ from the port's (the
//! epoch as the refill reads it, two clocks after the visit), before its queued packets.

use crate::timing::{bit_start, frame_bits, DOWNLINK_QUEUE_PACKETS, DOWNLINK_REFILL_LATENCY};
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::cell_command::{CellCommand, CellCommandRepr, CommandCode, ALL_CELLS};
use skinbox_protocol::command::ALL_PORTS;
use std::collections::VecDeque;

/// A change of one transmit pin: from clock `tick` on, `port`'s pin is at `level`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PinChange {
    /// First tick with the new level.
    pub tick: u64,
    /// The port.
    pub port: usize,
    /// The new level.
    pub level: bool,
}

/// A packet starting on a pin: its first start bit is on `port`'s pin from `tick` on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PacketStart {
    /// First tick of the start bit.
    pub tick: u64,
    /// The port.
    pub port: usize,
    /// The packet as it leaves (a time sync stamped).
    pub bytes: [u8; PACKET_LEN],
    /// It is the box's own sync (the sync generator's), not a queued packet.
    pub generated: bool,
}

/// Clocks from the offer to the first copy's commit: the offer register, then 20 copy
/// clocks (the commit is the 20th).
const OFFER_TO_COMMIT: u64 = 1 + PACKET_LEN as u64;
/// Edges from a refill visit to the edge its slot is freed (the count read two clocks
/// later, registered once more).
const VISIT_TO_FREE: u64 = 4;
/// Clocks from a refill visit to the clock it compares the port's epoch with the
/// generator's (the position RAM's read).
const VISIT_TO_EPOCH: u64 = 2;

/// `packet` as it leaves with its first start bit at `tick`: a time sync's bytes 4-11 are
/// the tick, big-endian.
pub fn stamped(mut packet: [u8; PACKET_LEN], tick: u64) -> [u8; PACKET_LEN] {
    if packet[3] == CommandCode::TimeSync as u8 {
        packet[4..12].copy_from_slice(&tick.to_be_bytes());
    }
    packet
}

/// The box's own time sync to every cell, leaving with its first start bit at `tick`.
pub fn generated_sync(tick: u64) -> [u8; PACKET_LEN] {
    CellCommandRepr {
        cell_id: ALL_CELLS,
        command: CellCommand::TimeSync { box_tick: tick },
    }
    .to_bytes()
}

/// The sync generator: its epoch toggles every `period` clocks from `origin` (the clock
/// after reset or after the clock a new period is first seen), and once at the origin of
/// a new period other than 0.
#[derive(Debug, Clone, Copy)]
struct SyncGenerator {
    period: u64,
    origin: u64,
    at_origin: bool,
}

impl SyncGenerator {
    /// The epoch in clock `tick`.
    fn epoch(&self, tick: u64) -> bool {
        if self.period == 0 || tick < self.origin {
            return self.at_origin;
        }
        self.at_origin ^ ((tick - self.origin) / self.period % 2 == 1)
    }

    /// The first clock after `tick` whose epoch differs from the clock before.
    fn next_toggle_after(&self, tick: u64) -> Option<u64> {
        if self.period == 0 {
            return None;
        }
        let n = tick.saturating_sub(self.origin) / self.period + 1;
        Some(self.origin + n * self.period)
    }
}

/// One port's queue.
#[derive(Debug, Clone, Default)]
struct Port {
    /// Packets counted in the queue (committed, last byte not yet read).
    count: u64,
    /// The packets committed whose bytes are not all read, oldest first.
    packets: VecDeque<[u8; PACKET_LEN]>,
    /// Next byte of the oldest packet.
    index: usize,
    /// The edge at which the oldest packet's slot is freed, once its last byte was read.
    free_at: Option<u64>,
    /// The pin's level after the last change written.
    pin: bool,
    /// The packet on the line is the generator's sync (`index` is its next byte).
    generated: bool,
    /// The generator's epoch when the port last started its sync.
    epoch_sent: bool,
    /// The packet on the line as it leaves (stamped).
    current: [u8; PACKET_LEN],
}

/// A copy into the queues under way.
#[derive(Debug, Clone)]
struct Copy {
    packet: [u8; PACKET_LEN],
    /// The ports still to commit, in order, and the cycle of the next commit.
    ports: VecDeque<usize>,
    next_commit: u64,
}

/// The downlink of a box with `ports` ports.
#[derive(Debug, Clone)]
pub struct DownlinkModel {
    clock_hz: u64,
    baud: u64,
    frame_bits: u64,
    /// The registers are those of this cycle (every edge up to it applied).
    tick: u64,
    ports: Vec<Port>,
    /// The offer taken last: busy until its copy's last commit (inclusive).
    busy_until: Option<u64>,
    copy: Option<Copy>,
    /// The frame whose refill scan is under way or next, and its next port to visit.
    frame: u64,
    next_port: usize,
    changes: Vec<PinChange>,
    /// The changes of the frame whose refill scan is under way.
    frame_changes: Vec<PinChange>,
    starts: Vec<PacketStart>,
    generator: SyncGenerator,
}

impl DownlinkModel {
    /// The downlink of `ports` pins at `baud` with a `clock_hz` box clock, just out of
    /// reset at tick 0: queues empty, pins high.
    pub fn new(ports: usize, clock_hz: u64, baud: u64) -> DownlinkModel {
        DownlinkModel {
            clock_hz,
            baud,
            frame_bits: frame_bits(ports),
            tick: 0,
            ports: (0..ports)
                .map(|_| Port {
                    pin: true,
                    ..Port::default()
                })
                .collect(),
            busy_until: None,
            copy: None,
            frame: 0,
            next_port: 0,
            changes: Vec::new(),
            frame_changes: Vec::new(),
            starts: Vec::new(),
            generator: SyncGenerator {
                period: 0,
                origin: 0,
                at_origin: false,
            },
        }
    }

    /// The same downlink whose sync period after reset is `ticks` (0: no syncs): the first
    /// clock after reset restarts the generator, so every port sends a sync at once.
    pub fn with_sync_period(mut self, ticks: u64) -> DownlinkModel {
        self.generator = SyncGenerator {
            period: ticks,
            origin: 1,
            at_origin: ticks != 0,
        };
        self
    }

    /// The sync period in effect, ticks (0: none).
    pub fn sync_period(&self) -> u64 {
        self.generator.period
    }

    /// Sets the sync period to `ticks` in clock `tick` (the command unit's clock that
    /// applies it, the clock before `done`): the generator restarts in the next clock, a
    /// sync at once unless 0. Ticks must not go back.
    pub fn set_sync_period(&mut self, tick: u64, ticks: u64) {
        self.advance_to(tick);
        let restart = tick + 1;
        self.generator = SyncGenerator {
            period: ticks,
            origin: restart + 1,
            at_origin: self.generator.epoch(restart) ^ (ticks != 0),
        };
    }

    /// The first frame from the current one whose refill scan starts at or after `tick`.
    fn first_frame_from(&self, tick: u64) -> u64 {
        // (a galloping search: the frames' starts follow the phase accumulator's rounding)
        let mut low = self.frame;
        if self.refill_start(low) >= tick {
            return low;
        }
        let mut step = 1;
        while self.refill_start(low + step) < tick {
            low += step;
            step *= 2;
        }
        // refill_start(low) < tick <= refill_start(low + step)
        let mut high = low + step;
        while high - low > 1 {
            let middle = low + (high - low) / 2;
            if self.refill_start(middle) < tick {
                low = middle;
            } else {
                high = middle;
            }
        }
        high
    }

    /// With nothing queued: moves on to the first frame before `tick`'s whose refill would
    /// start a sync, or to the first frame from `tick` (whole periods at a time).
    fn skip_idle_frames(&mut self, tick: u64) {
        let scan_clocks = VISIT_TO_EPOCH + self.ports.len() as u64;
        loop {
            let target = self.first_frame_from(tick);
            if self.frame >= target || self.sync_due(self.frame) {
                return;
            }
            // no port's epoch changes before the next toggle
            let scan = self.refill_start(self.frame);
            let quiet = match self.generator.next_toggle_after(scan + scan_clocks - 1) {
                Some(t) => target.min(self.first_frame_from(t.saturating_sub(scan_clocks))),
                None => target,
            };
            self.frame = quiet.max(self.frame + 1);
        }
    }

    /// A port's refill in frame `frame`'s scan would start the generator's sync.
    fn sync_due(&self, frame: u64) -> bool {
        let scan = self.refill_start(frame) + VISIT_TO_EPOCH;
        let (first, last) = (
            self.generator.epoch(scan),
            self.generator.epoch(scan + self.ports.len() as u64),
        );
        if first == last {
            return self.ports.iter().any(|p| p.epoch_sent != first);
        }
        self.ports
            .iter()
            .enumerate()
            .any(|(s, p)| p.epoch_sent != self.generator.epoch(scan + s as u64))
    }

    /// Tick from which bit `bit` of the shared frames is on the pins.
    fn bit_start(&self, bit: u64) -> u64 {
        bit_start(self.clock_hz, self.baud, bit)
    }

    /// The cycle of frame `frame`'s refill visit of port 0 (the clock after the pins took
    /// its last data bit).
    fn refill_start(&self, frame: u64) -> u64 {
        self.bit_start(frame * self.frame_bits + 8)
    }

    /// Nothing queued, copied or in flight: refills load nothing.
    fn idle(&self) -> bool {
        self.copy.is_none()
            && self
                .ports
                .iter()
                .all(|p| p.count == 0 && p.free_at.is_none() && !p.generated)
    }

    /// Applies the copy's commits whose count is in place by edge `edge` (a commit in
    /// cycle `c` counts from edge `c + 1`).
    fn commit_until(&mut self, edge: u64) {
        while let Some(copy) = &mut self.copy {
            if copy.next_commit + 1 > edge {
                return;
            }
            let port = copy.ports.pop_front().expect("a copy has ports left");
            let packet = copy.packet;
            copy.next_commit += PACKET_LEN as u64;
            if copy.ports.is_empty() {
                self.copy = None;
            }
            let p = &mut self.ports[port];
            p.count += 1;
            p.packets.push_back(packet);
        }
    }

    /// Applies the slot frees that happen by edge `edge`.
    fn free_until(&mut self, edge: u64) {
        for p in &mut self.ports {
            if p.free_at.is_some_and(|at| at <= edge) {
                p.free_at = None;
                p.count -= 1;
            }
        }
    }

    /// The cycle of the next refill visit (port `self.next_port` of `self.frame`).
    fn next_visit(&self) -> u64 {
        self.refill_start(self.frame) + self.next_port as u64
    }

    /// One refill visit: the port's byte for the next frame, and that frame's pins.
    fn visit(&mut self) {
        let visit = self.next_visit();
        let s = self.next_port;
        let start_bit = (self.frame + 1) * self.frame_bits;
        debug_assert!(visit + DOWNLINK_REFILL_LATENCY < self.bit_start(start_bit));
        self.next_port += 1;
        if self.next_port == self.ports.len() {
            self.next_port = 0;
            self.frame += 1;
        }
        self.visit_port(visit, s, start_bit);
        if self.next_port == 0 {
            // the frame's changes, in tick order and port order within a tick
            self.frame_changes.sort_by_key(|c| (c.tick, c.port));
            self.changes.append(&mut self.frame_changes);
        }
    }

    /// Port `s`'s refill at cycle `visit`, for the frame starting at bit `start_bit`.
    fn visit_port(&mut self, visit: u64, s: usize, start_bit: u64) {
        self.commit_until(visit);
        self.free_until(visit);
        let (clock_hz, baud) = (self.clock_hz, self.baud);
        let epoch = self.generator.epoch(visit + VISIT_TO_EPOCH);
        let start = bit_start(clock_hz, baud, start_bit);
        let port = &mut self.ports[s];
        let index = port.index;
        if port.generated {
            // the generator's sync under way
        } else if index == 0 && port.epoch_sent != epoch {
            // the generator's sync goes before the queued packets
            port.generated = true;
            port.epoch_sent = epoch;
            port.current = generated_sync(start);
        } else if port.count == 0 {
            return;
        } else if index == 0 {
            let packet = *port.packets.front().expect("a counted packet is queued");
            port.current = stamped(packet, start);
        }
        port.index += 1;
        if port.index == PACKET_LEN {
            port.index = 0;
            if port.generated {
                port.generated = false;
            } else {
                port.packets.pop_front();
                port.free_at = Some(visit + VISIT_TO_FREE);
            }
        }
        let packet = port.current;
        let byte = packet[index];
        let levels = std::iter::once(false)
            .chain((0..8).map(|b| byte >> b & 1 == 1))
            .chain(std::iter::once(true));
        for (b, level) in levels.enumerate() {
            if level != port.pin {
                port.pin = level;
                self.frame_changes.push(PinChange {
                    tick: bit_start(clock_hz, baud, start_bit + b as u64),
                    port: s,
                    level,
                });
            }
        }
        if index == 0 {
            self.starts.push(PacketStart {
                tick: start,
                port: s,
                bytes: packet,
                generated: port.generated,
            });
        }
    }

    /// Evaluates clocks up to (not including) `tick`: the registers are then those of
    /// cycle `tick`.
    pub fn advance_to(&mut self, tick: u64) {
        if tick <= self.tick {
            return;
        }
        loop {
            if self.idle() && self.next_port == 0 {
                self.skip_idle_frames(tick);
                if self.refill_start(self.frame) >= tick {
                    break;
                }
            }
            if self.next_visit() >= tick {
                break;
            }
            self.visit();
        }
        self.commit_until(tick);
        self.free_until(tick);
        self.tick = tick;
    }

    /// Offers `packet` for `port` (or `ALL_PORTS`) in clock `tick` (the command unit's
    /// clock before `done`); true when it is queued, false when refused (a copy under
    /// way, or a target port full). Ticks must not go back.
    pub fn offer(&mut self, tick: u64, port: u8, packet: [u8; PACKET_LEN]) -> bool {
        self.advance_to(tick);
        let full = |p: &Port| p.count == DOWNLINK_QUEUE_PACKETS;
        let busy = self.busy_until.is_some_and(|until| tick <= until);
        let refused = busy
            || if port == ALL_PORTS {
                self.ports.iter().any(full)
            } else {
                self.ports.get(port as usize).is_none_or(full)
            };
        if refused {
            return false;
        }
        let targets: VecDeque<usize> = if port == ALL_PORTS {
            (0..self.ports.len()).collect()
        } else {
            VecDeque::from([port as usize])
        };
        let first_commit = tick + OFFER_TO_COMMIT;
        self.busy_until = Some(first_commit + (targets.len() as u64 - 1) * PACKET_LEN as u64);
        self.copy = Some(Copy {
            packet,
            ports: targets,
            next_commit: first_commit,
        });
        true
    }

    /// Pin changes so far, in tick order and port order within a tick: every change of a
    /// frame whose refill scan ran (a change at tick `t` is reported by the time the model
    /// reached `t`).
    pub fn changes(&self) -> &[PinChange] {
        &self.changes
    }

    /// The packets started on the pins so far, in tick order.
    pub fn starts(&self) -> &[PacketStart] {
        &self.starts
    }

    /// Takes the pin changes so far (a long-running user keeps memory bounded).
    pub fn take_changes(&mut self) -> Vec<PinChange> {
        self.starts.clear();
        std::mem::take(&mut self.changes)
    }

    /// Runs until every packet taken has left its pin; returns the tick after that.
    pub fn drain(&mut self) -> u64 {
        while !(self.idle() && self.next_port == 0) {
            let next = self.next_visit();
            self.advance_to(next.max(self.tick) + 1);
        }
        // the last frame loaded (the frame after the last refill that found a byte) ends
        let end = self.bit_start((self.frame + 1) * self.frame_bits);
        self.advance_to(end.max(self.tick));
        self.tick
    }
}
