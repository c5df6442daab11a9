//! Commands to the box and its acknowledgements: UDP payloads of the box's own magic "SK",
//! version 1, with the kinds 3 (command, host to box) and 4 (acknowledgement, box to host).
//!
//! A command has the box datagram's 24-byte header style; its `opcode` sits where a box
//! datagram has its port count, its arguments follow the header:
//!
//! | bytes | field |
//! |---|---|
//! | 0-1 | magic "SK" |
//! | 2 | version 1 |
//! | 3 | kind 3 (command) |
//! | 4-5 | box id addressed, 0xFFFF = any box |
//! | 6 | opcode ([`Opcode`]) |
//! | 7 | flags, 0 |
//! | 8-11 | command sequence number (u32): newer than the last one the box accepted from this host |
//! | 12-19 | host time (u64, opaque to the box, echoed; the host's send time in ns) |
//! | 20-21 | argument length in bytes |
//! | 22-23 | reserved, 0 |
//! | 24.. | arguments (per opcode) |
//!
//! The box answers every command from its host subnet that has a well-formed header with
//! one acknowledgement ([`AckRepr`]): the header echoes sequence number and host time, the
//! 24-byte body says the opcode, the result ([`AckResult`]), the last sequence number the
//! box accepted from this host, and the box ticks at which the command arrived and the
//! acknowledgement left; a reply follows for stream-to (the destination now in effect) and
//! status-now (the box counter block, [`crate::box_counters`]).
//!
//! The contract is that of the other formats: `new_checked` before reading untrusted bytes,
//! `parse` never panics after it, `emit` never panics into `buffer_len()` bytes.

use crate::box_counters::{BoxCounters, BOX_COUNTERS_LEN};
use crate::cell::PACKET_LEN;
use crate::datagram::{MAGIC, VERSION};
use crate::{check_len, get_u16, get_u32, get_u64, Error, Format, LayoutRow, Result};
use core::fmt;

/// Kind byte of a command datagram.
pub const KIND_COMMAND: u8 = 3;
/// Kind byte of an acknowledgement datagram.
pub const KIND_ACK: u8 = 4;
/// Box id of a command addressed to whichever box receives it.
pub const ANY_BOX: u16 = 0xFFFF;
/// Port of a cell-network command meant for every port.
pub const ALL_PORTS: u8 = 0xFF;
/// Hosts whose last accepted sequence number the box remembers (docs/control.md).
pub const HOST_SLOTS: usize = 4;
/// Shortest status period a command may set: 1 ms (125,000 ticks), so status reports
/// never take more than a small share of the link.
pub const MIN_STATUS_PERIOD_TICKS: u32 = 125_000;
/// Shortest sync period a command may set other than 0 (off): 1 ms (125,000 ticks), so the
/// box's time syncs never take more than 5 % of a bus (a packet is 50 us).
pub const MIN_SYNC_PERIOD_TICKS: u32 = 125_000;
/// Longest flush timeout a command may set (the box compares 32-bit ticks: 2^31 - 1).
pub const MAX_FLUSH_TIMEOUT_TICKS: u32 = (1 << 31) - 1;

/// Byte positions of the command header.
pub mod field {
    use crate::Field;
    pub const MAGIC: Field = 0..2;
    pub const VERSION: usize = 2;
    pub const KIND: usize = 3;
    pub const BOX_ID: Field = 4..6;
    pub const OPCODE: usize = 6;
    pub const FLAGS: usize = 7;
    pub const SEQUENCE: Field = 8..12;
    pub const HOST_TIME: Field = 12..20;
    pub const LENGTH: Field = 20..22;
    pub const RESERVED: Field = 22..24;
}

/// Byte positions of the acknowledgement header (the command header's, with the box's
/// port count where the command has its opcode) and of its body.
pub mod ack_field {
    use crate::Field;
    pub const PORT_COUNT: usize = 6;
    pub const OPCODE: usize = 0;
    pub const RESULT: usize = 1;
    pub const RESERVED: Field = 2..4;
    pub const LAST_ACCEPTED: Field = 4..8;
    pub const RECEIVE_TICK: Field = 8..16;
    pub const SEND_TICK: Field = 16..24;
}

/// Byte positions of a stream-to destination (argument and reply).
pub mod destination_field {
    use crate::Field;
    pub const MAC: Field = 0..6;
    pub const IP: Field = 6..10;
    pub const PORT: Field = 10..12;
}

/// Byte positions of a cell-network command's arguments.
pub mod cell_command_field {
    use crate::Field;
    pub const PORT: usize = 0;
    pub const RESERVED: Field = 1..4;
    pub const PACKET: Field = 4..4 + crate::cell::PACKET_LEN;
}

/// Byte positions of the set-flush-timeout and set-status-period argument.
pub mod ticks_field {
    use crate::Field;
    pub const TICKS: Field = 0..4;
}

/// Length of the command and acknowledgement headers.
pub const HEADER_LEN: usize = field::RESERVED.end;

