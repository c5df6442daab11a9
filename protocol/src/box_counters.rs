//! The box-wide counter block: the receive side's counters and the link state.
//!
//! A status datagram carries it after its port counter blocks when its header flag
//! [`FLAG_BOX_COUNTERS`](crate::datagram::FLAG_BOX_COUNTERS) is set (status datagrams without
//! the flag are exactly those of version 1 before the block existed); the acknowledgement of
//! a status-now command carries it too ([`crate::command`]).
//!
//! | bytes | field |
//! |---|---|
//! | 0 | link_up: 1 when the PHY reports the link up, else 0 |
//! | 1 | link_speed: 0 = 10, 1 = 100, 2 = 1000 Mbit/s, 3 = unknown |
//! | 2-3 | reserved, 0 |
//! | 4.. | one u32 per [`BoxCounter`], in its wire order |
//!
//! Every frame the box receives is counted in `frames_received` and in exactly one other
//! counter (its fate), so `frames_received` is the sum of all the others (modulo 2^32).
//! Counters are u32 since reset and wrap.

use crate::{check_len, get_u32, Error, Format, LayoutRow, Result};
use core::fmt;

/// Byte offsets in the block.
pub mod field {
    use crate::Field;
    /// Link state byte.
    pub const LINK_UP: usize = 0;
    /// Link speed byte.
    pub const LINK_SPEED: usize = 1;
    /// Reserved, 0.
    pub const RESERVED: Field = 2..4;
    /// The first counter.
    pub const FIRST_COUNTER: usize = 4;
}

/// Length of the counter block.
pub const BOX_COUNTERS_LEN: usize = field::FIRST_COUNTER + BoxCounter::ALL.len() * 4;

/// The box-wide counters, in wire order. All but `frames_received` are the fates of a
/// received frame: each frame is counted in exactly one of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum BoxCounter {
    /// Every frame the MAC received (SFD seen), good or bad.
    FramesReceived,
    /// Frames whose frame check sequence was wrong.
    BadFcs,
    /// Frames shorter than 64 or longer than 1518 bytes (FCS included).
    BadLength,
    /// Frames for another station: another destination MAC (not the box's, not broadcast),
    /// an EtherType other than ARP and IPv4, an ARP not asking for the box's IP, an IPv4
    /// packet to another address, a protocol other than ICMP and UDP, an ICMP type other
    /// than echo request.
    NotForUs,
    /// IPv4 headers with a wrong version, header checksum or total length.
    Ipv4BadHeader,
    /// IPv4 headers with options (IHL above 5): refused.
    Ipv4Options,
    /// IPv4 fragments (MF set or a fragment offset): refused.
    Ipv4Fragment,
    /// ICMP or UDP messages too short for their header, a UDP length other than the IPv4
    /// payload's, or a wrong ICMP or UDP checksum (a UDP checksum of 0 means none).
    BadTransport,
    /// UDP datagrams to a port other than the box's command port.
    UnknownUdpPort,
    /// ARP requests answered.
    ArpAnswered,
    /// ICMP echo requests answered.
    PingsAnswered,
    /// Commands carried out (acknowledged with result `ok`).
    CommandsAccepted,
    /// Commands from outside the configured host subnet: not answered.
    RefusedForeignSubnet,
    /// Datagrams to the command port that are no well-formed command: not answered.
    RefusedMalformed,
    /// Commands with a sequence number not newer than the last accepted from the host.
    RefusedReplay,
    /// Commands addressed to another box id.
    RefusedOtherBox,
    /// Commands with an opcode the box does not know.
    RefusedUnknownOpcode,
    /// Commands with arguments of the wrong length or out of range.
    RefusedBadArgument,
    /// Cell-network commands refused because the downlink had no room for them (a target
    /// port's queue full, or the previous cell command still being queued).
    RefusedDownlinkFull,
    /// Frames that would be answered (ARP request, echo request, command) while the
    /// previous reply had not left yet: the box holds one frame for its reply, so these
    /// are neither stored, carried out nor answered.
    ReplyBusy,
}

