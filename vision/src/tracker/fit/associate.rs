//! Association: every point takes the candidate edge the current motion explains best.

use super::buffers::FitBuffers;
use super::histogram::HIST_PER_PX;
use super::types::Vec8;
use crate::tracker::search::MAX_CANDIDATES;
use crate::tracker::simd::F32x4;

/// Gives every point the candidate closest to the motion's prediction (distance plus the
/// candidate's penalty; the first of equals) and records its offset, residual and whether it
/// had one; with `BIN`, bins the absolute residuals of those that did. Returns their number.
/// Four points at a time, branch-free over the candidate slots.
#[inline]
pub(super) fn associate<const BIN: bool, const CHOSEN: bool>(theta: &Vec8, buf: &mut FitBuffers) -> usize {
    #[cfg(target_arch = "x86_64")]
    if buf.avx2 {
        // SAFETY: the processor has AVX2 (checked when the buffers were made).
        return unsafe { associate_avx2::<BIN, CHOSEN>(theta, buf) };
    }
    let th: [F32x4; 8] = std::array::from_fn(|k| F32x4::splat(theta[k] as f32));
    let lanes = buf.lanes;
    buf.check_lanes();
    let (x, y, nx, ny, c) = (buf.x.as_ptr(), buf.y.as_ptr(), buf.nx.as_ptr(), buf.ny.as_ptr(), buf.c.as_ptr());
    let (cand_h, cand_pen) = (buf.cand_h.as_ptr(), buf.cand_pen.as_ptr());
    let (h, r_out, valid_out) = (buf.h.as_mut_ptr(), buf.r.as_mut_ptr(), buf.valid.as_mut_ptr());
    let chosen_out = buf.chosen_lane.as_mut_ptr();
    let inf = F32x4::splat(f32::INFINITY);
    let scale = F32x4::splat(HIST_PER_PX as f32);
    let top = F32x4::splat(buf.bins.top as f32);
    let bins = &mut buf.bins.counts;
    let mut found = 0usize;
    for i in (0..lanes).step_by(4) {
        // SAFETY: i + 4 <= lanes and every array holds `lanes` values per slot (checked
        // above), so every access below is in bounds.
        unsafe {
            let (px, py) = (F32x4::load_ptr(x.add(i)), F32x4::load_ptr(y.add(i)));
            // n·(t + A p) − c (g·p), in the order of `associate_scalar`.
            let along_x = th[0].add(th[2].mul(px)).add(th[3].mul(py));
            let along_y = th[1].add(th[4].mul(px)).add(th[5].mul(py));
            let perspective = th[6].mul(px).add(th[7].mul(py));
            let pred = F32x4::load_ptr(nx.add(i))
                .mul(along_x)
                .add(F32x4::load_ptr(ny.add(i)).mul(along_y))
                .sub(F32x4::load_ptr(c.add(i)).mul(perspective));
            let (mut best, mut best_h, mut best_k) = (inf, F32x4::splat(0.0), F32x4::splat(-1.0));
            for k in 0..MAX_CANDIDATES {
                let hk = F32x4::load_ptr(cand_h.add(k * lanes + i));
                let cost = hk.sub(pred).abs().add(F32x4::load_ptr(cand_pen.add(k * lanes + i)));
                let better = cost.lt(best);
                best = better.select(cost, best);
                best_h = better.select(hk, best_h);
                if CHOSEN {
                    best_k = better.select(F32x4::splat(k as f32), best_k);
                }
            }
            if CHOSEN {
                best_k.store_ptr(chosen_out.add(i));
            }
            let valid = best.lt(inf);
            let r = best_h.sub(pred);
            best_h.store_ptr(h.add(i));
            r.store_ptr(r_out.add(i));
            valid.store_ptr(valid_out.add(i));
            let bits = valid.mask_bits();
            found += bits.count_ones() as usize;
            if BIN {
                // Bin |r| · 16, the top bin taking everything beyond (and a NaN residual,
                // which only a non-finite motion makes, and the tracker declares that lost).
                let scaled = r.abs().mul(scale);
                let lane_bins = scaled.lt(top).select(scaled, top).to_i32_array();
                for (l, bin) in lane_bins.iter().enumerate() {
                    bins[*bin as usize][l] += ((bits >> l) & 1) as u16;
                }
            }
        }
    }
    found
}

