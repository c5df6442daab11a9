//! The box-tick-to-host-time mapping on loopback, with user-space or kernel stamps of the
//! exchanges (`skinbox bench clock-map`, `tests/clock_map_loopback.rs`).
//!
//! A responder thread plays the box's "read tick" command with a clock of its own (reset
//! at a known host time, running a known drift fast) and injects known, random,
//! asymmetric delays before it stamps the request and after it stamps the answer. The host
//! stamps each exchange's send and receive either with its own clock readings around
//! `send_to` and `recv` ([`ExchangeStamping::UserSpace`], as before `SO_TIMESTAMPING`), or
//! with the kernel's stamps ([`ExchangeStamping::Kernel`], [`crate::kernel_stamps`]); after
//! each exchange it maps the tick of that moment and compares it with the responder's true
//! clock. Every host time is CLOCK_REALTIME, the clock of the kernel's software stamps, fed
//! to the map less a base time of the run (an f64 holds a CLOCK_REALTIME time only to
//! 256 ns).

use crate::clock_map::{host_clock::realtime_ns, ClockMap, TimeExchange};
use crate::kernel_stamps::{self, ExchangeStamps, Fallback, SendStamps, StampSource};
use serde::Serialize;
use std::collections::BTreeMap;
use std::io;
use std::net::UdpSocket;
use std::time::Duration;

/// How the host stamps the exchanges' send and receive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ExchangeStamping {
    /// Its own CLOCK_REALTIME readings just before `send_to` and just after `recv`.
    UserSpace,
    /// The kernel's send and receive stamps, user-space ones where the kernel gave none.
    Kernel,
}

/// The responder's box clock: 8 ns ticks since `reset_ns` (CLOCK_REALTIME), `drift_ppm`
/// fast.
#[derive(Debug, Clone, Copy)]
pub struct BoxClock {
    /// Host time of the box's reset, ns.
    pub reset_ns: u64,
    /// How much faster than the host clock it runs, ppm.
    pub drift_ppm: f64,
}

impl BoxClock {
    /// The box tick at host time `host_ns`.
    pub fn tick_at(&self, host_ns: u64) -> u64 {
        (host_ns.saturating_sub(self.reset_ns) as f64 * (1.0 + self.drift_ppm * 1e-6) / 8.0) as u64
    }

    /// The true host time of box tick `tick`, ns since host time `base_ns` (at most its
    /// reset: a CLOCK_REALTIME time itself, near 2^61 ns, has a resolution of 256 ns in an
    /// f64).
    pub fn host_since(&self, base_ns: u64, tick: u64) -> f64 {
        self.reset_ns.saturating_sub(base_ns) as f64
            + tick as f64 * 8.0 / (1.0 + self.drift_ppm * 1e-6)
    }
}

/// One exchange and the mapping right after it.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct ClockMapSample {
    /// The exchange as fed to the map: host times in ns since the run's base time (a
    /// second before the box's reset), so the map's f64 keeps them to the ns.
    #[serde(skip)]
    pub exchange: TimeExchange,
    /// Where its host send and receive times came from.
    pub source: StampSource,
    /// The mapped host time of the tick of that moment minus its true host time, absolute,
    /// ns.
    pub error_ns: f64,
    /// The map's error bound of that host time, ns.
    pub bound_ns: f64,
}

/// One run of [`clock_map_loopback`].
#[derive(Debug, Clone, Serialize)]
pub struct ClockMapRun {
    /// How the exchanges were stamped.
    pub stamping: ExchangeStamping,
    /// Every exchange after the warm-up, in order.
    pub samples: Vec<ClockMapSample>,
    /// Exchanges that fell back to user-space stamps, by reason ([`Fallback::name`]).
    pub fallbacks: BTreeMap<&'static str, u64>,
    /// Warm-up exchanges before the counted ones (until the kernel stamped the responder's
    /// request and, with kernel stamps, a reply).
    pub warm_up_exchanges: u32,
    /// Why the socket has no kernel stamps, if it has none.
    pub not_enabled: Option<String>,
    /// The map's drift, ppm (host time per box time: minus the box's).
    pub drift_ppm: Option<f64>,
    /// Its bound, ppm.
    pub drift_bound_ppm: Option<f64>,
}

/// p50, p99 and max of a set of values.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct Percentiles {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// Largest.
    pub max: f64,
}

impl ClockMapRun {
    /// The mapping errors' p50, p99 and max, us.
    pub fn error_us(&self) -> Percentiles {
        let mut e: Vec<f64> = self.samples.iter().map(|s| s.error_ns / 1e3).collect();
        e.sort_by(f64::total_cmp);
        let at = |q: usize| e.get((e.len() * q / 100).min(e.len().saturating_sub(1)));
        Percentiles {
            p50: at(50).copied().unwrap_or(f64::NAN),
            p99: at(99).copied().unwrap_or(f64::NAN),
            max: e.last().copied().unwrap_or(f64::NAN),
        }
    }

