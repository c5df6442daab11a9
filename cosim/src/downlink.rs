//! The box's downlink to the cells, clock by clock: a model of the gateware's
//! `CellDownlink` (`gateware/src/cell_downlink.rs`) and its `UartTx` pins, register for
//! register, so the reference model can say which cell commands the box takes and when
//! every bit of them is on which transmit pin.
//!
//! Clocks are box ticks (the tick counter and the downlink leave reset together). The
//! model runs only while something is under way (a copy, a queued packet, a byte in
//! flight) and jumps over idle stretches, so a run of seconds with a few commands costs
//! a few hundred thousand port-clocks.

use skinbox_gateware::cell_downlink::QUEUE_PACKETS;
use skinbox_gateware::uart_rx::{phase_increment, PHASE_BITS};
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::ALL_PORTS;

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
    /// The packet.
    pub bytes: [u8; PACKET_LEN],
}

/// One port's queue, holding register and transmitter.
#[derive(Debug, Clone, Copy, Default)]
struct Port {
    count: u64,
    head: bool,
    read_index: usize,
    fetching: bool,
    holding_valid: bool,
    holding: u8,
    // the transmitter
    phase: u32,
    sending: bool,
    bit_index: u8,
    shift: u16,
    pin: bool,
    /// Bytes of the oldest packet taken by the transmitter so far.
    taken: usize,
}

/// The downlink of a box with `ports` ports.
#[derive(Debug, Clone)]
pub struct DownlinkModel {
    increment: u32,
    /// The next clock to evaluate.
    tick: u64,
    ports: Vec<Port>,
    /// Two packet slots per port.
    ram: Vec<[[u8; PACKET_LEN]; 2]>,
    staging: [u8; PACKET_LEN],
    /// The packet being copied, whole.
    copy_packet: [u8; PACKET_LEN],
    /// The offer taken in the previous clock (registered: its copy starts now).
    offered: Option<(u8, [u8; PACKET_LEN])>,
    copying: bool,
    broadcast: bool,
    copy_port: usize,
    copy_index: usize,
    scan: usize,
    /// Reads in flight, newest first: (port, slot, byte index); the oldest's data arrives
    /// in this clock (address register, then the RAM's two clocks).
    reads: [Option<(usize, bool, usize)>; 3],
    changes: Vec<PinChange>,
    starts: Vec<PacketStart>,
    /// Per port, the packets committed and not yet fully taken, oldest first.
    packets: Vec<std::collections::VecDeque<[u8; PACKET_LEN]>>,
}

impl DownlinkModel {
    /// The downlink of `ports` pins at `baud` with a `clock_hz` box clock, just out of
    /// reset at tick 0: queues empty, pins high.
    pub fn new(ports: usize, clock_hz: u64, baud: u64) -> DownlinkModel {
        DownlinkModel {
            increment: phase_increment(clock_hz, baud) as u32,
            tick: 0,
            ports: (0..ports)
                .map(|_| Port {
                    pin: true,
                    ..Port::default()
                })
                .collect(),
            ram: vec![[[0; PACKET_LEN]; 2]; ports],
            staging: [0; PACKET_LEN],
            copy_packet: [0; PACKET_LEN],
            offered: None,
            copying: false,
            broadcast: false,
            copy_port: 0,
            copy_index: 0,
            scan: 0,
            reads: [None; 3],
            changes: Vec::new(),
            starts: Vec::new(),
            packets: vec![std::collections::VecDeque::new(); ports],
        }
    }

    /// Nothing under way: the state only changes by the scan's position.
    fn idle(&self) -> bool {
        !self.copying
            && self.offered.is_none()
            && self.reads.iter().all(Option::is_none)
            && self
                .ports
                .iter()
                .all(|p| p.count == 0 && !p.fetching && !p.holding_valid && !p.sending)
    }

    /// Evaluates clocks up to (not including) `tick`.
    pub fn advance_to(&mut self, tick: u64) {
        while self.tick < tick {
            if self.idle() {
                let n = self.ports.len() as u64;
                self.scan = ((self.scan as u64 + (tick - self.tick)) % n) as usize;
                self.tick = tick;
                return;
            }
            self.clock(None);
        }
    }

    /// Offers `packet` for `port` (or `ALL_PORTS`) in clock `tick` (the command unit's
    /// clock before `done`); true when it is queued, false when refused (a copy under
    /// way, or a target port full). Ticks must not go back.
    pub fn offer(&mut self, tick: u64, port: u8, packet: [u8; PACKET_LEN]) -> bool {
        self.advance_to(tick);
        let full = |p: &Port| p.count == QUEUE_PACKETS;
        let refused = self.copying
            || self.offered.is_some()
            || if port == ALL_PORTS {
                self.ports.iter().any(full)
            } else {
                self.ports.get(port as usize).is_none_or(full)
            };
        if !refused {
            self.clock(Some((port, packet)));
        }
        !refused
    }

