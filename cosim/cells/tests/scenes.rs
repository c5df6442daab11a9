//! Scenes end to end: files, errors, calibration, reconstruction, buses, determinism.

use skinbox_cells::bus::{BITS_PER_PACKET, MAX_CELLS_PER_BUS};
use skinbox_cells::calibration::{calibrate, Figure, FACTOR, SEED_TABLE};
use skinbox_cells::{scenes_dir, GenerateOptions, Mode, Scene};
use skinbox_protocol::{CellRepr, Channel, Modality};
use std::sync::OnceLock;

const SCENES: [&str; 8] = [
    "idle",
    "stroking_upper_arm",
    "stroking_arm",
    "hammering_end_effector",
    "moving_arm",
    "reactive_control",
    "force_test_stand",
    "feather_teasing",
];

fn load(name: &str) -> Scene {
    Scene::load(&scenes_dir().join(format!("{name}.toml"))).unwrap_or_else(|e| panic!("{e}"))
}

/// A shortened copy of a scene.
fn short(name: &str, duration_s: f64) -> Scene {
    let mut scene = load(name);
    scene.config.scene.duration_s = duration_s;
    scene.config.scene.warmup_s = 0.5;
    scene.check().unwrap();
    scene
}

/// The calibration run, shared by the tests that read it.
fn figures() -> &'static [Figure] {
    static FIGURES: OnceLock<Vec<Figure>> = OnceLock::new();
    FIGURES.get_or_init(|| calibrate(&scenes_dir()).unwrap_or_else(|e| panic!("{e}")))
}

#[test]
fn every_scene_file_parses_and_makes_packets() {
    for name in SCENES {
        let scene = short(name, 1.5);
        assert_eq!(scene.name(), name);
        let g = scene.generate(&GenerateOptions::default());
        let sent: usize = g.buses.iter().map(|b| b.packets.len()).sum();
        assert!(sent > 0, "{name} sent nothing");
        assert_eq!(g.buses.len(), scene.config.scene.buses, "{name}");
        for bus in &g.buses {
            for p in &bus.packets {
                CellRepr::parse(&p.bytes, &Default::default())
                    .unwrap_or_else(|e| panic!("{name}: {e}"));
            }
        }
    }
}

#[test]
fn all_30_figures_land_within_the_factor_of_the_seed_table() {
    let rated: Vec<_> = figures().iter().filter(|f| f.seed.is_some()).collect();
    assert_eq!(rated.len(), 30);
    assert_eq!(rated.len(), SEED_TABLE.len() * 5);
    for f in rated {
        let ratio = f.ratio().unwrap();
        assert!(
            (1.0 / FACTOR..=FACTOR).contains(&ratio),
            "{} {}: model {:.3}, seed {:.3}, ratio {ratio:.3}",
            f.scene,
            f.quantity,
            f.model,
            f.seed.unwrap()
        );
    }
}

#[test]
fn reconstruction_error_stays_below_half_a_percent_of_full_range() {
    let rms: Vec<_> = figures()
        .iter()
        .filter(|f| f.quantity.starts_with("rms_error_pct_"))
        .collect();
    assert_eq!(rms.len(), SEED_TABLE.len() * Channel::COUNT);
    for f in rms {
        assert!(
            f.model < 0.5,
            "{} {}: {:.3} %",
            f.scene,
            f.quantity,
            f.model
        );
    }
    // Acceleration is the channel that moves most: its error is not trivially zero.
    let accel = figures()
        .iter()
        .find(|f| f.scene == "moving_arm" && f.quantity == "rms_error_pct_accel_x")
        .unwrap();
    assert!(accel.model > 0.05, "{accel:?}");
}

