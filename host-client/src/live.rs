//! Live capture on a tokio UDP socket: the thin async shell around [`Decoder`].
//!
//! A full 1 Gbit/s link carries about 82,000 datagrams/s (4.5 M records/s, docs/design.md
//! section 5). The socket gets a large receive buffer so bursts wait in the kernel, and
//! after each wake-up the loop drains every queued datagram before it sleeps again. On
//! Linux it takes up to [`CaptureLimits::batch`] datagrams per system call (`recvmmsg`),
//! each with the kernel's receive timestamp (`SO_TIMESTAMPNS`), which a pcap recording
//! keeps; elsewhere it takes one datagram per call, timestamped when taken.
//!
//! The kernel may grant a smaller receive buffer than asked (Linux caps `SO_RCVBUF` at the
//! sysctl `net.core.rmem_max` unless the process has `CAP_NET_ADMIN`):
//! [`recv_buffer_warning`] says so and names the sysctl.

use crate::decoder::{Decoder, RecordSink};
use crate::pcap::{PcapError, PcapFrameWriter};
use serde::Serialize;
use socket2::{Domain, Protocol, Socket, Type};
use std::future::Future;
use std::io::{self, Write};
use std::net::SocketAddr;
use std::time::{Duration, Instant, SystemTime};
use tokio::net::UdpSocket;

/// Receive buffer asked for by default: about 0.4 s of a full link.
pub const DEFAULT_RECV_BUFFER_BYTES: usize = 64 << 20;

/// Datagrams taken per receive call by default.
pub const DEFAULT_BATCH: usize = 64;

/// Wait between draining the socket and waiting for it again, by default
/// ([`CaptureLimits::coalesce`]): none. Measured on loopback (`skinbox bench live`), a
/// 1 ms wait cut the receive calls from 1 per 2.6 datagrams to 1 per 51, but raised the
/// receiver's CPU per record from 55-61 ns to 65-75 ns: datagrams that wait go cold in the
/// cache, and the copy out of the kernel costs more than the calls saved.
pub const DEFAULT_COALESCE: Duration = Duration::ZERO;

/// Bytes of one receive slot: the box's largest payload is 1472 bytes; a longer datagram
/// is counted as bad input (`live: datagram longer than the receive slot`).
pub const SLOT_BYTES: usize = 2048;

/// The receive buffer the socket can use of what the kernel reports: Linux reports twice
/// the size asked for (the other half is its bookkeeping).
pub fn usable_recv_buffer(granted: usize) -> usize {
    if cfg!(target_os = "linux") {
        granted / 2
    } else {
        granted
    }
}

/// A warning when the kernel granted less receive buffer than `asked` (`granted` as
/// [`bind_udp`] returns it), naming the sysctl that allows more.
pub fn recv_buffer_warning(asked: usize, granted: usize) -> Option<String> {
    let usable = usable_recv_buffer(granted);
    (usable < asked).then(|| {
        format!(
            "warning: asked for a {asked}-byte receive buffer, the kernel granted {usable}; \
             bursts beyond it are lost. Raise the limit with \
             'sysctl -w net.core.rmem_max={asked}' (as root), or run with CAP_NET_ADMIN"
        )
    })
}

/// Binds a UDP socket with a receive buffer of (up to) `recv_buffer_bytes`; returns it and
/// the size the kernel granted (Linux reports twice the usable size and caps it at
/// `net.core.rmem_max` unless the process may override that). Call inside a tokio runtime.
pub fn bind_udp(addr: SocketAddr, recv_buffer_bytes: usize) -> io::Result<(UdpSocket, usize)> {
    let socket = Socket::new(Domain::for_address(addr), Type::DGRAM, Some(Protocol::UDP))?;
    // SO_RCVBUFFORCE passes net.core.rmem_max when the process may (CAP_NET_ADMIN);
    // otherwise SO_RCVBUF gets what the kernel allows.
    if !force_recv_buffer(&socket, recv_buffer_bytes) {
        let _ = socket.set_recv_buffer_size(recv_buffer_bytes);
    }
    let granted = socket.recv_buffer_size().unwrap_or(0);
    enable_timestamps(&socket);
    socket.set_nonblocking(true)?;
    socket.bind(&addr.into())?;
    let socket = UdpSocket::from_std(socket.into())?;
    Ok((socket, granted))
}