impl BoxCounter {
    /// All counters in wire order.
    pub const ALL: [BoxCounter; 20] = [
        BoxCounter::FramesReceived,
        BoxCounter::BadFcs,
        BoxCounter::BadLength,
        BoxCounter::NotForUs,
        BoxCounter::Ipv4BadHeader,
        BoxCounter::Ipv4Options,
        BoxCounter::Ipv4Fragment,
        BoxCounter::BadTransport,
        BoxCounter::UnknownUdpPort,
        BoxCounter::ArpAnswered,
        BoxCounter::PingsAnswered,
        BoxCounter::CommandsAccepted,
        BoxCounter::RefusedForeignSubnet,
        BoxCounter::RefusedMalformed,
        BoxCounter::RefusedReplay,
        BoxCounter::RefusedOtherBox,
        BoxCounter::RefusedUnknownOpcode,
        BoxCounter::RefusedBadArgument,
        BoxCounter::RefusedDownlinkFull,
        BoxCounter::ReplyBusy,
    ];

    /// Position in the block's counter list.
    pub fn index(self) -> usize {
        self as usize
    }

    /// Byte range in the block.
    pub fn bytes(self) -> crate::Field {
        let at = field::FIRST_COUNTER + 4 * self.index();
        at..at + 4
    }

    /// Lowercase identifier, as in JSON and docs/wire-format.md.
    pub fn name(self) -> &'static str {
        match self {
            BoxCounter::FramesReceived => "frames_received",
            BoxCounter::BadFcs => "bad_fcs",
            BoxCounter::BadLength => "bad_length",
            BoxCounter::NotForUs => "not_for_us",
            BoxCounter::Ipv4BadHeader => "ipv4_bad_header",
            BoxCounter::Ipv4Options => "ipv4_options",
            BoxCounter::Ipv4Fragment => "ipv4_fragment",
            BoxCounter::BadTransport => "bad_transport",
            BoxCounter::UnknownUdpPort => "unknown_udp_port",
            BoxCounter::ArpAnswered => "arp_answered",
            BoxCounter::PingsAnswered => "pings_answered",
            BoxCounter::CommandsAccepted => "commands_accepted",
            BoxCounter::RefusedForeignSubnet => "refused_foreign_subnet",
            BoxCounter::RefusedMalformed => "refused_malformed",
            BoxCounter::RefusedReplay => "refused_replay",
            BoxCounter::RefusedOtherBox => "refused_other_box",
            BoxCounter::RefusedUnknownOpcode => "refused_unknown_opcode",
            BoxCounter::RefusedBadArgument => "refused_bad_argument",
            BoxCounter::RefusedDownlinkFull => "refused_downlink_full",
            BoxCounter::ReplyBusy => "reply_busy",
        }
    }
}

/// Link speed as the PHY reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum LinkSpeed {
    /// 10 Mbit/s.
    Mbit10 = 0,
    /// 100 Mbit/s.
    Mbit100 = 1,
    /// 1000 Mbit/s.
    Mbit1000 = 2,
    /// Not known (no PHY status, or an emulated box).
    Unknown = 3,
}

impl LinkSpeed {
    fn from_code(code: u8) -> Option<LinkSpeed> {
        Some(match code {
            0 => LinkSpeed::Mbit10,
            1 => LinkSpeed::Mbit100,
            2 => LinkSpeed::Mbit1000,
            3 => LinkSpeed::Unknown,
            _ => return None,
        })
    }

    /// Name as printed (`10`, `100`, `1000` Mbit/s or `unknown`).
    pub fn name(self) -> &'static str {
        match self {
            LinkSpeed::Mbit10 => "10 Mbit/s",
            LinkSpeed::Mbit100 => "100 Mbit/s",
            LinkSpeed::Mbit1000 => "1000 Mbit/s",
            LinkSpeed::Unknown => "unknown speed",
        }
    }
}

