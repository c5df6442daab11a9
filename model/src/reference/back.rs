//! The shared back end: packet store (write ring, slots, reader, output FIFO), framer,
//! transmitter, status reporter and counter file. It runs through the clock cycles in which
//! something moves (a record between store and framer, a datagram closing, a frame starting, a report beginning or
//! ending) and jumps over every stretch in which only free-running counters advance.

use super::front::{PortFront, StartedPacket};
use super::receive::ReceiveSide;
use crate::control::Effect;
use crate::downlink::PinChange;
use crate::inputs::{LINK_SPEED, LINK_UP};
use crate::timing::{
    ARBITER_OFFER_LATENCY, DEFRAMER_DECISION_CLOCKS, INCREMENT_WRITE_EDGE, RECORD_BEATS, SLOTS,
    STATUS_BOX_COUNTER_WORDS, STATUS_CLOCKS_PER_WORD, STATUS_HEADER_WORDS, STATUS_WORD_VALUE_CLOCK,
    STORE_FIFO_DEPTH, TAKE_TO_RAW_BODY,
};
use skinbox_protocol::box_counters::{BoxCounter, BoxCounters, BOX_COUNTERS_LEN};
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::command::Destination;
use skinbox_protocol::datagram::{
    DatagramBody, FLAG_FLUSH_TIMEOUT, FLAG_TIME_SYNCS, HEADER_LEN, MAX_RECORDS,
};
use skinbox_protocol::link::PREAMBLE_LEN;
use skinbox_protocol::status::PortCounter;
use skinbox_protocol::{DatagramRepr, PortCounters, RecordRepr, StatusRepr};
use std::borrow::Cow;
use std::collections::VecDeque;

// `offer` is the arbiter's one offer register
const _: () = assert!(ARBITER_OFFER_LATENCY == 1);

/// Fixed numbers of the back end.
#[derive(Debug, Clone)]
pub(super) struct BackTiming {
    /// Ports.
    pub ports: usize,
    /// Tick of cycle `c` is `c - tick_offset`.
    pub tick_offset: u64,
    /// First cycle the counter file is ready (status reports may start).
    pub counters_ready_from: u64,
    /// Flush timeout in ticks.
    pub flush_timeout: u64,
    /// Status period in clocks.
    pub status_period: u64,
    /// Time-sync period after reset, ticks (0: the box sends none).
    pub sync_period: u64,
    /// Ports per status datagram.
    pub ports_per_status: usize,
    /// Boot id in the status reports.
    pub boot_id: u32,
    /// Box id and port count in every datagram header.
    pub box_id: u16,
    /// Frame bytes before the body (preamble to the box header).
    pub body_start: u64,
    /// FCS and inter-frame gap after the padding.
    pub frame_tail: u64,
    /// Clocks from a transmitter start to its first GMII byte.
    pub start_to_first_byte: u64,
    /// The deframing engine's scan period (it counts one event of a port per visit).
    pub scan_period: u64,
}

/// A frame the back end sends.
#[derive(Debug, Clone)]
pub(super) struct SentFrame {
    /// Cycle of its first preamble byte on GMII.
    pub first_cycle: u64,
    /// What it carries.
    pub content: Sent,
}

/// What a sent frame carries.
#[derive(Debug, Clone)]
pub(super) enum Sent {
    /// A box datagram to `destination`, a status datagram with its box counter block.
    Datagram {
        datagram: DatagramRepr,
        box_counters: Option<BoxCounters>,
        destination: Destination,
    },
    /// A reply of the receive path, preamble to FCS.
    Reply(Vec<u8>),
}

/// Last issue of a store record (port, flags, 4 tick bytes, 20 cell bytes).
const LAST_ISSUE: u8 = RECORD_BEATS as u8 - 1;
/// Framer beat at which the tick offset is computed (the last tick byte).
const OFFSET_BEAT: u8 = 5;
/// Clocks the framer pauses after [`OFFSET_BEAT`] to write the offset bytes.
const OFFSET_PAUSE: u8 = 4;
/// Last framer beat of a record.
const RECORD_END_BEAT: u8 = 25;
const DROPPED: u8 = 1 << PortCounter::DroppedOverflow as u8;

#[derive(Debug, Clone)]
struct Stored {
    flags: u8,
    stamp: u32,
    bytes: [u8; PACKET_LEN],
}

/// A record beat in the store's read pipeline or output FIFO: its port and packet.
#[derive(Debug, Clone)]
struct RecordBeat {
    port: u8,
    slot: Stored,
}

