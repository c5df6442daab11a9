//! Every port busy at UART line rate (20,000 packets/s each, back to back), each line with
//! its own clock error and +-10 ns of edge jitter: nothing is lost, nothing corrupted,
//! every stamp lies within one tick after the true (jittered) start edge; the reference
//! model predicts the same frames. Eight ports (the default box), 45 (the board's largest
//! box: both banks of the packet store; busy lines at clock errors up to +-3 %, idle and
//! edge-of-tolerance lines through the one deframing engine) and 64 (the largest box, whose
//! receivers hold their bytes in hold registers) for 10 ms.

use skinbox_cosim::reference::run_reference;
use skinbox_cosim::sim::{run_rtl, SentPacket, SimSpec};
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::{Channel, DataRepr, EventRepr};

#[test]
fn eight_ports_at_line_rate_lose_nothing() {
    // clock errors from -1 % to +1 %
    at_line_rate(8, 120, 0.01);
}

#[test]
fn sixty_four_ports_at_line_rate_for_ten_ms_lose_nothing() {
    // the largest box: both banks full, 12,800 packets over 10 ms, clock errors +-3 %
    at_line_rate(64, 200, 0.03);
}

#[test]
fn forty_five_ports_busy_idle_and_at_the_tolerance_edges_through_the_shared_engine() {
    // the board's largest box: 37 ports at line rate with random clock errors (+-3 %) and
    // start phases, 6 idle, one 4 % fast and one 4 % slow (the receiver's +-4.75 % less the
    // lines' 10 ns of jitter); the deframing engine
    // visits each port every 45 clocks, the receivers hold their bytes in their shift
    // registers
    let ports = 45;
    let mut state = 0x5EED_u64;
    let mut random = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let lines: Vec<Option<(f64, f64)>> = (0..ports)
        .map(|port| match port {
            3 | 11 | 20 | 29 | 38 | 41 => None,
            43 => Some((0.04, 10_000.0)),
            44 => Some((-0.04, 10_100.0)),
            _ => Some((0.06 * random() - 0.03, 10_000.0 + 250.0 * random())),
        })
        .collect();
    check_lines(&lines, 40);
}

/// `per_port` packets back to back on each of `ports` lines, the lines' clock errors
/// spread evenly over +-`spread`.
fn at_line_rate(ports: usize, per_port: usize, spread: f64) {
    let lines: Vec<Option<(f64, f64)>> = (0..ports)
        .map(|port| {
            // start phases spread over a bit
            let error = spread * (2.0 * port as f64 / (ports - 1) as f64 - 1.0);
            Some((error, 10_000.0 + port as f64 * 37.3))
        })
        .collect();
    check_lines(&lines, per_port);
}

/// `per_port` packets back to back on each line that has a (clock error, first start
/// in ns), none on the others: the RTL loses nothing and stamps every packet within a
/// tick, and the reference model predicts its frames.
fn check_lines(lines: &[Option<(f64, f64)>], per_port: usize) {
    let ports = lines.len();
    let busy = lines.iter().filter(|l| l.is_some()).count();
    let spec = SimSpec {
        config: BoxConfig {
            ports,
            ..BoxConfig::default()
        },
        ports: lines
            .iter()
            .enumerate()
            .map(|(port, line)| {
                let Some((error, first)) = *line else {
                    return vec![];
                };
                let bit_ns = 250.0 / (1.0 + error);
                (0..per_port)
                    .map(|k| {
                        let id = (port * per_port + k + 1) as u16;
                        let bytes = if k % 2 == 0 {
                            DataRepr::from_raw(id, [k as i32, -7, 250, 1, 2, 3, 4000, 61, 0])
                                .unwrap()
                                .to_bytes()
                        } else {
                            EventRepr::new(id, k as u16, false, &[(Channel::AccelZ, -(k as i32))])
                                .unwrap()
                                .to_bytes()
                        };
                        SentPacket {
                            bytes,
                            start_ns: first + k as f64 * 200.0 * bit_ns,
                            bit_ns,
                        }
                    })
                    .collect()
            })
            .collect(),
        duration_ns: 10_000 + per_port as u64 * 50_600 + 300_000,
        pcap: None,
        vcd: None,
        jitter: skinbox_cosim::line::Jitter {
            peak_ns: 10.0,
            seed: 42,
        },
        host_frames: vec![],
    };
    let run = run_rtl(&spec).unwrap();
    assert!(
        run_reference(&spec).unwrap().frames == run.frames,
        "reference and RTL differ"
    );
    let report = run.report;
    eprintln!("{report:?}");
    assert_eq!(report.packets_sent, (busy * per_port) as u64);
    assert_eq!(report.packets_delivered, report.packets_sent);
    assert_eq!(report.records_corrupted, 0);
    assert!(
        report.losses_by_cause.iter().all(|(_, n)| *n == 0),
        "{:?}",
        report.losses_by_cause
    );
    assert!(
        report.ts_error_max_ticks < 1.0 && report.ts_error_mean_ticks >= 0.0,
        "{report:?}"
    );
    assert!(report.min_inter_frame_gap.unwrap() >= 12);
    assert!(report.status_datagrams >= 1);
}
