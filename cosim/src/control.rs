//! The box's control behaviour as one model: what the box does with every Ethernet frame
//! it receives. The receive path of the gateware follows it byte for byte, and `skinbox
//! emulate` runs it behind a real UDP socket.
//!
//! [`BoxControl::receive`] takes one frame as the MAC sees it after the start-of-frame
//! delimiter (destination MAC to FCS) and the box tick of its last byte, and says its fate
//! (exactly one [`BoxCounter`] besides `frames_received`), the reply (an ARP reply, an ICMP
//! echo reply or a command acknowledgement) and the effect on the box's run-time
//! configuration. The rules, in the order they are applied (docs/control.md):
//!
//! 1. Length 64..=1518 bytes with FCS, else `bad_length`; then the FCS, else `bad_fcs`.
//! 2. Destination MAC the box's or broadcast, else `not_for_us`.
//! 3. EtherType ARP (0x0806): a request (Ethernet/IPv4, 6/4, operation 1) for the box's IP is
//!    answered (`arp_answered`), every other ARP is `not_for_us`.
//! 4. EtherType IPv4 (0x0800) to the box's MAC (broadcast IPv4 is `not_for_us`): version 4
//!    and IHL of at least 5, else `ipv4_bad_header`; IHL above 5 is `ipv4_options`; a wrong
//!    header checksum or a total length outside 20..=the frame's payload is `ipv4_bad_header`;
//!    MF set or a fragment offset is `ipv4_fragment`; another destination IP is `not_for_us`.
//!    Every other EtherType is `not_for_us`.
//! 5. ICMP: shorter than 8 bytes or a wrong checksum is `bad_transport`; an echo request
//!    (type 8, code 0) is answered (`pings_answered`), every other message is `not_for_us`.
//! 6. UDP: shorter than 8 bytes, a UDP length other than the IPv4 payload's, or a wrong
//!    non-zero checksum is `bad_transport`; a port other than the box's is `unknown_udp_port`.
//!    Every other IP protocol is `not_for_us`.
//! 7. Commands (UDP to the box's port): a sender outside the host subnet is
//!    `refused_foreign_subnet`; a payload that is no well-formed command header is
//!    `refused_malformed` (neither is answered). Then, each answered with its result: another
//!    box id (`refused_other_box`); a sequence number not newer than the last accepted from
//!    this host (`refused_replay`); an unknown opcode, bad arguments or a cell-network command
//!    the downlink has no room for ([`DownlinkModel::offer`]) (`refused_unknown_opcode`,
//!    `refused_bad_argument`, `refused_downlink_full`: these three take the sequence
//!    number, so none can be replayed); else the command is carried out
//!    (`commands_accepted`; a cell command is queued on the downlink).
//!
//! The box remembers the last accepted sequence number of [`HOST_SLOTS`] hosts (by IPv4
//! address); a host it does not remember may start at any sequence number and takes the
//! slot of the host accepted longest ago. "Newer" is serial-number arithmetic (RFC 1982):
//! `(sequence - last) as i32 > 0`.

use crate::downlink::DownlinkModel;
use skinbox_gateware::crc32::POLYNOMIAL_REFLECTED;
use skinbox_protocol::box_counters::{BoxCounter, BoxCounters, LinkSpeed};
use skinbox_protocol::command::{
    AckReply, AckRepr, AckResult, Command, Destination, Request, ANY_BOX,
};
use skinbox_protocol::link::{
    LinkConfig, ETHERNET_HEADER_LEN, FCS_LEN, IPV4_HEADER_LEN, IPV4_TTL, MIN_FRAME_LEN,
    PREAMBLE_LEN, UDP_HEADER_LEN,
};
pub use skinbox_protocol::link::{
    ETHERTYPE_ARP, ETHERTYPE_IPV4, IP_PROTOCOL_ICMP, IP_PROTOCOL_UDP,
};
use skinbox_protocol::Error;

pub use skinbox_protocol::command::HOST_SLOTS;
pub use skinbox_protocol::link::{MAX_RECEIVE_LEN, MIN_RECEIVE_LEN};
/// Length of an ARP message for Ethernet and IPv4 (RFC 826).
pub const ARP_LEN: usize = 28;
/// Length of the ICMP echo header (type, code, checksum, identifier, sequence).
pub const ICMP_ECHO_HEADER_LEN: usize = 8;
const BROADCAST: [u8; 6] = [0xFF; 6];

