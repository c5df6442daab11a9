//! The receiver's failure point under UART clock mismatch, through the verilated box:
//! within +-4.7 % every packet arrives intact with the tick of its start edge; beyond the
//! point where bytes break, the box rejects packets but delivers none corrupted, and the status counters show the loss:
//! rejected packets, or, where not even a header byte survives, garbage bytes.

use skinbox_cosim::frames::{assemble, check};
use skinbox_cosim::harness::play;
use skinbox_cosim::line::{
    back_to_back, baud_sweep_config, transitions, BAUD_SWEEP_CYCLES, BAUD_SWEEP_STATUS_TICKS,
};
use skinbox_cosim::reference::predict_frames;
use skinbox_cosim::sim::RESET_CYCLES;
use skinbox_cosim::sim::TICK_ZERO_CYCLE;
use skinbox_cosim::traffic::random_data_packets;
use skinbox_cosim::{Dut, Model};
use skinbox_protocol::cell::{PACKET_LEN, UART_BITS_PER_PACKET};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::status::PortCounter;
use skinbox_protocol::DatagramRepr;
use skinbox_protocol::TICK_NS;
use std::collections::HashMap;

const PACKETS: usize = 150;

/// What the box made of one line.
struct Outcome {
    /// Packets delivered with their bytes intact.
    intact: usize,
    /// Records whose bytes were not sent.
    corrupted: usize,
    /// Rejected packets and garbage bytes, as the status counters say.
    rejected: u32,
    /// Of the intact packets: stamp minus the true start edge, in ticks.
    stamp_errors: Vec<f64>,
}

fn run(error_percent: f64) -> Outcome {
    let config = baud_sweep_config();
    let model = Model::build(&config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    let mut dut = Dut::new(&model, None).unwrap();
    let sent = random_data_packets(PACKETS);
    let bytes: Vec<u8> = sent.iter().flatten().copied().collect();
    let bit_ns = 250.0 / (1.0 + error_percent / 100.0);
    let line = transitions(&back_to_back(&bytes, 10_000.0, bit_ns));
    let end_tick = (10_000.0 + bytes.len() as f64 * 10.0 * bit_ns) as u64 / 8;
    assert!(end_tick + 2 * 5_000 < BAUD_SWEEP_STATUS_TICKS);
    let cycles = BAUD_SWEEP_CYCLES;
    let out = play(&mut dut, std::slice::from_ref(&line), RESET_CYCLES, cycles);
    let (frames, _) = assemble(&out);
    // the reference model predicts the same frames, failures included
    assert!(
        predict_frames(&config, &[line], cycles).unwrap() == frames,
        "reference and RTL differ at {error_percent} %"
    );
    // each packet's true start edge: a packet's bits after the previous one
    let true_start_ns: HashMap<[u8; PACKET_LEN], f64> = sent
        .into_iter()
        .enumerate()
        .map(|(i, p)| {
            (
                p,
                10_000.0 + (i as u64 * UART_BITS_PER_PACKET) as f64 * bit_ns,
            )
        })
        .collect();
    let (mut intact, mut corrupted, mut rejected) = (0, 0, 0);
    let mut stamp_errors = vec![];
    for f in &frames {
        let (_, payload) = check(&f.bytes).unwrap();
        let datagram = DatagramRepr::parse(payload).unwrap();
        match datagram.body {
            DatagramBody::Records(records) => {
                for r in records {
                    match true_start_ns.get(&r.cell_packet) {
                        Some(true_ns) => {
                            intact += 1;
                            let stamp_ns = (r.tick(datagram.base_tick) + TICK_ZERO_CYCLE) * TICK_NS;
                            stamp_errors.push((stamp_ns as f64 - true_ns) / TICK_NS as f64);
                        }
                        None => corrupted += 1,
                    }
                }
            }
            DatagramBody::Status(s) => {
                rejected = [
                    PortCounter::RejectedEndByte,
                    PortCounter::RejectedFraming,
                    PortCounter::RejectedTruncated,
                    PortCounter::GarbageBytes,
                ]
                .iter()
                .map(|c| s.ports[0].get(*c))
                .sum();
            }
        }
    }
    Outcome {
        intact,
        corrupted,
        rejected,
        stamp_errors,
    }
}

/// Within the receiver's tolerance every packet arrives with the tick of its true start
/// edge (within the one tick of sampling). Up to +-4.75 %: at +4.5 % and beyond, the stop
/// bit's middle is sampled just before the next start edge, where the next header's start
/// once got a wrong tick although its bytes were intact.
#[test]
fn within_the_receivers_tolerance_every_packet_arrives_with_its_start_edge() {
    for e in [
        -4.7, -4.5, -4.0, -3.0, -1.0, 0.0, 1.0, 3.0, 4.0, 4.4, 4.5, 4.6, 4.7,
    ] {
        let o = run(e);
        assert_eq!(
            (o.intact, o.corrupted, o.rejected),
            (PACKETS, 0, 0),
            "{e} %"
        );
        let worst = o.stamp_errors.iter().fold(f64::NAN, |a, &b| {
            if a.is_nan() || (b - 0.5).abs() > (a - 0.5).abs() {
                b
            } else {
                a
            }
        });
        assert!(
            o.stamp_errors.iter().all(|x| (0.0..1.0).contains(x)),
            "{e} %: stamp - true start edge {worst} ticks"
        );
    }
}

#[test]
fn beyond_the_failure_point_nothing_corrupted_is_delivered() {
    for e in [-10.0, -7.0, -6.0, -5.5, 5.5, 6.0, 7.0, 10.0] {
        let Outcome {
            intact,
            corrupted,
            rejected,
            ..
        } = run(e);
        eprintln!(
            "{e:+} %: {intact} intact, {corrupted} corrupted, {rejected} rejected or garbage"
        );
        assert_eq!(corrupted, 0, "{e} %: corrupted packets delivered");
        assert!(
            intact < PACKETS,
            "{e} %: expected the receiver to fail here"
        );
        assert!(rejected > 0, "{e} %: losses must be counted");
    }
}