/// Published layout of the box counter block.
pub fn layout() -> Vec<LayoutRow> {
    let mut rows = vec![
        LayoutRow {
            name: "link_up",
            bytes: field::LINK_UP..field::LINK_UP + 1,
        },
        LayoutRow {
            name: "link_speed",
            bytes: field::LINK_SPEED..field::LINK_SPEED + 1,
        },
        LayoutRow {
            name: "reserved",
            bytes: field::RESERVED,
        },
    ];
    rows.extend(BoxCounter::ALL.iter().map(|c| LayoutRow {
        name: c.name(),
        bytes: c.bytes(),
    }));
    rows
}

/// The parsed box counter block.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct BoxCounters {
    /// The PHY reports the link up.
    pub link_up: bool,
    /// The link speed.
    pub link_speed: LinkSpeed,
    /// The counters, indexed by [`BoxCounter::index`].
    pub counts: [u32; BoxCounter::ALL.len()],
}

impl Default for BoxCounters {
    fn default() -> Self {
        BoxCounters {
            link_up: false,
            link_speed: LinkSpeed::Unknown,
            counts: [0; BoxCounter::ALL.len()],
        }
    }
}

impl BoxCounters {
    /// Value of one counter.
    pub fn get(&self, counter: BoxCounter) -> u32 {
        self.counts[counter.index()]
    }

    /// Adds one to a counter (wrapping, as the box's u32 counters do).
    pub fn bump(&mut self, counter: BoxCounter) {
        let c = &mut self.counts[counter.index()];
        *c = c.wrapping_add(1);
    }

    /// Parses an untrusted block: length, a link_up of 0 or 1, a speed code, reserved 0.
    pub fn parse(bytes: &[u8]) -> Result<BoxCounters> {
        check_len(Format::BoxCounters, bytes, BOX_COUNTERS_LEN)?;
        let up = bytes[field::LINK_UP];
        if up > 1 {
            return Err(Error::BadField {
                format: Format::BoxCounters,
                field: "link_up",
                found: u32::from(up),
            });
        }
        let speed = bytes[field::LINK_SPEED];
        let link_speed = LinkSpeed::from_code(speed).ok_or(Error::BadField {
            format: Format::BoxCounters,
            field: "link_speed",
            found: u32::from(speed),
        })?;
        if bytes[field::RESERVED].iter().any(|&b| b != 0) {
            return Err(Error::BadField {
                format: Format::BoxCounters,
                field: "reserved",
                found: u32::from(crate::get_u16(bytes, field::RESERVED)),
            });
        }
        Ok(BoxCounters {
            link_up: up == 1,
            link_speed,
            counts: BoxCounter::ALL.map(|c| get_u32(bytes, c.bytes())),
        })
    }

    /// Writes the block into `buffer[..BOX_COUNTERS_LEN]`.
    pub fn emit(&self, buffer: &mut [u8]) {
        buffer[field::LINK_UP] = u8::from(self.link_up);
        buffer[field::LINK_SPEED] = self.link_speed as u8;
        buffer[field::RESERVED].fill(0);
        for c in BoxCounter::ALL {
            buffer[c.bytes()].copy_from_slice(&self.get(c).to_be_bytes());
        }
    }

    /// The counters by name, for reports.
    pub fn named(&self) -> Vec<(&'static str, u32)> {
        BoxCounter::ALL
            .iter()
            .map(|&c| (c.name(), self.get(c)))
            .collect()
    }

    /// Frames counted in no fate, or in more than one: `frames_received` minus the sum of
    /// every other counter (wrapping); 0 for a consistent block.
    pub fn unaccounted_frames(&self) -> u32 {
        BoxCounter::ALL[1..]
            .iter()
            .fold(self.get(BoxCounter::FramesReceived), |left, &c| {
                left.wrapping_sub(self.get(c))
            })
    }
}

