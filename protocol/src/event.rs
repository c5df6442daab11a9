//! The cell event packet: the channels that changed by more than their threshold (header
//! 0xA2), after Fig. 4 and Algorithm 1 of Bergner et al.
//!
//! | bytes | field |
//! |---|---|
//! | 0 | header 0xA2 |
//! | 1-2 | cell id |
//! | 3-4 | mask: bit 0 accel x .. bit 8 temperature 2; bit 15 second packet; bits 9-14 zero |
//! | 5-16 | up to six 16-bit values in mask-bit order (i16 acceleration, u16 otherwise), unused 0 |
//! | 17-18 | per-cell event packet sequence number (u16, wraps) |
//! | 19 | end of packet 0x55 |
//!
//! Values are absolute, so a lost event packet costs accuracy until the channel fires again,
//! never a drift. A sample with seven to nine events is sent as two packets: the first six
//! channels in bit order, then the rest with bit 15 set and the next sequence number.

use crate::cell::{self, CellFraming, CellKind, CellPacket, PACKET_LEN};
use crate::{get_u16, Channel, ChannelMask, Error, Format, LayoutRow, Result};
use core::fmt;

mod field {
    use crate::Field;
    pub const MASK: Field = 3..5;
    pub const VALUES: [Field; super::MAX_EVENTS] = [5..7, 7..9, 9..11, 11..13, 13..15, 15..17];
    pub const SEQUENCE: Field = 17..19;
}

/// Most values one event packet carries.
pub const MAX_EVENTS: usize = 6;
/// Mask bit set on the second packet of a split sample.
pub const MASK_SECOND_PART: u16 = 1 << 15;
const MASK_RESERVED: u16 = !(MASK_SECOND_PART | ChannelMask::CHANNEL_BITS);

/// Published layout of the event packet.
pub fn layout() -> Vec<LayoutRow> {
    let mut rows = cell::layout();
    let end = rows.pop().expect("cell layout ends with end_of_packet");
    rows.pop();
    rows.push(LayoutRow {
        name: "mask",
        bytes: field::MASK,
    });
    const NAMES: [&str; MAX_EVENTS] = [
        "value_1", "value_2", "value_3", "value_4", "value_5", "value_6",
    ];
    for (name, bytes) in NAMES.iter().zip(field::VALUES) {
        rows.push(LayoutRow { name, bytes });
    }
    rows.push(LayoutRow {
        name: "sequence",
        bytes: field::SEQUENCE,
    });
    rows.push(end);
    rows
}

/// Checks the frame of an event packet: length, event header, end-of-packet byte, cell id.
fn check_frame(b: &[u8], framing: &CellFraming) -> Result<()> {
    match CellPacket::new_unchecked(b).check(Format::EventPacket, framing)? {
        CellKind::Event => Ok(()),
        CellKind::Data => Err(Error::BadHeader {
            format: Format::EventPacket,
            found: framing.data_header,
            data: framing.data_header,
            event: framing.event_header,
        }),
    }
}

/// A view over an event packet.
#[derive(Debug, Clone)]
pub struct EventPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> EventPacket<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        EventPacket { buffer }
    }

    /// Wraps untrusted bytes framed with the default header and end-of-packet values.
    pub fn new_checked(buffer: T) -> Result<Self> {
        Self::new_checked_with(buffer, &CellFraming::DEFAULT)
    }

    /// Wraps untrusted bytes: framing, cell id, and a mask with no reserved bit and one to
    /// six events.
    pub fn new_checked_with(buffer: T, framing: &CellFraming) -> Result<Self> {
        check_frame(buffer.as_ref(), framing)?;
        EventRepr::from_checked_frame(buffer.as_ref())?;
        Ok(EventPacket { buffer })
    }

    pub fn cell_id(&self) -> u16 {
        get_u16(self.buffer.as_ref(), cell::field::CELL_ID)
    }

    /// The whole 16-bit mask field.
    pub fn mask_field(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::MASK)
    }

    /// The channels carried.
    pub fn channels(&self) -> ChannelMask {
        ChannelMask::from_bits(self.mask_field() & ChannelMask::CHANNEL_BITS)
            .unwrap_or(ChannelMask::EMPTY)
    }

    /// Whether this is the second packet of a split sample.
    pub fn is_second_part(&self) -> bool {
        self.mask_field() & MASK_SECOND_PART != 0
    }

    /// The 16-bit word in value slot `slot` (0..6).
    pub fn value_word(&self, slot: usize) -> u16 {
        get_u16(self.buffer.as_ref(), field::VALUES[slot].clone())
    }

    /// Event packet sequence number.
    pub fn sequence(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::SEQUENCE)
    }
}

