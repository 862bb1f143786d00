//! The histogram of absolute residuals that the association fills and the robust scale reads
//! its median from.

use super::types::LANES;

/// Residual histogram bins: 1/16 px wide up to 16 px, for the median absolute residual.
pub(super) const HIST_BINS: usize = 256;
pub(super) const HIST_PER_PX: f64 = 16.0;

/// The histogram of absolute residuals behind the robust scale: 1/16 px bins, `top` taking
/// everything from there on. One count per lane of [`associate`](super::associate::associate),
/// so that the lanes' increments (often of the same bin) do not wait on each other.
#[derive(Debug, Clone)]
pub(super) struct ResidualBins {
    pub(super) counts: [[u16; LANES]; HIST_BINS],
    pub(super) top: usize,
}

impl Default for ResidualBins {
    fn default() -> Self {
        Self { counts: [[0; LANES]; HIST_BINS], top: HIST_BINS - 1 }
    }
}

impl ResidualBins {
    /// Empties the bins up to `top` and makes that the last one.
    pub(super) fn clear(&mut self, top: usize) {
        self.top = top.min(HIST_BINS - 1);
        self.counts[..=self.top].fill([0; LANES]);
    }

    /// Median of the `count` binned values (bin centre), px.
    pub(super) fn median(&self, count: usize) -> f64 {
        let half = count.div_ceil(2);
        let mut seen = 0usize;
        for (bin, c) in self.counts[..=self.top].iter().enumerate() {
            seen += c.iter().map(|v| *v as usize).sum::<usize>();
            if seen >= half {
                return (bin as f64 + 0.5) / HIST_PER_PX;
            }
        }
        HIST_BINS as f64 / HIST_PER_PX
    }
}
