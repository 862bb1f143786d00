//! The workspace's seeded random generators: SplitMix64 for everything, and the xorshift64
//! that the planner's synthetic scenes were made with ([`XorShift64`], for them alone).
//!
//! Everything random in handeye is reproducible from a seed: the simulator's block shades,
//! layouts and sensor noise, the synthetic images and noise of the tests, the planner's test
//! layouts. Nothing needs cryptographic quality, and a generator written out here (rather
//! than a crate's, whose stream may change between versions) keeps every seed's results
//! bit-identical across builds: the end-to-end runs and batches compare them.
//!
//! ```
//! use handeye_vision::rng::{mix64, SplitMix64};
//!
//! let mut a = SplitMix64::new(mix64(7));
//! let mut b = SplitMix64::new(mix64(7));
//! let x = a.range(-1.0, 1.0);
//! assert!((-1.0..1.0).contains(&x));
//! assert_eq!(x, b.range(-1.0, 1.0)); // same seed, same stream
//! assert!(a.below(6) < 6);
//! ```

/// SplitMix64 (Steele, Lea and Flood 2014): one 64-bit state advanced by a constant and
/// mixed on the way out; full period, statistics good enough for shades, layouts and noise.
#[derive(Debug, Clone)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// The generator whose first output is `mix64(seed + γ)`; any seed (zero too) is fine.
    pub const fn new(seed: u64) -> Self {
        Self { state: seed }
    }

    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.state)
    }

    /// Uniform in `[0, 1)`: the top 53 bits, so every value is a multiple of 2⁻⁵³.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `[lo, hi)`.
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// Uniform in `0..n` (the modulo's bias is below 2⁻⁶⁰ for the small `n` drawn here).
    ///
    /// # Panics
    /// When `n` is 0.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    /// Standard normal, by Box-Muller (two uniform draws per value).
    pub fn normal(&mut self) -> f64 {
        let u1 = self.next_f64().max(1e-300);
        let u2 = self.next_f64();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// Marsaglia's xorshift64 (shifts 13, 7, 17): kept only for the planner's synthetic scenes.
///
/// [`planner::synth`](crate::planner::synth) draws its box layouts and image noise from this
/// stream, and the planner's synthetic acceptance measures (`tests/planner_synthetic.rs`:
/// found rate over ten seeded layouts, the bootstrap's recovery) were set on it; on
/// SplitMix64's layouts they do not hold as they stand (86 % found, or a bootstrap that does
/// not re-match). Moving those scenes to SplitMix64 means re-baselining those tests, which is
/// a decision of its own. **New code should use [`SplitMix64`]**: this one has a weaker
/// output (no final mix) and a state of zero that never leaves zero.
#[derive(Debug, Clone)]
pub struct XorShift64 {
    state: u64,
}

impl XorShift64 {
    /// The generator with state `state`, which must not be zero (zero stays zero for ever;
    /// the synthetic scenes set the low bit).
    pub const fn new(state: u64) -> Self {
        Self { state }
    }

    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.state;
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        self.state = x;
        x
    }

    /// Uniform in [0, 1): the top 24 bits.
    pub fn uniform(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// Approximately standard normal (sum of four uniforms, rescaled).
    pub fn gauss(&mut self) -> f32 {
        let s: f32 = (0..4).map(|_| self.uniform()).sum();
        (s - 2.0) * (3.0f32).sqrt()
    }
}

/// The SplitMix64 finaliser: a bijective 64-bit mix, used to derive independent seeds from
/// one (per block, per frame, per purpose).
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_sequence_and_uniform_range() {
        let mut a = SplitMix64::new(42);
        let mut b = SplitMix64::new(42);
        let mut c = SplitMix64::new(43);
        let xs: Vec<u64> = (0..8).map(|_| a.next_u64()).collect();
        let ys: Vec<u64> = (0..8).map(|_| b.next_u64()).collect();
        let zs: Vec<u64> = (0..8).map(|_| c.next_u64()).collect();
        assert_eq!(xs, ys);
        assert_ne!(xs, zs);
        let mut r = SplitMix64::new(1);
        let mean = (0..10_000).map(|_| r.next_f64()).inspect(|x| assert!((0.0..1.0).contains(x))).sum::<f64>() / 10_000.0;
        assert!((mean - 0.5).abs() < 0.02, "mean {mean}");
    }

    #[test]
    fn the_stream_is_the_published_splitmix64() {
        // The reference outputs for seed 1234567 (Vigna's splitmix64.c): the simulator's
        // scenarios and every seeded test depend on exactly this stream.
        let mut r = SplitMix64::new(1_234_567);
        let first: Vec<u64> = (0..3).map(|_| r.next_u64()).collect();
        assert_eq!(first, [6_457_827_717_110_365_317, 3_203_168_211_198_807_973, 9_817_491_932_198_370_423]);
    }

    #[test]
    fn normal_draws_have_unit_spread() {
        let mut r = SplitMix64::new(5);
        let xs: Vec<f64> = (0..20_000).map(|_| r.normal()).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / xs.len() as f64;
        assert!(mean.abs() < 0.03 && (var - 1.0).abs() < 0.05, "mean {mean} var {var}");
    }

    #[test]
    fn the_xorshift_stream_is_the_synthetic_scenes_one() {
        // xorshift64 (13, 7, 17) from state 1234567: the planner's synthetic layouts and
        // noise, and the acceptance measures set on them, depend on exactly this stream.
        let mut r = XorShift64::new(1_234_567);
        let first: Vec<u64> = (0..3).map(|_| r.next_u64()).collect();
        assert_eq!(first, [1_333_627_000_697_578, 14_261_447_996_154_253_071, 3_585_844_736_910_023_377]);
        let mut r = XorShift64::new(1_234_567);
        assert_eq!(r.uniform(), (1_333_627_000_697_578u64 >> 40) as f32 / (1u64 << 24) as f32);
    }
}
