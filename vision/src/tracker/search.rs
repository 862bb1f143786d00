//! The local edge finder: a 1-D search along the contour normal for maxima of the intensity
//! gradient, with sub-pixel location.
//!
//! Speed comes from sampling on the pixel grid. A point whose normal is closer to horizontal
//! is searched along its image row, otherwise along its column, so every sample is one byte
//! load (contiguous for rows, one stride apart for columns) and no interpolation is needed.
//! This is exact for a straight edge: moving `d` pixels along the row from the predicted point
//! `x` reaches the edge line `n·p = c` where `n·(x + d·u) = c`, so the normal offset is
//! `h = n·(p_edge − x)`, computed from the row sample's true position. The search covers
//! `±search_px` along the normal, i.e. `±search_px / |n_axis|` samples along the axis (at most
//! 1.42x more for a 45° edge).

use crate::image::ImageView;

/// Most candidate edges kept per point.
pub const MAX_CANDIDATES: usize = 4;
/// Longest search half-length accepted, pixels along the normal.
pub const MAX_SEARCH_PX: f64 = 40.0;
/// Extra samples read beyond the search window at each end, for the gradient's neighbours
/// and the intensities just inside and outside a peak.
const PAD: usize = 4;
/// Samples along the axis for the longest search: `40 · √2 + 2` each side plus padding.
const BUF: usize = 2 * (58 + PAD) + 1;

/// Which intensity change across the contour an edge must have.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Polarity {
    /// Two-sided: either sign ("two-sided" snake of the thesis).
    #[default]
    Either,
    /// One-sided: darker inside the contour than outside.
    DarkInside,
    /// One-sided: brighter inside the contour than outside.
    BrightInside,
}

impl Polarity {
    /// Sign of the intensity derivative along the outward normal: +1, -1, or 0 for either.
    #[inline]
    pub(crate) fn outward_sign(self) -> i32 {
        match self {
            Polarity::Either => 0,
            Polarity::DarkInside => 1,
            Polarity::BrightInside => -1,
        }
    }
}

/// Search geometry shared by all points of one polygon side in one update.
#[derive(Debug, Clone, Copy)]
pub(crate) struct SideGeometry {
    /// Outward unit normal in the image.
    pub normal: [f64; 2],
    /// Search along the row (`true`) or the column.
    pub horizontal: bool,
    /// Normal component along the search axis (`n.x` or `n.y`), |.| >= 0.707.
    pub n_axis: f64,
    /// `1 / n_axis`.
    pub inv_n_axis: f64,
    /// Samples each side of the base pixel.
    pub half: usize,
}

impl SideGeometry {
    pub fn new(normal: [f64; 2], search_px: f64) -> Self {
        let horizontal = normal[0].abs() >= normal[1].abs();
        let n_axis = if horizontal { normal[0] } else { normal[1] };
        // Rounding the base pixel moves the search line up to 0.71 px along the normal.
        let half = ((search_px + 0.71) / n_axis.abs()).ceil() as usize;
        Self { normal, horizontal, n_axis, inv_n_axis: 1.0 / n_axis, half: half.min((BUF - 1) / 2 - PAD) }
    }
}

/// One candidate edge on a search line.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Candidate {
    /// Offset along the outward normal from the predicted point, pixels.
    pub h_px: f32,
    /// Gradient along the outward normal at the peak, signed (central difference, grey levels
    /// per two samples: -255..255). Positive: brighter outside.
    pub contrast: f32,
    /// Mean grey level 2-3 samples inside the peak (towards the contour's interior).
    pub inside: u8,
    /// Mean grey level 2-3 samples outside the peak.
    pub outside: u8,
    /// Extra cost (px) the fit adds to this candidate's distance when choosing among a
    /// point's candidates (set by the tracker from its appearance; 0 from the search).
    pub penalty_px: f32,
}

/// What a search line found.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct PointEdges {
    pub candidates: [Candidate; MAX_CANDIDATES],
    pub count: u8,
    /// The search line left the image: no measurement.
    pub outside: bool,
}

impl PointEdges {
    #[inline]
    pub fn as_slice(&self) -> &[Candidate] {
        &self.candidates[..self.count as usize]
    }
}

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

