//! The body of a status datagram: the box's counters, so the host sees every drop and reset.
//!
//! The box sends one status report every status period; with more ports than fit one
//! datagram, the report spans several datagrams, each naming its first port. The header's
//! base tick is the box time of the report and its entry count is the number of port
//! counter blocks that follow.
//!
//! | bytes | field |
//! |---|---|
//! | 0-3 | boot id: changes at every box reset |
//! | 4-7 | records datagrams sent since reset (u32, wraps) |
//! | 8-11 | records sent since reset (u32, wraps) |
//! | 12 | first port of the counter blocks below |
//! | 13-15 | reserved, 0 |
//! | 16.. | one 32-byte [`PortCounters`] block per port |
//!
//! Counters are u32 and wrap: compare successive reports modulo 2^32.

use crate::{check_len, get_u32, Format, LayoutRow, Result};
use core::fmt;

pub(crate) mod field {
    use crate::Field;
    pub const BOOT_ID: Field = 0..4;
    pub const DATAGRAMS_SENT: Field = 4..8;
    pub const RECORDS_SENT: Field = 8..12;
    pub const FIRST_PORT: usize = 12;
    pub const RESERVED: Field = 13..16;
}

/// Length of the fixed part of a status body.
pub const STATUS_FIXED_LEN: usize = field::RESERVED.end;
/// Length of one port's counter block.
pub const PORT_COUNTERS_LEN: usize = PortCounter::ALL.len() * 4;

/// Published layout of the fixed part of a status body.
pub fn layout() -> Vec<LayoutRow> {
    vec![
        LayoutRow {
            name: "boot_id",
            bytes: field::BOOT_ID,
        },
        LayoutRow {
            name: "datagrams_sent",
            bytes: field::DATAGRAMS_SENT,
        },
        LayoutRow {
            name: "records_sent",
            bytes: field::RECORDS_SENT,
        },
        LayoutRow {
            name: "first_port",
            bytes: field::FIRST_PORT..field::FIRST_PORT + 1,
        },
        LayoutRow {
            name: "reserved",
            bytes: field::RESERVED,
        },
    ]
}

/// Published layout of one port counter block.
pub fn port_counters_layout() -> Vec<LayoutRow> {
    PortCounter::ALL
        .iter()
        .map(|c| LayoutRow {
            name: c.name(),
            bytes: c.index() * 4..c.index() * 4 + 4,
        })
        .collect()
}

/// The per-port counters, in wire order.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PortCounter {
    /// Packets the deframer accepted (header, length and end byte right).
    PacketsGood,
    /// Good packets dropped whole because both packet slots of the port were full.
    DroppedOverflow,
    /// Packets rejected: the 20th byte was not the end-of-packet value.
    RejectedEndByte,
    /// Packets rejected: a byte inside had a UART framing error.
    RejectedFraming,
    /// Packets rejected: the line went idle before the 20th byte.
    RejectedTruncated,
    /// Bytes discarded while hunting for a header.
    GarbageBytes,
    /// UART framing errors (stop bit low), wherever they fell.
    FramingErrors,
    /// Times the deframer lost alignment and went back to hunting for a header.
    Resyncs,
}

impl PortCounter {
    /// All counters in wire order.
    pub const ALL: [PortCounter; 8] = [
        PortCounter::PacketsGood,
        PortCounter::DroppedOverflow,
        PortCounter::RejectedEndByte,
        PortCounter::RejectedFraming,
        PortCounter::RejectedTruncated,
        PortCounter::GarbageBytes,
        PortCounter::FramingErrors,
        PortCounter::Resyncs,
    ];

    /// Position in the counter block.
    pub fn index(self) -> usize {
        self as usize
    }

    /// Lowercase identifier.
    pub fn name(self) -> &'static str {
        match self {
            PortCounter::PacketsGood => "packets_good",
            PortCounter::DroppedOverflow => "dropped_overflow",
            PortCounter::RejectedEndByte => "rejected_end_byte",
            PortCounter::RejectedFraming => "rejected_framing",
            PortCounter::RejectedTruncated => "rejected_truncated",
            PortCounter::GarbageBytes => "garbage_bytes",
            PortCounter::FramingErrors => "framing_errors",
            PortCounter::Resyncs => "resyncs",
        }
    }

    /// Whether the counter counts lost cell packets.
    pub fn is_packet_loss(self) -> bool {
        matches!(
            self,
            PortCounter::DroppedOverflow
                | PortCounter::RejectedEndByte
                | PortCounter::RejectedFraming
                | PortCounter::RejectedTruncated
        )
    }
}

