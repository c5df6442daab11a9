//! The box's UDP payload: a 24-byte header, then records or a status body. Version 1.
//!
//! | bytes | field |
//! |---|---|
//! | 0-1 | magic "SK" |
//! | 2 | version 1 |
//! | 3 | kind: 1 records, 2 status |
//! | 4-5 | box id |
//! | 6 | port count of the box |
//! | 7 | flags: bit 0 = records datagram sent by flush timeout (not full); bit 1 = status datagram carries the box counter block; bit 2 = status datagram of a box whose sync generator is on |
//! | 8-11 | sequence number, +1 per datagram of either kind (u32, wraps) |
//! | 12-19 | base tick (u64, 8 ns): first record's tick, or the status report's time |
//! | 20-21 | entry count: records, or port counter blocks |
//! | 22-23 | reserved, 0 |
//!
//! The payload length is exact: header plus entries, nothing after them. At most 55
//! records (1454 bytes) or 44 port counter blocks fit the 1472-byte UDP payload of a
//! 1500-byte IPv4 packet.
//!
//! A status datagram with flag bit 1 carries the 84-byte box counter block
//! ([`crate::box_counters`]) after its port counter blocks (then at most 42 of them fit);
//! without the flag it is byte for byte what it was before the block existed. Kinds 3 and 4
//! (command and acknowledgement) share magic and version but are read by
//! [`crate::command`], not here.

use crate::box_counters::{BoxCounters, BOX_COUNTERS_LEN};
use crate::record::{Record, RecordRepr, RECORD_LEN};
use crate::status::{StatusRepr, PORT_COUNTERS_LEN, STATUS_FIXED_LEN};
use crate::{check_len, get_u16, get_u32, get_u64, Error, Format, LayoutRow, Result};
use core::fmt;

/// Byte ranges and positions of the header's fields (the table above).
pub mod field {
    use crate::Field;
    pub const MAGIC: Field = 0..2;
    pub const VERSION: usize = 2;
    pub const KIND: usize = 3;
    pub const BOX_ID: Field = 4..6;
    pub const PORT_COUNT: usize = 6;
    pub const FLAGS: usize = 7;
    pub const SEQUENCE: Field = 8..12;
    pub const BASE_TICK: Field = 12..20;
    pub const ENTRY_COUNT: Field = 20..22;
    pub const RESERVED: Field = 22..24;
}

/// Datagram magic.
pub const MAGIC: [u8; 2] = *b"SK";
/// Version this crate reads and writes.
pub const VERSION: u8 = 1;
/// Length of the datagram header.
pub const HEADER_LEN: usize = field::RESERVED.end;
/// Largest UDP payload of an IPv4 packet of [`MTU`](crate::link::MTU) bytes: 1472.
pub const MAX_PAYLOAD_LEN: usize =
    crate::link::MTU - crate::link::IPV4_HEADER_LEN - crate::link::UDP_HEADER_LEN;
/// Most records in one datagram.
pub const MAX_RECORDS: usize = (MAX_PAYLOAD_LEN - HEADER_LEN) / RECORD_LEN;
/// Most port counter blocks in one status datagram.
pub const MAX_STATUS_PORTS: usize =
    (MAX_PAYLOAD_LEN - HEADER_LEN - STATUS_FIXED_LEN) / PORT_COUNTERS_LEN;
/// Most UART ports a box has (the `port_count` field is 1..=64).
pub const MAX_PORTS: u8 = 64;
/// Header flag: a records datagram sent because its oldest record waited the flush timeout.
pub const FLAG_FLUSH_TIMEOUT: u8 = 0x01;
/// Header flag of a status datagram: the box counter block follows the port counter blocks.
pub const FLAG_BOX_COUNTERS: u8 = 0x02;
/// Header flag of a status datagram: the box's sync generator is on (it sends a time-sync
/// cell command down every port each sync period, docs/time.md), so the cells sample on its
/// tick grid.
pub const FLAG_TIME_SYNCS: u8 = 0x04;
/// Most port counter blocks in a status datagram that carries the box counter block.
pub const MAX_STATUS_PORTS_WITH_BOX_COUNTERS: usize =
    (MAX_PAYLOAD_LEN - HEADER_LEN - STATUS_FIXED_LEN - BOX_COUNTERS_LEN) / PORT_COUNTERS_LEN;

/// Whether a UDP payload is a skinbox datagram of any kind (box datagram, command or
/// acknowledgement): it begins with the magic "SK". A payload that does not is someone
/// else's traffic; one that does is judged by the rules of its kind.
pub fn has_magic(bytes: &[u8]) -> bool {
    bytes.starts_with(&MAGIC)
}