/// Sets the integer socket option `name` at level `SOL_SOCKET` on `fd`.
#[cfg(target_os = "linux")]
fn set_socket_int(fd: std::os::fd::RawFd, name: libc::c_int, value: libc::c_int) -> io::Result<()> {
    // SAFETY: setsockopt reads one c_int through a valid pointer of the given length.
    let rc = unsafe {
        libc::setsockopt(
            fd,
            libc::SOL_SOCKET,
            name,
            (&value as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
    if rc == 0 {
        Ok(())
    } else {
        Err(io::Error::last_os_error())
    }
}

#[cfg(target_os = "linux")]
fn force_recv_buffer(socket: &Socket, bytes: usize) -> bool {
    use std::os::fd::AsRawFd;
    let value = libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
    set_socket_int(socket.as_raw_fd(), libc::SO_RCVBUFFORCE, value).is_ok()
}

#[cfg(not(target_os = "linux"))]
fn force_recv_buffer(_socket: &Socket, _bytes: usize) -> bool {
    false
}

/// Asks for the kernel's receive timestamp of every datagram (SO_TIMESTAMPNS). Without
/// timestamps the capture stamps datagrams when it takes them.
#[cfg(target_os = "linux")]
fn enable_timestamps(socket: &Socket) {
    use std::os::fd::AsRawFd;
    let _ = set_socket_int(socket.as_raw_fd(), libc::SO_TIMESTAMPNS, 1);
}

#[cfg(not(target_os = "linux"))]
fn enable_timestamps(_socket: &Socket) {}

/// Asks the kernel to stamp every datagram `socket` receives (SO_TIMESTAMPNS: CLOCK_REALTIME
/// when the datagram entered the host's stack), for [`recv_stamped`]; an error where the
/// system has no such option.
pub fn enable_receive_timestamps(socket: &std::net::UdpSocket) -> io::Result<()> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        set_socket_int(socket.as_raw_fd(), libc::SO_TIMESTAMPNS, 1)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = socket;
        Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "no kernel receive timestamps on this system",
        ))
    }
}

/// One datagram from a blocking `socket` into `buf` (waiting as the socket's read timeout
/// says, or not at all with `dont_wait`): its length (cut to `buf`), sender and kernel
/// receive timestamp (since the Unix epoch; `None` unless [`enable_receive_timestamps`]
/// was granted). Errors as `recv_from`: `WouldBlock` or `TimedOut` when none came.
pub fn recv_stamped(
    socket: &std::net::UdpSocket,
    buf: &mut [u8],
    dont_wait: bool,
) -> io::Result<(usize, Option<SocketAddr>, Option<Duration>)> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        linux::recv_one(socket.as_raw_fd(), buf, dont_wait)
    }
    #[cfg(not(target_os = "linux"))]
    {
        socket.set_nonblocking(dont_wait)?;
        let got = socket.recv_from(buf);
        socket.set_nonblocking(false)?;
        got.map(|(n, peer)| (n.min(buf.len()), Some(peer), None))
    }
}

/// When a capture stops by itself, how often it reports progress, and how it receives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CaptureLimits {
    /// Stop after this many datagrams (any kind, good or bad).
    pub max_datagrams: Option<u64>,
    /// Interval of the progress callback.
    pub progress_every: Duration,
    /// Datagrams taken per receive call (1: one call per datagram).
    pub batch: usize,
    /// After draining the socket, wait this long before waiting for it again, so datagrams
    /// gather in the receive buffer and one wake-up takes many (0: wake when one is
    /// there). The wait runs on tokio's timer (1 ms resolution), so it adds up to about
    /// 2 ms of latency and needs that much receive buffer: 2 ms of a full link is 164
    /// datagrams. See [`DEFAULT_COALESCE`] for what it costs.
    pub coalesce: Duration,
}

impl Default for CaptureLimits {
    fn default() -> Self {
        CaptureLimits {
            max_datagrams: None,
            progress_every: Duration::from_secs(1),
            batch: DEFAULT_BATCH,
            coalesce: DEFAULT_COALESCE,
        }
    }
}

