//! The cell command packet: what the box sends down a bus to the cells (header 0xA5).
//!
//! | bytes | field |
//! |---|---|
//! | 0 | header 0xA5 |
//! | 1-2 | target cell id (14 bits), 0x3FFF: every cell of the bus |
//! | 3 | command: 1 mode, 2 sample rate, 3 thresholds, 4 channel enable mask, 5 time sync |
//! | 4-18 | arguments by command, unused bytes 0 |
//! | 19 | end of packet 0x55 |
//!
//! Arguments:
//! - mode: byte 4, 0 data, 1 event;
//! - sample rate: byte 4, a [`SampleRate`] code (0 62.5 Hz, 1 125, 2 250, 3 500, 4 1000);
//! - thresholds: bytes 4-11, four u16 in raw steps: acceleration, force, proximity,
//!   temperature (every channel of a modality takes its modality's threshold);
//! - channel enable mask: bytes 4-5, u16, bit 0 accel x .. bit 8 temperature 2 (as the event
//!   packet's mask), bits 9-15 zero;
//! - time sync: bytes 4-11, u64 box tick at which the packet's first start bit left the box.
//!
//! Like every cell packet it is 20 bytes on the 4 Mbit/s UART. The cells relay it from the
//! root outward and apply it at their next sample boundary. `new_checked` refuses a wrong
//! length, header, end byte or cell id, an unknown command, an undefined argument value and
//! unused bytes that are not 0; after it `CellCommandRepr::parse` never fails.

use crate::cell::{self, PACKET_LEN};
use crate::{check_len, get_u16, get_u64, ChannelMask, Error, Format, LayoutRow, Modality, Result};
use core::fmt;

mod field {
    use crate::Field;
    pub const HEADER: usize = 0;
    pub const CELL_ID: Field = 1..3;
    pub const COMMAND: usize = 3;
    pub const ARGUMENTS: Field = 4..19;
    pub const END_OF_PACKET: usize = 19;
    pub const MODE: usize = 4;
    pub const RATE: usize = 4;
    pub const THRESHOLDS: [Field; 4] = [4..6, 6..8, 8..10, 10..12];
    pub const ENABLE_MASK: Field = 4..6;
    pub const TICK: Field = 4..12;
}

/// Default header byte of a cell command packet (neither data 0xA1 nor event 0xA2).
pub const COMMAND_HEADER: u8 = 0xA5;
/// Target cell id meaning every cell of the bus.
pub const ALL_CELLS: u16 = cell::CELL_ID_BROADCAST;

/// The fixed bytes that frame a cell command packet; parameters of the box and the cells.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct CellCommandFraming {
    /// First byte.
    pub header: u8,
    /// Last byte.
    pub end_of_packet: u8,
}

impl CellCommandFraming {
    /// The cells' firmware values: 0xA5, 0x55.
    pub const DEFAULT: CellCommandFraming = CellCommandFraming {
        header: COMMAND_HEADER,
        end_of_packet: cell::END_OF_PACKET,
    };
}

impl Default for CellCommandFraming {
    fn default() -> Self {
        Self::DEFAULT
    }
}

fn row(name: &'static str, bytes: crate::Field) -> LayoutRow {
    LayoutRow { name, bytes }
}

/// Published layout of the cell command packet.
pub fn layout() -> Vec<LayoutRow> {
    vec![
        row("header", field::HEADER..field::HEADER + 1),
        row("cell_id", field::CELL_ID),
        row("command", field::COMMAND..field::COMMAND + 1),
        row("arguments", field::ARGUMENTS),
        row("end_of_packet", field::END_OF_PACKET..PACKET_LEN),
    ]
}

/// Published layout of the arguments of `code`, offsets within the packet; ends with the
/// reserved bytes up to the end-of-packet byte.
pub fn arguments_layout(code: CommandCode) -> Vec<LayoutRow> {
    let mut rows = match code {
        CommandCode::Mode => vec![row("mode", field::MODE..field::MODE + 1)],
        CommandCode::SampleRate => vec![row("rate_code", field::RATE..field::RATE + 1)],
        CommandCode::Thresholds => {
            const NAMES: [&str; 4] = [
                "threshold_acceleration",
                "threshold_force",
                "threshold_proximity",
                "threshold_temperature",
            ];
            NAMES
                .iter()
                .zip(field::THRESHOLDS)
                .map(|(name, bytes)| row(name, bytes))
                .collect()
        }
        CommandCode::EnableMask => vec![row("enable_mask", field::ENABLE_MASK)],
        CommandCode::TimeSync => vec![row("box_tick", field::TICK)],
    };
    let end = rows.last().map_or(field::ARGUMENTS.start, |r| r.bytes.end);
    rows.push(row("reserved", end..field::ARGUMENTS.end));
    rows
}

