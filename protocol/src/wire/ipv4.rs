//! The IPv4 header (RFC 791) as the box takes it: 20 bytes, no options, no fragments.
//!
//! | bytes | field |
//! |---|---|
//! | 0 | version (high nibble, 4) and IHL (low nibble, 32-bit words, 5) |
//! | 1 | DSCP and ECN |
//! | 2-3 | total length: header and payload |
//! | 4-5 | identification |
//! | 6-7 | flags (bit 14 don't fragment, bit 13 more fragments) and fragment offset (13 bits) |
//! | 8 | time to live |
//! | 9 | protocol |
//! | 10-11 | header checksum |
//! | 12-15 | source address |
//! | 16-19 | destination address |

use super::checksum::checksum;
use super::{array, one, set_u16};
use crate::{check_len, get_u16, Error, Format, LayoutRow, Result};

/// Byte ranges and positions of the header's fields.
pub mod field {
    use crate::Field;
    pub const VERSION_IHL: usize = 0;
    pub const DSCP_ECN: usize = 1;
    pub const TOTAL_LEN: Field = 2..4;
    pub const IDENTIFICATION: Field = 4..6;
    pub const FLAGS_FRAGMENT_OFFSET: Field = 6..8;
    pub const TTL: usize = 8;
    pub const PROTOCOL: usize = 9;
    pub const CHECKSUM: Field = 10..12;
    pub const SOURCE: Field = 12..16;
    pub const DESTINATION: Field = 16..20;
}

/// Length of the header without options (IHL 5), the only one the box takes.
pub const HEADER_LEN: usize = field::DESTINATION.end;
/// IP protocol number of ICMP.
pub const PROTOCOL_ICMP: u8 = 1;
/// IP protocol number of UDP.
pub const PROTOCOL_UDP: u8 = 17;
/// The don't-fragment flag in the flags and fragment offset field.
pub const FLAG_DONT_FRAGMENT: u16 = 0x4000;
/// The more-fragments flag in the flags and fragment offset field.
pub const FLAG_MORE_FRAGMENTS: u16 = 0x2000;
/// The fragment offset's bits in the flags and fragment offset field.
pub const FRAGMENT_OFFSET: u16 = 0x1FFF;

/// Published layout of the header.
pub fn layout() -> Vec<LayoutRow> {
    let row = |name, bytes| LayoutRow { name, bytes };
    vec![
        row("version_ihl", one(field::VERSION_IHL)),
        row("dscp_ecn", one(field::DSCP_ECN)),
        row("total_len", field::TOTAL_LEN),
        row("identification", field::IDENTIFICATION),
        row("flags_fragment_offset", field::FLAGS_FRAGMENT_OFFSET),
        row("ttl", one(field::TTL)),
        row("protocol", one(field::PROTOCOL)),
        row("checksum", field::CHECKSUM),
        row("source", field::SOURCE),
        row("destination", field::DESTINATION),
    ]
}

/// A view over an IPv4 packet.
#[derive(Debug, Clone)]
pub struct Ipv4Packet<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> Ipv4Packet<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        Ipv4Packet { buffer }
    }

    /// Wraps untrusted bytes: at least the 20-byte header. The header's own values
    /// (version, IHL, checksum, total length, fragments) are checked by
    /// [`Ipv4Repr::parse`], or one by one with the getters.
    pub fn new_checked(buffer: T) -> Result<Self> {
        check_len(Format::Ipv4, buffer.as_ref(), HEADER_LEN)?;
        Ok(Ipv4Packet { buffer })
    }

    /// IP version (the high nibble of byte 0).
    pub fn version(&self) -> u8 {
        self.buffer.as_ref()[field::VERSION_IHL] >> 4
    }

    /// Internet header length in 32-bit words (the low nibble of byte 0).
    pub fn ihl(&self) -> u8 {
        self.buffer.as_ref()[field::VERSION_IHL] & 0x0F
    }

    /// DSCP and ECN.
    pub fn dscp_ecn(&self) -> u8 {
        self.buffer.as_ref()[field::DSCP_ECN]
    }

    /// Total length: header and payload.
    pub fn total_len(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::TOTAL_LEN)
    }

    /// Identification.
    pub fn identification(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::IDENTIFICATION)
    }

    /// The don't-fragment flag.
    pub fn dont_fragment(&self) -> bool {
        get_u16(self.buffer.as_ref(), field::FLAGS_FRAGMENT_OFFSET) & FLAG_DONT_FRAGMENT != 0
    }

    /// The more-fragments flag.
    pub fn more_fragments(&self) -> bool {
        get_u16(self.buffer.as_ref(), field::FLAGS_FRAGMENT_OFFSET) & FLAG_MORE_FRAGMENTS != 0
    }

    /// Fragment offset, in 8-byte units.
    pub fn fragment_offset(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::FLAGS_FRAGMENT_OFFSET) & FRAGMENT_OFFSET
    }

    /// Time to live.
    pub fn ttl(&self) -> u8 {
        self.buffer.as_ref()[field::TTL]
    }

    /// Protocol of the payload.
    pub fn protocol(&self) -> u8 {
        self.buffer.as_ref()[field::PROTOCOL]
    }

    /// Header checksum field.
    pub fn checksum(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::CHECKSUM)
    }

    /// Source address.
    pub fn source(&self) -> [u8; 4] {
        array(self.buffer.as_ref(), field::SOURCE)
    }

    /// Destination address.
    pub fn destination(&self) -> [u8; 4] {
        array(self.buffer.as_ref(), field::DESTINATION)
    }

    /// Whether the checksum of the 20-byte header is right.
    pub fn verify_checksum(&self) -> bool {
        checksum(&[&self.buffer.as_ref()[..HEADER_LEN]]) == 0
    }

    /// The payload after a 20-byte header up to the total length, if the total length
    /// lies within 20..=the bytes present.
    pub fn payload(&self) -> Option<&[u8]> {
        let total = usize::from(self.total_len());
        let b = self.buffer.as_ref();
        (HEADER_LEN..=b.len())
            .contains(&total)
            .then(|| &b[HEADER_LEN..total])
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> Ipv4Packet<T> {
    /// Fills in the header checksum over the 20-byte header.
    pub fn fill_checksum(&mut self) {
        let b = self.buffer.as_mut();
        set_u16(b, field::CHECKSUM, 0);
        let sum = checksum(&[&b[..HEADER_LEN]]);
        set_u16(b, field::CHECKSUM, sum);
    }
}

/// A parsed IPv4 header: no options, no fragments.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct Ipv4Repr {
    /// Source address.
    pub source: [u8; 4],
    /// Destination address.
    pub destination: [u8; 4],
    /// Protocol of the payload.
    pub protocol: u8,
    /// Payload length (total length less the header).
    pub payload_len: usize,
    /// DSCP and ECN.
    pub dscp_ecn: u8,
    /// Identification.
    pub identification: u16,
    /// The don't-fragment flag.
    pub dont_fragment: bool,
    /// Time to live.
    pub ttl: u8,
}