/// One event packet: which channels fired and their new raw values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct EventRepr {
    /// Sending cell (14 bits).
    pub cell_id: u16,
    /// The second packet of a sample that fired more than six channels.
    pub second_part: bool,
    /// Channels carried, one to six.
    pub channels: ChannelMask,
    /// Raw values in mask-bit order; slots past `channels.len()` are 0.
    values: [i32; MAX_EVENTS],
    /// Per-cell event packet sequence number.
    pub sequence: u16,
}

impl EventRepr {
    /// One packet from `(channel, raw value)` pairs in strictly increasing channel order.
    pub fn new(
        cell_id: u16,
        sequence: u16,
        second_part: bool,
        events: &[(Channel, i32)],
    ) -> Result<EventRepr> {
        if events.is_empty() {
            return Err(Error::BadEvents { reason: "no event" });
        }
        if events.len() > MAX_EVENTS {
            return Err(Error::BadEvents {
                reason: "more than six events for one packet",
            });
        }
        let mut values = [0; MAX_EVENTS];
        let mut channels = ChannelMask::EMPTY;
        let mut previous = None;
        for (slot, &(channel, value)) in events.iter().enumerate() {
            if previous.is_some_and(|p| p >= channel) {
                return Err(Error::BadEvents {
                    reason: "events not in strictly increasing channel order",
                });
            }
            if channel.encode_word(value).is_none() {
                return Err(Error::ValueOutOfRange {
                    format: Format::EventPacket,
                    channel,
                    value,
                    min: *channel.word_range().start(),
                    max: *channel.word_range().end(),
                });
            }
            previous = Some(channel);
            channels.insert(channel);
            values[slot] = value;
        }
        Ok(EventRepr {
            cell_id: cell_id & cell::CELL_ID_MAX,
            second_part,
            channels,
            values,
            sequence,
        })
    }

    /// The packets for one sample's events (one to nine, in channel order): six in the
    /// first, the rest in a second one with the next sequence number.
    pub fn split(
        cell_id: u16,
        sequence: u16,
        events: &[(Channel, i32)],
    ) -> Result<(EventRepr, Option<EventRepr>)> {
        if events.len() <= MAX_EVENTS {
            return Ok((Self::new(cell_id, sequence, false, events)?, None));
        }
        let (head, tail) = events.split_at(MAX_EVENTS);
        if head.last().map(|e| e.0) >= tail.first().map(|e| e.0) {
            return Err(Error::BadEvents {
                reason: "events not in strictly increasing channel order",
            });
        }
        let first = Self::new(cell_id, sequence, false, head)?;
        let second = Self::new(cell_id, sequence.wrapping_add(1), true, tail)?;
        Ok((first, Some(second)))
    }

