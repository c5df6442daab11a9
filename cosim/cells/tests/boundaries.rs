//! The failure boundaries of the cell-side methods, each asserted on both sides (the
//! `skinbox report` study C4 charts where they lie):
//! - a bus carries every packet up to its UART's 20,000 packets/s and drops the excess above;
//! - send-on-delta saves packets at the calibrated sensor noise and turns into an event
//!   storm above data mode when the noise grows a few times;
//! - a host that loses events holds wrong values until a channel fires again: without a
//!   refresh the reconstruction error leaves the papers' 0.5 % at about 1 % packet loss, and a
//!   full refresh every second keeps it inside at ten times that loss.

use skinbox_cells::bus::{BITS_PER_PACKET, UART_BAUD};
use skinbox_cells::{scenes_dir, GenerateOptions, Mode, Scene, SceneStats};
use skinbox_protocol::Channel;

fn load(name: &str) -> Scene {
    Scene::load(&scenes_dir().join(format!("{name}.toml"))).unwrap_or_else(|e| panic!("{e}"))
}

/// Mean RMS reconstruction error of the eight channels that carry a signal (the second
/// temperature sensor reads 0), % of full range.
fn mean_error_pct(stats: &SceneStats) -> f64 {
    Channel::ALL[..8]
        .iter()
        .map(|&c| stats.rms_error_pct(c))
        .sum::<f64>()
        / 8.0
}

/// One bus of `cells` cells in data mode at 250 Hz, on an exact UART clock, for 2 s.
fn bus_of(cells: usize) -> (u64, u64) {
    let mut scene = load("idle");
    let s = &mut scene.config.scene;
    s.cells = cells;
    s.buses = 1;
    s.mode = Mode::Data;
    s.sample_rate_hz = 250.0;
    s.duration_s = 2.0;
    s.warmup_s = 0.5;
    scene.config.bus.uart_error_ppm = 0.0;
    scene.config.bus.max_cells = cells;
    scene.check().unwrap();
    let g = scene.generate(&GenerateOptions::default());
    (g.buses[0].stats.offered, g.buses[0].stats.dropped)
}

#[test]
fn a_bus_drops_nothing_up_to_its_uart_rate_and_the_excess_above_it() {
    // Independent of the bus model: a 4 Mbit/s 8N1 line carries 4e6 / 200 = 20,000
    // packets/s, 80 cells at 250 Hz.
    let capacity_per_s = (UART_BAUD / BITS_PER_PACKET) as f64;
    assert_eq!(capacity_per_s, 20_000.0);
    for cells in [66, 72, 79] {
        let (offered, dropped) = bus_of(cells);
        assert!(offered > 0);
        assert_eq!(dropped, 0, "{cells} cells: {offered} offered");
    }
    for cells in [82, 90, 120] {
        let (offered, dropped) = bus_of(cells);
        let expected = 1.0 - capacity_per_s / (cells as f64 * 250.0);
        let loss = dropped as f64 / offered as f64;
        // The FIFO (32 packets) and the 2 s run blur the closed form by well under a point.
        assert!(
            (loss - expected).abs() < 0.01,
            "{cells} cells: loss {loss:.4}, closed form {expected:.4}"
        );
    }
}

/// Packets of the idle scene (40 cells, 3 s) in % of data mode at `factor` times its noise.
fn idle_packet_rate_pct(factor: f64) -> f64 {
    let mut scene = load("idle");
    scene.config.scene.cells = 40;
    scene.config.scene.buses = 1;
    scene.config.scene.duration_s = 3.0;
    scene.config.noise = scene.config.noise.scaled(factor);
    scene.check().unwrap();
    scene
        .generate(&GenerateOptions {
            keep_packets: false,
            ..Default::default()
        })
        .stats
        .packet_rate_pct()
}

#[test]
fn send_on_delta_saves_packets_at_the_calibrated_noise_and_storms_above_data_mode_at_six_times_it()
{
    let calibrated = idle_packet_rate_pct(1.0);
    assert!((3.0..7.0).contains(&calibrated), "{calibrated} %");
    assert!(idle_packet_rate_pct(2.0) < 100.0);
    for factor in [6.0, 16.0] {
        let storm = idle_packet_rate_pct(factor);
        // Above data mode, and never above two packets per sample (Algorithm 1 splits seven
        // to nine events into two packets, at most).
        assert!(
            (100.0..=200.0).contains(&storm),
            "noise x{factor}: {storm} %"
        );
    }
}

/// Mean reconstruction error of the idle scene (260 cells, 6 s) at a packet loss, with a full
/// refresh every `refresh_s` (0: none).
fn idle_error_pct(loss: f64, refresh_s: f64) -> f64 {
    let mut scene = load("idle");
    scene.config.scene.duration_s = 6.0;
    scene.config.thresholds.refresh_s = refresh_s;
    scene.check().unwrap();
    let g = scene.generate(&GenerateOptions {
        keep_packets: false,
        packet_loss: loss,
        ..Default::default()
    });
    if loss == 0.0 {
        assert_eq!(g.stats.packets_lost, 0);
    } else {
        // The losses drawn match the rate asked for.
        let drawn = g.stats.packets_lost as f64 / g.stats.packets as f64;
        assert!((drawn / loss - 1.0).abs() < 0.2, "{drawn} for {loss}");
    }
    mean_error_pct(&g.stats)
}

#[test]
fn without_refresh_event_loss_breaks_reconstruction_and_a_one_second_refresh_holds_it() {
    const BOUND_PCT: f64 = 0.5; // the papers' reconstruction error
    let lossless = idle_error_pct(0.0, 0.0);
    assert!(lossless < 0.2, "{lossless}");
    assert!(idle_error_pct(0.001, 0.0) < BOUND_PCT);
    let broken = idle_error_pct(0.05, 0.0);
    assert!(broken > BOUND_PCT, "5 % loss without refresh: {broken}");
    // With the refresh, the same losses stay inside the bound, and it costs no accuracy
    // without loss.
    let refreshed = idle_error_pct(0.05, 1.0);
    assert!(refreshed < BOUND_PCT, "5 % loss, 1 s refresh: {refreshed}");
    assert!(idle_error_pct(0.0, 1.0) <= lossless + 1e-9);
}
