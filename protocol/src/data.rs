//! The cell data packet: one full sample of all nine channels (header 0xA1).
//!
//! | bytes | field |
//! |---|---|
//! | 0 | header 0xA1 |
//! | 1-2 | cell id |
//! | 3-8 | accel x, y, z: i16, 1/256 g |
//! | 9-14 | force 1, 2, 3: u16, 1/1024 |
//! | 15-16 | proximity: u16, 1/65536 |
//! | 17, 18 | temperature 1, 2: u8, 0.5 C |
//! | 19 | end of packet 0x55 |

use crate::cell::{self, CellFraming, CellKind, CellPacket, PACKET_LEN};
use crate::{get_u16, Channel, Error, Format, LayoutRow, Result};
use core::fmt;

mod field {
    use crate::Field;
    pub const ACCEL: [Field; 3] = [3..5, 5..7, 7..9];
    pub const FORCE: [Field; 3] = [9..11, 11..13, 13..15];
    pub const PROXIMITY: Field = 15..17;
    pub const TEMPERATURE: [usize; 2] = [17, 18];
}

/// The channels of [`DataRepr::accel`], [`DataRepr::force`] and [`DataRepr::temperature`].
const ACCEL: [Channel; 3] = [Channel::AccelX, Channel::AccelY, Channel::AccelZ];
const FORCE: [Channel; 3] = [Channel::Force1, Channel::Force2, Channel::Force3];
const TEMPERATURE: [Channel; 2] = [Channel::Temperature1, Channel::Temperature2];

/// Published layout of the data packet.
pub fn layout() -> Vec<LayoutRow> {
    let mut rows = cell::layout();
    let end = rows.pop().expect("cell layout ends with end_of_packet");
    rows.pop(); // the body is split into channels here
    for c in Channel::ALL {
        rows.push(LayoutRow {
            name: c.name(),
            bytes: channel_field(c),
        });
    }
    rows.push(end);
    rows
}

fn channel_field(c: Channel) -> crate::Field {
    match c {
        Channel::AccelX | Channel::AccelY | Channel::AccelZ => {
            field::ACCEL[c.index() - Channel::AccelX.index()].clone()
        }
        Channel::Force1 | Channel::Force2 | Channel::Force3 => {
            field::FORCE[c.index() - Channel::Force1.index()].clone()
        }
        Channel::Proximity => field::PROXIMITY,
        Channel::Temperature1 | Channel::Temperature2 => {
            let at = field::TEMPERATURE[c.index() - Channel::Temperature1.index()];
            at..at + 1
        }
    }
}

/// Checks the frame of a data packet: length, data header, end-of-packet byte, cell id.
fn check_frame(b: &[u8], framing: &CellFraming) -> Result<()> {
    match CellPacket::new_unchecked(b).check(Format::DataPacket, framing)? {
        CellKind::Data => Ok(()),
        CellKind::Event => Err(Error::BadHeader {
            format: Format::DataPacket,
            found: framing.event_header,
            data: framing.data_header,
            event: framing.event_header,
        }),
    }
}

/// A view over a data packet.
#[derive(Debug, Clone)]
pub struct DataPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> DataPacket<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        DataPacket { buffer }
    }

    /// Wraps untrusted bytes framed with the default header and end-of-packet values.
    pub fn new_checked(buffer: T) -> Result<Self> {
        Self::new_checked_with(buffer, &CellFraming::DEFAULT)
    }

    /// Wraps untrusted bytes: length, data header, end-of-packet byte, 14-bit cell id,
    /// accelerations in their 10-bit signed range.
    pub fn new_checked_with(buffer: T, framing: &CellFraming) -> Result<Self> {
        check_frame(buffer.as_ref(), framing)?;
        DataRepr::from_checked_frame(buffer.as_ref())?;
        Ok(DataPacket { buffer })
    }

    /// Cell id.
    pub fn cell_id(&self) -> u16 {
        get_u16(self.buffer.as_ref(), cell::field::CELL_ID)
    }

    /// Raw value of one channel.
    pub fn raw(&self, channel: Channel) -> i32 {
        let b = self.buffer.as_ref();
        let at = channel_field(channel);
        match channel {
            Channel::Temperature1 | Channel::Temperature2 => i32::from(b[at.start]),
            _ => channel.decode_word(get_u16(b, at)),
        }
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> DataPacket<T> {
    /// Sets the raw value of one channel, if it fits the field.
    pub fn set_raw(&mut self, channel: Channel, raw: i32) -> Result<()> {
        if !channel.data_range().contains(&raw) {
            return Err(Error::ValueOutOfRange {
                format: Format::DataPacket,
                channel,
                value: raw,
                min: *channel.data_range().start(),
                max: *channel.data_range().end(),
            });
        }
        let at = channel_field(channel);
        let b = self.buffer.as_mut();
        match channel {
            Channel::Temperature1 | Channel::Temperature2 => b[at.start] = raw as u8,
            _ => b[at].copy_from_slice(&(raw as u16).to_be_bytes()),
        }
        Ok(())
    }
}

/// A full sample of one cell, in raw units.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct DataRepr {
    /// Sending cell (14 bits).
    pub cell_id: u16,
    /// Acceleration x, y, z in 1/256 g.
    pub accel: [i16; 3],
    /// Force 1..3 in 1/1024 of the normalised force.
    pub force: [u16; 3],
    /// Proximity in 1/65536.
    pub proximity: u16,
    /// Temperature 1 and 2 in 0.5 C steps from 0 C.
    pub temperature: [u8; 2],
}