/// The command byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum CommandCode {
    /// Data or event mode.
    Mode = 1,
    /// Sample rate.
    SampleRate = 2,
    /// Send-on-delta thresholds per modality.
    Thresholds = 3,
    /// Channels enabled for events.
    EnableMask = 4,
    /// The box's tick, for the cells' sample time.
    TimeSync = 5,
}

impl CommandCode {
    /// Every command, in code order.
    pub const ALL: [CommandCode; 5] = [
        CommandCode::Mode,
        CommandCode::SampleRate,
        CommandCode::Thresholds,
        CommandCode::EnableMask,
        CommandCode::TimeSync,
    ];

    /// The command of a command byte.
    pub fn from_u8(code: u8) -> Option<CommandCode> {
        Self::ALL.into_iter().find(|c| *c as u8 == code)
    }

    /// Lowercase name, as in docs/wire-format.md.
    pub fn name(self) -> &'static str {
        match self {
            CommandCode::Mode => "mode",
            CommandCode::SampleRate => "sample_rate",
            CommandCode::Thresholds => "thresholds",
            CommandCode::EnableMask => "enable_mask",
            CommandCode::TimeSync => "time_sync",
        }
    }

    /// Last argument byte used (exclusive), within the packet.
    fn arguments_end(self) -> usize {
        match self {
            CommandCode::Mode => field::MODE + 1,
            CommandCode::SampleRate => field::RATE + 1,
            CommandCode::Thresholds => field::THRESHOLDS[3].end,
            CommandCode::EnableMask => field::ENABLE_MASK.end,
            CommandCode::TimeSync => field::TICK.end,
        }
    }
}

/// What a cell sends: every sample, or send-on-delta events.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum CellMode {
    /// One data packet (0xA1) per sample.
    Data = 0,
    /// Event packets (0xA2), send-on-delta.
    Event = 1,
}

/// The sample rates a cell runs at, as coded on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[repr(u8)]
pub enum SampleRate {
    /// 62.5 Hz (code 0).
    Hz62_5 = 0,
    /// 125 Hz (code 1).
    Hz125 = 1,
    /// 250 Hz (code 2).
    Hz250 = 2,
    /// 500 Hz (code 3).
    Hz500 = 3,
    /// 1000 Hz (code 4).
    Hz1000 = 4,
}

impl SampleRate {
    /// Every rate, in code order.
    pub const ALL: [SampleRate; 5] = [
        SampleRate::Hz62_5,
        SampleRate::Hz125,
        SampleRate::Hz250,
        SampleRate::Hz500,
        SampleRate::Hz1000,
    ];

    /// The rate of a code byte.
    pub fn from_code(code: u8) -> Option<SampleRate> {
        Self::ALL.into_iter().find(|r| *r as u8 == code)
    }

    /// The rate of a frequency in Hz, when it is one of the five.
    pub fn from_hz(hz: f64) -> Option<SampleRate> {
        Self::ALL.into_iter().find(|r| r.hz() == hz)
    }

    /// Frequency, Hz.
    pub fn hz(self) -> f64 {
        match self {
            SampleRate::Hz62_5 => 62.5,
            SampleRate::Hz125 => 125.0,
            SampleRate::Hz250 => 250.0,
            SampleRate::Hz500 => 500.0,
            SampleRate::Hz1000 => 1000.0,
        }
    }
}

impl fmt::Display for SampleRate {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} Hz", self.hz())
    }
}

/// Send-on-delta thresholds per modality in raw steps of that modality's channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub struct ModalityThresholds {
    /// Thresholds in [`Modality::ALL`] order: acceleration, force, proximity, temperature.
    pub raw: [u16; 4],
}

