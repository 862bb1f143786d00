//! The edge search one line at a time: what `batch::ContourSearch` computes, bit for bit, for
//! its tests to compare against (test builds only).
//!
//! A side's points are searched in one call: every line is placed and every column window
//! gathered first, then each window is scanned sixteen samples at a time (SSE2): saturating
//! byte differences give the score, byte comparisons the local maxima; the strongest four go
//! through a branch-free max/min network, and their sub-pixel steps run in four f32 lanes.

use super::super::simd::F32x4;
use super::{Appearance, Candidate, PointEdges, SideGeometry, SignRule, MAX_CANDIDATES, MAX_HALF, PAD};
use crate::image::ImageView;

/// Longest search line: the window, one more sample each side for rounding, and the padding.
const LINE_MAX: usize = 2 * (MAX_HALF + 1 + PAD) + 1;
/// Most samples in a window (`k_lo..=k_hi`), rounded up to whole 16-sample chunks.
const WINDOW_MAX: usize = 128;
const _: () = assert!(LINE_MAX - 2 * PAD <= WINDOW_MAX);

/// `floor` as an integer without a libm call (the baseline x86-64 target has no SSE4.1
/// rounding instruction) and without the saturating conversion's checks. Callers pass
/// finite values of magnitude below 2^31 (checked once per point).
#[inline(always)]
fn floor_to_isize(x: f64) -> isize {
    debug_assert!(x.is_finite() && x.abs() < 2147483648.0);
    // SAFETY: `x` is finite and within isize's range (see above), which is all
    // `to_int_unchecked` requires.
    let t = unsafe { x.to_int_unchecked::<i32>() } as isize;
    t - ((x < t as f64) as isize)
}

/// `ceil` as an integer, likewise.
#[inline(always)]
fn ceil_to_isize(x: f64) -> isize {
    -floor_to_isize(-x)
}

/// Hints that `bytes[0]` will be read soon (a no-op where there is no such hint).
#[inline(always)]
fn prefetch(bytes: &[u8]) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is part of the x86_64 baseline; a prefetch never faults.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(bytes.as_ptr() as *const i8)
    };
    #[cfg(not(target_arch = "x86_64"))]
    let _ = bytes;
}

/// Bytes readable past the last sample of a line: the 16-lane peak scan loads up to 13
/// bytes beyond it.
const SLACK: usize = 16;


/// Bytes kept per line in [`SideScratch`]: a whole line plus the scan's slack.
const LINE_BYTES: usize = LINE_MAX + SLACK;

/// Where one point's search line lies, from the first phase of [`search_side`].
#[derive(Debug, Clone, Copy, Default)]
struct LinePlan {
    /// The line leaves the image.
    outside: bool,
    /// The window holds no sample (`k_lo > k_hi`).
    empty: bool,
    /// The line's samples are read from the image at `start` (a row), not from the side's
    /// gathered columns.
    in_place: bool,
    /// Offset of the line's sample 0: in the image data (in place) or in
    /// [`SideScratch::columns`].
    start: usize,
    k_lo: usize,
    k_hi: usize,
    /// Normal offset of the base pixel from the predicted point, px.
    h0: f64,
}

/// Working space of [`search_side`], sized at construction for the most points a side can
/// have; reused from side to side (stale contents are initialised, nothing is cleared).
#[derive(Debug, Clone)]
pub(crate) struct SideScratch {
    plans: Vec<LinePlan>,
    /// Each point's line, `LINE_BYTES` apart: the gathered samples of a column, or a row's
    /// copy when it cannot be read in place (at the very end of the image buffer).
    columns: Vec<u8>,
    /// Score of each window sample, `k_lo + i` at `i` (clamped to 0..=255: exact at peaks).
    scores: [u8; WINDOW_MAX],
    /// Peak flags, 16 window samples per entry.
    masks: [u16; WINDOW_MAX / 16],
}

impl SideScratch {
    /// Room for sides of up to `points` points.
    pub fn with_capacity(points: usize) -> Self {
        Self {
            plans: vec![LinePlan::default(); points],
            columns: vec![0; points * LINE_BYTES],
            scores: [0; WINDOW_MAX],
            masks: [0; WINDOW_MAX / 16],
        }
    }
}