/// The build-time parameters the control model needs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ControlConfig {
    /// Addresses, ports and the host subnet.
    pub link: LinkConfig,
    /// Box id.
    pub box_id: u16,
    /// Ports of the box.
    pub port_count: u8,
    /// Flush timeout after reset, ticks.
    pub flush_timeout_ticks: u32,
    /// Status period after reset, ticks.
    pub status_period_ticks: u32,
    /// The box clock, Hz (the downlink's bit times).
    pub clock_hz: u64,
    /// The cells' UART baud rate (the downlink's).
    pub cell_baud: u64,
}

impl ControlConfig {
    /// The control parameters of a box built with `config`.
    pub fn of(config: &skinbox_gateware::interface_box::BoxConfig) -> ControlConfig {
        ControlConfig {
            link: config.link,
            box_id: config.box_id,
            port_count: config.ports as u8,
            flush_timeout_ticks: config.flush_timeout_ticks as u32,
            status_period_ticks: config.status_period_ticks as u32,
            clock_hz: config.clock_hz,
            cell_baud: config.baud,
        }
    }
}

/// Ticks from a command's receive tick to the clock in which the command unit offers a
/// cell command to the downlink: the parser's decision, then the command unit's pipeline
/// up to the clock before `done`.
pub const DOWNLINK_OFFER_AFTER_RECEIVE_TICK: u64 = skinbox_gateware::frame_parser::DECISION_LATENCY
    + skinbox_gateware::command_unit::DOWNLINK_OFFER_AFTER_COMMAND;

/// What a carried-out command changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Effect {
    /// Datagrams go to this destination from the next one on.
    StreamTo(Destination),
    /// Datagrams opened from now on close after this flush timeout (ticks).
    SetFlushTimeout(u32),
    /// Status reports every this many ticks from now on.
    SetStatusPeriod(u32),
    /// A status report now.
    StatusNow,
}

/// A frame the box sends in answer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// An ARP reply, the whole frame (preamble to FCS).
    Arp(Vec<u8>),
    /// An ICMP echo reply, the whole frame (preamble to FCS).
    Echo(Vec<u8>),
    /// A command acknowledgement to `to`; its send tick is filled in when it leaves.
    Ack {
        /// The acknowledgement (send tick 0 until it leaves).
        ack: AckRepr,
        /// The command's sender.
        to: Destination,
    },
}

/// What the box did with one frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outcome {
    /// The counter the frame was counted in (besides `frames_received`).
    pub fate: BoxCounter,
    /// The answer, if any.
    pub reply: Option<Reply>,
    /// The change to the run-time configuration, if any.
    pub effect: Option<Effect>,
}

/// The control state of the box: the run-time configuration, the remembered hosts and the
/// box counters.
#[derive(Debug, Clone)]
pub struct BoxControl {
    config: ControlConfig,
    /// Where the datagrams go.
    pub destination: Destination,
    /// The flush timeout in effect, ticks.
    pub flush_timeout_ticks: u32,
    /// The status period in effect, ticks.
    pub status_period_ticks: u32,
    /// The box counters (the link fields as the PHY reports them).
    pub counters: BoxCounters,
    /// (host IPv4 address, last accepted sequence), accepted longest ago first.
    hosts: Vec<([u8; 4], u32)>,
    /// The frame being received could be stored for a reply (the previous reply left).
    reply_slot_free: bool,
    /// The downlink to the cells: its queues and pins, clock by clock.
    pub downlink: DownlinkModel,
    /// The receive tick of the frame being decided.
    receive_tick: u64,
}

impl BoxControl {
    /// The state after reset: the build-time destination and timing, counters 0.
    pub fn new(config: ControlConfig) -> BoxControl {
        let link = &config.link;
        BoxControl {
            config,
            destination: Destination {
                mac: link.host_mac,
                ip: link.host_ip,
                port: link.host_port,
            },
            flush_timeout_ticks: config.flush_timeout_ticks,
            status_period_ticks: config.status_period_ticks,
            counters: BoxCounters {
                link_up: true,
                link_speed: LinkSpeed::Mbit1000,
                ..BoxCounters::default()
            },
            hosts: Vec::with_capacity(HOST_SLOTS),
            reply_slot_free: true,
            downlink: DownlinkModel::new(
                usize::from(config.port_count),
                config.clock_hz,
                config.cell_baud,
            ),
            receive_tick: 0,
        }
    }

    /// The build-time parameters.
    pub fn config(&self) -> &ControlConfig {
        &self.config
    }

