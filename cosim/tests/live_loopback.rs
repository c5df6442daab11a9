//! The live path on loopback: a pcap is replayed to a capture on 127.0.0.1:0 and every
//! record received is compared with the pcap's, one by one.

use skinbox_cosim::synthetic::{self, SyntheticConfig};
use skinbox_host::bench::loopback_run;
use skinbox_host::pcap::{self, PcapFrameWriter, PcapOptions};
use skinbox_host::replay::Pacing;
use std::net::SocketAddr;
use std::time::Duration;

#[test]
fn replayed_pcap_arrives_record_by_record() {
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 120,
        samples_per_cell: 40,
        status_period_ticks: 2_500_000,
        ..SyntheticConfig::default()
    })
    .unwrap();
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
    // the same records and cells, from the sending socket's address instead of the pcap's
    for (live, file) in run.records.iter().zip(&from_file.records) {
        assert_eq!(live.source.map(|a| a.ip()), Some([127, 0, 0, 1].into()));
        let live = skinbox_host::DecodedRecord {
            source: file.source,
            ..*live
        };
        assert_eq!(&live, file);
    }
    assert_eq!(run.report.losses, from_file.report.losses);
    assert_eq!(run.report.records, from_file.report.records);
    let without_source = |cells: &[skinbox_host::report::CellReport]| {
        cells
            .iter()
            .map(|c| skinbox_host::report::CellReport {
                source: None,
                ..c.clone()
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(
        without_source(&run.report.cells),
        without_source(&from_file.report.cells)
    );
}

#[test]
fn one_socket_follows_several_boxes() {
    use skinbox_host::live::{self, CaptureLimits};
    use skinbox_host::{Decoder, DecoderConfig};
    let boxes: Vec<Vec<Vec<u8>>> = [1u16, 2]
        .iter()
        .map(|&box_id| {
            synthetic::generate(&SyntheticConfig {
                cells: 30,
                samples_per_cell: 20,
                box_id,
                seed: u64::from(box_id),
                ..SyntheticConfig::default()
            })
            .unwrap()
            .payloads()
        })
        .collect();
    let total: usize = boxes.iter().map(|b| b.len()).sum();
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let (report, stats, senders) = rt.block_on(async {
        let (socket, _) = live::bind_udp("127.0.0.1:0".parse().unwrap(), 1 << 20).unwrap();
        let to = socket.local_addr().unwrap();
        // Both boxes send from their own socket, interleaved datagram by datagram.
        let senders: Vec<std::net::UdpSocket> = (0..2)
            .map(|_| std::net::UdpSocket::bind("127.0.0.1:0").unwrap())
            .collect();
        let addrs: Vec<SocketAddr> = senders.iter().map(|s| s.local_addr().unwrap()).collect();
        let payloads = boxes.clone();
        let thread = std::thread::spawn(move || {
            for i in 0..payloads[0].len().max(payloads[1].len()) {
                for (s, p) in senders.iter().zip(&payloads) {
                    if let Some(p) = p.get(i) {
                        s.send_to(p, to).unwrap();
                    }
                }
                std::thread::sleep(Duration::from_micros(50));
            }
        });
        let mut decoder = Decoder::new(DecoderConfig::default());
        let stats = live::run_capture(
            &socket,
            &mut decoder,
            &mut (),
            None::<&mut PcapFrameWriter<Vec<u8>>>,
            CaptureLimits {
                max_datagrams: Some(total as u64),
                ..CaptureLimits::default()
            },
            tokio::time::sleep(Duration::from_secs(20)),
            &mut |_, _| {},
        )
        .await
        .unwrap();
        thread.join().unwrap();
        (decoder.report(), stats, addrs)
    });
    assert_eq!(stats.datagrams, total as u64);
    assert!(stats.receive_calls >= 1 && stats.receive_calls <= stats.datagrams);
    assert_eq!(report.boxes.len(), 2);
    for (b, (payloads, source)) in report.boxes.iter().zip(boxes.iter().zip(&senders)) {
        let alone = pcap_free_report(payloads);
        assert_eq!(b.source, Some(*source));
        assert_eq!(b.records, alone.records);
        assert_eq!(b.losses.datagrams_missing, 0);
    }
}

fn pcap_free_report(payloads: &[Vec<u8>]) -> skinbox_host::Report {
    let mut d = skinbox_host::Decoder::new(skinbox_host::DecoderConfig::default());
    for p in payloads {
        d.push_datagram(p, &mut ());
    }
    d.report()
}