/// Counts of a running or finished capture.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct CaptureStats {
    /// Datagrams received.
    pub datagrams: u64,
    /// Payload bytes received.
    pub bytes: u64,
    /// Records decoded.
    pub records: u64,
    /// Receive system calls that returned datagrams.
    pub receive_calls: u64,
    /// Datagrams longer than [`SLOT_BYTES`], cut by the receive slot and not decoded.
    pub truncated: u64,
    /// Wall time since the start, in seconds.
    pub wall_s: f64,
    /// CPU time of the capturing thread (receiving and decoding), in seconds.
    pub cpu_s: f64,
}

impl CaptureStats {
    /// Receiving thread's CPU time per datagram, in nanoseconds.
    pub fn cpu_ns_per_datagram(&self) -> f64 {
        self.cpu_s * 1e9 / self.datagrams.max(1) as f64
    }

    /// Receiving thread's CPU time per record, in nanoseconds.
    pub fn cpu_ns_per_record(&self) -> f64 {
        self.cpu_s * 1e9 / self.records.max(1) as f64
    }
}

/// One received datagram: its length in its slot, sender, kernel timestamp.
#[derive(Debug, Clone, Copy)]
struct Received {
    len: usize,
    peer: Option<SocketAddr>,
    timestamp: Option<Duration>,
    truncated: bool,
}

/// Buffers of one batched receive call.
struct Batch {
    slots: Vec<u8>,
    received: Vec<Received>,
    #[cfg(target_os = "linux")]
    mm: linux::MmsgBuffers,
}

impl Batch {
    fn new(batch: usize) -> Self {
        let batch = batch.max(1);
        Batch {
            slots: vec![0; batch * SLOT_BYTES],
            received: Vec::with_capacity(batch),
            #[cfg(target_os = "linux")]
            mm: linux::MmsgBuffers::new(batch),
        }
    }

    fn slot(&self, i: usize) -> &[u8] {
        &self.slots[i * SLOT_BYTES..i * SLOT_BYTES + self.received[i].len]
    }

    /// Takes what is queued (up to the batch) without waiting; `WouldBlock` when nothing is.
    #[cfg(target_os = "linux")]
    fn receive(&mut self, socket: &UdpSocket) -> io::Result<usize> {
        use std::os::fd::AsRawFd;
        let fd = socket.as_raw_fd();
        let Batch {
            slots,
            received,
            mm,
        } = self;
        socket.try_io(tokio::io::Interest::READABLE, || {
            mm.receive(fd, slots, received)
        })
    }

    #[cfg(not(target_os = "linux"))]
    fn receive(&mut self, socket: &UdpSocket) -> io::Result<usize> {
        self.received.clear();
        let (len, peer) = socket.try_recv_from(&mut self.slots[..SLOT_BYTES])?;
        self.received.push(Received {
            len: len.min(SLOT_BYTES),
            peer: Some(peer),
            timestamp: None,
            truncated: len > SLOT_BYTES,
        });
        Ok(1)
    }
}

#[cfg(target_os = "linux")]
pub(crate) mod linux {
    //! `recvmmsg` with the sender's address and the SO_TIMESTAMPNS control message.
    use super::{Received, SLOT_BYTES};
    use crate::sockaddr::peer;
    use std::io;
    use std::net::SocketAddr;
    use std::os::fd::RawFd;
    use std::time::Duration;

    /// Control buffer of one message, aligned for `cmsghdr`: room for the SO_TIMESTAMPNS
    /// timespec (32 bytes) and, on a socket that also asks for SO_TIMESTAMPING (a capture
    /// sending read-tick commands), its scm_timestamping (64 bytes).
    type Control = [u64; 16];

    pub(super) struct MmsgBuffers {
        headers: Vec<libc::mmsghdr>,
        iovecs: Vec<libc::iovec>,
        names: Vec<libc::sockaddr_storage>,
        controls: Vec<Control>,
    }

    impl MmsgBuffers {
        pub(super) fn new(batch: usize) -> Self {
            // SAFETY: all-zero bytes are valid values of these plain C structs.
            let zeroed = || unsafe { std::mem::zeroed::<libc::mmsghdr>() };
            MmsgBuffers {
                headers: (0..batch).map(|_| zeroed()).collect(),
                iovecs: vec![
                    libc::iovec {
                        iov_base: std::ptr::null_mut(),
                        iov_len: 0
                    };
                    batch
                ],
                // SAFETY: as above.
                names: (0..batch).map(|_| unsafe { std::mem::zeroed() }).collect(),
                controls: vec![[0; 16]; batch],
            }
        }

