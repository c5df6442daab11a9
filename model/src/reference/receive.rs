//! The receive side of the reference model: the host's frames, what the box decides about
//! each (the control model, [`crate::control`]), when, and the replies it queues for the
//! transmitter. The back end asks it, cycle by cycle, for its events: a frame decided, a
//! command carried out, a reply ready for the datagram arbiter (its third source).
//!
//! The timing is the gateware's, written down once in [`ReceiveTiming`] from the blocks'
//! named latencies: a frame is stored for a reply when the reply buffer was free at its
//! first beat; the parser decides a fixed time after its last beat; a command is carried out
//! a fixed time after that; a reply's build takes a fixed time per kind; the buffer is free
//! again when the transmitter took the reply's last byte.

use crate::control::{BoxControl, Effect, Reply};
use crate::frame::HostFrame;
use skinbox_protocol::box_counters::{BoxCounter, BoxCounters};
use skinbox_protocol::command::AckReply;
use skinbox_protocol::link::{LinkConfig, FCS_LEN, PREAMBLE_LEN};
use std::collections::VecDeque;

/// The receive path's fixed numbers, from the gateware.
#[derive(Debug, Clone)]
pub(crate) struct ReceiveTiming {
    /// Clocks from the edge that samples a frame's first byte (its `edge`) to the clock in
    /// which the parser samples `buffer_locked` (its first beat after the SFD).
    pub first_beat_after_edge: u64,
    /// Clocks from the edge that samples a frame's last byte to the parser's `decided`.
    pub decided_after_last_edge: u64,
    /// The receive tick of a frame is its last edge plus this, less the tick offset.
    pub receive_tick_after_last_edge: u64,
    /// Clocks from `decided` of a command to the command unit's `done`.
    pub command_latency: u64,
    /// Clocks from `decided` (or `done`) to the first clock whose counter reads see the
    /// count of `frames_received`, and of the fate.
    pub frames_received_visible_after: u64,
    pub fate_visible_after: u64,
    /// Clocks from `done` to the clock in which the run-time configuration has changed,
    /// and to the clock in which a report asked for now is due.
    pub config_after_done: u64,
    pub report_now_after_done: u64,
    /// Clocks from a reply's start to its descriptor's `valid`: ARP, echo, and
    /// acknowledgements with no reply, a destination, the box counters.
    pub build_arp: u64,
    pub build_echo: u64,
    pub build_ack: [u64; 3],
    /// Clocks from the clock the last body byte is taken to the first clock the buffer
    /// is free (`locked` low).
    pub unlock_after_last_take: u64,
}

/// A reply waiting for the wire, or going out.
#[derive(Debug, Clone)]
pub(crate) struct PendingReply {
    /// First clock its descriptor is offered.
    pub ready_at: u64,
    pub reply: Reply,
}

/// The receive side's state.
pub(crate) struct ReceiveSide {
    t: ReceiveTiming,
    tick_offset: u64,
    link: LinkConfig,
    frames: Vec<HostFrame>,
    next: usize,
    pub control: BoxControl,
    /// Counts in the order they become visible: (first clock a read sees it, counter).
    counts: Vec<(u64, BoxCounter)>,
    base: BoxCounters,
    /// The reply being built or waiting for the arbiter.
    pub pending: Option<PendingReply>,
    /// The buffer is locked from this clock on (the clock after a reserve) ...
    locked_from: Option<u64>,
    /// ... until this clock (known once the reply went out).
    locked_until: Option<u64>,
    /// Effects due, in clock order.
    effects: VecDeque<(u64, Effect)>,
}

impl ReceiveSide {
    pub(crate) fn new(
        t: ReceiveTiming,
        tick_offset: u64,
        control: BoxControl,
        frames: Vec<HostFrame>,
    ) -> ReceiveSide {
        let base = control.counters;
        let link = control.config().link;
        ReceiveSide {
            t,
            tick_offset,
            link,
            frames,
            next: 0,
            control,
            counts: vec![],
            base,
            pending: None,
            locked_from: None,
            locked_until: None,
            effects: VecDeque::new(),
        }
    }

    fn decided_at(&self, f: &HostFrame) -> u64 {
        f.last_edge() + self.t.decided_after_last_edge
    }

    /// The next clock at or after `c` in which something happens here (u64::MAX: none).
    pub(crate) fn next_event(&self, c: u64) -> u64 {
        let mut next = u64::MAX;
        if let Some(f) = self.frames.get(self.next) {
            next = next.min(self.decided_at(f));
        }
        if let Some((at, _)) = self.effects.front() {
            next = next.min(*at);
        }
        if let Some(p) = &self.pending {
            next = next.min(p.ready_at.max(c));
        }
        next
    }