/// Searches one point's normal for up to [`MAX_CANDIDATES`] gradient maxima of at least
/// `min_contrast` with the wanted outward sign (`0` = either), keeping the strongest, and
/// writes them into `out`. `(x, y)` is the predicted point in pixels.
// The hot path takes plain scalars rather than a parameter struct built per point.
#[allow(clippy::too_many_arguments)]
#[inline]
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
    out.count = 0;
    out.outside = false;
    if !(x.is_finite() && y.is_finite()) || x.abs() > 1e8 || y.abs() > 1e8 {
        out.outside = true;
        return;
    }
    let (w, h, stride) = (image.width() as isize, image.height() as isize, image.stride());
    let (bxi, byi) = (floor_to_isize(x + 0.5), floor_to_isize(y + 0.5));
    let reach = (side.half + 1 + PAD) as isize;
    let len = 2 * reach as usize + 1;
    // The samples along the axis, one byte each: the row itself, or the column gathered with
    // the stride into a small buffer. Bounds are checked once here, not per sample.
    let mut column = [0u8; BUF];
    let data = image.data();
    let samples: &[u8] = if side.horizontal {
        if byi < 0 || byi >= h || bxi - reach < 0 || bxi + reach >= w {
            out.outside = true;
            return;
        }
        let start = byi as usize * stride + (bxi - reach) as usize;
        &data[start..start + len]
    } else {
        if bxi < 0 || bxi >= w || byi - reach < 0 || byi + reach >= h {
            out.outside = true;
            return;
        }
        let start = (byi - reach) as usize * stride + bxi as usize;
        let last = start + (len - 1) * stride;
        // The column's last sample is inside the image (checked above), so is every one.
        let column_data = &data[start..=last];
        for (j, b) in column[..len].iter_mut().enumerate() {
            // SAFETY: j * stride <= (len - 1) * stride = last - start < column_data.len().
            *b = unsafe { *column_data.get_unchecked(j * stride) };
        }
        &column[..len]
    };

    // The score the wanted polarity maximises at every sample: the derivative along the axis
    // (central difference), times the sign that turns it into the outward derivative and
    // selects the polarity, or its magnitude for either polarity. One straight loop per case,
    // which the compiler vectorises; score[k] belongs to sample k + 1.
    let axis_sign: i16 = if side.n_axis >= 0.0 { 1 } else { -1 };
    let mut score = [0i16; BUF];
    let inner = len - 2;
    let (before, after) = (&samples[..inner], &samples[2..len]);
    if outward_sign == 0 {
        for ((sc, &b), &a) in score[..inner].iter_mut().zip(before).zip(after) {
            *sc = (a as i16 - b as i16).abs();
        }
    } else {
        let sigma = axis_sign * outward_sign.signum() as i16;
        for ((sc, &b), &a) in score[..inner].iter_mut().zip(before).zip(after) {
            *sc = sigma * (a as i16 - b as i16);
        }
    }
    // Normal offset of the base pixel relative to the predicted point, and per axis step; the
    // samples whose offset lies within ±search_px.
    let h0 = side.normal[0] * (bxi as f64 - x) + side.normal[1] * (byi as f64 - y);
    let step_h = side.n_axis;
    let (k_a, k_b) = ((-search_px - h0) * side.inv_n_axis, (search_px - h0) * side.inv_n_axis);
    let k_lo = (ceil_to_isize(k_a.min(k_b)) + reach).max(PAD as isize) as usize;
    let k_hi = (floor_to_isize(k_a.max(k_b)) + reach).min((len - PAD - 1) as isize) as usize;
    if k_lo > k_hi {
        return;
    }
    // Peaks: local maxima of the score above the threshold, flagged branch-free over three
    // shifted views of the scores (vectorised), then visited eight flags at a time.
    let threshold = min_contrast.clamp(1, i16::MAX as i32) as i16;
    let mut flags = [0u8; BUF + 8];
    let n = k_hi + 1 - k_lo;
    let (prev, here, next) = (&score[k_lo - 2..k_hi - 1], &score[k_lo - 1..k_hi], &score[k_lo..=k_hi]);
    for (((f, &p), &s), &q) in flags[..n].iter_mut().zip(prev).zip(here).zip(next) {
        *f = ((s >= threshold) & (s > p) & (s >= q)) as u8;
    }
    // Keep the strongest few by score (integer work only)...
    let mut peaks = [(0i16, 0usize); MAX_CANDIDATES];
    let mut count = 0usize;
    for (chunk_index, chunk) in flags[..n.div_ceil(8) * 8].chunks_exact(8).enumerate() {
        let mut bits = u64::from_le_bytes([chunk[0], chunk[1], chunk[2], chunk[3], chunk[4], chunk[5], chunk[6], chunk[7]]);
        while bits != 0 {
            let offset = chunk_index * 8 + bits.trailing_zeros() as usize / 8;
            bits &= bits - 1;
            let k = k_lo + offset;
            let s = score[k - 1];
            let mut pos = count;
            while pos > 0 && peaks[pos - 1].0 < s {
                if pos < MAX_CANDIDATES {
                    peaks[pos] = peaks[pos - 1];
                }
                pos -= 1;
            }
            if pos < MAX_CANDIDATES {
                peaks[pos] = (s, k);
                count = (count + 1).min(MAX_CANDIDATES);
            }
        }
    }
    // ...and do the sub-pixel and appearance work for those alone.
    let inward = -(axis_sign as isize);
    let mut kept = 0usize;
    let (h0, step_h, limit) = (h0 as f32, step_h as f32, search_px as f32);
    for &(s, k) in &peaks[..count] {
        // Parabola through the peak and its neighbours (score index k - 1 is sample k). At a
        // strict local maximum the denominator is negative and the vertex within ±½.
        let (a, b, c) = (score[k - 2] as f32, s as f32, score[k] as f32);
        let denom = a - 2.0 * b + c;
        let delta = if denom < 0.0 { (0.5 * (a - c) / denom).clamp(-0.5, 0.5) } else { 0.0 };
        let h_px = h0 + ((k as isize - reach) as f32 + delta) * step_h;
        if h_px.abs() > limit {
            continue; // the interpolated peak slipped just past the window's end
        }
        let peak = b - 0.25 * (a - c) * delta;
        let outward_derivative = axis_sign * (samples[k + 1] as i16 - samples[k - 1] as i16);
        let sign = if outward_derivative >= 0 { 1.0 } else { -1.0 };
        let at = |offset: isize| samples[(k as isize + offset) as usize] as u32;
        let inside = (at(2 * inward) + at(3 * inward)).div_ceil(2) as u8;
        let outside = (at(-2 * inward) + at(-3 * inward)).div_ceil(2) as u8;
        out.candidates[kept] = Candidate { h_px, contrast: sign * peak, inside, outside, penalty_px: 0.0 };
        kept += 1;
    }
    out.count = kept as u8;
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
}
