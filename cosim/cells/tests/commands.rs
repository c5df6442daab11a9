//! Cell commands down the buses: arrival per hop, application at the sample boundary, mode
//! and rate switches seen in the packets, malformed packets counted, scene errors.
//!
//! The oracle is the downlink's arithmetic written out here from docs/wire-format.md and the
//! bus model (20 bytes at 4 Mbit/s: 50 us to the root, then 52 us per hop) and the packets'
//! own bytes, parsed by the protocol crate.

use skinbox_cells::{scenes_dir, GenerateOptions, Generated, Scene};
use skinbox_protocol::cell_command::{CellCommand, CellCommandRepr};
use skinbox_protocol::{CellRepr, Channel};

const PACKET_NS: u64 = 50_000;
const HOP_NS: u64 = 52_000;

fn load(name: &str) -> Scene {
    Scene::load(&scenes_dir().join(format!("{name}.toml"))).unwrap_or_else(|e| panic!("{e}"))
}

/// When a command that left the box at `leave_ns` is complete in the cell at `position`.
fn arrival_ns(leave_ns: u64, position: usize) -> u64 {
    leave_ns + PACKET_NS + position as u64 * HOP_NS
}

/// (sample time ns, header byte) of every packet of cell `id`, in sample order.
fn packets_of(g: &Generated, id: u16) -> Vec<(u64, u8)> {
    let mut p: Vec<_> = g
        .buses
        .iter()
        .flat_map(|b| b.packets.iter())
        .filter(|p| p.cell_id == id)
        .map(|p| (p.sample_time_ns, p.bytes[0]))
        .collect();
    p.sort();
    p
}

#[test]
fn mode_switch_turns_data_into_events_at_each_cells_next_sample_after_its_hop() {
    let scene = load("mode_switch");
    let g = scene.generate(&GenerateOptions::default());
    let mut before = 0;
    let mut after = 0;
    for bus in &g.buses {
        assert_eq!(bus.downlink.len(), 1);
        let (leave_ns, bytes) = bus.downlink[0];
        assert_eq!(leave_ns, 1_500_000_000);
        assert_eq!(bytes[..4], [0xA5, 0x3F, 0xFF, 0x01]);
        assert_eq!(bytes[4], 1);
        for (position, &id) in bus.cell_ids.iter().enumerate() {
            let arrival = arrival_ns(leave_ns, position);
            let p = packets_of(&g, id);
            let first_event = p.iter().position(|&(_, h)| h == 0xA2).unwrap();
            // Data packets up to the arrival, events from the first sample at or after it.
            assert!(p[..first_event]
                .iter()
                .all(|&(t, h)| h == 0xA1 && t < arrival));
            assert!(p[first_event..]
                .iter()
                .all(|&(t, h)| h == 0xA2 && t >= arrival));
            let last_data = p[first_event - 1].0;
            // The first event sample is the next sample boundary: one period (8 ms +- drift)
            // after the last data sample, and the switch resends all nine channels.
            let period = p[first_event].0 - last_data;
            assert!(
                (7_998_000..=8_002_000).contains(&period),
                "cell {id}: {period}"
            );
            let first: Vec<_> = p[first_event..]
                .iter()
                .take_while(|&&(t, _)| t == p[first_event].0)
                .collect();
            assert_eq!(first.len(), 2, "cell {id}: nine events in two packets");
            before += p[..first_event]
                .iter()
                .filter(|(t, _)| *t >= 500_000_000)
                .count();
            after += p.len() - first_event;
        }
        assert!(bus
            .cell_commands
            .iter()
            .all(|c| c.applied == 1 && c.malformed == 0));
    }
    assert_eq!(g.stats.commands.applied, 260);
    let data_rate = before as f64 / (260.0 * 1.0);
    let event_rate = after as f64 / (260.0 * 1.5);
    println!(
        "mode_switch: data mode {data_rate:.2} packets/cell/s, event mode {event_rate:.2} \
         packets/cell/s (including the switch's full resend)"
    );
    assert!((124.5..=125.5).contains(&data_rate), "{data_rate}");
    assert!(event_rate < 12.5, "{event_rate}");
}