    /// Whether the buffer is locked in clock `c`.
    fn locked(&self, c: u64) -> bool {
        self.locked_from.is_some_and(|from| c >= from)
            && self.locked_until.is_none_or(|until| c < until)
    }

    /// Runs clock `c`: decides the frame whose decision falls in it; returns the
    /// configuration changes taking effect in it.
    pub(crate) fn step(&mut self, c: u64) -> Vec<Effect> {
        while let Some(f) = self.frames.get(self.next) {
            let decided = self.decided_at(f);
            if decided > c {
                break;
            }
            assert_eq!(decided, c, "the receive side skipped a decision");
            let first_beat = f.edge + self.t.first_beat_after_edge;
            let stored = !self.locked(first_beat);
            let receive_tick =
                f.last_edge() + self.t.receive_tick_after_last_edge - self.tick_offset;
            let frame = f.frame.clone();
            self.next += 1;
            let outcome = self.control.receive_with_slot(&frame, receive_tick, stored);
            // the command unit counts the fates it decides
            let command = matches!(
                outcome.fate,
                BoxCounter::CommandsAccepted
                    | BoxCounter::RefusedReplay
                    | BoxCounter::RefusedOtherBox
                    | BoxCounter::RefusedUnknownOpcode
                    | BoxCounter::RefusedBadArgument
                    | BoxCounter::RefusedDownlinkFull
            );
            let counted = if command {
                decided + self.t.command_latency
            } else {
                decided
            };
            self.counts.push((
                counted + self.t.frames_received_visible_after,
                BoxCounter::FramesReceived,
            ));
            self.counts
                .push((counted + self.t.fate_visible_after, outcome.fate));
            if let Some(reply) = outcome.reply {
                // reserved at the decision: locked from the next clock
                self.locked_from = Some(decided + 1);
                self.locked_until = None;
                let (start, build) = match &reply {
                    Reply::Arp(_) => (decided, self.t.build_arp),
                    Reply::Echo(_) => (decided, self.t.build_echo),
                    Reply::Ack { ack, .. } => {
                        let k = match ack.reply {
                            AckReply::None => 0,
                            AckReply::Destination(_) => 1,
                            AckReply::Counters(_) => 2,
                        };
                        (decided + self.t.command_latency, self.t.build_ack[k])
                    }
                };
                self.pending = Some(PendingReply {
                    ready_at: start + build,
                    reply,
                });
            }
            if let Some(effect) = outcome.effect {
                let done = decided + self.t.command_latency;
                let at = match effect {
                    Effect::StatusNow => done + self.t.report_now_after_done,
                    _ => done + self.t.config_after_done,
                };
                self.effects.push_back((at, effect));
            }
        }
        let mut due = vec![];
        while self.effects.front().is_some_and(|(at, _)| *at <= c) {
            due.push(self.effects.pop_front().expect("checked").1);
        }
        due
    }

    /// A reply's descriptor is offered in clock `c`.
    pub(crate) fn reply_waits(&self, c: u64) -> bool {
        self.pending.as_ref().is_some_and(|p| c >= p.ready_at)
    }

    /// The arbiter granted the reply in clock `c` (the frame's first byte is on GMII
    /// `start_to_first_byte` later): its wire bytes, preamble to FCS. `last_take` is the
    /// clock in which its last body byte is taken.
    pub(crate) fn take_reply(&mut self, c: u64, start_to_first_byte: u64) -> Vec<u8> {
        let p = self.pending.take().expect("a reply waits");
        let send_tick = c + start_to_first_byte - self.tick_offset;
        p.reply.frame(&self.link, send_tick)
    }

    /// The reply taken last has its last body byte taken in clock `last_take`.
    pub(crate) fn reply_sent(&mut self, last_take: u64) {
        self.locked_until = Some(last_take + self.t.unlock_after_last_take);
    }

    /// The box counters a read in clock `c` sees (the link as in the model's block).
    pub(crate) fn counters_at(&self, c: u64) -> BoxCounters {
        let mut b = self.base;
        for (at, counter) in &self.counts {
            if *at <= c {
                b.bump(*counter);
            }
        }
        b
    }

    /// Body length of a raw frame: the wire bytes less preamble and FCS.
    pub(crate) fn body_len(wire: &[u8]) -> u64 {
        (wire.len() - PREAMBLE_LEN - FCS_LEN) as u64
    }
}
