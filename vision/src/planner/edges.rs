//! Edge detection with sub-pixel localisation (Canny-style).
//!
//! Stages, all in integer arithmetic on whole rows so the compiler vectorises them:
//! 1. Smoothing by a separable 5-tap binomial kernel `[1 4 6 4 1]/16` (σ ≈ 1 px), kept at
//!    4 extra bits of precision (values ×16) so the gradient of weak edges is not quantised away.
//! 2. Sobel gradient (`i16`) and squared magnitude (`i32`).
//! 3. Non-maximum suppression along the dominant gradient axis (horizontal when `|gx| ≥ |gy|`,
//!    else vertical) with a parabolic fit of the magnitude through the three samples for the
//!    sub-pixel peak, after Devernay (1995): comparing along the pixel axes rather than the
//!    quantised gradient direction gives unbiased sub-pixel positions at every orientation.
//! 4. Hysteresis: weak maxima survive when 8-connected to a strong one.
//!
//! Corners and junctions are rounded by any isotropic smoothing; rather than smoothing
//! anisotropically (as the thesis suggests), the planner restores them exactly by intersecting
//! the fitted lines (see `relations`), which is cheaper and more precise.
//!
//! The detector owns its scratch buffers: after the first image of a size, a call allocates
//! nothing, and only the entries touched by the previous call are cleared.
//!
//! ```
//! use handeye_vision::image::ImageBuf;
//! use handeye_vision::planner::edges::{EdgeConfig, EdgeDetector};
//! // A vertical step edge between columns 9 and 10: pixel x covers [x, x+1), so the
//! // boundary is at x = 10.0.
//! let mut img = ImageBuf::filled(20, 12, 50);
//! for y in 0..12 { for x in 10..20 { img.set(x, y, 150); } }
//! let mut det = EdgeDetector::new(EdgeConfig::default());
//! let edges = det.detect(&img.view());
//! let p = edges.points.iter().find(|p| p.y == 6.5).unwrap();
//! assert!((p.x - 10.0).abs() < 0.05);
//! ```

use crate::cpu::has_avx2;
use crate::image::ImageView;

/// Thresholds on the gradient magnitude, in grey levels per pixel (of the smoothed image).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgeConfig {
    /// Maxima below this are never edges.
    pub low_grad: f32,
    /// Maxima above this seed edges; weaker ones survive only when connected to a seed.
    pub high_grad: f32,
    /// When set, both thresholds come down (never up) to this many sigmas of the image's own
    /// gradient noise, measured on each image (the median gradient magnitude: most pixels
    /// are flat; σ_grad ≈ 0.14 σ of the pixels' noise), keeping their ratio: a quiet image
    /// shows its fainter edges (at σ 0.5 a pixel the high threshold is 1.1 rather than 3.0
    /// grey levels a pixel), while at the noise the thresholds were tuned on (σ 1.5, where
    /// `high_grad` is ~14 of these sigmas) and above they are the tuned ones. Pure noise
    /// gives no edge at 7 sigmas; 16 keeps the tuned scenes as they were (a lower setting
    /// cost the planner_sim dark-table population 1.2 points of found rate).
    pub noise_sigmas: Option<f32>,
}

impl Default for EdgeConfig {
    fn default() -> Self {
        Self { low_grad: 1.5, high_grad: 3.0, noise_sigmas: Some(16.0) }
    }
}

/// One edge element: sub-pixel position and the gradient there, grey levels per pixel,
/// pointing from dark to bright. Positions are continuous image coordinates in which pixel
/// `(i, j)` covers `[i, i+1) x [j, j+1)` (its centre is at `(i + 0.5, j + 0.5)`), the
/// convention of rasterisers and of the simulator's ground truth.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EdgePoint {
    pub x: f32,
    pub y: f32,
    pub gx: f32,
    pub gy: f32,
}