#[derive(Debug, Default)]
struct Buffer {
    slots: VecDeque<Stored>,
    /// A packet committed in the previous cycle: the store counts it a clock after the
    /// engine's decision, so it joins `slots` at the end of this cycle.
    committed: Option<Stored>,
    /// Both slots were full at the visit of the header being decided.
    full_at_check: bool,
    dropping: bool,
    loss_pending: bool,
    /// Loss flag captured with the header of the packet being written.
    flag_of_writing: bool,
}

/// The store reader's next register values, computed in one clock.
struct ReaderStep {
    /// The slot freed in this clock.
    read_done: Option<usize>,
    next_reading: Option<usize>,
    next_hit: bool,
    /// The record beat issued to the read pipeline.
    issued: Option<RecordBeat>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Report {
    Wait,
    Start,
    /// Writing the body: the request follows at cycle `request_at`.
    Build {
        from: u64,
        request_at: u64,
    },
    Request,
    Sending,
}

/// Counter events of one port: pending bits, one counted per visit of the engine.
#[derive(Debug, Default)]
struct PortCounting {
    /// Events (decision cycle, bits), in cycle order.
    events: Vec<(u64, u8)>,
    next_event: usize,
    /// Cycle up to which visits were processed (exclusive).
    done_until: u64,
    pending: u8,
    /// Per counter: the cycles whose edge writes an increment, ascending.
    writes: [Vec<u64>; 8],
}

/// What the engine does with a packet in one cycle, in the order they happen in a cycle.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
enum Step {
    /// It visits the header's port: the store's occupancy of this cycle is what it sees.
    Check,
    /// It decides the end of the packet.
    End,
    /// It decides the header (after an end in the same decision: a truncation).
    Start,
}

struct FrontBeat {
    cycle: u64,
    port: usize,
    packet: usize,
    step: Step,
}

/// The engine's steps on port `port`'s packets (unsorted).
fn beats_of(port: usize, front: &PortFront) -> impl Iterator<Item = FrontBeat> + '_ {
    front.packets.iter().enumerate().flat_map(move |(i, p)| {
        [
            (p.check, Step::Check),
            (p.start, Step::Start),
            (p.end, Step::End),
        ]
        .map(|(cycle, step)| FrontBeat {
            cycle,
            port,
            packet: i,
            step,
        })
    })
}

/// The back end's state: the registers of the gateware that matter to the frames.
pub(super) struct Back<'a> {
    t: BackTiming,
    /// Borrowed from the prepared reference until a port's front end is replaced.
    fronts: Cow<'a, [PortFront]>,
    beats: Vec<FrontBeat>,
    next_beat: usize,
    buffers: Vec<Buffer>,
    counting: Vec<PortCounting>,
    // store reader
    scan: usize,
    hit: bool,
    hit_port: usize,
    reading: Option<usize>,
    /// The port whose slot is freed this cycle (a clock after its record's last issue).
    freeing: Option<usize>,
    issue_index: u8,
    read1: Option<RecordBeat>,
    read2: Option<RecordBeat>,
    fifo: VecDeque<RecordBeat>,
    // framer
    beat: u8,
    offset_left: u8,
    fill: Vec<RecordRepr>,
    record: RecordRepr,
    base_tick: u64,
    deadline: u32,
    deadline_passed: bool,
    pending: Option<DatagramRepr>,
    /// First cycle after the last body byte of the records datagram sent last was taken
    /// (its buffer is free from then on).
    records_body_until: u64,
    // datagram arbiter: the source granted last (records 0, status 1, replies 2); the
    // first waiting source after it goes next, else the lowest waiting; the source it
    // offers, chosen in the clock before (`OFFER_LATENCY`)
    last_grant: Option<usize>,
    offer: Option<usize>,
    /// Cycles from which each records datagram counts as sent, and the records sum.
    started_records: Vec<(u64, u64)>,
    records_sent: u64,
    // transmitter
    idle_from: u64,
    sequence: u32,
    // status reporter
    report: Report,
    due: bool,
    first_port: usize,
    page_ports: usize,
    report_tick: u64,
    /// The box's sync generator is on (its period is not 0).
    syncs_on: bool,
    /// ... when the report being built started (its flag `FLAG_TIME_SYNCS`).
    report_syncs: bool,
    status_body: Option<StatusRepr>,
    /// Its box counter block, read with it.
    status_block: Option<BoxCounters>,
    /// As `records_body_until`, for the status datagram sent last.
    status_body_until: u64,
    /// A cycle in which the status timer is zero (its zeros are a period apart from it).
    period_origin: u64,
    /// The receive path, when the host sends frames.
    receive: Option<ReceiveSide>,
    /// Where the datagrams go (stream-to changes it).
    destination: Destination,
    /// Frames sent, in order.
    pub frames: Vec<SentFrame>,
}