/// Frame position of a command's arguments (an acknowledgement's body): after the
/// Ethernet, IPv4 and UDP headers and the command header.
pub const ARGUMENTS_AT: usize = crate::link::PAYLOAD_AT + HEADER_LEN;
/// Length of the acknowledgement body before its reply.
pub const ACK_FIXED_LEN: usize = ack_field::SEND_TICK.end;
/// Length of a stream-to destination.
pub const DESTINATION_LEN: usize = destination_field::PORT.end;
/// Length of a set-flush-timeout or set-status-period argument.
pub const TICKS_LEN: usize = ticks_field::TICKS.end;
/// Length of a cell-network command's arguments.
pub const CELL_COMMAND_LEN: usize = cell_command_field::PACKET.end;
/// Longest command datagram: the header and the longest arguments.
pub const MAX_COMMAND_LEN: usize = HEADER_LEN + CELL_COMMAND_LEN;

fn one(at: usize) -> crate::Field {
    at..at + 1
}

fn row(name: &'static str, bytes: crate::Field) -> LayoutRow {
    LayoutRow { name, bytes }
}

/// Published layout of the command header.
pub fn layout() -> Vec<LayoutRow> {
    vec![
        row("magic", field::MAGIC),
        row("version", one(field::VERSION)),
        row("kind", one(field::KIND)),
        row("box_id", field::BOX_ID),
        row("opcode", one(field::OPCODE)),
        row("flags", one(field::FLAGS)),
        row("sequence", field::SEQUENCE),
        row("host_time", field::HOST_TIME),
        row("argument_length", field::LENGTH),
        row("reserved", field::RESERVED),
    ]
}

/// Published layout of the acknowledgement header.
pub fn ack_layout() -> Vec<LayoutRow> {
    vec![
        row("magic", field::MAGIC),
        row("version", one(field::VERSION)),
        row("kind", one(field::KIND)),
        row("box_id", field::BOX_ID),
        row("port_count", one(ack_field::PORT_COUNT)),
        row("flags", one(field::FLAGS)),
        row("sequence", field::SEQUENCE),
        row("host_time", field::HOST_TIME),
        row("body_length", field::LENGTH),
        row("reserved", field::RESERVED),
    ]
}

/// Published layout of the acknowledgement body before its reply.
pub fn ack_body_layout() -> Vec<LayoutRow> {
    vec![
        row("opcode", one(ack_field::OPCODE)),
        row("result", one(ack_field::RESULT)),
        row("reserved", ack_field::RESERVED),
        row("last_accepted", ack_field::LAST_ACCEPTED),
        row("receive_tick", ack_field::RECEIVE_TICK),
        row("send_tick", ack_field::SEND_TICK),
    ]
}

/// Published layout of a stream-to destination.
pub fn destination_layout() -> Vec<LayoutRow> {
    vec![
        row("mac", destination_field::MAC),
        row("ip", destination_field::IP),
        row("port", destination_field::PORT),
    ]
}

/// Published layout of a cell-network command's arguments.
pub fn cell_command_layout() -> Vec<LayoutRow> {
    vec![
        row("port", one(cell_command_field::PORT)),
        row("reserved", cell_command_field::RESERVED),
        row("cell_packet", cell_command_field::PACKET),
    ]
}

/// What a command asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Opcode {
    /// Send the box's datagrams to the command's sender, or to a given destination.
    StreamTo = 1,
    /// Set the flush timeout (u32 ticks).
    SetFlushTimeout = 2,
    /// Set the status period (u32 ticks).
    SetStatusPeriod = 3,
    /// Send a status report now; the acknowledgement carries the box counters.
    StatusNow = 4,
    /// Read the box's tick (every acknowledgement carries it; this one only that).
    ReadTick = 5,
    /// Pass a cell-network command to one port or all.
    CellCommand = 6,
    /// Set the period of the box's own time syncs to every cell (u32 ticks, 0: off).
    SetSyncPeriod = 7,
}

impl Opcode {
    /// Every opcode, in wire-value order.
    pub const ALL: [Opcode; 7] = [
        Opcode::StreamTo,
        Opcode::SetFlushTimeout,
        Opcode::SetStatusPeriod,
        Opcode::StatusNow,
        Opcode::ReadTick,
        Opcode::CellCommand,
        Opcode::SetSyncPeriod,
    ];

    /// The opcode of a wire value.
    pub fn from_byte(b: u8) -> Option<Opcode> {
        Opcode::ALL.into_iter().find(|o| *o as u8 == b)
    }

    /// Lowercase name, as in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Opcode::StreamTo => "stream_to",
            Opcode::SetFlushTimeout => "set_flush_timeout",
            Opcode::SetStatusPeriod => "set_status_period",
            Opcode::StatusNow => "status_now",
            Opcode::ReadTick => "read_tick",
            Opcode::CellCommand => "cell_command",
            Opcode::SetSyncPeriod => "set_sync_period",
        }
    }
}

/// Where the box sends its datagrams.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct Destination {
    /// Destination MAC address.
    pub mac: [u8; 6],
    /// Destination IPv4 address.
    pub ip: [u8; 4],
    /// Destination UDP port.
    pub port: u16,
}