impl ModalityThresholds {
    /// The papers' Table I: 0.02 g, 0.001, 0.0001, 0.5 C: 5, 1, 6 and 1 raw steps.
    pub fn table_i() -> ModalityThresholds {
        ModalityThresholds {
            raw: Modality::ALL.map(|m| Self::first_channel(m).table_i_threshold_raw()),
        }
    }

    /// Thresholds from host units (g, normalised force, normalised proximity, C) rounded
    /// down to whole raw steps as [`crate::Channel::table_i_threshold_raw`] does; `None` when
    /// one is negative, not a number or above 65,535 steps.
    pub fn from_units(units: [f64; 4]) -> Option<ModalityThresholds> {
        let mut raw = [0u16; 4];
        for ((r, m), u) in raw.iter_mut().zip(Modality::ALL).zip(units) {
            let steps = (u / Self::first_channel(m).units_per_lsb() + 1e-9).floor();
            if !(0.0..=65_535.0).contains(&steps) {
                return None;
            }
            *r = steps as u16;
        }
        Some(ModalityThresholds { raw })
    }

    fn first_channel(modality: Modality) -> crate::Channel {
        crate::Channel::ALL
            .into_iter()
            .find(|c| c.modality() == modality)
            .unwrap_or(crate::Channel::AccelX)
    }

    /// The threshold of one modality, raw steps.
    pub fn of(&self, modality: Modality) -> u16 {
        let i = Modality::ALL
            .iter()
            .position(|m| *m == modality)
            .unwrap_or(0);
        self.raw[i]
    }
}

/// What a cell command asks, with its arguments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CellCommand {
    /// Switch to data or event mode.
    Mode(CellMode),
    /// Sample at this rate from the next sample on.
    SampleRate(SampleRate),
    /// New send-on-delta thresholds.
    Thresholds(ModalityThresholds),
    /// Channels enabled for events.
    EnableMask(ChannelMask),
    /// The box's tick when the packet's first start bit left the box.
    TimeSync {
        /// Box tick (8 ns).
        box_tick: u64,
    },
}

impl CellCommand {
    /// Its command byte.
    pub fn code(&self) -> CommandCode {
        match self {
            CellCommand::Mode(_) => CommandCode::Mode,
            CellCommand::SampleRate(_) => CommandCode::SampleRate,
            CellCommand::Thresholds(_) => CommandCode::Thresholds,
            CellCommand::EnableMask(_) => CommandCode::EnableMask,
            CellCommand::TimeSync { .. } => CommandCode::TimeSync,
        }
    }
}

fn bad(field: &'static str, found: u32) -> Error {
    Error::BadField {
        format: Format::CellCommandPacket,
        field,
        found,
    }
}

/// A view over a cell command packet.
#[derive(Debug, Clone)]
pub struct CellCommandPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> CellCommandPacket<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        CellCommandPacket { buffer }
    }

    /// Wraps untrusted bytes framed with the default header and end-of-packet values.
    pub fn new_checked(buffer: T) -> Result<Self> {
        Self::new_checked_with(buffer, &CellCommandFraming::DEFAULT)
    }

    /// Wraps untrusted bytes: length, header, end byte, 14-bit cell id, a known command with
    /// defined arguments and zero unused bytes.
    pub fn new_checked_with(buffer: T, framing: &CellCommandFraming) -> Result<Self> {
        let p = Self::new_unchecked(buffer);
        p.check(framing)?;
        Ok(p)
    }

    fn check(&self, framing: &CellCommandFraming) -> Result<()> {
        let b = self.buffer.as_ref();
        check_len(Format::CellCommandPacket, b, PACKET_LEN)?;
        if b.len() != PACKET_LEN {
            return Err(Error::LengthMismatch {
                format: Format::CellCommandPacket,
                required: PACKET_LEN,
                actual: b.len(),
            });
        }
        if b[field::HEADER] != framing.header {
            return Err(bad("header", u32::from(b[field::HEADER])));
        }
        if b[field::END_OF_PACKET] != framing.end_of_packet {
            return Err(Error::BadEndOfPacket {
                format: Format::CellCommandPacket,
                found: b[field::END_OF_PACKET],
                expected: framing.end_of_packet,
            });
        }
        let id = get_u16(b, field::CELL_ID);
        if id > cell::CELL_ID_MAX {
            return Err(Error::BadCellId {
                format: Format::CellCommandPacket,
                found: id,
            });
        }
        let code = CommandCode::from_u8(b[field::COMMAND])
            .ok_or_else(|| bad("command", u32::from(b[field::COMMAND])))?;
        if b[code.arguments_end()..field::ARGUMENTS.end]
            .iter()
            .any(|&x| x != 0)
        {
            return Err(bad(
                "reserved",
                u32::from(
                    b[code.arguments_end()..field::ARGUMENTS.end]
                        .iter()
                        .copied()
                        .find(|&x| x != 0)
                        .unwrap_or(0),
                ),
            ));
        }
        match code {
            CommandCode::Mode if b[field::MODE] > CellMode::Event as u8 => {
                Err(bad("mode", u32::from(b[field::MODE])))
            }
            CommandCode::SampleRate if SampleRate::from_code(b[field::RATE]).is_none() => {
                Err(bad("rate_code", u32::from(b[field::RATE])))
            }
            CommandCode::EnableMask => {
                let mask = get_u16(b, field::ENABLE_MASK);
                match ChannelMask::from_bits(mask) {
                    Some(_) => Ok(()),
                    None => Err(bad("enable_mask", u32::from(mask))),
                }
            }
            _ => Ok(()),
        }
    }

    /// Target cell id ([`ALL_CELLS`] for every cell).
    pub fn cell_id(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::CELL_ID)
    }

    /// The command byte.
    pub fn command_byte(&self) -> u8 {
        self.buffer.as_ref()[field::COMMAND]
    }
}