    /// Pin changes so far, in tick order within each port (a change at tick `t` is
    /// reported once the model evaluated clock `t - 1`).
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
        while !self.idle() {
            self.clock(None);
        }
        self.tick
    }

    /// One clock, with an accepted offer in it.
    fn clock(&mut self, offer: Option<(u8, [u8; PACKET_LEN])>) {
        let offered = std::mem::replace(&mut self.offered, offer);
        let n = self.ports.len();
        let tick = self.tick;
        // the copy (registers as they were at the start of the clock)
        let mut commit = None;
        let (mut next_copying, mut next_copy_port, mut next_copy_index, mut next_broadcast) = (
            self.copying,
            self.copy_port,
            self.copy_index,
            self.broadcast,
        );
        let mut next_staging = self.staging;
        if self.copying {
            let p = &self.ports[self.copy_port];
            let slot = p.head ^ (p.count == 1);
            self.ram[self.copy_port][usize::from(slot)][self.copy_index] = self.staging[0];
            next_staging.rotate_left(1);
            next_copy_index = self.copy_index + 1;
            if self.copy_index == PACKET_LEN - 1 {
                commit = Some(self.copy_port);
                next_copy_index = 0;
                if self.broadcast && self.copy_port != n - 1 {
                    next_copy_port = self.copy_port + 1;
                } else {
                    next_copying = false;
                }
            }
        }
        if let Some((port, packet)) = offered {
            next_staging = packet;
            self.copy_packet = packet;
            next_copying = true;
            next_copy_index = 0;
            next_broadcast = port == ALL_PORTS;
            next_copy_port = if port == ALL_PORTS { 0 } else { port as usize };
        }
        // the scan, and the read whose data arrives in this clock
        let arriving = self.reads[2];
        let mut issued = None;
        for (i, p) in self.ports.iter_mut().enumerate() {
            // the transmitter (its `ready`/take, from the registers)
            let bit_end = p.phase >> PHASE_BITS & 1 == 1;
            let ready = !p.sending || (bit_end && p.bit_index == 9);
            let take = ready && p.holding_valid;
            let mut next = *p;
            next.phase = (p.phase & ((1 << PHASE_BITS) - 1)) + self.increment;
            if p.sending && bit_end {
                if p.bit_index == 9 {
                    next.sending = false;
                } else {
                    next.pin = p.shift & 1 == 1;
                    next.shift = p.shift >> 1 | 1 << 8;
                    next.bit_index = p.bit_index + 1;
                }
            }
            if take {
                if !p.sending {
                    next.phase = self.increment;
                }
                next.sending = true;
                next.pin = false;
                next.bit_index = 0;
                next.shift = u16::from(p.holding) | 1 << 8;
                next.holding_valid = false;
                if p.taken == 0 {
                    self.starts.push(PacketStart {
                        tick: tick + 1,
                        port: i,
                        bytes: self.packets[i].front().copied().unwrap_or_default(),
                    });
                }
                next.taken = p.taken + 1;
                if next.taken == PACKET_LEN {
                    next.taken = 0;
                    self.packets[i].pop_front();
                }
            }
            // the queue
            if self.scan == i && p.count != 0 && !p.fetching && !p.holding_valid {
                issued = Some((i, p.head, p.read_index));
                next.fetching = true;
                next.read_index = p.read_index + 1;
                if p.read_index == PACKET_LEN - 1 {
                    next.read_index = 0;
                    next.head = !p.head;
                    next.count = p.count - 1;
                    if commit == Some(i) {
                        next.count = p.count;
                    }
                }
            }
            if commit == Some(i) && !(issued.is_some_and(|r| r.0 == i) && p.read_index == 19) {
                next.count = p.count + 1;
            }
            if commit == Some(i) {
                self.packets[i].push_back(self.copy_packet);
            }
            if let Some((port, slot, index)) = arriving {
                if port == i {
                    next.holding = self.ram[port][usize::from(slot)][index];
                    next.holding_valid = true;
                    next.fetching = false;
                }
            }
            if next.pin != p.pin {
                self.changes.push(PinChange {
                    tick: tick + 1,
                    port: i,
                    level: next.pin,
                });
            }
            *p = next;
        }
        self.reads = [issued, self.reads[0], self.reads[1]];
        self.scan = if self.scan == n - 1 { 0 } else { self.scan + 1 };
        self.staging = next_staging;
        self.copying = next_copying;
        self.copy_port = next_copy_port;
        self.copy_index = next_copy_index;
        self.broadcast = next_broadcast;
        self.tick = tick + 1;
    }
}