impl Destination {
    /// Parses 12 bytes (no check: every value is a destination; the box checks range).
    pub fn parse(bytes: &[u8]) -> Result<Destination> {
        check_len(Format::Command, bytes, DESTINATION_LEN)?;
        let mut mac = [0u8; 6];
        mac.copy_from_slice(&bytes[destination_field::MAC]);
        let mut ip = [0u8; 4];
        ip.copy_from_slice(&bytes[destination_field::IP]);
        Ok(Destination {
            mac,
            ip,
            port: get_u16(bytes, destination_field::PORT),
        })
    }

    /// Writes the 12 bytes.
    pub fn emit(&self, buffer: &mut [u8]) {
        buffer[destination_field::MAC].copy_from_slice(&self.mac);
        buffer[destination_field::IP].copy_from_slice(&self.ip);
        buffer[destination_field::PORT].copy_from_slice(&self.port.to_be_bytes());
    }
}

impl fmt::Display for Destination {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [a, b, c, d] = self.ip;
        write!(f, "{a}.{b}.{c}.{d}:{} (MAC ", self.port)?;
        for (i, m) in self.mac.iter().enumerate() {
            write!(f, "{}{m:02x}", if i == 0 { "" } else { ":" })?;
        }
        f.write_str(")")
    }
}

/// A command's request: opcode and arguments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "opcode", rename_all = "snake_case")]
pub enum Request {
    /// Stream to the sender of the command (no arguments) or to the given destination
    /// (12 bytes: MAC, IPv4 address, UDP port; neither address 0 nor port 0).
    StreamTo {
        /// The destination, or none for the sender.
        to: Option<Destination>,
    },
    /// Set the flush timeout: 4 bytes, u32 ticks in 1..=2^31 - 1.
    SetFlushTimeout {
        /// New flush timeout in ticks.
        ticks: u32,
    },
    /// Set the status period: 4 bytes, u32 ticks, at least [`MIN_STATUS_PERIOD_TICKS`].
    SetStatusPeriod {
        /// New status period in ticks.
        ticks: u32,
    },
    /// Send a status report now (no arguments).
    StatusNow,
    /// Read the box's tick (no arguments).
    ReadTick,
    /// A cell-network command: 24 bytes: port (or [`ALL_PORTS`]), 3 reserved zero bytes, the
    /// 20-byte cell command packet.
    CellCommand {
        /// Port, or [`ALL_PORTS`].
        port: u8,
        /// The cell command packet, passed on unchanged (a time sync's bytes 4-11 are
        /// written by the box as it leaves).
        packet: [u8; PACKET_LEN],
    },
    /// Set the period of the box's time syncs: 4 bytes, u32 ticks, 0 (off) or at least
    /// [`MIN_SYNC_PERIOD_TICKS`].
    SetSyncPeriod {
        /// New sync period in ticks.
        ticks: u32,
    },
}

impl Request {
    /// The opcode.
    pub fn opcode(&self) -> Opcode {
        match self {
            Request::StreamTo { .. } => Opcode::StreamTo,
            Request::SetFlushTimeout { .. } => Opcode::SetFlushTimeout,
            Request::SetStatusPeriod { .. } => Opcode::SetStatusPeriod,
            Request::StatusNow => Opcode::StatusNow,
            Request::ReadTick => Opcode::ReadTick,
            Request::CellCommand { .. } => Opcode::CellCommand,
            Request::SetSyncPeriod { .. } => Opcode::SetSyncPeriod,
        }
    }

    /// Length of the arguments.
    pub fn argument_len(&self) -> usize {
        match self {
            Request::StreamTo { to: None } | Request::StatusNow | Request::ReadTick => 0,
            Request::StreamTo { to: Some(_) } => DESTINATION_LEN,
            Request::SetFlushTimeout { .. }
            | Request::SetStatusPeriod { .. }
            | Request::SetSyncPeriod { .. } => TICKS_LEN,
            Request::CellCommand { .. } => CELL_COMMAND_LEN,
        }
    }

