//! Locating the gripper by frame differencing (METHOD.md §3, "Locating the gripper"): with
//! the arm still, one frame with the jaws open and one with them closed; what changed between
//! them is the fingers. Threshold the absolute difference above the sensor noise, clean it
//! with a morphological opening and closing, label the connected regions, drop the ones of
//! implausible size, and suggest where to put the gripper-face template: the centre and
//! principal axis of all moving pixels (for a parallel gripper, the axis is the jaw axis).
//!
//! Runs once per acquisition, not in the hard loop: it allocates its working images.

use thiserror::Error;

use crate::image::ImageView;
use crate::moments::Moments;

/// Why no gripper was located.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum LocateError {
    #[error("the two frames differ in size ({a_width}x{a_height} vs {b_width}x{b_height})")]
    SizeMismatch { a_width: usize, a_height: usize, b_width: usize, b_height: usize },
    #[error("nothing moved above threshold {threshold} (grey levels): did the jaws open and close in view?")]
    NoMotion { threshold: u8 },
    #[error("{percent:.0}% of the image changed: the camera or the lighting moved, not just the jaws")]
    TooMuchMotion { percent: f64 },
    #[error("locate config: {field} is out of range")]
    Config { field: &'static str },
}

/// Tuning of [`locate_moving`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocateConfig {
    /// A pixel moved when its difference exceeds this many noise sigmas (the noise of the
    /// difference image, estimated from its median)...
    pub noise_sigmas: f64,
    /// ...and at least this many grey levels.
    pub min_threshold: u8,
    /// Regions smaller than this (pixels, after cleaning) are noise.
    pub min_area_px: usize,
    /// Regions larger than this fraction of the image are not fingers.
    pub max_area_fraction: f64,
    /// More than this fraction of the image changed by more than `min_threshold`: the whole
    /// view changed.
    pub max_changed_fraction: f64,
    /// When nothing moved above the threshold, the difference is looked at again averaged
    /// over 3 x 3 pixels (a third of the noise) at this many of its own noise sigmas (measured
    /// the same way), at least `faint_min_threshold` grey levels: dark fingers over a dark
    /// table change the image by a few grey levels, under the 12 that the plain difference
    /// needs, yet over a finger's whole area.
    pub faint_noise_sigmas: f64,
    pub faint_min_threshold: f64,
}

impl Default for LocateConfig {
    fn default() -> Self {
        Self {
            noise_sigmas: 5.0,
            min_threshold: 12,
            min_area_px: 20,
            max_area_fraction: 0.05,
            max_changed_fraction: 0.25,
            faint_noise_sigmas: 4.0,
            faint_min_threshold: 2.0,
        }
    }
}

/// One connected region of change, pixel coordinates (pixel centres at integers).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Blob {
    pub area_px: usize,
    /// Inclusive bounds `[x0, y0, x1, y1]`.
    pub bbox: [usize; 4],
    pub centroid_px: [f64; 2],
    /// Direction of the principal axis, radians in `(−π/2, π/2]`, from `+u` towards `+v`.
    pub axis_rad: f64,
    /// Extent along and across the axis, `4σ` of the pixel distribution, pixels.
    pub length_px: f64,
    pub width_px: f64,
}

/// Where to place the gripper-face template in this view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Placement {
    pub centre_px: [f64; 2],
    /// The moving pixels' principal axis (the jaw axis), radians in `(−π/2, π/2]`.
    pub axis_rad: f64,
    /// Extent along and across the axis, `4σ` of all moving pixels, pixels.
    pub length_px: f64,
    pub width_px: f64,
}

/// What moved in the image between the two frames (not a robot motion: pixels).
#[derive(Debug, Clone, PartialEq)]
pub struct ImageMotion {
    /// Kept regions, largest first.
    pub blobs: Vec<Blob>,
    pub placement: Placement,
    /// The threshold used, grey levels.
    pub threshold: u8,
    /// Estimated noise sigma of the difference image, grey levels.
    pub noise_sigma: f64,
    /// Regions dropped as too small or too large.
    pub dropped: usize,
}

impl Moments {
    /// Centre, axis angle, and 4σ extents along and across the axis.
    fn shape(&self) -> ([f64; 2], f64, f64, f64) {
        let ([mx, my], cxx, cxy, cyy) = self.central();
        let angle = 0.5 * (2.0 * cxy).atan2(cxx - cyy);
        let mean = 0.5 * (cxx + cyy);
        let half_diff = (0.25 * (cxx - cyy).powi(2) + cxy * cxy).sqrt();
        let (l1, l2) = ((mean + half_diff).max(0.0), (mean - half_diff).max(0.0));
        let axis = if angle <= -std::f64::consts::FRAC_PI_2 { angle + std::f64::consts::PI } else { angle };
        ([mx, my], axis, 4.0 * l1.sqrt(), 4.0 * l2.sqrt())
    }
}