impl<'a> Back<'a> {
    pub(super) fn new(
        t: BackTiming,
        fronts: &'a [PortFront],
        destination: Destination,
        receive: Option<ReceiveSide>,
    ) -> Self {
        let syncs_on = t.sync_period != 0;
        // the engine's steps on each packet, in cycle order
        let mut beats: Vec<FrontBeat> = fronts
            .iter()
            .enumerate()
            .flat_map(|(port, f)| beats_of(port, f))
            .collect();
        beats.sort_by_key(|b| (b.cycle, b.step, b.port));
        let counting = fronts
            .iter()
            .map(|f| PortCounting {
                events: f.events.clone(),
                ..Default::default()
            })
            .collect();
        let period_origin = t.tick_offset;
        Back {
            buffers: (0..t.ports).map(|_| Buffer::default()).collect(),
            counting,
            t,
            fronts: Cow::Borrowed(fronts),
            beats,
            next_beat: 0,
            scan: 0,
            hit: false,
            hit_port: 0,
            reading: None,
            freeing: None,
            issue_index: 0,
            read1: None,
            read2: None,
            fifo: VecDeque::new(),
            beat: 0,
            offset_left: 0,
            fill: vec![],
            record: empty_record(),
            base_tick: 0,
            deadline: 0,
            deadline_passed: false,
            pending: None,
            records_body_until: 0,
            last_grant: None,
            offer: None,
            started_records: vec![],
            records_sent: 0,
            idle_from: 0,
            sequence: 0,
            report: Report::Wait,
            due: false,
            first_port: 0,
            page_ports: 0,
            report_tick: 0,
            syncs_on,
            report_syncs: false,
            status_body: None,
            status_block: None,
            status_body_until: 0,
            period_origin,
            receive,
            destination,
            frames: vec![],
        }
    }

    fn tick(&self, c: u64) -> u64 {
        c - self.t.tick_offset
    }

    /// Port `port`'s front end becomes `front` from cycle `done` on (the cycles before it
    /// have run): its steps and counter events from `done` on replace the old ones. Fails
    /// when `front` differs from the old one before `done` (the pin changed in the past).
    pub(super) fn replace_front(
        &mut self,
        port: usize,
        front: PortFront,
        done: u64,
    ) -> Result<(), String> {
        let old = &self.fronts[port];
        let settled = |f: &PortFront| {
            let packets: Vec<_> = f
                .packets
                .iter()
                .take_while(|p| p.check < done)
                .map(|p| {
                    (
                        p.check,
                        p.start,
                        p.stamp,
                        (p.end < done).then_some((p.end, p.good, p.bytes)),
                    )
                })
                .collect();
            let events: Vec<_> = f
                .events
                .iter()
                .take_while(|e| e.0 < done)
                .copied()
                .collect();
            (packets, events)
        };
        if settled(old) != settled(&front) {
            return Err(format!(
                "port {port}: the front end changed before cycle {done}, which has run"
            ));
        }
        let counting = &mut self.counting[port];
        let keep = counting
            .events
            .partition_point(|e| e.0 < done)
            .max(counting.next_event);
        let after = keep
            .checked_sub(1)
            .map_or(done, |k| (counting.events[k].0 + 1).max(done));
        counting.events.truncate(keep);
        counting
            .events
            .extend(front.events.iter().filter(|e| e.0 >= after));
        let mut rest: Vec<FrontBeat> = self
            .beats
            .drain(self.next_beat..)
            .filter(|b| b.port != port)
            .collect();
        rest.extend(beats_of(port, &front).filter(|b| b.cycle >= done));
        rest.sort_by_key(|b| (b.cycle, b.step, b.port));
        self.beats.extend(rest);
        self.fronts.to_mut()[port] = front;
        Ok(())
    }

    /// Run-time configuration (the box's commands): flush timeout, status period, and a
    /// status report as soon as the reporter waits.
    pub(super) fn set_flush_timeout(&mut self, ticks: u64) {
        self.t.flush_timeout = ticks;
    }
    /// The status period becomes `ticks` in cycle `c`: the timer restarts, the next
    /// report is due a period later.
    pub(super) fn set_status_period(&mut self, ticks: u64, c: u64) {
        self.t.status_period = ticks;
        self.period_origin = c + ticks;
    }
    pub(super) fn request_status(&mut self) {
        self.due = true;
    }

