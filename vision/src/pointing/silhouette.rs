//! The pointing arm in one view: what changed against the scene before it came (image
//! differencing, as for the gripper), and the axis of that silhouette with its tip end.
//!
//! The finger, the hand and the forearm share one axis, so the midline of the silhouette is
//! the image of the finger's line. The midline is measured across the silhouette (the middle
//! of each cross-section perpendicular to its principal direction) rather than taken as the
//! principal axis, so a wide hand on a narrow finger, or a forearm cut by the image border,
//! does not tilt it; cross-sections that touch the border, or whose middle lies far off the
//! line (a hole where the arm passes over something of its own grey), are left out of the
//! final fit. A silhouette with no axis (a blob: the hand from the front, the sleeve lost
//! against the scene) gets the finger's own, found as a part of its own (`finger.rs`).
//!
//! Nothing is allocated per frame once the buffers have grown to the image size.

use super::finger::FingerFinder;
use super::line_fit::{robust_fit, LineFit};
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
    /// A cross-section's end on a background edge stronger than this (grey levels across
    /// 4 px) may be where something in front hides the arm: the section is left out.
    pub occluder_edge: u8,
    /// A cross-section counts only if the sections within 3 px of it along the arm have its
    /// width within this, pixels (away from the steps between finger, hand and forearm).
    pub max_width_step_px: f64,
}

impl Default for SilhouetteConfig {
    fn default() -> Self {
        Self { min_difference: 18, min_neighbours: 4, min_pixels: 300, min_elongation: 1.5, occluder_edge: 20, max_width_step_px: 1.5 }
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
    /// Centroid of the changed pixels (how the whole arm moves), pixels.
    pub centroid_px: [f64; 2],
    /// The silhouette's own end at the tip: the mean of its changed pixels within 2 px of its
    /// extreme along their principal direction, pixels. Unlike `tip_px` (on the fitted line),
    /// it does not move when the fit changes its mind between the finger's and the whole arm's
    /// midline from one frame to the next: it says whether the hand moved.
    pub end_px: [f64; 2],
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
    #[error("the arm's narrow end runs out of the image ({narrow_px} px wide against {wide_px} px inside): no fingertip in view")]
    NarrowEndOutside { narrow_px: u32, wide_px: u32 },
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
    /// Per section: it reaches within [`TAIL_BORDER_PX`] of the image border.
    near_border: Vec<bool>,
    mids: Vec<[f64; 3]>,
    keep: Vec<bool>,
    /// The narrow end (the fingertip) is at the start of `mids` (lowest s).
    tip_at_start: bool,
    finger: FingerFinder,
    /// The finger part's pixels when the last axis came from it (else empty).
    finger_pixels: Vec<(u16, u16)>,
}

/// Sections on each side of a section that must have its width for it to count, 1 px each.
const STEP_REACH: usize = 3;
/// An end of the silhouette this close to the image border runs out of the image, px. Not
/// only the pixels on it: a sleeve nearly the scene's grey changes only some of its pixels,
/// and which of them reach the border's row differs from frame to frame (point_clutter3
/// seed 64's first gesture: the sleeve's end 0-6 px from the border, and the tip flipped to
/// it whenever none was on it).
const TAIL_BORDER_PX: u16 = 8;

/// The finger alone gives the line when this many of its sections are clean.
const MIN_FINGER_SECTIONS: usize = 15;
/// A finger found as a part of its own ([`FingerFinder`]) is at least this many times longer
/// than wide, and this long, px (a fingertip seen nearly end-on has no line worth fitting).
const FINGER_MIN_ELONGATION: f64 = 1.5;
const FINGER_MIN_LENGTH_PX: f64 = 20.0;
/// A finger seen nearly end-on is a stub: at least as long as it is wide (shorter, its root
/// and tip are not apart and it has no direction at all), and this long, px (two minimum
/// finger widths: the root and the tip at least one width apart).
const STUB_MIN_ELONGATION: f64 = 1.0;
const STUB_MIN_LENGTH_PX: f64 = 12.0;
/// Where a stub's tip is (the mean of its end pixels) is good to about this, px.
const STUB_TIP_SIGMA_PX: f64 = 1.0;

impl SilhouetteFinder {
    pub fn new(config: SilhouetteConfig) -> Self {
        Self { config, ..Self::default() }
    }

