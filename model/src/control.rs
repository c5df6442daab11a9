//! The box's control behaviour as one model: what the box does with every Ethernet frame
//! it receives. The receive path of the gateware follows it byte for byte, and `skinbox
//! emulate` runs it behind a real UDP socket.
//!
//! Every header is read and written through `skinbox_protocol::wire` (Ethernet II, ARP,
//! IPv4, ICMP echo, UDP); [`BoxControl::receive_udp`] takes a datagram that arrived on a
//! socket, where there is no frame, as its IPv4 and UDP representations.
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
use crate::timing::DOWNLINK_OFFER_AFTER_RECEIVE_TICK;
use skinbox_gateware::crc32::POLYNOMIAL_REFLECTED;
use skinbox_protocol::box_counters::{BoxCounter, BoxCounters, LinkSpeed};
use skinbox_protocol::command::{
    AckReply, AckRepr, AckResult, Command, Destination, Request, ANY_BOX,
};
use skinbox_protocol::link::{
    box_ipv4_header, LinkConfig, ETHERNET_HEADER_LEN, FCS_LEN, IPV4_HEADER_LEN, MIN_FRAME_LEN,
    PREAMBLE_LEN,
};
pub use skinbox_protocol::link::{
    ETHERTYPE_ARP, ETHERTYPE_IPV4, IP_PROTOCOL_ICMP, IP_PROTOCOL_UDP,
};
use skinbox_protocol::wire::ethernet::{EthernetFrame, BROADCAST};
use skinbox_protocol::wire::ipv4::Ipv4Packet;
use skinbox_protocol::wire::{
    ArpOperation, ArpRepr, EchoMessage, EthernetRepr, IcmpEchoRepr, Ipv4Repr, UdpRepr,
};
use skinbox_protocol::Error;

