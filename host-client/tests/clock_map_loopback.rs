//! The box-tick-to-host-time mapping on loopback: a UDP responder thread plays the box's
//! "read tick" command with a clock of its own (reset at a known host time, running a known
//! drift fast), and injects known, random, asymmetric delays before it stamps the request
//! and after it stamps the answer. The host side maps box ticks to CLOCK_MONOTONIC from the
//! exchanges; every mapping is checked against the responder's true clock.

use skinbox_host::clock_map::{host_clock, ClockMap, TimeExchange};
use std::net::UdpSocket;
use std::time::Duration;

/// The responder's box clock: 8 ns ticks since `reset_ns` (CLOCK_MONOTONIC), `drift_ppm`
/// fast.
#[derive(Clone, Copy)]
struct BoxClock {
    reset_ns: u64,
    drift_ppm: f64,
}

impl BoxClock {
    fn tick_at(&self, host_ns: u64) -> u64 {
        ((host_ns - self.reset_ns) as f64 * (1.0 + self.drift_ppm * 1e-6) / 8.0) as u64
    }
    fn host_of(&self, tick: u64) -> f64 {
        self.reset_ns as f64 + tick as f64 * 8.0 / (1.0 + self.drift_ppm * 1e-6)
    }
}

/// Busy-waits `ns` (sleep's granularity would blur the injected delays).
fn spin(ns: u64) {
    let until = host_clock::monotonic_ns() + ns;
    while host_clock::monotonic_ns() < until {
        std::hint::spin_loop();
    }
}

/// Answers `count` requests: 8 bytes of sequence in, sequence, receive and send ticks out.
fn responder(socket: UdpSocket, clock: BoxClock, count: usize) {
    let mut x = 0x0DDB_1A5E_5BAD_5EEDu64;
    let mut rand = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x >> 11
    };
    let mut buf = [0u8; 64];
    for _ in 0..count {
        let Ok((n, peer)) = socket.recv_from(&mut buf) else {
            return;
        };
        // Injected: up to 60 us more on the way in, up to 20 us on the way out.
        spin(rand() % 60_000);
        let receive = clock.tick_at(host_clock::monotonic_ns());
        spin(2_000);
        let send = clock.tick_at(host_clock::monotonic_ns());
        spin(rand() % 20_000);
        let mut reply = [0u8; 24];
        reply[..8].copy_from_slice(&buf[..8.min(n)]);
        reply[8..16].copy_from_slice(&receive.to_le_bytes());
        reply[16..24].copy_from_slice(&send.to_le_bytes());
        if socket.send_to(&reply, peer).is_err() {
            return;
        }
    }
}

#[test]
fn loopback_mapping_stays_within_its_bound_and_50_us_at_p99() {
    const EXCHANGES: usize = 300;
    let clock = BoxClock {
        reset_ns: host_clock::monotonic_ns() - 3_000_000_000,
        drift_ppm: 80.0,
    };
    let box_socket = UdpSocket::bind("127.0.0.1:0").unwrap();
    let box_addr = box_socket.local_addr().unwrap();
    let thread = std::thread::spawn(move || responder(box_socket, clock, EXCHANGES));
    let host = UdpSocket::bind("127.0.0.1:0").unwrap();
    host.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    let mut map = ClockMap::new();
    let mut errors = Vec::new();
    let mut buf = [0u8; 64];
    for seq in 0..EXCHANGES as u64 {
        let host_send_ns = host_clock::monotonic_ns();
        host.send_to(&seq.to_le_bytes(), box_addr).unwrap();
        let (n, _) = host.recv_from(&mut buf).unwrap();
        let host_receive_ns = host_clock::monotonic_ns();
        assert_eq!(n, 24);
        assert_eq!(u64::from_le_bytes(buf[..8].try_into().unwrap()), seq);
        let exchange = TimeExchange {
            host_send_ns,
            box_receive_tick: u64::from_le_bytes(buf[8..16].try_into().unwrap()),
            box_send_tick: u64::from_le_bytes(buf[16..24].try_into().unwrap()),
            host_receive_ns,
        };
        map.push(1, exchange).unwrap();
        // A record stamped now, mapped with what the map knows now.
        let tick = clock.tick_at(host_clock::monotonic_ns());
        let mapped = map.to_host(tick).unwrap();
        let error = (mapped.host_ns - clock.host_of(tick)).abs();
        let bound = mapped.error_bound_ns.unwrap();
        assert!(
            error <= bound + 8.0,
            "exchange {seq}: error {error:.0} ns beyond the bound {bound:.0} ns"
        );
        errors.push(error);
        std::thread::sleep(Duration::from_millis(2));
    }
    thread.join().unwrap();
    errors.sort_by(f64::total_cmp);
    let p99 = errors[errors.len() * 99 / 100];
    eprintln!(
        "loopback mapping error: p50 {:.1} us, p99 {:.1} us, max {:.1} us; drift {:.1} +- {:.1} ppm",
        errors[errors.len() / 2] / 1e3,
        p99 / 1e3,
        errors[errors.len() - 1] / 1e3,
        map.drift_ppm().unwrap_or(f64::NAN),
        map.drift_bound_ppm().unwrap_or(f64::NAN)
    );
    assert!(p99 <= 50_000.0, "p99 {p99} ns");
    // Host time per box time: 80 ppm fast box, -80 ppm, within the map's own bound.
    let (drift, bound) = (map.drift_ppm().unwrap(), map.drift_bound_ppm().unwrap());
    assert!(
        (drift + 80.0).abs() <= bound,
        "drift {drift} +- {bound} ppm"
    );
}

