//! Kernel timestamps of a UDP socket's sends and receives (`SO_TIMESTAMPING`, Linux).
//!
//! [`enable`] asks the kernel to stamp every datagram the socket sends (software: when the
//! driver takes it, `skb_tx_timestamp`) and receives (software: when it entered the
//! host's stack), and to report hardware stamps where the NIC takes them ([`FLAGS`]).
//! [`recv`] returns a datagram with its receive stamp (the `SCM_TIMESTAMPING` control
//! message: `struct scm_timestamping`, three timespecs, `[0]` software, `[2]` raw
//! hardware). Each sent datagram's stamp arrives on the socket's error queue, numbered by
//! the kernel from 0 in send order (`SOF_TIMESTAMPING_OPT_ID`) and without the payload
//! (`SOF_TIMESTAMPING_OPT_TSONLY`): [`SendStamps::take`] reads it.
//!
//! Software stamps are CLOCK_REALTIME (ns since the Unix epoch), the clock of the capture's
//! other host times. Hardware stamps are the NIC's own clock (its PTP hardware clock):
//! they are only comparable with each other, so an exchange takes them only when both of
//! its stamps are hardware stamps ([`ExchangeStamps::pick`]). A NIC stamps only once it is
//! told to (`SIOCSHWTSTAMP`, e.g. `hwstamp_ctl -i eth0 -t 1 -r 1` as root; docs/time.md).
//!
//! The kernel gives no stamp in a few cases (no `SO_TIMESTAMPING` on this system, the
//! first datagrams after enabling receive stamps, an error queue that overflowed): the
//! caller then falls back to its own user-space stamps and counts why ([`Fallback`]).

use std::io;
use std::net::{SocketAddr, UdpSocket};
use std::time::Duration;

/// A datagram's kernel stamps, ns: software (CLOCK_REALTIME) and hardware (the NIC's
/// clock), each where the kernel gave it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct KernelStamp {
    /// Software stamp, ns since the Unix epoch (CLOCK_REALTIME).
    pub software_ns: Option<u64>,
    /// Raw hardware stamp, ns on the NIC's clock.
    pub hardware_ns: Option<u64>,
}

impl KernelStamp {
    /// Whether the kernel gave any stamp.
    pub fn is_some(&self) -> bool {
        self.software_ns.is_some() || self.hardware_ns.is_some()
    }

    /// `other`'s stamps where this one has none (the kernel reports a send's software and
    /// hardware stamps in two messages).
    fn merge(&mut self, other: KernelStamp) {
        self.software_ns = self.software_ns.or(other.software_ns);
        self.hardware_ns = self.hardware_ns.or(other.hardware_ns);
    }
}

/// Which stamps an exchange's send and receive times are.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StampSource {
    /// The kernel's software stamps (CLOCK_REALTIME).
    KernelSoftware,
    /// The NIC's hardware stamps (its own clock).
    KernelHardware,
    /// The program's own clock readings around the send and the receive.
    UserSpace,
}

impl StampSource {
    /// Name in reports.
    pub fn name(self) -> &'static str {
        match self {
            StampSource::KernelSoftware => "kernel_software",
            StampSource::KernelHardware => "kernel_hardware",
            StampSource::UserSpace => "user_space",
        }
    }
}

/// Why an exchange fell back to user-space stamps.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Fallback {
    /// The socket has no kernel stamps (`SO_TIMESTAMPING` refused or not on this system).
    NotEnabled,
    /// The error queue gave no stamp for the send in time.
    NoSendStamp,
    /// The reply came without a receive stamp.
    NoReceiveStamp,
    /// Send and receive stamps of no common clock (one software only, one hardware only).
    NoCommonClock,
    /// The send stamp lies outside the `send_to` call that sent it (a numbering out of
    /// step, or a clock step): not taken.
    SendStampOutOfRange,
}