    /// Takes one received frame (destination MAC to FCS, no preamble) whose last byte
    /// arrived at `receive_tick`.
    pub fn receive(&mut self, frame: &[u8], receive_tick: u64) -> Outcome {
        self.receive_with_slot(frame, receive_tick, true)
    }

    /// As [`BoxControl::receive`], for a frame that found the box's reply buffer free
    /// (`reply_slot_free`) or still holding the previous reply: then a frame that would be
    /// answered (an ARP request for the box, an echo request, a command past step 16) is
    /// `reply_busy`: not answered, not carried out, its sequence number not taken.
    pub fn receive_with_slot(
        &mut self,
        frame: &[u8],
        receive_tick: u64,
        reply_slot_free: bool,
    ) -> Outcome {
        self.reply_slot_free = reply_slot_free;
        self.receive_tick = receive_tick;
        self.counters.bump(BoxCounter::FramesReceived);
        let outcome = self.classify(frame, receive_tick);
        self.counters.bump(outcome.fate);
        // status-now answers with the counters, this command counted
        match outcome.reply {
            Some(Reply::Ack { mut ack, to }) if matches!(ack.reply, AckReply::Counters(_)) => {
                ack.reply = AckReply::Counters(self.counters);
                Outcome {
                    reply: Some(Reply::Ack { ack, to }),
                    ..outcome
                }
            }
            _ => outcome,
        }
    }

    fn classify(&mut self, frame: &[u8], receive_tick: u64) -> Outcome {
        let fate = |fate: BoxCounter| Outcome {
            fate,
            reply: None,
            effect: None,
        };
        if !(MIN_RECEIVE_LEN..=MAX_RECEIVE_LEN).contains(&frame.len()) {
            return fate(BoxCounter::BadLength);
        }
        let (body, fcs) = frame.split_at(frame.len() - FCS_LEN);
        if fcs != crc32(body).to_le_bytes() {
            return fate(BoxCounter::BadFcs);
        }
        let link = self.config.link;
        let destination_mac = &body[0..6];
        let broadcast = destination_mac == BROADCAST;
        if destination_mac != link.box_mac && !broadcast {
            return fate(BoxCounter::NotForUs);
        }
        let ethertype = u16::from_be_bytes([body[12], body[13]]);
        let payload = &body[ETHERNET_HEADER_LEN..];
        match ethertype {
            ETHERTYPE_ARP => match arp_reply(&link, payload) {
                Some(_) if !self.reply_slot_free => fate(BoxCounter::ReplyBusy),
                Some(reply) => Outcome {
                    fate: BoxCounter::ArpAnswered,
                    reply: Some(Reply::Arp(reply)),
                    effect: None,
                },
                None => fate(BoxCounter::NotForUs),
            },
            ETHERTYPE_IPV4 if !broadcast => self.ipv4(body, receive_tick),
            _ => fate(BoxCounter::NotForUs),
        }
    }

