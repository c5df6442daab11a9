//! A box without a board: the reference model of the box's uplink
//! ([`crate::reference::SlicedReference`]) and its control model
//! ([`crate::control::BoxControl`]) played together, free of I/O. `skinbox emulate` puts a
//! real UDP socket and a clock around it.
//!
//! A command payload from a UDP sender is wrapped into the Ethernet frame it would be on the
//! box's wire (the sender's IPv4 address and port, [`SENDER_MAC`]) and goes through the
//! control model exactly as a received frame would; its effects change the reference
//! model from that tick on: stream-to names where the datagrams go, set-flush-timeout and
//! set-status-period change the uplink's timing, status-now starts a report. Until a
//! stream-to claims the stream, the datagrams are counted but sent nowhere (the build-time
//! destination of a real box is a documentation address).

use crate::control::{crc32, BoxControl, ControlConfig, Effect, Reply};
use crate::reference::{PreparedReference, SlicedReference};
use crate::run::TICK_ZERO_CYCLE;
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::command::Destination;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::link::{LinkConfig, IPV4_TTL};
use std::net::SocketAddrV4;

/// The MAC address the emulator gives every UDP sender (there is no Ethernet on a socket).
pub const SENDER_MAC: [u8; 6] = [0x02, 0x00, 0x00, 0x00, 0x00, 0x01];

/// What the emulated box did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct EmulatorStats {
    /// Records datagrams sent to the claimed destination.
    pub records_datagrams_sent: u64,
    /// Status datagrams sent to the claimed destination.
    pub status_datagrams_sent: u64,
    /// Datagrams the box made before any stream-to claimed the stream: sent nowhere.
    pub datagrams_unclaimed: u64,
    /// Command payloads taken.
    pub commands_received: u64,
    /// Acknowledgements sent.
    pub acks_sent: u64,
}

/// A UDP payload to send, and where.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Outgoing {
    /// The payload.
    pub payload: Vec<u8>,
    /// The destination's IPv4 address and UDP port.
    pub to: SocketAddrV4,
}

fn socket_of(d: &Destination) -> SocketAddrV4 {
    SocketAddrV4::new(d.ip.into(), d.port)
}

/// The emulated box.
pub struct EmulatedBox<'a> {
    reference: SlicedReference<'a>,
    control: BoxControl,
    claimed: bool,
    /// What it did so far.
    pub stats: EmulatorStats,
}

/// The control parameters of a box built with `config`.
pub fn control_config(config: &BoxConfig) -> ControlConfig {
    ControlConfig::of(config)
}