/// Searches one point's normal for up to [`MAX_CANDIDATES`] gradient maxima of at least
/// `min_contrast` with the wanted outward sign (`0` = either), keeping the strongest, and
/// writes them into `out`. `(x, y)` is the predicted point in pixels. This is the tracker's
/// own search (`batch::ContourSearch`): the behaviour tests below test what runs, and
/// `batch`'s tests that it agrees with [`search_side`].
#[allow(clippy::too_many_arguments)]
pub(crate) fn search_point(
    image: &ImageView<'_>,
    side: &SideGeometry,
    x: f64,
    y: f64,
    search_px: f64,
    outward_sign: i32,
    min_contrast: i32,
    out: &mut PointEdges,
) {
    let settings = super::super::batch::SearchSettings {
        search_px,
        signs: SignRule::Fixed(outward_sign),
        appearance: Appearance::NONE,
        min_contrast,
    };
    let out = std::slice::from_mut(out);
    super::super::batch::ContourSearch::new().search(image, std::slice::from_ref(side), &[0], &[x], &[y], &settings, out, None);
}

/// Searches the normals of one side's points at `(xs[i], ys[i])` (see [`search_point`]) into
/// `out[i]`, each candidate with its appearance penalty.
///
/// Two phases: first every point's line is placed and, for a column, the samples its window
/// needs are gathered (the strided loads of all points in one burst, and written well before
/// they are read back); then each window is scanned: scores and local maxima sixteen samples
/// at a time ([`peak_scan`]), and the sub-pixel and appearance work for the strongest few.
// The tracker searches with `batch::ContourSearch`, which computes exactly this; this one
// line at a time is the reference its tests compare against.
#[allow(clippy::too_many_arguments)]
pub(crate) fn search_side(
    image: &ImageView<'_>,
    side: &SideGeometry,
    xs: &[f64],
    ys: &[f64],
    search_px: f64,
    signs: SignRule<'_>,
    appearance: Appearance<'_>,
    min_contrast: i32,
    scratch: &mut SideScratch,
    out: &mut [PointEdges],
) {
    let count = xs.len();
    assert!(ys.len() == count && out.len() == count && scratch.plans.len() >= count, "side buffers too small");
    let (w, h, stride) = (image.width() as isize, image.height() as isize, image.stride());
    let data = image.data();
    // Sample j of a line is the pixel `j - reach` steps along the axis from the base pixel.
    let reach = (side.half + 1 + PAD) as isize;
    let len = 2 * reach as usize + 1;
    let (along_size, across_size) = if side.horizontal { (w, h) } else { (h, w) };
    let SideScratch { plans, columns, scores, masks } = scratch;
    for (i, (plan, (&x, &y))) in plans.iter_mut().zip(xs.iter().zip(ys)).enumerate() {
        *plan = LinePlan { outside: true, ..LinePlan::default() };
        // Also false for NaN.
        if !(x.abs() <= 1e8 && y.abs() <= 1e8) {
            continue;
        }
        let (bxi, byi) = (floor_to_isize(x + 0.5), floor_to_isize(y + 0.5));
        let (along, across) = if side.horizontal { (bxi, byi) } else { (byi, bxi) };
        if !(across >= 0 && across < across_size && along - reach >= 0 && along + reach < along_size) {
            continue;
        }
        plan.outside = false;
        // Normal offset of the base pixel relative to the predicted point, and the samples
        // whose offset lies within ±search_px.
        let h0 = side.normal[0] * (bxi as f64 - x) + side.normal[1] * (byi as f64 - y);
        let (k_a, k_b) = ((-search_px - h0) * side.inv_n_axis, (search_px - h0) * side.inv_n_axis);
        let k_lo = (ceil_to_isize(k_a.min(k_b)) + reach).max(PAD as isize) as usize;
        let k_hi = (floor_to_isize(k_a.max(k_b)) + reach).min((len - PAD - 1) as isize) as usize;
        (plan.h0, plan.k_lo, plan.k_hi) = (h0, k_lo, k_hi);
        if k_lo > k_hi {
            plan.empty = true;
            continue;
        }
        let line = &mut columns[i * LINE_BYTES..(i + 1) * LINE_BYTES];
        if side.horizontal {
            let start = byi as usize * stride + (bxi - reach) as usize;
            if start + len + SLACK <= data.len() {
                (plan.in_place, plan.start) = (true, start);
                // The scan reads the row a few hundred instructions from now: ask for the
                // window's cache lines (two at most) in the meantime.
                prefetch(&data[start + k_lo - 3..]);
                prefetch(&data[start + k_hi + 3..]);
            } else {
                line[..len].copy_from_slice(&data[start..start + len]);
                (plan.in_place, plan.start) = (false, i * LINE_BYTES);
            }
        } else {
            // Peaks at k use samples k-3..=k+3 (gradient neighbours, grey levels inside and
            // outside); PAD keeps that range inside the line.
            let start = (byi - reach) as usize * stride + bxi as usize;
            let column = &data[start..=start + (len - 1) * stride];
            let (first, end) = (k_lo - 3, k_hi + 4);
            debug_assert!(end < len);
            let mut src = column[first * stride..].as_ptr();
            for b in &mut line[first..end] {
                // SAFETY: the sample read is first * stride + (j - first) * stride = j * stride
                // for j < end <= len - 1, inside `column`; advancing past the last one is not
                // read.
                unsafe {
                    *b = *src;
                    src = src.wrapping_add(stride);
                }
            }
            (plan.in_place, plan.start) = (false, i * LINE_BYTES);
        }
    }
    // The score the wanted polarity maximises at sample k: the derivative along the axis
    // (central difference), times the sign that turns it into the outward derivative and
    // selects the polarity, or its magnitude for either polarity.
    let axis_sign: i16 = if side.n_axis >= 0.0 { 1 } else { -1 };
    for (i, (plan, out)) in plans[..count].iter().zip(out.iter_mut()).enumerate() {
        out.count = 0;
        out.outside = plan.outside;
        if plan.outside || plan.empty {
            continue;
        }
        let samples = if plan.in_place {
            &data[plan.start..plan.start + len + SLACK]
        } else {
            &columns[plan.start..plan.start + LINE_BYTES]
        };
        let window = Window {
            samples,
            k_lo: plan.k_lo,
            n: plan.k_hi + 1 - plan.k_lo,
            reach,
            inward: -(axis_sign as isize),
            axis_sign,
            min_contrast,
            h0: plan.h0 as f32,
            step_h: side.n_axis as f32,
            limit: search_px as f32,
        };
        match axis_sign * signs.sign(i).signum() as i16 {
            0 => window.edges::<0>(scores, masks, out),
            1 => window.edges::<1>(scores, masks, out),
            _ => window.edges::<2>(scores, masks, out),
        }
        if appearance.gain > 0.0 && appearance.reference[i] >= 0.0 {
            let reference = appearance.reference[i];
            for c in &mut out.candidates[..out.count as usize] {
                c.penalty_px = appearance.gain * ((c.inside as f32 - reference).abs() - appearance.tolerance).max(0.0);
            }
        }
    }
}