    /// The status timer reaches zero in cycle `c` (every period from the end of reset, or
    /// from the last change of the period).
    fn timer_zero(&self, c: u64) -> bool {
        c >= self.period_origin && (c - self.period_origin).is_multiple_of(self.t.status_period)
    }

    /// First cycle at or after `c` in which the status timer is zero.
    fn next_timer_zero(&self, c: u64) -> u64 {
        let c = c.max(self.period_origin);
        let since = (c - self.period_origin) % self.t.status_period;
        if since == 0 {
            c
        } else {
            c + self.t.status_period - since
        }
    }

    /// Runs cycles `from..end`.
    pub(super) fn run(&mut self, from: u64, end: u64) {
        let mut c = from;
        while c < end {
            if self.quiet(c) {
                let next = self.next_event(c).min(end);
                if next > c {
                    self.skip(c, next);
                    c = next;
                    continue;
                }
            }
            self.step(c);
            c += 1;
        }
    }

    /// Nothing but free-running counters changes in cycle `c`.
    fn quiet(&self, c: u64) -> bool {
        let idle = c >= self.idle_from;
        self.reading.is_none()
            && self.freeing.is_none()
            && !self.hit
            && self.read1.is_none()
            && self.read2.is_none()
            && self.fifo.is_empty()
            && self
                .buffers
                .iter()
                .all(|b| b.slots.is_empty() && b.committed.is_none())
            && self.offset_left == 0
            && self.beat == 0
            && !self.close_now(c)
            && !(idle && self.offer.is_some())
            && self.offer == self.choose(c)
            && match self.report {
                Report::Wait => !(self.due && c >= self.t.counters_ready_from),
                Report::Start => false,
                Report::Build { request_at, .. } => c + 1 != request_at,
                Report::Request => true,
                Report::Sending => c < self.status_body_until,
            }
            && self.beats.get(self.next_beat).is_none_or(|b| b.cycle > c)
            && self.receive.as_ref().is_none_or(|r| r.next_event(c) > c)
    }

    /// The source the datagram arbiter chooses from the sources waiting in cycle `c` (on
    /// the registers as they are): the first after the source granted last, else the
    /// lowest.
    fn choose(&self, c: u64) -> Option<usize> {
        let waiting = [
            self.pending.is_some(),
            self.report == Report::Request,
            self.receive.as_ref().is_some_and(|r| r.reply_waits(c)),
        ];
        let after_last = |i: usize| self.last_grant.is_some_and(|last| i > last);
        (0..waiting.len())
            .find(|&i| waiting[i] && after_last(i))
            .or_else(|| (0..waiting.len()).find(|&i| waiting[i]))
    }

    /// The earliest cycle after `c` at which something may change.
    fn next_event(&self, c: u64) -> u64 {
        let mut next = u64::MAX;
        if let Some(b) = self.beats.get(self.next_beat) {
            next = next.min(b.cycle);
        }
        for until in [
            self.idle_from,
            self.records_body_until,
            self.status_body_until,
        ] {
            if c < until {
                next = next.min(until);
            }
        }
        if !self.fill.is_empty() && !self.deadline_passed {
            // deadline_passed rises one clock after the tick reaches the deadline
            let due = self.deadline_cycle() + 1;
            next = next.min(due.max(c + 1));
        }
        if let Some(r) = &self.receive {
            next = next.min(r.next_event(c).max(c + 1));
        }
        match self.report {
            Report::Wait => {
                let due_at = if self.due {
                    self.t.counters_ready_from
                } else {
                    self.next_timer_zero(c) + 1
                };
                next = next.min(due_at.max(c + 1));
            }
            Report::Build { request_at, .. } => next = next.min(request_at - 1),
            _ => {}
        }
        next.max(c + 1)
    }

    /// Cycle whose tick equals the deadline (the deadline is 32 bits of tick).
    fn deadline_cycle(&self) -> u64 {
        let now = self.base_tick;
        let delta = self.deadline.wrapping_sub(now as u32) as u64;
        now + delta + self.t.tick_offset
    }

    /// Advances the free-running counters over the quiet cycles `from..to`.
    fn skip(&mut self, from: u64, to: u64) {
        let n = to - from;
        self.scan = (self.scan + (n % self.t.ports as u64) as usize) % self.t.ports;
        if self.next_timer_zero(from) < to {
            self.due = true;
        }
        // the registered deadline test as of the last skipped cycle
        let last_tick = self.tick(to - 1) as u32;
        self.deadline_passed = (last_tick.wrapping_sub(self.deadline) as i32) >= 0;
    }

