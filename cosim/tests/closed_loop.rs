//! The loop closed at RTL: the host's cell commands go through the verilated box, the
//! cells' UART receivers decode its transmit pins, and the cells act on what they decoded.
//! The records the box sends must change as the commands say (a sync puts bus 0 on the
//! box's time grid, a rate command doubles bus 1's rate, a mode command stops the data
//! packets); the reference model closes the same loop to the same frames; and a bit
//! flipped on the way to the cells makes them miss the command.

use skinbox_cells::scene::Scene;
use skinbox_cosim::closed_loop::{run_closed_loop, ClosedLoopRun, ClosedLoopSpec};
use skinbox_cosim::sim::Fidelity;
use skinbox_gateware::interface_box::BoxConfig;
use skinbox_protocol::cell_command::{CellCommand, CellCommandRepr, CellMode, SampleRate};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::CellRepr;

/// Box ticks per ms.
const MS: u64 = 125_000;

/// 8 idle cells on 2 buses in data mode at 125 Hz (processing 20 us, 52 us a hop); the
/// host sends a time sync to bus 0 at 20 ms, "250 Hz" to bus 1 at 30 ms and "event mode"
/// to every cell at 60 ms. The box listens from 10 ms for 70 ms.
fn spec() -> ClosedLoopSpec {
    let text = std::fs::read_to_string(skinbox_cells::scenes_dir().join("mode_switch.toml"))
        .unwrap()
        .replace("duration_s = 3.0", "duration_s = 0.09")
        .replace("warmup_s = 0.5", "warmup_s = 0.0")
        .replace("cells = 260", "cells = 8")
        .replace("buses = 4", "buses = 2")
        .replace(
            "time_s = 1.5\nmode = \"event\"",
            "time_s = 0.06\nmode = \"event\"\n\n[[commands]]\ntime_s = 0.03\nport = 1\n\
             rate_hz = 250.0\n\n[[commands]]\ntime_s = 0.02\nport = 0\ntime_sync = true",
        );
    let scene = Scene::parse(&text, "small_switch.toml").unwrap();
    // the scene's own sync on bus 0 is the one that moves its cells onto the grid: the
    // box's syncs off (they have a test of their own, sync_generator.rs)
    let config = BoxConfig {
        ports: 2,
        sync_period_ticks: 0,
        ..BoxConfig::default()
    };
    ClosedLoopSpec::new(&scene, config, 10_000_000, 70_000_000)
}

/// The records: (cell id, port, box tick, data or event).
fn records(run: &ClosedLoopRun) -> Vec<(u16, u8, u64, bool)> {
    let framing = skinbox_protocol::CellFraming::default();
    let mut out = vec![];
    for d in &run.run.datagrams {
        if let DatagramBody::Records(rs) = &d.body {
            for r in rs {
                let tick = (d.base_tick as i64 + i64::from(r.tick_offset)) as u64;
                match CellRepr::parse(&r.cell_packet, &framing).unwrap() {
                    CellRepr::Data(p) => out.push((p.cell_id, r.port, tick, true)),
                    CellRepr::Event(p) => out.push((p.cell_id, r.port, tick, false)),
                }
            }
        }
    }
    out
}

/// The median time between one cell's data records on `port` in ticks `from..to`, ms.
fn spacing_ms(records: &[(u16, u8, u64, bool)], port: u8, from: u64, to: u64) -> f64 {
    let cells: std::collections::BTreeSet<u16> = records
        .iter()
        .filter(|r| r.1 == port)
        .map(|r| r.0)
        .collect();
    let mut gaps = vec![];
    for cell in cells {
        let ticks: Vec<u64> = records
            .iter()
            .filter(|r| r.0 == cell && r.3 && r.2 >= from && r.2 < to)
            .map(|r| r.2)
            .collect();
        gaps.extend(ticks.windows(2).map(|w| (w[1] - w[0]) as f64 / MS as f64));
    }
    gaps.sort_by(f64::total_cmp);
    assert!(gaps.len() >= 4, "port {port}: {} gaps", gaps.len());
    gaps[gaps.len() / 2]
}

