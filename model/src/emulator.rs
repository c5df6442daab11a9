//! A box without a board: the reference model of the box's uplink
//! ([`crate::reference::SlicedReference`]) and its control model
//! ([`crate::control::BoxControl`]) played together, free of I/O: box ticks and received
//! command payloads in, the box's UDP payloads out. `skinbox emulate` (the
//! `skinbox-emulator` crate) puts a real UDP socket and a clock around it.
//!
//! A command payload from a UDP sender goes to the control model as what arrived on the
//! socket: an IPv4 header from the sender's address to the box's and a UDP datagram from
//! its port to the box's ([`deliver`]), which the model decides as the frame carrying them
//! would be; its effects change the reference model from that tick on: stream-to names
//! where the datagrams go, set-flush-timeout and set-status-period change the uplink's timing, status-now starts a report. Until a
//! stream-to claims the stream, the datagrams are counted but sent nowhere (the build-time
//! destination of a real box is a documentation address).
//!
//! A cell command the control model queues goes out on the downlink model's transmit pins,
//! where the cells' UART receivers ([`crate::cell_uart`]) decode it
//! ([`EmulatedBox::take_received`]). The downlink's pins depend on the host's commands
//! and the box's sync period alone, so a packet's bits are known once it is queued: the
//! receivers take them at the command, ahead of the box's time, and the box's own syncs
//! before the uplink runs past their start ([`EmulatedBox::hear_downlink`]); whoever plays
//! the cells has them before the cells can act on them; a port whose cells then send
//! otherwise is given its new pin ([`EmulatedBox::replace_port`]).

use crate::cell_uart::{CellUartReceiver, ReceivedPacket};
use crate::control::{BoxControl, ControlConfig, Effect, Outcome, Reply};
use crate::downlink::DownlinkModel;
use crate::pins::Transition;
use crate::reference::{PreparedReference, SlicedReference};
use crate::timing::TICK_ZERO_CYCLE;
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::command::Destination;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::link::{IPV4_TTL, IP_PROTOCOL_UDP};
use skinbox_protocol::wire::{Ipv4Repr, UdpRepr};
use std::net::SocketAddrV4;

/// The MAC address the emulator gives every UDP sender: a socket shows none, and the
/// control model keeps one for each sender (stream-to's destination names it).
pub const SENDER_MAC: [u8; 6] = [0x02, 0x00, 0x00, 0x00, 0x00, 0x01];