        /// One `recvmmsg` call into `slots`, filling `received`.
        pub(super) fn receive(
            &mut self,
            fd: RawFd,
            slots: &mut [u8],
            received: &mut Vec<Received>,
        ) -> io::Result<usize> {
            let batch = self.headers.len();
            for i in 0..batch {
                self.iovecs[i] = libc::iovec {
                    iov_base: slots[i * SLOT_BYTES..].as_mut_ptr().cast(),
                    iov_len: SLOT_BYTES,
                };
                let h = &mut self.headers[i].msg_hdr;
                h.msg_name = (&mut self.names[i] as *mut libc::sockaddr_storage).cast();
                h.msg_namelen = std::mem::size_of::<libc::sockaddr_storage>() as libc::socklen_t;
                h.msg_iov = &mut self.iovecs[i];
                h.msg_iovlen = 1;
                h.msg_control = self.controls[i].as_mut_ptr().cast();
                h.msg_controllen = std::mem::size_of::<Control>() as _;
                h.msg_flags = 0;
                self.headers[i].msg_len = 0;
            }
            // SAFETY: every header points at live buffers of the lengths it names (slots
            // holds batch * SLOT_BYTES bytes); the kernel writes at most that much.
            let n = unsafe {
                libc::recvmmsg(
                    fd,
                    self.headers.as_mut_ptr(),
                    batch as libc::c_uint,
                    libc::MSG_DONTWAIT,
                    std::ptr::null_mut(),
                )
            };
            if n < 0 {
                return Err(io::Error::last_os_error());
            }
            let n = n as usize;
            received.clear();
            for i in 0..n {
                let m = &self.headers[i];
                received.push(Received {
                    len: (m.msg_len as usize).min(SLOT_BYTES),
                    peer: peer(&self.names[i], m.msg_hdr.msg_namelen),
                    timestamp: timestamp(&m.msg_hdr),
                    truncated: m.msg_hdr.msg_flags & libc::MSG_TRUNC != 0,
                });
            }
            Ok(n)
        }
    }

    /// One `recvmsg` into `buf`, with the sender and the SO_TIMESTAMPNS control message.
    pub(super) fn recv_one(
        fd: RawFd,
        buf: &mut [u8],
        dont_wait: bool,
    ) -> io::Result<(usize, Option<SocketAddr>, Option<Duration>)> {
        let mut iov = libc::iovec {
            iov_base: buf.as_mut_ptr().cast(),
            iov_len: buf.len(),
        };
        // SAFETY: all-zero bytes are valid values of these plain C structs.
        let mut name: libc::sockaddr_storage = unsafe { std::mem::zeroed() };
        let mut control: Control = [0; 16];
        // SAFETY: as above.
        let mut h: libc::msghdr = unsafe { std::mem::zeroed() };
        h.msg_name = (&mut name as *mut libc::sockaddr_storage).cast();
        h.msg_namelen = std::mem::size_of::<libc::sockaddr_storage>() as libc::socklen_t;
        h.msg_iov = &mut iov;
        h.msg_iovlen = 1;
        h.msg_control = control.as_mut_ptr().cast();
        h.msg_controllen = std::mem::size_of::<Control>() as _;
        let flags = if dont_wait { libc::MSG_DONTWAIT } else { 0 };
        // SAFETY: the header points at live buffers of the lengths it names; the kernel
        // writes at most that much.
        let n = unsafe { libc::recvmsg(fd, &mut h, flags) };
        if n < 0 {
            return Err(io::Error::last_os_error());
        }
        Ok((
            (n as usize).min(buf.len()),
            peer(&name, h.msg_namelen),
            timestamp(&h),
        ))
    }

    fn timestamp(h: &libc::msghdr) -> Option<Duration> {
        // SAFETY: the control buffer and its length are as the kernel left them; the
        // CMSG_* functions walk it within msg_controllen.
        unsafe {
            let mut c = libc::CMSG_FIRSTHDR(h);
            while !c.is_null() {
                if (*c).cmsg_level == libc::SOL_SOCKET && (*c).cmsg_type == libc::SCM_TIMESTAMPNS {
                    let ts: libc::timespec =
                        std::ptr::read_unaligned(libc::CMSG_DATA(c).cast::<libc::timespec>());
                    return Some(Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32));
                }
                c = libc::CMSG_NXTHDR(h, c);
            }
        }
        None
    }
}