    /// Parses the arguments of `opcode` against a box of `port_count` ports: lengths and
    /// ranges; [`Error::UnknownOpcode`] or [`Error::BadArgument`] say what is wrong.
    pub fn parse(opcode: u8, args: &[u8], port_count: u8) -> Result<Request> {
        let op = Opcode::from_byte(opcode).ok_or(Error::UnknownOpcode { found: opcode })?;
        let bad = |reason: &'static str| Error::BadArgument {
            opcode: op.name(),
            reason,
        };
        let want = |len: usize, reason: &'static str| {
            if args.len() == len {
                Ok(())
            } else {
                Err(bad(reason))
            }
        };
        match op {
            Opcode::StreamTo => match args.len() {
                0 => Ok(Request::StreamTo { to: None }),
                DESTINATION_LEN => {
                    let d = Destination::parse(args)?;
                    if d.ip == [0; 4] || d.port == 0 {
                        return Err(bad("destination IP 0.0.0.0 or port 0"));
                    }
                    Ok(Request::StreamTo { to: Some(d) })
                }
                _ => Err(bad(
                    "arguments are 0 bytes (the sender) or 12 (MAC, IP, port)",
                )),
            },
            Opcode::SetFlushTimeout => {
                want(TICKS_LEN, "arguments are 4 bytes (u32 ticks)")?;
                let ticks = get_u32(args, ticks_field::TICKS);
                if !(1..=MAX_FLUSH_TIMEOUT_TICKS).contains(&ticks) {
                    return Err(bad("flush timeout outside 1..=2^31-1 ticks"));
                }
                Ok(Request::SetFlushTimeout { ticks })
            }
            Opcode::SetStatusPeriod => {
                want(TICKS_LEN, "arguments are 4 bytes (u32 ticks)")?;
                let ticks = get_u32(args, ticks_field::TICKS);
                if ticks < MIN_STATUS_PERIOD_TICKS {
                    return Err(bad("status period below 125,000 ticks (1 ms)"));
                }
                Ok(Request::SetStatusPeriod { ticks })
            }
            Opcode::StatusNow => {
                want(0, "status-now takes no arguments")?;
                Ok(Request::StatusNow)
            }
            Opcode::ReadTick => {
                want(0, "read-tick takes no arguments")?;
                Ok(Request::ReadTick)
            }
            Opcode::CellCommand => {
                want(
                    CELL_COMMAND_LEN,
                    "arguments are 24 bytes (port, 3 reserved, cell packet)",
                )?;
                let port = args[cell_command_field::PORT];
                if port != ALL_PORTS && port >= port_count {
                    return Err(bad("port not on this box (0xFF = all ports)"));
                }
                if args[cell_command_field::RESERVED].iter().any(|&b| b != 0) {
                    return Err(bad("reserved bytes not 0"));
                }
                let mut packet = [0u8; PACKET_LEN];
                packet.copy_from_slice(&args[cell_command_field::PACKET]);
                Ok(Request::CellCommand { port, packet })
            }
            Opcode::SetSyncPeriod => {
                want(TICKS_LEN, "arguments are 4 bytes (u32 ticks)")?;
                let ticks = get_u32(args, ticks_field::TICKS);
                if ticks != 0 && ticks < MIN_SYNC_PERIOD_TICKS {
                    return Err(bad(
                        "sync period neither 0 nor at least 125,000 ticks (1 ms)",
                    ));
                }
                Ok(Request::SetSyncPeriod { ticks })
            }
        }
    }

    /// Writes the arguments into `buffer[..argument_len()]`.
    pub fn emit_arguments(&self, buffer: &mut [u8]) {
        match self {
            Request::StreamTo { to: Some(d) } => d.emit(buffer),
            Request::SetFlushTimeout { ticks }
            | Request::SetStatusPeriod { ticks }
            | Request::SetSyncPeriod { ticks } => {
                buffer[ticks_field::TICKS].copy_from_slice(&ticks.to_be_bytes())
            }
            Request::CellCommand { port, packet } => {
                buffer[cell_command_field::PORT] = *port;
                buffer[cell_command_field::RESERVED].fill(0);
                buffer[cell_command_field::PACKET].copy_from_slice(packet);
            }
            Request::StreamTo { to: None } | Request::StatusNow | Request::ReadTick => {}
        }
    }
}

/// The kind byte of a UDP payload that starts like a skinbox datagram (magic and version),
/// so a receiver can tell box datagrams, commands and acknowledgements apart.
pub fn peek_kind(bytes: &[u8]) -> Option<u8> {
    (bytes.len() >= HEADER_LEN && bytes[field::MAGIC] == MAGIC && bytes[field::VERSION] == VERSION)
        .then(|| bytes[field::KIND])
}

/// Checks the 24-byte header shared by commands and acknowledgements: magic, version,
/// kind, flags 0, reserved 0, and a total length of header plus the announced length.
fn check_header(format: Format, b: &[u8], kind: u8) -> Result<()> {
    check_len(format, b, HEADER_LEN)?;
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
    if b[field::KIND] != kind {
        return Err(Error::UnknownKind {
            found: b[field::KIND],
        });
    }
    if b[field::FLAGS] != 0 {
        return Err(Error::BadFlags {
            format,
            found: b[field::FLAGS],
            defined: 0,
        });
    }
    if b[field::RESERVED].iter().any(|&x| x != 0) {
        return Err(Error::BadField {
            format,
            field: "reserved",
            found: u32::from(get_u16(b, field::RESERVED)),
        });
    }
    let required = HEADER_LEN + usize::from(get_u16(b, field::LENGTH));
    if b.len() != required {
        return Err(Error::LengthMismatch {
            format,
            required,
            actual: b.len(),
        });
    }
    Ok(())
}

/// A view over a command datagram.
#[derive(Debug, Clone)]
pub struct Command<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Command<T> {
    /// Wraps untrusted bytes: magic, version, kind 3, flags and reserved 0, and the exact
    /// length of header plus arguments. The arguments are checked by [`Command::request`].
    pub fn new_checked(buffer: T) -> Result<Self> {
        check_header(Format::Command, buffer.as_ref(), KIND_COMMAND)?;
        Ok(Command { buffer })
    }

