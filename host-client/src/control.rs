//! Commanding a box: one command datagram, its acknowledgement, with timeout and retries.
//!
//! [`BoxClient`] sends [`Request`]s from a blocking UDP socket to a box (or `skinbox
//! emulate`) and waits for the acknowledgement that echoes the command's sequence number
//! and host time. Each attempt takes a fresh sequence number (every command is safe to
//! repeat), so a lost acknowledgement costs a retry, never a replay refusal; a replay
//! refusal (another program commanded the box from this host with newer numbers) moves the
//! numbering past the box's last accepted one and tries again. Datagrams of the box's
//! stream that arrive on the same socket meanwhile are kept for the caller
//! ([`Exchange::passed_over`]): `skinbox capture --claim` decodes them.
//!
//! An exchange records the four times of an NTP-style clock exchange: host send and
//! receive time (ns since the Unix epoch) and the box's receive and send ticks.

use skinbox_protocol::command::{
    peek_kind, AckRepr, AckResult, CommandRepr, Request, ANY_BOX, KIND_ACK,
};
use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Default wait for an acknowledgement per attempt.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_millis(250);
/// Default retries after the first attempt.
pub const DEFAULT_RETRIES: u32 = 3;
/// Most stream datagrams kept while waiting for one acknowledgement (more are counted).
pub const MAX_PASSED_OVER: usize = 4096;

/// Why a command got no acknowledgement.
#[derive(Debug, thiserror::Error)]
pub enum ControlError {
    /// The socket failed.
    #[error("command socket: {0}")]
    Io(#[from] io::Error),
    /// No acknowledgement within the timeout, on every attempt.
    #[error(
        "no acknowledgement from {box_addr} after {attempts} attempts of {timeout_ms} ms each"
    )]
    Timeout {
        /// The box.
        box_addr: SocketAddr,
        /// Attempts made.
        attempts: u32,
        /// Wait per attempt, ms.
        timeout_ms: u64,
    },
}

/// One command and its acknowledgement.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Exchange {
    /// The command as sent in the last attempt.
    pub command: CommandRepr,
    /// The acknowledgement.
    pub ack: AckRepr,
    /// Attempts it took (1 = no retry).
    pub attempts: u32,
    /// Host time the last attempt was sent, ns since the Unix epoch.
    pub host_send_ns: u64,
    /// Host time its acknowledgement was received, ns since the Unix epoch.
    pub host_receive_ns: u64,
    /// Round trip of the last attempt, ns (monotonic clock).
    pub rtt_ns: u64,
    /// Datagrams from the box's stream (not acknowledgements) received meanwhile, with
    /// their source, in order.
    #[serde(skip)]
    pub passed_over: Vec<(SocketAddr, Vec<u8>)>,
    /// Datagrams received meanwhile beyond [`MAX_PASSED_OVER`], or acknowledgements of
    /// other commands: dropped, counted here.
    pub dropped: u64,
}

/// Sends commands to one box.
#[derive(Debug)]
pub struct BoxClient<'s> {
    socket: &'s UdpSocket,
    box_addr: SocketAddr,
    /// Box id the commands address ([`ANY_BOX`] by default).
    pub box_id: u16,
    /// Wait per attempt.
    pub timeout: Duration,
    /// Retries after the first attempt.
    pub retries: u32,
    next_sequence: u32,
}

fn unix_ns() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64)
}

