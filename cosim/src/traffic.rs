//! Seeded test traffic shared by the tests, benchmarks and studies.

use skinbox_protocol::{Channel, DataRepr};

/// splitmix64: a small seeded generator, the same sequence on every machine.
#[derive(Debug, Clone)]
pub struct SplitMix64(pub u64);

impl SplitMix64 {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `low..high`.
    pub fn uniform(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `0..n`.
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }
}

/// `n` data packets (cell ids 1..=n) with every channel drawn over its full range, always
/// the same for the same `n`.
pub fn random_data_packets(n: usize) -> Vec<[u8; 20]> {
    let mut random = SplitMix64(0x2545_F491_4F6C_DD1D);
    (0..n)
        .map(|i| {
            let mut raw = [0i32; 9];
            for (c, v) in raw.iter_mut().enumerate() {
                let range = Channel::ALL[c].data_range();
                let span = (range.end() - range.start() + 1) as u64;
                *v = range.start() + random.below(span) as i32;
            }
            DataRepr::from_raw(i as u16 + 1, raw)
                .expect("values inside the ranges")
                .to_bytes()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packets_are_valid_seeded_and_spread_over_the_ranges() {
        let a = random_data_packets(200);
        assert_eq!(a, random_data_packets(200));
        let decoded: Vec<DataRepr> = a.iter().map(|p| DataRepr::parse(p).unwrap()).collect();
        assert_eq!(decoded[0].cell_id, 1);
        // each channel takes many values
        for c in Channel::ALL {
            let values: std::collections::HashSet<i32> = decoded.iter().map(|d| d.raw(c)).collect();
            assert!(values.len() > 100, "{c:?}: {} values", values.len());
        }
    }
}
