//! The UDP header (RFC 768), its checksum over the IPv4 pseudo header.
//!
//! | bytes | field |
//! |---|---|
//! | 0-1 | source port |
//! | 2-3 | destination port |
//! | 4-5 | length: header and payload |
//! | 6-7 | checksum over pseudo header, header and payload; 0 = none |

use super::checksum::{checksum, ipv4_pseudo_header};
use super::ipv4::PROTOCOL_UDP;
use super::set_u16;
use crate::{check_len, get_u16, Error, Format, LayoutRow, Result};

/// Byte ranges of the header's fields.
pub mod field {
    use crate::Field;
    pub const SOURCE_PORT: Field = 0..2;
    pub const DESTINATION_PORT: Field = 2..4;
    pub const LENGTH: Field = 4..6;
    pub const CHECKSUM: Field = 6..8;
}

/// Length of the UDP header.
pub const HEADER_LEN: usize = field::CHECKSUM.end;

/// Published layout of the header.
pub fn layout() -> Vec<LayoutRow> {
    let row = |name, bytes| LayoutRow { name, bytes };
    vec![
        row("source_port", field::SOURCE_PORT),
        row("destination_port", field::DESTINATION_PORT),
        row("length", field::LENGTH),
        row("checksum", field::CHECKSUM),
    ]
}

/// A view over a UDP datagram (the whole IPv4 payload).
#[derive(Debug, Clone)]
pub struct UdpPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> UdpPacket<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        UdpPacket { buffer }
    }

    /// Wraps untrusted bytes: at least the 8-byte header.
    pub fn new_checked(buffer: T) -> Result<Self> {
        check_len(Format::Udp, buffer.as_ref(), HEADER_LEN)?;
        Ok(UdpPacket { buffer })
    }

    /// Source port.
    pub fn source_port(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::SOURCE_PORT)
    }

    /// Destination port.
    pub fn destination_port(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::DESTINATION_PORT)
    }

    /// Length field: header and payload.
    pub fn length(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::LENGTH)
    }

    /// Checksum field (0: the sender computed none).
    pub fn checksum(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::CHECKSUM)
    }

    /// The bytes after the header.
    pub fn payload(&self) -> &[u8] {
        &self.buffer.as_ref()[HEADER_LEN..]
    }

    /// Whether the checksum is right for a datagram from `source` to `destination`: 0 (no
    /// checksum) or the sum over pseudo header and all the bytes verifies.
    pub fn verify_checksum(&self, source: [u8; 4], destination: [u8; 4]) -> bool {
        self.checksum() == 0 || sum(self.buffer.as_ref(), source, destination) == 0
    }
}

fn sum(udp: &[u8], source: [u8; 4], destination: [u8; 4]) -> u16 {
    let len = u16::try_from(udp.len()).expect("UDP length above 65535");
    checksum(&[
        &ipv4_pseudo_header(source, destination, PROTOCOL_UDP, len),
        udp,
    ])
}

/// A parsed UDP datagram.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct UdpRepr<'a> {
    /// Source port.
    pub source_port: u16,
    /// Destination port.
    pub destination_port: u16,
    /// The payload.
    pub payload: &'a [u8],
}

impl<'a> UdpRepr<'a> {
    /// Parses an untrusted datagram, the whole IPv4 payload of a packet from `source` to
    /// `destination`: at least 8 bytes, a length field equal to the bytes' length, a
    /// checksum of 0 or right.
    pub fn parse(bytes: &'a [u8], source: [u8; 4], destination: [u8; 4]) -> Result<Self> {
        let p = UdpPacket::new_checked(bytes)?;
        if usize::from(p.length()) != bytes.len() {
            return Err(Error::LengthMismatch {
                format: Format::Udp,
                required: p.length().into(),
                actual: bytes.len(),
            });
        }
        if !p.verify_checksum(source, destination) {
            let mut header = [0u8; HEADER_LEN];
            header.copy_from_slice(&bytes[..HEADER_LEN]);
            header[field::CHECKSUM].fill(0);
            let len = p.length();
            let pseudo = ipv4_pseudo_header(source, destination, PROTOCOL_UDP, len);
            return Err(Error::BadChecksum {
                format: Format::Udp,
                found: p.checksum(),
                computed: checksum(&[&pseudo, &header, p.payload()]),
            });
        }
        Ok(UdpRepr {
            source_port: p.source_port(),
            destination_port: p.destination_port(),
            payload: &bytes[HEADER_LEN..],
        })
    }

    /// Bytes [`UdpRepr::emit`] writes: header and payload.
    pub const fn buffer_len(&self) -> usize {
        HEADER_LEN + self.payload.len()
    }

    /// Writes the datagram from `source` to `destination` into `buffer[..buffer_len()]`
    /// with its checksum (a sum of 0 is sent as 0xFFFF, RFC 768). The length must fit
    /// 16 bits.
    pub fn emit(&self, buffer: &mut [u8], source: [u8; 4], destination: [u8; 4]) {
        let len = u16::try_from(self.buffer_len()).expect("UDP length above 65535");
        let b = &mut buffer[..self.buffer_len()];
        set_u16(b, field::SOURCE_PORT, self.source_port);
        set_u16(b, field::DESTINATION_PORT, self.destination_port);
        set_u16(b, field::LENGTH, len);
        set_u16(b, field::CHECKSUM, 0);
        b[HEADER_LEN..].copy_from_slice(self.payload);
        let sum = match sum(b, source, destination) {
            0 => 0xFFFF,
            s => s,
        };
        set_u16(b, field::CHECKSUM, sum);
    }
}