    /// Pixels that changed between `background` and `frame` in the last call to
    /// [`Self::find`] (after the neighbour test).
    pub fn changed_pixels(&self) -> usize {
        self.pixels.len()
    }

    /// When the last axis came from the finger found as a part of its own (the whole
    /// silhouette had none), the finger's pixels; else empty. For overlays and diagnosis.
    pub fn finger_part_pixels(&self) -> &[(u16, u16)] {
        &self.finger_pixels
    }

    /// The arm's axis in `frame`, against `background` (the same view before the arm came).
    pub fn find(&mut self, background: &ImageView, frame: &ImageView) -> Result<ArmAxis, SilhouetteError> {
        let (w, h) = (frame.width(), frame.height());
        if background.width() != w || background.height() != h {
            return Err(SilhouetteError::SizeMismatch);
        }
        self.difference(background, frame);
        self.finger_pixels.clear();
        let n = self.pixels.len();
        if n < self.config.min_pixels {
            self.finger.forget();
            return Err(SilhouetteError::NothingThere { pixels: n });
        }
        self.finger.next_frame();
        let (sx, sy) = self.pixels.iter().fold((0.0, 0.0), |(sx, sy), &(x, y)| (sx + f64::from(x), sy + f64::from(y)));
        let centroid_px = [sx / n as f64, sy / n as f64];
        // The whole silhouette's midline; failing that (a blob: the hand seen from the front,
        // its sleeve lost against the scene), the finger's alone, as a part of its own.
        let axis = match self.whole_axis(background) {
            Ok(axis) => axis,
            Err(whole) => match self.finger_axis(background, w, h) {
                Some(axis) => axis,
                None => self.stub_axis(w, h).ok_or(whole)?,
            },
        };
        Ok(ArmAxis { centroid_px, pixels: n, ..axis })
    }

    /// The axis of the whole silhouette (`pixels`), if it is elongated like an arm.
    fn whole_axis(&mut self, background: &ImageView) -> Result<ArmAxis, SilhouetteError> {
        let (c, e, elongation) = principal(&self.pixels).ok_or(SilhouetteError::NotElongated)?;
        if elongation < self.config.min_elongation {
            return Err(SilhouetteError::NotElongated);
        }
        self.axis_along(background, c, e, None)
    }

    /// The axis of the finger found as the silhouette's thin protrusion ([`FingerFinder`]),
    /// measured on the finger's pixels only; `None` if there is no such part or no line on it.
    fn finger_axis(&mut self, background: &ImageView, w: usize, h: usize) -> Option<ArmAxis> {
        let part = self.finger.find(&self.pixels, w, h, FINGER_MIN_ELONGATION, FINGER_MIN_LENGTH_PX, &mut self.finger_pixels)?;
        let Some((c, e, _)) = principal(&self.finger_pixels) else {
            self.finger_pixels.clear();
            return None;
        };
        // Measured on the finger's pixels alone (buffers swapped, not copied).
        std::mem::swap(&mut self.pixels, &mut self.finger_pixels);
        let axis = self.axis_along(background, c, e, Some(part.root_px));
        std::mem::swap(&mut self.pixels, &mut self.finger_pixels);
        if axis.is_err() {
            self.finger_pixels.clear();
        }
        let mut axis = axis.ok()?;
        // A line on a short finger is uncertain in angle beyond its sections' scatter: each end
        // of the measured part is good to about a third of a pixel (the edges' grey, the
        // fingertip's and the knuckles' end faces).
        let length = (axis.tip_px[0] - axis.tail_px[0]).hypot(axis.tip_px[1] - axis.tail_px[1]).max(1.0);
        axis.angle_sigma_rad = axis.angle_sigma_rad.max(0.5 / length);
        axis.offset_sigma_px = axis.offset_sigma_px.max(0.25);
        Some(axis)
    }

