//! Where box tick 0 is and what the box sends after reset, as docs/wire-format.md ("Box
//! time and reset") says, at RTL and in the reference model.

use skinbox_cosim::line::Jitter;
use skinbox_cosim::reference::run_reference;
use skinbox_cosim::run::{SentPacket, SimSpec, PORTS_READY_CYCLE, RESET_CYCLES, TICK_ZERO_CYCLE};
use skinbox_cosim::sim::run_rtl;
use skinbox_gateware::counter_file::CLEAR_CLOCKS;
use skinbox_gateware::interface_box::{BoxConfig, RESET_LATENCY};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::{DataRepr, TICK_NS};

/// The figures of "Box time and reset", as the document words them.
fn doc() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../docs/wire-format.md"
    ))
    .unwrap()
    .split_whitespace()
    .collect::<Vec<_>>()
    .join(" ")
}

/// A spec of `config` with one packet on port 1 whose start edge is sampled at
/// `start_cycle`.
fn spec(config: BoxConfig, start_cycle: u64, cycles: u64) -> SimSpec {
    let mut ports = vec![vec![]; config.ports];
    ports[1].push(SentPacket {
        bytes: DataRepr::from_raw(9, [1; 9]).unwrap().to_bytes(),
        // just before the sampling edge
        start_ns: (start_cycle * TICK_NS) as f64 - 1.0,
        bit_ns: 250.0,
    });
    SimSpec {
        config,
        ports,
        duration_ns: cycles * TICK_NS,
        pcap: None,
        vcd: None,
        jitter: Jitter::NONE,
        host_frames: vec![],
    }
}

#[test]
fn tick_zero_and_the_status_report_after_reset() {
    // the default box (the model other tests build): its first datagrams at RTL
    let start_cycle = 2_000u64;
    let short = spec(BoxConfig::default(), start_cycle, 30_000);
    let rtl = run_rtl(&short).unwrap();
    assert_eq!(
        rtl.datagrams,
        run_reference(&short).unwrap().datagrams,
        "RTL == reference"
    );
    assert_eq!(rtl.report.records_mistimed, 0);

    // tick 0: the clock after the reset register, RESET_LATENCY after the reset pin falls
    assert_eq!((RESET_CYCLES, RESET_LATENCY, TICK_ZERO_CYCLE), (4, 1, 5));
    let d = doc();
    assert!(d.contains(&format!(
        "`RESET_LATENCY` ({RESET_LATENCY}) clock after the edge that samples the `reset` pin low"
    )));
    assert!(d.contains(&format!(
        "holds reset for `RESET_CYCLES` ({RESET_CYCLES}) clocks, so tick 0 is simulation cycle {TICK_ZERO_CYCLE} (`TICK_ZERO_CYCLE`) and a packet whose start edge is sampled at cycle `c` is stamped tick `c - {TICK_ZERO_CYCLE}`"
    )));
    let record = rtl
        .datagrams
        .iter()
        .find_map(|d| match &d.body {
            DatagramBody::Records(r) => Some(r[0].tick(d.base_tick)),
            _ => None,
        })
        .unwrap();
    assert_eq!(record, start_cycle - TICK_ZERO_CYCLE);

    // after reset: a status report first, sequence 0, when the counters have cleared
    let first = &rtl.datagrams[0];
    let ready_tick = PORTS_READY_CYCLE - TICK_ZERO_CYCLE;
    assert_eq!(ready_tick, CLEAR_CLOCKS + 1);
    assert!(matches!(first.body, DatagramBody::Status(_)));
    assert_eq!((first.sequence, first.base_tick), (0, ready_tick));
    assert!(d.contains(&format!(
        "sequence 0, base tick {ready_tick}, the tick its counters have cleared (`CLEAR_CLOCKS` ({CLEAR_CLOCKS}) after tick 0, plus one)"
    )));

    // then one every period (the reference model, which the RTL tests hold equal to it)
    let period = 50_000u64;
    let config = BoxConfig {
        status_period_ticks: period,
        ..BoxConfig::default()
    };
    let long = run_reference(&spec(config, start_cycle, 2 * period + 20_000)).unwrap();
    assert_eq!(long.datagrams[0], *first);
    let later: Vec<u64> = long
        .datagrams
        .iter()
        .skip(1)
        .filter(|d| matches!(d.body, DatagramBody::Status(_)))
        .map(|d| d.base_tick)
        .collect();
    assert_eq!(later, [2 + period, 2 + 2 * period]);
    assert!(d.contains("at base tick `2 + k x status_period_ticks` for k = 1, 2, ..."));
    let sequences: Vec<u32> = long.datagrams.iter().map(|d| d.sequence).collect();
    assert_eq!(
        sequences,
        (0..long.datagrams.len() as u32).collect::<Vec<_>>()
    );
}