/// 3x3 binary erosion (`grow = false`) or dilation (`grow = true`), separable; pixels
/// outside the image count as background.
fn morph(src: &[bool], dst: &mut [bool], tmp: &mut [bool], w: usize, h: usize, grow: bool) {
    let pick = |a: bool, b: bool| if grow { a || b } else { a && b };
    for y in 0..h {
        let row = &src[y * w..(y + 1) * w];
        for x in 0..w {
            let mut v = row[x];
            v = pick(v, if x > 0 { row[x - 1] } else { false });
            v = pick(v, if x + 1 < w { row[x + 1] } else { false });
            tmp[y * w + x] = v;
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut v = tmp[y * w + x];
            v = pick(v, if y > 0 { tmp[(y - 1) * w + x] } else { false });
            v = pick(v, if y + 1 < h { tmp[(y + 1) * w + x] } else { false });
            dst[y * w + x] = v;
        }
    }
}

/// Finds what moved between `open` and `closed` (any order) and where the gripper template
/// should go.
pub fn locate_moving(open: &ImageView<'_>, closed: &ImageView<'_>, config: &LocateConfig) -> Result<ImageMotion, LocateError> {
    if !(config.noise_sigmas > 0.0 && config.noise_sigmas.is_finite()) {
        return Err(LocateError::Config { field: "noise_sigmas" });
    }
    if !(config.max_area_fraction > 0.0 && config.max_area_fraction <= 1.0) {
        return Err(LocateError::Config { field: "max_area_fraction" });
    }
    if !(config.max_changed_fraction > 0.0 && config.max_changed_fraction <= 1.0) {
        return Err(LocateError::Config { field: "max_changed_fraction" });
    }
    let (w, h) = (open.width(), open.height());
    if (w, h) != (closed.width(), closed.height()) {
        return Err(LocateError::SizeMismatch { a_width: w, a_height: h, b_width: closed.width(), b_height: closed.height() });
    }
    let n = w * h;
    let mut diff = vec![0u8; n];
    let mut histogram = [0usize; 256];
    for y in 0..h {
        for ((d, a), b) in diff[y * w..(y + 1) * w].iter_mut().zip(open.row(y)).zip(closed.row(y)) {
            *d = a.abs_diff(*b);
            histogram[*d as usize] += 1;
        }
    }
    // The median absolute difference is noise as long as less than half the image moved:
    // for Gaussian noise it is 0.674 σ of the difference.
    let mut seen = 0;
    let median = (0..256).find(|&v| {
        seen += histogram[v];
        2 * seen >= n
    });
    let noise_sigma = median.unwrap_or(0) as f64 / 0.6745;
    let threshold = (config.noise_sigmas * noise_sigma).ceil().clamp(config.min_threshold as f64, 254.0) as u8;
    // Judged at the fixed floor: the adaptive threshold would rise with a global change and
    // hide it.
    let changed: usize = histogram[config.min_threshold as usize + 1..].iter().sum();
    if changed as f64 > config.max_changed_fraction * n as f64 {
        return Err(LocateError::TooMuchMotion { percent: 100.0 * changed as f64 / n as f64 });
    }

    let mut mask: Vec<bool> = diff.iter().map(|&d| d > threshold).collect();
    let (mut blobs, mut all, mut dropped) = regions(&mut mask, w, h, config);
    let (mut threshold, mut noise_sigma) = (threshold, noise_sigma);
    if blobs.is_empty() {
        // Faint motion: the signed difference averaged over 3 x 3 pixels, at 4x its grey
        // levels to keep fractions, thresholded at its own measured noise. Each pixel's
        // difference is clipped to the plain threshold first: a change that large and this
        // small in extent is speckle (the plain pass would have found a finger), and must not
        // grow into a 3 x 3 blob.
        const SCALE: f64 = 4.0;
        let clip = i32::from(threshold);
        let signed = |x: usize, y: usize| (i32::from(open.row(y)[x]) - i32::from(closed.row(y)[x])).clamp(-clip, clip);
        let mut smooth = vec![0u8; n];
        let mut hist = [0usize; 256];
        for y in 1..h.saturating_sub(1) {
            for x in 1..w.saturating_sub(1) {
                let mut sum = 0;
                for dy in 0..3 {
                    for dx in 0..3 {
                        sum += signed(x + dx - 1, y + dy - 1);
                    }
                }
                let v = (SCALE * f64::from(sum.abs()) / 9.0).round().min(255.0) as u8;
                smooth[y * w + x] = v;
                hist[v as usize] += 1;
            }
        }
        let inner = (w.saturating_sub(2) * h.saturating_sub(2)).max(1);
        let mut seen = 0;
        let median = (0..256).find(|&v| {
            seen += hist[v];
            2 * seen >= inner
        });
        let sigma = median.unwrap_or(0) as f64 / 0.6745;
        let cut = (config.faint_noise_sigmas * sigma).max(SCALE * config.faint_min_threshold).ceil().min(254.0) as u8;
        let mut faint: Vec<bool> = smooth.iter().map(|&d| d > cut).collect();
        (blobs, all, dropped) = regions(&mut faint, w, h, config);
        if blobs.is_empty() {
            return Err(LocateError::NoMotion { threshold });
        }
        threshold = (f64::from(cut) / SCALE).ceil() as u8;
        noise_sigma = sigma / SCALE;
    }
    blobs.sort_by_key(|b| std::cmp::Reverse(b.area_px));
    let (centre_px, axis_rad, length_px, width_px) = all.shape();
    Ok(ImageMotion { blobs, placement: Placement { centre_px, axis_rad, length_px, width_px }, threshold, noise_sigma, dropped })
}

