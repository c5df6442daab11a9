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
            next_sequence: (unix_ns() / 1_000_000) as u32,
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