/// Published layout of the datagram header.
pub fn layout() -> Vec<LayoutRow> {
    let one = |at: usize| at..at + 1;
    vec![
        LayoutRow {
            name: "magic",
            bytes: field::MAGIC,
        },
        LayoutRow {
            name: "version",
            bytes: one(field::VERSION),
        },
        LayoutRow {
            name: "kind",
            bytes: one(field::KIND),
        },
        LayoutRow {
            name: "box_id",
            bytes: field::BOX_ID,
        },
        LayoutRow {
            name: "port_count",
            bytes: one(field::PORT_COUNT),
        },
        LayoutRow {
            name: "flags",
            bytes: one(field::FLAGS),
        },
        LayoutRow {
            name: "sequence",
            bytes: field::SEQUENCE,
        },
        LayoutRow {
            name: "base_tick",
            bytes: field::BASE_TICK,
        },
        LayoutRow {
            name: "entry_count",
            bytes: field::ENTRY_COUNT,
        },
        LayoutRow {
            name: "reserved",
            bytes: field::RESERVED,
        },
    ]
}

/// What a datagram carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum DatagramKind {
    /// Cell packet records.
    Records = 1,
    /// A status report.
    Status = 2,
}

impl DatagramKind {
    /// Every kind, in wire-value order.
    pub const ALL: [DatagramKind; 2] = [DatagramKind::Records, DatagramKind::Status];

    /// Lowercase name, as in JSON (`records`, `status`).
    pub const fn name(self) -> &'static str {
        match self {
            DatagramKind::Records => "records",
            DatagramKind::Status => "status",
        }
    }

    fn from_byte(b: u8) -> Result<DatagramKind> {
        match b {
            1 => Ok(DatagramKind::Records),
            2 => Ok(DatagramKind::Status),
            found => Err(Error::UnknownKind { found }),
        }
    }

    /// Most entries one datagram of this kind holds.
    pub const fn max_entries(self) -> usize {
        match self {
            DatagramKind::Records => MAX_RECORDS,
            DatagramKind::Status => MAX_STATUS_PORTS,
        }
    }

    /// Payload length with `entries` entries.
    pub const fn payload_len(self, entries: usize) -> usize {
        HEADER_LEN
            + match self {
                DatagramKind::Records => entries * RECORD_LEN,
                DatagramKind::Status => StatusRepr::body_len(entries),
            }
    }
}