#[test]
fn a_box_reset_restarts_the_mapping() {
    let mut map = ClockMap::new();
    let exchange = |send: u64, tick: u64| TimeExchange {
        host_send_ns: send,
        box_receive_tick: tick,
        box_send_tick: tick + 1,
        host_receive_ns: send + 100_000,
    };
    for i in 0..10u64 {
        map.push(
            41,
            exchange(10_000_000_000 + i * 1_000_000, 1_000_000_000 + i * 125_000),
        )
        .unwrap();
    }
    // The box restarted: boot id 42, ticks from near zero.
    map.push(42, exchange(20_000_000_000, 1_000)).unwrap();
    assert_eq!(map.restarts(), 1);
    assert_eq!(map.boot_id(), Some(42));
    let mapped = map.to_host(1_000).unwrap();
    assert!((mapped.host_ns - 20_000_050_000.0).abs() <= mapped.error_bound_ns.unwrap());
}

/// The same loopback responder twice in one run: the exchanges stamped in user space
/// around `send_to` and `recv`, then by the kernel (`SO_TIMESTAMPING`). Both mappings stay
/// within their bound at every exchange; the kernel's stamps are in order and bracket each
/// reply. The figures are printed, not asserted (shared machines are noisy).
#[cfg(target_os = "linux")]
#[test]
fn kernel_stamped_exchanges_map_within_their_bound_beside_user_space_ones() {
    use skinbox_host::clock_bench::{clock_map_loopback, ClockMapBenchConfig, ExchangeStamping};
    use skinbox_host::kernel_stamps::StampSource;
    // 300 exchanges 2 ms apart, an 80 ppm fast box, 0-60 us of delay in, 0-20 us out
    let config = ClockMapBenchConfig::default();
    const EXCHANGES: usize = 300;
    assert_eq!(config.exchanges, EXCHANGES);
    let user = clock_map_loopback(ExchangeStamping::UserSpace, &config).unwrap();
    let kernel = clock_map_loopback(ExchangeStamping::Kernel, &config).unwrap();
    for run in [&user, &kernel] {
        assert_eq!(run.samples.len(), EXCHANGES, "{:?}", run.stamping);
        for (i, s) in run.samples.iter().enumerate() {
            assert!(
                s.error_ns <= s.bound_ns + 8.0,
                "{:?} exchange {i}: error {:.0} ns beyond the bound {:.0} ns",
                run.stamping,
                s.error_ns,
                s.bound_ns
            );
        }
        let (drift, bound) = (run.drift_ppm.unwrap(), run.drift_bound_ppm.unwrap());
        assert!(
            (drift + 80.0).abs() <= bound,
            "drift {drift} +- {bound} ppm"
        );
        let e = run.error_us();
        eprintln!(
            "{:?}: mapping error p50 {:.2} us, p99 {:.2} us, max {:.2} us; stamps {:?}, fallbacks {:?}, warm-up {}",
            run.stamping, e.p50, e.p99, e.max, run.sources(), run.fallbacks, run.warm_up_exchanges
        );
    }
    assert!(user
        .samples
        .iter()
        .all(|s| s.source == StampSource::UserSpace));
    assert_eq!(kernel.not_enabled, None);
    // loopback always has software stamps once they are on: a fallback is counted, and
    // rare
    let stamped: Vec<_> = kernel
        .samples
        .iter()
        .filter(|s| s.source == StampSource::KernelSoftware)
        .collect();
    assert!(
        stamped.len() >= EXCHANGES * 9 / 10,
        "{} of {EXCHANGES} kernel-stamped, fallbacks {:?}",
        stamped.len(),
        kernel.fallbacks
    );
    let fell_back: u64 = kernel.fallbacks.values().sum();
    assert_eq!(fell_back as usize, EXCHANGES - stamped.len());
    let mut last_receive = 0;
    for s in &stamped {
        let e = s.exchange;
        assert!(e.host_send_ns <= e.host_receive_ns, "{e:?}");
        // the box's turnaround lies inside the stamps
        assert!(e.check().is_ok(), "{e:?}");
        assert!(last_receive < e.host_send_ns, "stamps in order: {e:?}");
        last_receive = e.host_receive_ns;
    }
}
