//! Robust weighting: the scale from the median absolute residual (binned as the association
//! runs) and the weights of Tukey's, Huber's or the plain loss.

use super::buffers::FitBuffers;
use super::types::RobustLoss;
use crate::tracker::simd::F32x4;

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