    /// The events as `(channel, raw value)` in channel order.
    pub fn events(&self) -> impl Iterator<Item = (Channel, i32)> + '_ {
        self.channels.iter().zip(self.values)
    }

    /// Parses untrusted bytes framed with the default values.
    pub fn parse(bytes: &[u8]) -> Result<EventRepr> {
        Self::parse_with(bytes, &CellFraming::DEFAULT)
    }

    /// Parses untrusted bytes: the frame checked, then the body decoded once.
    pub fn parse_with(bytes: &[u8], framing: &CellFraming) -> Result<EventRepr> {
        check_frame(bytes, framing)?;
        Self::from_checked_frame(bytes)
    }

    /// The body of an event packet whose 20 bytes, header, end byte and cell id were
    /// checked: the mask, each value in its range, unused value slots 0, in one pass. The
    /// decoder's path ([`crate::CellRepr::parse`]).
    pub(crate) fn from_checked_frame(b: &[u8]) -> Result<EventRepr> {
        let mask = get_u16(b, field::MASK);
        let bits = mask & ChannelMask::CHANNEL_BITS;
        let used = bits.count_ones() as usize;
        let reason = if mask & MASK_RESERVED != 0 {
            Some("reserved bits 9-14 set")
        } else if used == 0 {
            Some("no channel")
        } else if used > MAX_EVENTS {
            Some("more than six channels")
        } else {
            None
        };
        if let Some(reason) = reason {
            return Err(Error::BadEventMask { mask, reason });
        }
        let mut values = [0; MAX_EVENTS];
        let mut rest = bits;
        for (slot, value) in values.iter_mut().enumerate() {
            let w = get_u16(b, field::VALUES[slot].clone());
            if rest == 0 {
                if w != 0 {
                    return Err(Error::UnusedValueSet {
                        slot,
                        used,
                        word: w,
                    });
                }
                continue;
            }
            let channel = Channel::ALL[rest.trailing_zeros() as usize];
            rest &= rest - 1;
            let v = channel.decode_word(w);
            let range = channel.word_range();
            if !range.contains(&v) {
                return Err(Error::ValueOutOfRange {
                    format: Format::EventPacket,
                    channel,
                    value: v,
                    min: *range.start(),
                    max: *range.end(),
                });
            }
            *value = v;
        }
        Ok(EventRepr {
            cell_id: get_u16(b, cell::field::CELL_ID),
            second_part: mask & MASK_SECOND_PART != 0,
            channels: ChannelMask::from_bits(bits).unwrap_or(ChannelMask::EMPTY),
            values,
            sequence: get_u16(b, field::SEQUENCE),
        })
    }

    /// Bytes [`EventRepr::emit`] writes.
    pub const fn buffer_len(&self) -> usize {
        PACKET_LEN
    }

    /// Writes the packet with the default framing into `buffer[..20]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        self.emit_with(buffer, &CellFraming::DEFAULT)
    }

    /// Writes the packet into `buffer[..20]`; unused value slots are 0.
    pub fn emit_with(&self, buffer: &mut [u8], framing: &CellFraming) {
        let b = &mut buffer[..PACKET_LEN];
        CellPacket::new_unchecked(&mut *b).emit_frame(framing.event_header, self.cell_id, framing);
        let mask = self.channels.bits()
            | if self.second_part {
                MASK_SECOND_PART
            } else {
                0
            };
        b[field::MASK].copy_from_slice(&mask.to_be_bytes());
        for slot in 0..MAX_EVENTS {
            let word = match self.channels.iter().nth(slot) {
                Some(channel) => channel.encode_word(self.values[slot]).unwrap_or(0),
                None => 0,
            };
            b[field::VALUES[slot].clone()].copy_from_slice(&word.to_be_bytes());
        }
        b[field::SEQUENCE].copy_from_slice(&self.sequence.to_be_bytes());
    }

    /// The packet as bytes, default framing.
    pub fn to_bytes(&self) -> [u8; PACKET_LEN] {
        let mut b = [0u8; PACKET_LEN];
        self.emit(&mut b);
        b
    }
}

impl fmt::Display for EventRepr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "event cell {:5} seq {:5}{}:",
            self.cell_id,
            self.sequence,
            if self.second_part { " (2nd)" } else { "" }
        )?;
        for (i, (channel, raw)) in self.events().enumerate() {
            let sep = if i == 0 { " " } else { ", " };
            let value = channel.to_units(raw);
            let unit = channel.unit();
            let space = if unit.is_empty() { "" } else { " " };
            write!(f, "{sep}{channel} {value:.5}{space}{unit}")?;
        }
        Ok(())
    }
}