/// One search line's samples and window, for [`Window::edges`].
struct Window<'a> {
    /// The line's samples, readable `SLACK` past its end.
    samples: &'a [u8],
    /// The window: samples `k_lo..k_lo + n`, with `k_lo >= PAD` and `k_lo + n + PAD <=` the
    /// line's length.
    k_lo: usize,
    n: usize,
    /// Index of the base pixel.
    reach: isize,
    /// Step towards the contour's interior along the line (±1).
    inward: isize,
    axis_sign: i16,
    min_contrast: i32,
    /// Normal offset of the base pixel, normal offset per sample, and the search half-length.
    h0: f32,
    step_h: f32,
    limit: f32,
}

impl Window<'_> {
    /// The peaks of the score (`MODE` 0: magnitude, 1: derivative, 2: minus the derivative),
    /// the strongest [`MAX_CANDIDATES`] of them with sub-pixel offsets, into `out`.
    #[inline(always)]
    fn edges<const MODE: u8>(
        &self,
        scores: &mut [u8; WINDOW_MAX],
        masks: &mut [u16; WINDOW_MAX / 16],
        out: &mut PointEdges,
    ) {
        let sigma: i16 = match MODE {
            0 => 0,
            1 => 1,
            _ => -1,
        };
        // Peaks: local maxima above the threshold (`s >= threshold, s > previous, s >= next`).
        let chunks = peak_scan(self.samples, self.k_lo, self.n, sigma, self.min_contrast, scores, masks);
        // Keep the strongest few, the earlier one first among equals: each peak as the key
        // `score << 8 | (255 - i)` (unique, larger is better; 0 = empty slot) through a
        // max/min insertion network, branch-free.
        let mut top = [0u32; MAX_CANDIDATES];
        for (c, &mask) in masks[..chunks].iter().enumerate() {
            let mut bits = mask;
            while bits != 0 {
                let i = c * 16 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let mut key = (scores[i] as u32) << 8 | (255 - i as u32);
                for slot in &mut top {
                    let better = (*slot).max(key);
                    key = (*slot).min(key);
                    *slot = better;
                }
            }
        }
        // The sub-pixel and appearance work for those alone. A peak k reads samples
        // k-3..=k+3, inside the line (see the field docs).
        let (samples, k_lo) = (self.samples, self.k_lo);
        debug_assert!(k_lo >= 3 && k_lo + self.n + 3 <= samples.len());
        // SAFETY: called with indices within k-3..=k+3 of a peak k in the window only.
        let at = |j: usize| unsafe { *samples.get_unchecked(j) } as i16;
        let score = |after: i16, before: i16| -> i16 {
            match MODE {
                0 => (after - before).abs(),
                1 => after - before,
                _ => before - after,
            }
        };
        // The integer part per peak (the keys are sorted, empty slots last)...
        let peaks = top.iter().take_while(|key| **key != 0).count();
        let (mut a, mut b, mut c, mut offset) = ([0i32; 4], [1i32; 4], [0i32; 4], [0i32; 4]);
        let (mut sign, mut grey) = ([1.0f32; 4], [(0u8, 0u8); 4]);
        for (j, &key) in top[..peaks].iter().enumerate() {
            let k = k_lo + (255 - (key & 0xff)) as usize;
            let (s_m2, s_m1, s_0, s_p1, s_p2) = (at(k - 2), at(k - 1), at(k), at(k + 1), at(k + 2));
            // The neighbours' true scores (the stored ones are clamped at 0).
            (a[j], b[j], c[j]) = (score(s_0, s_m2) as i32, (key >> 8) as i32, score(s_p2, s_0) as i32);
            offset[j] = (k as isize - self.reach) as i32;
            sign[j] = if self.axis_sign * (s_p1 - s_m1) >= 0 { 1.0 } else { -1.0 };
            let (k_in, k_out) = ((k as isize + 2 * self.inward) as usize, (k as isize - 2 * self.inward) as usize);
            let inside = (at(k_in) + at((k_in as isize + self.inward) as usize) + 1) >> 1;
            let outside = (at(k_out) + at((k_out as isize - self.inward) as usize) + 1) >> 1;
            grey[j] = (inside as u8, outside as u8);
        }
        // ...and the sub-pixel step for all of them at once: the parabola through each peak
        // and its neighbours. At a strict local maximum the denominator is negative and the
        // vertex within ±½. (The same f32 operations, in the same order, as one at a time.)
        let (a, b, c) = (F32x4::from_i32(a), F32x4::from_i32(b), F32x4::from_i32(c));
        let zero = F32x4::splat(0.0);
        let denom = a.sub(F32x4::splat(2.0).mul(b)).add(c);
        let vertex = F32x4::splat(0.5).mul(a.sub(c)).div(denom).min(F32x4::splat(0.5)).max(F32x4::splat(-0.5));
        let delta = denom.lt(zero).select(vertex, zero);
        let h_px = F32x4::splat(self.h0).add(F32x4::from_i32(offset).add(delta).mul(F32x4::splat(self.step_h)));
        // An interpolated peak may slip just past the window's end: dropped.
        let slipped = F32x4::splat(self.limit).lt(h_px.abs()).mask_bits();
        let peak = b.sub(F32x4::splat(0.25).mul(a.sub(c)).mul(delta));
        let (h_px, contrast) = (h_px.to_array(), peak.mul(F32x4::load_array(sign)).to_array());
        let mut kept = 0usize;
        for j in 0..peaks {
            if slipped >> j & 1 == 0 {
                let (inside, outside) = grey[j];
                out.candidates[kept] = Candidate { h_px: h_px[j], contrast: contrast[j], inside, outside, penalty_px: 0.0 };
                kept += 1;
            }
        }
        out.count = kept as u8;
    }
}