/// [`associate`] eight points at a time with AVX (the same f32 operations per lane, so the
/// same results).
///
/// # Safety
/// The processor supports AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn associate_avx2<const BIN: bool, const CHOSEN: bool>(theta: &Vec8, buf: &mut FitBuffers) -> usize {
    use std::arch::x86_64::*;
    let lanes = buf.lanes;
    buf.check_lanes();
    let (x, y, nx, ny, c) = (buf.x.as_ptr(), buf.y.as_ptr(), buf.nx.as_ptr(), buf.ny.as_ptr(), buf.c.as_ptr());
    let (cand_h, cand_pen) = (buf.cand_h.as_ptr(), buf.cand_pen.as_ptr());
    let (h, r_out, valid_out) = (buf.h.as_mut_ptr(), buf.r.as_mut_ptr(), buf.valid.as_mut_ptr());
    let chosen_out = buf.chosen_lane.as_mut_ptr();
    let top_bin = buf.bins.top;
    let bins = &mut buf.bins.counts;
    let th: [__m256; 8] = std::array::from_fn(|k| _mm256_set1_ps(theta[k] as f32));
    let inf = _mm256_set1_ps(f32::INFINITY);
    let sign_bit = _mm256_set1_ps(-0.0);
    let scale = _mm256_set1_ps(HIST_PER_PX as f32);
    let top = _mm256_set1_ps(top_bin as f32);
    let mut found = 0usize;
    for i in (0..lanes).step_by(8) {
        // SAFETY: i + 8 <= lanes (lanes is a multiple of 8) and every array holds `lanes`
        // values per slot (checked above).
        unsafe {
            let (px, py) = (_mm256_loadu_ps(x.add(i)), _mm256_loadu_ps(y.add(i)));
            let along_x = _mm256_add_ps(_mm256_add_ps(th[0], _mm256_mul_ps(th[2], px)), _mm256_mul_ps(th[3], py));
            let along_y = _mm256_add_ps(_mm256_add_ps(th[1], _mm256_mul_ps(th[4], px)), _mm256_mul_ps(th[5], py));
            let perspective = _mm256_add_ps(_mm256_mul_ps(th[6], px), _mm256_mul_ps(th[7], py));
            let pred = _mm256_sub_ps(
                _mm256_add_ps(
                    _mm256_mul_ps(_mm256_loadu_ps(nx.add(i)), along_x),
                    _mm256_mul_ps(_mm256_loadu_ps(ny.add(i)), along_y),
                ),
                _mm256_mul_ps(_mm256_loadu_ps(c.add(i)), perspective),
            );
            let (mut best, mut best_h, mut best_k) = (inf, _mm256_setzero_ps(), _mm256_set1_ps(-1.0));
            for k in 0..MAX_CANDIDATES {
                let hk = _mm256_loadu_ps(cand_h.add(k * lanes + i));
                let distance = _mm256_andnot_ps(sign_bit, _mm256_sub_ps(hk, pred));
                let cost = _mm256_add_ps(distance, _mm256_loadu_ps(cand_pen.add(k * lanes + i)));
                let better = _mm256_cmp_ps::<_CMP_LT_OQ>(cost, best);
                best = _mm256_blendv_ps(best, cost, better);
                best_h = _mm256_blendv_ps(best_h, hk, better);
                if CHOSEN {
                    best_k = _mm256_blendv_ps(best_k, _mm256_set1_ps(k as f32), better);
                }
            }
            if CHOSEN {
                _mm256_storeu_ps(chosen_out.add(i), best_k);
            }
            let valid = _mm256_cmp_ps::<_CMP_LT_OQ>(best, inf);
            let r = _mm256_sub_ps(best_h, pred);
            _mm256_storeu_ps(h.add(i), best_h);
            _mm256_storeu_ps(r_out.add(i), r);
            _mm256_storeu_ps(valid_out.add(i), valid);
            let bits = _mm256_movemask_ps(valid) as u32;
            found += bits.count_ones() as usize;
            if BIN {
                let scaled = _mm256_mul_ps(_mm256_andnot_ps(sign_bit, r), scale);
                let capped = _mm256_blendv_ps(top, scaled, _mm256_cmp_ps::<_CMP_LT_OQ>(scaled, top));
                let mut lane_bins = [0i32; 8];
                _mm256_storeu_si256(lane_bins.as_mut_ptr() as *mut __m256i, _mm256_cvttps_epi32(capped));
                for (l, bin) in lane_bins.iter().enumerate() {
                    bins[*bin as usize][l] += ((bits >> l) & 1) as u16;
                }
            }
        }
    }
    found
}

/// [`associate`] one point at a time, also recording the chosen candidate's index: the
/// reference the vector paths are tested against.
#[cfg(test)]
pub(super) fn associate_scalar(theta: &Vec8, buf: &mut FitBuffers) {
    let th: [f32; 8] = std::array::from_fn(|k| theta[k] as f32);
    let lanes = buf.lanes;
    for i in 0..buf.n {
        let (px, py) = (buf.x[i], buf.y[i]);
        let pred = buf.nx[i] * (th[0] + th[2] * px + th[3] * py) + buf.ny[i] * (th[1] + th[4] * px + th[5] * py)
            - buf.c[i] * (th[6] * px + th[7] * py);
        let (mut best, mut best_h, mut best_k) = (f32::INFINITY, 0.0f32, -1i8);
        for k in 0..MAX_CANDIDATES {
            let hk = buf.cand_h[k * lanes + i];
            let cost = (hk - pred).abs() + buf.cand_pen[k * lanes + i];
            if cost < best {
                (best, best_h, best_k) = (cost, hk, k as i8);
            }
        }
        buf.h[i] = best_h;
        buf.r[i] = best_h - pred;
        buf.valid[i] = f32::from_bits(if best_k >= 0 { u32::MAX } else { 0 });
        buf.chosen[i] = best_k;
    }
}
