//! The normal equations from nine weighted moments per straight side.

use super::buffers::FitBuffers;
use super::types::{FitSide, Mat8, Vec8};
use crate::tracker::simd::F32x4;

/// Positions of a side's coefficient vector `u = (n.x, n.y, −c)` in `θ` for the `p.x` and the
/// `p.y` part of a point's row `J = J0 + p.x·Jx + p.y·Jy`.
const IX: [usize; 3] = [2, 4, 6];

const IY: [usize; 3] = [3, 5, 7];

/// Weighted moments of one side's points.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Moments {
    pub(super) w: f64,
    pub(super) x: f64,
    pub(super) y: f64,
    pub(super) xx: f64,
    pub(super) xy: f64,
    pub(super) yy: f64,
    pub(super) h: f64,
    pub(super) hx: f64,
    pub(super) hy: f64,
}

/// Moments of one side's weighted points, summed four lanes at a time.
#[inline]
pub(super) fn side_moments(side: &FitSide, buf: &FitBuffers) -> Moments {
    let (first, end) = (side.first, side.first + side.count);
    let full = first + side.count / 4 * 4;
    let zero = F32x4::splat(0.0);
    let mut acc = [zero; 9];
    buf.check_lanes();
    assert!(end <= buf.lanes, "side beyond the points");
    let (x, y, h, w) = (buf.x.as_ptr(), buf.y.as_ptr(), buf.h.as_ptr(), buf.w.as_ptr());
    for j in (first..full).step_by(4) {
        // SAFETY: j + 4 <= full <= end <= lanes, the arrays' length (checked above).
        let (xi, yi, hi, wi) =
            unsafe { (F32x4::load_ptr(x.add(j)), F32x4::load_ptr(y.add(j)), F32x4::load_ptr(h.add(j)), F32x4::load_ptr(w.add(j))) };
        let (wx, wy, wh) = (wi.mul(xi), wi.mul(yi), wi.mul(hi));
        let add = [wi, wx, wy, wx.mul(xi), wx.mul(yi), wy.mul(yi), wh, wh.mul(xi), wh.mul(yi)];
        for (a, v) in acc.iter_mut().zip(add) {
            *a = a.add(v);
        }
    }
    let mut sum = [0.0f64; 9];
    for (s, a) in sum.iter_mut().zip(&acc) {
        *s = a.to_array().iter().map(|v| *v as f64).sum();
    }
    for j in full..end {
        let (xi, yi, hi, wi) = (buf.x[j] as f64, buf.y[j] as f64, buf.h[j] as f64, buf.w[j] as f64);
        let (wx, wy, wh) = (wi * xi, wi * yi, wi * hi);
        let add = [wi, wx, wy, wx * xi, wx * yi, wy * yi, wh, wh * xi, wh * yi];
        for (s, a) in sum.iter_mut().zip(add) {
            *s += a;
        }
    }
    Moments { w: sum[0], x: sum[1], y: sum[2], xx: sum[3], xy: sum[4], yy: sum[5], h: sum[6], hx: sum[7], hy: sum[8] }
}

/// Adds one side's share to the normal equations `M θ = b`. A point's row is
/// `J = J0 + p.x Jx + p.y Jy` with `J0 = (n, 0…)` and `u = (n.x, n.y, −c)` at `IX` / `IY`.
#[inline]
pub(super) fn accumulate_side(m: &mut Mat8, b: &mut Vec8, side: &FitSide, mo: &Moments) {
    let n = [side.normal.x, side.normal.y];
    let u = [side.normal.x, side.normal.y, -side.np];
    for i in 0..2 {
        for j in 0..2 {
            m[(i, j)] += mo.w * n[i] * n[j];
        }
        for k in 0..3 {
            let vx = mo.x * n[i] * u[k];
            let vy = mo.y * n[i] * u[k];
            m[(i, IX[k])] += vx;
            m[(IX[k], i)] += vx;
            m[(i, IY[k])] += vy;
            m[(IY[k], i)] += vy;
        }
        b[i] += mo.h * n[i];
    }
    for k in 0..3 {
        for l in 0..3 {
            let uu = u[k] * u[l];
            m[(IX[k], IX[l])] += mo.xx * uu;
            m[(IY[k], IY[l])] += mo.yy * uu;
            m[(IX[k], IY[l])] += mo.xy * uu;
            m[(IY[l], IX[k])] += mo.xy * uu;
        }
        b[IX[k]] += mo.hx * u[k];
        b[IY[k]] += mo.hy * u[k];
    }
}