    /// Box id addressed.
    pub fn box_id(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::BOX_ID)
    }

    /// Opcode byte.
    pub fn opcode(&self) -> u8 {
        self.buffer.as_ref()[field::OPCODE]
    }

    /// Command sequence number.
    pub fn sequence(&self) -> u32 {
        get_u32(self.buffer.as_ref(), field::SEQUENCE)
    }

    /// Host time (echoed in the acknowledgement).
    pub fn host_time(&self) -> u64 {
        get_u64(self.buffer.as_ref(), field::HOST_TIME)
    }

    /// The argument bytes.
    pub fn arguments(&self) -> &[u8] {
        &self.buffer.as_ref()[HEADER_LEN..]
    }

    /// The request, its arguments checked against a box of `port_count` ports.
    pub fn request(&self, port_count: u8) -> Result<Request> {
        Request::parse(self.opcode(), self.arguments(), port_count)
    }
}

/// A parsed command.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct CommandRepr {
    /// Box id addressed ([`ANY_BOX`] for any).
    pub box_id: u16,
    /// Command sequence number.
    pub sequence: u32,
    /// Host time, echoed.
    pub host_time: u64,
    /// What is asked.
    pub request: Request,
}

impl CommandRepr {
    /// Parses an untrusted command for a box of `port_count` ports.
    pub fn parse(bytes: &[u8], port_count: u8) -> Result<CommandRepr> {
        let c = Command::new_checked(bytes)?;
        Ok(CommandRepr {
            box_id: c.box_id(),
            sequence: c.sequence(),
            host_time: c.host_time(),
            request: c.request(port_count)?,
        })
    }

    /// Bytes [`CommandRepr::emit`] writes.
    pub fn buffer_len(&self) -> usize {
        HEADER_LEN + self.request.argument_len()
    }

    /// Writes the command into `buffer[..buffer_len()]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        let args = self.request.argument_len();
        let b = &mut buffer[..HEADER_LEN + args];
        b[field::MAGIC].copy_from_slice(&MAGIC);
        b[field::VERSION] = VERSION;
        b[field::KIND] = KIND_COMMAND;
        b[field::BOX_ID].copy_from_slice(&self.box_id.to_be_bytes());
        b[field::OPCODE] = self.request.opcode() as u8;
        b[field::FLAGS] = 0;
        b[field::SEQUENCE].copy_from_slice(&self.sequence.to_be_bytes());
        b[field::HOST_TIME].copy_from_slice(&self.host_time.to_be_bytes());
        b[field::LENGTH].copy_from_slice(&(args as u16).to_be_bytes());
        b[field::RESERVED].fill(0);
        self.request.emit_arguments(&mut b[HEADER_LEN..]);
    }

    /// The command as bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = vec![0u8; self.buffer_len()];
        self.emit(&mut b);
        b
    }
}

/// The result of a command, in its acknowledgement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum AckResult {
    /// Carried out.
    Ok = 0,
    /// Refused: the sequence number is not newer than the last accepted from this host
    /// (the acknowledgement says which that was).
    Replay = 1,
    /// Refused: addressed to another box id.
    OtherBox = 2,
    /// Refused: opcode unknown.
    UnknownOpcode = 3,
    /// Refused: arguments of the wrong length or out of range.
    BadArgument = 4,
    /// Refused: the downlink queue of the target port (of some port, for all ports) is full,
    /// or the downlink is still queueing the previous cell command; nothing was queued.
    DownlinkFull = 5,
}

impl AckResult {
    /// Every result, in wire-value order.
    pub const ALL: [AckResult; 6] = [
        AckResult::Ok,
        AckResult::Replay,
        AckResult::OtherBox,
        AckResult::UnknownOpcode,
        AckResult::BadArgument,
        AckResult::DownlinkFull,
    ];

    /// The result of a wire value.
    pub fn from_byte(b: u8) -> Option<AckResult> {
        AckResult::ALL.into_iter().find(|r| *r as u8 == b)
    }

    /// Lowercase name, as in JSON.
    pub fn name(self) -> &'static str {
        match self {
            AckResult::Ok => "ok",
            AckResult::Replay => "replay",
            AckResult::OtherBox => "other_box",
            AckResult::UnknownOpcode => "unknown_opcode",
            AckResult::BadArgument => "bad_argument",
            AckResult::DownlinkFull => "downlink_full",
        }
    }
}

/// What follows an acknowledgement's fixed body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "reply", content = "value", rename_all = "snake_case")]
pub enum AckReply {
    /// Nothing (every result but `ok` of stream-to and status-now).
    None,
    /// Stream-to, `ok`: the destination now in effect (12 bytes).
    Destination(Destination),
    /// Status-now, `ok`: the box counters, this command counted (84 bytes).
    Counters(BoxCounters),
}

impl AckReply {
    fn len(&self) -> usize {
        match self {
            AckReply::None => 0,
            AckReply::Destination(_) => DESTINATION_LEN,
            AckReply::Counters(_) => BOX_COUNTERS_LEN,
        }
    }
}