/// The latest a command can take effect: its packet on the line, 4 hops, the cell's next
/// sample (8 ms at 125 Hz), relayed back (4 hops and the root's queue, < 1 ms).
fn effect_bound(start: u64) -> u64 {
    start + 50 * 125 + 4 * 52 * 125 + 8 * MS + MS
}

/// Where a data record of bus 0 falls from the box's 8 ms grid, ticks (signed): its stamp
/// less the cell's path to the pin (20 us processing, 52 us a hop; cell `id` at hop
/// `id - 1`), modulo the period.
fn off_grid(record: &(u16, u8, u64, bool)) -> i64 {
    let path = (20_000 + 52_000 * u64::from(record.0 - 1)) / 8;
    let phase = ((record.2 - path) % (8 * MS)) as i64;
    if phase > 4 * MS as i64 {
        phase - 8 * MS as i64
    } else {
        phase
    }
}

/// Asserts the stream of `run` changed as the commands say (the rate command on bus 1
/// applied when `rate_applied`).
fn assert_commands_applied(run: &ClosedLoopRun, rate_applied: bool) {
    let records = records(run);
    let start = |port: usize, code: fn(&CellCommand) -> bool| {
        run.received
            .iter()
            .find(|p| p.port == port && code(&CellCommandRepr::parse(&p.bytes).unwrap().command))
            .map(|p| p.tick)
    };
    let sync = start(0, |c| matches!(c, CellCommand::TimeSync { .. })).unwrap();
    let mode = start(0, |c| matches!(c, CellCommand::Mode(_))).unwrap();
    // before the sync, bus 0's cells sample on their own clocks (off the grid); after it,
    // on the box's grid, but for their drift since (100 ppm: 12.5 ticks a ms, 45 ms)
    let before: Vec<i64> = records
        .iter()
        .filter(|r| r.1 == 0 && r.3 && r.2 < sync)
        .map(off_grid)
        .collect();
    assert!(before.iter().any(|e| e.abs() > 2_000), "{before:?}");
    let after: Vec<i64> = records
        .iter()
        .filter(|r| r.1 == 0 && r.3 && r.2 > effect_bound(sync) && r.2 < mode)
        .map(off_grid)
        .collect();
    assert!(after.len() >= 8, "{after:?}");
    assert!(after.iter().all(|e| e.abs() <= 600), "{after:?}");
    // 8 ms on bus 1 before the rate command (sent at 30 ms, box tick 20 ms), on bus 0
    // after the sync; after the rate command 4 ms on bus 1 (when applied)
    let rate = start(1, |c| matches!(c, CellCommand::SampleRate(_)));
    let rate_from = rate.unwrap_or(20 * MS);
    let gap = spacing_ms(&records, 1, 0, rate_from);
    assert!((gap - 8.0).abs() < 0.1, "bus 1: {gap} ms before");
    let gap = spacing_ms(&records, 0, effect_bound(sync), mode);
    assert!((gap - 8.0).abs() < 0.1, "bus 0: {gap} ms");
    let gap_1 = spacing_ms(&records, 1, effect_bound(rate_from), mode);
    let expected = if rate_applied { 4.0 } else { 8.0 };
    assert!((gap_1 - expected).abs() < 0.1, "bus 1: {gap_1} ms");
    // no event packet before the mode command left the box, no data packet once it took
    // effect; events after it
    assert!(records.iter().all(|r| r.3 || r.2 >= mode));
    assert!(records.iter().all(|r| !r.3 || r.2 < effect_bound(mode)));
    assert!(records.iter().filter(|r| !r.3).count() >= 8);
    let r = &run.run.report;
    assert_eq!(
        (r.packets_delivered, r.records_corrupted, r.records_mistimed),
        (r.packets_sent, 0, 0),
        "{r:?}"
    );
}

