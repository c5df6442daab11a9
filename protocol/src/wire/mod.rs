//! The frames around the box's datagrams: Ethernet II, ARP for IPv4 over Ethernet, IPv4
//! (no options, no fragments, as the box takes it), ICMP echo and UDP.
//!
//! Each header follows the crate's contract (a `Packet` view with private field ranges,
//! a `Repr` with `parse`, `emit` and `buffer_len`, a published `layout()` checked against
//! docs/wire-format.md); [`checksum`] holds the one Internet checksum (RFC 1071) all of them
//! use. The link's addresses and the box's own choices (TTL, don't fragment) live in
//! [`crate::link`].

pub mod arp;
pub mod checksum;
pub mod ethernet;
pub mod icmp;
pub mod ipv4;
pub mod udp;

pub use arp::{ArpOperation, ArpRepr};
pub use ethernet::EthernetRepr;
pub use icmp::{EchoMessage, IcmpEchoRepr};
pub use ipv4::Ipv4Repr;
pub use udp::UdpRepr;

use crate::Field;

#[inline]
pub(crate) fn set_u16(b: &mut [u8], at: Field, value: u16) {
    b[at].copy_from_slice(&value.to_be_bytes());
}

#[inline]
pub(crate) fn array<const N: usize>(b: &[u8], at: Field) -> [u8; N] {
    let mut a = [0u8; N];
    a.copy_from_slice(&b[at]);
    a
}

#[inline]
pub(crate) fn one(at: usize) -> Field {
    at..at + 1
}
