//! The albedo of every block face: as the scenario writes them, or seeded random shades.
//! One function serves the work cell (what the renderer draws) and the layout randomiser
//! (what it predicts the renderer will draw), so the two cannot disagree.

use super::config::BlockConfig;
use handeye_vision::rng::SplitMix64;

impl BlockConfig {
    /// Albedo per face (the face order of `kind`, see `sim/README.md`) of this block, the
    /// `index`-th of a scenario seeded `scenario_seed`: its `shades`, or else
    /// seeded random shades from its `shade_seed` (default: derived from the scenario seed and
    /// the block's index).
    pub fn face_shades(&self, index: usize, scenario_seed: u64) -> Vec<f64> {
        match &self.shades {
            Some(s) => s.clone(),
            None => random_shades(self.shade_seed.unwrap_or_else(|| handeye_vision::rng::mix64(scenario_seed ^ (index as u64 + 1))), self.kind.face_count()),
        }
    }
}

/// Default face shades: well-spread levels in a seeded order, so neighbouring faces differ.
fn random_shades(seed: u64, count: usize) -> Vec<f64> {
    let mut rng = SplitMix64::new(seed);
    let mut levels: Vec<f64> = (0..count).map(|i| 0.35 + 0.6 * i as f64 / (count.max(2) - 1) as f64).collect();
    for i in (1..levels.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        levels.swap(i, j);
    }
    levels
}
