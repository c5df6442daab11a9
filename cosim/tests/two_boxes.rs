//! Two boxes on one capture: interleaved datagrams whose sequence numbers overlap, wrap and
//! restart together at a simultaneous reset. Each box is followed on its own (box id and
//! source address), so each reports exactly its own losses and nothing of the other's.

use skinbox_cosim::synthetic::{self, SyntheticConfig};
use skinbox_host::{DecodedRecord, Decoder, DecoderConfig};
use skinbox_protocol::datagram::DatagramBody;
use skinbox_protocol::DatagramRepr;
use std::net::SocketAddr;

struct BoxRun {
    source: SocketAddr,
    box_id: u16,
    /// Payloads in sending order: the first boot, then the second.
    payloads: Vec<Vec<u8>>,
    /// Index of the second boot's first payload.
    reset_at: usize,
}

fn box_run(box_id: u16, source: &str, first_sequence: u32, seed: u64) -> BoxRun {
    let mut config = SyntheticConfig {
        cells: 24,
        samples_per_cell: 150,
        event_every: 2,
        status_period_ticks: 2_500_000,
        box_id,
        boot_id: 0x1000 + u32::from(box_id),
        first_sequence,
        seed,
        ..SyntheticConfig::default()
    };
    let mut payloads = synthetic::generate(&config).unwrap().payloads();
    let reset_at = payloads.len();
    // The reset: a new boot id, numbering and clock from zero.
    config.boot_id += 0x100;
    config.first_sequence = 0;
    config.start_tick = 1_000;
    config.seed += 100;
    payloads.extend(synthetic::generate(&config).unwrap().payloads());
    BoxRun {
        source: source.parse().unwrap(),
        box_id,
        payloads,
        reset_at,
    }
}

fn is_records(p: &[u8]) -> bool {
    matches!(
        DatagramRepr::parse(p).unwrap().body,
        DatagramBody::Records(_)
    )
}

fn records_in(p: &[u8]) -> u64 {
    match DatagramRepr::parse(p).unwrap().body {
        DatagramBody::Records(r) => r.len() as u64,
        DatagramBody::Status(_) => 0,
    }
}

#[test]
fn each_box_reports_exactly_its_own_losses() {
    // Both start near the top of the numbering, overlapping, and wrap before the reset.
    let a = box_run(1, "192.0.2.10:54091", u32::MAX - 20, 1);
    let b = box_run(2, "192.0.2.11:54091", u32::MAX - 12, 2);
    let half = |r: &BoxRun| r.reset_at;
    assert!(
        a.reset_at > 40 && b.reset_at > 40,
        "{} {}",
        a.reset_at,
        b.reset_at
    );

    // Datagrams lost on the way: the records datagrams of these ranks (counted among the
    // records datagrams only, from the start or from the reset) of each box's stream, on both
    // sides of the reset and across the wrap.
    let records_datagram = |r: &BoxRun, from: usize, rank: usize| -> usize {
        (from..r.payloads.len())
            .filter(|&i| is_records(&r.payloads[i]))
            .nth(rank)
            .expect("enough records datagrams")
    };
    let drops_a: Vec<usize> = [(0, 5), (0, 20), (0, 21), (0, 22), (half(&a), 6)]
        .map(|(from, rank)| records_datagram(&a, from, rank))
        .to_vec();
    let drops_b: Vec<usize> = [(0, 2), (0, 13), (half(&b), 2), (half(&b), 3), (half(&b), 8)]
        .map(|(from, rank)| records_datagram(&b, from, rank))
        .to_vec();

    // Interleave: before the reset, then after it (both boxes reset together), each phase
    // alternating between the boxes in an irregular pattern.
    let mut stream: Vec<(SocketAddr, &[u8])> = Vec::new();
    for phase in 0..2 {
        let range = |r: &BoxRun| {
            if phase == 0 {
                0..half(r)
            } else {
                half(r)..r.payloads.len()
            }
        };
        let (mut ia, mut ib) = (range(&a), range(&b));
        let mut k = 0u32;
        loop {
            let take_a = k % 3 != 1;
            k += 1;
            let next = if take_a {
                ia.next()
                    .map(|i| (&a, i, &drops_a))
                    .or_else(|| ib.next().map(|i| (&b, i, &drops_b)))
            } else {
                ib.next()
                    .map(|i| (&b, i, &drops_b))
                    .or_else(|| ia.next().map(|i| (&a, i, &drops_a)))
            };
            let Some((run, i, drops)) = next else { break };
            if !drops.contains(&i) {
                stream.push((run.source, &run.payloads[i]));
            }
        }
    }

    let mut decoder = Decoder::new(DecoderConfig::default());
    let mut records: Vec<DecodedRecord> = Vec::new();
    for (source, p) in &stream {
        decoder.push_datagram_from(Some(*source), p, &mut records);
    }
    let report = decoder.report();
    assert_eq!(report.boxes.len(), 2);
    assert_eq!(report.bad_input.total, 0, "{:?}", report.bad_input);
    for (run, drops) in [(&a, &drops_a), (&b, &drops_b)] {
        let r = report
            .boxes
            .iter()
            .find(|r| r.box_id == run.box_id)
            .unwrap();
        assert_eq!(r.source, Some(run.source));
        let l = &r.losses;
        assert_eq!(
            l.datagrams_missing,
            drops.len() as u64,
            "box {}: {l:?}",
            run.box_id
        );
        assert_eq!(l.datagrams_duplicate, 0, "box {}: {l:?}", run.box_id);
        assert_eq!(l.datagrams_reordered, 0, "box {}: {l:?}", run.box_id);
        assert_eq!(l.box_resets, 1, "box {}: {l:?}", run.box_id);
        // the box reports at reset: the new boot id arrives before the numbering restarts
        assert_eq!(l.sequence_restarts, 0, "box {}: {l:?}", run.box_id);
        assert_eq!(
            r.box_status.boot_ids,
            vec![
                0x1000 + u32::from(run.box_id),
                0x1100 + u32::from(run.box_id)
            ]
        );
        // Oracle: the records of the datagrams that were not dropped.
        let sent: u64 = run
            .payloads
            .iter()
            .enumerate()
            .filter(|(i, _)| !drops.contains(i))
            .map(|(_, p)| records_in(p))
            .sum();
        assert_eq!(r.records, sent, "box {}", run.box_id);
        let decoded = records.iter().filter(|x| x.box_id == run.box_id).count() as u64;
        assert_eq!(decoded, sent, "box {}", run.box_id);
    }
    let total = &report.losses;
    assert_eq!(
        total.datagrams_missing,
        (drops_a.len() + drops_b.len()) as u64
    );
    assert_eq!(total.box_resets, 2);
}

#[test]
fn same_box_id_from_two_addresses_is_two_boxes() {
    let a = box_run(7, "192.0.2.10:54091", 0, 3);
    let b = box_run(7, "192.0.2.11:54091", 0, 4);
    let mut decoder = Decoder::new(DecoderConfig::default());
    for (x, y) in a.payloads.iter().zip(&b.payloads) {
        decoder.push_datagram_from(Some(a.source), x, &mut ());
        decoder.push_datagram_from(Some(b.source), y, &mut ());
    }
    let report = decoder.report();
    assert_eq!(report.boxes.len(), 2);
    for r in &report.boxes {
        assert_eq!(
            (r.losses.datagrams_missing, r.losses.datagrams_duplicate),
            (0, 0),
            "{r:?}"
        );
    }
}
