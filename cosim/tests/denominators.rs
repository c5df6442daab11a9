//! The report's denominators: the sample rate (given, or learned from the stamps) and the
//! cell count (the skin's, or the cells seen), checked on synthetic captures whose truth
//! is known.

use skinbox_cosim::synthetic::{self, SynthCapture, SyntheticConfig};
use skinbox_host::rate::ASSUMED_SAMPLE_RATE_HZ;
use skinbox_host::report::{
    CELLS_GIVEN, CELLS_SEEN, SAMPLE_RATE_ASSUMED, SAMPLE_RATE_GIVEN, SAMPLE_RATE_LEARNED,
};
use skinbox_host::{Decoder, DecoderConfig, Report};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::TICKS_PER_SECOND;

fn decode(capture: &SynthCapture, config: DecoderConfig, skip_every: usize) -> Report {
    let mut d = Decoder::new(config);
    let mut records = 0;
    for (i, g) in capture.datagrams.iter().enumerate() {
        if skip_every > 0 && i % skip_every == 1 && matches!(g.body, DatagramBody::Records(_)) {
            continue;
        }
        d.push_datagram(&g.to_bytes(), &mut ());
        records += 1;
    }
    assert!(records > 0);
    d.report()
}

fn learned(config: DecoderConfig) -> DecoderConfig {
    DecoderConfig {
        sample_rate_hz: None,
        ..config
    }
}

#[test]
fn the_sample_rate_is_learned_in_data_and_event_mode_and_with_gaps() {
    for rate in [62.5, 125.0, 250.0, 500.0, 1000.0] {
        for event_every in [0, 1, 2] {
            for skip_every in [0, 3] {
                let capture = synthetic::generate(&SyntheticConfig {
                    cells: 32,
                    ports: 8,
                    sample_rate_hz: rate,
                    samples_per_cell: 60,
                    event_every,
                    seed: rate as u64 + u64::from(event_every),
                    ..SyntheticConfig::default()
                })
                .unwrap();
                let r = decode(&capture, learned(DecoderConfig::default()), skip_every);
                let what = format!("{rate} Hz, event_every {event_every}, skip {skip_every}");
                assert_eq!(
                    r.sample_rate_hz, rate,
                    "{what}: {:?}",
                    r.sample_rate_learned
                );
                assert_eq!(r.sample_rate_source, SAMPLE_RATE_LEARNED, "{what}");
                let e = r.sample_rate_learned.unwrap();
                assert_eq!(e.standard_hz, Some(rate), "{what}");
                // The synthetic cells sample exactly at multiples of whole ticks.
                let exact = TICKS_PER_SECOND as f64 / (TICKS_PER_SECOND as f64 / rate).floor();
                assert!(
                    (e.estimated_hz - exact).abs() < 1e-6 * rate,
                    "{what}: {e:?}"
                );
            }
        }
    }
}

#[test]
fn a_given_sample_rate_wins_and_the_stamps_are_still_shown() {
    let capture = synthetic::generate(&SyntheticConfig {
        sample_rate_hz: 250.0,
        ..SyntheticConfig::default()
    })
    .unwrap();
    // 125 Hz given for a 250 Hz capture: used as given, the stamps say 250.
    let r = decode(
        &capture,
        DecoderConfig {
            sample_rate_hz: Some(125.0),
            ..DecoderConfig::default()
        },
        0,
    );
    assert_eq!(r.sample_rate_hz, 125.0);
    assert_eq!(r.sample_rate_source, SAMPLE_RATE_GIVEN);
    assert_eq!(r.sample_rate_learned.unwrap().standard_hz, Some(250.0));
    assert!(r.summary().contains("125 Hz, given (stamps: 250.00 Hz"));
}