/// Edge points of one image, with a per-pixel index for neighbour lookups.
#[derive(Debug, Clone, Default)]
pub struct EdgeMap {
    pub width: usize,
    pub height: usize,
    pub points: Vec<EdgePoint>,
    /// Per pixel (row-major, `width` per row): index into `points`, or [`EdgeMap::NONE`].
    pub index: Vec<u32>,
    /// Pixel index of each point (to clear `index` cheaply on the next call).
    pub pixel: Vec<u32>,
}

impl EdgeMap {
    pub const NONE: u32 = u32::MAX;

    /// The point at pixel `(x, y)`, if any.
    #[inline]
    pub fn at(&self, x: usize, y: usize) -> Option<&EdgePoint> {
        let i = self.index[y * self.width + x];
        (i != Self::NONE).then(|| &self.points[i as usize])
    }
}

/// A reusable Canny-style detector (see the module docs).
#[derive(Debug, Clone)]
pub struct EdgeDetector {
    pub config: EdgeConfig,
    tmp: Vec<u16>,
    smooth: Vec<u16>,
    gx: Vec<i16>,
    gy: Vec<i16>,
    mag2: Vec<i32>,
    flags: Vec<i32>,
    /// 0 none, 1 weak maximum, 2 strong (or connected to strong).
    class: Vec<u8>,
    candidates: Vec<(u32, EdgePoint)>,
    stack: Vec<u32>,
    /// Sampled squared gradient magnitudes, for the noise estimate.
    samples: Vec<i32>,
    /// The thresholds of the last image (`low`, `high`), grey levels per pixel.
    thresholds: (f32, f32),
    /// The gradient noise sigma measured on the last image, grey levels per pixel.
    noise_grad: f32,
    map: EdgeMap,
    /// Whether the integer stages run in the AVX2 build of their code (same results, the
    /// processor permitting; see `front_end`).
    use_avx2: bool,
}

/// Sobel responses on the ×16 smoothed image are `128×` the gradient in grey levels per pixel.
const SOBEL_SCALE: f32 = 128.0;

/// The least gradient noise sigma that scales the thresholds, grey levels per pixel (pixel
/// noise σ ~0.25): below it the image is noise-free (synthetic) and keeps the tuned ones.
const MIN_NOISE_GRAD: f32 = 0.035;

impl EdgeDetector {
    pub fn new(config: EdgeConfig) -> Self {
        Self {
            config,
            tmp: Vec::new(),
            smooth: Vec::new(),
            gx: Vec::new(),
            gy: Vec::new(),
            mag2: Vec::new(),
            flags: Vec::new(),
            class: Vec::new(),
            candidates: Vec::new(),
            stack: Vec::new(),
            samples: Vec::new(),
            thresholds: (config.low_grad, config.high_grad),
            noise_grad: 0.0,
            map: EdgeMap::default(),
            use_avx2: has_avx2(),
        }
    }

    /// The result of the last [`detect`](Self::detect).
    pub fn edges(&self) -> &EdgeMap {
        &self.map
    }

    /// The thresholds the last [`detect`](Self::detect) used, `(low, high)`, grey levels per
    /// pixel, and the gradient noise sigma it measured.
    pub fn last_thresholds(&self) -> ((f32, f32), f32) {
        (self.thresholds, self.noise_grad)
    }

    /// Detects the edges of `img`. Images smaller than 5x5 give no edges.
    pub fn detect(&mut self, img: &ImageView) -> &EdgeMap {
        let (w, h) = (img.width(), img.height());
        self.resize(w, h);
        if w < 5 || h < 5 {
            return &self.map;
        }
        #[cfg(target_arch = "x86_64")]
        if self.use_avx2 {
            // SAFETY: `use_avx2` is only true when the processor has AVX2.
            unsafe { self.front_end_avx2(img) };
        } else {
            self.front_end(img);
        }
        #[cfg(not(target_arch = "x86_64"))]
        self.front_end(img);
        self.hysteresis(w, h);
        &self.map
    }