/// A parsed acknowledgement.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct AckRepr {
    /// Box id of the box answering.
    pub box_id: u16,
    /// Ports of the box answering.
    pub port_count: u8,
    /// Sequence number of the command, echoed.
    pub sequence: u32,
    /// Host time of the command, echoed.
    pub host_time: u64,
    /// Opcode byte of the command, echoed (unknown opcodes too).
    pub opcode: u8,
    /// What the box did.
    pub result: AckResult,
    /// The last sequence number the box accepted from this host, after this command.
    pub last_accepted: u32,
    /// Box tick at which the command frame's last byte arrived.
    pub receive_tick: u64,
    /// Box tick of the acknowledgement frame's first byte.
    pub send_tick: u64,
    /// Reply of stream-to and status-now.
    pub reply: AckReply,
}

/// A view over an acknowledgement datagram.
#[derive(Debug, Clone)]
pub struct Ack<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Ack<T> {
    /// Wraps untrusted bytes: the header as for a command (kind 4), a port count of
    /// 1..=64, a known result the box can give the opcode (`unknown_opcode` exactly for
    /// unknown opcodes, unless refused earlier as `replay` or `other_box`;
    /// `downlink_full` only for a cell command), a last accepted sequence number equal to
    /// the command's for every result but `replay` and `other_box`, reserved 0, and the
    /// reply length the opcode and result call for (the reply itself is checked by
    /// [`AckRepr::parse`]).
    pub fn new_checked(buffer: T) -> Result<Self> {
        let b = buffer.as_ref();
        check_header(Format::Ack, b, KIND_ACK)?;
        check_len(Format::Ack, b, HEADER_LEN + ACK_FIXED_LEN)?;
        let port_count = b[ack_field::PORT_COUNT];
        if !(1..=crate::datagram::MAX_PORTS).contains(&port_count) {
            return Err(Error::BadPortCount {
                found: port_count,
                max: crate::datagram::MAX_PORTS,
            });
        }
        let body = &b[HEADER_LEN..];
        let result = AckResult::from_byte(body[ack_field::RESULT]).ok_or(Error::BadField {
            format: Format::Ack,
            field: "result",
            found: u32::from(body[ack_field::RESULT]),
        })?;
        if body[ack_field::RESERVED].iter().any(|&x| x != 0) {
            return Err(Error::BadField {
                format: Format::Ack,
                field: "reserved",
                found: u32::from(get_u16(body, ack_field::RESERVED)),
            });
        }
        // The result must be one the box can give the opcode: an unknown opcode is refused
        // at step 19 (or earlier, as another box's or a replay); only a cell command
        // finds the downlink full.
        let opcode = Opcode::from_byte(body[ack_field::OPCODE]);
        let possible = match (opcode, result) {
            (None, r) => matches!(
                r,
                AckResult::Replay | AckResult::OtherBox | AckResult::UnknownOpcode
            ),
            (Some(_), AckResult::UnknownOpcode) => false,
            (Some(op), AckResult::DownlinkFull) => op == Opcode::CellCommand,
            (Some(_), _) => true,
        };
        if !possible {
            return Err(Error::BadField {
                format: Format::Ack,
                field: "result",
                found: u32::from(body[ack_field::RESULT]),
            });
        }
        // Steps 19 to 22 take the command's sequence number whatever their result.
        let takes_sequence = !matches!(result, AckResult::Replay | AckResult::OtherBox);
        if takes_sequence && get_u32(body, ack_field::LAST_ACCEPTED) != get_u32(b, field::SEQUENCE)
        {
            return Err(Error::BadField {
                format: Format::Ack,
                field: "last_accepted",
                found: get_u32(body, ack_field::LAST_ACCEPTED),
            });
        }
        let expected = match (opcode, result) {
            (Some(Opcode::StreamTo), AckResult::Ok) => DESTINATION_LEN,
            (Some(Opcode::StatusNow), AckResult::Ok) => BOX_COUNTERS_LEN,
            _ => 0,
        };
        if body.len() != ACK_FIXED_LEN + expected {
            return Err(Error::LengthMismatch {
                format: Format::Ack,
                required: HEADER_LEN + ACK_FIXED_LEN + expected,
                actual: b.len(),
            });
        }
        Ok(Ack { buffer })
    }

    fn body(&self) -> &[u8] {
        &self.buffer.as_ref()[HEADER_LEN..]
    }