#[test]
fn rate_sweep_changes_each_cells_period_at_its_sample_boundary() {
    let scene = load("rate_sweep");
    let g = scene.generate(&GenerateOptions::default());
    let steps = [
        (0u64, 62.5),
        (1_000_000_000, 125.0),
        (2_000_000_000, 250.0),
        (3_000_000_000, 500.0),
    ];
    let mut per_step = [0usize; 4];
    for bus in &g.buses {
        let leaves: Vec<u64> = bus.downlink.iter().map(|d| d.0).collect();
        assert_eq!(leaves, vec![1_000_000_000, 2_000_000_000, 3_000_000_000]);
        for (position, &id) in bus.cell_ids.iter().enumerate() {
            let p = packets_of(&g, id);
            assert!(p.iter().all(|&(_, h)| h == 0xA1));
            for pair in p.windows(2) {
                let (t0, t1) = (pair[0].0, pair[1].0);
                // The rate in force for the interval after t0: the last command whose
                // arrival at this cell is at or before t0.
                let step = steps
                    .iter()
                    .rposition(|&(leave, _)| leave == 0 || arrival_ns(leave, position) <= t0)
                    .unwrap();
                let period = 1e9 / steps[step].1;
                let ratio = (t1 - t0) as f64 / period;
                // Clock drift is at most 100 ppm; 1 ns rounding on the sample times.
                assert!(
                    (ratio - 1.0).abs() < 1.2e-4 + 2.0 / period,
                    "cell {id}: {t0} -> {t1}, step {step}, ratio {ratio}"
                );
            }
            for (t, _) in &p {
                let second = (*t / 1_000_000_000) as usize;
                if second < 4 {
                    per_step[second] += 1;
                }
            }
        }
    }
    let rates: Vec<f64> = per_step.iter().map(|n| *n as f64 / 40.0).collect();
    println!("rate_sweep: packets per cell in each second: {rates:?}");
    for (r, (_, hz)) in rates.iter().zip(steps) {
        // Each second holds its rate but for the few samples before the command's hops.
        assert!((r - hz).abs() <= 2.0, "{rates:?}");
    }
}

#[test]
fn a_cell_on_the_boxs_grid_takes_its_new_rate_at_its_sample_boundary_too() {
    // rate_sweep (62.5 -> 125 -> 250 -> 500 Hz at 1, 2 and 3 s) with a sync every 0.1 s and
    // the rate servo: every cell samples on the box's grid (box time is scene time here)
    let scene = load("rate_sweep");
    let sync = skinbox_cells::TimeSync {
        rate: true,
        ..skinbox_cells::TimeSync::every(0.1, &scene.config.bus)
    };
    let g = scene.generate(&GenerateOptions {
        time_sync: Some(sync),
        ..Default::default()
    });
    let steps = [
        (0u64, 62.5),
        (1_000_000_000, 125.0),
        (2_000_000_000, 250.0),
        (3_000_000_000, 500.0),
    ];
    // a sync sets the phase to about a microsecond once the rate is learnt; before that
    // the drift since the last sync, up to 10 us
    let tolerance_ns = 12_000.0;
    let mut checked = 0;
    for bus in &g.buses {
        for (position, &id) in bus.cell_ids.iter().enumerate() {
            let p = packets_of(&g, id);
            // from the second sync's arrival on (the first takes the cell onto the grid)
            let settled = arrival_ns(100_000_000, position);
            for pair in p.windows(2).filter(|w| w[0].0 >= settled) {
                let (t0, t1) = (pair[0].0, pair[1].0);
                let step = steps
                    .iter()
                    .rposition(|&(leave, _)| leave == 0 || arrival_ns(leave, position) <= t0)
                    .unwrap();
                let period = 1e9 / steps[step].1;
                assert!(
                    ((t1 - t0) as f64 - period).abs() < tolerance_ns,
                    "cell {id}: {t0} -> {t1}, {} Hz in force",
                    steps[step].1
                );
                // on the grid of the rate in force
                let off = (t1 as f64 / period).round() * period - t1 as f64;
                assert!(
                    off.abs() < tolerance_ns,
                    "cell {id}: {t1} is {off} ns off the grid"
                );
                checked += 1;
            }
        }
    }
    assert!(checked > 40 * 900, "{checked}");
}

fn base(commands: &str) -> String {
    format!(
        "[scene]\nduration_s = 1.0\nwarmup_s = 0.1\nseed = 3\ncells = 10\nbuses = 2\n\
         mode = \"data\"\nsample_rate_hz = 125.0\n\n[noise]\naccel_g = 0.005\nforce = 0.0002\n\
         proximity = 3e-5\ntemperature_c = 0.1\n{commands}"
    )
}