    fn close_due(&self) -> bool {
        self.beat == 0
            && self.offset_left == 0
            && (self.fill.len() == MAX_RECORDS || (!self.fill.is_empty() && self.deadline_passed))
    }

    /// The filling datagram closes in cycle `c`: due, none waiting, the other buffer free.
    fn close_now(&self, c: u64) -> bool {
        self.close_due() && self.pending.is_none() && c >= self.records_body_until
    }

    /// One clock cycle of every block, as the gateware computes it.
    fn step(&mut self, c: u64) {
        let tick = self.tick(c);
        let idle = c >= self.idle_from;

        // the receive side: frames decided, the configuration changing in this clock
        self.step_receive(c);

        // framer input control
        let closing = self.close_now(c);
        let accept = self.offset_left == 0 && !self.close_due();

        // store reader: scan, grant, issue (on the registers as they are)
        let reader = self.step_reader();

        // framer: one beat from the store's FIFO or one offset byte per clock
        let (framer_takes, next_deadline) = self.step_framer(tick, accept);
        // the read pipeline (two clocks of block RAM) and the FIFO
        if framer_takes {
            self.fifo.pop_front();
        }
        if let Some(arrived) = self.read2.take() {
            self.fifo.push_back(arrived);
        }
        self.read2 = self.read1.take();
        self.read1 = reader.issued;
        self.reading = reader.next_reading;
        self.hit = reader.next_hit;
        if let Some(p) = reader.read_done {
            self.buffers[p].slots.pop_front();
        }
        let next_deadline_passed = (tick as u32).wrapping_sub(self.deadline) as i32 >= 0;
        self.deadline = next_deadline;

        // arbiter and transmitter
        self.step_transmitter(c, tick, idle);
        if closing {
            self.close_datagram();
        }

        // store write side: the engine's steps on packets this cycle
        self.step_writer(c, reader.read_done);

        self.deadline_passed = next_deadline_passed;
    }

    /// The box's sync generator is on from now on (`ticks` not 0).
    pub(super) fn set_sync_period(&mut self, ticks: u64) {
        self.syncs_on = ticks != 0;
    }

    /// The receive side's clock: frames decided, the configuration changing in this clock.
    fn step_receive(&mut self, c: u64) {
        let effects = self.receive.as_mut().map_or(vec![], |r| r.step(c));
        for effect in effects {
            match effect {
                Effect::StreamTo(d) => self.destination = d,
                Effect::SetFlushTimeout(t) => self.t.flush_timeout = t.into(),
                Effect::SetStatusPeriod(t) => self.set_status_period(t.into(), c),
                Effect::StatusNow => self.due = true,
                Effect::SetSyncPeriod(t) => self.syncs_on = t != 0,
            }
        }
    }

    /// The store reader's clock on the registers as they are: scan, grant, issue. Updates
    /// the scan, issue index and freed slot; returns the registers' next values.
    fn step_reader(&mut self) -> ReaderStep {
        let n = self.t.ports;
        let in_flight = usize::from(self.read1.is_some()) + usize::from(self.read2.is_some());
        let issue = self.reading.is_some() && self.fifo.len() + in_flight < STORE_FIFO_DEPTH;
        // the slot freed this cycle (registered: the record's last issue was a clock ago)
        let read_done = self.freeing.take();
        let mut next_reading = self.reading;
        let mut next_hit = false;
        let mut issued = None;
        if let Some(p) = self.reading {
            if issue {
                issued = self.buffers[p].slots.front().map(|s| RecordBeat {
                    port: p as u8,
                    slot: s.clone(),
                });
                if self.issue_index == LAST_ISSUE {
                    next_reading = None;
                    self.freeing = Some(p);
                } else {
                    self.issue_index += 1;
                }
            }
        } else if read_done.is_some() {
            // the scan waits while a slot is freed
        } else if self.hit {
            // grant; the scan already stands on the next port and waits there
            next_reading = Some(self.hit_port);
            self.issue_index = 0;
        } else {
            next_hit = !self.buffers[self.scan].slots.is_empty();
            self.hit_port = self.scan;
            self.scan = (self.scan + 1) % n;
        }
        ReaderStep {
            read_done,
            next_reading,
            next_hit,
            issued,
        }
    }

