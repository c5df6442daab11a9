//! What every 20-byte cell packet shares: header byte, 14-bit cell id, end-of-packet byte.
//!
//! | bytes | field |
//! |---|---|
//! | 0 | header: 0xA1 data, 0xA2 event |
//! | 1-2 | cell id (14 bits, top 2 bits 0) |
//! | 3-18 | body, see [`crate::data`] and [`crate::event`] |
//! | 19 | end of packet, 0x55 |
//!
//! The header and end-of-packet values are parameters of the box ([`CellFraming`]); the
//! defaults are the cells' firmware values.

use crate::{check_len, get_u16, DataRepr, Error, EventRepr, Format, Result};
use core::fmt;

pub(crate) mod field {
    use crate::Field;
    pub const HEADER: usize = 0;
    pub const CELL_ID: Field = 1..3;
    pub const BODY: Field = 3..19;
    pub const END_OF_PACKET: usize = 19;
}

/// Length of every cell packet.
pub const PACKET_LEN: usize = field::END_OF_PACKET + 1;
/// UART bit rate of the cell buses (8N1).
pub const UART_BAUD: u64 = 4_000_000;
/// UART bits per byte on the line: start bit, 8 data bits, stop bit (8N1).
pub const UART_BITS_PER_BYTE: u64 = 10;
/// UART bits of one packet on the line.
pub const UART_BITS_PER_PACKET: u64 = PACKET_LEN as u64 * UART_BITS_PER_BYTE;
/// Default header byte of a data packet.
pub const DATA_HEADER: u8 = 0xA1;
/// Default header byte of an event packet.
pub const EVENT_HEADER: u8 = 0xA2;
/// Default end-of-packet byte.
pub const END_OF_PACKET: u8 = 0x55;
/// Largest cell id (14 bits); also the interface/broadcast id.
pub const CELL_ID_MAX: u16 = 0x3FFF;
/// Cell id meaning "no cell".
pub const CELL_ID_NONE: u16 = 0;
/// Cell id of the interface (broadcast).
pub const CELL_ID_BROADCAST: u16 = CELL_ID_MAX;

/// Published layout of the fields every cell packet shares.
pub fn layout() -> Vec<crate::LayoutRow> {
    use crate::LayoutRow as R;
    vec![
        R {
            name: "header",
            bytes: field::HEADER..field::HEADER + 1,
        },
        R {
            name: "cell_id",
            bytes: field::CELL_ID,
        },
        R {
            name: "body",
            bytes: field::BODY,
        },
        R {
            name: "end_of_packet",
            bytes: field::END_OF_PACKET..PACKET_LEN,
        },
    ]
}

/// The fixed bytes that frame a cell packet; parameters of the box.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct CellFraming {
    /// Header byte of data packets.
    pub data_header: u8,
    /// Header byte of event packets.
    pub event_header: u8,
    /// Last byte of every packet.
    pub end_of_packet: u8,
}

impl CellFraming {
    /// The cells' firmware values: 0xA1, 0xA2, 0x55.
    pub const DEFAULT: CellFraming = CellFraming {
        data_header: DATA_HEADER,
        event_header: EVENT_HEADER,
        end_of_packet: END_OF_PACKET,
    };
}

