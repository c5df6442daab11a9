//! The downlink at RTL: cell commands sent by the host on GMII leave the verilated box on
//! its UART transmit pins. Every pin change must equal the reference model's (the clock
//! model of the downlink inside the control model), the acknowledgements the control
//! model's, and the pins, decoded here by sampling each bit in its middle, must carry
//! exactly the packets the box accepted, port by port, in order. The uplink meanwhile runs
//! at line rate and loses nothing.

mod support;

use skinbox_cosim::harness::{LINK_SPEED, LINK_UP};
use skinbox_cosim::reference::run_reference;
use skinbox_cosim::run::{HostFrame, SimSpec, TICK_ZERO_CYCLE};
use skinbox_cosim::sim::run_rtl;
use skinbox_gateware::interface_box::{BoxConfig, RECEIVE_TICK_LAG};
use skinbox_model::control::{BoxControl, ControlConfig};
use skinbox_model::downlink::PinChange;
use skinbox_model::timing::DOWNLINK_OFFER_AFTER_RECEIVE_TICK;
use skinbox_protocol::box_counters::BoxCounter;
use skinbox_protocol::command::{AckRepr, AckResult, Request, ALL_PORTS};
use support::*;

#[test]
fn cell_commands_leave_on_the_uart_pins_as_the_reference_says_while_the_uplink_runs_at_line_rate() {
    let config = box_config();
    let us = 125u64;
    let schedule = downlink_schedule();
    let mut host_frames: Vec<HostFrame> = schedule
        .iter()
        .enumerate()
        .map(|(i, &(edge, port, n, _))| HostFrame {
            edge,
            frame: command(
                HOST_IP,
                100 + i as u32,
                Request::CellCommand {
                    port,
                    packet: cell_packet(n),
                },
            ),
        })
        .collect();
    host_frames.push(HostFrame {
        edge: 420 * us,
        frame: command(HOST_IP, 1000, Request::StatusNow),
    });
    let duration_ns = 440_000;
    let spec = SimSpec {
        config: config.clone(),
        ports: traffic(config.ports, 20_000.0, 300_000.0, 50_000.0),
        duration_ns,
        pcap: None,
        vcd: None,
        jitter: skinbox_cosim::line::Jitter::NONE,
        host_frames: host_frames.clone(),
    };
    let run = run_rtl(&spec).unwrap();
    let predicted = run_reference(&spec).unwrap();
    assert_eq!(
        run.frames, predicted.frames,
        "frames: RTL against reference"
    );
    assert!(!run.uart_tx.is_empty());
    for (i, (r, p)) in run.uart_tx.iter().zip(&predicted.uart_tx).enumerate() {
        assert_eq!(r, p, "pin change {i}: RTL against reference");
    }
    assert_eq!(run.uart_tx.len(), predicted.uart_tx.len(), "pin changes");

    // the acknowledgements: the control model's, with the results the rules give
    let mut m = BoxControl::new(ControlConfig::of(&config));
    m.counters.link_up = LINK_UP;
    m.counters.link_speed = LINK_SPEED;
    let receive_tick = |f: &HostFrame| f.last_edge() + RECEIVE_TICK_LAG - TICK_ZERO_CYCLE;
    let acks: Vec<AckRepr> = run
        .replies
        .iter()
        .map(|f| AckRepr::parse(&f.bytes[8 + 42..f.bytes.len() - 4]).unwrap())
        .collect();
    assert_eq!(acks.len(), host_frames.len());
    for (i, f) in host_frames.iter().enumerate() {
        let outcome = m.receive(&f.frame, receive_tick(f));
        let Some(skinbox_model::control::Reply::Ack { ack, .. }) = outcome.reply else {
            panic!("frame {i}: no acknowledgement from the model");
        };
        assert_eq!(acks[i].result, ack.result, "frame {i}");
        if let Some(&(_, _, _, result)) = schedule.get(i) {
            assert_eq!(acks[i].result, result, "frame {i}");
        }
    }
    let counters = match acks.last().unwrap().reply {
        skinbox_protocol::command::AckReply::Counters(c) => c,
        r => panic!("status now answered {r:?}"),
    };
    // five cell commands and the status now
    assert_eq!(counters.get(BoxCounter::CommandsAccepted), 6);
    assert_eq!(counters.get(BoxCounter::RefusedDownlinkFull), 3);

    // the pins carry the accepted packets, whole, port by port, in order
    let mut expected: Vec<Vec<u8>> = vec![vec![]; config.ports];
    for &(_, port, n, result) in &schedule {
        if result == AckResult::Ok {
            for (p, bytes) in expected.iter_mut().enumerate() {
                if port == ALL_PORTS || usize::from(port) == p {
                    bytes.extend(cell_packet(n));
                }
            }
        }
    }
    let decoded = decode_pins(&run.uart_tx, config.ports);
    for (p, bytes) in decoded.iter().enumerate() {
        let got: Vec<u8> = bytes.iter().map(|b| b.1).collect();
        assert_eq!(got, expected[p], "port {p}");
    }
    // an accepted command's first start bit leaves after the offer and the copy (22
    // clocks), at the start of the frame after the next refill scan: within two frames
    let first_ok = &host_frames[0];
    let start = decoded[3][0].0;
    let earliest = receive_tick(first_ok) + DOWNLINK_OFFER_AFTER_RECEIVE_TICK;
    let frame_ticks = skinbox_gateware::cell_downlink::frame_bits(config.ports) as f64 * BIT_TICKS;
    assert!(
        start > earliest + 22 && start as f64 <= (earliest + 22) as f64 + 2.0 * frame_ticks + 1.0,
        "first start bit at {start}, offer at {earliest}"
    );
    // two queued packets go out back to back: 400 bits
    let second = decoded[3][20].0;
    assert!(((second - start) as f64 - 200.0 * BIT_TICKS).abs() <= 1.0);

    let r = &run.report;
    assert_eq!(
        (r.packets_delivered, r.records_corrupted, r.records_mistimed),
        (r.packets_sent, 0, 0),
        "no record lost while commands went down: {r:?}"
    );
}