impl Fallback {
    /// Name in reports.
    pub fn name(self) -> &'static str {
        match self {
            Fallback::NotEnabled => "not_enabled",
            Fallback::NoSendStamp => "no_send_stamp",
            Fallback::NoReceiveStamp => "no_receive_stamp",
            Fallback::NoCommonClock => "no_common_clock",
            Fallback::SendStampOutOfRange => "send_stamp_out_of_range",
        }
    }
}

/// An exchange's host send and receive times, ns, and where they came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ExchangeStamps {
    /// Host send time, ns.
    pub send_ns: u64,
    /// Host receive time, ns.
    pub receive_ns: u64,
    /// Their source.
    pub source: StampSource,
    /// Why they are user-space stamps, when they are.
    pub fallback: Option<Fallback>,
}

impl ExchangeStamps {
    /// The kernel's stamps of a send and its reply where both have one on a common clock
    /// (hardware first), else the user-space ones (`user_send_ns`, `user_receive_ns`) with
    /// the reason. Never a mix of the two.
    pub fn pick(
        send: Option<KernelStamp>,
        receive: Option<KernelStamp>,
        user_send_ns: u64,
        user_receive_ns: u64,
    ) -> ExchangeStamps {
        let user = |fallback| ExchangeStamps {
            send_ns: user_send_ns,
            receive_ns: user_receive_ns,
            source: StampSource::UserSpace,
            fallback: Some(fallback),
        };
        let Some(send) = send.filter(KernelStamp::is_some) else {
            return user(Fallback::NoSendStamp);
        };
        let Some(receive) = receive.filter(KernelStamp::is_some) else {
            return user(Fallback::NoReceiveStamp);
        };
        let kernel = |send_ns, receive_ns, source| ExchangeStamps {
            send_ns,
            receive_ns,
            source,
            fallback: None,
        };
        match (send, receive) {
            (
                KernelStamp {
                    hardware_ns: Some(s),
                    ..
                },
                KernelStamp {
                    hardware_ns: Some(r),
                    ..
                },
            ) => kernel(s, r, StampSource::KernelHardware),
            (
                KernelStamp {
                    software_ns: Some(s),
                    ..
                },
                KernelStamp {
                    software_ns: Some(r),
                    ..
                },
            ) => kernel(s, r, StampSource::KernelSoftware),
            _ => user(Fallback::NoCommonClock),
        }
    }
}

/// The `SO_TIMESTAMPING` flags [`enable`] sets: software send and receive stamps, reported
/// (`SOFTWARE`); the hardware ones generated and reported (`RAW_HARDWARE`) where the NIC
/// was told to stamp; sends numbered (`OPT_ID`) and reported without their payload
/// (`OPT_TSONLY`).
#[cfg(target_os = "linux")]
pub const FLAGS: u32 = libc::SOF_TIMESTAMPING_TX_SOFTWARE
    | libc::SOF_TIMESTAMPING_RX_SOFTWARE
    | libc::SOF_TIMESTAMPING_SOFTWARE
    | libc::SOF_TIMESTAMPING_TX_HARDWARE
    | libc::SOF_TIMESTAMPING_RX_HARDWARE
    | libc::SOF_TIMESTAMPING_RAW_HARDWARE
    | libc::SOF_TIMESTAMPING_OPT_ID
    | libc::SOF_TIMESTAMPING_OPT_TSONLY;

/// [`FLAGS`] without the send stamps: for a socket whose error queue nobody reads (its
/// stamps would fill it, and it shares the receive buffer with the datagrams).
#[cfg(target_os = "linux")]
pub const RECEIVE_FLAGS: u32 = libc::SOF_TIMESTAMPING_RX_SOFTWARE
    | libc::SOF_TIMESTAMPING_SOFTWARE
    | libc::SOF_TIMESTAMPING_RX_HARDWARE
    | libc::SOF_TIMESTAMPING_RAW_HARDWARE;

