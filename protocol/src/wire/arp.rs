//! ARP for IPv4 over Ethernet (RFC 826): 28 bytes.
//!
//! | bytes | field |
//! |---|---|
//! | 0-1 | hardware type, 1 (Ethernet) |
//! | 2-3 | protocol type, 0x0800 (IPv4) |
//! | 4 | hardware address length, 6 |
//! | 5 | protocol address length, 4 |
//! | 6-7 | operation: 1 request, 2 reply |
//! | 8-13 | sender MAC |
//! | 14-17 | sender IPv4 address |
//! | 18-23 | target MAC |
//! | 24-27 | target IPv4 address |

use super::ethernet::ETHERTYPE_IPV4;
use super::{array, one};
use crate::{check_len, get_u16, Error, Format, LayoutRow, Result};

/// Byte ranges and positions of the packet's fields.
pub mod field {
    use crate::Field;
    pub const HARDWARE_TYPE: Field = 0..2;
    pub const PROTOCOL_TYPE: Field = 2..4;
    pub const HARDWARE_LEN: usize = 4;
    pub const PROTOCOL_LEN: usize = 5;
    pub const OPERATION: Field = 6..8;
    pub const SENDER_MAC: Field = 8..14;
    pub const SENDER_IP: Field = 14..18;
    pub const TARGET_MAC: Field = 18..24;
    pub const TARGET_IP: Field = 24..28;
}

/// Length of an ARP packet for IPv4 over Ethernet.
pub const PACKET_LEN: usize = field::TARGET_IP.end;
/// Hardware type of Ethernet.
pub const HARDWARE_ETHERNET: u16 = 1;
/// Operation code of a request.
pub const OPERATION_REQUEST: u16 = 1;
/// Operation code of a reply.
pub const OPERATION_REPLY: u16 = 2;
/// The first 8 bytes of every request for IPv4 over Ethernet: hardware type 1, protocol
/// type 0x0800, address lengths 6 and 4, operation 1.
pub const REQUEST_HEADER: [u8; 8] = fixed_header(OPERATION_REQUEST);
/// The first 8 bytes of every reply: as [`REQUEST_HEADER`], operation 2.
pub const REPLY_HEADER: [u8; 8] = fixed_header(OPERATION_REPLY);

const fn fixed_header(operation: u16) -> [u8; 8] {
    let [h0, h1] = HARDWARE_ETHERNET.to_be_bytes();
    let [p0, p1] = ETHERTYPE_IPV4.to_be_bytes();
    let [o0, o1] = operation.to_be_bytes();
    [h0, h1, p0, p1, 6, 4, o0, o1]
}

/// Published layout of the packet.
pub fn layout() -> Vec<LayoutRow> {
    let row = |name, bytes| LayoutRow { name, bytes };
    vec![
        row("hardware_type", field::HARDWARE_TYPE),
        row("protocol_type", field::PROTOCOL_TYPE),
        row("hardware_len", one(field::HARDWARE_LEN)),
        row("protocol_len", one(field::PROTOCOL_LEN)),
        row("operation", field::OPERATION),
        row("sender_mac", field::SENDER_MAC),
        row("sender_ip", field::SENDER_IP),
        row("target_mac", field::TARGET_MAC),
        row("target_ip", field::TARGET_IP),
    ]
}

/// A view over an ARP packet.
#[derive(Debug, Clone)]
pub struct ArpPacket<T: AsRef<[u8]>> {
    buffer: T,
}

impl<T: AsRef<[u8]>> ArpPacket<T> {
    /// Wraps bytes without checking them.
    pub fn new_unchecked(buffer: T) -> Self {
        ArpPacket { buffer }
    }

    /// Wraps untrusted bytes: at least 28 bytes (what follows is Ethernet padding). The
    /// types and lengths are checked by [`ArpRepr::parse`].
    pub fn new_checked(buffer: T) -> Result<Self> {
        check_len(Format::Arp, buffer.as_ref(), PACKET_LEN)?;
        Ok(ArpPacket { buffer })
    }