#[test]
fn a_fixed_seed_gives_the_same_packets_and_another_seed_does_not() {
    let a = short("moving_arm", 1.2).generate(&GenerateOptions::default());
    let b = short("moving_arm", 1.2).generate(&GenerateOptions::default());
    let packets = |g: &skinbox_cells::Generated| {
        g.buses
            .iter()
            .flat_map(|b| b.packets.iter().copied())
            .collect::<Vec<_>>()
    };
    assert!(!packets(&a).is_empty());
    assert_eq!(packets(&a), packets(&b));
    let mut other = short("moving_arm", 1.2);
    other.config.scene.seed += 1;
    assert_ne!(
        packets(&a),
        packets(&other.generate(&GenerateOptions::default()))
    );
}

/// One bus of 66 cells in data mode at `rate_hz`.
fn full_bus(rate_hz: f64) -> Scene {
    let mut scene = short("idle", 1.0);
    let s = &mut scene.config.scene;
    s.cells = MAX_CELLS_PER_BUS;
    s.buses = 1;
    s.mode = Mode::Data;
    s.sample_rate_hz = rate_hz;
    scene.config.bus.uart_error_ppm = 0.0;
    scene.check().unwrap();
    scene
}

#[test]
fn a_bus_below_20000_packets_per_second_delivers_every_sample_in_time() {
    // 66 cells at 250 Hz: 16,500 packets/s.
    let scene = full_bus(250.0);
    let g = scene.generate(&GenerateOptions::default());
    let bus = &g.buses[0];
    assert_eq!(bus.stats.dropped, 0);
    assert_eq!(bus.stats.sent, bus.stats.offered);
    // 250 samples per cell in 1 s, give or take one for the phase and drift.
    let n = bus.packets.len() as u64;
    assert!((66 * 249..=66 * 251).contains(&n), "{n}");
    let b = &scene.config.bus;
    let mut previous_end_ps = 0;
    for p in &bus.packets {
        let position = bus.cell_ids.iter().position(|&id| id == p.cell_id).unwrap() as u64;
        let ready_ps = (p.sample_time_ns + b.processing_ns + position * b.hop_latency_ns) * 1000;
        assert!(p.pin_edge_ps >= ready_ps);
        assert!(
            p.pin_edge_ps >= previous_end_ps,
            "packets overlap on the pin"
        );
        assert_eq!(p.pin_end_ps() - p.pin_edge_ps, BITS_PER_PACKET * 250_000);
        previous_end_ps = p.pin_end_ps();
    }
}

#[test]
fn a_bus_above_20000_packets_per_second_drops_and_counts_every_drop() {
    // 66 cells at 400 Hz: 26,400 packets/s offered, 20,000 fit.
    let scene = full_bus(400.0);
    let g = scene.generate(&GenerateOptions::default());
    let bus = &g.buses[0];
    let s = &bus.stats;
    assert_eq!(s.offered, 66 * 400);
    assert_eq!(s.sent + s.dropped, s.offered);
    assert_eq!(s.sent, bus.packets.len() as u64);
    assert_eq!(bus.dropped_per_cell.iter().sum::<u64>(), s.dropped);
    assert_eq!(s.max_queue_packets, scene.config.bus.fifo_packets);
    // Once the FIFO has filled, the line runs back to back at 50 us per packet.
    let back_to_back = bus
        .packets
        .windows(2)
        .filter(|w| w[1].pin_edge_ps == w[0].pin_end_ps())
        .count();
    assert!(bus
        .packets
        .windows(2)
        .all(|w| w[1].pin_edge_ps >= w[0].pin_end_ps()));
    assert!(
        back_to_back as u64 >= s.sent - 100,
        "{back_to_back} of {}",
        s.sent
    );
    let span_ps = bus.packets.last().unwrap().pin_end_ps() - bus.packets[0].pin_edge_ps;
    assert!(span_ps / 50_000_000 >= s.sent - 100);
    // 26,400 offered, about 20,000 carried in the second plus what the FIFO held.
    assert!((6_000..=6_500).contains(&s.dropped), "{s:?}");
}