/// Turns on the kernel's send and receive stamps of `socket` ([`FLAGS`]). The sends'
/// numbering starts at 0 with the first datagram sent after the first call. Every send
/// then queues a stamp on the error queue: read them ([`SendStamps`]). An error where the
/// system has no `SO_TIMESTAMPING`.
pub fn enable(socket: &UdpSocket) -> io::Result<()> {
    #[cfg(target_os = "linux")]
    return set_flags(socket, FLAGS);
    #[cfg(not(target_os = "linux"))]
    unsupported(socket)
}

/// Turns on the kernel's receive stamps of `socket` only ([`RECEIVE_FLAGS`]).
pub fn enable_receive(socket: &UdpSocket) -> io::Result<()> {
    #[cfg(target_os = "linux")]
    return set_flags(socket, RECEIVE_FLAGS);
    #[cfg(not(target_os = "linux"))]
    unsupported(socket)
}

#[cfg(not(target_os = "linux"))]
fn unsupported(_socket: &UdpSocket) -> io::Result<()> {
    Err(io::Error::new(
        io::ErrorKind::Unsupported,
        "no SO_TIMESTAMPING on this system",
    ))
}

#[cfg(target_os = "linux")]
fn set_flags(socket: &UdpSocket, flags: u32) -> io::Result<()> {
    {
        use std::os::fd::AsRawFd;
        let flags = flags as libc::c_int;
        // SAFETY: setsockopt reads one c_int through a valid pointer of the given length.
        let rc = unsafe {
            libc::setsockopt(
                socket.as_raw_fd(),
                libc::SOL_SOCKET,
                libc::SO_TIMESTAMPING,
                (&flags as *const libc::c_int).cast(),
                std::mem::size_of::<libc::c_int>() as libc::socklen_t,
            )
        };
        if rc == 0 {
            Ok(())
        } else {
            Err(io::Error::last_os_error())
        }
    }
}

/// One datagram from a blocking `socket` into `buf` (waiting as its read timeout says):
/// its length (cut to `buf`), sender, and receive stamp (empty unless [`enable`]d and the
/// kernel stamped it). Errors as `recv_from`: `WouldBlock` or `TimedOut` when none came.
pub fn recv(
    socket: &UdpSocket,
    buf: &mut [u8],
) -> io::Result<(usize, Option<SocketAddr>, KernelStamp)> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let got = linux::recv(socket.as_raw_fd(), buf, 0)?;
        Ok((got.len, got.peer, got.stamp))
    }
    #[cfg(not(target_os = "linux"))]
    {
        let (n, peer) = socket.recv_from(buf)?;
        Ok((n.min(buf.len()), Some(peer), KernelStamp::default()))
    }
}

/// Most send stamps [`SendStamps`] keeps before the oldest go.
pub const MAX_PENDING_SEND_STAMPS: usize = 1024;

/// The send stamps of a socket, read from its error queue and kept by send number until
/// taken.
#[derive(Debug, Default)]
pub struct SendStamps {
    pending: std::collections::BTreeMap<u32, KernelStamp>,
    /// Error-queue messages that were no send stamp (e.g. an ICMP error), or stamps
    /// dropped beyond [`MAX_PENDING_SEND_STAMPS`].
    pub ignored: u64,
}

impl SendStamps {
    /// No stamps yet.
    pub fn new() -> SendStamps {
        SendStamps::default()
    }

    /// The stamp of the `id`-th datagram sent (from 0) on `socket`, waiting up to `wait`
    /// for it; `None` when none came. Stamps of other sends read meanwhile are kept.
    pub fn take(&mut self, socket: &UdpSocket, id: u32, wait: Duration) -> Option<KernelStamp> {
        let deadline = std::time::Instant::now() + wait;
        loop {
            self.drain(socket);
            if let Some(stamp) = self.pending.remove(&id) {
                // a hardware stamp comes in a message of its own: take it if it is there
                return Some(stamp);
            }
            let now = std::time::Instant::now();
            if now >= deadline || !wait_for_error_queue(socket, deadline - now) {
                self.drain(socket);
                return self.pending.remove(&id);
            }
        }
    }