#[test]
fn cells_hearing_the_rtl_pins_follow_its_commands_and_the_reference_model_agrees() {
    let spec = spec();
    let rtl = run_closed_loop(&spec, Fidelity::Rtl, &mut |_, _| {}).unwrap();
    // what the cells' receivers took: the sync (carrying the tick its first start bit
    // left at), the rate command on bus 1, the mode command on both
    let commands: Vec<(usize, CellCommand)> = rtl
        .received
        .iter()
        .map(|p| (p.port, CellCommandRepr::parse(&p.bytes).unwrap().command))
        .collect();
    let sync_tick = rtl.received[0].tick;
    assert_eq!(
        commands,
        vec![
            (
                0,
                CellCommand::TimeSync {
                    box_tick: sync_tick
                }
            ),
            (1, CellCommand::SampleRate(SampleRate::Hz250)),
            (0, CellCommand::Mode(CellMode::Event)),
            (1, CellCommand::Mode(CellMode::Event)),
        ]
    );
    assert_eq!(rtl.receiver.packets, 4);
    assert_eq!(rtl.receiver.framing_errors, 0);
    // three commands, three times the cells changed course (the mode command reaches both
    // buses in the same step)
    assert_eq!(rtl.generations, 4);
    assert_commands_applied(&rtl, true);

    let reference = run_closed_loop(&spec, Fidelity::Reference, &mut |_, _| {}).unwrap();
    assert_eq!(reference.received, rtl.received);
    assert_eq!(reference.spec.ports, rtl.spec.ports, "the cells' packets");
    assert_eq!(reference.run.uart_tx, rtl.run.uart_tx);
    assert_eq!(
        reference.run.frames, rtl.run.frames,
        "frames: reference against RTL"
    );
}

#[test]
fn a_bit_flipped_on_the_way_down_makes_the_cells_miss_the_command() {
    let mut spec = spec();
    // the stop bit of the rate command's first byte, on its way to bus 1's root
    spec.corrupt_uart_tx = Some((1, 9));
    let run = run_closed_loop(&spec, Fidelity::Rtl, &mut |_, _| {}).unwrap();
    assert_eq!(run.receiver.framing_errors, 1);
    assert_eq!(run.receiver.packets_discarded, 1);
    assert!(run.received.iter().all(|p| !matches!(
        CellCommandRepr::parse(&p.bytes).unwrap().command,
        CellCommand::SampleRate(_)
    )));
    assert_eq!(run.received.len(), 3);
    // the box sent it all the same: its pins are those of the good run
    let good = ClosedLoopSpec {
        corrupt_uart_tx: None,
        ..spec.clone()
    };
    let reference = run_closed_loop(&good, Fidelity::Reference, &mut |_, _| {}).unwrap();
    assert_eq!(run.run.uart_tx, reference.run.uart_tx);
    // bus 1 stays at 8 ms; the rest as the commands say
    assert_commands_applied(&run, false);
}

#[test]
fn a_command_heard_after_the_pins_it_changes_were_driven_is_refused() {
    use skinbox_cosim::closed_loop::Cells;
    use skinbox_cosim::error::CosimError;
    use skinbox_model::cell_uart::ReceivedPacket;
    use skinbox_protocol::cell_command::ALL_CELLS;
    let spec = spec();
    let event_mode = ReceivedPacket {
        port: 1,
        tick: 20 * MS,
        bytes: CellCommandRepr {
            cell_id: ALL_CELLS,
            command: CellCommand::Mode(CellMode::Event),
        }
        .to_bytes(),
    };
    // heard in time (the step ends as the packet is whole): bus 1 changes, bus 0 does not
    let mut cells = Cells::new(&spec).unwrap();
    let before: Vec<_> = (0..2).map(|p| cells.transitions(p).to_vec()).collect();
    let whole = skinbox_cosim::run::TICK_ZERO_CYCLE + 20 * MS + 200 * 125 / 4;
    assert_eq!(cells.receive(&[event_mode], whole).unwrap(), vec![1]);
    assert_eq!(cells.transitions(0), &before[0][..]);
    assert_ne!(cells.transitions(1), &before[1][..]);
    // heard 10 ms late: bus 1's cells would have changed packets already on the pin
    let mut cells = Cells::new(&spec).unwrap();
    let late = whole + 10 * MS;
    assert!(matches!(
        cells.receive(&[event_mode], late),
        Err(CosimError::ClosedLoop(_))
    ));
}