#[test]
fn scene_commands_sent_by_the_host_switch_the_cells_rate_and_mode_at_rtl() {
    use skinbox_cells::scene::Scene;
    use skinbox_cells::GenerateOptions;
    use skinbox_protocol::datagram::DatagramBody;
    use skinbox_protocol::CellRepr;
    // 8 idle cells on 2 buses in data mode at 125 Hz; the host sends "250 Hz" to bus 1 at
    // 30 ms and "event mode" to every cell at 60 ms
    let text = std::fs::read_to_string(skinbox_cells::scenes_dir().join("mode_switch.toml"))
        .unwrap()
        .replace("duration_s = 3.0", "duration_s = 0.09")
        .replace("warmup_s = 0.5", "warmup_s = 0.0")
        .replace("cells = 260", "cells = 8")
        .replace("buses = 4", "buses = 2")
        .replace(
            "time_s = 1.5\nmode = \"event\"",
            "time_s = 0.06\nmode = \"event\"\n\n[[commands]]\ntime_s = 0.03\nport = 1\nrate_hz = 250.0",
        );
    let scene = Scene::parse(&text, "small_switch.toml").unwrap();
    // the scene's own sync on bus 0 is the one that moves its cells onto the grid: the
    // box's syncs off (they have a test of their own, sync_generator.rs)
    let config = BoxConfig {
        ports: 2,
        sync_period_ticks: 0,
        ..BoxConfig::default()
    };
    let (from_ns, duration_ns) = (10_000_000, 70_000_000);
    let plan = skinbox_cosim::scene::plan_downlink(&scene, &config, from_ns, duration_ns);
    assert_eq!(
        (plan.host_frames.len(), plan.accepted, plan.refused),
        (2, 2, 0)
    );
    // the rate change leaves on port 1 only, the mode change on both
    let starts: Vec<(usize, u64)> = plan.starts.iter().map(|s| (s.port, s.tick)).collect();
    assert_eq!(starts.iter().filter(|s| s.0 == 1).count(), 2);
    assert_eq!(starts.iter().filter(|s| s.0 == 0).count(), 1);
    let generated = skinbox_cosim::scene::generate_with(
        &scene,
        0.08,
        &GenerateOptions {
            downlink: Some(plan.per_bus.clone()),
            ..Default::default()
        },
    )
    .unwrap();
    let mut spec = skinbox_cosim::scene::spec(&generated, config.clone(), from_ns, duration_ns);
    spec.host_frames = plan.host_frames.clone();
    let run = run_rtl(&spec).unwrap();
    let last = skinbox_cosim::run::cycles(&spec) - TICK_ZERO_CYCLE;
    let planned: Vec<PinChange> = plan
        .pin_changes
        .iter()
        .filter(|c| c.tick <= last)
        .copied()
        .collect();
    assert_eq!(
        run.uart_tx, planned,
        "the box's pins are the plan the cells were driven with"
    );

    // the decoded records: (cell id, bus, box tick, data or event)
    let framing = skinbox_protocol::CellFraming::default();
    let mut records = vec![];
    for d in &run.datagrams {
        if let DatagramBody::Records(rs) = &d.body {
            for r in rs {
                let tick = (d.base_tick as i64 + i64::from(r.tick_offset)) as u64;
                match CellRepr::parse(&r.cell_packet, &framing).unwrap() {
                    CellRepr::Data(p) => records.push((p.cell_id, r.port, tick, true)),
                    CellRepr::Event(p) => records.push((p.cell_id, r.port, tick, false)),
                }
            }
        }
    }
    // the latest a command can take effect: its packet on the line, 4 hops, the cell's
    // next sample (8 ms at 125 Hz), relayed back (4 hops and the root's queue, < 1 ms)
    let ms = 125_000u64;
    let bound = |start: u64| start + 50 * 125 + 4 * 52 * 125 + 8 * ms + ms;
    let rate_start = plan.starts.iter().find(|s| s.port == 1).unwrap().tick;
    let mode_start = plan.starts.iter().rfind(|s| s.port == 0).unwrap().tick;
    // the median time between one cell's data records on a bus, in a window of ticks
    let spacing_ms = |port: u8, from: u64, to: u64| {
        let mut gaps = vec![];
        for cell in records
            .iter()
            .filter(|r| r.1 == port)
            .map(|r| r.0)
            .collect::<std::collections::BTreeSet<_>>()
        {
            let ticks: Vec<u64> = records
                .iter()
                .filter(|r| r.0 == cell && r.3 && r.2 >= from && r.2 < to)
                .map(|r| r.2)
                .collect();
            gaps.extend(ticks.windows(2).map(|w| (w[1] - w[0]) as f64 / ms as f64));
        }
        gaps.sort_by(f64::total_cmp);
        assert!(gaps.len() >= 4, "port {port}: {} gaps", gaps.len());
        gaps[gaps.len() / 2]
    };
    // before the rate command both buses sample every 8 ms
    for port in [0, 1] {
        let gap = spacing_ms(port, 0, rate_start);
        assert!((gap - 8.0).abs() < 0.1, "port {port}: {gap} ms before");
    }
    // once the rate command took effect, bus 1 every 4 ms, bus 0 still every 8 ms
    let gap_1 = spacing_ms(1, bound(rate_start), mode_start);
    let gap_0 = spacing_ms(0, bound(rate_start), mode_start);
    assert!(
        (gap_1 - 4.0).abs() < 0.1,
        "bus 1: {gap_1} ms after the rate command"
    );
    assert!((gap_0 - 8.0).abs() < 0.1, "bus 0: {gap_0} ms");
    // no event packet before the mode command left the box, no data packet once it took
    // effect; events after it (the switch re-sends every channel once)
    assert!(records.iter().all(|r| r.3 || r.2 >= mode_start));
    let late = bound(mode_start);
    assert!(records.iter().all(|r| !r.3 || r.2 < late));
    assert!(records.iter().filter(|r| !r.3).count() >= 8);
}