/// What the emulated box did so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct EmulatorStats {
    /// Records datagrams sent to the claimed destination.
    pub records_datagrams_sent: u64,
    /// Records (cell packets) in them.
    pub records_sent: u64,
    /// Status datagrams sent to the claimed destination.
    pub status_datagrams_sent: u64,
    /// Datagrams the box made before any stream-to claimed the stream: sent nowhere.
    pub datagrams_unclaimed: u64,
    /// Command payloads taken.
    pub commands_received: u64,
    /// Acknowledgements sent.
    pub acks_sent: u64,
    /// Cell command packets the cells' receivers decoded from the transmit pins.
    pub cell_commands_heard: u64,
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
    /// Where the datagrams go, once a stream-to claimed them.
    claimed: Option<Destination>,
    /// Effects on the uplink not yet applied, with the ticks they apply at, in order.
    effects: std::collections::VecDeque<(u64, Effect)>,
    /// The downlink run ahead of the commands, to the uplink's tick: the box's own syncs
    /// (a copy of the control model's, taken again at each command).
    ahead: DownlinkModel,
    receivers: CellUartReceiver,
    /// Per port, the tick up to which the receivers have the pin (exclusive).
    heard_until: Vec<u64>,
    received: Vec<ReceivedPacket>,
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
            ahead: control.downlink.clone(),
            control,
            claimed: None,
            effects: Default::default(),
            receivers: CellUartReceiver::new(config.ports, config.clock_hz, config.baud),
            heard_until: vec![0; config.ports],
            received: Vec::new(),
            stats: EmulatorStats::default(),
        }
    }

    /// The control state (destination, timing, counters).
    pub fn control(&self) -> &BoxControl {
        &self.control
    }

    /// Runs the box up to box tick `tick`, applying the commands' effects on the uplink at
    /// their ticks; returns the datagrams it sent meanwhile, to the claimed destination
    /// (none before a claim; they are counted).
    pub fn advance(&mut self, tick: u64) -> Vec<Outgoing> {
        let mut out = Vec::new();
        while let Some(&(at, effect)) = self.effects.front().filter(|e| e.0 <= tick) {
            self.run_to(at, &mut out);
            self.effects.pop_front();
            match effect {
                Effect::StreamTo(to) => self.claimed = Some(to),
                Effect::SetFlushTimeout(t) => self.reference.set_flush_timeout_ticks(t.into()),
                Effect::SetStatusPeriod(t) => self.reference.set_status_period_ticks(t.into()),
                Effect::StatusNow => self.reference.request_status(),
                Effect::SetSyncPeriod(t) => self.reference.set_sync_period_ticks(t.into()),
            }
        }
        self.run_to(tick, &mut out);
        out
    }

    fn run_to(&mut self, tick: u64, out: &mut Vec<Outgoing>) {
        for s in self.reference.run_until(TICK_ZERO_CYCLE + tick) {
            let Some(to) = self.claimed else {
                self.stats.datagrams_unclaimed += 1;
                continue;
            };
            let payload = match &s.datagram.body {
                DatagramBody::Status(_) => {
                    self.stats.status_datagrams_sent += 1;
                    s.datagram
                        .to_bytes_with_box_counters(&self.control.counters)
                }
                DatagramBody::Records(records) => {
                    self.stats.records_datagrams_sent += 1;
                    self.stats.records_sent += records.len() as u64;
                    s.datagram.to_bytes()
                }
            };
            out.push(Outgoing {
                payload,
                to: socket_of(&to),
            });
        }
    }

    /// The cycle the uplink has run to.
    pub fn cycle(&self) -> u64 {
        self.reference.cycle()
    }

    /// The cell command packets the cells' receivers decoded since the last call, in port
    /// order, each port's in order (each with the tick its first start bit leaves the box).
    pub fn take_received(&mut self) -> Vec<ReceivedPacket> {
        std::mem::take(&mut self.received)
    }

    /// Port `port`'s pin carries `transitions` from [`EmulatedBox::cycle`] on (the cells'
    /// packets after they acted on a command); fails when they differ before it.
    pub fn replace_port(&mut self, port: usize, transitions: &[Transition]) -> Result<(), String> {
        self.reference.replace_port(port, transitions)
    }

    /// The receivers take the transmit pins of every packet queued so far and of every
    /// sync of the box's own that starts before box tick `until` (a copy of the downlink
    /// runs them out: later commands only queue behind); call it before the uplink runs
    /// to `until`, so whoever plays the cells has the syncs first. Each command does it. A command taken after that at a
    /// tick before such a sync's period starts, to a port left idle until then, would
    /// have gone ahead of it on the pin: the cells hear it after the sync instead.
    pub fn hear_downlink(&mut self, until: u64) {
        self.ahead.advance_to(until);
        let mut ahead = self.ahead.clone();
        self.ahead.take_changes();
        let end = ahead.drain();
        for c in ahead.changes() {
            if c.tick >= self.heard_until[c.port] {
                self.receivers.push(c);
                self.heard_until[c.port] = c.tick + 1;
            }
        }
        let packets = self.receivers.advance_to(end);
        self.stats.cell_commands_heard += packets.len() as u64;
        self.received.extend(packets);
        // (a long-running box keeps memory bounded)
        self.control.downlink.take_changes();
    }

    /// Takes a UDP payload from `from` at box tick `tick` (ticks never go back): the
    /// acknowledgement, with `send_tick()` as its send tick, if the control model answers.
    /// Its effect on the uplink applies when [`EmulatedBox::advance`] reaches the later of
    /// `tick` and the tick the uplink had reached.
    pub fn command(
        &mut self,
        from: SocketAddrV4,
        payload: &[u8],
        tick: u64,
        send_tick: impl FnOnce() -> u64,
    ) -> Option<Outgoing> {
        self.stats.commands_received += 1;
        let outcome = deliver(&mut self.control, from, payload, tick);
        self.ahead = self.control.downlink.clone();
        self.hear_downlink(tick);
        if let Some(effect) = outcome.effect {
            self.effects.push_back((tick, effect));
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

/// Hands `control` a UDP payload that arrived on the box's socket from `from` at box tick
/// `tick`: the IPv4 header (from `from`'s address to the box's, UDP; the socket shows no
/// other field, so they are those of a plain unfragmented packet: TTL 64, don't fragment)
/// and the UDP datagram (from `from`'s port to the box's), from [`SENDER_MAC`].
pub fn deliver(control: &mut BoxControl, from: SocketAddrV4, payload: &[u8], tick: u64) -> Outcome {
    let link = control.config().link;
    let udp = UdpRepr {
        source_port: from.port(),
        destination_port: link.box_port,
        payload,
    };
    let ip = Ipv4Repr {
        source: from.ip().octets(),
        destination: link.box_ip,
        protocol: IP_PROTOCOL_UDP,
        payload_len: udp.buffer_len(),
        dscp_ecn: 0,
        identification: 0,
        dont_fragment: true,
        ttl: IPV4_TTL,
    };
    control.receive_udp(SENDER_MAC, &ip, &udp, tick)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::udp_frame;
    use skinbox_protocol::command::{CommandRepr, Request};
    use skinbox_protocol::link::LinkConfig;
    use skinbox_protocol::link::PREAMBLE_LEN;

    /// What [`deliver`] hands the control model is decided exactly as the frame that
    /// would carry the datagram on the box's wire: same fate, reply, effect and counters.
    #[test]
    fn a_delivered_datagram_is_decided_as_its_frame_would_be() {
        let config = ControlConfig {
            link: LinkConfig::DEFAULT,
            box_id: 1,
            port_count: 4,
            flush_timeout_ticks: 12_500,
            status_period_ticks: 12_500_000,
            sync_period_ticks: 12_500_000,
            clock_hz: skinbox_gateware::CLOCK_HZ,
            cell_baud: skinbox_gateware::CELL_BAUD,
        };
        let (mut delivered, mut framed) = (BoxControl::new(config), BoxControl::new(config));
        let link = config.link;
        let to_box = Destination {
            mac: link.box_mac,
            ip: link.box_ip,
            port: link.box_port,
        };
        let command = |box_id, sequence, request| {
            CommandRepr {
                box_id,
                sequence,
                host_time: 7,
                request,
            }
            .to_bytes()
        };
        let host: SocketAddrV4 = "192.0.2.1:40000".parse().unwrap();
        let foreign: SocketAddrV4 = "198.51.100.7:40000".parse().unwrap();
        let cases = [
            (host, command(1, 1, Request::ReadTick)),
            (host, command(1, 2, Request::StreamTo { to: None })),
            (host, command(1, 2, Request::ReadTick)), // a replay
            (host, command(9, 3, Request::ReadTick)), // another box
            (
                host,
                command(1, 4, Request::SetFlushTimeout { ticks: 2_000 }),
            ),
            (host, command(1, 5, Request::StatusNow)),
            (host, vec![0x53, 0x4B, 1]), // malformed
            (host, vec![0; 1473]),       // more than one frame holds
            (foreign, command(1, 1, Request::ReadTick)),
        ];
        let mut fates = vec![];
        for (tick, (from, payload)) in (1_000u64..).step_by(1_000).zip(&cases) {
            let sender = LinkConfig {
                box_mac: SENDER_MAC,
                box_ip: from.ip().octets(),
                box_port: from.port(),
                ..link
            };
            let frame = udp_frame(&sender, &to_box, payload);
            let expected = framed.receive(&frame[PREAMBLE_LEN..], tick);
            let got = deliver(&mut delivered, *from, payload, tick);
            assert_eq!(got, expected, "{from}, {} bytes", payload.len());
            assert_eq!(delivered.counters, framed.counters);
            fates.push(got.fate);
        }
        use skinbox_protocol::box_counters::BoxCounter::*;
        assert_eq!(
            fates,
            [
                CommandsAccepted,
                CommandsAccepted,
                RefusedReplay,
                RefusedOtherBox,
                CommandsAccepted,
                CommandsAccepted,
                RefusedMalformed,
                BadLength,
                RefusedForeignSubnet,
            ]
        );
    }
}
