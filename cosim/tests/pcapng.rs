//! pcapng as Wireshark's tools write it: a pcap made by the project, converted by editcap
//! (`editcap -F pcapng`) and merged by mergecap (two interfaces with different timestamp
//! resolutions), decodes to exactly what the pcap decodes to. Needs editcap and mergecap
//! (Debian's wireshark-common; scripts/test installs it). Simple packet blocks (no
//! timestamp) are read and counted, outside the capture span.

use pcap_file::pcap::{PcapHeader, PcapPacket, PcapTsResolution, PcapWriter};
use pcap_file::pcapng::blocks::enhanced_packet::EnhancedPacketBlock;
use pcap_file::pcapng::blocks::interface_description::InterfaceDescriptionBlock;
use pcap_file::pcapng::blocks::simple_packet::SimplePacketBlock;
use pcap_file::pcapng::{PcapNgBlock, PcapNgWriter};
use pcap_file::DataLink;
use skinbox_cosim::synthetic::{self, SyntheticConfig};
use skinbox_host::pcap::{decode_pcap_bytes, udp_payloads, PcapFrameWriter, PcapOptions};
use std::borrow::Cow;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

fn dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(tool: &str, args: &[&Path]) {
    let out = Command::new(tool)
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("{tool} not runnable ({e}): install wireshark-common"));
    assert!(
        out.status.success(),
        "{tool} {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn payloads(box_id: u16, seed: u64) -> Vec<Vec<u8>> {
    synthetic::generate(&SyntheticConfig {
        cells: 30,
        samples_per_cell: 40,
        box_id,
        seed,
        ..SyntheticConfig::default()
    })
    .unwrap()
    .payloads()
}

const HOST: &str = "192.0.2.1:54091";
const T0: u64 = 1_700_000_000;

/// The project's writer: nanosecond pcap. Timestamps with digits below the microsecond.
fn nanosecond_pcap(box_id: u16, source: &str) -> (Vec<u8>, Vec<Duration>) {
    let mut w = PcapFrameWriter::new(Vec::new()).unwrap();
    let src: SocketAddr = source.parse().unwrap();
    let mut times = Vec::new();
    for (i, p) in payloads(box_id, 1).iter().enumerate() {
        let t = Duration::new(T0, 789 + 1_000_000 * i as u32);
        w.write_udp(t, src, HOST.parse().unwrap(), p).unwrap();
        times.push(t);
    }
    (w.finish().unwrap(), times)
}

/// A microsecond pcap of another box, frames built by the project's frame builder.
fn microsecond_pcap(box_id: u16, source: &str) -> (Vec<u8>, Vec<Duration>) {
    let header = PcapHeader {
        datalink: DataLink::ETHERNET,
        ts_resolution: PcapTsResolution::MicroSecond,
        ..PcapHeader::default()
    };
    let mut w = PcapWriter::with_header(Vec::new(), header).unwrap();
    let src: SocketAddr = source.parse().unwrap();
    let mut times = Vec::new();
    for (i, p) in payloads(box_id, 2).iter().enumerate() {
        let t = Duration::new(T0, 456_000 + 1_000_000 * i as u32);
        let frame = skinbox_host::frame::build_udp_frame(src, HOST.parse().unwrap(), p);
        w.write_packet(&PcapPacket::new(t, frame.len() as u32, &frame[..]).unwrap())
            .unwrap();
        times.push(t);
    }
    (w.into_inner(), times)
}

#[test]
fn editcap_pcapng_decodes_like_the_pcap() {
    let d = dir("pcapng_editcap");
    let (pcap, _) = nanosecond_pcap(1, "192.0.2.10:54091");
    let (a, b) = (d.join("in.pcap"), d.join("out.pcapng"));
    std::fs::write(&a, &pcap).unwrap();
    run("editcap", &[Path::new("-F"), Path::new("pcapng"), &a, &b]);
    let ng = std::fs::read(&b).unwrap();
    assert_eq!(
        &ng[..4],
        &[0x0A, 0x0D, 0x0D, 0x0A],
        "editcap wrote no pcapng"
    );
    let from_pcap = decode_pcap_bytes(&pcap, &PcapOptions::default()).unwrap();
    let from_ng = decode_pcap_bytes(&ng, &PcapOptions::default()).unwrap();
    assert!(!from_pcap.records.is_empty());
    assert_eq!(from_ng.records, from_pcap.records);
    assert_eq!(
        from_ng.report.bad_input.total, 0,
        "{:?}",
        from_ng.report.bad_input
    );
    assert_eq!(from_ng.report.frames.frames, from_pcap.report.frames.frames);
    assert_eq!(
        from_ng.report.frames.capture_span_s,
        from_pcap.report.frames.capture_span_s
    );
    // Same payloads at the same nanosecond timestamps.
    assert_eq!(
        udp_payloads(&ng, None).unwrap().0,
        udp_payloads(&pcap, None).unwrap().0
    );
}