    /// Box id of the answering box.
    pub fn box_id(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::BOX_ID)
    }

    /// Ports of the answering box.
    pub fn port_count(&self) -> u8 {
        self.buffer.as_ref()[ack_field::PORT_COUNT]
    }

    /// The command's sequence number.
    pub fn sequence(&self) -> u32 {
        get_u32(self.buffer.as_ref(), field::SEQUENCE)
    }

    /// The command's host time.
    pub fn host_time(&self) -> u64 {
        get_u64(self.buffer.as_ref(), field::HOST_TIME)
    }

    /// The command's opcode byte.
    pub fn opcode(&self) -> u8 {
        self.body()[ack_field::OPCODE]
    }

    /// The result (valid after `new_checked`; `Ok` otherwise when unknown).
    pub fn result(&self) -> AckResult {
        AckResult::from_byte(self.body()[ack_field::RESULT]).unwrap_or(AckResult::Ok)
    }

    /// Last sequence number accepted from this host.
    pub fn last_accepted(&self) -> u32 {
        get_u32(self.body(), ack_field::LAST_ACCEPTED)
    }

    /// Box tick of the command frame's last byte.
    pub fn receive_tick(&self) -> u64 {
        get_u64(self.body(), ack_field::RECEIVE_TICK)
    }

    /// Box tick of the acknowledgement frame's first byte.
    pub fn send_tick(&self) -> u64 {
        get_u64(self.body(), ack_field::SEND_TICK)
    }

    /// The reply bytes after the fixed body (0, 12 or 84 bytes).
    pub fn reply(&self) -> &[u8] {
        &self.body()[ACK_FIXED_LEN..]
    }
}

impl AckRepr {
    /// Parses an untrusted acknowledgement: [`Ack::new_checked`], then its reply.
    pub fn parse(b: &[u8]) -> Result<AckRepr> {
        let a = Ack::new_checked(b)?;
        let rest = a.reply();
        let reply = match rest.len() {
            0 => AckReply::None,
            DESTINATION_LEN => AckReply::Destination(Destination::parse(rest)?),
            _ => AckReply::Counters(BoxCounters::parse(rest)?),
        };
        Ok(AckRepr {
            box_id: a.box_id(),
            port_count: a.port_count(),
            sequence: a.sequence(),
            host_time: a.host_time(),
            opcode: a.opcode(),
            result: a.result(),
            last_accepted: a.last_accepted(),
            receive_tick: a.receive_tick(),
            send_tick: a.send_tick(),
            reply,
        })
    }

    /// Bytes [`AckRepr::emit`] writes.
    pub fn buffer_len(&self) -> usize {
        HEADER_LEN + ACK_FIXED_LEN + self.reply.len()
    }

    /// Writes the acknowledgement into `buffer[..buffer_len()]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        let len = self.buffer_len();
        let b = &mut buffer[..len];
        b[field::MAGIC].copy_from_slice(&MAGIC);
        b[field::VERSION] = VERSION;
        b[field::KIND] = KIND_ACK;
        b[field::BOX_ID].copy_from_slice(&self.box_id.to_be_bytes());
        b[ack_field::PORT_COUNT] = self.port_count;
        b[field::FLAGS] = 0;
        b[field::SEQUENCE].copy_from_slice(&self.sequence.to_be_bytes());
        b[field::HOST_TIME].copy_from_slice(&self.host_time.to_be_bytes());
        b[field::LENGTH].copy_from_slice(&((len - HEADER_LEN) as u16).to_be_bytes());
        b[field::RESERVED].fill(0);
        let body = &mut b[HEADER_LEN..];
        body[ack_field::OPCODE] = self.opcode;
        body[ack_field::RESULT] = self.result as u8;
        body[ack_field::RESERVED].fill(0);
        body[ack_field::LAST_ACCEPTED].copy_from_slice(&self.last_accepted.to_be_bytes());
        body[ack_field::RECEIVE_TICK].copy_from_slice(&self.receive_tick.to_be_bytes());
        body[ack_field::SEND_TICK].copy_from_slice(&self.send_tick.to_be_bytes());
        match &self.reply {
            AckReply::None => {}
            AckReply::Destination(d) => d.emit(&mut body[ACK_FIXED_LEN..]),
            AckReply::Counters(c) => c.emit(&mut body[ACK_FIXED_LEN..]),
        }
    }

    /// The acknowledgement as bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = vec![0u8; self.buffer_len()];
        self.emit(&mut b);
        b
    }
}