/// One cell command: whom it addresses and what it asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
pub struct CellCommandRepr {
    /// Target cell (14 bits), or [`ALL_CELLS`].
    pub cell_id: u16,
    /// The command.
    pub command: CellCommand,
}

impl CellCommandRepr {
    /// Whether the cell `cell_id` obeys this command.
    pub fn addresses(&self, cell_id: u16) -> bool {
        self.cell_id == ALL_CELLS || self.cell_id == cell_id
    }

    /// Parses untrusted bytes framed with the default values.
    pub fn parse(bytes: &[u8]) -> Result<CellCommandRepr> {
        Self::parse_with(bytes, &CellCommandFraming::DEFAULT)
    }

    /// Parses untrusted bytes: checked as [`CellCommandPacket::new_checked_with`] does, then
    /// every field read once.
    pub fn parse_with(bytes: &[u8], framing: &CellCommandFraming) -> Result<CellCommandRepr> {
        let p = CellCommandPacket::new_checked_with(bytes, framing)?;
        let b = bytes;
        let command = match CommandCode::from_u8(p.command_byte()) {
            Some(CommandCode::Mode) => CellCommand::Mode(if b[field::MODE] == 0 {
                CellMode::Data
            } else {
                CellMode::Event
            }),
            Some(CommandCode::SampleRate) => CellCommand::SampleRate(
                SampleRate::from_code(b[field::RATE])
                    .ok_or_else(|| bad("rate_code", u32::from(b[field::RATE])))?,
            ),
            Some(CommandCode::Thresholds) => CellCommand::Thresholds(ModalityThresholds {
                raw: field::THRESHOLDS.map(|at| get_u16(b, at)),
            }),
            Some(CommandCode::EnableMask) => {
                let mask = get_u16(b, field::ENABLE_MASK);
                CellCommand::EnableMask(
                    ChannelMask::from_bits(mask).ok_or_else(|| bad("enable_mask", mask.into()))?,
                )
            }
            Some(CommandCode::TimeSync) => CellCommand::TimeSync {
                box_tick: get_u64(b, field::TICK),
            },
            None => return Err(bad("command", u32::from(p.command_byte()))),
        };
        Ok(CellCommandRepr {
            cell_id: p.cell_id(),
            command,
        })
    }

    /// Bytes [`CellCommandRepr::emit`] writes.
    pub const fn buffer_len(&self) -> usize {
        PACKET_LEN
    }