impl<'a> EmulatedBox<'a> {
    /// The box of `config` leaving reset, its pins as `prepared` has them.
    pub fn new(prepared: &'a PreparedReference, config: &BoxConfig) -> EmulatedBox<'a> {
        let mut control = BoxControl::new(control_config(config));
        // an emulated PHY: up, speed not known
        control.counters.link_speed = skinbox_protocol::box_counters::LinkSpeed::Unknown;
        EmulatedBox {
            reference: prepared.start(),
            control,
            claimed: false,
            stats: EmulatorStats::default(),
        }
    }

    /// The control state (destination, timing, counters).
    pub fn control(&self) -> &BoxControl {
        &self.control
    }

    /// Runs the box up to box tick `tick`; returns the datagrams it sent meanwhile, to the
    /// claimed destination (none before a claim; they are counted).
    pub fn advance(&mut self, tick: u64) -> Vec<Outgoing> {
        let sent = self.reference.run_until(TICK_ZERO_CYCLE + tick);
        let mut out = Vec::with_capacity(sent.len());
        for s in sent {
            if !self.claimed {
                self.stats.datagrams_unclaimed += 1;
                continue;
            }
            let payload = match &s.datagram.body {
                DatagramBody::Status(_) => {
                    self.stats.status_datagrams_sent += 1;
                    s.datagram
                        .to_bytes_with_box_counters(&self.control.counters)
                }
                DatagramBody::Records(_) => {
                    self.stats.records_datagrams_sent += 1;
                    s.datagram.to_bytes()
                }
            };
            out.push(Outgoing {
                payload,
                to: socket_of(&self.control.destination),
            });
        }
        out
    }

    /// Takes a UDP payload from `from` at box tick `tick` (run the box there first with
    /// [`EmulatedBox::advance`]): the acknowledgement, with `send_tick()` as its send tick,
    /// if the control model answers.
    pub fn command(
        &mut self,
        from: SocketAddrV4,
        payload: &[u8],
        tick: u64,
        send_tick: impl FnOnce() -> u64,
    ) -> Option<Outgoing> {
        self.stats.commands_received += 1;
        let sender = Destination {
            mac: SENDER_MAC,
            ip: from.ip().octets(),
            port: from.port(),
        };
        let frame = command_frame(&self.control.config().link, &sender, payload);
        let outcome = self.control.receive(&frame, tick);
        // the pins of an emulated box go nowhere
        self.control.downlink.take_changes();
        match outcome.effect {
            Some(Effect::StreamTo(_)) => self.claimed = true,
            Some(Effect::SetFlushTimeout(t)) => self.reference.set_flush_timeout_ticks(t.into()),
            Some(Effect::SetStatusPeriod(t)) => self.reference.set_status_period_ticks(t.into()),
            Some(Effect::StatusNow) => self.reference.request_status(),
            None => {}
        }
        match outcome.reply {
            Some(reply @ Reply::Ack { .. }) => {
                let (payload, to) = reply.ack_payload(send_tick())?;
                self.stats.acks_sent += 1;
                Some(Outgoing {
                    payload,
                    to: socket_of(&to),
                })
            }
            _ => None,
        }
    }
}

/// The frame (destination MAC to FCS) a UDP payload from `sender` to the box makes on the
/// box's wire: Ethernet II, IPv4 without options (identification 0, don't fragment, TTL
/// 64), UDP with its checksum.
pub fn command_frame(link: &LinkConfig, sender: &Destination, payload: &[u8]) -> Vec<u8> {
    use crate::control::{internet_checksum, ETHERTYPE_IPV4, IP_PROTOCOL_UDP};
    let udp_len = (8 + payload.len()) as u16;
    let mut udp = Vec::with_capacity(usize::from(udp_len));
    udp.extend_from_slice(&sender.port.to_be_bytes());
    udp.extend_from_slice(&link.box_port.to_be_bytes());
    udp.extend_from_slice(&udp_len.to_be_bytes());
    udp.extend_from_slice(&[0, 0]);
    udp.extend_from_slice(payload);
    let l = udp_len.to_be_bytes();
    let mut pseudo = Vec::with_capacity(12);
    pseudo.extend_from_slice(&sender.ip);
    pseudo.extend_from_slice(&link.box_ip);
    pseudo.extend_from_slice(&[0, IP_PROTOCOL_UDP, l[0], l[1]]);
    let sum = match internet_checksum(&[&pseudo, &udp]) {
        0 => 0xFFFF,
        s => s,
    };
    udp[6..8].copy_from_slice(&sum.to_be_bytes());
    let total = (20 + udp.len() as u16).to_be_bytes();
    let mut ip = [
        0x45,
        0,
        total[0],
        total[1],
        0,
        0,
        0x40,
        0,
        IPV4_TTL,
        IP_PROTOCOL_UDP,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
        0,
    ];
    ip[12..16].copy_from_slice(&sender.ip);
    ip[16..20].copy_from_slice(&link.box_ip);
    let sum = internet_checksum(&[&ip]);
    ip[10..12].copy_from_slice(&sum.to_be_bytes());
    let mut e = Vec::with_capacity(14 + 20 + udp.len() + 4);
    e.extend_from_slice(&link.box_mac);
    e.extend_from_slice(&sender.mac);
    e.extend_from_slice(&ETHERTYPE_IPV4.to_be_bytes());
    e.extend_from_slice(&ip);
    e.extend_from_slice(&udp);
    e.resize(e.len().max(60), 0);
    let fcs = crc32(&e);
    e.extend_from_slice(&fcs.to_le_bytes());
    e
}