    /// Hardware type.
    pub fn hardware_type(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::HARDWARE_TYPE)
    }

    /// Protocol type.
    pub fn protocol_type(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::PROTOCOL_TYPE)
    }

    /// Hardware address length.
    pub fn hardware_len(&self) -> u8 {
        self.buffer.as_ref()[field::HARDWARE_LEN]
    }

    /// Protocol address length.
    pub fn protocol_len(&self) -> u8 {
        self.buffer.as_ref()[field::PROTOCOL_LEN]
    }

    /// Operation code.
    pub fn operation(&self) -> u16 {
        get_u16(self.buffer.as_ref(), field::OPERATION)
    }

    /// Sender MAC address.
    pub fn sender_mac(&self) -> [u8; 6] {
        array(self.buffer.as_ref(), field::SENDER_MAC)
    }

    /// Sender IPv4 address.
    pub fn sender_ip(&self) -> [u8; 4] {
        array(self.buffer.as_ref(), field::SENDER_IP)
    }

    /// Target MAC address.
    pub fn target_mac(&self) -> [u8; 6] {
        array(self.buffer.as_ref(), field::TARGET_MAC)
    }

    /// Target IPv4 address.
    pub fn target_ip(&self) -> [u8; 4] {
        array(self.buffer.as_ref(), field::TARGET_IP)
    }
}

/// What an ARP packet asks or answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum ArpOperation {
    /// Who has the target IP? (operation 1)
    Request,
    /// The sender has the sender IP. (operation 2)
    Reply,
}

impl ArpOperation {
    /// The operation code.
    pub const fn code(self) -> u16 {
        match self {
            ArpOperation::Request => OPERATION_REQUEST,
            ArpOperation::Reply => OPERATION_REPLY,
        }
    }
}

/// A parsed ARP packet for IPv4 over Ethernet.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct ArpRepr {
    /// Request or reply.
    pub operation: ArpOperation,
    /// Sender MAC address.
    pub sender_mac: [u8; 6],
    /// Sender IPv4 address.
    pub sender_ip: [u8; 4],
    /// Target MAC address (0 in a request).
    pub target_mac: [u8; 6],
    /// Target IPv4 address.
    pub target_ip: [u8; 4],
}

impl ArpRepr {
    /// Parses untrusted bytes: hardware type 1, protocol type 0x0800, lengths 6 and 4,
    /// operation 1 or 2.
    pub fn parse(bytes: &[u8]) -> Result<ArpRepr> {
        let p = ArpPacket::new_checked(bytes)?;
        let bad = |field, found: u32| Error::BadField {
            format: Format::Arp,
            field,
            found,
        };
        if p.hardware_type() != HARDWARE_ETHERNET {
            return Err(bad("hardware_type", p.hardware_type().into()));
        }
        if p.protocol_type() != ETHERTYPE_IPV4 {
            return Err(bad("protocol_type", p.protocol_type().into()));
        }
        if p.hardware_len() != 6 {
            return Err(bad("hardware_len", p.hardware_len().into()));
        }
        if p.protocol_len() != 4 {
            return Err(bad("protocol_len", p.protocol_len().into()));
        }
        let operation = match p.operation() {
            OPERATION_REQUEST => ArpOperation::Request,
            OPERATION_REPLY => ArpOperation::Reply,
            other => return Err(bad("operation", other.into())),
        };
        Ok(ArpRepr {
            operation,
            sender_mac: p.sender_mac(),
            sender_ip: p.sender_ip(),
            target_mac: p.target_mac(),
            target_ip: p.target_ip(),
        })
    }

    /// Bytes [`ArpRepr::emit`] writes.
    pub const fn buffer_len(&self) -> usize {
        PACKET_LEN
    }

    /// Writes the packet into `buffer[..28]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        let b = &mut buffer[..PACKET_LEN];
        b[..field::OPERATION.end].copy_from_slice(&fixed_header(self.operation.code()));
        b[field::SENDER_MAC].copy_from_slice(&self.sender_mac);
        b[field::SENDER_IP].copy_from_slice(&self.sender_ip);
        b[field::TARGET_MAC].copy_from_slice(&self.target_mac);
        b[field::TARGET_IP].copy_from_slice(&self.target_ip);
    }
}