    /// The framer's clock: one beat from the store's FIFO or one offset byte. Returns
    /// whether it takes the FIFO's front beat, and the flush deadline's next value.
    fn step_framer(&mut self, tick: u64, accept: bool) -> (bool, u32) {
        let mut next_deadline = self.deadline;
        let framer_takes = self.offset_left == 0 && accept && !self.fifo.is_empty();
        if self.offset_left != 0 {
            self.offset_left -= 1;
        } else if let Some(beat) = self.fifo.front().filter(|_| accept) {
            let slot = &beat.slot;
            match self.beat {
                0 => self.record.port = beat.port,
                1 => self.record.flags = slot.flags,
                OFFSET_BEAT => {
                    self.offset_left = OFFSET_PAUSE;
                    if self.fill.is_empty() {
                        // the base tick: the 64-bit tick whose low half is the stamp
                        self.base_tick = tick - u64::from((tick as u32).wrapping_sub(slot.stamp));
                        next_deadline = (tick as u32).wrapping_add(self.t.flush_timeout as u32);
                        self.record.tick_offset = 0;
                    } else {
                        self.record.tick_offset =
                            slot.stamp.wrapping_sub(self.base_tick as u32) as i32;
                    }
                }
                RECORD_END_BEAT => {
                    self.record.cell_packet = slot.bytes;
                    self.fill
                        .push(std::mem::replace(&mut self.record, empty_record()));
                }
                _ => {}
            }
            self.beat = if self.beat == RECORD_END_BEAT {
                0
            } else {
                self.beat + 1
            };
        }
        (framer_takes, next_deadline)
    }

    /// Arbiter and transmitter: the idle transmitter takes the offered datagram; the
    /// arbiter chooses the next offer from the sources waiting now (a datagram closing
    /// now waits a clock to be chosen, and a clock more to be offered).
    fn step_transmitter(&mut self, c: u64, tick: u64, idle: bool) {
        let grant = self.offer.filter(|_| idle);
        let next_offer = if grant.is_some() {
            None
        } else {
            self.choose(c)
        };
        self.step_report(c, tick, grant == Some(1));

        match grant {
            Some(0) => {
                let mut d = self.pending.take().expect("checked");
                if let DatagramBody::Records(r) = &d.body {
                    self.records_sent += r.len() as u64;
                }
                // (the batcher counts it a clock after the take)
                self.started_records.push((c + 2, self.records_sent));
                d.sequence = self.sequence;
                self.records_body_until = self.send(c, d, None);
            }
            Some(1) => {
                let status = self
                    .status_body
                    .take()
                    .expect("a requested report has a body");
                let d = DatagramRepr {
                    box_id: self.t.box_id,
                    port_count: self.t.ports as u8,
                    flags: if self.report_syncs {
                        FLAG_TIME_SYNCS
                    } else {
                        0
                    },
                    sequence: self.sequence,
                    base_tick: self.report_tick,
                    body: DatagramBody::Status(status),
                };
                let block = self.status_block.take().expect("built with the body");
                self.status_body_until = self.send(c, d, Some(block));
            }
            Some(_) => {
                let receive = self.receive.as_mut().expect("a reply waits");
                let wire = receive.take_reply(c, self.t.start_to_first_byte);
                let body_len = ReceiveSide::body_len(&wire);
                let last_take = c + TAKE_TO_RAW_BODY + body_len - 1;
                receive.reply_sent(last_take);
                self.idle_from = c + PREAMBLE_LEN as u64 + body_len + self.t.frame_tail;
                self.frames.push(SentFrame {
                    first_cycle: c + self.t.start_to_first_byte,
                    content: Sent::Reply(wire),
                });
            }
            None => {}
        }
        if grant.is_some() {
            self.last_grant = grant;
        }
        self.offer = next_offer;
    }

    /// Closes the filling datagram: it waits for the arbiter.
    fn close_datagram(&mut self) {
        let records = std::mem::take(&mut self.fill);
        let flags = if records.len() == MAX_RECORDS {
            0
        } else {
            FLAG_FLUSH_TIMEOUT
        };
        self.pending = Some(DatagramRepr {
            box_id: self.t.box_id,
            port_count: self.t.ports as u8,
            flags,
            sequence: 0,
            base_tick: self.base_tick,
            body: DatagramBody::Records(records),
        });
    }

