//! The Ethernet II header (IEEE 802.3, no VLAN tag).
//!
//! | bytes | field |
//! |---|---|
//! | 0-5 | destination MAC |
//! | 6-11 | source MAC |
//! | 12-13 | EtherType |

use super::{array, set_u16};
use crate::{check_len, get_u16, Format, LayoutRow, Result};

/// Byte ranges of the header's fields.
pub mod field {
    use crate::Field;
    pub const DESTINATION: Field = 0..6;
    pub const SOURCE: Field = 6..12;
    pub const ETHERTYPE: Field = 12..14;
}

/// Length of the Ethernet II header.
pub const HEADER_LEN: usize = field::ETHERTYPE.end;
/// EtherType of IPv4.
pub const ETHERTYPE_IPV4: u16 = 0x0800;
/// EtherType of ARP.
pub const ETHERTYPE_ARP: u16 = 0x0806;
/// The broadcast MAC address.
pub const BROADCAST: [u8; 6] = [0xFF; 6];

/// Published layout of the header.
pub fn layout() -> Vec<LayoutRow> {
    vec![
        LayoutRow {
            name: "destination",
            bytes: field::DESTINATION,
        },
        LayoutRow {
            name: "source",
            bytes: field::SOURCE,
        },
        LayoutRow {
            name: "ethertype",
            bytes: field::ETHERTYPE,
        },
    ]
}

/// A view over an Ethernet II frame (from the destination MAC, no preamble; whatever
/// follows the header, FCS included if present, is the payload).
#[derive(Debug, Clone)]
pub struct EthernetFrame<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> EthernetFrame<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        EthernetFrame { buffer }
    }

    /// Wraps untrusted bytes: at least the 14-byte header.
    pub fn new_checked(buffer: T) -> Result<Self> {
        check_len(Format::Ethernet, buffer.as_ref(), HEADER_LEN)?;
        Ok(EthernetFrame { buffer })
    }

    /// Destination MAC address.
    pub fn destination(&self) -> [u8; 6] {
        array(self.buffer.as_ref(), field::DESTINATION)
    }

    /// Source MAC address.
    pub fn source(&self) -> [u8; 6] {
        array(self.buffer.as_ref(), field::SOURCE)
    }

    /// EtherType.
    pub fn ethertype(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::ETHERTYPE)
    }

    /// The bytes after the header.
    pub fn payload(&self) -> &[u8] {
        &self.buffer.as_ref()[HEADER_LEN..]
    }

    /// The underlying bytes.
    pub fn into_inner(self) -> T {
        self.buffer
    }
}

impl<T: AsRef<[u8]> + AsMut<[u8]>> EthernetFrame<T> {
    /// Sets the destination MAC address.
    pub fn set_destination(&mut self, mac: [u8; 6]) {
        self.buffer.as_mut()[field::DESTINATION].copy_from_slice(&mac);
    }

    /// Sets the source MAC address.
    pub fn set_source(&mut self, mac: [u8; 6]) {
        self.buffer.as_mut()[field::SOURCE].copy_from_slice(&mac);
    }

    /// Sets the EtherType.
    pub fn set_ethertype(&mut self, ethertype: u16) {
        set_u16(self.buffer.as_mut(), field::ETHERTYPE, ethertype);
    }

    /// The bytes after the header, to write.
    pub fn payload_mut(&mut self) -> &mut [u8] {
        &mut self.buffer.as_mut()[HEADER_LEN..]
    }
}

/// A parsed Ethernet II header.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct EthernetRepr {
    /// Destination MAC address.
    pub destination: [u8; 6],
    /// Source MAC address.
    pub source: [u8; 6],
    /// EtherType of the payload.
    pub ethertype: u16,
}

impl EthernetRepr {
    /// Parses the header of untrusted bytes (any EtherType).
    pub fn parse(bytes: &[u8]) -> Result<EthernetRepr> {
        let f = EthernetFrame::new_checked(bytes)?;
        Ok(EthernetRepr {
            destination: f.destination(),
            source: f.source(),
            ethertype: f.ethertype(),
        })
    }

    /// Bytes [`EthernetRepr::emit`] writes: the header.
    pub const fn buffer_len(&self) -> usize {
        HEADER_LEN
    }

    /// Writes the header into `buffer[..14]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        let mut f = EthernetFrame::new_unchecked(&mut buffer[..HEADER_LEN]);
        f.set_destination(self.destination);
        f.set_source(self.source);
        f.set_ethertype(self.ethertype);
    }
}