#[test]
fn malformed_and_unknown_packets_are_ignored_and_counted_by_every_cell_they_pass() {
    let text = base(
        "\n[[commands]]\ntime_s = 0.2\nport = 0\nraw = \"A13FFF0101000000000000000000000000000055\"\n\
         \n[[commands]]\ntime_s = 0.2\nport = 0\nraw = \"A53FFF0901000000000000000000000000000055\"\n\
         \n[[commands]]\ntime_s = 0.3\nport = 0\ncell = 3\nmode = \"event\"\n\
         \n[[commands]]\ntime_s = 0.4\ntime_sync = true\n",
    );
    let scene = Scene::parse(&text, "bad_commands.toml").unwrap_or_else(|e| panic!("{e}"));
    let g = scene.generate(&GenerateOptions::default());
    let bus0 = &g.buses[0];
    // Two packets at 0.2 s: the second leaves when the first has left the box's UART.
    let leaves: Vec<u64> = bus0.downlink.iter().map(|d| d.0).collect();
    assert_eq!(
        leaves,
        vec![200_000_000, 200_050_000, 300_000_000, 400_000_000]
    );
    // The time sync carries the box tick (8 ns) at which it leaves.
    match CellCommandRepr::parse(&bus0.downlink[3].1).unwrap().command {
        CellCommand::TimeSync { box_tick } => assert_eq!(box_tick, 400_000_000 / 8),
        other => panic!("{other:?}"),
    }
    for (position, c) in bus0.cell_commands.iter().enumerate() {
        let id = bus0.cell_ids[position];
        assert_eq!(c.received, 4, "cell {id}");
        assert_eq!(c.malformed, 2, "cell {id}");
        assert_eq!(c.applied, if id == 3 { 2 } else { 1 }, "cell {id}");
        let events = packets_of(&g, id).iter().filter(|p| p.1 == 0xA2).count();
        assert_eq!(events > 0, id == 3, "cell {id}");
    }
    for c in &g.buses[1].cell_commands {
        assert_eq!((c.received, c.applied, c.malformed), (1, 1, 0));
    }
    assert_eq!(g.stats.commands.malformed, 10);
    // Every packet the cells sent is still a valid data or event packet.
    for p in g.buses.iter().flat_map(|b| &b.packets) {
        CellRepr::parse(&p.bytes, &Default::default()).unwrap();
    }
}

#[test]
fn thresholds_and_enable_mask_reach_the_cells() {
    let text = base(
        "\n[[commands]]\ntime_s = 0.0\nmode = \"event\"\n\
         \n[[commands]]\ntime_s = 0.0\nenabled = [\"temperature_1\"]\n",
    );
    let g = Scene::parse(&text, "t.toml")
        .unwrap()
        .generate(&GenerateOptions::default());
    // After the switch only temperature 1 may fire.
    for p in g.buses.iter().flat_map(|b| &b.packets) {
        if let Ok(CellRepr::Event(e)) = CellRepr::parse(&p.bytes, &Default::default()) {
            if p.sample_time_ns > 20_000_000 {
                assert!(e.events().all(|(c, _)| c == Channel::Temperature1), "{e:?}");
            }
        }
    }
}

#[test]
fn command_errors_name_the_line_and_the_entry() {
    let cases = [
        ("\n[[commands]]\ntime_s = 0.5\nrate_hz = 100\n", 18, "62.5, 125, 250, 500 or 1000"),
        ("\n[[commands]]\ntime_s = 0.5\nmode = \"event\"\n\n[[commands]]\ntime_s = 0.6\nport = 2\nmode = \"data\"\n", 22, "`port` 2"),
        ("\n[[commands]]\ntime_s = 0.5\nport = 1\ncell = 2\nmode = \"data\"\n", 19, "not on bus 1"),
        ("\n[[commands]]\ntime_s = 0.5\nmode = \"data\"\nrate_hz = 250\n", 17, "exactly one of"),
        ("\n[[commands]]\ntime_s = 2.0\nmode = \"data\"\n", 17, "`time_s`"),
        ("\n[[commands]]\ntime_s = 0.5\nenabled = [\"accel_w\"]\n", 18, "unknown channel `accel_w`"),
        ("\n[[commands]]\ntime_s = 0.5\nraw = \"A5\"\n", 18, "40 hex digits"),
    ];
    for (commands, line, says) in cases {
        let e = Scene::parse(&base(commands), "c.toml").unwrap_err();
        assert_eq!(e.line, Some(line), "{e}");
        assert!(e.message.contains(says), "{e}");
        assert!(e.message.starts_with("[[commands]] #"), "{e}");
    }
    // An unknown key is refused by the schema, with its line.
    let e = Scene::parse(&base("\n[[commands]]\ntime_s = 0.5\nspeed = 3\n"), "c.toml").unwrap_err();
    assert_eq!(e.line, Some(18), "{e}");
}