    /// The store's write side: the engine's steps on packets in cycle `c` (`read_done` is
    /// the slot the reader frees in this cycle).
    fn step_writer(&mut self, c: u64, read_done: Option<usize>) {
        let counted_now: Vec<(usize, Stored)> = self
            .buffers
            .iter_mut()
            .enumerate()
            .filter_map(|(port, b)| b.committed.take().map(|s| (port, s)))
            .collect();
        while let Some(b) = self.beats.get(self.next_beat).filter(|b| b.cycle == c) {
            let (port, packet, step) = (b.port, b.packet, b.step);
            self.next_beat += 1;
            let p: &StartedPacket = &self.fronts[port].packets[packet];
            let buffer = &mut self.buffers[port];
            let used = buffer.slots.len() + usize::from(read_done == Some(port));
            match step {
                Step::Check => buffer.full_at_check = used == SLOTS,
                Step::Start => {
                    buffer.dropping = buffer.full_at_check;
                    buffer.flag_of_writing = buffer.loss_pending;
                }
                Step::End if !p.good => buffer.loss_pending = true,
                Step::End if buffer.dropping => {
                    buffer.loss_pending = true;
                    self.counting[port].add(c, DROPPED);
                }
                Step::End => {
                    buffer.committed = Some(Stored {
                        flags: u8::from(buffer.flag_of_writing),
                        stamp: p.stamp as u32,
                        bytes: p.bytes,
                    });
                    buffer.loss_pending = false;
                }
            }
        }
        for (port, stored) in counted_now {
            self.buffers[port].slots.push_back(stored);
        }
    }

    /// Starts a frame in cycle `c`; returns the first cycle after its body's last byte was
    /// taken from its source (the transmitter takes body byte `k` at frame byte
    /// `body_start + k`, the clock after the start being frame byte 0).
    fn send(&mut self, c: u64, d: DatagramRepr, box_counters: Option<BoxCounters>) -> u64 {
        let block_len = box_counters.map_or(0, |_| BOX_COUNTERS_LEN);
        let body_len = (d.buffer_len() - HEADER_LEN + block_len) as u64;
        // (the headers exceed the minimum frame: there is never padding)
        self.idle_from = c + self.t.body_start + body_len + self.t.frame_tail;
        self.sequence = self.sequence.wrapping_add(1);
        self.frames.push(SentFrame {
            first_cycle: c + self.t.start_to_first_byte,
            content: Sent::Datagram {
                datagram: d,
                box_counters,
                destination: self.destination,
            },
        });
        c + 1 + self.t.body_start + body_len
    }

    /// Records datagrams started before cycle `at` (the framer's count register then), and
    /// the records they held.
    fn sent_before(&self, at: u64) -> (u32, u32) {
        let k = self
            .started_records
            .partition_point(|(from, _)| *from <= at);
        let records = k.checked_sub(1).map_or(0, |i| self.started_records[i].1);
        (k as u32, records as u32)
    }

    /// One cycle of the status reporter, on the registers as they are; `taken`: its
    /// descriptor is taken in this cycle.
    fn step_report(&mut self, c: u64, tick: u64, taken: bool) {
        let mut due = self.due || self.timer_zero(c);
        match self.report {
            Report::Wait => {
                if self.due && c >= self.t.counters_ready_from {
                    due = false;
                    self.first_port = 0;
                    self.report = Report::Start;
                }
            }
            Report::Start => {
                self.report_tick = tick;
                self.report_syncs = self.syncs_on;
                self.page_ports = self.t.ports_per_status.min(self.t.ports - self.first_port);
                // words: boot id, datagrams, records, first port, 8 counters per port
                let words =
                    (STATUS_HEADER_WORDS + 8 * self.page_ports + STATUS_BOX_COUNTER_WORDS) as u64;
                self.report = Report::Build {
                    from: c + 1,
                    request_at: c + 1 + STATUS_CLOCKS_PER_WORD * words,
                };
            }
            Report::Build { from, request_at } => {
                if c + 1 == request_at {
                    self.status_body = Some(self.status_body(from));
                    self.status_block = Some(self.status_block(from));
                    self.report = Report::Request;
                }
            }
            Report::Request => {
                if taken {
                    self.report = Report::Sending;
                }
            }
            Report::Sending => {
                if c >= self.status_body_until {
                    self.first_port += self.page_ports;
                    self.report = if self.first_port == self.t.ports {
                        Report::Wait
                    } else {
                        Report::Start
                    };
                }
            }
        }
        self.due = due;
    }

    /// The box counter block of the body written from cycle `from` (its words after the
    /// port counters, each read as a port counter is): the link as the harness drives it,
    /// the receive side's counters as its reads see them.
    fn status_block(&self, from: u64) -> BoxCounters {
        let mut block = BoxCounters {
            link_up: LINK_UP,
            link_speed: LINK_SPEED,
            ..BoxCounters::default()
        };
        if let Some(receive) = &self.receive {
            let block_start = (STATUS_HEADER_WORDS + 8 * self.page_ports) as u64;
            for (i, counter) in BoxCounter::ALL.iter().enumerate() {
                let read = from + STATUS_CLOCKS_PER_WORD * (block_start + 1 + i as u64);
                block.counts[i] = receive.counters_at(read).get(*counter);
            }
        }
        block
    }