    /// A finger seen nearly end-on: a stub too short for a line of sections, found as the
    /// silhouette's protrusion with a lower floor on its shape. Its line runs from where it
    /// joins the hand to its tip, through the tip (what is well located); the root is known
    /// only to about half the finger's width (it is where the knuckles' outline meets the
    /// finger's), so the angle's sigma is large and the caller's propagation decides whether
    /// it matters: it turns the line about the tip, and where a view sees the finger end-on its
    /// ray through the tip nearly meets the indicated point, which the turn then hardly moves.
    /// `sections` is 0: the axis has no line of sections, only a tip and a direction.
    fn stub_axis(&mut self, w: usize, h: usize) -> Option<ArmAxis> {
        let part = self.finger.find(&self.pixels, w, h, STUB_MIN_ELONGATION, STUB_MIN_LENGTH_PX, &mut self.finger_pixels)?;
        // Its direction: from the root through its centroid. A stub about as wide as long has
        // no reliable principal direction, and the extreme along a wrong one is a corner of
        // its end face, not the tip.
        let n = self.finger_pixels.len() as f64;
        let (sx, sy) = self.finger_pixels.iter().fold((0.0, 0.0), |(sx, sy), &(x, y)| (sx + f64::from(x), sy + f64::from(y)));
        let c = [sx / n.max(1.0), sy / n.max(1.0)];
        let to_c = [c[0] - part.root_px[0], c[1] - part.root_px[1]];
        let norm = to_c[0].hypot(to_c[1]);
        if norm < 1e-9 {
            self.finger_pixels.clear();
            return None;
        }
        let dir = [to_c[0] / norm, to_c[1] / norm];
        // The tip: the middle of its end face, away from the root.
        std::mem::swap(&mut self.pixels, &mut self.finger_pixels);
        let tip = self.extreme_px(c, dir, false);
        std::mem::swap(&mut self.pixels, &mut self.finger_pixels);
        let length = (tip[0] - part.root_px[0]).hypot(tip[1] - part.root_px[1]);
        let line = if length >= 0.5 * STUB_MIN_LENGTH_PX { ImageLine::along(&tip, &dir).ok() } else { None };
        let Some(line) = line else {
            self.finger_pixels.clear();
            return None;
        };
        let root_sigma_px = 0.5 * part.width_px;
        Some(ArmAxis {
            line,
            tip_px: tip,
            tail_px: part.root_px,
            centre_px: tip,
            centroid_px: c,
            end_px: tip,
            pixels: self.pixels.len(),
            sections: 0,
            angle_sigma_rad: (root_sigma_px.hypot(STUB_TIP_SIGMA_PX) / length).atan(),
            offset_sigma_px: STUB_TIP_SIGMA_PX,
        })
    }