#[test]
fn cells_keep_their_own_clocks() {
    let scene = short("idle", 2.0);
    let g = scene.generate(&GenerateOptions {
        keep_packets: false,
        truth_cells: vec![1, 2, 260],
        ..Default::default()
    });
    assert_eq!(g.truth.len(), 3);
    let mut phases = Vec::new();
    for t in &g.truth {
        let times = &t.sample_time_ns;
        assert!(times.len() >= 249 && times.len() <= 251, "{}", times.len());
        let period_ns = (times[times.len() - 1] - times[0]) as f64 / (times.len() - 1) as f64;
        // 8 ms +- 100 ppm (0.8 us), +- 1 ns of rounding.
        assert!(
            (period_ns - 8e6).abs() <= 801.0,
            "cell {}: {period_ns}",
            t.cell_id
        );
        assert!(times[0] < 8_000_000);
        phases.push(times[0]);
        // Temperature 2 reads 0, as on the real cells.
        assert!(t.truth.iter().all(|v| v[8] == 0.0));
    }
    phases.dedup();
    assert_eq!(phases.len(), 3, "cells share a phase: {phases:?}");
}

#[test]
fn events_rebuild_the_true_signal() {
    // A host holding the last value of each channel, fed with one cell's packets, stays
    // within a threshold (plus noise) of the truth the model kept.
    let scene = short("stroking_upper_arm", 4.0);
    let id = 5;
    let g = scene.generate(&GenerateOptions {
        keep_packets: true,
        truth_cells: vec![id],
        ..Default::default()
    });
    let truth = &g.truth[0];
    let mut packets: Vec<_> = g
        .buses
        .iter()
        .flat_map(|b| b.packets.iter())
        .filter(|p| p.cell_id == id)
        .collect();
    packets.sort_by_key(|p| p.sample_time_ns);
    let mut held = [0i32; Channel::COUNT];
    let mut next = 0;
    let mut worst = [0.0f64; Channel::COUNT];
    for (time_ns, value) in truth.sample_time_ns.iter().zip(&truth.truth) {
        while next < packets.len() && packets[next].sample_time_ns <= *time_ns {
            match CellRepr::parse(&packets[next].bytes, &Default::default()).unwrap() {
                CellRepr::Event(e) => {
                    for (c, raw) in e.events() {
                        held[c.index()] = raw;
                    }
                }
                CellRepr::Data(_) => panic!("event scene sent a data packet"),
            }
            next += 1;
        }
        for c in Channel::ALL {
            let err = (c.to_units(held[c.index()]) - value[c.index()]).abs();
            worst[c.index()] = worst[c.index()].max(err / c.units_per_lsb());
        }
    }
    assert_eq!(next, packets.len());
    // Threshold, half a step of rounding and five sigma of sensor noise, in steps.
    let n = &scene.config.noise;
    for c in Channel::ALL {
        let sigma_units = match c.modality() {
            Modality::Acceleration => n.accel_g,
            Modality::Force => n.force,
            Modality::Proximity => n.proximity,
            Modality::Temperature if c == Channel::Temperature1 => n.temperature_c,
            Modality::Temperature => 0.0,
        };
        let bound =
            f64::from(c.table_i_threshold_raw()) + 0.5 + 5.0 * sigma_units / c.units_per_lsb();
        assert!(
            worst[c.index()] <= bound,
            "{c}: {} steps off, bound {bound}",
            worst[c.index()]
        );
    }
}

fn error_of(text: &str) -> skinbox_cells::SceneError {
    Scene::parse(text, "bad.toml").expect_err("the scene must be rejected")
}

const GOOD: &str = "\
[scene]
duration_s = 2.0
seed = 1
cells = 10
buses = 1
mode = \"event\"
sample_rate_hz = 125.0

[noise]
accel_g = 0.005
force = 0.0003
proximity = 0.00003
temperature_c = 0.1
";

#[test]
fn a_good_scene_parses() {
    let scene = Scene::parse(GOOD, "dir/good.toml").unwrap();
    assert_eq!(scene.name(), "good");
    assert_eq!(scene.config.scene.cells, 10);
}

