//! A small deterministic random number generator (xoshiro256++ seeded by SplitMix64).
//!
//! Our own, so that a scene's packets depend only on its seed, never on a dependency's
//! version. Every cell draws from its own stream ([`Rng::for_stream`]), so the packets of one
//! cell do not change when another cell is added or generated in another order.

/// xoshiro256++ (Blackman and Vigna).
#[derive(Debug, Clone)]
pub struct Rng {
    s: [u64; 4],
}

fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    /// A generator for `seed`.
    pub fn new(seed: u64) -> Rng {
        let mut sm = seed;
        let s = [
            splitmix64(&mut sm),
            splitmix64(&mut sm),
            splitmix64(&mut sm),
            splitmix64(&mut sm),
        ];
        Rng { s }
    }

    /// An independent stream `stream` of `seed` (e.g. one per cell).
    pub fn for_stream(seed: u64, stream: u64) -> Rng {
        let mut sm = seed ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03);
        Rng::new(splitmix64(&mut sm))
    }

    /// 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        let result = (self.s[0].wrapping_add(self.s[3]))
            .rotate_left(23)
            .wrapping_add(self.s[0]);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [low, high).
    pub fn range(&mut self, low: f64, high: f64) -> f64 {
        low + (high - low) * self.uniform()
    }

    /// An integer in `0..n` (`n` > 0; the modulo bias is below 2^-40 for `n` < 2^24).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next_u64() % n
    }

    /// Standard normal, by the ziggurat method (Marsaglia and Tsang, 2000): exact, tails
    /// included, which matters for rare noise events; about one table look-up per draw.
    #[inline]
    pub fn normal(&mut self) -> f64 {
        let zig = ziggurat();
        let bits = self.next_u64();
        let i = (bits & 0xff) as usize;
        let u = 2.0 * ((bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)) - 1.0;
        let x = u * zig.x[i];
        if x.abs() < zig.x[i + 1] {
            return x;
        }
        self.normal_slow(zig, i, u, x)
    }

    /// The rare draws (about 1 %) outside a layer's rectangle.
    #[cold]
    fn normal_slow(&mut self, zig: &Ziggurat, mut i: usize, mut u: f64, mut x: f64) -> f64 {
        loop {
            if i == 0 {
                // The tail beyond R (Marsaglia 1964).
                loop {
                    let tx = (1.0 - self.uniform()).ln() / ZIG_R;
                    let ty = (1.0 - self.uniform()).ln();
                    if -2.0 * ty >= tx * tx {
                        return if u < 0.0 { tx - ZIG_R } else { ZIG_R - tx };
                    }
                }
            }
            if zig.f[i + 1] + (zig.f[i] - zig.f[i + 1]) * self.uniform() < (-0.5 * x * x).exp() {
                return x;
            }
            let bits = self.next_u64();
            i = (bits & 0xff) as usize;
            u = 2.0 * ((bits >> 11) as f64 * (1.0 / (1u64 << 53) as f64)) - 1.0;
            x = u * zig.x[i];
            if x.abs() < zig.x[i + 1] {
                return x;
            }
        }
    }
}

/// Start of the tail and area of each of the 256 layers of the normal ziggurat.
const ZIG_R: f64 = 3.654_152_885_361_009;
const ZIG_V: f64 = 4.928_673_233_99e-3;

struct Ziggurat {
    x: [f64; 257],
    f: [f64; 257],
}

