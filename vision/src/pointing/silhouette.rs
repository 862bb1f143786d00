//! The pointing arm in one view: what changed against the scene before it came (image
//! differencing, as for the gripper), and the axis of that silhouette with its tip end.
//!
//! The finger, the hand and the forearm share one axis, so the midline of the silhouette is
//! the image of the finger's line. The midline is measured across the silhouette (the middle
//! of each cross-section perpendicular to its principal direction) rather than taken as the
//! principal axis, so a wide hand on a narrow finger, or a forearm cut by the image border,
//! does not tilt it; cross-sections that touch the border, or whose middle lies far off the
//! line (a hole where the arm passes over something of its own grey), are left out of the
//! final fit.
//!
//! Nothing is allocated per frame once the buffers have grown to the image size.

use super::geometry::ImageLine;
use crate::image::ImageView;

/// Tuning of the silhouette and its axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SilhouetteConfig {
    /// A pixel belongs to the arm when it differs from the background by more than this,
    /// grey levels (sensor noise is a few).
    pub min_difference: u8,
    /// ... and at least this many of its 8 neighbours do too (drops isolated noise).
    pub min_neighbours: u8,
    /// Fewer changed pixels than this: no arm in view.
    pub min_pixels: usize,
    /// The silhouette must be at least this many times longer than wide to have an axis.
    pub min_elongation: f64,
}

impl Default for SilhouetteConfig {
    fn default() -> Self {
        Self { min_difference: 18, min_neighbours: 4, min_pixels: 300, min_elongation: 2.5 }
    }
}

/// The arm's axis in one view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArmAxis {
    /// The axis line (the finger's line), pixels.
    pub line: ImageLine,
    /// The fingertip: the narrow end, on the line, pixels.
    pub tip_px: [f64; 2],
    /// The other end of the measured part (the forearm, or where the border cuts it).
    pub tail_px: [f64; 2],
    /// Where the fitted midline passes closest to the cross-sections' centroid, pixels.
    pub centre_px: [f64; 2],
    /// Changed pixels in the silhouette.
    pub pixels: usize,
    /// Cross-sections used in the final fit.
    pub sections: usize,
    /// Standard error of the line's angle (rad) and of its offset at `centre_px` (px).
    pub angle_sigma_rad: f64,
    pub offset_sigma_px: f64,
}

/// Why no axis was found in a view.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SilhouetteError {
    #[error("nothing changed against the background ({pixels} pixels)")]
    NothingThere { pixels: usize },
    #[error("the background and the frame differ in size")]
    SizeMismatch,
    #[error("the changed region is not elongated like an arm")]
    NotElongated,
    #[error("too few clean cross-sections across the arm ({sections})")]
    TooFewSections { sections: usize },
}

/// Reusable buffers for finding the arm's axis in one view.
#[derive(Debug, Clone, Default)]
pub struct SilhouetteFinder {
    pub config: SilhouetteConfig,
    changed: Vec<u8>,
    pixels: Vec<(u16, u16)>,
    /// Per cross-section (1 px bins along the principal direction): min t, max t, touches the
    /// border.
    lo: Vec<f32>,
    hi: Vec<f32>,
    border: Vec<bool>,
    mids: Vec<[f64; 3]>,
}

impl SilhouetteFinder {
    pub fn new(config: SilhouetteConfig) -> Self {
        Self { config, ..Self::default() }
    }

    /// Pixels that changed between `background` and `frame` in the last call to
    /// [`Self::find`] (after the neighbour test).
    pub fn changed_pixels(&self) -> usize {
        self.pixels.len()
    }

