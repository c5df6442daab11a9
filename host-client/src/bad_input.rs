//! Bad input, counted by reason: what was wrong, how often, and the first few messages.
//!
//! The counting key is a [`Reason`], an enum callers can match; in JSON and in text it is a
//! short stable string such as `frame: bad UDP checksum` or `record: port out of range`.

use serde::{Serialize, Serializer};
use skinbox_protocol::Error;
use std::collections::BTreeMap;
use std::fmt;

/// How many full messages [`BadInput`] keeps as examples.
pub const MAX_EXAMPLES: usize = 16;

/// What kind of format error the protocol crate found (its [`Error`] without the details).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[allow(missing_docs)] // each is its `Error` variant of the same name
pub enum FormatFault {
    Truncated,
    LengthMismatch,
    BadHeader,
    BadEndOfPacket,
    BadCellId,
    BadEventMask,
    BadMagic,
    UnsupportedVersion,
    UnknownKind,
    TooManyEntries,
    BadPort,
    ValueOutOfRange,
    BadEvents,
    BadPortCount,
    BadFlags,
    UnusedValueSet,
    BadField,
    UnknownOpcode,
    BadArgument,
    BadChecksum,
    Unsupported,
}

impl FormatFault {
    /// The kind of `error`.
    pub fn of(error: &Error) -> FormatFault {
        match error {
            Error::Truncated { .. } => FormatFault::Truncated,
            Error::LengthMismatch { .. } => FormatFault::LengthMismatch,
            Error::BadHeader { .. } => FormatFault::BadHeader,
            Error::BadEndOfPacket { .. } => FormatFault::BadEndOfPacket,
            Error::BadCellId { .. } => FormatFault::BadCellId,
            Error::BadEventMask { .. } => FormatFault::BadEventMask,
            Error::BadMagic { .. } => FormatFault::BadMagic,
            Error::UnsupportedVersion { .. } => FormatFault::UnsupportedVersion,
            Error::UnknownKind { .. } => FormatFault::UnknownKind,
            Error::TooManyEntries { .. } => FormatFault::TooManyEntries,
            Error::BadPort { .. } => FormatFault::BadPort,
            Error::ValueOutOfRange { .. } => FormatFault::ValueOutOfRange,
            Error::BadEvents { .. } => FormatFault::BadEvents,
            Error::BadPortCount { .. } => FormatFault::BadPortCount,
            Error::BadFlags { .. } => FormatFault::BadFlags,
            Error::UnusedValueSet { .. } => FormatFault::UnusedValueSet,
            Error::BadField { .. } => FormatFault::BadField,
            Error::UnknownOpcode { .. } => FormatFault::UnknownOpcode,
            Error::BadArgument { .. } => FormatFault::BadArgument,
            Error::BadChecksum { .. } => FormatFault::BadChecksum,
            Error::Unsupported { .. } => FormatFault::Unsupported,
        }
    }

    /// A short, stable name.
    pub fn name(self) -> &'static str {
        match self {
            FormatFault::Truncated => "truncated",
            FormatFault::LengthMismatch => "length mismatch",
            FormatFault::BadHeader => "bad cell packet header",
            FormatFault::BadEndOfPacket => "bad end-of-packet byte",
            FormatFault::BadCellId => "bad cell id",
            FormatFault::BadEventMask => "bad event mask",
            FormatFault::BadMagic => "bad magic",
            FormatFault::UnsupportedVersion => "unsupported version",
            FormatFault::UnknownKind => "unknown kind",
            FormatFault::TooManyEntries => "too many entries",
            FormatFault::BadPort => "port out of range",
            FormatFault::ValueOutOfRange => "value out of range",
            FormatFault::BadEvents => "bad events",
            FormatFault::BadPortCount => "port count out of range",
            FormatFault::BadFlags => "undefined flag bits",
            FormatFault::UnusedValueSet => "unused event value slot not 0",
            FormatFault::BadField => "undefined field value",
            FormatFault::UnknownOpcode => "unknown opcode",
            FormatFault::BadArgument => "bad command argument",
            FormatFault::BadChecksum => "bad checksum",
            FormatFault::Unsupported => "not supported",
        }
    }
}

/// Why a frame that carried (or may have carried) a skinbox datagram gave none (the kind
/// of a bad `frame::FrameReject`; frames of other traffic are not bad input).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum FrameFault {
    /// etherparse could not slice it.
    Malformed,
    /// Wrong IPv4 header checksum.
    BadIpv4Checksum,
    /// Wrong UDP checksum.
    BadUdpChecksum,
}

impl FrameFault {
    /// A short, stable name.
    pub fn name(self) -> &'static str {
        match self {
            FrameFault::Malformed => "malformed",
            FrameFault::BadIpv4Checksum => "bad IPv4 header checksum",
            FrameFault::BadUdpChecksum => "bad UDP checksum",
        }
    }
}