    /// The midline of `pixels` measured in cross-sections across `e` (unit) through `c`, fitted
    /// three times (each time across the line the last fit found). The tip is the narrow end,
    /// or with `root_px` (where a finger part joins the hand) the end away from it.
    fn axis_along(&mut self, background: &ImageView, c: [f64; 2], e: [f64; 2], root_px: Option<[f64; 2]>) -> Result<ArmAxis, SilhouetteError> {
        // Sections across the principal direction first, then again across the line that
        // fit found (a short, cut-off silhouette's principal direction can be well off).
        let (c0, e0) = (c, e);
        let (mut c, mut e) = (c, e);
        let mut fit = self.fit_sections(background, c, e)?;
        for _ in 0..2 {
            let n = [-e[1], e[0]];
            let centre = [c[0] + fit.s_mean * e[0] + fit.at(fit.s_mean) * n[0], c[1] + fit.s_mean * e[1] + fit.at(fit.s_mean) * n[1]];
            let d = [e[0] + fit.b * n[0], e[1] + fit.b * n[1]];
            let norm = d[0].hypot(d[1]);
            (c, e) = (centre, [d[0] / norm, d[1] / norm]);
            fit = self.fit_sections(background, c, e)?;
        }
        let ([cx, cy], [ex, ey]) = (c, e);
        let (nx, ny) = (-ey, ex);
        // Back to image coordinates: the point at s = mean s, and the direction.
        let to_image = |s: f64, t: f64| [cx + s * ex + t * nx, cy + s * ey + t * ny];
        let centre_px = to_image(fit.s_mean, fit.at(fit.s_mean));
        let dir = [ex + fit.b * nx, ey + fit.b * ny];
        let line = ImageLine::along(&centre_px, &dir).map_err(|_| SilhouetteError::NotElongated)?;
        // The tip: the narrower end (a finger against a hand and a forearm), or the end away
        // from the finger's root.
        if let Some(root) = root_px {
            let s_root = (root[0] - cx) * ex + (root[1] - cy) * ey;
            self.tip_at_start = s_root > 0.5 * (fit.s_min + fit.s_max);
        } else if let Some(tail_at_start) = self.border_end() {
            // An arm that runs out of the image at one end has its tail there: it belongs to
            // someone outside. Where its ends are as wide (a finger cut by the border, the hand
            // out of view), the width rule flipped the tip between the fingertip and the border
            // from frame to frame on noise, and the hand never held "still" (point_clutter3
            // seed 57): the border decides. Where the end that runs out is clearly the narrower
            // (a forearm under a hand seen from the back, wider than it), the finger is not
            // resolved at the other end, and the midline is the hand's, not the finger's (on
            // point_clutter3 seed 60's second gesture such a line pointed 130 mm off): no line
            // from the whole silhouette; the finger as a part of its own may still give one.
            let [first, last] = self.end_widths_px();
            let (narrow, wide) = if tail_at_start { (first, last) } else { (last, first) };
            if narrow + 2.0 * self.config.max_width_step_px < wide {
                return Err(SilhouetteError::NarrowEndOutside { narrow_px: narrow.round() as u32, wide_px: wide.round() as u32 });
            }
            self.tip_at_start = !tail_at_start;
        }
        let tip_at_start = self.tip_at_start;
        // The tip lies at the silhouette's last section at that end (the measured sections
        // stop short of it, at the fingertip's end face).
        let offset = self.lo.len() as f64 / 2.0;
        let (s_tip, s_tail) = match (tip_at_start, self.filled_bins()) {
            (true, Some((first, _))) => (first as f64 - offset, fit.s_max),
            (false, Some((_, last))) => (last as f64 - offset, fit.s_min),
            (true, None) => (fit.s_min, fit.s_max),
            (false, None) => (fit.s_max, fit.s_min),
        };
        // The silhouette's end along the pixels' own principal direction, not the fitted
        // line's: a fingertip's end face is blunt, and where the fit turned a few degrees
        // between the finger's and the whole arm's midline from frame to frame, the extreme
        // along the fit jumped between the face's corners (8-10 px on point_clutter3 seed 31's
        // first gesture, which never held "still").
        let same_way = e0[0] * ex + e0[1] * ey >= 0.0;
        let end_px = self.extreme_px(c0, e0, tip_at_start == same_way);
        Ok(ArmAxis {
            end_px,
            line,
            tip_px: to_image(s_tip, fit.at(s_tip)),
            tail_px: to_image(s_tail, fit.at(s_tail)),
            centre_px,
            centroid_px: centre_px,
            pixels: self.pixels.len(),
            sections: fit.count,
            angle_sigma_rad: fit.b_sigma,
            offset_sigma_px: fit.a_sigma,
        })
    }

