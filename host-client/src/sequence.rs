//! Datagram sequence numbers: gaps, duplicates, late (reordered) arrivals and restarts.
//!
//! The box numbers every datagram of either kind, +1 each, wrapping at 2^32 (docs/wire-format.md).
//! The tracker remembers which of the last [`WINDOW`] numbers below the highest one arrived,
//! so a late datagram fills its gap (counted as reordered, no longer missing) and a second
//! copy is a duplicate. A number further back than the window is taken as a restart of the
//! numbering (a box reset whose status report has not arrived yet).
//!
//! Each number can carry a tag (the decoder uses the datagram's base tick): a number seen
//! before with a different tag is not a copy but a new datagram of a numbering that started
//! again, so it is taken as a restart, never dropped as a duplicate. A tag more than
//! [`RESTART_TAG_DROP`] below the highest tag since the (re)start is a restart too: the box's
//! clock started again (a box reset), whatever its sequence number says.

use serde::Serialize;

/// How many sequence numbers behind the highest one are remembered: 0.2 s of a full
/// link (82,000 datagrams/s); a LAN does not reorder further than that.
pub const WINDOW: u32 = 1 << 14;
const WORDS: usize = (WINDOW / 64) as usize;

/// How far a tag (the datagram's base tick, 8 ns) may fall below the highest one before it
/// is taken as a restarted clock: 1 s, far more than a LAN reorders and far less than a
/// box runs between resets.
pub const RESTART_TAG_DROP: u64 = skinbox_protocol::TICKS_PER_SECOND;

/// What one sequence number was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SequenceEvent {
    /// The first number seen (or the first after a restart).
    First,
    /// The next number.
    InOrder,
    /// Ahead of the next number: `missing` numbers were skipped (for now).
    Gap {
        /// Numbers skipped.
        missing: u32,
    },
    /// Behind the highest number and not seen before: it fills a gap.
    Late,
    /// Seen before.
    Duplicate,
    /// Far behind the highest number: the numbering started again.
    Restart,
}

/// Counts over a stream of sequence numbers.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct SequenceCounts {
    /// Numbers received once (duplicates not counted).
    pub received: u64,
    /// Numbers skipped and not arrived late: lost datagrams.
    pub missing: u64,
    /// Copies of numbers already received.
    pub duplicate: u64,
    /// Numbers that arrived after a higher one (they are not missing).
    pub reordered: u64,
    /// Gaps seen when they opened (a reordered datagram still opens one).
    pub gaps: u64,
    /// Times the numbering started again far below the highest number.
    pub restarts: u64,
}

/// The tracker.
#[derive(Debug, Clone)]
pub struct SequenceTracker {
    highest: Option<u32>,
    /// Numbers since the (re)start, to tell a late datagram from one before the capture.
    span: u64,
    seen: Box<[u64; WORDS]>,
    tags: Vec<u64>,
    /// Highest tag since the (re)start.
    top_tag: Option<u64>,
    counts: SequenceCounts,
}

impl Default for SequenceTracker {
    fn default() -> Self {
        Self::new()
    }
}

impl SequenceTracker {
    /// A tracker that has seen nothing.
    pub fn new() -> Self {
        SequenceTracker {
            highest: None,
            span: 0,
            seen: Box::new([0; WORDS]),
            tags: vec![0; WINDOW as usize],
            top_tag: None,
            counts: SequenceCounts::default(),
        }
    }

    fn bit(&self, seq: u32) -> bool {
        let i = (seq % WINDOW) as usize;
        self.seen[i / 64] & (1 << (i % 64)) != 0
    }

    fn set(&mut self, seq: u32, on: bool) {
        let i = (seq % WINDOW) as usize;
        if on {
            self.seen[i / 64] |= 1 << (i % 64);
        } else {
            self.seen[i / 64] &= !(1 << (i % 64));
        }
    }

    fn start(&mut self, seq: u32, tag: Option<u64>) {
        self.top_tag = tag;
        let tag = tag.unwrap_or(0);
        self.seen.fill(0);
        self.highest = Some(seq);
        self.span = 0;
        self.set(seq, true);
        self.tags[(seq % WINDOW) as usize] = tag;
        self.counts.received += 1;
    }

    /// A number seen before: a copy when the tags agree, else the numbering restarted.
    fn seen_again(&mut self, seq: u32, tag: Option<u64>) -> SequenceEvent {
        match tag {
            Some(t) if self.tags[(seq % WINDOW) as usize] != t => {
                self.counts.restarts += 1;
                self.start(seq, Some(t));
                SequenceEvent::Restart
            }
            _ => {
                self.counts.duplicate += 1;
                SequenceEvent::Duplicate
            }
        }
    }

    /// Starts the numbering again at `seq` (a box reset), forgetting the window.
    pub fn restart_at(&mut self, seq: u32) {
        self.counts.restarts += 1;
        self.start(seq, None);
    }

    /// Starts the numbering at `seq` without counting a restart (the caller knows why).
    pub fn begin_at(&mut self, seq: u32, tag: u64) {
        self.start(seq, Some(tag));
    }

