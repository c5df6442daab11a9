//! Garbage never panics the decoder: random bytes, and valid datagrams with random bytes
//! flipped, truncated or extended (the fuzz target's check, as a property test).

use proptest::prelude::*;
use skinbox_cosim::synthetic::{self, SyntheticConfig};
use skinbox_host::pcap::{decode_pcap_bytes, PcapOptions};
use skinbox_host::{DecodedRecord, Decoder, DecoderConfig, RecordSink, Sample};

struct Samples(u64);

impl RecordSink for Samples {
    fn record(&mut self, _record: &DecodedRecord) {
        self.0 += 1;
    }
    fn wants_samples(&self) -> bool {
        true
    }
    fn sample(&mut self, _sample: &Sample) {}
}

fn valid_payloads() -> Vec<Vec<u8>> {
    synthetic::generate(&SyntheticConfig {
        cells: 12,
        samples_per_cell: 12,
        status_period_ticks: 2_500_000,
        ..SyntheticConfig::default()
    })
    .unwrap()
    .payloads()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]

    #[test]
    fn random_bytes(datagrams in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..1500), 1..8)) {
        let mut d = Decoder::new(DecoderConfig::default());
        let mut sink = Samples(0);
        for p in &datagrams {
            d.push_datagram(p, &mut sink);
        }
        let r = d.report();
        prop_assert!(r.records <= sink.0);
    }

    #[test]
    fn mutated_datagrams(which in 0usize..1000, flips in proptest::collection::vec((0usize..1500, any::<u8>()), 1..6), cut in 0usize..1500) {
        let payloads = valid_payloads();
        let mut p = payloads[which % payloads.len()].clone();
        for (at, v) in flips {
            let n = p.len();
            p[at % n] = v;
        }
        p.truncate(cut.max(1));
        let mut d = Decoder::new(DecoderConfig::default());
        let mut sink = Samples(0);
        for q in payloads.iter().take(3) {
            d.push_datagram(q, &mut sink);
        }
        d.push_datagram(&p, &mut sink);
        let _ = d.report();
    }

    #[test]
    fn random_pcap_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..400)) {
        let mut file = vec![0xd4, 0xc3, 0xb2, 0xa1, 2, 0, 4, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff, 0, 0, 1, 0, 0, 0];
        file.extend_from_slice(&bytes);
        let _ = decode_pcap_bytes(&file, &PcapOptions::default());
        let _ = decode_pcap_bytes(&bytes, &PcapOptions::default());
    }
}