    /// Reads every message waiting on `socket`'s error queue.
    pub fn drain(&mut self, socket: &UdpSocket) {
        #[cfg(target_os = "linux")]
        {
            use std::os::fd::AsRawFd;
            let mut buf = [0u8; 64];
            while let Ok(got) = linux::recv(
                socket.as_raw_fd(),
                &mut buf,
                libc::MSG_ERRQUEUE | libc::MSG_DONTWAIT,
            ) {
                match got.send_id {
                    Some(id) if got.stamp.is_some() => {
                        self.pending.entry(id).or_default().merge(got.stamp);
                        while self.pending.len() > MAX_PENDING_SEND_STAMPS {
                            self.pending.pop_first();
                            self.ignored += 1;
                        }
                    }
                    _ => self.ignored += 1,
                }
            }
        }
        #[cfg(not(target_os = "linux"))]
        let _ = socket;
    }
}

/// Most entries [`CommandSendStamps`] keeps before the oldest go.
pub const MAX_COMMAND_SEND_STAMPS: usize = 256;

/// Kernel send stamps of commands, by the host time each command carries (which its
/// acknowledgement echoes), handed from the thread that sends them to the one that takes
/// their acknowledgements (`skinbox capture --claim`: [`crate::live::send_read_ticks`] to
/// [`crate::timing::Timing`]). Each entry is the software send stamp (CLOCK_REALTIME, ns)
/// or why there is none.
#[derive(Debug, Clone, Default)]
pub struct CommandSendStamps(std::sync::Arc<CommandStampQueue>);

/// Commands' host times and send stamps, oldest first, and a signal for each new one.
#[derive(Debug, Default)]
struct CommandStampQueue {
    entries: std::sync::Mutex<std::collections::VecDeque<(u64, Result<u64, Fallback>)>>,
    recorded: std::sync::Condvar,
}

impl CommandSendStamps {
    /// None yet.
    pub fn new() -> CommandSendStamps {
        CommandSendStamps::default()
    }

    /// The command of host time `host_time` was sent at `stamp` (or why not known).
    pub fn record(&self, host_time: u64, stamp: Result<u64, Fallback>) {
        let mut q = self.0.entries.lock().unwrap_or_else(|e| e.into_inner());
        q.push_back((host_time, stamp));
        while q.len() > MAX_COMMAND_SEND_STAMPS {
            q.pop_front();
        }
        self.0.recorded.notify_all();
    }

    /// The send stamp of the command of host time `host_time`, taken out; `None` when none
    /// was recorded (not yet, or long ago).
    pub fn take(&self, host_time: u64) -> Option<Result<u64, Fallback>> {
        self.take_waiting(host_time, Duration::ZERO)
    }

    /// [`CommandSendStamps::take`], waiting up to `wait` for it to be recorded (an
    /// acknowledgement may come before the sending thread has read its command's stamp).
    pub fn take_waiting(&self, host_time: u64, wait: Duration) -> Option<Result<u64, Fallback>> {
        let deadline = std::time::Instant::now() + wait;
        let mut q = self.0.entries.lock().unwrap_or_else(|e| e.into_inner());
        loop {
            if let Some(at) = q.iter().position(|(t, _)| *t == host_time) {
                return q.remove(at).map(|(_, stamp)| stamp);
            }
            let now = std::time::Instant::now();
            if now >= deadline {
                return None;
            }
            q = self
                .0
                .recorded
                .wait_timeout(q, deadline - now)
                .map(|(q, _)| q)
                .unwrap_or_else(|e| e.into_inner().0);
        }
    }
}

/// The software send stamp of a datagram whose `send_to` call ran from `before_ns` to
/// `after_ns` (CLOCK_REALTIME), if it lies in that call or up to `late_ns` after (a NIC
/// queue may hold it); else why it is not taken.
pub fn checked_send_stamp(
    stamp: Option<KernelStamp>,
    before_ns: u64,
    after_ns: u64,
    late_ns: u64,
) -> Result<u64, Fallback> {
    let ns = stamp
        .and_then(|s| s.software_ns)
        .ok_or(Fallback::NoSendStamp)?;
    if ns < before_ns || ns > after_ns.saturating_add(late_ns) {
        return Err(Fallback::SendStampOutOfRange);
    }
    Ok(ns)
}