impl<'s> BoxClient<'s> {
    /// A client on `socket` (blocking; its read timeout is set per wait) for the box at
    /// `box_addr`. Sequence numbers start from the host's clock in milliseconds, so a new
    /// client on the same host starts above the numbers an earlier one used (for 24 days).
    pub fn new(socket: &'s UdpSocket, box_addr: SocketAddr) -> BoxClient<'s> {
        BoxClient {
            socket,
            box_addr,
            box_id: ANY_BOX,
            timeout: DEFAULT_TIMEOUT,
            retries: DEFAULT_RETRIES,
            // the host clock in microseconds: a client made after another one on this host
            // (a second `skinbox ctl`, even one started in the same millisecond as the
            // first one's last retry) starts past the first one's numbers (the numbers wrap
            // every 71.6 minutes, so a client after 35.8 minutes of silence may be taken
            // for a replay once: it then goes on past the box's number)
            next_sequence: (unix_ns() / 1_000) as u32,
        }
    }

    /// The box's address.
    pub fn box_addr(&self) -> SocketAddr {
        self.box_addr
    }

    /// Sends `request` and waits for its acknowledgement (any result: see `ack.result`).
    pub fn send(&mut self, request: Request) -> Result<Exchange, ControlError> {
        self.socket.set_nonblocking(false)?;
        let mut passed_over = Vec::new();
        let mut dropped = 0u64;
        let mut attempts = 0;
        let mut resynced = false;
        let mut buf = vec![0u8; 65536];
        while attempts <= self.retries {
            attempts += 1;
            let command = CommandRepr {
                box_id: self.box_id,
                sequence: self.next_sequence,
                host_time: unix_ns(),
                request,
            };
            self.next_sequence = self.next_sequence.wrapping_add(1);
            let sent_at = Instant::now();
            self.socket.send_to(&command.to_bytes(), self.box_addr)?;
            let deadline = sent_at + self.timeout;
            loop {
                let now = Instant::now();
                if now >= deadline {
                    break;
                }
                self.socket.set_read_timeout(Some(deadline - now))?;
                let (n, from) = match self.socket.recv_from(&mut buf) {
                    Ok(x) => x,
                    Err(e)
                        if matches!(
                            e.kind(),
                            io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                        ) =>
                    {
                        break
                    }
                    Err(e) => return Err(e.into()),
                };
                let host_receive_ns = unix_ns();
                let rtt_ns = sent_at.elapsed().as_nanos() as u64;
                let payload = &buf[..n];
                if peek_kind(payload) != Some(KIND_ACK) {
                    if passed_over.len() < MAX_PASSED_OVER {
                        passed_over.push((from, payload.to_vec()));
                    } else {
                        dropped += 1;
                    }
                    continue;
                }
                let ack = match AckRepr::parse(payload) {
                    Ok(a)
                        if from == self.box_addr
                            && a.sequence == command.sequence
                            && a.host_time == command.host_time =>
                    {
                        a
                    }
                    // a late acknowledgement of an earlier attempt, or not from this box
                    _ => {
                        dropped += 1;
                        continue;
                    }
                };
                if ack.result == AckResult::Replay && !resynced {
                    // numbered below what the box accepted from this host: go past it
                    resynced = true;
                    self.next_sequence = ack.last_accepted.wrapping_add(1);
                    attempts -= 1;
                    break;
                }
                return Ok(Exchange {
                    command,
                    ack,
                    attempts,
                    host_send_ns: command.host_time,
                    host_receive_ns,
                    rtt_ns,
                    passed_over,
                    dropped,
                });
            }
        }
        Err(ControlError::Timeout {
            box_addr: self.box_addr,
            attempts,
            timeout_ms: self.timeout.as_millis() as u64,
        })
    }
}

/// A box address (`host:port`) as its first IPv4 socket address.
pub fn resolve_ipv4(box_addr: &str) -> io::Result<SocketAddr> {
    use std::net::ToSocketAddrs;
    box_addr
        .to_socket_addrs()?
        .find(SocketAddr::is_ipv4)
        .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "no IPv4 address"))
}

/// The request of `set PARAMETER VALUE`: `flush-timeout-us` or `status-period-ms`, a
/// positive value, or `sync-period-ms`, 0 (the box sends no time syncs) or positive; else
/// why not.
pub fn set_request(parameter: &str, value: f64) -> Result<Request, String> {
    if parameter == "sync-period-ms" && value == 0.0 {
        return Ok(Request::SetSyncPeriod { ticks: 0 });
    }
    if !(value.is_finite() && value > 0.0) {
        return Err(format!("set {parameter}: {value} must be positive"));
    }
    match parameter {
        "flush-timeout-us" => Ok(Request::SetFlushTimeout {
            ticks: (value * 125.0).round().min(f64::from(u32::MAX)) as u32,
        }),
        "status-period-ms" => Ok(Request::SetStatusPeriod {
            ticks: (value * 125_000.0).round().min(f64::from(u32::MAX)) as u32,
        }),
        "sync-period-ms" => Ok(Request::SetSyncPeriod {
            ticks: (value * 125_000.0).round().min(f64::from(u32::MAX)) as u32,
        }),
        other => Err(format!(
            "set {other}: the parameters are flush-timeout-us, status-period-ms and \
             sync-period-ms"
        )),
    }
}

/// Why the box refused the command of `exchange`, or `None` when it accepted it.
pub fn refusal(exchange: &Exchange) -> Option<String> {
    match exchange.ack.result {
        AckResult::Ok => None,
        AckResult::DownlinkFull => Some(format!(
            "the box's downlink had no room (downlink_full): a target port already queues two \
             packets, or the previous cell command was still being queued; nothing was sent \
             down (sequence {}); send it again once the queue has drained (50 us a packet)",
            exchange.ack.sequence
        )),
        result => Some(format!(
            "the box refused the command: {} (last accepted sequence {})",
            result.name(),
            exchange.ack.last_accepted
        )),
    }
}