#[test]
fn scene_errors_name_file_line_and_problem() {
    let cases: [(String, usize, &str); 7] = [
        (
            GOOD.replace("seed = 1", "seed = 1\nspeed = 3"),
            4,
            "unknown field `speed`",
        ),
        (
            GOOD.replace("cells = 10", "cells = \"many\""),
            4,
            "invalid type",
        ),
        (
            GOOD.replace("duration_s = 2.0", "duration_s = -2.0"),
            2,
            "`duration_s` must be",
        ),
        (
            GOOD.replace("cells = 10", "cells = 200"),
            5,
            "200 cells on 1 buses put 200 cells on a bus; at most 66",
        ),
        (
            GOOD.replace("mode = \"event\"", "mode = \"events\""),
            6,
            "unknown variant `events`",
        ),
        (
            format!("{GOOD}\n[thresholds]\nenabled = [\"accel_x\", \"pressure\"]\n"),
            16,
            "unknown channel `pressure`",
        ),
        (
            format!("{GOOD}\n[stroke]\nregion = [0.5, 0.2]\n"),
            15,
            "missing field `hands`",
        ),
    ];
    for (text, line, what) in cases {
        let e = error_of(&text);
        assert_eq!(e.file, "bad.toml");
        assert_eq!(e.line, Some(line), "{e}");
        assert!(e.message.contains(what), "{e}");
        assert!(
            e.to_string().starts_with(&format!("bad.toml:{line}: ")),
            "{e}"
        );
    }
}

#[test]
fn a_bad_region_and_a_missing_file_are_reported() {
    let text = format!(
        "{GOOD}\n[motion]\nregion = [0.5, 0.2]\naccel_g = 0.1\nmove_s = 1.0\nrest_s = 1.0\n\
         vibration_g = 0.0\n"
    );
    let e = error_of(&text);
    assert_eq!(e.line, Some(16), "{e}");
    assert!(e.message.contains("[motion] `region` must be"), "{e}");
    let e = Scene::load(std::path::Path::new("no/such/scene.toml")).unwrap_err();
    assert_eq!((e.file.as_str(), e.line), ("no/such/scene.toml", None));
    assert!(e.message.contains("cannot read"), "{e}");
    let e = error_of("[scene\nduration_s = 1.0\n");
    assert_eq!(e.line, Some(1), "{e}");
}

#[test]
fn the_pin_runs_on_the_root_cells_uart_clock() {
    let scene = short("moving_arm", 1.0);
    let g = scene.generate(&GenerateOptions::default());
    let mut roots = Vec::new();
    for bus in &g.buses {
        assert_eq!(bus.cell_uart_error_ppm.len(), bus.cell_ids.len());
        assert!(bus
            .cell_uart_error_ppm
            .iter()
            .all(|e| e.abs() <= scene.config.bus.uart_error_ppm));
        assert_eq!(bus.root_uart_error_ppm, bus.cell_uart_error_ppm[0]);
        let root = skinbox_cells::bus::bit_period_ps(bus.root_uart_error_ppm);
        assert!(!bus.packets.is_empty());
        assert!(bus.packets.iter().all(|p| p.bit_period_ps == root));
        // +-1 % around 250 ns.
        assert!((247_524..=252_526).contains(&root), "{root}");
        roots.push(root);
        assert_eq!(
            scene
                .cell_clock(usize::from(bus.cell_ids[0]) - 1)
                .uart_error_ppm,
            bus.root_uart_error_ppm
        );
    }
    roots.dedup();
    assert_eq!(roots.len(), g.buses.len(), "buses share a clock: {roots:?}");
}