    /// Takes one sequence number.
    pub fn push(&mut self, seq: u32) -> SequenceEvent {
        self.push_tagged(seq, None)
    }

    /// Takes one sequence number with a tag that tells a copy from a new datagram.
    pub fn push_tagged(&mut self, seq: u32, tag: Option<u64>) -> SequenceEvent {
        let Some(highest) = self.highest else {
            self.start(seq, tag);
            return SequenceEvent::First;
        };
        if let (Some(t), Some(top)) = (tag, self.top_tag) {
            if top.saturating_sub(t) > RESTART_TAG_DROP {
                self.counts.restarts += 1;
                self.start(seq, tag);
                return SequenceEvent::Restart;
            }
            self.top_tag = Some(top.max(t));
        } else if tag.is_some() {
            self.top_tag = tag;
        }
        let ahead = seq.wrapping_sub(highest);
        if ahead == 0 {
            return self.seen_again(seq, tag);
        }
        if ahead < 1 << 31 {
            if ahead >= WINDOW {
                self.seen.fill(0);
            } else {
                for s in 1..ahead {
                    self.set(highest.wrapping_add(s), false);
                }
            }
            self.set(seq, true);
            self.tags[(seq % WINDOW) as usize] = tag.unwrap_or(0);
            self.highest = Some(seq);
            self.span += u64::from(ahead);
            self.counts.received += 1;
            if ahead == 1 {
                return SequenceEvent::InOrder;
            }
            self.counts.gaps += 1;
            self.counts.missing += u64::from(ahead - 1);
            return SequenceEvent::Gap { missing: ahead - 1 };
        }
        let behind = highest.wrapping_sub(seq);
        if behind >= WINDOW {
            self.restart_at(seq);
            return SequenceEvent::Restart;
        }
        if self.bit(seq) {
            return self.seen_again(seq, tag);
        }
        self.set(seq, true);
        self.tags[(seq % WINDOW) as usize] = tag.unwrap_or(0);
        self.counts.received += 1;
        self.counts.reordered += 1;
        if u64::from(behind) <= self.span {
            self.counts.missing -= 1;
        }
        SequenceEvent::Late
    }

    /// The counts so far.
    pub fn counts(&self) -> SequenceCounts {
        self.counts
    }

    /// The highest number seen since the (re)start.
    pub fn highest(&self) -> Option<u32> {
        self.highest
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(seqs: &[u32]) -> SequenceCounts {
        let mut t = SequenceTracker::new();
        for s in seqs {
            t.push(*s);
        }
        t.counts()
    }

    #[test]
    fn gap_duplicate_late_and_wrap() {
        let c = run(&[u32::MAX - 1, u32::MAX, 0, 3, 3, 1, 2, 2, 4]);
        assert_eq!(c.received, 7);
        assert_eq!(c.missing, 0);
        assert_eq!(c.duplicate, 2);
        assert_eq!(c.reordered, 2);
        assert_eq!(c.gaps, 1);

        let c = run(&[10, 11, 15, 16]);
        assert_eq!((c.missing, c.gaps, c.received), (3, 1, 4));
    }

    #[test]
    fn late_from_before_the_capture_is_not_unmissed() {
        let c = run(&[10, 11, 9]);
        assert_eq!((c.missing, c.reordered, c.received), (0, 1, 3));
    }

    #[test]
    fn same_number_other_tag_restarts() {
        let mut t = SequenceTracker::new();
        for s in 0..10 {
            t.push_tagged(s, Some(1000 + u64::from(s)));
        }
        assert_eq!(t.push_tagged(4, Some(1004)), SequenceEvent::Duplicate);
        assert_eq!(t.push_tagged(0, Some(7)), SequenceEvent::Restart);
        assert_eq!(t.push_tagged(1, Some(8)), SequenceEvent::InOrder);
        let c = t.counts();
        assert_eq!(
            (c.duplicate, c.restarts, c.missing, c.received),
            (1, 1, 0, 12)
        );
    }

    #[test]
    fn tag_far_below_restarts_even_on_a_missing_number() {
        let mut t = SequenceTracker::new();
        let second = skinbox_protocol::TICKS_PER_SECOND;
        for s in 0..10u32 {
            if s != 2 {
                t.push_tagged(s, Some(5 * second + u64::from(s)));
            }
        }
        // Number 2 never arrived; the restarted box's number 2 is no late arrival.
        assert_eq!(t.push_tagged(2, Some(1_000)), SequenceEvent::Restart);
        assert_eq!(t.push_tagged(3, Some(2_000)), SequenceEvent::InOrder);
        // A late datagram within the tolerance is still late.
        let mut u = SequenceTracker::new();
        u.push_tagged(0, Some(2 * second));
        u.push_tagged(2, Some(2 * second + 10));
        assert_eq!(u.push_tagged(1, Some(second + 20)), SequenceEvent::Late);
        let c = t.counts();
        assert_eq!((c.restarts, c.missing, c.received), (1, 1, 11));
    }

    #[test]
    fn far_behind_restarts() {
        let c = run(&[100_000, 100_001, 0, 1, 3]);
        assert_eq!((c.restarts, c.missing, c.received), (1, 1, 5));
    }
}