/// Receives datagrams on `socket` into `decoder` and `sink` until `shutdown` resolves or
/// the limit is reached, recording every datagram to `recorder` if given (with the
/// kernel's receive timestamp where there is one). The progress callback sees the counts
/// every `limits.progress_every`.
pub async fn run_capture<S, W, F>(
    socket: &UdpSocket,
    decoder: &mut Decoder,
    sink: &mut S,
    mut recorder: Option<&mut PcapFrameWriter<W>>,
    limits: CaptureLimits,
    shutdown: F,
    progress: &mut dyn FnMut(&CaptureStats, &Decoder),
) -> Result<CaptureStats, CaptureError>
where
    S: RecordSink + ?Sized,
    W: Write,
    F: Future<Output = ()>,
{
    let local = socket.local_addr()?;
    let start = Instant::now();
    let cpu_start = crate::thread_cpu_ns();
    let mut stats = CaptureStats::default();
    let mut batch = Batch::new(limits.batch);
    let mut ticker = tokio::time::interval(limits.progress_every.max(Duration::from_millis(1)));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    ticker.tick().await;
    tokio::pin!(shutdown);
    let done = |s: &CaptureStats| limits.max_datagrams.is_some_and(|m| s.datagrams >= m);
    while !done(&stats) {
        let mut drained = false;
        tokio::select! {
            biased;
            _ = &mut shutdown => break,
            _ = ticker.tick() => {
                stats.records = decoder.records();
                stats.wall_s = start.elapsed().as_secs_f64();
                stats.cpu_s = crate::thread_cpu_ns().saturating_sub(cpu_start) as f64 * 1e-9;
                progress(&stats, decoder);
            }
            r = socket.readable() => {
                r?;
                // Drain what is queued, a batch per call, then wait again.
                while !done(&stats) {
                    let n = match batch.receive(socket) {
                        Ok(n) => n,
                        Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                        Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
                        Err(e) => return Err(e.into()),
                    };
                    stats.receive_calls += 1;
                    for i in 0..n {
                        if done(&stats) {
                            // Past the limit: the rest of the batch is not counted.
                            break;
                        }
                        let got = batch.received[i];
                        let payload = batch.slot(i);
                        stats.datagrams += 1;
                        stats.bytes += payload.len() as u64;
                        if got.truncated {
                            stats.truncated += 1;
                            decoder.bad_input_mut().count(
                                crate::bad_input::Reason::LiveTruncated,
                                || format!("live: datagram from {:?} longer than {SLOT_BYTES} bytes, not decoded", got.peer),
                            );
                            continue;
                        }
                        sink.datagram_received(got.timestamp, got.peer, payload);
                        decoder.push_datagram_from(got.peer, payload, sink);
                        if let Some(w) = recorder.as_deref_mut() {
                            let ts = got.timestamp.unwrap_or_else(|| {
                                SystemTime::now()
                                    .duration_since(SystemTime::UNIX_EPOCH)
                                    .unwrap_or_default()
                            });
                            let peer = got.peer.unwrap_or(local);
                            w.write_udp(ts, peer, local, payload)?;
                        }
                    }
                }
                drained = true;
            }
        }
        if drained && !limits.coalesce.is_zero() && !done(&stats) {
            tokio::select! {
                biased;
                _ = &mut shutdown => break,
                _ = tokio::time::sleep(limits.coalesce) => {}
            }
        }
    }
    stats.records = decoder.records();
    stats.wall_s = start.elapsed().as_secs_f64();
    stats.cpu_s = crate::thread_cpu_ns().saturating_sub(cpu_start) as f64 * 1e-9;
    Ok(stats)
}

/// A socket that claimed a box's stream ([`claim`]).
#[derive(Debug)]
pub struct Claimed {
    /// The capture's socket, now receiving the box's stream.
    pub socket: UdpSocket,
    /// The stream-to exchange; the capture decodes its passed-over datagrams first.
    pub exchange: crate::control::Exchange,
    /// The box's command address.
    pub box_addr: SocketAddr,
    /// A handle of the same socket to send commands from.
    pub sender: std::net::UdpSocket,
}