    fn ipv4(&mut self, body: &[u8], receive_tick: u64) -> Outcome {
        let fate = |fate: BoxCounter| Outcome {
            fate,
            reply: None,
            effect: None,
        };
        let link = self.config.link;
        let ip = &body[ETHERNET_HEADER_LEN..];
        let version = ip[0] >> 4;
        let ihl = usize::from(ip[0] & 0x0F);
        if version != 4 || ihl < 5 {
            return fate(BoxCounter::Ipv4BadHeader);
        }
        if ihl > 5 {
            return fate(BoxCounter::Ipv4Options);
        }
        let header = &ip[..IPV4_HEADER_LEN];
        let total = usize::from(u16::from_be_bytes([ip[2], ip[3]]));
        if internet_checksum(&[header]) != 0 || !(IPV4_HEADER_LEN..=ip.len()).contains(&total) {
            return fate(BoxCounter::Ipv4BadHeader);
        }
        let more_fragments = ip[6] & 0x20 != 0;
        let offset = u16::from_be_bytes([ip[6], ip[7]]) & 0x1FFF;
        if more_fragments || offset != 0 {
            return fate(BoxCounter::Ipv4Fragment);
        }
        if ip[16..20] != link.box_ip {
            return fate(BoxCounter::NotForUs);
        }
        let source_ip: [u8; 4] = ip[12..16].try_into().expect("4 bytes");
        let source_mac: [u8; 6] = body[6..12].try_into().expect("6 bytes");
        let message = &ip[IPV4_HEADER_LEN..total];
        match ip[9] {
            IP_PROTOCOL_ICMP => {
                if message.len() < ICMP_ECHO_HEADER_LEN || internet_checksum(&[message]) != 0 {
                    return fate(BoxCounter::BadTransport);
                }
                if message[0] != 8 || message[1] != 0 {
                    return fate(BoxCounter::NotForUs);
                }
                if !self.reply_slot_free {
                    return fate(BoxCounter::ReplyBusy);
                }
                Outcome {
                    fate: BoxCounter::PingsAnswered,
                    reply: Some(Reply::Echo(echo_reply(
                        &link, source_mac, source_ip, message,
                    ))),
                    effect: None,
                }
            }
            IP_PROTOCOL_UDP => {
                if message.len() < UDP_HEADER_LEN
                    || usize::from(u16::from_be_bytes([message[4], message[5]])) != message.len()
                {
                    return fate(BoxCounter::BadTransport);
                }
                let checksum = u16::from_be_bytes([message[6], message[7]]);
                if checksum != 0 && udp_checksum(source_ip, link.box_ip, message, true) != 0 {
                    return fate(BoxCounter::BadTransport);
                }
                if u16::from_be_bytes([message[2], message[3]]) != link.box_port {
                    return fate(BoxCounter::UnknownUdpPort);
                }
                let sender = Destination {
                    mac: source_mac,
                    ip: source_ip,
                    port: u16::from_be_bytes([message[0], message[1]]),
                };
                self.command(sender, &message[UDP_HEADER_LEN..], receive_tick)
            }
            _ => fate(BoxCounter::NotForUs),
        }
    }

    fn command(&mut self, sender: Destination, payload: &[u8], receive_tick: u64) -> Outcome {
        let refuse = |fate: BoxCounter| Outcome {
            fate,
            reply: None,
            effect: None,
        };
        if !self.config.link.in_host_subnet(sender.ip) {
            return refuse(BoxCounter::RefusedForeignSubnet);
        }
        let Ok(command) = Command::new_checked(payload) else {
            return refuse(BoxCounter::RefusedMalformed);
        };
        if !self.reply_slot_free {
            return refuse(BoxCounter::ReplyBusy);
        }
        let slot = self.hosts.iter().position(|(ip, _)| *ip == sender.ip);
        let last = slot.map(|i| self.hosts[i].1);
        let sequence = command.sequence();
        let (fate, result, effect, reply) =
            if command.box_id() != self.config.box_id && command.box_id() != ANY_BOX {
                (
                    BoxCounter::RefusedOtherBox,
                    AckResult::OtherBox,
                    None,
                    AckReply::None,
                )
            } else if last.is_some_and(|last| (sequence.wrapping_sub(last) as i32) <= 0) {
                (
                    BoxCounter::RefusedReplay,
                    AckResult::Replay,
                    None,
                    AckReply::None,
                )
            } else {
                // the sequence number is taken whatever the request
                if let Some(i) = slot {
                    self.hosts.remove(i);
                } else if self.hosts.len() == HOST_SLOTS {
                    self.hosts.remove(0);
                }
                self.hosts.push((sender.ip, sequence));
                match command.request(self.config.port_count) {
                    Err(Error::UnknownOpcode { .. }) => (
                        BoxCounter::RefusedUnknownOpcode,
                        AckResult::UnknownOpcode,
                        None,
                        AckReply::None,
                    ),
                    Err(_) => (
                        BoxCounter::RefusedBadArgument,
                        AckResult::BadArgument,
                        None,
                        AckReply::None,
                    ),
                    Ok(request) => self.carry_out(sender, request),
                }
            };
        let last_accepted = self
            .hosts
            .iter()
            .find(|(ip, _)| *ip == sender.ip)
            .map_or(0, |h| h.1);
        Outcome {
            fate,
            reply: Some(Reply::Ack {
                ack: AckRepr {
                    box_id: self.config.box_id,
                    port_count: self.config.port_count,
                    sequence,
                    host_time: command.host_time(),
                    opcode: command.opcode(),
                    result,
                    last_accepted,
                    receive_tick,
                    send_tick: 0,
                    reply,
                },
                to: sender,
            }),
            effect,
        }
    }

