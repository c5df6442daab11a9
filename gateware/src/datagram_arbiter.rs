//! DatagramArbiter: merges whole datagrams of several sources into one, round robin.
//!
//! Each source offers a descriptor and then its body ([`DatagramSource`]). The arbiter
//! offers the descriptor of one waiting source at a time: the first waiting after the
//! source it granted last (so no source waits more than one datagram of each other
//! source), and passes the granted source's body through until its `last` beat; no other
//! descriptor is offered before that beat moved, so two datagrams never interleave.
//! The choice is made from the sources' `valid` and registers (the last grant, the
//! sources after it, "a body is open") through no adder or carry chain (a prefix OR picks
//! the lowest candidate) and is registered: the descriptor offered in a clock is that of
//! the source chosen from the sources waiting in the clock before ([`OFFER_LATENCY`]), so
//! the sink's descriptor registers and the sources' `ready` hang off one register, not off
//! the choice. The choice is made again every clock until the offer is taken (sources keep
//! `valid` until taken, so the offer never drops; it moves to a source of higher precedence
//! that starts waiting meanwhile). From the take until its body's last beat moved, the
//! granted source's descriptor stays on `datagrams` (`valid` low): a source holds its
//! descriptor until then, so the sink reads its fields there instead of holding copies.
//! The header fields (flags, entry count, base tick) follow a clock behind the rest of the
//! descriptor ([`FIELDS_LATENCY`]): the granted source's from the clock after the take until
//! a clock after its body's last beat. They are selected by a copy of `descriptor_from`
//! registered from it alone, which the placer may put beside the fields' reader (the
//! frame transmitter reads them from its frame's index 0, the clock after the take).

use crate::hdl::*;
use crate::stream::{DatagramSink, DatagramSource};

/// Most sources an arbiter takes.
pub const MAX_SOURCES: usize = 8;

/// Clocks from a source's `valid` to the arbiter offering its descriptor.
pub const OFFER_LATENCY: u64 = 1;

/// Clocks from the take to the granted source's header fields on `datagrams`.
pub const FIELDS_LATENCY: u64 = 1;

/// Round-robin, packet-atomic merge of datagram sources.
#[derive(LogicBlock)]
pub struct DatagramArbiter {
    /// The box clock.
    pub clock: Signal<In, Clock>,
    /// Synchronous reset.
    pub reset: Signal<In, Bit>,
    /// The sources, in their order of precedence after reset.
    pub sources: Vec<DatagramSink>,
    /// The merged datagrams.
    pub datagrams: DatagramSource,
    // the source granted last, one-hot, and the sources after it (0 after reset: source 0
    // comes first)
    last_grant: DFF<Bits<MAX_SOURCES>>,
    after_last_grant: DFF<Bits<MAX_SOURCES>>,
    // a descriptor was taken and its body's last beat has not moved
    body_open: DFF<Bit>,
    // the source offered, one-hot (chosen in the clock before)
    offered: DFF<Bits<MAX_SOURCES>>,
    // a source is offered (`offered != 0`, kept in a register: no OR of its bits before
    // `taken` and the offer's reset)
    offered_any: DFF<Bit>,
    // the source whose descriptor is on `datagrams`, one-hot: the offered one, then the
    // granted one while its body is open
    descriptor_from: DFF<Bits<MAX_SOURCES>>,
    // the source whose header fields are on `datagrams`: `descriptor_from` a clock later
    fields_from: DFF<Bits<MAX_SOURCES>>,
    // source i's bit
    source_bit: Vec<Constant<Bits<MAX_SOURCES>>>,
    waiting: Signal<Local, Bits<MAX_SOURCES>>,
    // the waiting sources after the last grant
    after_last: Signal<Local, Bits<MAX_SOURCES>>,
    candidates: Signal<Local, Bits<MAX_SOURCES>>,
    // the granted source, one-hot, the lowest candidate: a candidate below is seen
    grant: Signal<Local, Bits<MAX_SOURCES>>,
    candidate_below: Signal<Local, Bit>,
    // the sources after the offered one (for the next round), and "offered is below"
    after_offer: Signal<Local, Bits<MAX_SOURCES>>,
    offered_below: Signal<Local, Bit>,
    taken: Signal<Local, Bit>,
    last_beat_taken: Signal<Local, Bit>,
}