pub use skinbox_protocol::command::HOST_SLOTS;
pub use skinbox_protocol::link::{MAX_RECEIVE_LEN, MIN_RECEIVE_LEN};

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
    /// Time-sync period after reset, ticks (0: no syncs).
    pub sync_period_ticks: u32,
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
            sync_period_ticks: config.sync_period_ticks as u32,
            clock_hz: config.clock_hz,
            cell_baud: config.baud,
        }
    }
}

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
    /// The box's time syncs every this many ticks (0: none) from now on; the downlink
    /// model has it already.
    SetSyncPeriod(u32),
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
            )
            .with_sync_period(config.sync_period_ticks.into()),
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
        self.decide(receive_tick, reply_slot_free, |box_| {
            box_.classify(frame, receive_tick)
        })
    }

    /// Takes a UDP datagram that reached the box's address through a socket rather than a
    /// wire (the emulator): the IPv4 header `ip` and datagram `udp` it arrived with, from
    /// `source_mac`, at `receive_tick`, decided as the frame carrying them would be (with a
    /// free reply buffer): counted in `frames_received`; `bad_length` if it would not fit
    /// one frame; `not_for_us` to another address or over another protocol; then the UDP
    /// rules (port, command). There is no frame to check: no FCS, no checksums.
    pub fn receive_udp(
        &mut self,
        source_mac: [u8; 6],
        ip: &Ipv4Repr,
        udp: &UdpRepr,
        receive_tick: u64,
    ) -> Outcome {
        self.decide(receive_tick, true, |box_| {
            let fate = |fate: BoxCounter| Outcome {
                fate,
                reply: None,
                effect: None,
            };
            let frame_len = ETHERNET_HEADER_LEN + IPV4_HEADER_LEN + udp.buffer_len() + FCS_LEN;
            if frame_len > MAX_RECEIVE_LEN {
                return fate(BoxCounter::BadLength);
            }
            if ip.destination != box_.config.link.box_ip || ip.protocol != IP_PROTOCOL_UDP {
                return fate(BoxCounter::NotForUs);
            }
            box_.udp(source_mac, ip.source, udp, receive_tick)
        })
    }

    /// Counts a frame received at `receive_tick`, decides it with `classify` and counts its
    /// fate.
    fn decide(
        &mut self,
        receive_tick: u64,
        reply_slot_free: bool,
        classify: impl FnOnce(&mut BoxControl) -> Outcome,
    ) -> Outcome {
        self.reply_slot_free = reply_slot_free;
        self.receive_tick = receive_tick;
        self.counters.bump(BoxCounter::FramesReceived);
        let outcome = classify(self);
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
        let ethernet = EthernetFrame::new_unchecked(body);
        let broadcast = ethernet.destination() == BROADCAST;
        if ethernet.destination() != link.box_mac && !broadcast {
            return fate(BoxCounter::NotForUs);
        }
        match ethernet.ethertype() {
            ETHERTYPE_ARP => match arp_reply(&link, ethernet.payload()) {
                Some(_) if !self.reply_slot_free => fate(BoxCounter::ReplyBusy),
                Some(reply) => Outcome {
                    fate: BoxCounter::ArpAnswered,
                    reply: Some(Reply::Arp(reply)),
                    effect: None,
                },
                None => fate(BoxCounter::NotForUs),
            },
            ETHERTYPE_IPV4 if !broadcast => {
                self.ipv4(ethernet.source(), ethernet.payload(), receive_tick)
            }
            _ => fate(BoxCounter::NotForUs),
        }
    }

    /// An IPv4 packet (and the frame's padding after it) from `source_mac` to the box's MAC.
    fn ipv4(&mut self, source_mac: [u8; 6], bytes: &[u8], receive_tick: u64) -> Outcome {
        let fate = |fate: BoxCounter| Outcome {
            fate,
            reply: None,
            effect: None,
        };
        let link = self.config.link;
        // a frame of at least 64 bytes holds a 20-byte header
        let ip = Ipv4Packet::new_unchecked(bytes);
        if ip.version() != 4 || ip.ihl() < 5 {
            return fate(BoxCounter::Ipv4BadHeader);
        }
        if ip.ihl() > 5 {
            return fate(BoxCounter::Ipv4Options);
        }
        let Some(message) = ip.payload().filter(|_| ip.verify_checksum()) else {
            return fate(BoxCounter::Ipv4BadHeader);
        };
        if ip.more_fragments() || ip.fragment_offset() != 0 {
            return fate(BoxCounter::Ipv4Fragment);
        }
        if ip.destination() != link.box_ip {
            return fate(BoxCounter::NotForUs);
        }
        let source_ip = ip.source();
        match ip.protocol() {
            IP_PROTOCOL_ICMP => {
                let echo = match IcmpEchoRepr::parse(message) {
                    Err(Error::Truncated { .. } | Error::BadChecksum { .. }) => {
                        return fate(BoxCounter::BadTransport)
                    }
                    Ok(echo) if echo.message == EchoMessage::Request => echo,
                    _ => return fate(BoxCounter::NotForUs),
                };
                if !self.reply_slot_free {
                    return fate(BoxCounter::ReplyBusy);
                }
                Outcome {
                    fate: BoxCounter::PingsAnswered,
                    reply: Some(Reply::Echo(echo_reply(&link, source_mac, source_ip, &echo))),
                    effect: None,
                }
            }
            IP_PROTOCOL_UDP => {
                let Ok(udp) = UdpRepr::parse(message, source_ip, link.box_ip) else {
                    return fate(BoxCounter::BadTransport);
                };
                self.udp(source_mac, source_ip, &udp, receive_tick)
            }
            _ => fate(BoxCounter::NotForUs),
        }
    }

    /// A checked UDP datagram from `source_mac` and `source_ip` to the box.
    fn udp(
        &mut self,
        source_mac: [u8; 6],
        source_ip: [u8; 4],
        udp: &UdpRepr,
        receive_tick: u64,
    ) -> Outcome {
        if udp.destination_port != self.config.link.box_port {
            return Outcome {
                fate: BoxCounter::UnknownUdpPort,
                reply: None,
                effect: None,
            };
        }
        let sender = Destination {
            mac: source_mac,
            ip: source_ip,
            port: udp.source_port,
        };
        self.command(sender, udp.payload, receive_tick)
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
            Request::SetSyncPeriod { ticks } => {
                // applied in the clock a cell command would be offered
                let apply_tick = self.receive_tick + DOWNLINK_OFFER_AFTER_RECEIVE_TICK;
                self.downlink.set_sync_period(apply_tick, ticks.into());
                (
                    ok,
                    AckResult::Ok,
                    Some(Effect::SetSyncPeriod(ticks)),
                    AckReply::None,
                )
            }
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

/// Preamble and SFD, the Ethernet frame of `ethernet` with the `payload_len` bytes
/// `emit_payload` writes, padded with zeros to 60 bytes, and its FCS.
fn wire_frame(
    ethernet: EthernetRepr,
    payload_len: usize,
    emit_payload: impl FnOnce(&mut [u8]),
) -> Vec<u8> {
    let mut e = vec![0u8; (ETHERNET_HEADER_LEN + payload_len).max(MIN_FRAME_LEN)];
    ethernet.emit(&mut e);
    emit_payload(&mut e[ETHERNET_HEADER_LEN..ETHERNET_HEADER_LEN + payload_len]);
    let fcs = crc32(&e);
    let mut frame = Vec::with_capacity(PREAMBLE_LEN + e.len() + FCS_LEN);
    frame.extend_from_slice(&[0x55; 7]);
    frame.push(0xD5);
    frame.extend_from_slice(&e);
    frame.extend_from_slice(&fcs.to_le_bytes());
    frame
}

/// The wire frame of an IPv4 packet from the box (its header [`box_ipv4_header`]) to
/// `mac` and `ip`, with the `message_len` bytes `emit_message` writes.
fn ipv4_frame(
    link: &LinkConfig,
    mac: [u8; 6],
    ip: [u8; 4],
    protocol: u8,
    message_len: usize,
    emit_message: impl FnOnce(&mut [u8]),
) -> Vec<u8> {
    let ethernet = EthernetRepr {
        destination: mac,
        source: link.box_mac,
        ethertype: ETHERTYPE_IPV4,
    };
    let header: Ipv4Repr = box_ipv4_header(protocol, link.box_ip, ip, message_len);
    wire_frame(ethernet, header.buffer_len(), |b| {
        header.emit(b);
        emit_message(&mut b[IPV4_HEADER_LEN..]);
    })
}

/// A UDP frame from the box's addresses and port to `to`, as the box's framer builds it.
pub fn udp_frame(link: &LinkConfig, to: &Destination, payload: &[u8]) -> Vec<u8> {
    let udp = UdpRepr {
        source_port: link.box_port,
        destination_port: to.port,
        payload,
    };
    ipv4_frame(
        link,
        to.mac,
        to.ip,
        IP_PROTOCOL_UDP,
        udp.buffer_len(),
        |b| udp.emit(b, link.box_ip, to.ip),
    )
}

/// The reply to an ARP request for the box's IP (RFC 826), none for any other ARP message.
fn arp_reply(link: &LinkConfig, bytes: &[u8]) -> Option<Vec<u8>> {
    let request = ArpRepr::parse(bytes).ok()?;
    if request.operation != ArpOperation::Request || request.target_ip != link.box_ip {
        return None;
    }
    let reply = ArpRepr {
        operation: ArpOperation::Reply,
        sender_mac: link.box_mac,
        sender_ip: link.box_ip,
        target_mac: request.sender_mac,
        target_ip: request.sender_ip,
    };
    let ethernet = EthernetRepr {
        destination: request.sender_mac,
        source: link.box_mac,
        ethertype: ETHERTYPE_ARP,
    };
    Some(wire_frame(ethernet, reply.buffer_len(), |b| reply.emit(b)))
}

/// The echo reply to a checked echo `request`: identifier, sequence and data returned.
fn echo_reply(link: &LinkConfig, mac: [u8; 6], ip: [u8; 4], request: &IcmpEchoRepr) -> Vec<u8> {
    let reply = IcmpEchoRepr {
        message: EchoMessage::Reply,
        ..*request
    };
    ipv4_frame(link, mac, ip, IP_PROTOCOL_ICMP, reply.buffer_len(), |b| {
        reply.emit(b)
    })
}