impl DataRepr {
    /// A sample from nine raw values in channel order; fails when one does not fit.
    pub fn from_raw(cell_id: u16, raw: [i32; Channel::COUNT]) -> Result<DataRepr> {
        let mut buf = [0u8; PACKET_LEN];
        let mut p = DataPacket::new_unchecked(&mut buf[..]);
        for c in Channel::ALL {
            p.set_raw(c, raw[c.index()])?;
        }
        let p = DataPacket::new_unchecked(&buf[..]);
        Ok(Self::from_packet(cell_id & cell::CELL_ID_MAX, &p))
    }

    fn from_packet(cell_id: u16, p: &DataPacket<&[u8]>) -> DataRepr {
        DataRepr {
            cell_id,
            accel: ACCEL.map(|c| p.raw(c) as i16),
            force: FORCE.map(|c| p.raw(c) as u16),
            proximity: p.raw(Channel::Proximity) as u16,
            temperature: TEMPERATURE.map(|c| p.raw(c) as u8),
        }
    }

    /// Raw value of one channel.
    pub fn raw(&self, channel: Channel) -> i32 {
        match channel {
            Channel::AccelX | Channel::AccelY | Channel::AccelZ => {
                i32::from(self.accel[channel.index() - Channel::AccelX.index()])
            }
            Channel::Force1 | Channel::Force2 | Channel::Force3 => {
                i32::from(self.force[channel.index() - Channel::Force1.index()])
            }
            Channel::Proximity => i32::from(self.proximity),
            Channel::Temperature1 | Channel::Temperature2 => {
                i32::from(self.temperature[channel.index() - Channel::Temperature1.index()])
            }
        }
    }

    /// All nine raw values in channel order.
    pub fn raw_values(&self) -> [i32; Channel::COUNT] {
        Channel::ALL.map(|c| self.raw(c))
    }

    /// Parses untrusted bytes framed with the default values.
    pub fn parse(bytes: &[u8]) -> Result<DataRepr> {
        Self::parse_with(bytes, &CellFraming::DEFAULT)
    }

    /// Parses untrusted bytes: the frame checked, then every field read once.
    pub fn parse_with(bytes: &[u8], framing: &CellFraming) -> Result<DataRepr> {
        check_frame(bytes, framing)?;
        Self::from_checked_frame(bytes)
    }

    /// The body of a data packet whose 20 bytes, header, end byte and cell id were checked:
    /// every field read once, accelerations checked against their 10-bit range. The
    /// decoder's path ([`crate::CellRepr::parse`]).
    pub(crate) fn from_checked_frame(b: &[u8]) -> Result<DataRepr> {
        let accel = field::ACCEL.map(|at| get_u16(b, at) as i16);
        let range = Channel::AccelX.data_range();
        for (i, a) in accel.iter().enumerate() {
            let value = i32::from(*a);
            if !range.contains(&value) {
                return Err(Error::ValueOutOfRange {
                    format: Format::DataPacket,
                    channel: ACCEL[i],
                    value,
                    min: *range.start(),
                    max: *range.end(),
                });
            }
        }
        Ok(DataRepr {
            cell_id: get_u16(b, cell::field::CELL_ID),
            accel,
            force: field::FORCE.map(|at| get_u16(b, at)),
            proximity: get_u16(b, field::PROXIMITY),
            temperature: [b[field::TEMPERATURE[0]], b[field::TEMPERATURE[1]]],
        })
    }

    /// Bytes [`DataRepr::emit`] writes.
    pub const fn buffer_len(&self) -> usize {
        PACKET_LEN
    }

    /// Writes the packet with the default framing into `buffer[..20]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        self.emit_with(buffer, &CellFraming::DEFAULT)
    }

    /// Writes the packet into `buffer[..20]`.
    pub fn emit_with(&self, buffer: &mut [u8], framing: &CellFraming) {
        let b = &mut buffer[..PACKET_LEN];
        CellPacket::new_unchecked(&mut *b).emit_frame(framing.data_header, self.cell_id, framing);
        for (i, v) in self.accel.iter().enumerate() {
            b[field::ACCEL[i].clone()].copy_from_slice(&v.to_be_bytes());
        }
        for (i, v) in self.force.iter().enumerate() {
            b[field::FORCE[i].clone()].copy_from_slice(&v.to_be_bytes());
        }
        b[field::PROXIMITY].copy_from_slice(&self.proximity.to_be_bytes());
        for (i, v) in self.temperature.iter().enumerate() {
            b[field::TEMPERATURE[i]] = *v;
        }
    }

    /// The packet as bytes, default framing.
    pub fn to_bytes(&self) -> [u8; PACKET_LEN] {
        let mut b = [0u8; PACKET_LEN];
        self.emit(&mut b);
        b
    }
}

impl fmt::Display for DataRepr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let u = |c: Channel| c.to_units(self.raw(c));
        write!(
            f,
            "data  cell {:5}: accel ({:+.4}, {:+.4}, {:+.4}) g, force ({:.4}, {:.4}, {:.4}), \
             proximity {:.5}, temperature {:.1}/{:.1} C",
            self.cell_id,
            u(Channel::AccelX),
            u(Channel::AccelY),
            u(Channel::AccelZ),
            u(Channel::Force1),
            u(Channel::Force2),
            u(Channel::Force3),
            u(Channel::Proximity),
            u(Channel::Temperature1),
            u(Channel::Temperature2),
        )
    }
}