    /// The arm's axis in `frame`, against `background` (the same view before the arm came).
    pub fn find(&mut self, background: &ImageView, frame: &ImageView) -> Result<ArmAxis, SilhouetteError> {
        let (w, h) = (frame.width(), frame.height());
        if background.width() != w || background.height() != h {
            return Err(SilhouetteError::SizeMismatch);
        }
        self.difference(background, frame);
        let n = self.pixels.len();
        if n < self.config.min_pixels {
            return Err(SilhouetteError::NothingThere { pixels: n });
        }
        // Principal direction of the changed pixels.
        let (mut sx, mut sy) = (0.0, 0.0);
        for &(x, y) in &self.pixels {
            sx += f64::from(x);
            sy += f64::from(y);
        }
        let (cx, cy) = (sx / n as f64, sy / n as f64);
        let (mut cxx, mut cxy, mut cyy) = (0.0, 0.0, 0.0);
        for &(x, y) in &self.pixels {
            let (dx, dy) = (f64::from(x) - cx, f64::from(y) - cy);
            cxx += dx * dx;
            cxy += dx * dy;
            cyy += dy * dy;
        }
        let half_diff = 0.5 * (cxx - cyy);
        let root = (half_diff * half_diff + cxy * cxy).sqrt();
        let (l1, l2) = (0.5 * (cxx + cyy) + root, 0.5 * (cxx + cyy) - root);
        if l2 <= 0.0 || (l1 / l2).sqrt() < self.config.min_elongation {
            return Err(SilhouetteError::NotElongated);
        }
        let theta = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
        let (ex, ey) = (theta.cos(), theta.sin());
        let (nx, ny) = (-ey, ex);

        // Cross-sections: extent across the principal direction per 1 px of length.
        let span = (w as f64).hypot(h as f64).ceil() as usize + 2;
        let offset = span as f64 / 2.0;
        self.lo.clear();
        self.lo.resize(span, f32::INFINITY);
        self.hi.clear();
        self.hi.resize(span, f32::NEG_INFINITY);
        self.border.clear();
        self.border.resize(span, false);
        for &(x, y) in &self.pixels {
            let (dx, dy) = (f64::from(x) - cx, f64::from(y) - cy);
            let s = ((dx * ex + dy * ey) + offset).round() as usize;
            let t = (dx * nx + dy * ny) as f32;
            if s < span {
                self.lo[s] = self.lo[s].min(t);
                self.hi[s] = self.hi[s].max(t);
                if x <= 1 || y <= 1 || usize::from(x) + 2 >= w || usize::from(y) + 2 >= h {
                    self.border[s] = true;
                }
            }
        }
        // The midpoints (s, middle t, width) of clean sections.
        self.mids.clear();
        for s in 0..span {
            // A section next to one touching the border may be cut too.
            let near_border = self.border[s.saturating_sub(2)..(s + 3).min(span)].iter().any(|&b| b);
            if self.lo[s].is_finite() && !near_border {
                let (lo, hi) = (f64::from(self.lo[s]), f64::from(self.hi[s]));
                self.mids.push([s as f64 - offset, 0.5 * (lo + hi), hi - lo + 1.0]);
            }
        }
        if self.mids.len() < 10 {
            return Err(SilhouetteError::TooFewSections { sections: self.mids.len() });
        }
        // Robust straight-line fit t = a + b s to the midpoints: least squares, then again
        // without the sections more than 3 robust sigmas (at least 1 px) off the line.
        let mut fit = fit_line(&self.mids, |_| true);
        for _ in 0..3 {
            let mut dev: f64 = 0.0;
            let mut count = 0.0;
            for m in &self.mids {
                dev += (m[1] - fit.at(m[0])).abs();
                count += 1.0;
            }
            let limit = (3.0 * 1.25 * dev / count).max(1.0);
            fit = fit_line(&self.mids, |m| (m[1] - fit.at(m[0])).abs() <= limit);
        }
        if fit.count < 10 {
            return Err(SilhouetteError::TooFewSections { sections: fit.count });
        }
        // Back to image coordinates: the point at s = mean s, and the direction.
        let to_image = |s: f64, t: f64| [cx + s * ex + t * nx, cy + s * ey + t * ny];
        let centre_px = to_image(fit.s_mean, fit.at(fit.s_mean));
        let dir = [ex + fit.b * nx, ey + fit.b * ny];
        let line = ImageLine::along(&centre_px, &dir).map_err(|_| SilhouetteError::NotElongated)?;
        // The tip: the narrower end (a finger against a hand and a forearm).
        let tenth = (fit.count / 10).max(3);
        let on_line = |m: &&[f64; 3]| (m[1] - fit.at(m[0])).abs() <= fit.limit;
        let first: f64 = self.mids.iter().filter(on_line).take(tenth).map(|m| m[2]).sum();
        let last: f64 = self.mids.iter().rev().filter(on_line).take(tenth).map(|m| m[2]).sum();
        let tip_at_start = first <= last;
        let (s_tip, s_tail) = if tip_at_start { (fit.s_min, fit.s_max) } else { (fit.s_max, fit.s_min) };
        Ok(ArmAxis {
            line,
            tip_px: to_image(s_tip, fit.at(s_tip)),
            tail_px: to_image(s_tail, fit.at(s_tail)),
            centre_px,
            pixels: n,
            sections: fit.count,
            angle_sigma_rad: fit.b_sigma,
            offset_sigma_px: fit.a_sigma,
        })
    }