impl DatagramArbiter {
    /// An arbiter of `sources` sources (1 to [`MAX_SOURCES`]).
    pub fn new(sources: usize) -> Self {
        assert!(
            (1..=MAX_SOURCES).contains(&sources),
            "DatagramArbiter: {sources} sources, must be 1 to {MAX_SOURCES}"
        );
        Self {
            clock: Default::default(),
            reset: Default::default(),
            sources: (0..sources).map(|_| Default::default()).collect(),
            datagrams: Default::default(),
            last_grant: Default::default(),
            after_last_grant: Default::default(),
            body_open: Default::default(),
            offered: Default::default(),
            offered_any: Default::default(),
            descriptor_from: Default::default(),
            fields_from: Default::default(),
            source_bit: (0..sources)
                .map(|i| Constant::new((1u64 << i).into()))
                .collect(),
            waiting: Default::default(),
            after_last: Default::default(),
            candidates: Default::default(),
            grant: Default::default(),
            candidate_below: Default::default(),
            after_offer: Default::default(),
            offered_below: Default::default(),
            taken: Default::default(),
            last_beat_taken: Default::default(),
        }
    }
}

impl Logic for DatagramArbiter {
    #[hdl_gen]
    fn update(&mut self) {
        dff_setup!(
            self,
            clock,
            last_grant,
            after_last_grant,
            body_open,
            offered,
            offered_any,
            descriptor_from,
            fields_from
        );
        self.waiting.next = 0.into();
        for i in 0..self.sources.len() {
            if self.sources[i].valid.val() & !self.body_open.q.val() {
                self.waiting.next = self.waiting.val() | self.source_bit[i].val();
            }
        }
        // the waiting sources after the last grant first, else all waiting
        self.after_last.next = self.waiting.val() & self.after_last_grant.q.val();
        self.candidates.next = self.waiting.val();
        if self.after_last.val() != 0 {
            self.candidates.next = self.after_last.val();
        }
        // the lowest candidate; the sources after the offered one
        self.grant.next = 0.into();
        self.candidate_below.next = false;
        self.after_offer.next = 0.into();
        self.offered_below.next = false;
        for i in 0..self.sources.len() {
            if self.offered_below.val() {
                self.after_offer.next = self.after_offer.val() | self.source_bit[i].val();
            }
            if self.offered.q.val().get_bit(i) {
                self.offered_below.next = true;
            }
            if self.candidates.val().get_bit(i) & !self.candidate_below.val() {
                self.grant.next = self.source_bit[i].val();
            }
            self.candidate_below.next =
                self.candidate_below.val() | self.candidates.val().get_bit(i);
        }
        self.datagrams.valid.next = self.offered_any.q.val();
        self.datagrams.kind.next = 0.into();
        self.datagrams.flags.next = 0.into();
        self.datagrams.entry_count.next = 0.into();
        self.datagrams.base_tick.next = 0.into();
        self.datagrams.body_len.next = 0.into();
        self.datagrams.body_sum.next = 0.into();
        self.datagrams.body.valid.next = false;
        self.datagrams.body.data.next = 0.into();
        self.datagrams.body.last.next = false;
        self.datagrams.body.error.next = false;
        for i in 0..self.sources.len() {
            self.sources[i].ready.next =
                self.datagrams.ready.val() & self.offered.q.val().get_bit(i);
            if self.descriptor_from.q.val().get_bit(i) {
                self.datagrams.kind.next = self.sources[i].kind.val();
                self.datagrams.body_len.next = self.sources[i].body_len.val();
                self.datagrams.body_sum.next = self.sources[i].body_sum.val();
            }
            if self.fields_from.q.val().get_bit(i) {
                self.datagrams.flags.next = self.sources[i].flags.val();
                self.datagrams.entry_count.next = self.sources[i].entry_count.val();
                self.datagrams.base_tick.next = self.sources[i].base_tick.val();
            }
            // the body of the source granted last, while it is open
            self.sources[i].body.ready.next = self.datagrams.body.ready.val()
                & self.body_open.q.val()
                & self.last_grant.q.val().get_bit(i);
            if self.body_open.q.val() & self.last_grant.q.val().get_bit(i) {
                self.datagrams.body.valid.next = self.sources[i].body.valid.val();
                self.datagrams.body.data.next = self.sources[i].body.data.val();
                self.datagrams.body.last.next = self.sources[i].body.last.val();
                self.datagrams.body.error.next = self.sources[i].body.error.val();
            }
        }
        self.taken.next = self.datagrams.ready.val() & self.offered_any.q.val();
        self.offered.d.next = self.grant.val();
        self.offered_any.d.next = self.waiting.val() != 0;
        // (no source waits while a body is open: the grant is 0 then)
        self.descriptor_from.d.next = self.grant.val();
        self.fields_from.d.next = self.descriptor_from.q.val();
        if self.body_open.q.val() {
            self.descriptor_from.d.next = self.descriptor_from.q.val();
        }
        if self.taken.val() {
            self.descriptor_from.d.next = self.offered.q.val();
            self.offered.d.next = 0.into();
            self.offered_any.d.next = false;
            self.last_grant.d.next = self.offered.q.val();
            self.after_last_grant.d.next = self.after_offer.val();
            self.body_open.d.next = true;
        }
        // the granted source's last beat is taken: its own valid and last under the last
        // grant (not through the body multiplexer, which `body_open` selects too)
        self.last_beat_taken.next = false;
        for i in 0..self.sources.len() {
            if self.last_grant.q.val().get_bit(i)
                & self.sources[i].body.valid.val()
                & self.sources[i].body.last.val()
            {
                self.last_beat_taken.next = true;
            }
        }
        if self.body_open.q.val() & self.last_beat_taken.val() & self.datagrams.body.ready.val() {
            self.body_open.d.next = false;
            self.descriptor_from.d.next = 0.into();
        }
        if self.reset.val() {
            self.last_grant.d.next = 0.into();
            self.after_last_grant.d.next = 0.into();
            self.body_open.d.next = false;
            self.offered.d.next = 0.into();
            self.offered_any.d.next = false;
            self.descriptor_from.d.next = 0.into();
            self.fields_from.d.next = 0.into();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testbench::{Bench, TestRng};
    use std::collections::VecDeque;

    /// A datagram as a source offers it: descriptor fields and body bytes.
    #[derive(Clone, Debug, PartialEq)]
    struct Datagram {
        source: usize,
        kind: u8,
        flags: u8,
        entry_count: u16,
        base_tick: u64,
        body_sum: u32,
        body: Vec<u8>,
    }

    fn datagram(source: usize, k: usize, rng: &mut TestRng) -> Datagram {
        let len = 1 + (rng.next_u64() % 40) as usize;
        Datagram {
            source,
            kind: source as u8 + 1,
            flags: k as u8,
            entry_count: (k * 3 + source) as u16,
            base_tick: rng.next_u64(),
            body_sum: rng.next_u64() as u32 & 0x1_FFFF,
            body: (0..len).map(|_| rng.byte()).collect(),
        }
    }

    /// Sources offer their queues with random gaps (a body beat only after its
    /// descriptor was taken), the sink takes with random backpressure. Returns the
    /// datagrams in the order they came out and, per datagram, the sources that were
    /// waiting when it was granted.
    fn run(
        queues: Vec<VecDeque<Datagram>>,
        offer_p: f64,
        take_p: f64,
        seed: u64,
    ) -> (Vec<Datagram>, Vec<Vec<usize>>) {
        let n = queues.len();
        let total: usize = queues.iter().map(VecDeque::len).sum();
        let mut queues = queues;
        let mut rng = TestRng::new(seed);
        let mut bench = Bench::new(DatagramArbiter::new(n), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        // per source: descriptor offered, body position once taken
        let mut offering = vec![false; n];
        let mut body_at: Vec<Option<usize>> = vec![None; n];
        let mut out: Vec<Datagram> = vec![];
        let mut waiting_at_grant = vec![];
        let mut open: Option<Datagram> = None;
        for _ in 0..200_000 {
            for s in 0..n {
                if !offering[s] && body_at[s].is_none() && !queues[s].is_empty() {
                    offering[s] = rng.chance(offer_p);
                }
            }
            let take_descriptor = rng.chance(take_p);
            let take_body = rng.chance(take_p);
            let u = &mut bench.uut;
            for s in 0..n {
                let src = &mut u.sources[s];
                src.valid.next = offering[s];
                src.body.valid.next = false;
                if let Some(d) = queues[s].front() {
                    src.kind.next = u64::from(d.kind).into();
                    src.flags.next = u64::from(d.flags).into();
                    src.entry_count.next = u64::from(d.entry_count).into();
                    src.base_tick.next = d.base_tick.into();
                    src.body_len.next = (d.body.len() as u64).into();
                    src.body_sum.next = u64::from(d.body_sum).into();
                    if let Some(at) = body_at[s] {
                        // a body beat offered with random gaps
                        if rng.chance(offer_p) {
                            src.body.valid.next = true;
                            src.body.data.next = u64::from(d.body[at]).into();
                            src.body.last.next = at + 1 == d.body.len();
                            src.body.error.next = false;
                        }
                    }
                }
            }
            u.datagrams.ready.next = take_descriptor;
            u.datagrams.body.ready.next = take_body;
            bench.settle();
            let u = &bench.uut;
            if let Some(o) = &open {
                // the granted source's descriptor stays until its body's last beat (the
                // header fields from the clock after the take)
                assert_eq!(u.datagrams.kind.val().to_u8(), o.kind);
                assert_eq!(u.datagrams.flags.val().to_u8(), o.flags);
                assert_eq!(
                    u.datagrams.entry_count.val().index(),
                    o.entry_count as usize
                );
                assert_eq!(u.datagrams.base_tick.val().to_u64(), o.base_tick);
            }
            let ready: Vec<bool> = (0..n).map(|s| u.sources[s].ready.val()).collect();
            let body_ready: Vec<bool> = (0..n).map(|s| u.sources[s].body.ready.val()).collect();
            assert!(
                ready.iter().filter(|r| **r).count() <= 1,
                "one grant at a time"
            );
            if u.datagrams.valid.val() && take_descriptor {
                assert!(open.is_none(), "a descriptor while a body is open");
                let s = ready
                    .iter()
                    .position(|r| *r)
                    .expect("the granted source is told");
                let d = &queues[s][0];
                assert_eq!(u.datagrams.kind.val().to_u8(), d.kind);
                assert_eq!(u.datagrams.body_len.val().index(), d.body.len());
                assert_eq!(u.datagrams.body_sum.val().to_u64(), u64::from(d.body_sum));
                waiting_at_grant.push((0..n).filter(|&w| offering[w]).collect());
                open = Some(Datagram {
                    body: vec![],
                    ..d.clone()
                });
                offering[s] = false;
                body_at[s] = Some(0);
            } else {
                assert!(!ready.iter().any(|r| *r) || !take_descriptor);
            }
            if u.datagrams.body.valid.val() && take_body {
                let o = open.as_mut().expect("a body beat with no descriptor taken");
                let s = o.source;
                assert!(body_ready[s], "the beat comes from the granted source");
                o.body.push(u.datagrams.body.data.val().to_u8());
                let at = body_at[s].unwrap() + 1;
                assert_eq!(u.datagrams.body.last.val(), at == queues[s][0].body.len());
                body_at[s] = Some(at);
                if u.datagrams.body.last.val() {
                    out.push(open.take().unwrap());
                    queues[s].pop_front();
                    body_at[s] = None;
                }
            }
            for (s, ready) in body_ready.iter().enumerate() {
                assert!(
                    !ready
                        || open.as_ref().is_some_and(|o| o.source == s)
                        || out.last().is_some_and(|o| o.source == s),
                    "body ready only to the granted source"
                );
            }
            bench.cycle();
            if out.len() == total {
                break;
            }
        }
        assert_eq!(out.len(), total, "every datagram came out");
        (out, waiting_at_grant)
    }

    #[test]
    fn whole_datagrams_pass_unchanged_and_never_interleave() {
        for (seed, n, offer_p, take_p) in [
            (1, 2, 1.0, 1.0),
            (2, 2, 0.3, 0.8),
            (3, 5, 0.7, 0.4),
            (4, 8, 0.9, 0.9),
            (5, 1, 0.5, 0.5),
            (6, 3, 0.1, 1.0),
        ] {
            let mut rng = TestRng::new(seed);
            let queues: Vec<VecDeque<Datagram>> = (0..n)
                .map(|s| (0..12).map(|k| datagram(s, k, &mut rng)).collect())
                .collect();
            let (out, _) = run(queues.clone(), offer_p, take_p, seed);
            // each source's datagrams in their order, bodies whole
            for (s, queue) in queues.iter().enumerate() {
                let mine: Vec<&Datagram> = out.iter().filter(|d| d.source == s).collect();
                let sent: Vec<&Datagram> = queue.iter().collect();
                assert_eq!(mine, sent, "seed {seed}, source {s}");
            }
        }
    }

    #[test]
    fn every_waiting_source_is_served_within_one_round() {
        // all sources always waiting: the grants go round 0, 1, .., n - 1
        let mut rng = TestRng::new(9);
        let n = 4;
        let queues: Vec<VecDeque<Datagram>> = (0..n)
            .map(|s| (0..10).map(|k| datagram(s, k, &mut rng)).collect())
            .collect();
        let (out, _) = run(queues, 1.0, 1.0, 9);
        let order: Vec<usize> = out.iter().map(|d| d.source).collect();
        let expected: Vec<usize> = (0..40).map(|i| i % n).collect();
        assert_eq!(order, expected);
        // with random waiting: a source waiting at a grant is served before any other
        // source is served twice
        let mut rng = TestRng::new(11);
        let queues: Vec<VecDeque<Datagram>> = (0..n)
            .map(|s| (0..30).map(|k| datagram(s, k, &mut rng)).collect())
            .collect();
        let (out, waiting) = run(queues, 0.2, 0.7, 11);
        for (i, w) in waiting.iter().enumerate() {
            for &s in w {
                let served = out[i..].iter().position(|d| d.source == s);
                let Some(at) = served else { continue };
                let between = &out[i..i + at];
                for other in 0..n {
                    assert!(
                        between.iter().filter(|d| d.source == other).count() <= 1,
                        "source {s} waited while {other} was served twice: {:?}",
                        out.iter().map(|d| d.source).collect::<Vec<_>>()
                    );
                }
            }
        }
    }

    #[test]
    fn a_waiting_source_is_offered_a_clock_later_from_registers() {
        let mut bench = Bench::new(DatagramArbiter::new(3), |b| &mut b.clock);
        bench.uut.reset.next = true;
        bench.cycle();
        bench.uut.reset.next = false;
        bench.uut.datagrams.ready.next = true;
        bench.uut.datagrams.body.ready.next = false;
        bench.uut.sources[2].valid.next = true;
        bench.uut.sources[2].kind.next = 7.into();
        bench.settle();
        // the clock the source starts waiting: nothing offered, nothing taken
        assert!(!bench.uut.datagrams.valid.val());
        assert!(!bench.uut.sources[2].ready.val());
        for clock in 1..=OFFER_LATENCY {
            bench.cycle();
            bench.settle();
            let offered = bench.uut.datagrams.valid.val();
            assert_eq!(offered, clock == OFFER_LATENCY, "clock {clock}");
        }
        assert_eq!(bench.uut.datagrams.kind.val().to_u8(), 7);
        assert!(
            bench.uut.sources[2].ready.val(),
            "taken in the clock offered"
        );
        // taken: no offer in the next clock, though the source still says valid
        bench.cycle();
        bench.settle();
        assert!(!bench.uut.datagrams.valid.val());
    }
}