/// Why a claim failed; each names the box address as given.
#[derive(Debug, thiserror::Error)]
pub enum ClaimError {
    /// The address does not resolve to an IPv4 address.
    #[error("{box_addr}: {error}")]
    Address {
        /// The address as given.
        box_addr: String,
        /// Why not.
        error: io::Error,
    },
    /// The socket failed.
    #[error("{box_addr}: socket: {error}")]
    Io {
        /// The address as given.
        box_addr: String,
        /// The error.
        error: io::Error,
    },
    /// The box did not acknowledge.
    #[error("{box_addr}: {error}")]
    Control {
        /// The address as given.
        box_addr: String,
        /// The error.
        error: crate::control::ControlError,
    },
    /// The box refused the stream-to command.
    #[error("{box_addr}: the box refused stream-to: {result}")]
    Refused {
        /// The address as given.
        box_addr: String,
        /// The acknowledgement's result.
        result: &'static str,
    },
}

/// Claims the stream of the box at `box_addr` from `socket` (a stream-to of the sender),
/// so the box sends its datagrams to this socket.
pub fn claim(socket: UdpSocket, box_addr: &str) -> Result<Claimed, ClaimError> {
    let io_error = |error| ClaimError::Io {
        box_addr: box_addr.to_string(),
        error,
    };
    let addr = crate::control::resolve_ipv4(box_addr).map_err(|error| ClaimError::Address {
        box_addr: box_addr.to_string(),
        error,
    })?;
    let std_socket = socket.into_std().map_err(io_error)?;
    let exchange = crate::control::BoxClient::new(&std_socket, addr)
        .send(skinbox_protocol::command::Request::StreamTo { to: None })
        .map_err(|error| ClaimError::Control {
            box_addr: box_addr.to_string(),
            error,
        })?;
    if exchange.ack.result != skinbox_protocol::AckResult::Ok {
        return Err(ClaimError::Refused {
            box_addr: box_addr.to_string(),
            result: exchange.ack.result.name(),
        });
    }
    let sender = std_socket.try_clone().map_err(io_error)?;
    std_socket.set_nonblocking(true).map_err(io_error)?;
    Ok(Claimed {
        socket: UdpSocket::from_std(std_socket).map_err(io_error)?,
        exchange,
        box_addr: addr,
        sender,
    })
}

