//! The receiver's failure point under UART clock mismatch, through the verilated box:
//! within +-4 % every packet arrives intact; beyond the point where bytes break, the box
//! rejects packets but delivers none corrupted, and the status counters show the loss:
//! rejected packets, or, where not even a header byte survives, garbage bytes.

use skinbox_cosim::frames::{assemble, check};
use skinbox_cosim::harness::play;
use skinbox_cosim::line::{back_to_back, transitions};
use skinbox_cosim::reference::predict_frames;
use skinbox_cosim::sim::RESET_CYCLES;
use skinbox_cosim::traffic::random_data_packets;
use skinbox_cosim::{Dut, Model};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::status::PortCounter;
use skinbox_protocol::DatagramRepr;
use std::collections::HashSet;

const PACKETS: usize = 150;

/// (delivered intact, delivered corrupted, rejected packets + garbage bytes counted).
fn run(error_percent: f64) -> (usize, usize, u32) {
    let config = BoxConfig {
        ports: 1,
        flush_timeout_ticks: 5_000,
        status_period_ticks: 2_000_000,
        ..BoxConfig::default()
    };
    let model = Model::build(&config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    let mut dut = Dut::new(&model, None).unwrap();
    let sent = random_data_packets(PACKETS);
    let bytes: Vec<u8> = sent.iter().flatten().copied().collect();
    let bit_ns = 250.0 / (1.0 + error_percent / 100.0);
    let line = transitions(&back_to_back(&bytes, 10_000.0, bit_ns));
    let cycles = (10_000.0 + bytes.len() as f64 * 10.0 * bit_ns) as u64 / 8 + 2_000_100;
    let out = play(&mut dut, std::slice::from_ref(&line), RESET_CYCLES, cycles);
    let (frames, _) = assemble(&out);
    // the reference model predicts the same frames, failures included
    assert!(
        predict_frames(&config, &[line], cycles).unwrap() == frames,
        "reference and RTL differ at {error_percent} %"
    );
    let sent: HashSet<[u8; PACKET_LEN]> = sent.into_iter().collect();
    let (mut intact, mut corrupted, mut rejected) = (0, 0, 0);
    for f in &frames {
        let (_, payload) = check(&f.bytes).unwrap();
        match DatagramRepr::parse(payload).unwrap().body {
            DatagramBody::Records(records) => {
                for r in records {
                    if sent.contains(&r.cell_packet) {
                        intact += 1;
                    } else {
                        corrupted += 1;
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
    (intact, corrupted, rejected)
}

#[test]
fn within_4_percent_every_packet_arrives() {
    for e in [-4.0, -3.0, -1.0, 0.0, 1.0, 3.0, 4.0] {
        let (intact, corrupted, rejected) = run(e);
        assert_eq!((intact, corrupted, rejected), (PACKETS, 0, 0), "{e} %");
    }
}

#[test]
fn beyond_the_failure_point_nothing_corrupted_is_delivered() {
    for e in [-10.0, -7.0, -6.0, -5.5, 5.5, 6.0, 7.0, 10.0] {
        let (intact, corrupted, rejected) = run(e);
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