#[test]
fn a_time_sync_table_puts_every_cell_on_the_box_grid() {
    // synced_bus: 66 cells, 250 Hz, a sync every 0.1 s; without a box, box time is scene
    // time and each sync carries the tick it leaves at
    let scene = load("synced_bus");
    let g = scene.generate(&GenerateOptions {
        truth_cells: vec![1, 33, 66],
        ..Default::default()
    });
    let bus = &g.buses[0];
    let syncs = bus
        .downlink
        .iter()
        .filter(|d| {
            matches!(
                CellCommandRepr::parse(&d.1).map(|r| r.command),
                Ok(CellCommand::TimeSync { .. })
            )
        })
        .count();
    assert_eq!(syncs, 20, "2 s at 0.1 s");
    // after the first sync has reached the chain's end, every sample of every cell is
    // within 20 us of a 4 ms grid point (half its round trip believed, 100 ppm drift over
    // at most 0.1 s)
    let period_ns = 4_000_000.0;
    let settled_ns = 20_000 + 66 * 52_000 + 4_000_000;
    let mut checked = 0;
    for t in &g.truth {
        for &ns in t.sample_time_ns.iter().filter(|&&ns| ns > settled_ns) {
            let off = (ns as f64 / period_ns - (ns as f64 / period_ns).round()).abs() * period_ns;
            assert!(
                off < 20_000.0,
                "cell {}: sample at {ns} ns, {off} ns off",
                t.cell_id
            );
            checked += 1;
        }
    }
    assert!(checked > 1000, "{checked}");
    // a free-running scene's samples are not on that grid
    let free = load("idle").generate(&GenerateOptions {
        truth_cells: vec![1],
        ..Default::default()
    });
    let off_grid = free.truth[0]
        .sample_time_ns
        .iter()
        .filter(|&&ns| {
            let p = 8_000_000.0;
            (ns as f64 / p - (ns as f64 / p).round()).abs() * p > 20_000.0
        })
        .count();
    assert!(off_grid > free.truth[0].sample_time_ns.len() / 2);
    // the table is checked
    let text = std::fs::read_to_string(scenes_dir().join("synced_bus.toml"))
        .unwrap()
        .replace("interval_s = 0.1", "interval_s = 0.0001");
    let err = Scene::parse(&text, "fast_sync.toml")
        .unwrap_err()
        .to_string();
    assert!(err.contains("interval_s") && err.contains("0.001"), "{err}");
}

/// A time sync acts no earlier than the packet is whole at the root and processed, as
/// every other command (what the closed loop's regeneration asserts): the idle scene's
/// stream with one sync down bus 0 equals the stream without it up to that point, for
/// syncs leaving 15 to 65 us before one of the root cell's samples (the sample falls while
/// the packet is on the wire, or just after).
#[test]
fn a_time_sync_changes_nothing_before_it_is_whole_at_the_root() {
    use skinbox_cells::bus::DOWNLINK_PACKET_NS;
    use skinbox_protocol::cell_command::ALL_CELLS;
    let scene = load("idle");
    let buses = scene.config.scene.buses;
    let before = scene.generate(&GenerateOptions {
        downlink: Some(vec![vec![]; buses]),
        ..Default::default()
    });
    let processing_ns = scene.config.bus.processing_ns;
    let root = before.buses[0].cell_ids[0];
    let root_samples: Vec<u64> = before.buses[0]
        .packets
        .iter()
        .filter(|p| p.cell_id == root && p.sample_time_ns > 300_000_000)
        .map(|p| p.sample_time_ns)
        .take(6)
        .collect();
    assert_eq!(root_samples.len(), 6);
    let mut changed = 0;
    for sample_ns in root_samples {
        for ahead_us in [15, 25, 35, 45, 55, 65] {
            let leave_ns = sample_ns - ahead_us * 1000;
            let sync = CellCommandRepr {
                cell_id: ALL_CELLS,
                command: CellCommand::TimeSync {
                    box_tick: leave_ns / skinbox_protocol::TICK_NS,
                },
            };
            let mut downlink = vec![vec![]; buses];
            downlink[0].push((leave_ns, sync.to_bytes()));
            let after = scene.generate(&GenerateOptions {
                downlink: Some(downlink),
                ..Default::default()
            });
            let (old, new) = (&before.buses[0].packets, &after.buses[0].packets);
            let Some(first) = (0..old.len().max(new.len())).find(|&i| old.get(i) != new.get(i))
            else {
                continue;
            };
            changed += 1;
            let at_ps = [old.get(first), new.get(first)]
                .into_iter()
                .flatten()
                .map(|p| p.pin_edge_ps)
                .min()
                .unwrap();
            let earliest_ps = (leave_ns + DOWNLINK_PACKET_NS + processing_ns) * 1000;
            assert!(
                at_ps >= earliest_ps,
                "sync leaving {ahead_us} us before a root sample: packet {first} changed at \
                 {at_ps} ps, before {earliest_ps} ps"
            );
        }
    }
    assert_eq!(changed, 36, "every sync changes the stream");
}