    /// The mean of the changed pixels within 2 px of the silhouette's extreme along `e`
    /// (unit) through `c`: at its lowest end along `e` when `at_start`, else its highest.
    fn extreme_px(&self, c: [f64; 2], e: [f64; 2], at_start: bool) -> [f64; 2] {
        let sign = if at_start { -1.0 } else { 1.0 };
        let along = |&(x, y): &(u16, u16)| sign * ((f64::from(x) - c[0]) * e[0] + (f64::from(y) - c[1]) * e[1]);
        let far = self.pixels.iter().map(along).fold(f64::NEG_INFINITY, f64::max);
        let (mut sx, mut sy, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for p in self.pixels.iter().filter(|p| along(p) >= far - 2.0) {
            sx += f64::from(p.0);
            sy += f64::from(p.1);
            n += 1.0;
        }
        [sx / n.max(1.0), sy / n.max(1.0)]
    }

    /// Cross-sections of the silhouette perpendicular to direction `e` (unit) through `c`,
    /// the clean ones' middles in `mids` (s along `e`, t across, width), and the robust line
    /// `t(s)` through them.
    fn fit_sections(&mut self, background: &ImageView, c: [f64; 2], e: [f64; 2]) -> Result<LineFit, SilhouetteError> {
        let (w, h) = (background.width(), background.height());
        let ([cx, cy], [ex, ey]) = (c, e);
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
        self.near_border.clear();
        self.near_border.resize(span, false);
        let m = TAIL_BORDER_PX;
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
                if x < m || y < m || usize::from(x) + usize::from(m) >= w || usize::from(y) + usize::from(m) >= h {
                    self.near_border[s] = true;
                }
            }
        }
        // The midpoints (s, middle t, width) of sections away from the border; `keep` marks
        // (for now) those with an end on a scene edge.
        self.mids.clear();
        self.keep.clear();
        for s in 0..span {
            // A section next to one touching the border may be cut too.
            let near_border = self.border[s.saturating_sub(2)..(s + 3).min(span)].iter().any(|&b| b);
            if self.lo[s].is_finite() && !near_border {
                let (lo, hi) = (f64::from(self.lo[s]), f64::from(self.hi[s]));
                // An end of the section on an edge of the scene before the arm came: something
                // in front of the arm may hide it there (the robot), so its middle is not the
                // arm's.
                let along = s as f64 - offset;
                let on_scene_edge = |t: f64, out: f64| {
                    let at = |t: f64| sample(background, cx + along * ex + t * nx, cy + along * ey + t * ny);
                    match (at(t + out * 2.5), at(t - out * 1.5)) {
                        (Some(a), Some(b)) => (a - b).abs() > f64::from(self.config.occluder_edge),
                        _ => true,
                    }
                };
                self.mids.push([along, 0.5 * (lo + hi), hi - lo + 1.0]);
                self.keep.push(on_scene_edge(lo, -1.0) || on_scene_edge(hi, 1.0));
            }
        }
        self.drop_cut_sections();
        // Keep sections inside a part of even width (finger, hand, forearm): where the width
        // steps (the knuckles, the wrist, the fingertip's end face), the silhouette's edges are
        // the images of end faces seen at a slant, and their middle is off the axis.
        let k = STEP_REACH;
        self.keep.clear();
        for i in 0..self.mids.len() {
            let ok = i >= k
                && i + k < self.mids.len()
                && self.mids[i + k][0] - self.mids[i - k][0] <= 2.0 * k as f64 + 0.5
                && (i - k..=i + k).all(|j| (self.mids[j][2] - self.mids[i][2]).abs() <= self.config.max_width_step_px);
            self.keep.push(ok);
        }
        let mut n_keep = 0;
        for i in 0..self.mids.len() {
            if self.keep[i] {
                self.mids[n_keep] = self.mids[i];
                n_keep += 1;
            }
        }
        self.mids.truncate(n_keep);
        if self.mids.len() < 10 {
            return Err(SilhouetteError::TooFewSections { sections: self.mids.len() });
        }
        // The whole arm's midline, and the finger's alone: the finger's when they disagree
        // (a hand or forearm seen at a slant, cut by the border or partly hidden, has a
        // middle off the axis), the whole arm's (longer, so surer) when they agree.
        let all = robust_fit(&self.mids);
        let fit = match self.finger_sections() {
            Some(range) => {
                let finger = robust_fit(&self.mids[range]);
                let turn = (all.b - finger.b).abs();
                let shift = (all.at(finger.s_mean) - finger.a).abs();
                if turn <= 3.0 * finger.b_sigma + 2e-3 && shift <= 3.0 * finger.a_sigma + 0.5 { all } else { finger }
            }
            None => all,
        };
        if fit.count < 10 {
            return Err(SilhouetteError::TooFewSections { sections: fit.count });
        }
        Ok(fit)
    }

