//! ICMP echo request and reply (RFC 792): an 8-byte header, then data the reply returns.
//!
//! | bytes | field |
//! |---|---|
//! | 0 | type: 8 echo request, 0 echo reply |
//! | 1 | code, 0 |
//! | 2-3 | checksum over the whole message |
//! | 4-5 | identifier |
//! | 6-7 | sequence number |

use super::checksum::checksum;
use super::{one, set_u16};
use crate::{check_len, get_u16, Error, Format, LayoutRow, Result};

/// Byte ranges and positions of the header's fields.
pub mod field {
    use crate::Field;
    pub const TYPE: usize = 0;
    pub const CODE: usize = 1;
    pub const CHECKSUM: Field = 2..4;
    pub const IDENTIFIER: Field = 4..6;
    pub const SEQUENCE: Field = 6..8;
}

/// Length of the echo header.
pub const HEADER_LEN: usize = field::SEQUENCE.end;
/// ICMP type of an echo request.
pub const TYPE_ECHO_REQUEST: u8 = 8;
/// ICMP type of an echo reply.
pub const TYPE_ECHO_REPLY: u8 = 0;

/// Published layout of the echo header.
pub fn layout() -> Vec<LayoutRow> {
    let row = |name, bytes| LayoutRow { name, bytes };
    vec![
        row("type", one(field::TYPE)),
        row("code", one(field::CODE)),
        row("checksum", field::CHECKSUM),
        row("identifier", field::IDENTIFIER),
        row("sequence", field::SEQUENCE),
    ]
}

/// A view over an ICMP message (the whole IPv4 payload).
#[derive(Debug, Clone)]
pub struct IcmpPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> IcmpPacket<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        IcmpPacket { buffer }
    }

    /// Wraps untrusted bytes: at least the 8-byte header.
    pub fn new_checked(buffer: T) -> Result<Self> {
        check_len(Format::Icmp, buffer.as_ref(), HEADER_LEN)?;
        Ok(IcmpPacket { buffer })
    }

    /// Message type.
    pub fn message_type(&self) -> u8 {
        self.buffer.as_ref()[field::TYPE]
    }

    /// Message code.
    pub fn code(&self) -> u8 {
        self.buffer.as_ref()[field::CODE]
    }

    /// Checksum field.
    pub fn checksum(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::CHECKSUM)
    }

    /// Echo identifier.
    pub fn identifier(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::IDENTIFIER)
    }

    /// Echo sequence number.
    pub fn sequence(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::SEQUENCE)
    }

    /// The echo data after the header.
    pub fn data(&self) -> &[u8] {
        &self.buffer.as_ref()[HEADER_LEN..]
    }

    /// Whether the checksum over the whole message is right.
    pub fn verify_checksum(&self) -> bool {
        checksum(&[self.buffer.as_ref()]) == 0
    }
}

/// Echo request or reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum EchoMessage {
    /// Echo request (type 8).
    Request,
    /// Echo reply (type 0).
    Reply,
}

impl EchoMessage {
    /// The ICMP type.
    pub const fn message_type(self) -> u8 {
        match self {
            EchoMessage::Request => TYPE_ECHO_REQUEST,
            EchoMessage::Reply => TYPE_ECHO_REPLY,
        }
    }
}

/// A parsed ICMP echo message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct IcmpEchoRepr<'a> {
    /// Request or reply.
    pub message: EchoMessage,
    /// Identifier.
    pub identifier: u16,
    /// Sequence number.
    pub sequence: u16,
    /// The data, which a reply returns unchanged.
    pub data: &'a [u8],
}

impl<'a> IcmpEchoRepr<'a> {
    /// Parses an untrusted message (the whole IPv4 payload): at least 8 bytes, a right
    /// checksum, type 8 or 0 with code 0.
    pub fn parse(bytes: &'a [u8]) -> Result<IcmpEchoRepr<'a>> {
        let p = IcmpPacket::new_checked(bytes)?;
        if !p.verify_checksum() {
            return Err(Error::BadChecksum {
                format: Format::Icmp,
                found: p.checksum(),
                computed: checksum(&[
                    &bytes[..field::CHECKSUM.start],
                    &bytes[field::CHECKSUM.end..],
                ]),
            });
        }
        let message = match p.message_type() {
            TYPE_ECHO_REQUEST => EchoMessage::Request,
            TYPE_ECHO_REPLY => EchoMessage::Reply,
            other => {
                return Err(Error::BadField {
                    format: Format::Icmp,
                    field: "type",
                    found: other.into(),
                })
            }
        };
        if p.code() != 0 {
            return Err(Error::BadField {
                format: Format::Icmp,
                field: "code",
                found: p.code().into(),
            });
        }
        Ok(IcmpEchoRepr {
            message,
            identifier: p.identifier(),
            sequence: p.sequence(),
            data: &bytes[HEADER_LEN..],
        })
    }

    /// Bytes [`IcmpEchoRepr::emit`] writes: header and data.
    pub const fn buffer_len(&self) -> usize {
        HEADER_LEN + self.data.len()
    }

    /// Writes the message, checksum filled in, into `buffer[..buffer_len()]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        let b = &mut buffer[..self.buffer_len()];
        b[field::TYPE] = self.message.message_type();
        b[field::CODE] = 0;
        set_u16(b, field::CHECKSUM, 0);
        set_u16(b, field::IDENTIFIER, self.identifier);
        set_u16(b, field::SEQUENCE, self.sequence);
        b[HEADER_LEN..].copy_from_slice(self.data);
        let sum = checksum(&[b]);
        set_u16(b, field::CHECKSUM, sum);
    }
}