    fn resize(&mut self, w: usize, h: usize) {
        let n = w * h;
        if self.map.width != w || self.map.height != h || self.map.index.len() != n {
            self.tmp = vec![0; n];
            self.smooth = vec![0; n];
            self.gx = vec![0; n];
            self.gy = vec![0; n];
            self.mag2 = vec![0; n];
            self.flags = vec![0; w];
            self.class = vec![0; n];
            self.map.index = vec![EdgeMap::NONE; n];
            self.map.width = w;
            self.map.height = h;
        } else {
            // Clear only what the last call set.
            for &(i, _) in &self.candidates {
                self.class[i as usize] = 0;
            }
            for &i in &self.map.pixel {
                self.map.index[i as usize] = EdgeMap::NONE;
            }
        }
        self.candidates.clear();
        self.map.points.clear();
        self.map.pixel.clear();
    }

    /// Smoothing, gradient and non-maximum suppression: whole-row integer loops that the
    /// compiler vectorises, SSE2 on baseline x86-64. The AVX2 build of the same code doubles
    /// the lanes; integer arithmetic and the same scalar refinement give identical edges.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn front_end_avx2(&mut self, img: &ImageView) {
        self.front_end(img);
    }

    #[inline(always)]
    fn front_end(&mut self, img: &ImageView) {
        self.smooth_image(img);
        self.gradient_and_suppress(img.width(), img.height());
    }

    #[inline(always)]
    fn smooth_image(&mut self, img: &ImageView) {
        let (w, h) = (img.width(), img.height());
        // Horizontal [1 4 6 4 1] → u16 (≤ 16·255).
        for y in 0..h {
            let r = img.row(y);
            let t = &mut self.tmp[y * w..(y + 1) * w];
            let px = |x: isize| r[x.clamp(0, w as isize - 1) as usize] as u16;
            for x in [0usize, 1, w - 2, w - 1] {
                let xi = x as isize;
                t[x] = px(xi - 2) + 4 * px(xi - 1) + 6 * px(xi) + 4 * px(xi + 1) + px(xi + 2);
            }
            let out = &mut t[2..w - 2];
            let (a, b, c, d, e) = (&r[0..w - 4], &r[1..w - 3], &r[2..w - 2], &r[3..w - 1], &r[4..w]);
            for i in 0..out.len() {
                out[i] = a[i] as u16 + 4 * b[i] as u16 + 6 * c[i] as u16 + 4 * d[i] as u16 + e[i] as u16;
            }
        }
        // Vertical [1 4 6 4 1], then /16: result is 16× the smoothed grey level (≤ 4080).
        for y in 0..h {
            let row = |k: isize| {
                let yy = (y as isize + k).clamp(0, h as isize - 1) as usize;
                &self.tmp[yy * w..(yy + 1) * w]
            };
            let (a, b, c, d, e) = (row(-2), row(-1), row(0), row(1), row(2));
            let out = &mut self.smooth[y * w..(y + 1) * w];
            for i in 0..w {
                out[i] = (a[i] + 4 * b[i] + 6 * c[i] + 4 * d[i] + e[i] + 8) >> 4;
            }
        }
    }

    /// Sobel gradient row by row, with non-maximum suppression of the previous row done
    /// right after (its three magnitude rows are still in cache).
    #[inline(always)]
    fn gradient_and_suppress(&mut self, w: usize, h: usize) {
        // Borders (first/last row and column) have no gradient.
        self.gx[..w].fill(0);
        self.gy[..w].fill(0);
        self.mag2[..w].fill(0);
        self.gx[(h - 1) * w..].fill(0);
        self.gy[(h - 1) * w..].fill(0);
        self.mag2[(h - 1) * w..].fill(0);
        for y in 1..h - 1 {
            self.gradient_row(w, y);
        }
        self.set_thresholds(w, h);
        // Rows < 2 and >= h − 2 are border.
        for y in 2..h - 2 {
            self.suppress_row(w, y);
        }
    }

    /// The thresholds for this image (see [`EdgeConfig::noise_sigmas`]): the gradient noise
    /// sigma from the median squared magnitude of every 7th interior pixel (for Rayleigh-
    /// distributed magnitudes the median is 1.177 σ).
    fn set_thresholds(&mut self, w: usize, h: usize) {
        let (low, high) = (self.config.low_grad, self.config.high_grad);
        self.thresholds = (low, high);
        self.noise_grad = 0.0;
        let Some(k) = self.config.noise_sigmas else { return };
        self.samples.clear();
        self.samples.extend(self.mag2[w..(h - 1) * w].iter().step_by(7).copied());
        if self.samples.is_empty() {
            return;
        }
        let mid = self.samples.len() / 2;
        let (_, &mut median, _) = self.samples.select_nth_unstable(mid);
        self.noise_grad = (median.max(0) as f32).sqrt() / SOBEL_SCALE / 1.1774;
        let adaptive = k * self.noise_grad;
        // No noise measured (a synthetic, noise-free image): nothing to scale by.
        if self.noise_grad >= MIN_NOISE_GRAD && adaptive < high && high > 0.0 {
            let high_now = adaptive;
            self.thresholds = (low * high_now / high, high_now);
        }
    }

    #[inline(always)]
    fn gradient_row(&mut self, w: usize, y: usize) {
        let up = &self.smooth[(y - 1) * w..y * w];
        let mid = &self.smooth[y * w..(y + 1) * w];
        let dn = &self.smooth[(y + 1) * w..(y + 2) * w];
        let gx = &mut self.gx[y * w..(y + 1) * w];
        let gy = &mut self.gy[y * w..(y + 1) * w];
        let m2 = &mut self.mag2[y * w..(y + 1) * w];
        gx[0] = 0;
        gy[0] = 0;
        m2[0] = 0;
        gx[w - 1] = 0;
        gy[w - 1] = 0;
        m2[w - 1] = 0;
        let n = w - 2;
        let (ul, uc, ur) = (&up[0..n], &up[1..n + 1], &up[2..n + 2]);
        let (ml, mr) = (&mid[0..n], &mid[2..n + 2]);
        let (dl, dc, dr) = (&dn[0..n], &dn[1..n + 1], &dn[2..n + 2]);
        let (gxo, gyo, m2o) = (&mut gx[1..n + 1], &mut gy[1..n + 1], &mut m2[1..n + 1]);
        for i in 0..n {
            let sx = (ur[i] as i16 - ul[i] as i16) + 2 * (mr[i] as i16 - ml[i] as i16) + (dr[i] as i16 - dl[i] as i16);
            let sy = (dl[i] as i16 + 2 * dc[i] as i16 + dr[i] as i16) - (ul[i] as i16 + 2 * uc[i] as i16 + ur[i] as i16);
            gxo[i] = sx;
            gyo[i] = sy;
            // ≤ 2·16320² < 2³¹: fits i32, which keeps the comparisons below vectorisable.
            m2o[i] = sx as i32 * sx as i32 + sy as i32 * sy as i32;
        }
    }

    /// Non-maximum suppression of row `y` (2 ≤ y < h − 2): a branch-free pass marks the
    /// maxima above the low threshold, then only those are refined.
    #[inline(always)]
    fn suppress_row(&mut self, w: usize, y: usize) {
        let low = (self.thresholds.0 * SOBEL_SCALE).max(1.0);
        let high = (self.thresholds.1 * SOBEL_SCALE).max(low);
        let low2 = (low * low) as i32;
        let high2 = (high * high) as i32;
        let inv = 1.0 / SOBEL_SCALE;
        let base = y * w;
        let up = &self.mag2[base - w..base];
        let row = &self.mag2[base..base + w];
        let dn = &self.mag2[base + w..base + 2 * w];
        let (gxr, gyr) = (&self.gx[base..base + w], &self.gy[base..base + w]);
        // Columns 2..w−2 (the 2-pixel border has incomplete gradients).
        let n = w - 4;
        let flags = &mut self.flags[..n];
        {
            let (l, c, r) = (&row[1..n + 1], &row[2..n + 2], &row[3..n + 3]);
            let (u, d) = (&up[2..n + 2], &dn[2..n + 2]);
            let (sx, sy) = (&gxr[2..n + 2], &gyr[2..n + 2]);
            // Written with masks rather than branches so it compiles to SIMD even on baseline
            // x86-64 (SSE2).
            for i in 0..n {
                let (ax, ay) = ((sx[i] as i32).abs(), (sy[i] as i32).abs());
                let hm = -((ax >= ay) as i32);
                let a = (l[i] & hm) | (u[i] & !hm);
                let b = (r[i] & hm) | (d[i] & !hm);
                let m = c[i];
                // Strict on one side, non-strict on the other: a plateau yields one maximum.
                flags[i] = -((m >= low2) as i32) & -((m > a) as i32) & -((m >= b) as i32);
            }
        }
        const CHUNK: usize = 16;
        let mut x0 = 0;
        while x0 < n {
            let x1 = (x0 + CHUNK).min(n);
            if flags[x0..x1].iter().fold(0, |a, &f| a | f) == 0 {
                x0 = x1;
                continue;
            }
            for k in x0..x1 {
                if flags[k] == 0 {
                    continue;
                }
                let x = k + 2;
                let i = base + x;
                let (sx, sy) = (gxr[x], gyr[x]);
                let m = row[x];
                let horizontal = sx.unsigned_abs() >= sy.unsigned_abs();
                let (ma, mb) = if horizontal { (row[x - 1], row[x + 1]) } else { (up[x], dn[x]) };
                let (a, b, c) = ((ma as f32).sqrt(), (m as f32).sqrt(), (mb as f32).sqrt());
                let den = a - 2.0 * b + c;
                let off = if den < 0.0 { (0.5 * (a - c) / den).clamp(-0.5, 0.5) } else { 0.0 };
                let (px, py) = if horizontal { (x as f32 + 0.5 + off, y as f32 + 0.5) } else { (x as f32 + 0.5, y as f32 + 0.5 + off) };
                self.class[i] = if m >= high2 { 2 } else { 1 };
                self.candidates.push((i as u32, EdgePoint { x: px, y: py, gx: sx as f32 * inv, gy: sy as f32 * inv }));
            }
            x0 = x1;
        }
    }

    fn hysteresis(&mut self, w: usize, _h: usize) {
        self.stack.clear();
        for &(i, _) in &self.candidates {
            if self.class[i as usize] == 2 {
                self.stack.push(i);
            }
        }
        let offsets = [-(w as isize) - 1, -(w as isize), -(w as isize) + 1, -1, 1, w as isize - 1, w as isize, w as isize + 1];
        while let Some(i) = self.stack.pop() {
            for o in offsets {
                // Candidates keep 2 pixels from the border, so neighbours are in range.
                let j = (i as isize + o) as usize;
                if self.class[j] == 1 {
                    self.class[j] = 2;
                    self.stack.push(j as u32);
                }
            }
        }
        for &(i, p) in &self.candidates {
            if self.class[i as usize] == 2 {
                self.map.index[i as usize] = self.map.points.len() as u32;
                self.map.points.push(p);
                self.map.pixel.push(i);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::synth::Canvas;

    /// Distance from (x, y) to the line through `a` with unit normal `n`.
    fn line_dist(p: &EdgePoint, a: [f64; 2], n: [f64; 2]) -> f64 {
        ((p.x as f64 - a[0]) * n[0] + (p.y as f64 - a[1]) * n[1]).abs()
    }

    #[test]
    fn sub_pixel_accuracy_on_a_rotated_square() {
        let c = [100.3, 80.7];
        let (s, co) = (0.37f64.sin(), 0.37f64.cos());
        let half = 40.0;
        let corners: Vec<[f64; 2]> = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]
            .iter()
            .map(|d| [c[0] + half * (d[0] * co - d[1] * s), c[1] + half * (d[0] * s + d[1] * co)])
            .collect();
        let mut canvas = Canvas::new(200, 160, 60.0);
        canvas.fill_polygon(&corners, 160.0);
        let img = canvas.to_image(0.0, 0);
        let mut det = EdgeDetector::new(EdgeConfig::default());
        let edges = det.detect(&img.view()).clone();
        let mut errs = Vec::new();
        for p in &edges.points {
            // Distance to each side; skip points within 4 px of a corner (rounded there).
            let q = [p.x as f64, p.y as f64];
            if corners.iter().any(|k| (k[0] - q[0]).hypot(k[1] - q[1]) < 4.0) {
                continue;
            }
            let mut best = f64::INFINITY;
            for i in 0..4 {
                let (a, b) = (corners[i], corners[(i + 1) % 4]);
                let d = [b[0] - a[0], b[1] - a[1]];
                let l = d[0].hypot(d[1]);
                let n = [-d[1] / l, d[0] / l];
                let ep = EdgePoint { x: q[0] as f32, y: q[1] as f32, gx: 0.0, gy: 0.0 };
                best = best.min(line_dist(&ep, a, n));
            }
            errs.push(best);
        }
        // Perimeter 320 px: one point per row or column crossed along each side.
        assert!(errs.len() > 250, "only {} edge points", errs.len());
        let max = errs.iter().cloned().fold(0.0, f64::max);
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        assert!(max < 0.15 && mean < 0.05, "sub-pixel error mean {mean:.3} max {max:.3}");
        // Gradients point from dark (outside) to bright (inside): towards the centre.
        for p in &edges.points {
            let to_c = [c[0] - p.x as f64, c[1] - p.y as f64];
            assert!(to_c[0] * p.gx as f64 + to_c[1] * p.gy as f64 > 0.0);
        }
    }

    #[test]
    fn noise_below_threshold_gives_no_edges_and_weak_edges_need_a_strong_neighbour() {
        let flat = Canvas::new(64, 48, 100.0).to_image(2.0, 3);
        let mut det = EdgeDetector::new(EdgeConfig::default());
        assert_eq!(det.detect(&flat.view()).points.len(), 0, "σ=2 noise must not make edges");
        // A faint step (contrast 9: peak gradient 9 x 5/16 = 2.8 grey/px, between low and
        // high) is dropped alone, but kept when it continues a strong step.
        let mut faint = Canvas::new(64, 48, 100.0);
        faint.fill_polygon(&[[32.0, 0.0], [64.0, 0.0], [64.0, 48.0], [32.0, 48.0]], 109.0);
        assert_eq!(det.detect(&faint.to_image(0.0, 0).view()).points.len(), 0);
        let mut mixed = faint.clone();
        mixed.fill_polygon(&[[32.0, 0.0], [64.0, 0.0], [64.0, 20.0], [32.0, 20.0]], 160.0);
        let n = det.detect(&mixed.to_image(0.0, 0).view()).points.iter().filter(|p| (p.x - 32.0).abs() < 0.5 && p.y > 26.0).count();
        assert!(n > 15, "faint continuation kept by hysteresis: {n}");
    }

    #[test]
    fn reuse_clears_previous_results() {
        let mut a = Canvas::new(40, 30, 50.0);
        a.fill_polygon(&[[10.0, 5.0], [30.0, 5.0], [30.0, 25.0], [10.0, 25.0]], 200.0);
        let mut det = EdgeDetector::new(EdgeConfig::default());
        let first = det.detect(&a.to_image(0.0, 0).view()).points.len();
        assert!(first > 40);
        let blank = Canvas::new(40, 30, 50.0).to_image(0.0, 0);
        let map = det.detect(&blank.view());
        assert_eq!(map.points.len(), 0);
        assert!(map.index.iter().all(|&i| i == EdgeMap::NONE));
    }

    /// The AVX2 build of the integer stages finds exactly the edges the baseline build finds
    /// (a vectorisation that rounded or saturated differently would move or drop edges).
    #[test]
    fn avx2_and_baseline_builds_find_identical_edges() {
        if !has_avx2() {
            eprintln!("no AVX2 on this processor: nothing to compare");
            return;
        }
        let mut rng = crate::rng::SplitMix64::new(0x9e37_79b9_7f4a_7c15);
        let mut c = Canvas::new(203, 157, 90.0);
        for _ in 0..40 {
            let (x, y) = (rng.range(0.0, 203.0), rng.range(0.0, 157.0));
            let (a, r) = (rng.range(0.0, 6.3), rng.range(4.0, 34.0));
            let p: Vec<[f64; 2]> = (0..4).map(|k| {
                let t = a + k as f64 * 1.7;
                [x + r * t.cos(), y + r * (1.3 * t).sin()]
            }).collect();
            c.fill_polygon(&p, rng.range(0.0, 255.0) as f32);
        }
        let img = c.to_image(6.0, 3);
        let mut fast = EdgeDetector::new(EdgeConfig::default());
        let mut base = EdgeDetector::new(EdgeConfig::default());
        base.use_avx2 = false;
        let (a, b) = (fast.detect(&img.view()).clone(), base.detect(&img.view()).clone());
        assert!(a.points.len() > 500, "{} edge points: the scene should be busy", a.points.len());
        assert_eq!(a.pixel, b.pixel);
        let bits = |m: &EdgeMap| m.points.iter().map(|p| [p.x, p.y, p.gx, p.gy].map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b));
    }

    /// A 40 px vertical step of `step` grey levels on 60, pixel noise `sigma`: how many
    /// edge points lie within 1 px of it, and how many elsewhere.
    fn faint_step(step: f64, sigma: f64, config: EdgeConfig) -> (usize, usize, ((f32, f32), f32)) {
        let mut rng = crate::rng::SplitMix64::new(5);
        let mut img = crate::image::ImageBuf::filled(120, 80, 60);
        for y in 0..80 {
            for x in 0..120 {
                let on = (20..60).contains(&y) && x >= 60;
                let v = 60.0 + if on { step } else { 0.0 } + sigma * rng.normal();
                img.set(x, y, v.round().clamp(0.0, 255.0) as u8);
            }
        }
        let mut det = EdgeDetector::new(config);
        let edges = det.detect(&img.view());
        let on = edges.points.iter().filter(|p| (p.x - 60.0).abs() < 1.0 && (22.0..58.0).contains(&p.y)).count();
        // Elsewhere: off the rectangle's outline (its left side, and its top and bottom).
        let near_outline = |p: &&EdgePoint| ((p.x - 60.0).abs() < 1.5 && (18.0..62.0).contains(&p.y)) || (((p.y - 20.0).abs() < 1.5 || (p.y - 60.0).abs() < 1.5) && p.x > 58.0);
        let off = edges.points.iter().filter(|p| !near_outline(p)).count();
        (on, off, det.last_thresholds())
    }

    #[test]
    fn a_quiet_image_shows_its_faint_edges_and_a_noisy_one_keeps_the_tuned_thresholds() {
        // A 4-grey-level step at σ 0.5: under the tuned 3.0 grey levels a pixel once smoothed
        // (~1.6), found at the image's own noise.
        let fixed = EdgeConfig { noise_sigmas: None, ..EdgeConfig::default() };
        let (on, _, _) = faint_step(4.0, 0.5, fixed);
        assert!(on < 10, "the tuned thresholds miss it: {on}");
        let (on, off, (th, noise)) = faint_step(4.0, 0.5, EdgeConfig::default());
        assert!(on >= 30, "found along its 40 px: {on} (thresholds {th:?}, noise {noise})");
        assert!(off <= 4, "and little else: {off}");
        // At σ 1.5 and above, the tuned thresholds.
        let (_, _, (th, _)) = faint_step(12.0, 1.5, EdgeConfig::default());
        assert_eq!(th, (1.5, 3.0));
    }
}