/// The regions of `mask` (consumed): opened and closed, 8-connected, those of plausible size
/// kept, with the moments of all kept pixels and the count of dropped regions.
fn regions(mask: &mut [bool], w: usize, h: usize, config: &LocateConfig) -> (Vec<Blob>, Moments, usize) {
    let n = w * h;
    // Opening removes speckle and hairlines; closing then mends small gaps in a finger.
    let (mut a, mut tmp) = (vec![false; n], vec![false; n]);
    morph(mask, &mut a, &mut tmp, w, h, false);
    morph(&a, mask, &mut tmp, w, h, true);
    morph(mask, &mut a, &mut tmp, w, h, true);
    morph(&a, mask, &mut tmp, w, h, false);

    // 8-connected regions by flood fill.
    let max_area = (config.max_area_fraction * n as f64) as usize;
    let mut blobs = Vec::new();
    let mut all = Moments::default();
    let mut dropped = 0;
    let mut stack = Vec::new();
    for start in 0..n {
        if !mask[start] {
            continue;
        }
        mask[start] = false;
        stack.push(start);
        let mut m = Moments::default();
        let mut bbox = [usize::MAX, usize::MAX, 0, 0];
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            m.add(x as f64, y as f64);
            bbox = [bbox[0].min(x), bbox[1].min(y), bbox[2].max(x), bbox[3].max(y)];
            for dy in [-1isize, 0, 1] {
                for dx in [-1isize, 0, 1] {
                    let (nx, ny) = (x as isize + dx, y as isize + dy);
                    if nx >= 0 && ny >= 0 && (nx as usize) < w && (ny as usize) < h {
                        let j = ny as usize * w + nx as usize;
                        if mask[j] {
                            mask[j] = false;
                            stack.push(j);
                        }
                    }
                }
            }
        }
        let area_px = m.n as usize;
        if area_px < config.min_area_px || area_px > max_area {
            dropped += 1;
            continue;
        }
        all.merge(&m);
        let (centroid_px, axis_rad, length_px, width_px) = m.shape();
        blobs.push(Blob { area_px, bbox, centroid_px, axis_rad, length_px, width_px });
    }
    (blobs, all, dropped)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::ImageBuf;
    use crate::rng::SplitMix64;

    const W: usize = 640;
    const H: usize = 480;

    /// A cluttered static scene: a gradient and 40 random grey rectangles, away from the
    /// gripper region around (320, 215).
    fn background(rng: &mut SplitMix64) -> ImageBuf {
        let mut img = ImageBuf::new(W, H);
        for y in 0..H {
            for x in 0..W {
                img.set(x, y, (60 + x / 8 + y / 12) as u8);
            }
        }
        for _ in 0..40 {
            let (x0, y0) = (rng.range(0.0, 600.0) as usize, rng.range(0.0, 440.0) as usize);
            let (x1, y1) = ((x0 + rng.range(5.0, 60.0) as usize).min(W), (y0 + rng.range(5.0, 60.0) as usize).min(H));
            if x1 > 240 && x0 < 400 && y1 > 150 && y0 < 280 {
                continue;
            }
            let grey = rng.range(0.0, 255.0) as u8;
            for y in y0..y1 {
                for x in x0..x1 {
                    img.set(x, y, grey);
                }
            }
        }
        img
    }

    /// Fingers: 12 x 30 px rectangles centred at `centres`, turned by `angle` (their length
    /// across the jaw axis), grey 230. Returns the image and the set of finger pixels.
    fn draw_fingers(base: &ImageBuf, centres: &[[f64; 2]], angle: f64) -> (ImageBuf, Vec<bool>) {
        let mut img = base.clone();
        let mut on = vec![false; W * H];
        let (c, s) = (angle.cos(), angle.sin());
        for y in 0..H {
            for x in 0..W {
                for cen in centres {
                    let (dx, dy) = (x as f64 - cen[0], y as f64 - cen[1]);
                    let (along, across) = (c * dx + s * dy, -s * dx + c * dy);
                    if along.abs() < 6.0 && across.abs() < 15.0 {
                        img.set(x, y, 230);
                        on[y * W + x] = true;
                    }
                }
            }
        }
        (img, on)
    }

    fn add_noise(img: &ImageBuf, sigma: f64, rng: &mut SplitMix64) -> ImageBuf {
        let mut out = img.clone();
        for v in out.data.iter_mut() {
            *v = (*v as f64 + sigma * rng.normal()).round().clamp(0.0, 255.0) as u8;
        }
        out
    }

    /// Open and closed frames of a gripper whose jaw axis is at `angle` through (320, 215):
    /// fingers 35 px from the centre when open, 15 px when closed. Also returns where the
    /// frames truly differ (a finger in one frame and not the other).
    fn jaws(angle: f64, sigma: f64, seed: u64) -> (ImageBuf, ImageBuf, Vec<bool>) {
        let mut rng = SplitMix64::new(seed);
        let bg = background(&mut rng);
        let (c, s) = (angle.cos(), angle.sin());
        let at = |r: f64| [[320.0 - r * c, 215.0 - r * s], [320.0 + r * c, 215.0 + r * s]];
        let (open, on_open) = draw_fingers(&bg, &at(35.0), angle);
        let (closed, on_closed) = draw_fingers(&bg, &at(15.0), angle);
        let truth = on_open.iter().zip(&on_closed).map(|(a, b)| a != b).collect();
        (add_noise(&open, sigma, &mut rng), add_noise(&closed, sigma, &mut rng), truth)
    }

    fn truth_shape(truth: &[bool]) -> ([f64; 2], f64, f64, f64) {
        let mut m = Moments::default();
        for (i, _) in truth.iter().enumerate().filter(|(_, t)| **t) {
            m.add((i % W) as f64, (i / W) as f64);
        }
        m.shape()
    }

    #[test]
    fn finds_two_moving_fingers_among_static_clutter_and_noise() {
        for seed in 1..=3 {
            let (open, closed, truth) = jaws(0.0, 2.0, seed);
            let m = locate_moving(&open.view(), &closed.view(), &LocateConfig::default()).unwrap();
            // Each finger leaves two separate 11 x 29 px regions (open and closed positions).
            assert_eq!(m.blobs.len(), 4, "{:?}", m.blobs);
            for b in &m.blobs {
                assert!((b.area_px as i64 - 11 * 29).abs() <= 10, "{b:?}");
                let i = b.centroid_px[1].round() as usize * W + b.centroid_px[0].round() as usize;
                assert!(truth[i], "a blob where nothing moved: {b:?}");
            }
            let (centre, axis, length, _) = truth_shape(&truth);
            let p = m.placement;
            assert!((p.centre_px[0] - centre[0]).abs() < 0.5 && (p.centre_px[1] - centre[1]).abs() < 0.5, "{p:?} vs {centre:?}");
            assert!((p.axis_rad - axis).abs() < 1f64.to_radians() && axis.abs() < 1e-9, "{p:?}");
            assert!((p.length_px - length).abs() < 2.0, "{p:?} vs {length}");
            // The noise estimate matches the sensor: σ 2 per frame is σ 2.8 in the difference
            // (the median of integer differences is coarse, so ±1 grey level).
            assert!((m.noise_sigma - 2.83).abs() < 1.5, "{}", m.noise_sigma);
            assert!(m.threshold >= 12 && m.threshold <= 25, "{}", m.threshold);
        }
    }

    #[test]
    fn dark_fingers_over_a_dark_table_are_found_from_their_faint_change() {
        // Fingers 8 grey levels above a flat dark table (40), σ 1.5 noise a frame: under the
        // plain difference's 12-level floor, found in the 3 x 3 average at its own noise.
        let mut rng = SplitMix64::new(11);
        let mut bg = ImageBuf::new(W, H);
        bg.data.iter_mut().for_each(|v| *v = 40);
        let at = |r: f64| [[320.0 - r, 215.0], [320.0 + r, 215.0]];
        let finger = |img: &ImageBuf| {
            let mut out = img.clone();
            out.data.iter_mut().for_each(|v| *v = if *v == 230 { 48 } else { 40 });
            out
        };
        let (open, on_open) = draw_fingers(&bg, &at(35.0), 0.0);
        let (closed, on_closed) = draw_fingers(&bg, &at(15.0), 0.0);
        let truth: Vec<bool> = on_open.iter().zip(&on_closed).map(|(a, b)| a != b).collect();
        let (open, closed) = (add_noise(&finger(&open), 1.5, &mut rng), add_noise(&finger(&closed), 1.5, &mut rng));
        let m = locate_moving(&open.view(), &closed.view(), &LocateConfig::default()).expect("faint fingers found");
        assert_eq!(m.blobs.len(), 4, "{:?}", m.blobs);
        assert!(m.threshold < 8, "found below the change itself: {}", m.threshold);
        let (centre, ..) = truth_shape(&truth);
        assert!((m.placement.centre_px[0] - centre[0]).abs() < 1.0 && (m.placement.centre_px[1] - centre[1]).abs() < 1.0, "{:?} vs {centre:?}", m.placement);
        // The same noise with nothing moving: still no motion.
        let still = add_noise(&bg, 1.5, &mut rng);
        let still2 = add_noise(&bg, 1.5, &mut rng);
        assert!(matches!(locate_moving(&still.view(), &still2.view(), &LocateConfig::default()), Err(LocateError::NoMotion { .. })));
    }

    #[test]
    fn the_axis_follows_a_turned_gripper() {
        let angle = 30f64.to_radians();
        let (open, closed, truth) = jaws(angle, 2.0, 7);
        let m = locate_moving(&open.view(), &closed.view(), &LocateConfig::default()).unwrap();
        let (centre, ..) = truth_shape(&truth);
        let p = m.placement;
        assert!((p.axis_rad - angle).abs() < 2f64.to_radians(), "{} deg", p.axis_rad.to_degrees());
        assert!((p.centre_px[0] - centre[0]).abs() < 1.0 && (p.centre_px[1] - centre[1]).abs() < 1.0, "{p:?} vs {centre:?}");
        // The order of the frames does not matter.
        let swapped = locate_moving(&closed.view(), &open.view(), &LocateConfig::default()).unwrap();
        assert_eq!(swapped.placement, m.placement);
    }

    #[test]
    fn noise_and_speckle_alone_are_no_motion() {
        let mut rng = SplitMix64::new(3);
        let bg = background(&mut rng);
        let a = add_noise(&bg, 2.0, &mut rng);
        let mut b = add_noise(&bg, 2.0, &mut rng);
        // Salt: 200 isolated bright pixels (dead-pixel flicker).
        for _ in 0..200 {
            let (x, y) = (rng.range(0.0, W as f64) as usize, rng.range(0.0, H as f64) as usize);
            b.set(x, y, 255);
        }
        assert!(matches!(locate_moving(&a.view(), &b.view(), &LocateConfig::default()), Err(LocateError::NoMotion { .. })));
    }

    #[test]
    fn a_global_change_is_not_taken_for_fingers() {
        let (open, mut closed, _) = jaws(0.0, 2.0, 2);
        for v in closed.data.iter_mut() {
            *v = v.saturating_add(40);
        }
        assert!(matches!(locate_moving(&open.view(), &closed.view(), &LocateConfig::default()), Err(LocateError::TooMuchMotion { percent }) if percent > 90.0));
    }

    #[test]
    fn bad_input_is_an_error() {
        let a = ImageBuf::new(10, 10);
        let b = ImageBuf::new(10, 11);
        assert!(matches!(locate_moving(&a.view(), &b.view(), &LocateConfig::default()), Err(LocateError::SizeMismatch { .. })));
        let bad = LocateConfig { noise_sigmas: f64::NAN, ..Default::default() };
        assert_eq!(locate_moving(&a.view(), &a.view(), &bad), Err(LocateError::Config { field: "noise_sigmas" }));
    }
}