/// What a network interface can stamp, as the kernel reports it (`SIOCETHTOOL`
/// `ETHTOOL_GET_TS_INFO`, what `ethtool -T` prints).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct InterfaceStamping {
    /// Software send stamps (`SOF_TIMESTAMPING_TX_SOFTWARE`).
    pub software_send: bool,
    /// Software receive stamps (`SOF_TIMESTAMPING_RX_SOFTWARE`).
    pub software_receive: bool,
    /// Hardware send stamps (`SOF_TIMESTAMPING_TX_HARDWARE`): the NIC can, once told to
    /// (`SIOCSHWTSTAMP`).
    pub hardware_send: bool,
    /// Hardware receive stamps (`SOF_TIMESTAMPING_RX_HARDWARE`).
    pub hardware_receive: bool,
    /// The NIC's PTP hardware clock (`/dev/ptpN`), if it has one.
    pub phc_index: Option<u32>,
}

/// What the interface `name` (e.g. `eth0`, `lo`) can stamp; an error when there is no such
/// interface or the system cannot say.
pub fn interface_stamping(name: &str) -> io::Result<InterfaceStamping> {
    #[cfg(target_os = "linux")]
    {
        linux::interface_stamping(name)
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = name;
        Err(io::Error::new(
            io::ErrorKind::Unsupported,
            "no SIOCETHTOOL on this system",
        ))
    }
}

/// Waits up to `wait` for `socket`'s error queue; whether something is there.
fn wait_for_error_queue(socket: &UdpSocket, wait: Duration) -> bool {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        // events 0: poll reports only POLLERR, which a queued error-queue message raises
        let mut fd = libc::pollfd {
            fd: socket.as_raw_fd(),
            events: 0,
            revents: 0,
        };
        let ms = wait.as_millis().clamp(1, i32::MAX as u128) as libc::c_int;
        // SAFETY: poll reads and writes one pollfd through a valid pointer.
        let n = unsafe { libc::poll(&mut fd, 1, ms) };
        n > 0 && fd.revents & libc::POLLERR != 0
    }
    #[cfg(not(target_os = "linux"))]
    {
        let _ = (socket, wait);
        false
    }
}

#[cfg(target_os = "linux")]
mod linux {
    //! `recvmsg` with the `SCM_TIMESTAMPING` and `IP_RECVERR` control messages.
    use super::KernelStamp;
    use crate::sockaddr::peer;
    use std::io;
    use std::net::SocketAddr;
    use std::os::fd::RawFd;

    /// Control buffer, aligned for `cmsghdr`: room for `scm_timestamping` (48 bytes),
    /// `sock_extended_err` with its address, and an `SO_TIMESTAMPNS` timespec.
    type Control = [u64; 32];

    /// `ee_info` of a send stamp (`SCM_TSTAMP_SND` in linux/errqueue.h).
    const SCM_TSTAMP_SND: u32 = 0;

    /// `struct ethtool_ts_info` (linux/ethtool.h).
    #[repr(C)]
    #[derive(Default)]
    struct EthtoolTsInfo {
        cmd: u32,
        so_timestamping: u32,
        phc_index: i32,
        tx_types: u32,
        tx_reserved: [u32; 3],
        rx_filters: u32,
        rx_reserved: [u32; 3],
    }

    /// `ETHTOOL_GET_TS_INFO` (linux/ethtool.h).
    const ETHTOOL_GET_TS_INFO: u32 = 0x41;

