//! The byte formats of skinbox, defined once.
//!
//! Every part of the project (gateware tests, cell models, the reference model of the box and
//! the host client) reads and writes bytes through this crate and never re-types an offset.
//!
//! Formats, in the order a cell packet travels:
//! - [`data`]: the cell's 20-byte data packet (every sample, header 0xA1);
//! - [`event`]: the cell's 20-byte event packet (send-on-delta, header 0xA2);
//! - [`cell_command`]: the box's 20-byte command packet down a bus to the cells (header 0xA5);
//! - [`datagram`]: the box's UDP payload: a 24-byte header, then 26-byte [`record`]s or a
//!   [`status`] body with per-port counters, and optionally the [`box_counters`] block;
//! - [`command`]: commands to the box (kind 3) and its acknowledgements (kind 4);
//! - [`wire`]: the Ethernet II, ARP, IPv4, ICMP echo and UDP headers around them, and the
//!   Internet checksum;
//! - [`pcap`]: Ethernet frames in a pcap capture file.
//!
//! Each format follows one contract, after smoltcp's `wire` module:
//! - `Packet<T: AsRef<[u8]>>` is a zero-copy view; field offsets live once in a private
//!   `field` module and the published `LAYOUT` table (checked against `docs/wire-format.md`).
//! - `Packet::new_checked` validates untrusted bytes (length, fixed bytes, reserved bits);
//!   after it, getters and `Repr::parse` never panic.
//! - `Repr` holds only the meaningful fields; `Repr::emit` never panics into a buffer of at
//!   least `Repr::buffer_len()` bytes and derives every length and count itself.
//! - Errors say which format, which field and what was found ([`Error`]).
//!
//! All multi-byte fields are big-endian.

pub mod box_counters;
pub mod cell;
pub mod cell_command;
pub mod channel;
pub mod command;
pub mod data;
pub mod datagram;
mod error;
pub mod event;
pub mod link;
pub mod pcap;
pub mod record;
pub mod status;
pub mod wire;

pub use box_counters::{BoxCounter, BoxCounters};
pub use cell::{CellFraming, CellRepr};
pub use cell_command::{CellCommand, CellCommandRepr, CellMode, SampleRate};
pub use channel::{Channel, ChannelMask, Modality};
pub use command::{AckRepr, AckResult, CommandRepr, Request};
pub use data::DataRepr;
pub use datagram::{DatagramKind, DatagramRepr};
pub use error::{Error, Format, Result};
pub use event::EventRepr;
pub use link::LinkConfig;
pub use record::RecordRepr;
pub use status::{PortCounter, PortCounters, StatusRepr};

/// A byte range inside a format, as used by the `field` modules and `LAYOUT` tables.
pub type Field = core::ops::Range<usize>;

/// One row of a format's published layout: field name and byte range.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LayoutRow {
    /// Field name as written in `docs/wire-format.md`.
    pub name: &'static str,
    /// Byte range of the field within its format.
    pub bytes: Field,
}

/// Duration of one box tick: the box counts its 125 MHz clock, so this is also its clock
/// period.
pub const TICK_NS: u64 = 8;

/// Box ticks per second.
pub const TICKS_PER_SECOND: u64 = 1_000_000_000 / TICK_NS;

#[inline]
pub(crate) fn check_len(format: Format, buffer: &[u8], required: usize) -> Result<()> {
    if buffer.len() < required {
        Err(Error::Truncated {
            format,
            required,
            actual: buffer.len(),
        })
    } else {
        Ok(())
    }
}

#[inline]
pub(crate) fn get_u16(b: &[u8], at: Field) -> u16 {
    u16::from_be_bytes([b[at.start], b[at.start + 1]])
}

#[inline]
pub(crate) fn get_u32(b: &[u8], at: Field) -> u32 {
    let mut w = [0u8; 4];
    w.copy_from_slice(&b[at]);
    u32::from_be_bytes(w)
}

#[inline]
pub(crate) fn get_u64(b: &[u8], at: Field) -> u64 {
    let mut w = [0u8; 8];
    w.copy_from_slice(&b[at]);
    u64::from_be_bytes(w)
}
