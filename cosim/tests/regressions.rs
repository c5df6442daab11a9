//! Regression co-simulations of the verilated box: flushing by full datagram and by
//! timeout, and status counters that match injected faults.

use skinbox_cosim::frames::{assemble, check};
use skinbox_cosim::harness::play;
use skinbox_cosim::line::{back_to_back, transitions, Transition, UartByte};
use skinbox_cosim::reference::{predict_frames, run_reference};
use skinbox_cosim::sim::{run_rtl, SentPacket, SimSpec, RESET_CYCLES};
use skinbox_cosim::{Dut, Model};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::datagram::{DatagramBody, FLAG_FLUSH_TIMEOUT, MAX_RECORDS};
use skinbox_protocol::status::PortCounter;
use skinbox_protocol::{DataRepr, DatagramRepr};

fn packet(id: u16) -> [u8; PACKET_LEN] {
    DataRepr::from_raw(id, [1, 2, 3, 4, 5, 6, 7, 8, 9])
        .unwrap()
        .to_bytes()
}

#[test]
fn busy_ports_fill_datagrams_a_lull_flushes_by_timeout() {
    // 8 ports at line rate for 3 ms with a 1 ms flush timeout: datagrams fill to 55
    // records; the last one leaves by timeout
    let config = BoxConfig {
        ports: 8,
        flush_timeout_ticks: 125_000,
        status_period_ticks: 1_000_000,
        ..BoxConfig::default()
    };
    let per_port = 60;
    let spec = SimSpec {
        config,
        ports: (0..8u16)
            .map(|p| {
                (0..per_port)
                    .map(|k| SentPacket {
                        bytes: packet(p * 100 + k + 1),
                        start_ns: 5_000.0 + f64::from(p) * 11.0 + f64::from(k) * 50_000.0,
                        bit_ns: 250.0,
                    })
                    .collect()
            })
            .collect(),
        duration_ns: 5_000 + u64::from(per_port) * 50_000 + 2_000_000,
        pcap: None,
        vcd: None,
        jitter: skinbox_cosim::line::Jitter::NONE,
        host_frames: vec![],
    };
    let run = run_rtl(&spec).unwrap();
    assert!(
        run_reference(&spec).unwrap().frames == run.frames,
        "reference and RTL differ"
    );
    assert_eq!(run.report.packets_delivered, 8 * u64::from(per_port));
    let sizes: Vec<(usize, u8)> = run
        .datagrams
        .iter()
        .filter_map(|d| match &d.body {
            DatagramBody::Records(r) => Some((r.len(), d.flags)),
            DatagramBody::Status(_) => None,
        })
        .collect();
    let total: usize = sizes.iter().map(|s| s.0).sum();
    assert_eq!(total, 480);
    let (last, full) = sizes.split_last().unwrap();
    assert!(
        full.iter().all(|s| *s == (MAX_RECORDS, 0)),
        "full datagrams: {sizes:?}"
    );
    assert_eq!(
        last.1, FLAG_FLUSH_TIMEOUT,
        "the rest leaves by timeout: {sizes:?}"
    );
    assert_eq!(last.0, 480 % MAX_RECORDS);
}

#[test]
fn status_counters_match_injected_faults() {
    let config = BoxConfig {
        ports: 2,
        flush_timeout_ticks: 2_000,
        status_period_ticks: 250_000,
        ..BoxConfig::default()
    };
    let bit = 250.0;
    let mut faulty: Vec<UartByte> = vec![];
    let mut t = 10_000.0;
    let push = |data: &[u8], gap_bits: f64, t: &mut f64, out: &mut Vec<UartByte>| {
        let bytes = back_to_back(data, *t, bit);
        *t = bytes.last().map_or(*t, |b| b.end_ns()) + gap_bits * bit;
        out.extend(bytes);
    };
    // 5 garbage bytes (no header value), a good packet, a truncated packet (12 bytes then
    // idle), a packet with a wrong end byte, a good packet
    push(&[0x00, 0x10, 0x20, 0x30, 0x40], 3.0, &mut t, &mut faulty);
    push(&packet(1), 3.0, &mut t, &mut faulty);
    push(&packet(2)[..12], 40.0, &mut t, &mut faulty);
    let mut wrong_end = packet(3);
    wrong_end[19] = 0x5A;
    push(&wrong_end, 3.0, &mut t, &mut faulty);
    push(&packet(4), 3.0, &mut t, &mut faulty);
    // a framing error inside a packet: its 11th byte's stop bit low
    let mut broken = back_to_back(&packet(5), t, bit);
    broken[10].stop_level = false;
    let end = broken.last().unwrap().end_ns();
    faulty.extend(broken);
    // then a 60 ns low glitch on the idle line: the receiver starts nothing, counts nothing
    let mut line = transitions(&faulty);
    let glitch = (end / 8.0) as u64 + 300;
    line.extend([
        Transition {
            edge: glitch,
            level: false,
        },
        Transition {
            edge: glitch + 8,
            level: true,
        },
    ]);

    let model = Model::build(&config, false, &skinbox_cosim::model::default_cache_dir()).unwrap();
    let mut dut = Dut::new(&model, None).unwrap();
    let clean = back_to_back(&packet(9), 30_000.0, bit);
    let lines = [line, transitions(&clean)];
    let out = play(&mut dut, &lines, RESET_CYCLES, 600_000);
    let (frames, _) = assemble(&out);
    assert!(
        predict_frames(&config, &lines, 600_000).unwrap() == frames,
        "reference and RTL differ"
    );
    let datagrams: Vec<DatagramRepr> = frames
        .iter()
        .map(|f| DatagramRepr::parse(check(&f.bytes).unwrap().1).unwrap())
        .collect();
    let delivered: Vec<[u8; PACKET_LEN]> = datagrams
        .iter()
        .filter_map(|d| match &d.body {
            DatagramBody::Records(r) => Some(r.iter().map(|r| r.cell_packet).collect::<Vec<_>>()),
            DatagramBody::Status(_) => None,
        })
        .flatten()
        .collect();
    assert_eq!(delivered.len(), 3);
    for p in [packet(1), packet(4), packet(9)] {
        assert!(delivered.contains(&p));
    }
    let status = datagrams
        .iter()
        .rev()
        .find_map(|d| match &d.body {
            DatagramBody::Status(s) => Some(s.clone()),
            DatagramBody::Records(_) => None,
        })
        .unwrap();
    let port0 = status.ports[0];
    assert_eq!(port0.get(PortCounter::PacketsGood), 2);
    assert_eq!(port0.get(PortCounter::RejectedTruncated), 1);
    assert_eq!(port0.get(PortCounter::RejectedEndByte), 1);
    assert_eq!(port0.get(PortCounter::RejectedFraming), 1);
    assert_eq!(port0.get(PortCounter::FramingErrors), 1);
    assert_eq!(port0.get(PortCounter::DroppedOverflow), 0);
    assert_eq!(port0.get(PortCounter::Resyncs), 3);
    assert!(port0.get(PortCounter::GarbageBytes) >= 5, "{port0:?}");
    assert_eq!(status.ports[1].get(PortCounter::PacketsGood), 1);
    assert_eq!(status.records_sent, 3);
}