/// An exchange as `skinbox ctl --json` prints it: the command, its result, the four
/// times, and what the acknowledgement carries (destination or box counters).
pub fn exchange_json(e: &Exchange) -> serde_json::Value {
    use skinbox_protocol::command::{AckReply, Opcode};
    let op = Opcode::from_byte(e.ack.opcode).map_or("unknown", Opcode::name);
    let mut v = serde_json::json!({
        "command": op,
        "sequence": e.ack.sequence,
        "result": e.ack.result.name(),
        "last_accepted": e.ack.last_accepted,
        "attempts": e.attempts,
        "rtt_us": e.rtt_ns as f64 / 1000.0,
        "host_send_ns": e.host_send_ns,
        "box_receive_tick": e.ack.receive_tick,
        "box_send_tick": e.ack.send_tick,
        "host_receive_ns": e.host_receive_ns,
        "box_id": e.ack.box_id,
        "port_count": e.ack.port_count,
    });
    match &e.ack.reply {
        AckReply::None => {}
        AckReply::Destination(d) => {
            v["streaming_to"] = serde_json::json!({
                "ip": std::net::Ipv4Addr::from(d.ip).to_string(),
                "port": d.port,
                "mac": d.mac.iter().map(|b| format!("{b:02x}")).collect::<Vec<_>>().join(":"),
            })
        }
        AckReply::Counters(c) => {
            v["box_counters"] =
                serde_json::to_value(crate::report::BoxCountersReport::from(c)).unwrap_or_default()
        }
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use skinbox_protocol::command::{AckReply, Opcode};

    fn ack_for(command: &CommandRepr, result: AckResult, last_accepted: u32) -> Vec<u8> {
        AckRepr {
            box_id: 1,
            port_count: 4,
            sequence: command.sequence,
            host_time: command.host_time,
            opcode: command.request.opcode() as u8,
            result,
            last_accepted,
            receive_tick: 10,
            send_tick: 11,
            reply: AckReply::None,
        }
        .to_bytes()
    }

    /// A box on a thread that ignores the first command, answers the second as a replay
    /// (last accepted 5000) after a stream datagram, and accepts the third if it is 5001.
    #[test]
    fn retries_after_a_timeout_and_goes_past_a_replay() {
        let fake_box = UdpSocket::bind("127.0.0.1:0").unwrap();
        let box_addr = fake_box.local_addr().unwrap();
        let thread = std::thread::spawn(move || {
            let mut buf = [0u8; 256];
            let mut sequences = vec![];
            for step in 0..3 {
                let (n, from) = fake_box.recv_from(&mut buf).unwrap();
                let command = CommandRepr::parse(&buf[..n], 4).unwrap();
                sequences.push(command.sequence);
                match step {
                    0 => {}
                    1 => {
                        fake_box.send_to(b"a stream datagram", from).unwrap();
                        let ack = ack_for(&command, AckResult::Replay, 5000);
                        fake_box.send_to(&ack, from).unwrap();
                    }
                    _ => {
                        let ack = ack_for(&command, AckResult::Ok, command.sequence);
                        fake_box.send_to(&ack, from).unwrap();
                    }
                }
            }
            sequences
        });
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        let mut client = BoxClient::new(&socket, box_addr);
        client.timeout = Duration::from_millis(100);
        client.retries = 1;
        let e = client.send(Request::ReadTick).unwrap();
        let sequences = thread.join().unwrap();
        assert_eq!(sequences[1], sequences[0].wrapping_add(1));
        assert_eq!(sequences[2], 5001);
        assert_eq!((e.ack.result, e.ack.sequence), (AckResult::Ok, 5001));
        assert_eq!(e.ack.opcode, Opcode::ReadTick as u8);
        assert_eq!(e.attempts, 2);
        assert_eq!(e.passed_over.len(), 1);
        assert_eq!(e.passed_over[0].1, b"a stream datagram");
        assert!(e.host_send_ns <= e.host_receive_ns);
    }

    #[test]
    fn no_box_is_a_timeout_after_every_attempt() {
        let silent = UdpSocket::bind("127.0.0.1:0").unwrap();
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        let mut client = BoxClient::new(&socket, silent.local_addr().unwrap());
        client.timeout = Duration::from_millis(20);
        client.retries = 2;
        match client.send(Request::StatusNow) {
            Err(ControlError::Timeout { attempts, .. }) => assert_eq!(attempts, 3),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_decoder_counts_commands_and_acknowledgements_apart_from_bad_input() {
        let command = CommandRepr {
            box_id: 1,
            sequence: 1,
            host_time: 2,
            request: Request::ReadTick,
        };
        let mut decoder = crate::Decoder::new(crate::DecoderConfig::default());
        let outcome = decoder.push_datagram(&ack_for(&command, AckResult::Ok, 1), &mut ());
        assert_eq!(outcome, crate::decoder::DatagramOutcome::Acknowledgement);
        assert_eq!(decoder.bad_input_total(), 0);
        assert_eq!(decoder.report().acknowledgements, 1);
        let outcome = decoder.push_datagram(&command.to_bytes(), &mut ());
        assert_eq!(outcome, crate::decoder::DatagramOutcome::Command);
        assert_eq!(decoder.bad_input_total(), 0);
        assert_eq!(decoder.report().commands, 1);
    }
}