/// A view over a box datagram.
#[derive(Debug, Clone)]
pub struct Datagram<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Datagram<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        Datagram { buffer }
    }

    /// Wraps untrusted bytes: magic, version, kind, entry count, exact length, port count
    /// (1..=64), flags, and a status body's ports against the port count. Records are not
    /// looked into: a bad record rejects only itself (check each with [`Record::check`]
    /// and its cell packet with `CellRepr::parse`).
    pub fn new_checked(buffer: T) -> Result<Self> {
        let d = Datagram { buffer };
        let b = d.buffer.as_ref();
        check_len(Format::Datagram, b, HEADER_LEN)?;
        let magic = [b[0], b[1]];
        if magic != MAGIC {
            return Err(Error::BadMagic { found: magic });
        }
        if b[field::VERSION] != VERSION {
            return Err(Error::UnsupportedVersion {
                found: b[field::VERSION],
                supported: VERSION,
            });
        }
        let kind = DatagramKind::from_byte(b[field::KIND])?;
        let format = match kind {
            DatagramKind::Records => Format::Datagram,
            DatagramKind::Status => Format::Status,
        };
        let flags = d.flags();
        let defined = match kind {
            DatagramKind::Records => FLAG_FLUSH_TIMEOUT,
            DatagramKind::Status => FLAG_FLUSH_TIMEOUT | FLAG_BOX_COUNTERS | FLAG_TIME_SYNCS,
        };
        if flags & !defined != 0 {
            return Err(Error::BadFlags {
                format: Format::Datagram,
                found: flags,
                defined,
            });
        }
        let with_box_counters = kind == DatagramKind::Status && flags & FLAG_BOX_COUNTERS != 0;
        let count = d.entry_count();
        let max = if with_box_counters {
            MAX_STATUS_PORTS_WITH_BOX_COUNTERS
        } else {
            kind.max_entries()
        };
        if count > max {
            return Err(Error::TooManyEntries { format, count, max });
        }
        let required = kind.payload_len(count)
            + if with_box_counters {
                BOX_COUNTERS_LEN
            } else {
                0
            };
        check_len(format, b, required)?;
        if b.len() != required {
            return Err(Error::LengthMismatch {
                format,
                required,
                actual: b.len(),
            });
        }
        let port_count = d.port_count();
        if !(1..=MAX_PORTS).contains(&port_count) {
            return Err(Error::BadPortCount {
                found: port_count,
                max: MAX_PORTS,
            });
        }
        // A status body is one unit: a counter block of a port the box does not have
        // rejects the datagram. Records are checked one by one (`Record::check`).
        if kind == DatagramKind::Status && count > 0 {
            let first = usize::from(b[HEADER_LEN + crate::status::field::FIRST_PORT]);
            let port = first + count - 1;
            if port >= usize::from(port_count) {
                return Err(Error::BadPort {
                    format,
                    port,
                    port_count,
                });
            }
        }
        Ok(d)
    }

    /// Version byte.
    pub fn version(&self) -> u8 {
        self.buffer.as_ref()[field::VERSION]
    }

    /// Kind (valid after `new_checked`; records otherwise when unknown).
    pub fn kind(&self) -> DatagramKind {
        DatagramKind::from_byte(self.buffer.as_ref()[field::KIND]).unwrap_or(DatagramKind::Records)
    }

    /// Box id.
    pub fn box_id(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::BOX_ID)
    }

    /// Number of ports of the box.
    pub fn port_count(&self) -> u8 {
        self.buffer.as_ref()[field::PORT_COUNT]
    }

    /// Header flags.
    pub fn flags(&self) -> u8 {
        self.buffer.as_ref()[field::FLAGS]
    }

    /// Datagram sequence number.
    pub fn sequence(&self) -> u32 {
        get_u32(self.buffer.as_ref(), field::SEQUENCE)
    }

    /// Base tick.
    pub fn base_tick(&self) -> u64 {
        get_u64(self.buffer.as_ref(), field::BASE_TICK)
    }

    /// Number of records or port counter blocks.
    pub fn entry_count(&self) -> usize {
        usize::from(get_u16(self.buffer.as_ref(), field::ENTRY_COUNT))
    }

    /// The records of a records datagram (none for a status datagram), without copying.
    pub fn records(&self) -> impl Iterator<Item = Record<&[u8]>> + '_ {
        let n = match self.kind() {
            DatagramKind::Records => self.entry_count(),
            DatagramKind::Status => 0,
        };
        self.buffer.as_ref()[HEADER_LEN..]
            .chunks_exact(RECORD_LEN)
            .take(n)
            .map(Record::new_unchecked)
    }

    /// The bytes after the header.
    pub fn body(&self) -> &[u8] {
        &self.buffer.as_ref()[HEADER_LEN..]
    }

    /// The box counter block of a status datagram with [`FLAG_BOX_COUNTERS`] (valid after
    /// `new_checked`), none for every other datagram.
    pub fn box_counters(&self) -> Result<Option<BoxCounters>> {
        if self.kind() != DatagramKind::Status || self.flags() & FLAG_BOX_COUNTERS == 0 {
            return Ok(None);
        }
        let at = StatusRepr::body_len(self.entry_count());
        BoxCounters::parse(&self.body()[at..]).map(Some)
    }
}

/// What follows the header.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "kind", content = "entries", rename_all = "snake_case")]
pub enum DatagramBody {
    /// Cell packet records.
    Records(Vec<RecordRepr>),
    /// A status report.
    Status(StatusRepr),
}

/// A parsed box datagram.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize)]
pub struct DatagramRepr {
    /// Box id.
    pub box_id: u16,
    /// Number of ports of the box.
    pub port_count: u8,
    /// Header flags ([`FLAG_FLUSH_TIMEOUT`], [`FLAG_TIME_SYNCS`]); [`FLAG_BOX_COUNTERS`] is not kept here: read
    /// the block with [`DatagramRepr::parse_box_counters`], write it with
    /// [`DatagramRepr::to_bytes_with_box_counters`].
    pub flags: u8,
    /// Sequence number.
    pub sequence: u32,
    /// Base tick.
    pub base_tick: u64,
    /// Records or status.
    pub body: DatagramBody,
}

impl DatagramRepr {
    /// Parses an untrusted UDP payload: the header as [`Datagram::new_checked`] checks it,
    /// each record's port and flags ([`Record::check`]) and a status body. The cell packets
    /// are kept as bytes; parse each with `CellRepr::parse`. Unlike a decoder, which drops
    /// only a bad record, this whole-datagram parse fails on the first bad record.
    pub fn parse(bytes: &[u8]) -> Result<DatagramRepr> {
        let d = Datagram::new_checked(bytes)?;
        let body = match d.kind() {
            DatagramKind::Records => DatagramBody::Records(
                d.records()
                    .map(|r| {
                        r.check(d.port_count())?;
                        RecordRepr::parse(r.into_inner())
                    })
                    .collect::<Result<_>>()?,
            ),
            DatagramKind::Status => {
                DatagramBody::Status(StatusRepr::parse_body(d.body(), d.entry_count())?)
            }
        };
        Ok(DatagramRepr {
            box_id: d.box_id(),
            port_count: d.port_count(),
            flags: d.flags() & !FLAG_BOX_COUNTERS,
            sequence: d.sequence(),
            base_tick: d.base_tick(),
            body,
        })
    }