/// Sends a read-tick command to the box at `to` from `socket` every `every`, its host time
/// the send time (CLOCK_REALTIME, ns) and its sequence number the host clock in
/// microseconds (newer each time), until `stop`; returns the commands sent. The
/// acknowledgements arrive on the capture's socket, where a [`crate::timing::Timing`]
/// takes them as exchanges.
pub fn send_read_ticks(
    socket: std::net::UdpSocket,
    to: SocketAddr,
    box_id: u16,
    every: Duration,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<u64> {
    send_read_ticks_stamped(socket, to, box_id, every, stop, None)
}

/// How long the read-tick sender waits for a command's send stamp on the error queue.
pub const SEND_STAMP_WAIT: Duration = Duration::from_millis(5);

/// [`send_read_ticks`], and with `send_stamps` the kernel's send stamp of every command
/// ([`crate::kernel_stamps`]: SO_TIMESTAMPING turned on for `socket`, which the capture's
/// socket shares): each command's stamp, or why it has none, goes to `send_stamps` under
/// the command's host time, for the [`crate::timing::Timing`] that takes the
/// acknowledgements ([`crate::timing::Timing::with_send_stamps`]).
pub fn send_read_ticks_stamped(
    socket: std::net::UdpSocket,
    to: SocketAddr,
    box_id: u16,
    every: Duration,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    send_stamps: Option<crate::kernel_stamps::CommandSendStamps>,
) -> std::thread::JoinHandle<u64> {
    use crate::kernel_stamps::{self, Fallback, SendStamps};
    std::thread::spawn(move || {
        let stamped = send_stamps
            .as_ref()
            .map(|_| kernel_stamps::enable(&socket).is_ok());
        let mut from_error_queue = SendStamps::new();
        // the kernel numbers the datagrams sent after the option was set, from 0
        let mut send_id = 0u32;
        let mut sent = 0u64;
        let mut last_sequence = 0u32;
        while !stop.load(std::sync::atomic::Ordering::Relaxed) {
            let now_ns = crate::clock_map::host_clock::realtime_ns();
            let sequence = ((now_ns / 1_000) as u32).max(last_sequence.wrapping_add(1));
            last_sequence = sequence;
            let command = skinbox_protocol::command::CommandRepr {
                box_id,
                sequence,
                host_time: now_ns,
                request: skinbox_protocol::command::Request::ReadTick,
            };
            if socket.send_to(&command.to_bytes(), to).is_ok() {
                sent += 1;
                let after_ns = crate::clock_map::host_clock::realtime_ns();
                if let (Some(stamps), Some(enabled)) = (&send_stamps, stamped) {
                    let stamp = if enabled {
                        let stamp = from_error_queue.take(&socket, send_id, SEND_STAMP_WAIT);
                        send_id = send_id.wrapping_add(1);
                        kernel_stamps::checked_send_stamp(
                            stamp,
                            now_ns,
                            after_ns,
                            SEND_STAMP_WAIT.as_nanos() as u64,
                        )
                    } else {
                        Err(Fallback::NotEnabled)
                    };
                    stamps.record(now_ns, stamp);
                }
            }
            std::thread::sleep(every);
        }
        sent
    })
}

/// Why a capture stopped with an error.
#[derive(Debug, thiserror::Error)]
pub enum CaptureError {
    /// The socket failed.
    #[error("socket: {0}")]
    Io(#[from] io::Error),
    /// Recording to the pcap failed.
    #[error("{0}")]
    Pcap(#[from] PcapError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[cfg(target_os = "linux")]
    #[test]
    fn stamped_datagrams_carry_the_kernel_arrival_time_inside_the_send() {
        let epoch_ns = || {
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .as_nanos()
        };
        let receiver = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let sender = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        enable_receive_timestamps(&receiver).unwrap();
        let to = receiver.local_addr().unwrap();
        let mut buf = [0u8; 16];
        // the kernel turns its arrival stamps on in a deferred work item once a socket
        // asks (before, a datagram is stamped when read): wait for a probe stamped inside
        // its send
        let on = (0..500).any(|_| {
            let before = epoch_ns();
            sender.send_to(b"probe", to).unwrap();
            let after = epoch_ns();
            let (_, _, stamp) = recv_stamped(&receiver, &mut buf, false).unwrap();
            let inside = stamp.is_some_and(|s| (before..=after).contains(&s.as_nanos()));
            if !inside {
                std::thread::sleep(Duration::from_millis(10));
            }
            inside
        });
        assert!(on, "no arrival stamps within 5 s");
        let mut brackets = vec![];
        for i in 0..5u8 {
            let before = epoch_ns();
            sender.send_to(&[i; 30], to).unwrap();
            brackets.push((before, epoch_ns()));
        }
        for (i, (before, after)) in brackets.into_iter().enumerate() {
            let (n, from, stamp) = recv_stamped(&receiver, &mut buf, true).unwrap();
            assert_eq!(
                (n, from),
                (16, Some(sender.local_addr().unwrap())),
                "cut to buf"
            );
            assert_eq!(buf, [i as u8; 16]);
            let stamp = stamp.expect("a kernel timestamp").as_nanos();
            assert!(
                (before..=after).contains(&stamp),
                "{i}: {before} {stamp} {after}"
            );
        }
        let e = recv_stamped(&receiver, &mut buf, true).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::WouldBlock);
    }

    #[test]
    fn warns_only_when_granted_less_than_asked() {
        let reported = |usable: usize| {
            if cfg!(target_os = "linux") {
                2 * usable
            } else {
                usable
            }
        };
        assert_eq!(recv_buffer_warning(1 << 20, reported(1 << 20)), None);
        assert_eq!(recv_buffer_warning(1 << 20, reported(2 << 20)), None);
        let w = recv_buffer_warning(128 << 20, reported((128 << 20) - 1)).unwrap();
        assert!(w.contains("net.core.rmem_max=134217728"), "{w}");
        assert!(w.contains(&((128usize << 20) - 1).to_string()), "{w}");
    }
}
