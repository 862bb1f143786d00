//! Sensor noise, added on the CPU to each view after it is read back.
//!
//! A per-pixel hash and Gaussian in a shader pass cost ~12 ms per stereo frame on lavapipe;
//! this costs a fraction of a millisecond: a table of Gaussian samples (already scaled by the
//! camera's sigma and rounded to grey levels) is built once, and each image row adds a window
//! of it starting at an offset drawn from the frame's seed. Deterministic for a seed; a
//! different seed gives different noise.

use handeye_vision::rng::{SplitMix64, mix64};

/// Table length: large against a row (640 px), so rows rarely share a window.
const TABLE_LEN: usize = 1 << 18;

/// Gaussian noise of one standard deviation, in grey levels, ready to add.
#[derive(Debug, Clone)]
pub struct NoiseTable {
    sigma: f64,
    values: Vec<i16>,
}

impl NoiseTable {
    /// Samples of N(0, sigma²), rounded to whole grey levels.
    pub fn new(sigma: f64) -> Self {
        let mut rng = SplitMix64::new(0x6E01_5E5E_ED00_0001);
        let mut values = Vec::with_capacity(TABLE_LEN);
        while values.len() < TABLE_LEN {
            // Box-Muller: two independent normals per pair of uniforms.
            let u1 = rng.next_f64().max(f64::MIN_POSITIVE);
            let u2 = rng.next_f64();
            let r = (-2.0 * u1.ln()).sqrt() * sigma;
            let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
            values.push((r * c).round().clamp(-255.0, 255.0) as i16);
            values.push((r * s).round().clamp(-255.0, 255.0) as i16);
        }
        Self { sigma, values }
    }

    pub fn sigma(&self) -> f64 {
        self.sigma
    }

    /// Adds noise to an image of `width`-byte rows; `seed` picks the rows' windows.
    pub fn apply(&self, pixels: &mut [u8], width: usize, seed: u64) {
        let span = (self.values.len() - width) as u64;
        for (row, line) in pixels.chunks_exact_mut(width).enumerate() {
            let start = (mix64(seed ^ (row as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)) % span) as usize;
            for (p, &n) in line.iter_mut().zip(&self.values[start..start + width]) {
                *p = (i16::from(*p) + n).clamp(0, 255) as u8;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_has_the_asked_sigma_and_zero_mean_and_depends_on_the_seed() {
        let t = NoiseTable::new(2.0);
        let mut img = vec![128u8; 640 * 480];
        t.apply(&mut img, 640, 7);
        let n = img.len() as f64;
        let mean = img.iter().map(|&p| f64::from(p) - 128.0).sum::<f64>() / n;
        let var = img.iter().map(|&p| (f64::from(p) - 128.0 - mean).powi(2)).sum::<f64>() / n;
        assert!(mean.abs() < 0.05, "mean {mean}");
        // Rounding adds 1/12 to the variance.
        assert!((var - (4.0 + 1.0 / 12.0)).abs() < 0.15, "variance {var}");
        let mut again = vec![128u8; 640 * 480];
        t.apply(&mut again, 640, 7);
        assert_eq!(img, again);
        let mut other = vec![128u8; 640 * 480];
        t.apply(&mut other, 640, 8);
        assert_ne!(img, other);
        // Clamped at the ends of the range, never wrapped.
        let mut dark = vec![0u8; 640 * 4];
        t.apply(&mut dark, 640, 1);
        assert!(dark.iter().all(|&p| p < 20));
    }
}