    /// Exchanges of each stamp source.
    pub fn sources(&self) -> BTreeMap<&'static str, u64> {
        let mut n = BTreeMap::new();
        for s in &self.samples {
            *n.entry(s.source.name()).or_insert(0) += 1;
        }
        n
    }
}

/// Busy-waits `ns` (sleep's granularity would blur the injected delays).
fn spin(ns: u64) {
    let until = realtime_ns() + ns;
    while realtime_ns() < until {
        std::hint::spin_loop();
    }
}

/// What [`clock_map_loopback`] runs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ClockMapBenchConfig {
    /// Exchanges mapped (after the warm-up).
    pub exchanges: usize,
    /// Wait between exchanges.
    pub interval: Duration,
    /// How much faster than the host clock the responder's box clock runs, ppm.
    pub drift_ppm: f64,
    /// Most random delay the responder adds before it stamps a request, ns (the path's
    /// asymmetry the host cannot see).
    pub max_delay_in_ns: u64,
    /// Most random delay it adds after it stamps its answer, ns.
    pub max_delay_out_ns: u64,
}

impl Default for ClockMapBenchConfig {
    /// 300 exchanges 2 ms apart, an 80 ppm fast box, 0 to 60 us of delay in and 0 to 20 us
    /// out.
    fn default() -> Self {
        ClockMapBenchConfig {
            exchanges: 300,
            interval: Duration::from_millis(2),
            drift_ppm: 80.0,
            max_delay_in_ns: 60_000,
            max_delay_out_ns: 20_000,
        }
    }
}

/// Busy-waits until CLOCK_REALTIME reaches `ns`.
fn spin_until(ns: u64) {
    while realtime_ns() < ns {
        std::hint::spin_loop();
    }
}

/// Answers requests until an empty datagram or 5 s of silence: 8 bytes of sequence in,
/// sequence, receive and send ticks out, and 1 when the arrival was the kernel's stamp.
/// Like the box, which stamps at its pin, it takes a
/// request's arrival from the kernel's receive stamp (its thread's wake-up is no part of
/// the path; its own clock where the kernel gave none), plus a random delay of up to
/// `delay_in_ns`; its send tick at least 2 us later, then a random delay of up to
/// `delay_out_ns` before the answer goes.
fn respond(socket: UdpSocket, clock: BoxClock, delay_in_ns: u64, delay_out_ns: u64) {
    let mut x = 0x0DDB_1A5E_5BAD_5EEDu64;
    let mut rand = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x >> 11
    };
    let _ = socket.set_read_timeout(Some(Duration::from_secs(5)));
    let _ = kernel_stamps::enable_receive(&socket);
    let mut buf = [0u8; 64];
    loop {
        let Ok((n, Some(peer), arrival)) = kernel_stamps::recv(&socket, &mut buf) else {
            return;
        };
        if n == 0 {
            return;
        }
        let arrived_ns = arrival.software_ns.unwrap_or_else(realtime_ns);
        let stamped_ns = arrived_ns + rand() % delay_in_ns.saturating_add(1);
        spin_until(stamped_ns);
        let receive = clock.tick_at(stamped_ns);
        spin_until(stamped_ns + 2_000);
        let send = clock.tick_at(realtime_ns());
        spin(rand() % delay_out_ns.saturating_add(1));
        let mut reply = [0u8; 25];
        reply[..8].copy_from_slice(&buf[..8.min(n)]);
        reply[8..16].copy_from_slice(&receive.to_le_bytes());
        reply[16..24].copy_from_slice(&send.to_le_bytes());
        reply[24] = u8::from(arrival.software_ns.is_some());
        if socket.send_to(&reply, peer).is_err() {
            return;
        }
    }
}

/// Most warm-up exchanges waiting for the kernel's first receive stamp (it switches them
/// on in deferred work once a socket asks).
const MAX_WARM_UP: u32 = 500;
/// Warm-up exchanges at least (the responder thread's start-up).
const MIN_WARM_UP: u32 = 10;

