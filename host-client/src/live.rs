//! Live capture on a tokio UDP socket: the thin async shell around [`Decoder`].
//!
//! A full 1 Gbit/s link carries about 82,000 datagrams/s (4.5 M records/s, DESIGN.md
//! section 5). The socket gets a large receive buffer so bursts wait in the kernel, and
//! after each wake-up the loop drains every queued datagram with `try_recv_from` before it
//! sleeps again, so the cost per datagram is one system call and the decoding.

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
    socket.set_nonblocking(true)?;
    socket.bind(&addr.into())?;
    let socket = UdpSocket::from_std(socket.into())?;
    Ok((socket, granted))
}

#[cfg(target_os = "linux")]
fn force_recv_buffer(socket: &Socket, bytes: usize) -> bool {
    use std::os::fd::AsRawFd;
    let value = libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
    // SAFETY: setsockopt reads one c_int through a valid pointer of the given length.
    let rc = unsafe {
        libc::setsockopt(
            socket.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_RCVBUFFORCE,
            (&value as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
    rc == 0
}

#[cfg(not(target_os = "linux"))]
fn force_recv_buffer(_socket: &Socket, _bytes: usize) -> bool {
    false
}

/// When a capture stops by itself, and how often it reports progress.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CaptureLimits {
    /// Stop after this many datagrams (any kind, good or bad).
    pub max_datagrams: Option<u64>,
    /// Interval of the progress callback.
    pub progress_every: Duration,
}

impl Default for CaptureLimits {
    fn default() -> Self {
        CaptureLimits {
            max_datagrams: None,
            progress_every: Duration::from_secs(1),
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
    /// Wall time since the start, in seconds.
    pub wall_s: f64,
    /// CPU time of the capturing thread, in seconds.
    pub cpu_s: f64,
}

/// Receives datagrams on `socket` into `decoder` and `sink` until `shutdown` resolves or
/// the limit is reached, recording every datagram to `recorder` if given. The progress
/// callback sees the counts every `limits.progress_every`.
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
    let mut buf = vec![0u8; 65_536];
    let mut ticker = tokio::time::interval(limits.progress_every.max(Duration::from_millis(1)));
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    ticker.tick().await;
    tokio::pin!(shutdown);
    let done = |s: &CaptureStats| limits.max_datagrams.is_some_and(|m| s.datagrams >= m);
    let mut take = |n: usize,
                    peer: SocketAddr,
                    buf: &[u8],
                    stats: &mut CaptureStats,
                    decoder: &mut Decoder|
     -> Result<(), CaptureError> {
        stats.datagrams += 1;
        stats.bytes += n as u64;
        decoder.push_datagram_from(Some(peer), &buf[..n], sink);
        if let Some(w) = recorder.as_deref_mut() {
            let now = SystemTime::now()
                .duration_since(SystemTime::UNIX_EPOCH)
                .unwrap_or_default();
            w.write_udp(now, peer, local, &buf[..n])?;
        }
        Ok(())
    };
    while !done(&stats) {
        tokio::select! {
            biased;
            _ = &mut shutdown => break,
            _ = ticker.tick() => {
                stats.records = decoder.records();
                stats.wall_s = start.elapsed().as_secs_f64();
                stats.cpu_s = crate::thread_cpu_ns().saturating_sub(cpu_start) as f64 * 1e-9;
                progress(&stats, decoder);
            }
            r = socket.recv_from(&mut buf) => {
                let (n, peer) = r?;
                take(n, peer, &buf, &mut stats, decoder)?;
                while !done(&stats) {
                    match socket.try_recv_from(&mut buf) {
                        Ok((n, peer)) => take(n, peer, &buf, &mut stats, decoder)?,
                        Err(e) if e.kind() == io::ErrorKind::WouldBlock => break,
                        Err(e) => return Err(e.into()),
                    }
                }
            }
        }
    }
    stats.records = decoder.records();
    stats.wall_s = start.elapsed().as_secs_f64();
    stats.cpu_s = crate::thread_cpu_ns().saturating_sub(cpu_start) as f64 * 1e-9;
    Ok(stats)
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
