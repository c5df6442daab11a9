//! The live path on loopback: a pcap is replayed to a capture on 127.0.0.1:0 and every
//! record received is compared with the pcap's, one by one.

use skinbox_host::bench::loopback_run;
use skinbox_host::pcap::{self, PcapFrameWriter, PcapOptions};
use skinbox_host::replay::Pacing;
use skinbox_host::synth::{self, SynthConfig};
use std::net::SocketAddr;
use std::time::Duration;

#[test]
fn replayed_pcap_arrives_record_by_record() {
    let capture = synth::generate(&SynthConfig {
        cells: 120,
        samples_per_cell: 40,
        status_every: 25,
        ..SynthConfig::default()
    });
    // Write the capture as a pcap, the way the co-simulation or `capture --pcap` does.
    let src: SocketAddr = "127.0.0.1:5000".parse().unwrap();
    let dst: SocketAddr = "127.0.0.1:6000".parse().unwrap();
    let mut w = PcapFrameWriter::new(Vec::new()).unwrap();
    for (i, p) in capture.payloads().iter().enumerate() {
        w.write_udp(Duration::from_micros(100 * i as u64), src, dst, p)
            .unwrap();
    }
    let file = w.finish().unwrap();

    let from_file = pcap::decode_pcap_bytes(&file, &PcapOptions::default()).unwrap();
    assert_eq!(from_file.records.len(), capture.truth.len());
    let (payloads, _) = pcap::udp_payloads(&file, None).unwrap();
    let slices: Vec<&[u8]> = payloads.iter().map(|p| p.payload.as_slice()).collect();

    // Paced gently so loopback loses nothing; the capture ends when all have arrived, or
    // (only if some were lost, failing the comparison below) 20 s after the sender.
    let run = loopback_run(
        &slices,
        Pacing::Rate {
            datagrams_per_second: 20_000.0,
        },
        true,
        Duration::from_secs(20),
    )
    .unwrap();
    assert_eq!(run.sent.datagrams, payloads.len() as u64);
    assert_eq!(run.received.datagrams, payloads.len() as u64);
    assert_eq!(run.records.len(), from_file.records.len());
    for (live, file) in run.records.iter().zip(&from_file.records) {
        assert_eq!(live, file);
    }
    assert_eq!(run.report.losses, from_file.report.losses);
    assert_eq!(run.report.records, from_file.report.records);
    assert_eq!(run.report.cells, from_file.report.cells);
}
