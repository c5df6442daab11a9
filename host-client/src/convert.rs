//! The event-to-data converter (Algorithm 2 of Bergner et al.'s second paper): keeps the
//! full nine-channel state of every cell from its packets and emits a full [`Sample`] for
//! each one.
//!
//! Event values are absolute, so one lost event packet costs accuracy only until its
//! channels fire again, never a drift. The converter therefore marks channels *stale* when
//! the cell's event sequence shows a gap: a stale channel may hold an old value, and it
//! stops being stale when it fires again (or a data packet refreshes every channel).
//! Channels never received are *unknown* (value 0) until they fire.
//!
//! One sample is emitted per packet: a sample whose seven to nine events were split into two
//! packets gives two samples at the two packets' ticks, the second one complete.

use serde::Serialize;
use skinbox_protocol::{CellRepr, Channel, ChannelMask};

/// Number of cell ids (14 bits).
pub const CELL_IDS: usize = 1 << 14;

/// One full sample of a cell, as the converter knows it after a packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct Sample {
    /// The box the cell is on (set by the decoder; 0 from a bare converter).
    pub box_id: u16,
    /// The source address of the box's datagrams, where known (set by the decoder).
    pub source: Option<std::net::SocketAddr>,
    /// The cell.
    pub cell_id: u16,
    /// Box tick of the packet that produced the sample.
    pub tick: u64,
    /// Raw values in channel order.
    pub raw: [i32; Channel::COUNT],
    /// Channels received at least once.
    pub known: ChannelMask,
    /// Channels not refreshed since an event sequence gap of this cell.
    pub stale: ChannelMask,
    /// Channels this packet carried.
    pub updated: ChannelMask,
}

impl Sample {
    /// One channel in physical units.
    pub fn value(&self, channel: Channel) -> f64 {
        channel.to_units(self.raw[channel.index()])
    }

    /// Box time in seconds.
    pub fn time_s(&self) -> f64 {
        crate::ticks_to_seconds(self.tick)
    }

    /// Whether any channel is stale.
    pub fn is_stale(&self) -> bool {
        !self.stale.is_empty()
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct CellState {
    raw: [i32; Channel::COUNT],
    known: u16,
    stale: u16,
}

/// The converter: state of every cell id.
#[derive(Debug, Clone)]
pub struct EventToData {
    cells: Vec<CellState>,
}

impl Default for EventToData {
    fn default() -> Self {
        Self::new()
    }
}

impl EventToData {
    /// A converter that knows no cell.
    pub fn new() -> Self {
        EventToData { cells: Vec::new() }
    }

    /// The state of a cell, growing the table to the highest id seen (ids are 14 bits).
    fn cell(&mut self, cell_id: u16) -> &mut CellState {
        let index = usize::from(cell_id) % CELL_IDS;
        if index >= self.cells.len() {
            self.cells.resize(index + 1, CellState::default());
        }
        &mut self.cells[index]
    }

    /// Marks every known channel of `cell_id` stale (an event packet of it was lost).
    pub fn mark_gap(&mut self, cell_id: u16) {
        self.cell(cell_id).stale = ChannelMask::CHANNEL_BITS;
    }

    /// Takes one cell packet at `tick`; `gap_before` says the cell's event sequence showed a
    /// gap just before this packet. Returns the cell's full sample after it.
    pub fn push(&mut self, tick: u64, cell: &CellRepr, gap_before: bool) -> Sample {
        let cell_id = cell.cell_id();
        if gap_before {
            self.mark_gap(cell_id);
        }
        let s = self.cell(cell_id);
        let updated = match cell {
            CellRepr::Data(d) => {
                s.raw = d.raw_values();
                ChannelMask::CHANNEL_BITS
            }
            CellRepr::Event(e) => {
                for (channel, raw) in e.events() {
                    s.raw[channel.index()] = raw;
                }
                e.channels.bits()
            }
        };
        s.known |= updated;
        s.stale &= !updated;
        s.stale &= s.known;
        Sample {
            box_id: 0,
            source: None,
            cell_id,
            tick,
            raw: s.raw,
            known: ChannelMask::from_bits(s.known).unwrap_or_default(),
            stale: ChannelMask::from_bits(s.stale).unwrap_or_default(),
            updated: ChannelMask::from_bits(updated).unwrap_or_default(),
        }
    }

    /// The current state of one cell, if it sent anything.
    pub fn state(&self, cell_id: u16) -> Option<([i32; Channel::COUNT], ChannelMask)> {
        let s = self.cells.get(usize::from(cell_id))?;
        (s.known != 0).then(|| (s.raw, ChannelMask::from_bits(s.known).unwrap_or_default()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_protocol::{DataRepr, EventRepr};

    #[test]
    fn events_update_state_and_gaps_mark_stale() {
        let mut c = EventToData::new();
        let d = DataRepr::from_raw(7, [1, 2, 256, 3, 4, 5, 6, 60, 0]).unwrap();
        let s = c.push(10, &CellRepr::Data(d), false);
        assert_eq!(s.raw, [1, 2, 256, 3, 4, 5, 6, 60, 0]);
        assert_eq!(s.known, ChannelMask::ALL);

        let e = EventRepr::new(
            7,
            1,
            false,
            &[(Channel::AccelZ, 300), (Channel::Proximity, 99)],
        )
        .unwrap();
        let s = c.push(20, &CellRepr::Event(e), true);
        assert_eq!(s.raw, [1, 2, 300, 3, 4, 5, 99, 60, 0]);
        assert_eq!(s.value(Channel::AccelZ), 300.0 / 256.0);
        let still: ChannelMask = Channel::ALL
            .into_iter()
            .filter(|c| *c != Channel::AccelZ && *c != Channel::Proximity)
            .collect();
        assert_eq!(s.stale, still);

        let s = c.push(30, &CellRepr::Data(d), false);
        assert!(!s.is_stale());
    }

    #[test]
    fn unknown_channels_are_not_stale() {
        let mut c = EventToData::new();
        let e = EventRepr::new(9, 5, false, &[(Channel::Force1, 12)]).unwrap();
        let s = c.push(1, &CellRepr::Event(e), true);
        assert_eq!(s.known.bits(), 1 << 3);
        assert!(s.stale.is_empty());
        assert_eq!(s.raw[3], 12);
    }
}