    /// Kind of the body.
    pub fn kind(&self) -> DatagramKind {
        match self.body {
            DatagramBody::Records(_) => DatagramKind::Records,
            DatagramBody::Status(_) => DatagramKind::Status,
        }
    }

    /// Entries [`DatagramRepr::emit`] writes: those of the body, at most
    /// [`DatagramKind::max_entries`].
    pub fn written_entries(&self) -> usize {
        let entries = match &self.body {
            DatagramBody::Records(r) => r.len(),
            DatagramBody::Status(s) => s.ports.len(),
        };
        entries.min(self.kind().max_entries())
    }

    /// Bytes [`DatagramRepr::emit`] writes: the header and the written entries.
    pub fn buffer_len(&self) -> usize {
        self.kind().payload_len(self.written_entries())
    }

    /// Writes the datagram into `buffer[..buffer_len()]`. Entries past the most one
    /// datagram holds are neither written nor counted (see [`DatagramRepr::written_entries`]),
    /// so the output parses whenever every port is below `port_count`, to this datagram
    /// without the entries left out.
    pub fn emit(&self, buffer: &mut [u8]) {
        let kind = self.kind();
        let entries = self.written_entries();
        let b = &mut buffer[..kind.payload_len(entries)];
        b[field::MAGIC].copy_from_slice(&MAGIC);
        b[field::VERSION] = VERSION;
        b[field::KIND] = kind as u8;
        b[field::BOX_ID].copy_from_slice(&self.box_id.to_be_bytes());
        b[field::PORT_COUNT] = self.port_count;
        b[field::FLAGS] = self.flags;
        b[field::SEQUENCE].copy_from_slice(&self.sequence.to_be_bytes());
        b[field::BASE_TICK].copy_from_slice(&self.base_tick.to_be_bytes());
        b[field::ENTRY_COUNT].copy_from_slice(&(entries as u16).to_be_bytes());
        b[field::RESERVED].fill(0);
        match &self.body {
            DatagramBody::Records(records) => {
                for (i, r) in records.iter().take(entries).enumerate() {
                    r.emit(&mut b[HEADER_LEN + i * RECORD_LEN..]);
                }
            }
            DatagramBody::Status(s) => {
                let clipped = StatusRepr {
                    ports: s.ports[..entries].to_vec(),
                    ..s.clone()
                };
                clipped.emit_body(&mut b[HEADER_LEN..]);
            }
        }
    }

    /// The datagram as bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = vec![0u8; self.buffer_len()];
        self.emit(&mut b);
        b
    }

    /// Parses an untrusted datagram as [`DatagramRepr::parse`] does, and the box counter
    /// block a status datagram with [`FLAG_BOX_COUNTERS`] carries.
    pub fn parse_box_counters(bytes: &[u8]) -> Result<(DatagramRepr, Option<BoxCounters>)> {
        let counters = Datagram::new_checked(bytes)?.box_counters()?;
        Ok((DatagramRepr::parse(bytes)?, counters))
    }

    /// A status datagram as bytes with `counters` after its port counter blocks (at most
    /// [`MAX_STATUS_PORTS_WITH_BOX_COUNTERS`] of them are written); a records datagram as
    /// [`DatagramRepr::to_bytes`] writes it (records carry no box counters).
    pub fn to_bytes_with_box_counters(&self, counters: &BoxCounters) -> Vec<u8> {
        let DatagramBody::Status(status) = &self.body else {
            return self.to_bytes();
        };
        let clipped = DatagramRepr {
            body: DatagramBody::Status(StatusRepr {
                ports: status
                    .ports
                    .iter()
                    .take(MAX_STATUS_PORTS_WITH_BOX_COUNTERS)
                    .copied()
                    .collect(),
                ..status.clone()
            }),
            ..self.clone()
        };
        let mut b = clipped.to_bytes();
        b[field::FLAGS] |= FLAG_BOX_COUNTERS;
        let at = b.len();
        b.resize(at + BOX_COUNTERS_LEN, 0);
        counters.emit(&mut b[at..]);
        b
    }
}

impl fmt::Display for DatagramRepr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "datagram box {} seq {} base tick {} ({:.6} s)",
            self.box_id,
            self.sequence,
            self.base_tick,
            self.base_tick as f64 / crate::TICKS_PER_SECOND as f64
        )?;
        if self.flags & FLAG_FLUSH_TIMEOUT != 0 {
            f.write_str(", flushed by timeout")?;
        }
        match &self.body {
            DatagramBody::Records(records) => {
                write!(f, ", {} records", records.len())?;
                for r in records {
                    write!(f, "\n  {r}")?;
                }
                Ok(())
            }
            DatagramBody::Status(s) => write!(f, "\n{s}"),
        }
    }
}