    /// Drops the sections (marked in `keep`) with an end on a scene edge that are narrower
    /// than the nearest clean sections beside them. An edge in the scene (the robot's base)
    /// may be an occluder cutting the arm there, which shortens the section and moves its
    /// middle; but an arm in front of the edge keeps its width, and dropping all such
    /// sections loses a finger that crosses the base. A marked section with no clean
    /// neighbour is dropped: nothing says it is whole.
    fn drop_cut_sections(&mut self) {
        let n = self.mids.len();
        let step = self.config.max_width_step_px;
        // Which sections stay, decided on the sections as they are: compacting `mids` while
        // deciding would shift the neighbours a later section is compared with.
        let mut next_clean = vec![None; n];
        let mut clean = None;
        for i in (0..n).rev() {
            next_clean[i] = clean;
            if !self.keep[i] {
                clean = Some(self.mids[i][2]);
            }
        }
        let mut previous_clean: Option<f64> = None;
        let mut out = 0;
        for i in 0..n {
            let width = self.mids[i][2];
            let whole = !self.keep[i] || {
                let narrowest = match (previous_clean, next_clean[i]) {
                    (Some(a), Some(b)) => Some(a.min(b)),
                    (a, b) => a.or(b),
                };
                narrowest.is_some_and(|w| width >= w - step)
            };
            if !self.keep[i] {
                previous_clean = Some(width);
            }
            if whole {
                self.mids[out] = self.mids[i];
                out += 1;
            }
        }
        self.mids.truncate(out);
        self.keep.clear();
    }

    /// The finger's sections (a range of `mids`): the run of narrow sections at the narrow
    /// end, when there are enough of them. Also decides which end is the tip. The finger is
    /// the part that points, and the part least often cut by the image border or hidden
    /// behind the robot.
    fn finger_sections(&mut self) -> Option<std::ops::Range<usize>> {
        let n = self.mids.len();
        let [first, last] = self.end_widths_px();
        self.tip_at_start = first <= last;
        let limit = first.min(last) * 1.5 + 2.0;
        let run = |order: &mut dyn Iterator<Item = &[f64; 3]>| {
            let mut count = 0;
            let mut prev: Option<f64> = None;
            for m in order {
                if m[2] > limit || prev.is_some_and(|p| (m[0] - p).abs() > 8.0) {
                    break;
                }
                prev = Some(m[0]);
                count += 1;
            }
            count
        };
        let count = if self.tip_at_start { run(&mut self.mids.iter()) } else { run(&mut self.mids.iter().rev()) };
        (count >= MIN_FINGER_SECTIONS && count < n).then(|| if self.tip_at_start { 0..count } else { n - count..n })
    }

    /// The mean widths of the last fit's (`mids`) five sections at its start and at its end, px.
    fn end_widths_px(&self) -> [f64; 2] {
        let mean = |it: &mut dyn Iterator<Item = &[f64; 3]>| {
            let (sum, count) = it.take(5).fold((0.0f64, 0.0f64), |(s, c), m| (s + m[2], c + 1.0));
            sum / count.max(1.0)
        };
        [mean(&mut self.mids.iter()), mean(&mut self.mids.iter().rev())]
    }

