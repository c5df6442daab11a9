//! Generation speed: the packet streams of a 5,742-cell scene (the original box's limit,
//! docs/design.md section 2) for 1 simulated second at 250 Hz, on one core.
//!
//! `cargo bench -p skinbox-cells --bench generate` prints one JSON object per run; the goal
//! is at most 1 s of wall time per simulated second.

use skinbox_cells::{scenes_dir, GenerateOptions, Mode, Scene};
use std::time::Instant;

/// CPU time this thread has run, s (Linux: /proc/thread-self/schedstat), so a busy machine
/// shows as wall time above CPU time rather than as a slower model.
fn thread_cpu_s() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    let ns: f64 = text.split_whitespace().next()?.parse().ok()?;
    Some(ns * 1e-9)
}

fn main() {
    // `cargo bench` passes `--bench`; without it (`cargo test --all-targets`) this is a smoke
    // test on one bus. Any other argument picks scenes by name.
    let args: Vec<String> = std::env::args().skip(1).collect();
    let full = args.iter().any(|a| a == "--bench");
    let (cells, buses, runs) = if full { (5_742, 87, 3) } else { (66, 1, 1) };
    let filters: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    for (name, mode) in [
        ("moving_arm", Mode::Event),
        ("moving_arm", Mode::Data),
        ("stroking_arm", Mode::Event),
        ("hammering_end_effector", Mode::Event),
    ] {
        if !filters.is_empty() && !filters.iter().any(|f| name.contains(f.as_str())) {
            continue;
        }
        let mut scene = Scene::load(&scenes_dir().join(format!("{name}.toml")))
            .unwrap_or_else(|e| panic!("{e}"));
        let s = &mut scene.config.scene;
        s.cells = cells;
        s.buses = buses; // 66 cells each
        s.columns = 60;
        s.sample_rate_hz = 250.0;
        s.duration_s = 1.0;
        s.warmup_s = 0.0;
        s.mode = mode;
        scene.check().unwrap_or_else(|e| panic!("{e}"));
        let mut best_s = f64::INFINITY;
        let mut best_cpu_s = f64::INFINITY;
        let mut packets = 0;
        let mut dropped = 0;
        for _ in 0..runs {
            let start = Instant::now();
            let cpu_start = thread_cpu_s();
            let g = scene.generate(&GenerateOptions::default());
            best_s = best_s.min(start.elapsed().as_secs_f64());
            if let (Some(a), Some(b)) = (cpu_start, thread_cpu_s()) {
                best_cpu_s = best_cpu_s.min(b - a);
            }
            packets = g.buses.iter().map(|b| b.packets.len()).sum::<usize>();
            dropped = g.buses.iter().map(|b| b.stats.dropped).sum::<u64>();
        }
        println!(
            "{{\"scene\": \"{name}\", \"mode\": \"{mode:?}\", \"cells\": {cells}, \
             \"sample_rate_hz\": 250, \"simulated_s\": 1.0, \"wall_s\": {best_s:.3}, \
             \"cpu_s\": {best_cpu_s:.3}, \"packets\": {packets}, \"dropped\": {dropped}}}"
        );
    }
}