    /// Writes the packet with the default framing into `buffer[..20]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        self.emit_with(buffer, &CellCommandFraming::DEFAULT)
    }

    /// Writes the packet into `buffer[..20]`; the cell id is cut to 14 bits.
    pub fn emit_with(&self, buffer: &mut [u8], framing: &CellCommandFraming) {
        let b = &mut buffer[..PACKET_LEN];
        b.fill(0);
        b[field::HEADER] = framing.header;
        b[field::CELL_ID].copy_from_slice(&(self.cell_id & cell::CELL_ID_MAX).to_be_bytes());
        b[field::COMMAND] = self.command.code() as u8;
        match self.command {
            CellCommand::Mode(m) => b[field::MODE] = m as u8,
            CellCommand::SampleRate(r) => b[field::RATE] = r as u8,
            CellCommand::Thresholds(t) => {
                for (at, v) in field::THRESHOLDS.into_iter().zip(t.raw) {
                    b[at].copy_from_slice(&v.to_be_bytes());
                }
            }
            CellCommand::EnableMask(m) => {
                b[field::ENABLE_MASK].copy_from_slice(&m.bits().to_be_bytes())
            }
            CellCommand::TimeSync { box_tick } => {
                b[field::TICK].copy_from_slice(&box_tick.to_be_bytes())
            }
        }
        b[field::END_OF_PACKET] = framing.end_of_packet;
    }

    /// The packet as bytes, default framing.
    pub fn to_bytes(&self) -> [u8; PACKET_LEN] {
        let mut b = [0u8; PACKET_LEN];
        self.emit(&mut b);
        b
    }
}

