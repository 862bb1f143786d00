//! Robust weighting: the scale from the median absolute residual (binned as the association
//! runs) and the weights of Tukey's, Huber's or the plain loss.

use super::buffers::FitBuffers;
use super::{RobustLoss, LANES};
use crate::tracker::simd::F32x4;

/// Residual histogram bins: 1/16 px wide up to 16 px, for the median absolute residual.
pub(super) const HIST_BINS: usize = 256;
pub(super) const HIST_PER_PX: f64 = 16.0;

/// 1.4826 · MAD estimates the standard deviation of normally distributed residuals.
pub(super) const MAD_TO_SIGMA: f64 = 1.4826;

/// Robust weights of every point (0 without a candidate) into `buf.w`.
#[inline]
pub(super) fn weigh(loss: RobustLoss, sigma: f64, buf: &mut FitBuffers) {
    buf.check_lanes();
    let (r, valid, w) = (buf.r.as_ptr(), buf.valid.as_ptr(), buf.w.as_mut_ptr());
    let one = F32x4::splat(1.0);
    let (inv_tukey, k_huber) = (F32x4::splat((1.0 / (4.685 * sigma)) as f32), F32x4::splat((1.345 * sigma) as f32));
    for i in (0..buf.lanes).step_by(4) {
        // SAFETY: i + 4 <= lanes, the length of all three arrays (checked above).
        unsafe {
            let r = F32x4::load_ptr(r.add(i));
            let weight = match loss {
                RobustLoss::Tukey => {
                    let u = r.mul(inv_tukey);
                    let t = one.sub(u.mul(u)).max(F32x4::splat(0.0));
                    t.mul(t)
                }
                RobustLoss::Huber => {
                    let a = r.abs();
                    a.le(k_huber).select(one, k_huber.div(a))
                }
                RobustLoss::LeastSquares => one,
            };
            weight.and(F32x4::load_ptr(valid.add(i))).store_ptr(w.add(i));
        }
    }
}

/// The histogram of absolute residuals behind the robust scale: 1/16 px bins, `top` taking
/// everything from there on. One count per lane of [`associate`], so that the lanes'
/// increments (often of the same bin) do not wait on each other.
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