    fn carry_out(
        &mut self,
        sender: Destination,
        request: Request,
    ) -> (BoxCounter, AckResult, Option<Effect>, AckReply) {
        let ok = BoxCounter::CommandsAccepted;
        match request {
            Request::StreamTo { to } => {
                self.destination = to.unwrap_or(sender);
                (
                    ok,
                    AckResult::Ok,
                    Some(Effect::StreamTo(self.destination)),
                    AckReply::Destination(self.destination),
                )
            }
            Request::SetFlushTimeout { ticks } => {
                self.flush_timeout_ticks = ticks;
                (
                    ok,
                    AckResult::Ok,
                    Some(Effect::SetFlushTimeout(ticks)),
                    AckReply::None,
                )
            }
            Request::SetStatusPeriod { ticks } => {
                self.status_period_ticks = ticks;
                (
                    ok,
                    AckResult::Ok,
                    Some(Effect::SetStatusPeriod(ticks)),
                    AckReply::None,
                )
            }
            Request::StatusNow => (
                ok,
                AckResult::Ok,
                Some(Effect::StatusNow),
                // filled with the counters once this frame is counted
                AckReply::Counters(BoxCounters::default()),
            ),
            Request::ReadTick => (ok, AckResult::Ok, None, AckReply::None),
            Request::CellCommand { port, packet } => {
                let offer_tick = self.receive_tick + DOWNLINK_OFFER_AFTER_RECEIVE_TICK;
                if self.downlink.offer(offer_tick, port, packet) {
                    (ok, AckResult::Ok, None, AckReply::None)
                } else {
                    (
                        BoxCounter::RefusedDownlinkFull,
                        AckResult::DownlinkFull,
                        None,
                        AckReply::None,
                    )
                }
            }
        }
    }
}

impl Reply {
    /// The frame on the wire (preamble to FCS), an acknowledgement with `send_tick` as the
    /// tick of its first byte.
    pub fn frame(&self, link: &LinkConfig, send_tick: u64) -> Vec<u8> {
        match self {
            Reply::Arp(f) | Reply::Echo(f) => f.clone(),
            Reply::Ack { ack, to } => {
                let ack = AckRepr { send_tick, ..*ack };
                udp_frame(link, to, &ack.to_bytes())
            }
        }
    }

    /// The UDP payload of an acknowledgement with `send_tick` filled in (none for ARP and
    /// echo replies).
    pub fn ack_payload(&self, send_tick: u64) -> Option<(Vec<u8>, Destination)> {
        match self {
            Reply::Ack { ack, to } => Some((AckRepr { send_tick, ..*ack }.to_bytes(), *to)),
            _ => None,
        }
    }
}

/// The IEEE 802.3 CRC-32 of `bytes`, bit by bit as the gateware's `Crc32Byte` computes it
/// (reflected register from all ones, complemented at the end).
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut register = u32::MAX;
    for &b in bytes {
        register ^= u32::from(b);
        for _ in 0..8 {
            let low = register & 1;
            register >>= 1;
            if low != 0 {
                register ^= POLYNOMIAL_REFLECTED as u32;
            }
        }
    }
    !register
}

/// The one's complement of the one's complement sum of `parts` (RFC 1071): 0 over a
/// message whose checksum field is right, the checksum to write over one whose field is 0.
/// An odd part is padded with a zero byte (only the last part may be odd).
pub fn internet_checksum(parts: &[&[u8]]) -> u16 {
    let mut sum: u32 = 0;
    for part in parts {
        for pair in part.chunks(2) {
            let word = u16::from_be_bytes([pair[0], pair.get(1).copied().unwrap_or(0)]);
            sum += u32::from(word);
        }
    }
    while sum > 0xFFFF {
        sum = (sum & 0xFFFF) + (sum >> 16);
    }
    !(sum as u16)
}

/// The UDP checksum over the IPv4 pseudo header and `udp` (header and payload): with
/// `verify`, 0 when the field is right; else the value to write (the field zeroed, and a
/// result of 0 sent as 0xFFFF, RFC 768).
fn udp_checksum(source: [u8; 4], destination: [u8; 4], udp: &[u8], verify: bool) -> u16 {
    let len = (udp.len() as u16).to_be_bytes();
    let pseudo = [
        source[0],
        source[1],
        source[2],
        source[3],
        destination[0],
        destination[1],
        destination[2],
        destination[3],
        0,
        IP_PROTOCOL_UDP,
        len[0],
        len[1],
    ];
    let sum = internet_checksum(&[&pseudo, udp]);
    if verify || sum != 0 {
        sum
    } else {
        0xFFFF
    }
}