impl fmt::Display for CellCommandRepr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.cell_id == ALL_CELLS {
            f.write_str("cell command to all cells: ")?;
        } else {
            write!(f, "cell command to cell {}: ", self.cell_id)?;
        }
        match self.command {
            CellCommand::Mode(CellMode::Data) => f.write_str("data mode"),
            CellCommand::Mode(CellMode::Event) => f.write_str("event mode"),
            CellCommand::SampleRate(r) => write!(f, "sample rate {r}"),
            CellCommand::Thresholds(t) => write!(
                f,
                "thresholds acceleration {}, force {}, proximity {}, temperature {} raw steps",
                t.raw[0], t.raw[1], t.raw[2], t.raw[3]
            ),
            CellCommand::EnableMask(m) => write!(f, "enable mask 0x{:03X}", m.bits()),
            CellCommand::TimeSync { box_tick } => write!(f, "time sync at box tick {box_tick}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Channel;

    /// Written by hand from docs/wire-format.md.
    const RATE_250_TO_CELL_7: [u8; 20] = [
        0xA5, 0x00, 0x07, 0x02, 0x02, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x55,
    ];
    const THRESHOLDS_TO_ALL: [u8; 20] = [
        0xA5, 0x3F, 0xFF, 0x03, 0x00, 0x05, 0x00, 0x01, 0x00, 0x06, 0x01, 0x02, 0, 0, 0, 0, 0, 0,
        0, 0x55,
    ];
    const TIME_SYNC: [u8; 20] = [
        0xA5, 0x3F, 0xFF, 0x05, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0, 0, 0, 0, 0, 0,
        0, 0x55,
    ];

    #[test]
    fn golden_packets_parse_and_emit_into_a_poisoned_buffer() {
        let cases = [
            (
                RATE_250_TO_CELL_7,
                CellCommandRepr {
                    cell_id: 7,
                    command: CellCommand::SampleRate(SampleRate::Hz250),
                },
            ),
            (
                THRESHOLDS_TO_ALL,
                CellCommandRepr {
                    cell_id: ALL_CELLS,
                    command: CellCommand::Thresholds(ModalityThresholds {
                        raw: [5, 1, 6, 0x0102],
                    }),
                },
            ),
            (
                TIME_SYNC,
                CellCommandRepr {
                    cell_id: ALL_CELLS,
                    command: CellCommand::TimeSync {
                        box_tick: 0x0102_0304_0506_0708,
                    },
                },
            ),
        ];
        for (bytes, repr) in cases {
            assert_eq!(CellCommandRepr::parse(&bytes), Ok(repr));
            let mut out = vec![0xa5; repr.buffer_len()];
            repr.emit(&mut out);
            assert_eq!(out, bytes);
        }
        let p = CellCommandPacket::new_checked(&RATE_250_TO_CELL_7[..]).unwrap();
        assert_eq!((p.cell_id(), p.command_byte()), (7, 2));
    }

    #[test]
    fn every_command_and_value_round_trips() {
        let mut commands = vec![
            CellCommand::Mode(CellMode::Data),
            CellCommand::Mode(CellMode::Event),
            CellCommand::EnableMask(ChannelMask::EMPTY),
            CellCommand::EnableMask(ChannelMask::ALL),
            CellCommand::EnableMask([Channel::Proximity].into_iter().collect()),
            CellCommand::TimeSync { box_tick: u64::MAX },
            CellCommand::Thresholds(ModalityThresholds {
                raw: [u16::MAX, 0, 1, 2],
            }),
        ];
        commands.extend(SampleRate::ALL.map(CellCommand::SampleRate));
        for command in commands {
            for cell_id in [1, 42, 16_382, ALL_CELLS] {
                let repr = CellCommandRepr { cell_id, command };
                assert_eq!(CellCommandRepr::parse(&repr.to_bytes()), Ok(repr));
            }
        }
        assert_eq!(SampleRate::from_hz(62.5), Some(SampleRate::Hz62_5));
        assert_eq!(SampleRate::from_hz(100.0), None);
        assert_eq!(ModalityThresholds::table_i().raw, [5, 1, 6, 1]);
        assert_eq!(
            ModalityThresholds::from_units([0.02, 0.001, 0.0001, 0.5]),
            Some(ModalityThresholds::table_i())
        );
        assert_eq!(ModalityThresholds::from_units([-0.1, 0.0, 0.0, 0.0]), None);
    }

    fn with(mut bytes: [u8; 20], at: usize, value: u8) -> [u8; 20] {
        bytes[at] = value;
        bytes
    }

    #[test]
    fn malformed_packets_are_refused_with_the_field_named() {
        let good = RATE_250_TO_CELL_7;
        let field_of = |b: &[u8]| match CellCommandRepr::parse(b) {
            Err(Error::BadField { field, found, .. }) => (field, found),
            other => panic!("expected a bad field, got {other:?}"),
        };
        assert_eq!(field_of(&with(good, 0, 0xA1)), ("header", 0xA1));
        assert_eq!(field_of(&with(good, 3, 0)), ("command", 0));
        assert_eq!(field_of(&with(good, 3, 6)), ("command", 6));
        assert_eq!(field_of(&with(good, 4, 5)), ("rate_code", 5));
        assert_eq!(field_of(&with(good, 18, 1)), ("reserved", 1));
        // The rate argument is one byte: byte 5 is reserved for this command.
        assert_eq!(field_of(&with(good, 5, 9)), ("reserved", 9));
        let mode = CellCommandRepr {
            cell_id: 1,
            command: CellCommand::Mode(CellMode::Event),
        }
        .to_bytes();
        assert_eq!(field_of(&with(mode, 4, 2)), ("mode", 2));
        let mask = CellCommandRepr {
            cell_id: 1,
            command: CellCommand::EnableMask(ChannelMask::ALL),
        }
        .to_bytes();
        assert_eq!(field_of(&with(mask, 4, 0x03)), ("enable_mask", 0x3FF));
        assert_eq!(
            CellCommandRepr::parse(&with(good, 19, 0x54)),
            Err(Error::BadEndOfPacket {
                format: Format::CellCommandPacket,
                found: 0x54,
                expected: 0x55
            })
        );
        assert!(matches!(
            CellCommandRepr::parse(&with(good, 1, 0x40)),
            Err(Error::BadCellId { found: 0x4007, .. })
        ));
        assert!(matches!(
            CellCommandRepr::parse(&good[..19]),
            Err(Error::Truncated {
                required: 20,
                actual: 19,
                ..
            })
        ));
        assert!(matches!(
            CellCommandRepr::parse(&[good.as_slice(), &[0]].concat()),
            Err(Error::LengthMismatch { actual: 21, .. })
        ));
        let msg = CellCommandRepr::parse(&with(good, 3, 9))
            .unwrap_err()
            .to_string();
        assert_eq!(
            msg,
            "cell command packet: command is 9 (0x9), not a defined value"
        );
    }

    #[test]
    fn the_header_differs_from_the_uplink_packets() {
        assert_ne!(COMMAND_HEADER, cell::DATA_HEADER);
        assert_ne!(COMMAND_HEADER, cell::EVENT_HEADER);
        assert!(crate::CellRepr::parse(&RATE_250_TO_CELL_7, &Default::default()).is_err());
    }
}