/// Why input was rejected: the counting key of [`BadInput`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Reason {
    /// A captured frame (`frame: ...`).
    Frame(FrameFault),
    /// A datagram's header or length: the whole datagram (`datagram: ...`).
    Datagram(FormatFault),
    /// A status datagram's body (`status: ...`).
    Status(FormatFault),
    /// One record: its port, flags or cell packet (`record: ...`).
    Record(FormatFault),
    /// A command datagram (kind 3): its header, arguments or cell command packet
    /// (`command: ...`).
    Command(FormatFault),
    /// An acknowledgement datagram (kind 4): its header, body or reply (`ack: ...`).
    Ack(FormatFault),
    /// A datagram of a box past `decoder::MAX_BOXES` (`datagram: too many boxes`).
    TooManyBoxes,
    /// The capture file ends inside a packet (`pcap: truncated at end of file`).
    PcapTruncated,
    /// A capture file record or block that cannot be parsed (`pcap: corrupt packet record`).
    PcapCorrupt,
    /// A pcapng interface whose link type is not read (`pcap: unsupported link type`).
    PcapLinkType,
    /// A live datagram longer than the receive slot (`live: datagram longer than the
    /// receive slot`).
    LiveTruncated,
}

impl fmt::Display for Reason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Reason::Frame(k) => write!(f, "frame: {}", k.name()),
            Reason::Datagram(k) => write!(f, "datagram: {}", k.name()),
            Reason::Status(k) => write!(f, "status: {}", k.name()),
            Reason::Record(k) => write!(f, "record: {}", k.name()),
            Reason::Command(k) => write!(f, "command: {}", k.name()),
            Reason::Ack(k) => write!(f, "ack: {}", k.name()),
            Reason::TooManyBoxes => f.write_str("datagram: too many boxes"),
            Reason::PcapTruncated => f.write_str("pcap: truncated at end of file"),
            Reason::PcapCorrupt => f.write_str("pcap: corrupt packet record"),
            Reason::PcapLinkType => f.write_str("pcap: unsupported link type"),
            Reason::LiveTruncated => f.write_str("live: datagram longer than the receive slot"),
        }
    }
}

/// In JSON a reason is its text (a map key).
impl Serialize for Reason {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

/// Rejected input, counted by reason.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct BadInput {
    /// Everything rejected.
    pub total: u64,
    /// Count per reason.
    pub by_reason: BTreeMap<Reason, u64>,
    /// The first [`MAX_EXAMPLES`] rejections with their full messages.
    pub examples: Vec<String>,
}

impl BadInput {
    /// Counts one rejection for `reason` with its full `message`.
    pub fn count(&mut self, reason: Reason, message: impl FnOnce() -> String) {
        self.total += 1;
        *self.by_reason.entry(reason).or_insert(0) += 1;
        if self.examples.len() < MAX_EXAMPLES {
            self.examples.push(message());
        }
    }

    /// Counts one format error of the protocol crate; `reason` places it (e.g.
    /// `Reason::Record`).
    pub fn count_error(&mut self, reason: fn(FormatFault) -> Reason, error: &Error) {
        let reason = reason(FormatFault::of(error));
        let layer = match reason {
            Reason::Record(_) => "record",
            Reason::Status(_) => "status",
            Reason::Command(_) => "command",
            Reason::Ack(_) => "ack",
            _ => "datagram",
        };
        self.count(reason, || format!("{layer}: {error}"));
    }

    /// Count for one reason (0 when never seen).
    pub fn get(&self, reason: Reason) -> u64 {
        self.by_reason.get(&reason).copied().unwrap_or(0)
    }

    /// Adds another tally into this one.
    pub fn merge(&mut self, other: &BadInput) {
        self.total += other.total;
        for (k, v) in &other.by_reason {
            *self.by_reason.entry(*k).or_insert(0) += v;
        }
        for e in &other.examples {
            if self.examples.len() < MAX_EXAMPLES {
                self.examples.push(e.clone());
            }
        }
    }
}

impl fmt::Display for BadInput {
    /// `N` and each reason with its count, e.g. `2 (frame: bad UDP checksum 1, ...)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.total)?;
        if !self.by_reason.is_empty() {
            let parts: Vec<String> = self
                .by_reason
                .iter()
                .map(|(r, n)| format!("{r} {n}"))
                .collect();
            write!(f, " ({})", parts.join(", "))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_print_and_serialise_as_their_text() {
        let mut b = BadInput::default();
        b.count(Reason::Frame(FrameFault::BadUdpChecksum), || "x".into());
        b.count(Reason::Record(FormatFault::BadPort), || "y".into());
        b.count(Reason::Record(FormatFault::BadPort), || "z".into());
        let json = serde_json::to_value(&b).unwrap();
        assert_eq!(json["by_reason"]["frame: bad UDP checksum"], 1);
        assert_eq!(json["by_reason"]["record: port out of range"], 2);
        assert_eq!(b.get(Reason::Record(FormatFault::BadPort)), 2);
        assert_eq!(
            b.to_string(),
            "3 (frame: bad UDP checksum 1, record: port out of range 2)"
        );
    }
}