    /// The body written from cycle `from`: word `w` takes its value in cycle
    /// `from + STATUS_CLOCKS_PER_WORD w + STATUS_WORD_VALUE_CLOCK`, counters through an address taken at
    /// the edge after `from + STATUS_CLOCKS_PER_WORD w`.
    fn status_body(&mut self, from: u64) -> StatusRepr {
        let word_read = |w: u64| from + STATUS_CLOCKS_PER_WORD * w;
        let mut ports = Vec::with_capacity(self.page_ports);
        for i in 0..self.page_ports {
            let port = self.first_port + i;
            let first_word = 4 + 8 * i as u64;
            let last_read = word_read(first_word + 7);
            self.counting[port].advance(
                port,
                self.t.scan_period,
                self.t.tick_offset + DEFRAMER_DECISION_CLOCKS,
                last_read + 1,
            );
            let mut counters = PortCounters::default();
            for (k, counter) in PortCounter::ALL.iter().enumerate() {
                let read = word_read(first_word + k as u64);
                counters.set(*counter, self.counting[port].value(k, read));
            }
            ports.push(counters);
        }
        StatusRepr {
            boot_id: self.t.boot_id,
            datagrams_sent: self.sent_before(word_read(1) + STATUS_WORD_VALUE_CLOCK).0,
            records_sent: self.sent_before(word_read(2) + STATUS_WORD_VALUE_CLOCK).1,
            first_port: self.first_port as u8,
            ports,
        }
    }
}

fn empty_record() -> RecordRepr {
    RecordRepr {
        port: 0,
        flags: 0,
        tick_offset: 0,
        cell_packet: [0; PACKET_LEN],
    }
}

impl PortCounting {
    /// An event generated by the back end (a dropped packet), in cycle order (after the
    /// engine's events of the same decision: they are ORed together).
    fn add(&mut self, cycle: u64, bits: u8) {
        let at = self.events[self.next_event..].partition_point(|e| e.0 < cycle) + self.next_event;
        match self.events.get_mut(at) {
            Some(e) if e.0 == cycle => e.1 |= bits,
            _ => self.events.insert(at, (cycle, bits)),
        }
    }

    /// Counts pending bits at the engine's decisions on `port` before cycle `until`: they
    /// come every `period` clocks, the first at `origin + port`; each ORs in the events
    /// decided then and sends the lowest pending bit to the counter file.
    fn advance(&mut self, port: usize, period: u64, origin: u64, until: u64) {
        let period = period as i128;
        // first decision on this port at or after cycle c
        let decision = |c: u64| {
            let phase = (c as i128 - origin as i128 - port as i128).rem_euclid(period);
            c + ((period - phase) % period) as u64
        };
        let mut c = self.done_until;
        while c < until {
            if self.pending == 0 {
                let Some(&(e, _)) = self.events.get(self.next_event) else {
                    break;
                };
                // (events are decided at decisions on this port)
                c = c.max(e);
            }
            let v = decision(c);
            if v >= until {
                break;
            }
            if let Some(&(e, bits)) = self.events.get(self.next_event) {
                if e <= v {
                    debug_assert_eq!(e, v, "port {port}: an event off the engine's schedule");
                    self.next_event += 1;
                    self.pending |= bits;
                }
            }
            if self.pending == 0 {
                c = v + 1;
                continue;
            }
            let lowest = self.pending.trailing_zeros() as usize;
            self.pending &= !(1 << lowest);
            // the increment leaves the engine's register a clock after the decision and is
            // written INCREMENT_WRITE_EDGE edges later
            self.writes[lowest].push(v + 1 + INCREMENT_WRITE_EDGE);
            c = v + 1;
        }
        self.done_until = c.min(until).max(self.done_until);
    }

    /// The counter as a read whose address is taken at the edge after cycle `read` sees it.
    fn value(&self, counter: usize, read: u64) -> u32 {
        self.writes[counter].partition_point(|w| *w <= read) as u32
    }
}

impl Back<'_> {
    /// The downlink's pin changes up to and including tick `last` (none without a
    /// receive side).
    pub(crate) fn downlink_changes(&mut self, last: u64) -> Vec<PinChange> {
        let Some(receive) = self.receive.as_mut() else {
            return Vec::new();
        };
        let downlink = &mut receive.control.downlink;
        downlink.advance_to(last);
        downlink
            .changes()
            .iter()
            .filter(|c| c.tick <= last)
            .copied()
            .collect()
    }
}