#[test]
fn mangled_scene_files_give_errors_not_panics() {
    // Every value of a good file replaced, one at a time, by something wrong.
    let wrong = [
        "-1",
        "0",
        "nan",
        "inf",
        "-inf",
        "1e309",
        "\"x\"",
        "[",
        "[1.0]",
        "99999999999999999999",
        "true",
        "é",
    ];
    let good = format!(
        "{GOOD}\n[stroke]\nregion = [0.1, 0.2]\nhands = 1\nspeed_m_per_s = 0.05\n\
         return_speed_factor = 3.0\nlower_s = 0.3\nlift_height_m = 0.08\nhand_radius_m = 0.04\n\
         force = 0.1\nproximity = 0.5\nproximity_range_m = 0.015\nvibration_g = 0.0\n\
         \n[hammer]\nblows_per_s = 1.0\npeak_g = 0.1\nring_hz = [15.0, 45.0]\ndecay_s = 0.2\n\
         attenuation_per_m = 1.0\n"
    );
    Scene::parse(&good, "good.toml").unwrap();
    let lines: Vec<&str> = good.lines().collect();
    let mut rejected = 0;
    for (i, line) in lines.iter().enumerate() {
        let Some((key, _)) = line.split_once(" = ") else {
            continue;
        };
        for w in wrong {
            let mut mangled = lines.clone();
            let replaced = format!("{key} = {w}");
            mangled[i] = &replaced;
            match Scene::parse(&mangled.join("\n"), "m.toml") {
                Err(e) => {
                    rejected += 1;
                    assert!(e.line.is_some(), "{e}");
                    assert!(e.to_string().starts_with("m.toml:"), "{e}");
                }
                // Zero is legal for a seed, a noise level or a stimulus amplitude; nothing
                // else on this list is.
                Ok(_) => assert_eq!(w, "0", "{replaced} was accepted"),
            }
        }
    }
    assert_eq!(rejected, 300);
}

/// The papers' Fig. 11: each scene's packet rate follows its fit within a factor 1.2 from
/// 62.5 to 500 Hz (30 s windows here; docs/scenes.md gives the 60 s figures).
#[test]
fn packet_rates_follow_fig_11_across_sample_rates() {
    use skinbox_cells::calibration::{FIG11_FACTOR, FIG11_FITS, FIG11_RATES_HZ};
    let mut worst = (1.0f64, "", 0.0);
    for fit in FIG11_FITS {
        for rate in FIG11_RATES_HZ {
            let mut scene = load(fit.scene);
            scene.config.scene.sample_rate_hz = rate;
            scene.config.scene.duration_s = 31.0;
            scene.check().unwrap();
            let g = scene.generate(&GenerateOptions {
                keep_packets: false,
                ..Default::default()
            });
            let st = &g.stats;
            let model = st.packets_per_cell_s();
            let ratio = model / fit.packets_per_cell_s(rate);
            if (ratio.ln()).abs() > worst.0.ln().abs() {
                worst = (ratio, fit.scene, rate);
            }
            assert!(
                (1.0 / FIG11_FACTOR..=FIG11_FACTOR).contains(&ratio),
                "{} at {rate} Hz: {model:.2} packets per cell per second, {ratio:.3} of the fit",
                fit.scene
            );
        }
    }
    eprintln!("worst: {worst:?}");
}

#[test]
fn fig_11_fits_give_the_papers_numbers() {
    use skinbox_cells::calibration::FIG11_FITS;
    // the papers: idle's fit gives 6.76 packets per cell per second at 125 Hz
    let idle = FIG11_FITS.iter().find(|f| f.scene == "idle").unwrap();
    assert!((idle.packets_per_cell_s(125.0) - 6.76).abs() < 0.01);
    // the moving arm's fit is for all 260 cells: 392.2 per cell at 500 Hz, 49.2 at 62.5 Hz
    let arm = FIG11_FITS.iter().find(|f| f.scene == "moving_arm").unwrap();
    assert!((arm.packets_per_cell_s(500.0) - 392.2).abs() < 0.05);
    assert!((arm.packets_per_cell_s(62.5) - 49.21).abs() < 0.01);
    // hammering, per cell: 268.7 at 500 Hz
    let hammer = FIG11_FITS
        .iter()
        .find(|f| f.scene == "hammering_end_effector")
        .unwrap();
    assert!((hammer.packets_per_cell_s(500.0) - 268.70).abs() < 0.01);
}
