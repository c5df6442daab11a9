//! Seeded test traffic shared by the tests, benchmarks and studies.

use skinbox_cells::rng::Rng;
use skinbox_protocol::cell::PACKET_LEN;
use skinbox_protocol::{Channel, DataRepr};

/// `n` data packets (cell ids 1..=n) with every channel drawn over its full range, always
/// the same for the same `n`.
pub fn random_data_packets(n: usize) -> Vec<[u8; PACKET_LEN]> {
    let mut random = Rng::new(0x2545_F491_4F6C_DD1D);
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