/// One port's counters.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct PortCounters(pub [u32; PortCounter::ALL.len()]);

impl PortCounters {
    /// Value of one counter.
    pub fn get(&self, counter: PortCounter) -> u32 {
        self.0[counter.index()]
    }

    /// Sets one counter.
    pub fn set(&mut self, counter: PortCounter, value: u32) {
        self.0[counter.index()] = value;
    }

    /// Parses one untrusted counter block.
    pub fn parse(bytes: &[u8]) -> Result<PortCounters> {
        check_len(Format::PortCounters, bytes, PORT_COUNTERS_LEN)?;
        Ok(PortCounters(
            PortCounter::ALL.map(|c| get_u32(bytes, c.index() * 4..c.index() * 4 + 4)),
        ))
    }

    /// Writes the block into `buffer[..32]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        for (i, v) in self.0.iter().enumerate() {
            buffer[i * 4..i * 4 + 4].copy_from_slice(&v.to_be_bytes());
        }
    }
}

/// A parsed status body.
#[derive(Debug, Clone, PartialEq, Eq, Default, serde::Serialize)]
pub struct StatusRepr {
    /// Changes at every reset of the box.
    pub boot_id: u32,
    /// Records datagrams sent since reset.
    pub datagrams_sent: u32,
    /// Records sent since reset.
    pub records_sent: u32,
    /// Port of `ports[0]`.
    pub first_port: u8,
    /// Counters of ports `first_port..first_port + ports.len()`.
    pub ports: Vec<PortCounters>,
}

impl StatusRepr {
    /// Parses an untrusted status body holding `entries` counter blocks.
    pub(crate) fn parse_body(bytes: &[u8], entries: usize) -> Result<StatusRepr> {
        check_len(Format::Status, bytes, Self::body_len(entries))?;
        let ports = (0..entries)
            .map(|i| {
                let at = STATUS_FIXED_LEN + i * PORT_COUNTERS_LEN;
                PortCounters::parse(&bytes[at..at + PORT_COUNTERS_LEN])
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(StatusRepr {
            boot_id: get_u32(bytes, field::BOOT_ID),
            datagrams_sent: get_u32(bytes, field::DATAGRAMS_SENT),
            records_sent: get_u32(bytes, field::RECORDS_SENT),
            first_port: bytes[field::FIRST_PORT],
            ports,
        })
    }

    /// Length of a body with `entries` counter blocks.
    pub const fn body_len(entries: usize) -> usize {
        STATUS_FIXED_LEN + entries * PORT_COUNTERS_LEN
    }

    /// Writes the body into `buffer[..body_len(ports.len())]`.
    pub(crate) fn emit_body(&self, buffer: &mut [u8]) {
        buffer[field::BOOT_ID].copy_from_slice(&self.boot_id.to_be_bytes());
        buffer[field::DATAGRAMS_SENT].copy_from_slice(&self.datagrams_sent.to_be_bytes());
        buffer[field::RECORDS_SENT].copy_from_slice(&self.records_sent.to_be_bytes());
        buffer[field::FIRST_PORT] = self.first_port;
        buffer[field::RESERVED].fill(0);
        for (i, p) in self.ports.iter().enumerate() {
            p.emit(&mut buffer[STATUS_FIXED_LEN + i * PORT_COUNTERS_LEN..]);
        }
    }
}

impl fmt::Display for StatusRepr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "status boot {:08x}: {} datagrams, {} records sent",
            self.boot_id, self.datagrams_sent, self.records_sent
        )?;
        for (i, p) in self.ports.iter().enumerate() {
            write!(f, "\n  port {:2}:", usize::from(self.first_port) + i)?;
            for c in PortCounter::ALL {
                write!(f, " {}={}", c.name(), p.get(c))?;
            }
        }
        Ok(())
    }
}