    /// Fills `pixels` with the changed pixels that have enough changed neighbours.
    fn difference(&mut self, background: &ImageView, frame: &ImageView) {
        let (w, h) = (frame.width(), frame.height());
        self.changed.clear();
        self.changed.resize(w * h, 0);
        let t = self.config.min_difference;
        for y in 0..h {
            let (a, b) = (background.row(y), frame.row(y));
            let out = &mut self.changed[y * w..(y + 1) * w];
            for x in 0..w {
                out[x] = u8::from(a[x].abs_diff(b[x]) > t);
            }
        }
        self.pixels.clear();
        let need = self.config.min_neighbours;
        for y in 1..h.saturating_sub(1) {
            for x in 1..w.saturating_sub(1) {
                if self.changed[y * w + x] == 0 {
                    continue;
                }
                let row = |yy: usize| &self.changed[yy * w + x - 1..yy * w + x + 2];
                let around: u8 = row(y - 1).iter().sum::<u8>() + row(y + 1).iter().sum::<u8>() + self.changed[y * w + x - 1] + self.changed[y * w + x + 1];
                if around >= need {
                    self.pixels.push((x as u16, y as u16));
                }
            }
        }
    }
}

/// `t = a + b (s - s_mean)` fitted to the selected midpoints, with its standard errors.
#[derive(Debug, Clone, Copy)]
struct LineFit {
    a: f64,
    b: f64,
    s_mean: f64,
    s_min: f64,
    s_max: f64,
    count: usize,
    a_sigma: f64,
    b_sigma: f64,
    /// The selection limit the next pass uses for "on the line" (3 sigmas, at least 1 px).
    limit: f64,
}

impl LineFit {
    fn at(&self, s: f64) -> f64 {
        self.a + self.b * (s - self.s_mean)
    }
}

fn fit_line(mids: &[[f64; 3]], keep: impl Fn(&[f64; 3]) -> bool) -> LineFit {
    let (mut n, mut ss, mut st) = (0.0f64, 0.0f64, 0.0f64);
    let (mut s_min, mut s_max) = (f64::INFINITY, f64::NEG_INFINITY);
    for m in mids.iter().filter(|m| keep(m)) {
        n += 1.0;
        ss += m[0];
        st += m[1];
        s_min = s_min.min(m[0]);
        s_max = s_max.max(m[0]);
    }
    let (s_mean, t_mean) = (ss / n.max(1.0), st / n.max(1.0));
    let (mut sss, mut sst) = (0.0, 0.0);
    for m in mids.iter().filter(|m| keep(m)) {
        sss += (m[0] - s_mean).powi(2);
        sst += (m[0] - s_mean) * (m[1] - t_mean);
    }
    let b = if sss > 0.0 { sst / sss } else { 0.0 };
    let mut rss = 0.0;
    for m in mids.iter().filter(|m| keep(m)) {
        rss += (m[1] - t_mean - b * (m[0] - s_mean)).powi(2);
    }
    // Neighbouring sections share pixels' noise: count them as half as many independent ones.
    let sigma = (rss / (n - 2.0).max(1.0)).sqrt() * std::f64::consts::SQRT_2;
    LineFit {
        a: t_mean,
        b,
        s_mean,
        s_min,
        s_max,
        count: n as usize,
        a_sigma: sigma / n.max(1.0).sqrt(),
        b_sigma: sigma / sss.max(1e-9).sqrt(),
        limit: (3.0 * sigma).max(1.0),
    }
}