    /// The first and the last cross-section bin of the last sections that hold a pixel.
    fn filled_bins(&self) -> Option<(usize, usize)> {
        let filled = |i: &usize| self.lo[*i].is_finite();
        Some(((0..self.lo.len()).find(filled)?, (0..self.lo.len()).rev().find(filled)?))
    }

    /// The end at which the last sections ([`Self::fit_sections`]) run out of the image
    /// (`Some(true)`: their start, lowest s), when only one end does: reach within
    /// [`TAIL_BORDER_PX`] of the border in the outer quarter of the silhouette's extent along
    /// them.
    fn border_end(&self) -> Option<bool> {
        let (first, last) = self.filled_bins()?;
        let reach = (last - first) / 4;
        let touches = |range: std::ops::RangeInclusive<usize>| self.near_border[range].iter().any(|&b| b);
        match (touches(first..=first + reach), touches(last - reach..=last)) {
            (true, false) => Some(true),
            (false, true) => Some(false),
            _ => None,
        }
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

/// The grey at the nearest pixel to `(x, y)`, if inside the image.
fn sample(img: &ImageView, x: f64, y: f64) -> Option<f64> {
    let (xi, yi) = (x.round(), y.round());
    (xi >= 0.0 && yi >= 0.0 && (xi as usize) < img.width() && (yi as usize) < img.height()).then(|| f64::from(img.get(xi as usize, yi as usize)))
}

/// The centroid, the principal direction (unit) and the elongation (the ratio of the second
/// moments' square roots) of `pixels`; `None` for a degenerate set.
fn principal(pixels: &[(u16, u16)]) -> Option<([f64; 2], [f64; 2], f64)> {
    let n = pixels.len() as f64;
    let (sx, sy) = pixels.iter().fold((0.0, 0.0), |(sx, sy), &(x, y)| (sx + f64::from(x), sy + f64::from(y)));
    let (cx, cy) = (sx / n, sy / n);
    let (mut cxx, mut cxy, mut cyy) = (0.0, 0.0, 0.0);
    for &(x, y) in pixels {
        let (dx, dy) = (f64::from(x) - cx, f64::from(y) - cy);
        cxx += dx * dx;
        cxy += dx * dy;
        cyy += dy * dy;
    }
    let half_diff = 0.5 * (cxx - cyy);
    let root = (half_diff * half_diff + cxy * cxy).sqrt();
    let (l1, l2) = (0.5 * (cxx + cyy) + root, 0.5 * (cxx + cyy) - root);
    if pixels.is_empty() || l2 <= 0.0 {
        return None;
    }
    let theta = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
    Some(([cx, cy], [theta.cos(), theta.sin()], (l1 / l2).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_section_on_a_scene_edge_is_judged_against_its_own_clean_neighbours() {
        // Widths along the arm; `true`: an end on a scene edge. Section 1 is cut (narrower
        // than its clean neighbours 0 and 2) and goes. Section 4 is as wide as the clean
        // section 2 before it and stays, though the wide marked section 3 sits between them;
        // compacting while deciding once compared it with section 3's width (10) instead.
        let widths = [(10.0, false), (1.0, true), (3.0, false), (10.0, true), (3.5, true), (10.0, false)];
        let mut finder = SilhouetteFinder::new(SilhouetteConfig::default());
        finder.mids = widths.iter().enumerate().map(|(i, &(w, _))| [i as f64, 0.0, w]).collect();
        finder.keep = widths.iter().map(|&(_, marked)| marked).collect();
        finder.drop_cut_sections();
        let kept: Vec<f64> = finder.mids.iter().map(|m| m[0]).collect();
        assert_eq!(kept, [0.0, 2.0, 3.0, 4.0, 5.0]);
    }
}