impl fmt::Display for AckRepr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let op = Opcode::from_byte(self.opcode).map_or("unknown opcode", Opcode::name);
        write!(
            f,
            "ack box {} seq {} {}: {} (last accepted {}), received tick {}, sent tick {}",
            self.box_id,
            self.sequence,
            op,
            self.result.name(),
            self.last_accepted,
            self.receive_tick,
            self.send_tick
        )?;
        match &self.reply {
            AckReply::None => Ok(()),
            AckReply::Destination(d) => write!(f, "; streaming to {d}"),
            AckReply::Counters(c) => write!(f, "; {c}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_arguments_follow_the_three_headers_and_the_command_header() {
        // Ethernet 14, IPv4 20, UDP 8, command header 24
        assert_eq!((HEADER_LEN, ARGUMENTS_AT), (24, 66));
    }

    /// A set-flush-timeout command written byte by byte from the table above.
    const SET_FLUSH: [u8; 28] = [
        b'S', b'K', 1, 3, // magic, version, kind command
        0x00, 0x01, 2, 0, // box 1, opcode set flush timeout, flags
        0x00, 0x00, 0x01, 0x02, // sequence 258
        0, 0, 0, 0, 0, 0, 0x30, 0x39, // host time 12345
        0, 4, 0, 0, // 4 argument bytes, reserved
        0, 0, 0x04, 0xE2, // 1250 ticks
    ];

    #[test]
    fn golden_command() {
        let c = CommandRepr::parse(&SET_FLUSH, 8).unwrap();
        assert_eq!(
            c,
            CommandRepr {
                box_id: 1,
                sequence: 258,
                host_time: 12345,
                request: Request::SetFlushTimeout { ticks: 1250 },
            }
        );
        let mut out = vec![0xA5; c.buffer_len()];
        c.emit(&mut out);
        assert_eq!(out, SET_FLUSH);
        assert_eq!(peek_kind(&SET_FLUSH), Some(KIND_COMMAND));
    }

    #[test]
    fn golden_ack() {
        let ack = AckRepr {
            box_id: 1,
            port_count: 8,
            sequence: 258,
            host_time: 12345,
            opcode: Opcode::StreamTo as u8,
            result: AckResult::Ok,
            last_accepted: 258,
            receive_tick: 0x0102,
            send_tick: 0x0203,
            reply: AckReply::Destination(Destination {
                mac: [2, 0, 0, 0, 0, 9],
                ip: [127, 0, 0, 1],
                port: 0x1234,
            }),
        };
        let mut expected = vec![
            b'S', b'K', 1, 4, 0, 1, 8, 0, 0, 0, 1, 2, 0, 0, 0, 0, 0, 0, 0x30, 0x39, 0, 36, 0, 0,
        ];
        expected.extend([1, 0, 0, 0, 0, 0, 1, 2]);
        expected.extend([0, 0, 0, 0, 0, 0, 1, 2, 0, 0, 0, 0, 0, 0, 2, 3]);
        expected.extend([2, 0, 0, 0, 0, 9, 127, 0, 0, 1, 0x12, 0x34]);
        let mut out = vec![0xA5; ack.buffer_len()];
        ack.emit(&mut out);
        assert_eq!(out, expected);
        assert_eq!(AckRepr::parse(&out).unwrap(), ack);
        let view = Ack::new_checked(&out[..]).unwrap();
        assert_eq!((view.sequence(), view.receive_tick()), (258, 0x0102));

        // refused: an unknown result, a reply the result does not call for, port count 0
        let mut bad = out.clone();
        bad[HEADER_LEN + ack_field::RESULT] = 6;
        assert!(matches!(AckRepr::parse(&bad), Err(Error::BadField { .. })));
        let mut bad = out.clone();
        bad[HEADER_LEN + ack_field::RESULT] = AckResult::Replay as u8;
        assert!(matches!(
            AckRepr::parse(&bad),
            Err(Error::LengthMismatch { .. })
        ));
        let mut bad = out.clone();
        bad[ack_field::PORT_COUNT] = 0;
        assert!(matches!(
            AckRepr::parse(&bad),
            Err(Error::BadPortCount { .. })
        ));
        assert!(AckRepr::parse(&out[..out.len() - 1]).is_err());
    }

    #[test]
    fn every_request_round_trips() {
        let requests = [
            Request::StreamTo { to: None },
            Request::StreamTo {
                to: Some(Destination {
                    mac: [0xFF; 6],
                    ip: [10, 0, 0, 1],
                    port: 9,
                }),
            },
            Request::SetFlushTimeout { ticks: 1 },
            Request::SetStatusPeriod {
                ticks: MIN_STATUS_PERIOD_TICKS,
            },
            Request::StatusNow,
            Request::ReadTick,
            Request::CellCommand {
                port: ALL_PORTS,
                packet: [0x5A; PACKET_LEN],
            },
        ];
        for request in requests {
            let c = CommandRepr {
                box_id: ANY_BOX,
                sequence: u32::MAX,
                host_time: u64::MAX,
                request,
            };
            assert_eq!(CommandRepr::parse(&c.to_bytes(), 8).unwrap(), c);
        }
    }

    #[test]
    fn refuses_malformed_and_bad_arguments() {
        let mut b = SET_FLUSH.to_vec();
        b.push(0);
        assert!(matches!(
            Command::new_checked(&b[..]),
            Err(Error::LengthMismatch { .. })
        ));
        let mut b = SET_FLUSH;
        b[7] = 1;
        assert!(matches!(
            Command::new_checked(&b[..]),
            Err(Error::BadFlags { .. })
        ));
        let mut b = SET_FLUSH;
        b[6] = 99;
        assert_eq!(
            CommandRepr::parse(&b, 8),
            Err(Error::UnknownOpcode { found: 99 })
        );
        let mut b = SET_FLUSH;
        b[24..28].fill(0);
        assert!(matches!(
            CommandRepr::parse(&b, 8),
            Err(Error::BadArgument { .. })
        ));
        let cell = CommandRepr {
            box_id: 1,
            sequence: 1,
            host_time: 0,
            request: Request::CellCommand {
                port: 8,
                packet: [0; PACKET_LEN],
            },
        };
        assert!(matches!(
            CommandRepr::parse(&cell.to_bytes(), 8),
            Err(Error::BadArgument { .. })
        ));
        assert!(CommandRepr::parse(&cell.to_bytes(), 9).is_ok());
    }
}