    pub(super) fn interface_stamping(name: &str) -> io::Result<super::InterfaceStamping> {
        use std::os::fd::AsRawFd;
        let bytes = name.as_bytes();
        if bytes.is_empty() || bytes.len() >= libc::IFNAMSIZ || bytes.contains(&0) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("{name:?} is no interface name (1 to 15 bytes, no NUL)"),
            ));
        }
        let socket = std::net::UdpSocket::bind("0.0.0.0:0")?;
        let mut info = EthtoolTsInfo {
            cmd: ETHTOOL_GET_TS_INFO,
            ..EthtoolTsInfo::default()
        };
        // SAFETY: all-zero bytes are a valid ifreq (a name and a union of plain fields).
        let mut request: libc::ifreq = unsafe { std::mem::zeroed() };
        for (to, from) in request.ifr_name.iter_mut().zip(bytes) {
            *to = *from as libc::c_char;
        }
        request.ifr_ifru.ifru_data = (&mut info as *mut EthtoolTsInfo).cast();
        // SAFETY: SIOCETHTOOL reads the NUL-terminated name and writes one ethtool_ts_info
        // through ifru_data, which points at `info`, alive for the call.
        let rc = unsafe {
            libc::ioctl(
                socket.as_raw_fd(),
                libc::SIOCETHTOOL as _,
                &mut request as *mut libc::ifreq,
            )
        };
        if rc != 0 {
            let e = io::Error::last_os_error();
            return Err(io::Error::new(
                e.kind(),
                format!("{name}: ETHTOOL_GET_TS_INFO: {e}"),
            ));
        }
        let has = |flag: u32| info.so_timestamping & flag != 0;
        Ok(super::InterfaceStamping {
            software_send: has(libc::SOF_TIMESTAMPING_TX_SOFTWARE),
            software_receive: has(libc::SOF_TIMESTAMPING_RX_SOFTWARE),
            hardware_send: has(libc::SOF_TIMESTAMPING_TX_HARDWARE),
            hardware_receive: has(libc::SOF_TIMESTAMPING_RX_HARDWARE),
            phc_index: u32::try_from(info.phc_index).ok(),
        })
    }

    pub(super) struct Received {
        pub len: usize,
        pub peer: Option<SocketAddr>,
        pub stamp: KernelStamp,
        /// The send number of an error-queue send stamp.
        pub send_id: Option<u32>,
    }

    pub(super) fn recv(fd: RawFd, buf: &mut [u8], flags: libc::c_int) -> io::Result<Received> {
        let mut iov = libc::iovec {
            iov_base: buf.as_mut_ptr().cast(),
            iov_len: buf.len(),
        };
        // SAFETY: all-zero bytes are valid values of these plain C structs.
        let mut name: libc::sockaddr_storage = unsafe { std::mem::zeroed() };
        let mut control: Control = [0; 32];
        // SAFETY: as above.
        let mut h: libc::msghdr = unsafe { std::mem::zeroed() };
        h.msg_name = (&mut name as *mut libc::sockaddr_storage).cast();
        h.msg_namelen = std::mem::size_of::<libc::sockaddr_storage>() as libc::socklen_t;
        h.msg_iov = &mut iov;
        h.msg_iovlen = 1;
        h.msg_control = control.as_mut_ptr().cast();
        h.msg_controllen = std::mem::size_of::<Control>() as _;
        // SAFETY: the header points at live buffers of the lengths it names; the kernel
        // writes at most that much.
        let n = unsafe { libc::recvmsg(fd, &mut h, flags) };
        if n < 0 {
            return Err(io::Error::last_os_error());
        }
        let (stamp, send_id) = control_messages(&h);
        Ok(Received {
            len: (n as usize).min(buf.len()),
            peer: peer(&name, h.msg_namelen),
            stamp,
            send_id,
        })
    }

    fn ns(ts: &libc::timespec) -> Option<u64> {
        let ns = u64::try_from(ts.tv_sec)
            .ok()?
            .checked_mul(1_000_000_000)?
            .checked_add(u64::try_from(ts.tv_nsec).ok()?)?;
        (ns != 0).then_some(ns)
    }

    /// The stamps of `SCM_TIMESTAMPING` and the send number of a send stamp's
    /// `sock_extended_err`.
    fn control_messages(h: &libc::msghdr) -> (KernelStamp, Option<u32>) {
        let mut stamp = KernelStamp::default();
        let mut send_id = None;
        // SAFETY: the control buffer and its length are as the kernel left them; the
        // CMSG_* functions walk it within msg_controllen, and each payload is read
        // unaligned within its message's length, checked first.
        unsafe {
            let mut c = libc::CMSG_FIRSTHDR(h);
            while !c.is_null() {
                let data = libc::CMSG_DATA(c);
                let len = ((*c).cmsg_len as usize).saturating_sub(data as usize - c as usize);
                let (level, kind) = ((*c).cmsg_level, (*c).cmsg_type);
                if level == libc::SOL_SOCKET
                    && kind == libc::SCM_TIMESTAMPING
                    && len >= 3 * std::mem::size_of::<libc::timespec>()
                {
                    let ts: [libc::timespec; 3] = std::ptr::read_unaligned(data.cast());
                    stamp.software_ns = ns(&ts[0]);
                    stamp.hardware_ns = ns(&ts[2]);
                } else if ((level == libc::SOL_IP && kind == libc::IP_RECVERR)
                    || (level == libc::SOL_IPV6 && kind == libc::IPV6_RECVERR))
                    && len >= std::mem::size_of::<libc::sock_extended_err>()
                {
                    let e: libc::sock_extended_err = std::ptr::read_unaligned(data.cast());
                    if e.ee_errno == libc::ENOMSG as u32
                        && e.ee_origin == libc::SO_EE_ORIGIN_TIMESTAMPING
                        && e.ee_info == SCM_TSTAMP_SND
                    {
                        send_id = Some(e.ee_data);
                    }
                }
                c = libc::CMSG_NXTHDR(h, c);
            }
        }
        (stamp, send_id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_exchange_takes_kernel_stamps_of_one_clock_or_says_why_not() {
        let sw = |ns| KernelStamp {
            software_ns: Some(ns),
            hardware_ns: None,
        };
        let both = |s, h| KernelStamp {
            software_ns: Some(s),
            hardware_ns: Some(h),
        };
        let hw = |ns| KernelStamp {
            software_ns: None,
            hardware_ns: Some(ns),
        };
        let p = ExchangeStamps::pick(Some(sw(10)), Some(sw(20)), 5, 25);
        assert_eq!(
            (p.send_ns, p.receive_ns, p.source, p.fallback),
            (10, 20, StampSource::KernelSoftware, None)
        );
        let p = ExchangeStamps::pick(Some(both(10, 1)), Some(both(20, 2)), 5, 25);
        assert_eq!((p.send_ns, p.receive_ns), (1, 2));
        assert_eq!(p.source, StampSource::KernelHardware);
        let p = ExchangeStamps::pick(Some(both(10, 1)), Some(sw(20)), 5, 25);
        assert_eq!((p.send_ns, p.source), (10, StampSource::KernelSoftware));
        for (send, receive, why) in [
            (None, Some(sw(20)), Fallback::NoSendStamp),
            (
                Some(KernelStamp::default()),
                Some(sw(20)),
                Fallback::NoSendStamp,
            ),
            (Some(sw(10)), None, Fallback::NoReceiveStamp),
            (Some(hw(1)), Some(sw(20)), Fallback::NoCommonClock),
        ] {
            let p = ExchangeStamps::pick(send, receive, 5, 25);
            assert_eq!((p.send_ns, p.receive_ns), (5, 25));
            assert_eq!((p.source, p.fallback), (StampSource::UserSpace, Some(why)));
        }
    }

    #[test]
    fn command_send_stamps_are_taken_once_by_host_time_and_checked_against_the_send() {
        let stamps = CommandSendStamps::new();
        let sender = stamps.clone();
        sender.record(100, Ok(105));
        sender.record(200, Err(Fallback::NoSendStamp));
        assert_eq!(stamps.take(200), Some(Err(Fallback::NoSendStamp)));
        assert_eq!(stamps.take(100), Some(Ok(105)));
        assert_eq!(stamps.take(100), None);
        for t in 0..MAX_COMMAND_SEND_STAMPS as u64 + 1 {
            sender.record(t, Ok(t));
        }
        assert_eq!(stamps.take(0), None, "the oldest went");
        assert_eq!(stamps.take(1), Some(Ok(1)));
        // a stamp recorded while the taker waits
        let late = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            sender.record(7_000, Ok(7_001));
        });
        assert_eq!(
            stamps.take_waiting(7_000, Duration::from_secs(5)),
            Some(Ok(7_001))
        );
        late.join().unwrap();
        assert_eq!(stamps.take_waiting(8_000, Duration::from_millis(5)), None);
        let sw = |ns| {
            Some(KernelStamp {
                software_ns: Some(ns),
                hardware_ns: None,
            })
        };
        assert_eq!(checked_send_stamp(sw(15), 10, 20, 5), Ok(15));
        assert_eq!(checked_send_stamp(sw(25), 10, 20, 5), Ok(25));
        assert_eq!(
            checked_send_stamp(sw(26), 10, 20, 5),
            Err(Fallback::SendStampOutOfRange)
        );
        assert_eq!(
            checked_send_stamp(sw(9), 10, 20, 5),
            Err(Fallback::SendStampOutOfRange)
        );
        assert_eq!(
            checked_send_stamp(None, 10, 20, 5),
            Err(Fallback::NoSendStamp)
        );
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn loopback_stamps_in_software_only_and_bad_names_are_errors() {
        let lo = interface_stamping("lo").unwrap();
        assert!(lo.software_send && lo.software_receive, "{lo:?}");
        assert!(!lo.hardware_send && !lo.hardware_receive, "{lo:?}");
        assert_eq!(lo.phc_index, None);
        let e = interface_stamping("no-such-if0").unwrap_err();
        assert!(e.to_string().contains("no-such-if0"), "{e}");
        for bad in ["", "a-name-longer-than-15", "l\0o"] {
            assert_eq!(
                interface_stamping(bad).unwrap_err().kind(),
                io::ErrorKind::InvalidInput
            );
        }
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn loopback_sends_and_receives_carry_kernel_stamps_in_order() {
        use crate::clock_map::host_clock::realtime_ns;
        let a = UdpSocket::bind("127.0.0.1:0").unwrap();
        let b = UdpSocket::bind("127.0.0.1:0").unwrap();
        enable(&a).unwrap();
        enable(&b).unwrap();
        b.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
        let to = b.local_addr().unwrap();
        let mut sends = SendStamps::new();
        let mut buf = [0u8; 16];
        // receive stamps start once the kernel's deferred switch has run: probe until one
        // comes stamped
        let mut id = 0u32;
        let on = (0..500).any(|_| {
            a.send_to(b"probe", to).unwrap();
            let _ = sends.take(&a, id, Duration::from_millis(100));
            id += 1;
            let (_, _, stamp) = recv(&b, &mut buf).unwrap();
            if stamp.software_ns.is_none() {
                std::thread::sleep(Duration::from_millis(10));
            }
            stamp.software_ns.is_some()
        });
        assert!(on, "no receive stamps within 5 s");
        let mut last = 0;
        for i in 0..20u8 {
            let before = realtime_ns();
            a.send_to(&[i; 30], to).unwrap();
            let send = sends.take(&a, id, Duration::from_millis(100)).unwrap();
            id += 1;
            let (n, from, receive) = recv(&b, &mut buf).unwrap();
            let after = realtime_ns();
            assert_eq!((n, from), (16, Some(a.local_addr().unwrap())));
            assert_eq!(buf, [i; 16]);
            let (s, r) = (send.software_ns.unwrap(), receive.software_ns.unwrap());
            assert!(
                before <= s && s <= r && r <= after,
                "{before} {s} {r} {after}"
            );
            assert!(last < s, "send stamps in order");
            last = r;
        }
        assert_eq!(sends.take(&a, id, Duration::from_millis(1)), None);
    }
}