/// Nobody gave a rate: the default learns it from the stamps, and says it assumed one when
/// the stamps cannot tell.
#[test]
fn the_default_learns_the_rate_or_says_it_assumed_one() {
    assert_eq!(DecoderConfig::default().sample_rate_hz, None);
    let capture = synthetic::generate(&SyntheticConfig {
        sample_rate_hz: 250.0,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let r = decode(&capture, DecoderConfig::default(), 0);
    assert_eq!(r.sample_rate_hz, 250.0);
    assert_eq!(r.sample_rate_source, SAMPLE_RATE_LEARNED);

    // One packet per cell: no interval to learn from.
    let one = synthetic::generate(&SyntheticConfig {
        sample_rate_hz: 250.0,
        samples_per_cell: 1,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let r = decode(&one, DecoderConfig::default(), 0);
    assert!(r.records > 0);
    assert_eq!(r.sample_rate_hz, ASSUMED_SAMPLE_RATE_HZ);
    assert_eq!(r.sample_rate_source, SAMPLE_RATE_ASSUMED);
    assert_eq!(r.sample_rate_learned, None);
    assert!(r.summary().contains("125 Hz, assumed"), "{}", r.summary());
}

#[test]
fn per_cell_ratios_divide_by_the_skins_cells_when_given() {
    // 40 cells in data mode, but the skin has 50: 80 % of data mode.
    let samples = 30u32;
    let capture = synthetic::generate(&SyntheticConfig {
        cells: 40,
        sample_rate_hz: 125.0,
        samples_per_cell: samples,
        event_every: 0,
        ..SyntheticConfig::default()
    })
    .unwrap();
    let first = capture.truth.iter().map(|t| t.tick).min().unwrap();
    let last = capture.truth.iter().map(|t| t.tick).max().unwrap();
    let duration_s = (last - first) as f64 / TICKS_PER_SECOND as f64 + 1.0 / 125.0;
    let packets = f64::from(samples) * 40.0;
    assert_eq!(capture.cell_packets() as f64, packets);

    let given = decode(
        &capture,
        DecoderConfig {
            cells: Some(50),
            ..DecoderConfig::default()
        },
        0,
    );
    assert_eq!(given.cells_denominator.cells, 50);
    assert_eq!(given.cells_denominator.source, CELLS_GIVEN);
    assert_eq!(given.cells_active, 40);
    let want = 100.0 * packets / (125.0 * duration_s * 50.0);
    assert!((given.packet_rate_percent_of_data_mode - want).abs() < 1e-9);
    assert!((given.packets_per_cell_per_second - packets / 50.0 / duration_s).abs() < 1e-9);
    assert!(given.summary().contains("over 50 cells (given)"));

    let seen = decode(&capture, DecoderConfig::default(), 0);
    assert_eq!(seen.cells_denominator.cells, 40);
    assert_eq!(seen.cells_denominator.source, CELLS_SEEN);
    let want = 100.0 * packets / (125.0 * duration_s * 40.0);
    assert!((seen.packet_rate_percent_of_data_mode - want).abs() < 1e-9);
    assert!(seen.summary().contains("over 40 cells (cells seen)"));
}

/// The fired-together histogram, the channels' event ratios and the papers' packet-size
/// analysis, against the same figures computed here from the generator's packets.
#[test]
fn packet_size_analysis_matches_the_truth() {
    let rate = 250.0;
    let config = SyntheticConfig {
        cells: 48,
        ports: 6,
        sample_rate_hz: rate,
        samples_per_cell: 400,
        event_every: 1,
        seed: 7,
        walk_scale: 3,
        ..SyntheticConfig::default()
    };
    let capture = synthetic::generate(&config).unwrap();
    // Truth: group each cell's event packets into samples by mask bit 15.
    let mut open: std::collections::BTreeMap<u16, u32> = Default::default();
    let mut n = [0u64; 10];
    let mut channel_events = [0u64; 9];
    for t in &capture.truth {
        let p = &t.record.cell_packet;
        assert_eq!(p[0], 0xA2);
        let cell = u16::from_be_bytes([p[1], p[2]]);
        let mask = u16::from_be_bytes([p[3], p[4]]);
        for (i, e) in channel_events.iter_mut().enumerate() {
            *e += u64::from(mask >> i & 1);
        }
        let fired = (mask & 0x1FF).count_ones();
        if mask & 0x8000 != 0 {
            *open.get_mut(&cell).unwrap() += fired;
        } else if let Some(prev) = open.insert(cell, fired) {
            n[prev as usize] += 1;
        }
    }
    for fired in open.values() {
        n[*fired as usize] += 1;
    }
    assert!(
        n[7] + n[8] + n[9] > 0,
        "no split sample in the truth: {n:?}"
    );
    let first = capture.truth.iter().map(|t| t.tick).min().unwrap();
    let last = capture.truth.iter().map(|t| t.tick).max().unwrap();
    let duration_s = (last - first) as f64 / TICKS_PER_SECOND as f64 + 1.0 / rate;
    let samples = duration_s * rate * 48.0;

    let r = decode(
        &capture,
        DecoderConfig {
            cells: Some(48),
            sample_rate_hz: None,
            ..DecoderConfig::default()
        },
        0,
    );
    assert_eq!(r.fired_together_histogram, n[1..].to_vec());
    assert!((r.samples_of_the_cells - samples).abs() < 1e-6);
    assert_eq!(r.cells_active_ratio, 1.0);
    let names = [
        "accel_x",
        "accel_y",
        "accel_z",
        "force_1",
        "force_2",
        "force_3",
        "proximity",
        "temperature_1",
        "temperature_2",
    ];
    for (i, name) in names.iter().enumerate() {
        let got = r.channel_event_ratio[name];
        assert!(
            (got - channel_events[i] as f64 / samples).abs() < 1e-12,
            "{name}"
        );
    }
    let size = [7.0, 9.0, 10.0, 12.0, 14.0, 15.0, 17.0, 18.0, 20.0];
    let size_ts = [10.0, 12.0, 13.0, 15.0, 17.0, 18.0, 20.0, 21.0, 22.0];
    let mut best = (0, f64::INFINITY);
    let mut best_ts = (0, f64::INFINITY);
    for k in 1..=9usize {
        let packets: u64 = (1..=9usize).map(|i| n[i] * i.div_ceil(k) as u64).sum();
        let row = &r.packet_sizes.rows[k - 1];
        assert_eq!(row.k as usize, k);
        assert_eq!(row.packets, packets, "k = {k}");
        let want = packets as f64 / samples * size[k - 1] / 20.0;
        let want_ts = packets as f64 / samples * size_ts[k - 1] / 20.0;
        assert!((row.ratio - want).abs() < 1e-12, "k = {k}");
        assert!(
            (row.ratio_with_timestamp - want_ts).abs() < 1e-12,
            "k = {k}"
        );
        if want < best.1 {
            best = (k, want);
        }
        if want_ts < best_ts.1 {
            best_ts = (k, want_ts);
        }
    }
    let b = r.packet_sizes.best.unwrap();
    assert_eq!((b.k as usize, b.ratio), best);
    let b = r.packet_sizes.best_with_timestamp.unwrap();
    assert_eq!((b.k as usize, b.ratio), best_ts);
    // k = 6 is today's packet count: every event packet.
    assert_eq!(r.packet_sizes.rows[5].packets, capture.event_packets);
    let text = r.summary();
    assert!(text.contains(&format!(
        "channels fired in one sample (1..9): {:?}",
        &n[1..]
    )));
    assert!(
        text.contains(&format!("best k = {} at {:.4}", best.0, best.1)),
        "{text}"
    );
}