/// Preamble and SFD, `ethernet` padded with zeros to 60 bytes, and its FCS.
fn wire_frame(mut ethernet: Vec<u8>) -> Vec<u8> {
    ethernet.resize(ethernet.len().max(MIN_FRAME_LEN), 0);
    let fcs = crc32(&ethernet);
    let mut frame = Vec::with_capacity(PREAMBLE_LEN + ethernet.len() + FCS_LEN);
    frame.extend_from_slice(&[0x55; 7]);
    frame.push(0xD5);
    frame.extend_from_slice(&ethernet);
    frame.extend_from_slice(&fcs.to_le_bytes());
    frame
}

fn ethernet_header(destination: [u8; 6], source: [u8; 6], ethertype: u16) -> Vec<u8> {
    let mut h = Vec::with_capacity(MAX_RECEIVE_LEN);
    h.extend_from_slice(&destination);
    h.extend_from_slice(&source);
    h.extend_from_slice(&ethertype.to_be_bytes());
    h
}

/// The box's IPv4 header: no options, identification 0, don't fragment, TTL 64.
fn ipv4_header(
    protocol: u8,
    source: [u8; 4],
    destination: [u8; 4],
    payload_len: usize,
) -> [u8; 20] {
    let total = ((IPV4_HEADER_LEN + payload_len) as u16).to_be_bytes();
    let mut h = [
        0x45, 0, total[0], total[1], 0, 0, 0x40, 0, IPV4_TTL, protocol, 0, 0, 0, 0, 0, 0, 0, 0, 0,
        0,
    ];
    h[12..16].copy_from_slice(&source);
    h[16..20].copy_from_slice(&destination);
    let sum = internet_checksum(&[&h]);
    h[10..12].copy_from_slice(&sum.to_be_bytes());
    h
}

/// A UDP frame from the box's addresses and port to `to`, as the box's framer builds it.
pub fn udp_frame(link: &LinkConfig, to: &Destination, payload: &[u8]) -> Vec<u8> {
    let mut udp = Vec::with_capacity(UDP_HEADER_LEN + payload.len());
    udp.extend_from_slice(&link.box_port.to_be_bytes());
    udp.extend_from_slice(&to.port.to_be_bytes());
    udp.extend_from_slice(&((UDP_HEADER_LEN + payload.len()) as u16).to_be_bytes());
    udp.extend_from_slice(&[0, 0]);
    udp.extend_from_slice(payload);
    let sum = udp_checksum(link.box_ip, to.ip, &udp, false);
    udp[6..8].copy_from_slice(&sum.to_be_bytes());
    let mut e = ethernet_header(to.mac, link.box_mac, ETHERTYPE_IPV4);
    e.extend_from_slice(&ipv4_header(IP_PROTOCOL_UDP, link.box_ip, to.ip, udp.len()));
    e.extend_from_slice(&udp);
    wire_frame(e)
}

/// The reply to an ARP request for the box's IP (RFC 826), none for any other ARP message.
fn arp_reply(link: &LinkConfig, arp: &[u8]) -> Option<Vec<u8>> {
    let request_header = [0, 1, 8, 0, 6, 4, 0, 1];
    if arp[..8] != request_header || arp[24..28] != link.box_ip {
        return None;
    }
    let sender_mac: [u8; 6] = arp[8..14].try_into().expect("6 bytes");
    let mut e = ethernet_header(sender_mac, link.box_mac, ETHERTYPE_ARP);
    e.extend_from_slice(&[0, 1, 8, 0, 6, 4, 0, 2]);
    e.extend_from_slice(&link.box_mac);
    e.extend_from_slice(&link.box_ip);
    e.extend_from_slice(&arp[8..18]); // the requester's MAC and IP
    Some(wire_frame(e))
}

/// The echo reply to a checked echo request `message` (type 0, everything else copied).
fn echo_reply(link: &LinkConfig, mac: [u8; 6], ip: [u8; 4], message: &[u8]) -> Vec<u8> {
    let mut icmp = message.to_vec();
    icmp[0] = 0;
    icmp[2..4].fill(0);
    let sum = internet_checksum(&[&icmp]);
    icmp[2..4].copy_from_slice(&sum.to_be_bytes());
    let mut e = ethernet_header(mac, link.box_mac, ETHERTYPE_IPV4);
    e.extend_from_slice(&ipv4_header(IP_PROTOCOL_ICMP, link.box_ip, ip, icmp.len()));
    e.extend_from_slice(&icmp);
    wire_frame(e)
}