#[test]
fn mergecap_pcapng_with_two_interfaces_and_resolutions() {
    let d = dir("pcapng_mergecap");
    let (ns, ns_times) = nanosecond_pcap(1, "192.0.2.10:54091");
    let (us, us_times) = microsecond_pcap(2, "192.0.2.11:54091");
    let (a, b, m) = (
        d.join("ns.pcap"),
        d.join("us.pcap"),
        d.join("merged.pcapng"),
    );
    std::fs::write(&a, &ns).unwrap();
    std::fs::write(&b, &us).unwrap();
    run(
        "mergecap",
        &[
            Path::new("-F"),
            Path::new("pcapng"),
            Path::new("-w"),
            &m,
            &a,
            &b,
        ],
    );
    let merged = std::fs::read(&m).unwrap();
    assert_eq!(&merged[..4], &[0x0A, 0x0D, 0x0D, 0x0A]);

    // Every frame at its own timestamp: nanoseconds from one interface, microseconds from
    // the other (if_tsresol 9 and 6).
    let (got, scan) = udp_payloads(&merged, None).unwrap();
    assert_eq!(scan.bad.total, 0, "{:?}", scan.bad);
    let mut want: Vec<(Duration, Vec<u8>)> = udp_payloads(&ns, None)
        .unwrap()
        .0
        .into_iter()
        .chain(udp_payloads(&us, None).unwrap().0)
        .map(|p| (p.timestamp, p.payload))
        .collect();
    let mut got: Vec<(Duration, Vec<u8>)> =
        got.into_iter().map(|p| (p.timestamp, p.payload)).collect();
    want.sort();
    got.sort();
    assert_eq!(got.len(), ns_times.len() + us_times.len());
    assert_eq!(got, want);
    assert!(got.iter().any(|(t, _)| t.subsec_nanos() % 1_000 == 789));

    // Both boxes, each whole and lossless.
    let decoded = decode_pcap_bytes(&merged, &PcapOptions::default()).unwrap();
    let report = &decoded.report;
    assert_eq!(report.boxes.len(), 2);
    for (b, pcap) in report.boxes.iter().zip([&ns, &us]) {
        let alone = decode_pcap_bytes(pcap, &PcapOptions::default()).unwrap();
        assert_eq!(b.records, alone.report.records, "box {}", b.box_id);
        assert_eq!(b.losses.datagrams_missing, 0, "box {}", b.box_id);
        let mine: Vec<_> = decoded
            .records
            .iter()
            .filter(|r| r.box_id == b.box_id)
            .copied()
            .collect();
        assert_eq!(mine, alone.records);
    }
}

/// A pcapng written here: enhanced packet blocks 1 ms apart, with simple packet blocks
/// (no timestamp) first and in between. Every frame is counted and decoded; the span is
/// the enhanced packets' alone.
#[test]
fn simple_packet_blocks_are_counted_and_have_no_time() {
    let src: SocketAddr = "192.0.2.10:54091".parse().unwrap();
    let frames: Vec<Vec<u8>> = payloads(1, 3)
        .iter()
        .map(|p| skinbox_host::frame::build_udp_frame(src, HOST.parse().unwrap(), p))
        .collect();
    assert!(frames.len() > 4, "{}", frames.len());
    let mut w = PcapNgWriter::new(Vec::new()).unwrap();
    w.write_block(
        &InterfaceDescriptionBlock {
            linktype: DataLink::ETHERNET,
            snaplen: 0,
            options: vec![],
        }
        .into_block(),
    )
    .unwrap();
    let simple = [0, frames.len() / 2];
    let mut enhanced = 0u32;
    for (i, f) in frames.iter().enumerate() {
        let block = if simple.contains(&i) {
            SimplePacketBlock {
                original_len: f.len() as u32,
                data: Cow::Borrowed(&f[..]),
            }
            .into_block()
        } else {
            enhanced += 1;
            EnhancedPacketBlock {
                interface_id: 0,
                timestamp: Duration::new(T0, 1_000_000 * enhanced),
                original_len: f.len() as u32,
                data: Cow::Borrowed(&f[..]),
                options: vec![],
            }
            .into_block()
        };
        w.write_block(&block).unwrap();
    }
    let ng = w.into_inner();

    let (got, scan) = udp_payloads(&ng, None).unwrap();
    assert_eq!(scan.bad.total, 0, "{:?}", scan.bad);
    assert_eq!(scan.frames.frames, frames.len() as u64);
    assert_eq!(scan.frames.udp_payloads, frames.len() as u64);
    assert_eq!(got.len(), frames.len());
    for i in simple {
        assert_eq!(got[i].timestamp, Duration::ZERO);
    }
    // The enhanced packets span (enhanced - 1) ms.
    let want_span = f64::from(enhanced - 1) * 1e-3;
    assert!(
        (scan.frames.capture_span_s - want_span).abs() < 1e-9,
        "{} s",
        scan.frames.capture_span_s
    );

    let decoded = decode_pcap_bytes(&ng, &PcapOptions::default()).unwrap();
    assert_eq!(decoded.report.frames, scan.frames);
    assert_eq!(decoded.report.losses.datagrams_missing, 0);
    let mut from_pcap = PcapFrameWriter::new(Vec::new()).unwrap();
    for (i, f) in frames.iter().enumerate() {
        from_pcap
            .write_frame(Duration::new(T0, 1_000_000 * i as u32), f)
            .unwrap();
    }
    let alone = decode_pcap_bytes(&from_pcap.finish().unwrap(), &PcapOptions::default()).unwrap();
    assert!(!alone.records.is_empty());
    assert_eq!(decoded.records, alone.records);
}
