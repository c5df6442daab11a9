use core::fmt;

/// The formats this crate defines, named in every [`Error`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub enum Format {
    /// A 20-byte cell packet whose kind is not known yet.
    CellPacket,
    /// The cell data packet (header 0xA1).
    DataPacket,
    /// The cell event packet (header 0xA2).
    EventPacket,
    /// The cell command packet (header 0xA5, box to cells).
    CellCommandPacket,
    /// The box datagram header.
    Datagram,
    /// One record of a records datagram.
    Record,
    /// The body of a status datagram.
    Status,
    /// One port's counters inside a status datagram.
    PortCounters,
    /// A command datagram (host to box).
    Command,
    /// An acknowledgement datagram (box to host).
    Ack,
    /// The box-wide counter block.
    BoxCounters,
    /// An Ethernet II frame header.
    Ethernet,
    /// An ARP packet (IPv4 over Ethernet).
    Arp,
    /// An IPv4 packet.
    Ipv4,
    /// An ICMP echo message.
    Icmp,
    /// A UDP datagram.
    Udp,
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Format::CellPacket => "cell packet",
            Format::DataPacket => "data packet",
            Format::EventPacket => "event packet",
            Format::CellCommandPacket => "cell command packet",
            Format::Datagram => "box datagram",
            Format::Record => "record",
            Format::Status => "status datagram",
            Format::PortCounters => "port counters",
            Format::Command => "command",
            Format::Ack => "acknowledgement",
            Format::BoxCounters => "box counters",
            Format::Ethernet => "Ethernet frame",
            Format::Arp => "ARP packet",
            Format::Ipv4 => "IPv4 packet",
            Format::Icmp => "ICMP message",
            Format::Udp => "UDP datagram",
        })
    }
}

/// Why bytes were rejected, or why a value cannot be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Error {
    /// Fewer bytes than the format needs.
    #[error("{format}: truncated: needs {required} bytes, got {actual}")]
    Truncated {
        format: Format,
        required: usize,
        actual: usize,
    },
    /// The length announced by a header disagrees with the bytes present.
    #[error("{format}: length mismatch: header announces {required} bytes, got {actual}")]
    LengthMismatch {
        format: Format,
        required: usize,
        actual: usize,
    },
    /// The first byte of a cell packet is neither the data nor the event header.
    #[error("{format}: header byte 0x{found:02X} is not a known cell packet header (data 0x{data:02X}, event 0x{event:02X})")]
    BadHeader {
        format: Format,
        found: u8,
        data: u8,
        event: u8,
    },
    /// The last byte of a cell packet is not the end-of-packet value.
    #[error("{format}: end-of-packet byte 0x{found:02X}, expected 0x{expected:02X}")]
    BadEndOfPacket {
        format: Format,
        found: u8,
        expected: u8,
    },
    /// A cell id with one of the two reserved top bits set.
    #[error("{format}: cell id field 0x{found:04X} sets reserved top bits (cell ids are 14 bits)")]
    BadCellId { format: Format, found: u16 },
    /// An event mask with reserved bits, no event, or more than six events.
    #[error("event packet: mask 0x{mask:04X}: {reason}")]
    BadEventMask { mask: u16, reason: &'static str },
    /// The datagram does not start with "SK".
    #[error("box datagram: magic {:?}, expected \"SK\"", Bytes(*.found))]
    BadMagic { found: [u8; 2] },
    /// A datagram version this crate does not read.
    #[error("box datagram: version {found}, this decoder reads version {supported}")]
    UnsupportedVersion { found: u8, supported: u8 },
    /// A datagram kind that is neither records nor status.
    #[error(
        "box datagram: unknown kind {found} (1 records, 2 status; 3 and 4 are commands and acknowledgements)"
    )]
    UnknownKind { found: u8 },
    /// More entries than fit one datagram.
    #[error("{format}: {count} entries, at most {max} fit one datagram")]
    TooManyEntries {
        format: Format,
        count: usize,
        max: usize,
    },
    /// A record or counter block names a port the box does not have.
    #[error("{format}: port {port} out of range, the box has {port_count} ports")]
    BadPort {
        format: Format,
        port: usize,
        port_count: u8,
    },
    /// A channel value outside its range (acceleration: 10-bit signed) or its wire field.
    #[error("{format}: {channel} raw value {value} outside {min}..={max}")]
    ValueOutOfRange {
        format: Format,
        channel: crate::Channel,
        value: i32,
        min: i32,
        max: i32,
    },
    /// Events not in strictly increasing channel order, or too many for one packet.
    #[error("event packet: {reason}")]
    BadEvents { reason: &'static str },
    /// A datagram's port count outside 1..=64.
    #[error("box datagram: port count {found} outside 1..={max}")]
    BadPortCount { found: u8, max: u8 },
    /// Flag bits the format does not define.
    #[error("{format}: flags 0x{found:02X} set undefined bits (defined: 0x{defined:02X})")]
    BadFlags {
        format: Format,
        found: u8,
        defined: u8,
    },
    /// An event value slot past the mask's channels that is not 0.
    #[error("event packet: value_{} is 0x{word:04X}, but the mask names only {used} channels (unused value slots are 0)", .slot + 1)]
    UnusedValueSet { slot: usize, used: usize, word: u16 },
    /// A field with a value the format does not define.
    #[error("{format}: {field} is {found} (0x{found:X}), not a defined value")]
    BadField {
        format: Format,
        field: &'static str,
        found: u32,
    },
    /// A checksum field that disagrees with the bytes it covers.
    #[error("{format}: checksum 0x{found:04X}, the bytes give 0x{computed:04X}")]
    BadChecksum {
        format: Format,
        found: u16,
        computed: u16,
    },
    /// A well-formed field value the box does not accept (IPv4 options, fragments).
    #[error("{format}: {field} is {found} (0x{found:X}): {reason}")]
    Unsupported {
        format: Format,
        field: &'static str,
        found: u32,
        reason: &'static str,
    },
    /// A command opcode the box does not know.
    #[error("command: unknown opcode {found}")]
    UnknownOpcode { found: u8 },
    /// A command's arguments of the wrong length or out of range.
    #[error("command {opcode}: bad argument: {reason}")]
    BadArgument {
        opcode: &'static str,
        reason: &'static str,
    },
}

/// Result with this crate's [`Error`].
pub type Result<T> = core::result::Result<T, Error>;

struct Bytes([u8; 2]);

impl fmt::Debug for Bytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:02X} {:02X}", self.0[0], self.0[1])
    }
}
