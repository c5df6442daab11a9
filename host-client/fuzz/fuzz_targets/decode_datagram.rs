//! Fuzzes the datagram decoder: the input is a stream of datagrams, each preceded by a
//! one-byte length (0 = the rest), decoded into samples so the converter runs too.
#![no_main]

use libfuzzer_sys::fuzz_target;
use skinbox_host::{Decoder, DecoderConfig, DecodedRecord, RecordSink, Sample};

struct Samples(u64);

impl RecordSink for Samples {
    fn record(&mut self, _record: &DecodedRecord) {
        self.0 += 1;
    }
    fn wants_samples(&self) -> bool {
        true
    }
    fn sample(&mut self, sample: &Sample) {
        self.0 = self.0.wrapping_add(u64::from(sample.stale.bits()));
    }
}

fuzz_target!(|data: &[u8]| {
    let mut decoder = Decoder::new(DecoderConfig::default());
    let mut sink = Samples(0);
    let mut rest = data;
    while let Some((&len, tail)) = rest.split_first() {
        let n = if len == 0 { tail.len() } else { usize::from(len).min(tail.len()) };
        let (datagram, next) = tail.split_at(n);
        decoder.push_datagram(datagram, &mut sink);
        rest = next;
    }
    let report = decoder.report();
    assert!(report.records <= data.len() as u64 / 26);
});
