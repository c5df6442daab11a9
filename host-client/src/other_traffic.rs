//! Traffic that is not the box's, counted by kind: a capture of a real network holds ARP,
//! IPv6, TCP, LLDP, mDNS and more beside the box's datagrams. None of it is bad input
//! ([`crate::BadInput`] is a malformed skinbox datagram, and only that); it is counted here
//! so a report says what else was on the wire.
//!
//! A frame is the box's when it is an IPv4 (or IPv6) UDP datagram, on the capture's port
//! when one is given, whose payload begins with the magic "SK"
//! ([`skinbox_protocol::datagram::has_magic`]); every other frame is other traffic.

use serde::{Serialize, Serializer};
use std::collections::BTreeMap;
use std::fmt;

/// What a frame that is not a skinbox datagram is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum OtherKind {
    /// ARP (EtherType 0x0806).
    Arp,
    /// LLDP (EtherType 0x88CC).
    Lldp,
    /// Any other EtherType (the value).
    EtherType(u16),
    /// IPv6 that carries no skinbox datagram (ICMPv6, TCP, mDNS, ... over IPv6).
    Ipv6,
    /// An IPv4 fragment (the box never fragments).
    IpFragment,
    /// TCP over IPv4.
    Tcp,
    /// ICMP over IPv4.
    Icmp,
    /// Another IPv4 protocol (the protocol number).
    IpProtocol(u8),
    /// UDP of a well-known service (DNS, DHCP, NTP, NetBIOS, SSDP, mDNS, LLMNR) that is not
    /// a skinbox datagram.
    UdpService(&'static str),
    /// UDP to or from another port than the capture's.
    UdpOtherPort,
    /// UDP on the capture's port (or on any port without one) whose payload does not
    /// begin with the magic "SK".
    UdpNotSkinbox,
}

/// The name of the well-known UDP service on `port`, if any.
pub fn udp_service(port: u16) -> Option<&'static str> {
    Some(match port {
        53 => "DNS",
        67 | 68 => "DHCP",
        123 => "NTP",
        137 | 138 => "NetBIOS",
        1900 => "SSDP",
        5353 => "mDNS",
        5355 => "LLMNR",
        _ => return None,
    })
}

impl fmt::Display for OtherKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OtherKind::Arp => f.write_str("ARP"),
            OtherKind::Lldp => f.write_str("LLDP"),
            OtherKind::EtherType(t) => write!(f, "EtherType 0x{t:04X}"),
            OtherKind::Ipv6 => f.write_str("IPv6"),
            OtherKind::IpFragment => f.write_str("IPv4 fragment"),
            OtherKind::Tcp => f.write_str("TCP"),
            OtherKind::Icmp => f.write_str("ICMP"),
            OtherKind::IpProtocol(p) => write!(f, "IPv4 protocol {p}"),
            OtherKind::UdpService(s) => write!(f, "UDP {s}"),
            OtherKind::UdpOtherPort => f.write_str("UDP other port"),
            OtherKind::UdpNotSkinbox => f.write_str("UDP not skinbox"),
        }
    }
}

/// In JSON a kind is its text (a map key).
impl Serialize for OtherKind {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

/// Frames that are not the box's, counted by kind.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize)]
pub struct OtherTraffic {
    /// Every such frame.
    pub total: u64,
    /// Count per kind.
    pub by_kind: BTreeMap<OtherKind, u64>,
}

impl OtherTraffic {
    /// Counts one frame of `kind`.
    pub fn count(&mut self, kind: OtherKind) {
        self.total += 1;
        *self.by_kind.entry(kind).or_insert(0) += 1;
    }

    /// Count of one kind (0 when never seen).
    pub fn get(&self, kind: OtherKind) -> u64 {
        self.by_kind.get(&kind).copied().unwrap_or(0)
    }

    /// Adds another tally into this one.
    pub fn merge(&mut self, other: &OtherTraffic) {
        self.total += other.total;
        for (k, v) in &other.by_kind {
            *self.by_kind.entry(*k).or_insert(0) += v;
        }
    }
}

impl fmt::Display for OtherTraffic {
    /// `N` and each kind with its count, e.g. `3 (ARP 2, TCP 1)`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.total)?;
        if !self.by_kind.is_empty() {
            let parts: Vec<String> = self
                .by_kind
                .iter()
                .map(|(k, n)| format!("{k} {n}"))
                .collect();
            write!(f, " ({})", parts.join(", "))?;
        }
        Ok(())
    }
}