impl fmt::Display for BoxCounters {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "link {}, {}:",
            if self.link_up { "up" } else { "down" },
            self.link_speed.name()
        )?;
        for (name, value) in self.named() {
            if value != 0 || name == "frames_received" {
                write!(f, " {name}={value}")?;
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn golden_block() {
        let mut bytes = vec![0u8; BOX_COUNTERS_LEN];
        bytes[0] = 1;
        bytes[1] = 2;
        // frames_received = 7, arp_answered = 3, refused_replay = 0x01020304
        bytes[4..8].copy_from_slice(&[0, 0, 0, 7]);
        bytes[4 + 4 * 9..4 + 4 * 10].copy_from_slice(&[0, 0, 0, 3]);
        bytes[4 + 4 * 14..4 + 4 * 15].copy_from_slice(&[1, 2, 3, 4]);
        let c = BoxCounters::parse(&bytes).unwrap();
        assert!(c.link_up);
        assert_eq!(c.link_speed, LinkSpeed::Mbit1000);
        assert_eq!(c.get(BoxCounter::FramesReceived), 7);
        assert_eq!(c.get(BoxCounter::ArpAnswered), 3);
        assert_eq!(c.get(BoxCounter::RefusedReplay), 0x0102_0304);
        let mut out = vec![0xA5; BOX_COUNTERS_LEN];
        c.emit(&mut out);
        assert_eq!(out, bytes);
        assert_eq!(BOX_COUNTERS_LEN, 84);
    }

    #[test]
    fn status_datagrams_carry_the_block_behind_flag_bit_1() {
        use crate::datagram::{
            Datagram, DatagramBody, DatagramRepr, FLAG_BOX_COUNTERS,
            MAX_STATUS_PORTS_WITH_BOX_COUNTERS,
        };
        use crate::{PortCounters, StatusRepr};
        let status = |ports: usize| DatagramRepr {
            box_id: 3,
            port_count: 64,
            flags: 0,
            sequence: 9,
            base_tick: 1234,
            body: DatagramBody::Status(StatusRepr {
                boot_id: 7,
                datagrams_sent: 1,
                records_sent: 2,
                first_port: 0,
                ports: vec![PortCounters([5; 8]); ports],
            }),
        };
        let mut counters = BoxCounters::default();
        counters.bump(BoxCounter::FramesReceived);
        counters.bump(BoxCounter::PingsAnswered);
        let plain = status(4).to_bytes();
        let with = status(4).to_bytes_with_box_counters(&counters);
        // the same datagram, the flag and the block added
        assert_eq!(with.len(), plain.len() + BOX_COUNTERS_LEN);
        assert_eq!(with[7], FLAG_BOX_COUNTERS);
        assert_eq!(with[..7], plain[..7]);
        assert_eq!(with[8..plain.len()], plain[8..]);
        let (repr, parsed) = DatagramRepr::parse_box_counters(&with).unwrap();
        assert_eq!((repr, parsed), (status(4), Some(counters)));
        assert_eq!(
            DatagramRepr::parse_box_counters(&plain).unwrap(),
            (status(4), None)
        );
        assert_eq!(parsed.unwrap().unaccounted_frames(), 0);
        // at most 42 port blocks beside the block
        let full = status(44).to_bytes_with_box_counters(&counters);
        assert_eq!(
            Datagram::new_checked(&full[..]).unwrap().entry_count(),
            MAX_STATUS_PORTS_WITH_BOX_COUNTERS
        );
        assert!(full.len() <= crate::datagram::MAX_PAYLOAD_LEN);
        // the flag without the block, and the block without the flag, are refused
        let mut flag_only = plain.clone();
        flag_only[7] = FLAG_BOX_COUNTERS;
        assert!(Datagram::new_checked(&flag_only[..]).is_err());
        let mut block_only = with.clone();
        block_only[7] = 0;
        assert!(Datagram::new_checked(&block_only[..]).is_err());
    }

    #[test]
    fn refuses_bad_link_fields() {
        let mut bytes = vec![0u8; BOX_COUNTERS_LEN];
        bytes[0] = 2;
        assert!(BoxCounters::parse(&bytes).is_err());
        bytes[0] = 0;
        bytes[1] = 4;
        assert!(BoxCounters::parse(&bytes).is_err());
        bytes[1] = 3;
        bytes[3] = 1;
        assert!(BoxCounters::parse(&bytes).is_err());
        bytes[3] = 0;
        assert!(BoxCounters::parse(&bytes).is_ok());
        assert!(BoxCounters::parse(&bytes[..BOX_COUNTERS_LEN - 1]).is_err());
    }
}