impl Default for CellFraming {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The two kinds of cell packet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CellKind {
    Data,
    Event,
}

/// A view over a cell packet of either kind.
#[derive(Debug, Clone)]
pub struct CellPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> CellPacket<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        CellPacket { buffer }
    }

    /// Wraps untrusted bytes: checks length, header, end-of-packet byte and cell id.
    pub fn new_checked(buffer: T, framing: &CellFraming) -> Result<Self> {
        let p = Self::new_unchecked(buffer);
        p.check(Format::CellPacket, framing)?;
        Ok(p)
    }

    pub(crate) fn check(&self, format: Format, framing: &CellFraming) -> Result<CellKind> {
        let b = self.buffer.as_ref();
        check_len(format, b, PACKET_LEN)?;
        let kind = if b[field::HEADER] == framing.data_header {
            CellKind::Data
        } else if b[field::HEADER] == framing.event_header {
            CellKind::Event
        } else {
            return Err(Error::BadHeader {
                format,
                found: b[field::HEADER],
                data: framing.data_header,
                event: framing.event_header,
            });
        };
        if b[field::END_OF_PACKET] != framing.end_of_packet {
            return Err(Error::BadEndOfPacket {
                format,
                found: b[field::END_OF_PACKET],
                expected: framing.end_of_packet,
            });
        }
        let id = get_u16(b, field::CELL_ID);
        if id > CELL_ID_MAX {
            return Err(Error::BadCellId { format, found: id });
        }
        Ok(kind)
    }

    /// Header byte.
    pub fn header(&self) -> u8 {
        self.buffer.as_ref()[field::HEADER]
    }

    /// Cell id field (14 bits after `new_checked`).
    pub fn cell_id(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::CELL_ID)
    }

    /// End-of-packet byte.
    pub fn end_of_packet(&self) -> u8 {
        self.buffer.as_ref()[field::END_OF_PACKET]
    }

    /// The underlying bytes.
    pub fn into_inner(self) -> T {
        self.buffer
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> CellPacket<T> {
    pub(crate) fn emit_frame(&mut self, header: u8, cell_id: u16, framing: &CellFraming) {
        let b = self.buffer.as_mut();
        b[field::HEADER] = header;
        b[field::CELL_ID].copy_from_slice(&(cell_id & CELL_ID_MAX).to_be_bytes());
        b[field::END_OF_PACKET] = framing.end_of_packet;
    }
}

/// A parsed cell packet of either kind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum CellRepr {
    Data(DataRepr),
    Event(EventRepr),
}

impl CellRepr {
    /// Parses untrusted bytes of either kind.
    #[inline]
    pub fn parse(bytes: &[u8], framing: &CellFraming) -> Result<CellRepr> {
        match CellPacket::new_unchecked(bytes).check(Format::CellPacket, framing)? {
            CellKind::Data => DataRepr::from_checked_frame(bytes).map(CellRepr::Data),
            CellKind::Event => EventRepr::from_checked_frame(bytes).map(CellRepr::Event),
        }
    }

    /// The packet's kind.
    pub fn kind(&self) -> CellKind {
        match self {
            CellRepr::Data(_) => CellKind::Data,
            CellRepr::Event(_) => CellKind::Event,
        }
    }

    /// The sending cell.
    pub fn cell_id(&self) -> u16 {
        match self {
            CellRepr::Data(d) => d.cell_id,
            CellRepr::Event(e) => e.cell_id,
        }
    }

    /// Writes the packet into the first [`PACKET_LEN`] bytes of `buffer`.
    pub fn emit(&self, buffer: &mut [u8], framing: &CellFraming) {
        match self {
            CellRepr::Data(d) => d.emit_with(buffer, framing),
            CellRepr::Event(e) => e.emit_with(buffer, framing),
        }
    }

    /// The packet as bytes.
    pub fn to_bytes(&self, framing: &CellFraming) -> [u8; PACKET_LEN] {
        let mut b = [0u8; PACKET_LEN];
        self.emit(&mut b, framing);
        b
    }
}

impl fmt::Display for CellRepr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CellRepr::Data(d) => d.fmt(f),
            CellRepr::Event(e) => e.fmt(f),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn header_selects_kind_and_unknown_header_is_named() {
        let mut b = [0u8; PACKET_LEN];
        b[0] = 0xA3;
        b[19] = 0x55;
        let err = CellRepr::parse(&b, &CellFraming::DEFAULT).unwrap_err();
        assert_eq!(
            err,
            Error::BadHeader {
                format: Format::CellPacket,
                found: 0xA3,
                data: 0xA1,
                event: 0xA2
            }
        );
        assert!(err.to_string().contains("0xA3"), "{err}");
    }

    #[test]
    fn custom_framing_is_honoured() {
        let framing = CellFraming {
            data_header: 0x11,
            event_header: 0x22,
            end_of_packet: 0x33,
        };
        let repr = CellRepr::Data(DataRepr {
            cell_id: 5,
            ..DataRepr::default()
        });
        let bytes = repr.to_bytes(&framing);
        assert_eq!((bytes[0], bytes[19]), (0x11, 0x33));
        assert_eq!(CellRepr::parse(&bytes, &framing), Ok(repr));
        assert!(CellRepr::parse(&bytes, &CellFraming::DEFAULT).is_err());
    }
}