/// Runs `config.exchanges` exchanges with a responder thread, stamped as `stamping` says,
/// each followed by mapping the tick of that moment. Warm-up exchanges first (at least 10;
/// with kernel stamps, until a reply came stamped), not mapped.
pub fn clock_map_loopback(
    stamping: ExchangeStamping,
    config: &ClockMapBenchConfig,
) -> io::Result<ClockMapRun> {
    let ClockMapBenchConfig {
        exchanges,
        interval,
        drift_ppm,
        max_delay_in_ns,
        max_delay_out_ns,
    } = *config;
    let clock = BoxClock {
        reset_ns: realtime_ns().saturating_sub(3_000_000_000),
        drift_ppm,
    };
    let base_ns = clock.reset_ns.saturating_sub(1_000_000_000);
    let box_socket = UdpSocket::bind("127.0.0.1:0")?;
    let box_addr = box_socket.local_addr()?;
    let responder = std::thread::Builder::new()
        .name("skinbox-box".into())
        .spawn(move || respond(box_socket, clock, max_delay_in_ns, max_delay_out_ns))?;
    let host = UdpSocket::bind("127.0.0.1:0")?;
    host.set_read_timeout(Some(Duration::from_secs(2)))?;
    let not_enabled = match stamping {
        ExchangeStamping::UserSpace => None,
        ExchangeStamping::Kernel => kernel_stamps::enable(&host)
            .err()
            .map(|e| format!("SO_TIMESTAMPING: {e}")),
    };
    let kernel = stamping == ExchangeStamping::Kernel && not_enabled.is_none();
    let mut send_stamps = SendStamps::new();
    let mut sent = 0u32;
    let mut buf = [0u8; 64];
    // the exchange, its stamps' source and fallback, and whether the responder had the
    // kernel's arrival stamp
    type Stamped = (TimeExchange, StampSource, Option<Fallback>, bool);
    let mut exchange = |seq: u64| -> io::Result<Stamped> {
        let user_send_ns = realtime_ns();
        host.send_to(&seq.to_le_bytes(), box_addr)?;
        let id = sent;
        sent = sent.wrapping_add(1);
        let (n, _, receive_stamp) = kernel_stamps::recv(&host, &mut buf)?;
        let user_receive_ns = realtime_ns();
        if n != 25 || buf[..8] != seq.to_le_bytes() {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                format!("exchange {seq}: the responder's reply is {n} bytes, not 25 echoing it"),
            ));
        }
        let stamps = if kernel {
            let send_stamp = send_stamps.take(&host, id, Duration::from_millis(10));
            ExchangeStamps::pick(
                send_stamp,
                Some(receive_stamp),
                user_send_ns,
                user_receive_ns,
            )
        } else {
            ExchangeStamps {
                send_ns: user_send_ns,
                receive_ns: user_receive_ns,
                source: StampSource::UserSpace,
                fallback: (stamping == ExchangeStamping::Kernel).then_some(Fallback::NotEnabled),
            }
        };
        let tick = |at: usize| u64::from_le_bytes(buf[at..at + 8].try_into().unwrap_or([0; 8]));
        Ok((
            TimeExchange {
                host_send_ns: stamps.send_ns.saturating_sub(base_ns),
                box_receive_tick: tick(8),
                box_send_tick: tick(16),
                host_receive_ns: stamps.receive_ns.saturating_sub(base_ns),
            },
            stamps.source,
            stamps.fallback,
            buf[24] == 1,
        ))
    };
    let mut seq = 0u64;
    let mut warm_up_exchanges = 0;
    while warm_up_exchanges < MAX_WARM_UP {
        let (_, source, _, responder_stamped) = exchange(seq)?;
        seq += 1;
        warm_up_exchanges += 1;
        if warm_up_exchanges >= MIN_WARM_UP
            && responder_stamped
            && (!kernel || source != StampSource::UserSpace)
        {
            break;
        }
        std::thread::sleep(interval);
    }
    let mut map = ClockMap::new();
    let mut samples = Vec::with_capacity(exchanges);
    let mut fallbacks = BTreeMap::new();
    for _ in 0..exchanges {
        std::thread::sleep(interval);
        let (e, source, fallback, _) = exchange(seq)?;
        seq += 1;
        if let Some(f) = fallback {
            *fallbacks.entry(f.name()).or_insert(0) += 1;
        }
        map.push(1, e)
            .map_err(|err| io::Error::new(io::ErrorKind::InvalidData, err.to_string()))?;
        // a record stamped now, mapped with what the map knows now
        let tick = clock.tick_at(realtime_ns());
        let Some(mapped) = map.to_host(tick) else {
            continue;
        };
        samples.push(ClockMapSample {
            exchange: e,
            source,
            error_ns: (mapped.host_ns - clock.host_since(base_ns, tick)).abs(),
            bound_ns: mapped.error_bound_ns.unwrap_or(f64::INFINITY),
        });
    }
    let _ = host.send_to(&[], box_addr);
    let _ = responder.join();
    Ok(ClockMapRun {
        stamping,
        samples,
        fallbacks,
        warm_up_exchanges,
        not_enabled,
        drift_ppm: map.drift_ppm(),
        drift_bound_ppm: map.drift_bound_ppm(),
    })
}
