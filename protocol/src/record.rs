//! One record of a records datagram: a cell packet as the box received it.
//!
//! | bytes | field |
//! |---|---|
//! | 0 | port (0..port count) |
//! | 1 | flags: bit 0 = packets of this port were dropped since its previous record |
//! | 2-5 | tick offset: i32, record tick = datagram base tick + offset (8 ns ticks) |
//! | 6-25 | the 20 cell packet bytes, unchanged |
//!
//! The tick is the box time of the falling edge of the packet's first start bit at the
//! box pin. The offset is signed because the packet store may forward a packet that started
//! earlier after one that started later.

use crate::cell::PACKET_LEN;
use crate::{check_len, get_u32, Error, Format, LayoutRow, Result};
use core::fmt;

/// Byte ranges and positions of the record's fields.
pub mod field {
    use crate::Field;
    pub const PORT: usize = 0;
    pub const FLAGS: usize = 1;
    pub const TICK_OFFSET: Field = 2..6;
    pub const CELL: Field = 6..6 + crate::cell::PACKET_LEN;
}

/// Length of one record.
pub const RECORD_LEN: usize = field::CELL.end;
/// Record flag: the box dropped packets of this port since its previous record.
pub const FLAG_LOSS_BEFORE: u8 = 0x01;

/// Published layout of a record.
pub fn layout() -> Vec<LayoutRow> {
    vec![
        LayoutRow {
            name: "port",
            bytes: field::PORT..field::PORT + 1,
        },
        LayoutRow {
            name: "flags",
            bytes: field::FLAGS..field::FLAGS + 1,
        },
        LayoutRow {
            name: "tick_offset",
            bytes: field::TICK_OFFSET,
        },
        LayoutRow {
            name: "cell_packet",
            bytes: field::CELL,
        },
    ]
}

/// A view over one record.
#[derive(Debug, Clone)]
pub struct Record<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Record<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        Record { buffer }
    }

    /// Wraps untrusted bytes: checks the length only (the cell packet is the cell's own).
    pub fn new_checked(buffer: T) -> Result<Self> {
        check_len(Format::Record, buffer.as_ref(), RECORD_LEN)?;
        Ok(Record { buffer })
    }

    /// The box's own fields against the datagram's `port_count`: the port below it, no
    /// flag but [`FLAG_LOSS_BEFORE`]. (The cell packet is the cell's: `CellRepr::parse`.)
    pub fn check(&self, port_count: u8) -> Result<()> {
        if self.port() >= port_count {
            return Err(Error::BadPort {
                format: Format::Record,
                port: usize::from(self.port()),
                port_count,
            });
        }
        if self.flags() & !FLAG_LOSS_BEFORE != 0 {
            return Err(Error::BadFlags {
                format: Format::Record,
                found: self.flags(),
                defined: FLAG_LOSS_BEFORE,
            });
        }
        Ok(())
    }

    /// Port the packet arrived on.
    pub fn port(&self) -> u8 {
        self.buffer.as_ref()[field::PORT]
    }

    /// Record flags.
    pub fn flags(&self) -> u8 {
        self.buffer.as_ref()[field::FLAGS]
    }

    /// Signed tick offset from the datagram's base tick.
    pub fn tick_offset(&self) -> i32 {
        get_u32(self.buffer.as_ref(), field::TICK_OFFSET) as i32
    }

    /// The 20 cell packet bytes.
    pub fn cell_packet(&self) -> &[u8] {
        &self.buffer.as_ref()[field::CELL]
    }

    /// The underlying bytes.
    pub fn into_inner(self) -> T {
        self.buffer
    }
}

/// A parsed record.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct RecordRepr {
    /// Port the packet arrived on.
    pub port: u8,
    /// Record flags ([`FLAG_LOSS_BEFORE`]).
    pub flags: u8,
    /// Signed tick offset from the datagram's base tick.
    pub tick_offset: i32,
    /// The cell packet bytes as received.
    pub cell_packet: [u8; PACKET_LEN],
}

impl RecordRepr {
    /// Parses untrusted bytes.
    pub fn parse(bytes: &[u8]) -> Result<RecordRepr> {
        let r = Record::new_checked(bytes)?;
        let mut cell_packet = [0u8; PACKET_LEN];
        cell_packet.copy_from_slice(r.cell_packet());
        Ok(RecordRepr {
            port: r.port(),
            flags: r.flags(),
            tick_offset: r.tick_offset(),
            cell_packet,
        })
    }

    /// Bytes [`RecordRepr::emit`] writes.
    pub const fn buffer_len(&self) -> usize {
        RECORD_LEN
    }

    /// Writes the record into `buffer[..26]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        let b = &mut buffer[..RECORD_LEN];
        b[field::PORT] = self.port;
        b[field::FLAGS] = self.flags;
        b[field::TICK_OFFSET].copy_from_slice(&self.tick_offset.to_be_bytes());
        b[field::CELL].copy_from_slice(&self.cell_packet);
    }

    /// Absolute tick of the record in a datagram with `base_tick`.
    pub fn tick(&self, base_tick: u64) -> u64 {
        base_tick.wrapping_add_signed(i64::from(self.tick_offset))
    }
}

impl fmt::Display for RecordRepr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "port {:2} {:+11} ticks", self.port, self.tick_offset)?;
        if self.flags & FLAG_LOSS_BEFORE != 0 {
            f.write_str(" (loss before)")?;
        }
        match crate::CellRepr::parse(&self.cell_packet, &crate::CellFraming::DEFAULT) {
            Ok(cell) => write!(f, " {cell}"),
            Err(e) => write!(f, " undecodable: {e}"),
        }
    }
}
