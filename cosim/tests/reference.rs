//! The reference model against the verilated box: every frame byte for byte, and the
//! cycle of its first byte, on each regression scene.

use skinbox_cells::rng::Rng;
use skinbox_cosim::frames::{assemble, check, Frame};
use skinbox_cosim::harness::play;
use skinbox_cosim::line::{
    back_to_back, jittered_transitions, transitions, Jitter, Transition, UartByte,
};
use skinbox_cosim::reference::predict_frames;
use skinbox_cosim::sim::RESET_CYCLES;
use skinbox_cosim::{Dut, Model};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{Channel, DataRepr, DatagramRepr, EventRepr};

fn rtl_frames(config: &BoxConfig, lines: &[Vec<Transition>], cycles: u64) -> Vec<Frame> {
    let model = Model::build(config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    let mut dut = Dut::new(&model, None).unwrap();
    let out = play(&mut dut, lines, RESET_CYCLES, cycles);
    assemble(&out).0
}

fn describe(f: &Frame) -> String {
    match check(&f.bytes) {
        Ok((_, payload)) => match DatagramRepr::parse(payload) {
            Ok(d) => format!("cycle {} {d:?}", f.first_cycle),
            Err(e) => format!("cycle {} unparsable datagram: {e}", f.first_cycle),
        },
        Err(e) => format!("cycle {} bad frame: {e}", f.first_cycle),
    }
}

/// Runs both models and asserts the same frames at the same cycles; returns them.
fn agree(config: &BoxConfig, lines: &[Vec<Transition>], cycles: u64) -> Vec<Frame> {
    let rtl = rtl_frames(config, lines, cycles);
    let reference = predict_frames(config, lines, cycles).unwrap();
    for (i, (r, m)) in rtl.iter().zip(&reference).enumerate() {
        assert!(
            r == m,
            "frame {i} differs:\n RTL       {}\n reference {}",
            describe(r),
            describe(m)
        );
    }
    assert_eq!(
        rtl.len(),
        reference.len(),
        "frame counts differ; first extra: {:?}",
        rtl.get(reference.len())
            .or(reference.get(rtl.len()))
            .map(describe)
    );
    rtl
}

fn data(id: u16, k: i32) -> [u8; PACKET_LEN] {
    DataRepr::from_raw(id, [k, -7, 250, 1, 2, 3, 4000, 61, 0])
        .unwrap()
        .to_bytes()
}

/// The frames but one the run ended inside (its last, if it is cut short).
fn complete(frames: &[Frame]) -> &[Frame] {
    match frames.split_last() {
        Some((last, rest)) if check(&last.bytes).is_err() => rest,
        _ => frames,
    }
}

fn records(frames: &[Frame]) -> usize {
    complete(frames)
        .iter()
        .map(|f| {
            match DatagramRepr::parse(check(&f.bytes).unwrap().1)
                .unwrap()
                .body
            {
                DatagramBody::Records(r) => r.len(),
                DatagramBody::Status(_) => 0,
            }
        })
        .sum()
}

#[test]
fn one_port_a_few_packets() {
    let config = BoxConfig {
        ports: 1,
        flush_timeout_ticks: 3_000,
        status_period_ticks: 40_000,
        ..BoxConfig::default()
    };
    let bytes: Vec<UartByte> = (0..6)
        .flat_map(|k| {
            back_to_back(
                &data(k + 1, k.into()),
                7_000.0 + f64::from(k) * 61_000.0,
                251.0,
            )
        })
        .collect();
    let frames = agree(&config, &[transitions(&bytes)], 60_000);
    assert_eq!(records(&frames), 6);
}

/// Every port at line rate, each with its own clock error and +-10 ns of jitter: full
/// datagrams, arbiter contention, status reports while records flow.
#[test]
fn eight_ports_at_line_rate_with_jitter() {
    let ports = 8;
    let per_port = 60;
    let config = BoxConfig {
        ports,
        status_period_ticks: 200_000,
        ..BoxConfig::default()
    };
    let lines: Vec<Vec<Transition>> = (0..ports)
        .map(|port| {
            let bit_ns = 250.0 / (1.0 + (port as f64 - 3.5) / 350.0);
            let first = 10_000.0 + port as f64 * 37.3;
            let bytes: Vec<UartByte> = (0..per_port)
                .flat_map(|k| {
                    let id = (port * per_port + k + 1) as u16;
                    let packet = if k % 2 == 0 {
                        data(id, k as i32)
                    } else {
                        EventRepr::new(id, k as u16, false, &[(Channel::AccelZ, -(k as i32))])
                            .unwrap()
                            .to_bytes()
                    };
                    back_to_back(&packet, first + k as f64 * 200.0 * bit_ns, bit_ns)
                })
                .collect();
            let jitter = Jitter {
                peak_ns: 10.0,
                seed: 42 + port as u64,
            };
            jittered_transitions(&bytes, &jitter).0
        })
        .collect();
    let cycles = (10_000 + per_port as u64 * 50_600 + 150_000) / 8;
    let frames = agree(&config, &lines, cycles);
    assert_eq!(records(&frames), ports * per_port);
}

/// Status reports every 1,009 ticks and one records datagram per record (64-tick flush)
/// from 8 ports at line rate: status and records datagrams often wait together for the
/// link, and the arbiter's round robin (not the records first) decides which goes.
#[test]
fn status_and_records_waiting_together_take_turns() {
    let ports = 8;
    let per_port = 24;
    let config = BoxConfig {
        ports,
        flush_timeout_ticks: 64,
        status_period_ticks: 1_009,
        ..BoxConfig::default()
    };
    let lines: Vec<Vec<Transition>> = (0..ports)
        .map(|port| {
            let first = 8_000.0 + port as f64 * 611.3;
            let bytes: Vec<UartByte> = (0..per_port)
                .flat_map(|k| {
                    let id = (port * per_port + k + 1) as u16;
                    back_to_back(&data(id, k as i32), first + k as f64 * 50_000.0, 250.0)
                })
                .collect();
            transitions(&bytes)
        })
        .collect();
    let cycles = (8_000 + per_port as u64 * 50_000 + 100_000) / 8;
    let frames = agree(&config, &lines, cycles);
    assert_eq!(records(&frames), ports * per_port);
    let frames = complete(&frames);
    // frames that follow the previous one after the minimum gap went out of a queue: a
    // records frame, a status frame and a records frame back to back mean both kinds
    // waited while the first was sent
    let kinds: Vec<bool> = frames
        .iter()
        .map(|f| {
            matches!(
                DatagramRepr::parse(check(&f.bytes).unwrap().1)
                    .unwrap()
                    .body,
                DatagramBody::Status(_)
            )
        })
        .collect();
    let back_to_back = |i: usize| {
        frames[i + 1].first_cycle - (frames[i].first_cycle + frames[i].bytes.len() as u64) <= 13
    };
    let turns = (0..frames.len() - 2)
        .filter(|&i| {
            !kinds[i] && kinds[i + 1] && !kinds[i + 2] && back_to_back(i) && back_to_back(i + 1)
        })
        .count();
    assert!(
        turns > 0,
        "no contention between status and records in this run"
    );
}

/// The idle gap's edge, clock by clock: on each port a packet stops after 11 bytes and the
/// next one starts after an idle line of about the gap, 4 ns longer from port to port. Where
/// no byte completed within `10 + idle_gap_bits` bit times of the last one, the stopped
/// packet is truncated and the next one stored; where the header came in time, it
/// continues the stopped packet, which then fails. Both models must draw the line at the
/// same clock.
#[test]
fn truncation_at_the_idle_gap_clock_by_clock() {
    let ports = 24;
    let config = BoxConfig {
        ports,
        flush_timeout_ticks: 2_000,
        ..BoxConfig::default()
    };
    let bit_ns = 250.0;
    // strobe to strobe: the rest of the stop bit, the idle line and 9.5 bits of the header
    let idle_at_edge = config.idle_gap_bits as f64 * bit_ns;
    let lines: Vec<Vec<Transition>> = (0..ports)
        .map(|port| {
            let first = 5_000.0 + port as f64 * 101.0;
            let mut bytes = back_to_back(&data(2 * port as u16 + 1, 5)[..11], first, bit_ns);
            let idle = idle_at_edge + (port as f64 - 12.0) * 4.0;
            let next = bytes.last().unwrap().end_ns() + idle;
            bytes.extend(back_to_back(&data(2 * port as u16 + 2, 6), next, bit_ns));
            transitions(&bytes)
        })
        .collect();
    // the last packet ends by about 90 us; then the flush timeout (16 us)
    let frames = agree(&config, &lines, 120_000 / 8);
    let stored = records(&frames);
    assert!(
        0 < stored && stored < ports,
        "{stored} of {ports} ports truncated in time: the sweep misses the edge"
    );
}

/// A scene's packets through the 4-bus box: the default job's traffic, shortened.
#[test]
fn stroking_scene() {
    let spec = skinbox_cosim::scene::builtin_spec(
        "stroking_upper_arm",
        1_000_000_000,
        20_000_000,
        625_000,
    )
    .unwrap();
    let (lines, _) = skinbox_cosim::sim::lines(&spec);
    let frames = agree(&spec.config, &lines, skinbox_cosim::sim::cycles(&spec));
    let sent: usize = spec.ports.iter().map(Vec::len).sum();
    assert!(sent > 50, "{sent} packets");
    assert_eq!(records(&frames), sent);
}

/// One port's random traffic: bursts of packets back to back or with short gaps, each
/// line with its own clock error, and now and then a fault (garbage, truncation, wrong end
/// byte, low stop bit) or a glitch.
fn random_line(r: &mut Rng, port: usize, end_ns: f64) -> Vec<Transition> {
    let bit = 250.0 * r.range(0.97, 1.03);
    let mut t = r.range(5_000.0, 20_000.0);
    let mut bytes: Vec<UartByte> = vec![];
    let mut id = (port as u16) << 10;
    while t < end_ns {
        id += 1;
        // accel_x within its 10-bit range (docs/wire-format.md), 1,000 values as before.
        let mut packet = data(id, r.below(1000) as i32 - 500);
        let fault = r.below(40);
        let b0 = match fault {
            0 => back_to_back(&[0x11, 0x22, 0x33][..1 + r.below(3) as usize], t, bit),
            1 => back_to_back(&packet[..1 + r.below(19) as usize], t, bit),
            2 => {
                packet[19] ^= 0x10;
                back_to_back(&packet, t, bit)
            }
            _ => back_to_back(&packet, t, bit),
        };
        let mut b = b0;
        if fault == 3 {
            // a low stop bit; the line returns high after it, one bit before the next
            // start edge (so jitter cannot swap the two edges)
            let k = r.below(20) as usize;
            b[k].stop_level = false;
            for later in &mut b[k + 1..] {
                later.start_ns += bit;
            }
        }
        t = b.last().unwrap().end_ns() + if fault == 3 { bit } else { 0.0 };
        bytes.extend(b);
        // back to back, a short gap, or a pause longer than the flush timeout
        t += match r.below(8) {
            0..=2 => 0.0,
            3..=5 => r.range(0.0, 3.0) * bit,
            6 => r.range(10.0, 400.0) * bit,
            _ => r.range(400.0, 1_500.0) * bit,
        };
    }
    let jitter = Jitter {
        peak_ns: r.range(0.0, 30.0),
        seed: r.next_u64(),
    };
    jittered_transitions(&bytes, &jitter).0
}

/// Random traffic on three ports, several seeds: datagram boundaries by timeout and by
/// size land on every clock relative to the records, status reports cross records.
#[test]
fn random_traffic() {
    let config = BoxConfig {
        ports: 3,
        flush_timeout_ticks: 1_500,
        status_period_ticks: 20_000,
        ..BoxConfig::default()
    };
    let cycles = 400_000;
    let mut total = 0;
    for seed in 0..8 {
        let mut r = Rng::new(seed);
        let lines: Vec<Vec<Transition>> = (0..config.ports)
            .map(|port| random_line(&mut r, port, (cycles - 10_000) as f64 * 8.0))
            .collect();
        total += records(&agree(&config, &lines, cycles));
    }
    assert!(total > 600, "{total} records");
}

/// A packet whose counter event lands at every clock around the status report's read of
/// that counter: the counter file's and the reporter's latencies must agree to the clock.
#[test]
fn status_snapshot_at_every_clock_around_a_counter_event() {
    let config = BoxConfig {
        ports: 1,
        flush_timeout_ticks: 500,
        status_period_ticks: 20_000,
        ..BoxConfig::default()
    };
    let model = Model::build(&config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    let cycles = 26_000;
    let mut counts = std::collections::BTreeSet::new();
    // the second report starts at about clock 20,005 and reads port 0's good-packet counter
    // some 30 clocks later; the packet's 20 bytes take about 6,250 clocks
    for offset in 0..90u64 {
        let start_ns = ((20_000 - 6_250 - 30 + offset) * 8) as f64;
        let line = transitions(&back_to_back(&data(1, 1), start_ns, 250.0));
        let lines = [line];
        let mut dut = Dut::new(&model, None).unwrap();
        let rtl = assemble(&play(&mut dut, &lines, RESET_CYCLES, cycles)).0;
        let reference = predict_frames(&config, &lines, cycles).unwrap();
        assert!(
            rtl == reference,
            "offset {offset}: RTL and reference differ"
        );
        // the second status report counted the packet or not, depending on the offset
        let good: Vec<u32> = rtl
            .iter()
            .filter_map(|f| {
                match DatagramRepr::parse(check(&f.bytes).unwrap().1)
                    .unwrap()
                    .body
                {
                    DatagramBody::Status(s) => Some(s.ports[0].0[0]),
                    DatagramBody::Records(_) => None,
                }
            })
            .collect();
        counts.insert(good.get(1).copied());
    }
    assert_eq!(
        counts,
        [Some(0), Some(1)].into_iter().collect(),
        "the sweep crosses the report's read of the counter"
    );
}