impl Ipv4Repr {
    /// Parses an untrusted packet as the box takes it: version 4, IHL 5 (options are
    /// refused), a right header checksum, a total length within 20..=the bytes present
    /// (what follows is Ethernet padding), no more-fragments flag and no fragment offset.
    /// The reserved flag bit is ignored.
    pub fn parse(bytes: &[u8]) -> Result<Ipv4Repr> {
        let p = Ipv4Packet::new_checked(bytes)?;
        let bad = |field, found: u32| Error::BadField {
            format: Format::Ipv4,
            field,
            found,
        };
        if p.version() != 4 {
            return Err(bad("version", p.version().into()));
        }
        if p.ihl() < 5 {
            return Err(bad("ihl", p.ihl().into()));
        }
        if p.ihl() > 5 {
            return Err(Error::Unsupported {
                format: Format::Ipv4,
                field: "ihl",
                found: p.ihl().into(),
                reason: "options are not taken",
            });
        }
        if !p.verify_checksum() {
            let mut zeroed = [0u8; HEADER_LEN];
            zeroed.copy_from_slice(&bytes[..HEADER_LEN]);
            zeroed[field::CHECKSUM].fill(0);
            return Err(Error::BadChecksum {
                format: Format::Ipv4,
                found: p.checksum(),
                computed: checksum(&[&zeroed]),
            });
        }
        let Some(payload) = p.payload() else {
            return Err(Error::LengthMismatch {
                format: Format::Ipv4,
                required: usize::from(p.total_len()),
                actual: bytes.len(),
            });
        };
        if p.more_fragments() || p.fragment_offset() != 0 {
            return Err(Error::Unsupported {
                format: Format::Ipv4,
                field: "flags_fragment_offset",
                found: get_u16(bytes, field::FLAGS_FRAGMENT_OFFSET).into(),
                reason: "fragments are not taken",
            });
        }
        Ok(Ipv4Repr {
            source: p.source(),
            destination: p.destination(),
            protocol: p.protocol(),
            payload_len: payload.len(),
            dscp_ecn: p.dscp_ecn(),
            identification: p.identification(),
            dont_fragment: p.dont_fragment(),
            ttl: p.ttl(),
        })
    }

    /// Bytes of the whole packet: header and payload.
    pub const fn buffer_len(&self) -> usize {
        HEADER_LEN + self.payload_len
    }

    /// Writes the 20-byte header, checksum filled in, into `buffer[..20]` (the payload is
    /// the caller's to write after it). `payload_len` must fit the 16-bit total length.
    pub fn emit(&self, buffer: &mut [u8]) {
        let total = u16::try_from(self.buffer_len()).expect("IPv4 total length above 65535");
        let b = &mut buffer[..HEADER_LEN];
        b[field::VERSION_IHL] = 0x45;
        b[field::DSCP_ECN] = self.dscp_ecn;
        set_u16(b, field::TOTAL_LEN, total);
        set_u16(b, field::IDENTIFICATION, self.identification);
        let flags = if self.dont_fragment {
            FLAG_DONT_FRAGMENT
        } else {
            0
        };
        set_u16(b, field::FLAGS_FRAGMENT_OFFSET, flags);
        b[field::TTL] = self.ttl;
        b[field::PROTOCOL] = self.protocol;
        b[field::SOURCE].copy_from_slice(&self.source);
        b[field::DESTINATION].copy_from_slice(&self.destination);
        Ipv4Packet::new_unchecked(b).fill_checksum();
    }
}
