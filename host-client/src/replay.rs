//! Replay of UDP payloads (from a pcap) to a socket, at a fixed rate or as recorded, so the
//! live path can be exercised without hardware.

use serde::Serialize;
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// When each datagram is sent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pacing {
    /// Keeps the pcap's spacing, scaled by `speed` (2.0 = twice as fast).
    AsRecorded {
        /// Speed factor.
        speed: f64,
    },
    /// Evenly spaced at this many datagrams per second.
    Rate {
        /// Datagrams per second.
        datagrams_per_second: f64,
    },
    /// At this many datagrams per second on average, sent `burst` at a time back to back
    /// (as a NIC hands a busy link's frames to the host), sleeping between bursts: the
    /// sender then needs little CPU, unlike [`Pacing::Rate`]'s even spacing.
    Bursts {
        /// Datagrams per second on average.
        datagrams_per_second: f64,
        /// Datagrams per burst.
        burst: usize,
    },
    /// As fast as the socket takes them.
    Unpaced,
}

/// What a replay did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct ReplaySummary {
    /// Datagrams sent.
    pub datagrams: u64,
    /// Payload bytes sent.
    pub bytes: u64,
    /// Sends that failed (counted, not retried).
    pub send_errors: u64,
    /// Wall time, in seconds.
    pub wall_s: f64,
    /// Datagrams per second achieved.
    pub datagrams_per_second: f64,
}

/// Sends `payloads` (capture time, bytes) from `socket` to `to` with `pacing`; stops early
/// when `stop` becomes true. Blocking: run it on its own thread.
pub fn replay<'a>(
    socket: &UdpSocket,
    to: SocketAddr,
    payloads: impl IntoIterator<Item = (Duration, &'a [u8])>,
    pacing: Pacing,
    stop: &AtomicBool,
) -> ReplaySummary {
    let start = Instant::now();
    let mut summary = ReplaySummary::default();
    let mut first_ts = None;
    for (i, (ts, payload)) in payloads.into_iter().enumerate() {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        let due = match pacing {
            Pacing::Unpaced => None,
            Pacing::Rate {
                datagrams_per_second,
            } => Some(Duration::from_secs_f64(
                i as f64 / datagrams_per_second.max(1e-9),
            )),
            Pacing::Bursts {
                datagrams_per_second,
                burst,
            } => {
                let burst = burst.max(1);
                (i % burst == 0)
                    .then(|| Duration::from_secs_f64(i as f64 / datagrams_per_second.max(1e-9)))
            }
            Pacing::AsRecorded { speed } => {
                let first = *first_ts.get_or_insert(ts);
                Some(ts.saturating_sub(first).div_f64(speed.max(1e-9)))
            }
        };
        if let Some(due) = due {
            if matches!(pacing, Pacing::Bursts { .. }) {
                sleep_until(start, due);
            } else {
                wait_until(start, due);
            }
        }
        match socket.send_to(payload, to) {
            Ok(n) => {
                summary.datagrams += 1;
                summary.bytes += n as u64;
            }
            Err(_) => summary.send_errors += 1,
        }
    }
    summary.wall_s = start.elapsed().as_secs_f64();
    if summary.wall_s > 0.0 {
        summary.datagrams_per_second = summary.datagrams as f64 / summary.wall_s;
    }
    summary
}

/// Sleeps until `due` (to the scheduler's precision, tens of microseconds).
fn sleep_until(start: Instant, due: Duration) {
    let now = start.elapsed();
    if now < due {
        std::thread::sleep(due - now);
    }
}

/// Sleeps while far from `due`, then yields: accurate to a few microseconds without
/// burning a core the receiver may need.
fn wait_until(start: Instant, due: Duration) {
    loop {
        let now = start.elapsed();
        if now >= due {
            return;
        }
        let left = due - now;
        if left > Duration::from_micros(1500) {
            std::thread::sleep(left - Duration::from_micros(1000));
        } else {
            std::thread::yield_now();
        }
    }
}