/// Scores and peaks of the window `k_lo..k_lo + n` in 16-sample chunks; returns the number
/// of chunks. The score of sample k is `|S[k+1] − S[k−1]|` (`sigma == 0`) or
/// `sigma · (S[k+1] − S[k−1])` (`sigma = ±1`), clamped to 0..=255 and stored at
/// `scores[k − k_lo]`; bit `i` of `masks[c]` flags sample `k_lo + 16c + i` as a peak:
/// `s >= min_contrast`, `s >` the previous sample's score, `s >=` the next one's. Clamping
/// negative scores to 0 changes no flag, since a peak's own score is at least 1.
/// Needs `k_lo >= 2` and `samples` readable up to `k_lo + n + 16`.
#[inline]
fn peak_scan(
    samples: &[u8],
    k_lo: usize,
    n: usize,
    sigma: i16,
    min_contrast: i32,
    scores: &mut [u8; WINDOW_MAX],
    masks: &mut [u16; WINDOW_MAX / 16],
) -> usize {
    let chunks = n.div_ceil(16);
    assert!(
        n > 0 && n <= WINDOW_MAX && k_lo >= 2 && k_lo + 16 * chunks + 2 <= samples.len(),
        "search window out of range"
    );
    // Scores are at most 255: a threshold above that finds nothing, as it should.
    let below = (min_contrast.clamp(1, 256) - 1) as u8;
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE2 is part of the x86_64 baseline; the loads stay within `samples` and the
    // stores within `scores` and `masks` (checked above).
    unsafe {
        match sigma {
            0 => peak_scan_sse2::<0>(samples, k_lo, chunks, below, scores, masks),
            1 => peak_scan_sse2::<1>(samples, k_lo, chunks, below, scores, masks),
            _ => peak_scan_sse2::<2>(samples, k_lo, chunks, below, scores, masks),
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    peak_scan_scalar(samples, k_lo, chunks, sigma, below, scores, masks);
    // Lanes past the window are not samples of it.
    let rem = n - 16 * (chunks - 1);
    masks[chunks - 1] &= ((1u32 << rem) - 1) as u16;
    chunks
}

/// The portable form of [`peak_scan`] (all lanes of every chunk).
#[cfg_attr(target_arch = "x86_64", allow(dead_code))]
fn peak_scan_scalar(
    samples: &[u8],
    k_lo: usize,
    chunks: usize,
    sigma: i16,
    below: u8,
    scores: &mut [u8; WINDOW_MAX],
    masks: &mut [u16; WINDOW_MAX / 16],
) {
    let score = |k: usize| {
        let (after, before) = (samples[k + 1], samples[k - 1]);
        match sigma {
            0 => after.abs_diff(before),
            1 => after.saturating_sub(before),
            _ => before.saturating_sub(after),
        }
    };
    for (c, mask) in masks[..chunks].iter_mut().enumerate() {
        let mut bits = 0u16;
        for i in 0..16 {
            let k = k_lo + 16 * c + i;
            let s = score(k);
            scores[16 * c + i] = s;
            bits |= ((s > below && s > score(k - 1) && s >= score(k + 1)) as u16) << i;
        }
        *mask = bits;
    }
}

/// [`peak_scan`] with SSE2: five overlapping 16-byte loads give the scores at k-1, k and k+1
/// for sixteen k at once, as saturating byte differences (`MODE` 0: either sign, 1: positive,
/// 2: negative); unsigned comparisons are signed ones on values offset by 128.
///
/// # Safety
/// `samples` readable at `k_lo - 2 ..= k_lo + 16 * chunks + 1`, `chunks <= WINDOW_MAX / 16`.
#[cfg(target_arch = "x86_64")]
#[inline]
unsafe fn peak_scan_sse2<const MODE: u8>(
    samples: &[u8],
    k_lo: usize,
    chunks: usize,
    below: u8,
    scores: &mut [u8; WINDOW_MAX],
    masks: &mut [u16; WINDOW_MAX / 16],
) {
    use std::arch::x86_64::*;
    let p = samples.as_ptr();
    // SAFETY (for the whole body): see the function's contract.
    unsafe {
        let bias = _mm_set1_epi8(i8::MIN);
        let below = _mm_set1_epi8((below ^ 0x80) as i8);
        let load = |j: usize| _mm_loadu_si128(p.add(j) as *const __m128i);
        let score = |after: __m128i, before: __m128i| match MODE {
            0 => _mm_or_si128(_mm_subs_epu8(after, before), _mm_subs_epu8(before, after)),
            1 => _mm_subs_epu8(after, before),
            _ => _mm_subs_epu8(before, after),
        };
        for c in 0..chunks {
            let k = k_lo + 16 * c;
            let (s0, s1, s2, s3, s4) = (load(k - 2), load(k - 1), load(k), load(k + 1), load(k + 2));
            let here = score(s3, s1);
            _mm_storeu_si128(scores.as_mut_ptr().add(16 * c) as *mut __m128i, here);
            let prev = _mm_xor_si128(score(s2, s0), bias);
            let next = _mm_xor_si128(score(s4, s2), bias);
            let here = _mm_xor_si128(here, bias);
            let peak = _mm_andnot_si128(
                _mm_cmpgt_epi8(next, here),
                _mm_and_si128(_mm_cmpgt_epi8(here, below), _mm_cmpgt_epi8(here, prev)),
            );
            *masks.get_unchecked_mut(c) = _mm_movemask_epi8(peak) as u16;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::ImageBuf;

    /// An image with a straight step edge `n·p = c` (value `lo` on the side where `n·p < c`)
    /// blurred over about one pixel, rendered by supersampling.
    fn edge_image(n: [f64; 2], c: f64, lo: u8, hi: u8) -> ImageBuf {
        let mut img = ImageBuf::new(64, 64);
        for y in 0..64 {
            for x in 0..64 {
                let mut acc = 0.0;
                for sy in 0..8 {
                    for sx in 0..8 {
                        let (px, py) = (x as f64 + (sx as f64 + 0.5) / 8.0 - 0.5, y as f64 + (sy as f64 + 0.5) / 8.0 - 0.5);
                        let dist = n[0] * px + n[1] * py - c;
                        acc += 1.0 / (1.0 + (-2.0 * dist).exp());
                    }
                }
                let f = acc / 64.0;
                img.set(x, y, (lo as f64 + f * (hi as f64 - lo as f64)).round() as u8);
            }
        }
        img
    }

    #[test]
    fn finds_a_straight_edge_with_subpixel_accuracy_at_any_angle() {
        for deg in [0.0f64, 17.0, 44.0, 46.0, 90.0, 133.0, 200.0, 301.0] {
            let a = deg.to_radians();
            let n = [a.cos(), a.sin()];
            let centre = [32.3, 31.6];
            for true_h in [-4.3, -0.5, 0.0, 2.7, 6.1] {
                let c = n[0] * centre[0] + n[1] * centre[1] + true_h;
                let img = edge_image(n, c, 40, 200);
                let side = SideGeometry::new(n, 10.0);
                let mut out = PointEdges::default();
                search_point(&img.view(), &side, centre[0], centre[1], 10.0, 1, 10, &mut out);
                assert_eq!(out.count, 1, "angle {deg} h {true_h}");
                let got = out.candidates[0];
                assert!((got.h_px as f64 - true_h).abs() < 0.1, "angle {deg}: want {true_h}, got {}", got.h_px);
                assert!(got.contrast > 0.0);
                // Dark (40) inside, bright (200) outside.
                assert!(got.inside < 70 && got.outside > 170, "{got:?}");
                // The opposite polarity sees nothing.
                search_point(&img.view(), &side, centre[0], centre[1], 10.0, -1, 10, &mut out);
                assert_eq!(out.count, 0);
            }
        }
    }

    #[test]
    fn edges_beyond_the_search_range_or_too_weak_are_not_found() {
        let n = [1.0, 0.0];
        let img = edge_image(n, 32.0 + 8.0, 100, 200);
        let side = SideGeometry::new(n, 5.0);
        let mut out = PointEdges::default();
        search_point(&img.view(), &side, 32.0, 32.0, 5.0, 0, 10, &mut out);
        assert_eq!(out.count, 0);
        let side = SideGeometry::new(n, 10.0);
        search_point(&img.view(), &side, 32.0, 32.0, 10.0, 0, 10, &mut out);
        assert_eq!(out.count, 1);
        search_point(&img.view(), &side, 32.0, 32.0, 10.0, 0, 250, &mut out);
        assert_eq!(out.count, 0);
    }

    #[test]
    fn keeps_the_strongest_candidates_and_reports_leaving_the_image() {
        // Three vertical bars of different contrast to the right of x = 32.
        let mut img = ImageBuf::filled(64, 64, 100);
        for y in 0..64 {
            for x in 0..64 {
                let v = match x {
                    34..=35 => 130,
                    38..=39 => 190,
                    42..=43 => 110,
                    _ => 100,
                };
                img.set(x, y, v);
            }
        }
        let side = SideGeometry::new([1.0, 0.0], 12.0);
        let mut out = PointEdges::default();
        search_point(&img.view(), &side, 32.0, 20.0, 12.0, 1, 5, &mut out);
        let c = out.as_slice();
        assert_eq!(c.len(), 3);
        // Strongest first: the 190 bar's rising edge, then the 130, then the 110.
        assert!((c[0].h_px - 5.5).abs() < 0.6 && c[0].contrast > c[1].contrast);
        assert!((c[1].h_px - 1.5).abs() < 0.6 && c[1].contrast > c[2].contrast);
        assert!((c[2].h_px - 9.5).abs() < 0.6);
        search_point(&img.view(), &side, 60.0, 20.0, 12.0, 1, 5, &mut out);
        assert!(out.outside && out.count == 0);
    }

    #[test]
    fn peak_scan_matches_the_definition_on_random_lines() {
        // Random samples with runs and plateaus (ties are where an off-by-one would show),
        // every window start and length, all three polarity modes, several thresholds; the
        // reference is the definition in signed 16-bit arithmetic.
        let mut rng = crate::rng::SplitMix64::new(0x2545_f491_4f6c_dd1d);
        let mut next = || rng.next_u64();
        let mut samples = [0u8; LINE_MAX + SLACK];
        let (mut scores, mut masks) = ([0u8; WINDOW_MAX], [0u16; WINDOW_MAX / 16]);
        let mut peaks_seen = 0;
        for round in 0..400 {
            let mut v = 128i32;
            for s in samples.iter_mut() {
                let r = next();
                v = match r % 5 {
                    0 => v, // plateau
                    1 => (r >> 8) as i32 % 256,
                    _ => (v + ((r >> 16) % 41) as i32 - 20).clamp(0, 255),
                };
                *s = v as u8;
            }
            let k_lo = 2 + (next() % 8) as usize;
            let n = 1 + (next() as usize % WINDOW_MAX).min(LINE_MAX - 3 - k_lo);
            for sigma in [0i16, 1, -1] {
                let score = |k: usize| {
                    let d = samples[k + 1] as i16 - samples[k - 1] as i16;
                    if sigma == 0 { d.abs() } else { sigma * d }
                };
                for min_contrast in [1, 12, 40, 255, 300] {
                    let chunks = peak_scan(&samples, k_lo, n, sigma, min_contrast, &mut scores, &mut masks);
                    assert_eq!(chunks, n.div_ceil(16));
                    // The portable form agrees lane for lane (it is what other targets run).
                    let (mut scalar_scores, mut scalar_masks) = ([0u8; WINDOW_MAX], [0u16; WINDOW_MAX / 16]);
                    let below = (min_contrast.clamp(1, 256) - 1) as u8;
                    peak_scan_scalar(&samples, k_lo, chunks, sigma, below, &mut scalar_scores, &mut scalar_masks);
                    assert_eq!(scalar_scores[..16 * chunks], scores[..16 * chunks]);
                    assert_eq!(scalar_masks[..chunks - 1], masks[..chunks - 1]);
                    for i in 0..16 * chunks {
                        let k = k_lo + i;
                        let want = i < n && score(k) >= min_contrast as i16 && score(k) > score(k - 1) && score(k) >= score(k + 1);
                        let got = masks[i / 16] >> (i % 16) & 1 == 1;
                        assert_eq!(got, want, "round {round}: k_lo {k_lo} n {n} sigma {sigma} threshold {min_contrast} at {i}");
                        if want {
                            assert_eq!(scores[i] as i16, score(k));
                            peaks_seen += 1;
                        }
                    }
                }
            }
        }
        assert!(peaks_seen > 10_000, "the random lines must exercise the peak test ({peaks_seen} peaks)");
    }
}