fn ziggurat() -> &'static Ziggurat {
    static TABLE: std::sync::OnceLock<Ziggurat> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let pdf = |x: f64| (-0.5 * x * x).exp();
        let mut x = [0.0; 257];
        x[0] = ZIG_V / pdf(ZIG_R);
        x[1] = ZIG_R;
        for i in 2..256 {
            x[i] = (-2.0 * (ZIG_V / x[i - 1] + pdf(x[i - 1])).ln()).sqrt();
        }
        x[256] = 0.0;
        let f = x.map(pdf);
        Ziggurat { x, f }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    use rand_xoshiro::rand_core::{RngCore, SeedableRng};
    use rand_xoshiro::{SplitMix64, Xoshiro256PlusPlus};

    /// Seeds across the range, including the all-zero and all-one words.
    const SEEDS: [u64; 5] = [0, 1, 7, 0x5EED_0000_1234_5678, u64::MAX];

    #[test]
    fn integer_stream_is_rand_xoshiro_xoshiro256plusplus() {
        // rand_xoshiro seeds its Xoshiro256PlusPlus from SplitMix64, as `Rng::new` does.
        for seed in SEEDS {
            let (mut ours, mut oracle) = (Rng::new(seed), Xoshiro256PlusPlus::seed_from_u64(seed));
            for n in 0..10_000 {
                assert_eq!(ours.next_u64(), oracle.next_u64(), "seed {seed}, draw {n}");
            }
        }
    }

    #[test]
    fn stream_seed_is_one_splitmix64_step_of_the_mixed_seed() {
        for (seed, stream) in SEEDS.iter().flat_map(|s| [(*s, 0u64), (*s, 1), (*s, 259)]) {
            let mixed = seed ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03);
            let start = SplitMix64::seed_from_u64(mixed).next_u64();
            let mut oracle = Xoshiro256PlusPlus::seed_from_u64(start);
            let mut ours = Rng::for_stream(seed, stream);
            for _ in 0..1000 {
                assert_eq!(
                    ours.next_u64(),
                    oracle.next_u64(),
                    "seed {seed}, stream {stream}"
                );
            }
        }
        assert_ne!(
            Rng::for_stream(7, 1).next_u64(),
            Rng::for_stream(7, 2).next_u64()
        );
    }

    // Known answers from a second implementation in Python (`cosim/cells/tests/
    // rng_reference.py`: xoshiro256++ and SplitMix64 from their authors' description, the
    // ziggurat from Marsaglia and Tsang's paper), so a change of the generator, the seeding
    // or the normal sampler shows even if the oracle crate changed as well.

    #[test]
    fn known_integers_and_uniforms() {
        let mut r = Rng::new(0);
        let want = [
            0x5317_5d61_490b_23df,
            0x61da_6f3d_c380_d507,
            0x5c0f_df91_ec9a_7bfc,
            0x02ee_bf8c_3bbe_5e1a,
        ];
        assert_eq!([0; 4].map(|_| r.next_u64()), want);
        let mut r = Rng::for_stream(7, 1);
        let want = [
            0x8e60_88b4_a236_0dbf,
            0xa86c_ae1e_0b40_a68b,
            0x6b9c_5c13_b577_a2ef,
            0x0c55_af50_d7ef_c349,
        ];
        assert_eq!([0; 4].map(|_| r.next_u64()), want);
        let mut r = Rng::new(5);
        let want = [0.29202287154046747, 0.6114394140810253, 0.09796325663560501];
        assert_eq!([0; 3].map(|_| r.uniform()), want);
    }

    #[test]
    fn known_normals_on_all_three_paths() {
        // Draws 0..8 take the rectangle (fast path), draw 264 a wedge, draw 1264 the tail.
        let mut r = Rng::new(3);
        let draws: Vec<f64> = (0..1265).map(|_| r.normal()).collect();
        let want = [
            (0, -2.0383025271143813),
            (1, 0.6916613067062005),
            (2, 0.9743258773657404),
            (3, 1.457693184877974),
            (4, 0.49990356977087963),
            (5, -1.3072254598915467),
            (6, -1.3389839934226815),
            (7, 0.343925304769259),
            (264, -0.12698252380193806),
            (1264, -3.903778740403747),
        ];
        for (n, value) in want {
            assert_eq!(draws[n], value, "draw {n}");
        }
    }

    #[test]
    fn normal_has_unit_variance() {
        let mut r = Rng::new(3);
        let n = 200_000;
        let (mut sum, mut sq) = (0.0, 0.0);
        for _ in 0..n {
            let z = r.normal();
            sum += z;
            sq += z * z;
        }
        let mean = sum / n as f64;
        let var = sq / n as f64 - mean * mean;
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.01, "variance {var}");
    }

    #[test]
    fn normal_tails_are_right() {
        // P(|z| > 2) = 0.0455, P(|z| > 3) = 0.0027, P(|z| > 4) = 6.3e-5.
        let mut r = Rng::new(11);
        let n = 2_000_000;
        let mut over = [0u32; 3];
        for _ in 0..n {
            let z = r.normal().abs();
            for (k, o) in over.iter_mut().enumerate() {
                if z > (k + 2) as f64 {
                    *o += 1;
                }
            }
        }
        let p = over.map(|o| f64::from(o) / n as f64);
        assert!((p[0] - 0.0455).abs() < 0.001, "{p:?}");
        assert!((p[1] - 0.0027).abs() < 0.0002, "{p:?}");
        assert!((p[2] - 6.3e-5).abs() < 2.5e-5, "{p:?}");
    }
}
