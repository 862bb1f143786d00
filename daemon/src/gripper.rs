//! The gripper as the daemon sees it: the plate model from the configuration in the
//! tracker's template coordinates (marks, reference point, axis), finding the plate in an
//! image once the moving fingers have been located, and turning the plate and target
//! trackers into the servo's [`GripperView`] and [`StereoFrame`].

use handeye_vision::image::ImageView;
use handeye_vision::locate::ImageMotion;
use handeye_vision::servo::{ViewFrame, GripperView, StereoFrame, StereoPoint};
use handeye_vision::tracker::ContourTracker;
use nalgebra::{Vector2, Vector3};

use crate::config::GripperModel;

/// The plate model in the template coordinates of a tracker built from the plate's image
/// polygon (corners in the model's order): `e1` runs from corner 0 to corner 1, `e2` from
/// corner 0 to corner 3, the origin at the centre, so the corners sit at `(±½, ±½)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlateTemplate {
    pub marks_st: [[f64; 2]; 3],
    pub reference_st: [f64; 2],
    /// Template displacement of 1 m along the plate's `a` axis.
    pub a_axis_st: [f64; 2],
    /// Template displacement of 1 m along the plate's `b` axis (up).
    pub b_axis_st: [f64; 2],
}

impl PlateTemplate {
    pub fn new(model: &GripperModel) -> Self {
        let c = model.plate_corners_m;
        let o = [(c[0][0] + c[2][0]) / 2.0, (c[0][1] + c[2][1]) / 2.0];
        let e1 = [c[1][0] - c[0][0], c[1][1] - c[0][1]];
        let e2 = [c[3][0] - c[0][0], c[3][1] - c[0][1]];
        let det = e1[0] * e2[1] - e1[1] * e2[0];
        // (s, t) of a plate displacement d: solve d = s e1 + t e2.
        let dir = |d: [f64; 2]| [(d[0] * e2[1] - d[1] * e2[0]) / det, (e1[0] * d[1] - e1[1] * d[0]) / det];
        let at = |p: [f64; 2]| dir([p[0] - o[0], p[1] - o[1]]);
        Self {
            marks_st: model.marks_m.map(at),
            reference_st: at(model.reference_m),
            a_axis_st: dir([1.0, 0.0]),
            b_axis_st: dir([0.0, 1.0]),
        }
    }
}

/// Unit plate normal in the robot frame at tool yaw `yaw_rad` (horizontal).
pub fn plate_normal(model: &GripperModel, yaw_rad: f64) -> Vector3<f64> {
    let n0 = model.normal_at_zero_yaw;
    let (s, c) = yaw_rad.sin_cos();
    Vector3::new(c * n0[0] - s * n0[1], s * n0[0] + c * n0[1], 0.0).normalize()
}

/// `tool − reference` in the robot frame at tool yaw `yaw_rad`: the lever from the plate's
/// reference point (what the cameras see) to the tool point (what the robot moves).
pub fn tool_from_reference(model: &GripperModel, yaw_rad: f64) -> Vector3<f64> {
    let n = plate_normal(model, yaw_rad);
    let up = Vector3::z();
    let a = up.cross(&n);
    let t = model.tool_from_reference_m;
    a * t[0] + up * t[1] + n * t[2]
}

fn v2(p: [f64; 2]) -> Vector2<f64> {
    Vector2::new(p[0], p[1])
}

fn arr(v: Vector2<f64>) -> [f64; 2] {
    [v.x, v.y]
}

/// Where template point `st` is in the image.
fn at(t: &ContourTracker, st: [f64; 2]) -> [f64; 2] {
    arr(t.image_from_template(v2(st)))
}

/// Image displacement of template direction `d` around `st` (central difference of the
/// placement, so a projective placement gives its local derivative).
fn direction(t: &ContourTracker, st: [f64; 2], d: [f64; 2], scale: f64) -> [f64; 2] {
    let h = [d[0] * scale, d[1] * scale];
    let a = t.image_from_template(Vector2::new(st[0] + h[0], st[1] + h[1]));
    let b = t.image_from_template(Vector2::new(st[0] - h[0], st[1] - h[1]));
    arr((a - b) / (2.0 * scale))
}

/// The servo's view of the gripper from the two plate trackers: marks, reference point and
/// the plate's `a` axis (per metre of plate, in pixels).
pub fn gripper_view(plate: &PlateTemplate, left: &ContourTracker, right: &ContourTracker) -> GripperView {
    let pair = |st: [f64; 2]| StereoPoint { left: at(left, st), right: at(right, st) };
    // Half a centimetre either side keeps the difference inside the plate.
    let scale = 0.005;
    GripperView {
        marks: plate.marks_st.map(pair),
        reference: pair(plate.reference_st),
        axis: StereoPoint {
            left: direction(left, plate.reference_st, plate.a_axis_st, scale),
            right: direction(right, plate.reference_st, plate.a_axis_st, scale),
        },
    }
}

/// A facet's affine frame in one view from its tracker: the least-squares affine map from
/// the template's corners to where the tracker puts them in the image (origin = the image of
/// the template origin). Over the whole outline, this is steadier than the placement's local
/// derivative at the centre, and the plane transfer the servo builds from the two views'
/// frames is extrapolated far (to the gripper plate), so its steadiness is what counts.
/// No allocation (corners are accumulated on the fly).
pub fn facet_frame(t: &ContourTracker) -> ViewFrame {
    // Normal equations of p = o + E q over the corners, centred.
    let (mut n, mut qm, mut pm) = (0.0, Vector2::zeros(), Vector2::zeros());
    for (q, p) in t.template().corners().iter().zip(t.corners()) {
        n += 1.0;
        qm += q;
        pm += p;
    }
    if n < 3.0 {
        return ViewFrame { o: at(t, [0.0, 0.0]), e1: direction(t, [0.0, 0.0], [1.0, 0.0], 0.25), e2: direction(t, [0.0, 0.0], [0.0, 1.0], 0.25) };
    }
    qm /= n;
    pm /= n;
    let (mut qq, mut pq) = (nalgebra::Matrix2::zeros(), nalgebra::Matrix2::zeros());
    for (q, p) in t.template().corners().iter().zip(t.corners()) {
        let (dq, dp) = (q - qm, p - pm);
        qq += dq * dq.transpose();
        pq += dp * dq.transpose();
    }
    let Some(inv) = qq.try_inverse() else {
        return ViewFrame { o: at(t, [0.0, 0.0]), e1: direction(t, [0.0, 0.0], [1.0, 0.0], 0.25), e2: direction(t, [0.0, 0.0], [0.0, 1.0], 0.25) };
    };
    let e = pq * inv;
    let o = pm - e * qm;
    ViewFrame { o: [o.x, o.y], e1: [e[(0, 0)], e[(1, 0)]], e2: [e[(0, 1)], e[(1, 1)]] }
}

/// A facet's frames in both views, in *shared* coordinates: each view's frame is the
/// least-squares affine map from the left template's corners to that view's tracked corners
/// (the hint gives the corners in the same order in both views). Each tracker's own template
/// has its origin at its polygon's perimeter centroid, which is not the same point of the
/// facet in the two views (for a triangle seen from two sides it is off by pixels), and the
/// plane transfer `b = o' − A o` needs the two origins to be one point. Falls back to
/// [`facet_frame`] per view when the corner counts differ. No allocation.
pub fn stereo_frame(left: &ContourTracker, right: &ContourTracker) -> StereoFrame {
    let shared = left.template().corners();
    if shared.len() != right.template().corners().len() {
        return StereoFrame { left: facet_frame(left), right: facet_frame(right) };
    }
    let fit = |t: &ContourTracker| frame_through(shared, || t.corners()).unwrap_or_else(|| facet_frame(t));
    StereoFrame { left: fit(left), right: fit(right) }
}

/// The least-squares affine frame `p = o + E q` through template points `q` and image points
/// `p`, or `None` when the `q` span no plane.
fn frame_through<I: Iterator<Item = Vector2<f64>>>(q: &[Vector2<f64>], p: impl Fn() -> I) -> Option<ViewFrame> {
    let n = q.len() as f64;
    let qm = q.iter().sum::<Vector2<f64>>() / n;
    let pm = p().sum::<Vector2<f64>>() / n;
    let (mut qq, mut pq) = (nalgebra::Matrix2::zeros(), nalgebra::Matrix2::zeros());
    for (q, p) in q.iter().zip(p()) {
        let (dq, dp) = (q - qm, p - pm);
        qq += dq * dq.transpose();
        pq += dp * dq.transpose();
    }
    if n < 3.0 || qq.determinant().abs() <= 1e-12 * qq.norm_squared() {
        return None;
    }
    let e = pq * qq.try_inverse()?;
    let o = pm - e * qm;
    Some(ViewFrame { o: [o.x, o.y], e1: [e[(0, 0)], e[(1, 0)]], e2: [e[(0, 1)], e[(1, 1)]] })
}

/// Why the plate was not found next to the moving fingers.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlateError {
    #[error("no bright plate-shaped region above the moving fingers (window {window:?}, threshold {threshold})")]
    NotFound { window: [usize; 4], threshold: u8 },
    #[error("nothing moved")]
    NoMotion,
}

/// The least image area, px², that a converged plate tracker may have in a view: half of
/// the plate's area as the locator found it in the same view ([`find_plate`]: the plate's
/// measured image size, whatever the focal length and distance), and never under
/// `floor_px2`, the smallest plate a contour tracker can follow. A tracker that shrank
/// below half the plate it started on has collapsed onto something smaller. A fixed area
/// (it was 300 px²) cannot serve: the plate is ~2000 px² at the shipped 1800 px focal
/// length and ~150-250 px² at the randomised cells' 30-50° field of view and 1.9 m.
pub fn least_plate_area_px2(found_px2: f64, floor_px2: f64) -> f64 {
    (0.5 * found_px2).max(floor_px2)
}

/// Finds the plate's light rectangle above the moving fingers in `image` (a frame with the
/// arm still): the largest of [`plate_candidates`]. Allocates: run it off the hard loop.
pub fn find_plate(image: &ImageView<'_>, motion: &ImageMotion) -> Result<[[f64; 2]; 4], PlateError> {
    Ok(plate_candidates(image, motion)?.swap_remove(0))
}

/// A converged plate tracker may be at most this many times larger in one view than in the
/// other: the two views see one plate, turned towards both cameras.
pub const MAX_PLATE_AREA_RATIO: f64 = 1.6;

/// The plate's corners in both views from each view's candidates ([`plate_candidates`],
/// largest first): the largest pair whose areas are within [`MAX_PLATE_AREA_RATIO`] of each
/// other, else the two largest (which the converged trackers' check then refuses). Where a
/// view also sees a larger light face of the gripper's housing (randomised cell 22: its lit
/// top, 1284 px² against the plate's 568 in the other view), the plate is the candidate
/// that matches the other view's plate. The two largest are kept wherever their areas
/// agree, as the locator took them before.
pub fn pair_plates(left: &[[[f64; 2]; 4]], right: &[[[f64; 2]; 4]]) -> Option<[[[f64; 2]; 4]; 2]> {
    let area = |c: &[[f64; 2]; 4]| handeye_vision::planner::geom::area(c);
    let mut best: Option<(f64, [[[f64; 2]; 4]; 2])> = None;
    for l in left {
        for r in right {
            let (al, ar) = (area(l), area(r));
            if al.max(ar) > MAX_PLATE_AREA_RATIO * al.min(ar) {
                continue;
            }
            if best.as_ref().is_none_or(|b| al + ar > b.0) {
                best = Some((al + ar, [*l, *r]));
            }
        }
    }
    best.map(|b| b.1).or_else(|| Some([*left.first()?, *right.first()?]))
}

/// The plate's light rectangle above the moving fingers in `image` (a frame with the arm
/// still), every candidate, largest first: Otsu threshold in a window above the fingers,
/// the bright connected regions that do not touch the window's edge (the plate's dark
/// border encloses its light rectangle), fairly rectangular and above the fingers. Each as
/// its corners, top-left, top-right, bottom-right, bottom-left (the extreme points along the
/// diagonals, pushed half a pixel out to the region's boundary). Allocates: run it off the
/// hard loop.
pub fn plate_candidates(image: &ImageView<'_>, motion: &ImageMotion) -> Result<Vec<[[f64; 2]; 4]>, PlateError> {
    if motion.blobs.is_empty() {
        return Err(PlateError::NoMotion);
    }
    let mut bb = [usize::MAX, usize::MAX, 0, 0];
    for b in &motion.blobs {
        bb = [bb[0].min(b.bbox[0]), bb[1].min(b.bbox[1]), bb[2].max(b.bbox[2]), bb[3].max(b.bbox[3])];
    }
    let (w, h) = (bb[2] - bb[0] + 1, bb[3] - bb[1] + 1);
    let size = w.max(h);
    let x0 = bb[0].saturating_sub(size);
    let x1 = (bb[2] + size).min(image.width() - 1);
    let y0 = bb[1].saturating_sub(size + 40);
    let y1 = (bb[1] + h / 2).min(image.height() - 1);
    let (ww, wh) = (x1 - x0 + 1, y1 - y0 + 1);
    let mut hist = [0usize; 256];
    for y in y0..=y1 {
        for &p in &image.row(y)[x0..=x1] {
            hist[p as usize] += 1;
        }
    }
    let threshold = otsu(&hist);
    let window = [x0, y0, x1, y1];
    // 4-connected regions of bright pixels in the window.
    let mut label = vec![u32::MAX; ww * wh];
    let bright = |x: usize, y: usize| image.get(x0 + x, y0 + y) > threshold;
    let mut found: Vec<(usize, Vec<(usize, usize)>)> = Vec::new();
    let mut stack = Vec::new();
    let blob_cy = motion.placement.centre_px[1];
    for sy in 0..wh {
        for sx in 0..ww {
            if label[sy * ww + sx] != u32::MAX || !bright(sx, sy) {
                continue;
            }
            let mut pixels = Vec::new();
            let mut touches = false;
            label[sy * ww + sx] = 0;
            stack.push((sx, sy));
            while let Some((x, y)) = stack.pop() {
                pixels.push((x, y));
                touches |= x == 0 || y == 0 || x == ww - 1 || y == wh - 1;
                let mut visit = |nx: usize, ny: usize| {
                    if label[ny * ww + nx] == u32::MAX && bright(nx, ny) {
                        label[ny * ww + nx] = 0;
                        stack.push((nx, ny));
                    }
                };
                if x > 0 {
                    visit(x - 1, y);
                }
                if x + 1 < ww {
                    visit(x + 1, y);
                }
                if y > 0 {
                    visit(x, y - 1);
                }
                if y + 1 < wh {
                    visit(x, y + 1);
                }
            }
            if touches || pixels.len() < 60 {
                continue;
            }
            let (mut bx0, mut by0, mut bx1, mut by1) = (usize::MAX, usize::MAX, 0, 0);
            let mut cy = 0.0;
            for &(x, y) in &pixels {
                bx0 = bx0.min(x);
                by0 = by0.min(y);
                bx1 = bx1.max(x);
                by1 = by1.max(y);
                cy += y as f64;
            }
            cy = cy / pixels.len() as f64 + y0 as f64;
            let fill = pixels.len() as f64 / ((bx1 - bx0 + 1) * (by1 - by0 + 1)) as f64;
            if fill < 0.55 || cy > blob_cy {
                continue;
            }
            found.push((pixels.len(), pixels));
        }
    }
    if found.is_empty() {
        return Err(PlateError::NotFound { window, threshold });
    }
    // Largest first; equal sizes keep the scan order.
    found.sort_by_key(|f| std::cmp::Reverse(f.0));
    let corners = |pixels: &[(usize, usize)]| {
        let extreme = |f: &dyn Fn(f64, f64) -> f64| {
            let mut arg = (0.0, 0.0);
            let mut val = f64::NEG_INFINITY;
            for &(x, y) in pixels {
                let (u, v) = ((x0 + x) as f64, (y0 + y) as f64);
                let s = f(u, v);
                if s > val {
                    val = s;
                    arg = (u, v);
                }
            }
            arg
        };
        let tl = extreme(&|u, v| -u - v);
        let tr = extreme(&|u, v| u - v);
        let br = extreme(&|u, v| u + v);
        let bl = extreme(&|u, v| -u + v);
        let out = |p: (f64, f64), su: f64, sv: f64| [p.0 + 0.5 * su, p.1 + 0.5 * sv];
        [out(tl, -1.0, -1.0), out(tr, 1.0, -1.0), out(br, 1.0, 1.0), out(bl, -1.0, 1.0)]
    };
    Ok(found.iter().map(|(_, pixels)| corners(pixels)).collect())
}

/// Otsu's threshold of a grey-level histogram.
fn otsu(hist: &[usize; 256]) -> u8 {
    let total: f64 = hist.iter().sum::<usize>() as f64;
    let sum: f64 = hist.iter().enumerate().map(|(i, &c)| i as f64 * c as f64).sum();
    let (mut w0, mut sum0, mut best, mut best_t) = (0.0, 0.0, -1.0, 0u8);
    for (t, &c) in hist.iter().enumerate() {
        w0 += c as f64;
        sum0 += t as f64 * c as f64;
        let w1 = total - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let (m0, m1) = (sum0 / w0, (sum - sum0) / w1);
        let between = w0 * w1 * (m0 - m1) * (m0 - m1);
        if between > best {
            best = between;
            best_t = t as u8;
        }
    }
    best_t
}

/// Corners of a polygon refined from the tracker's last edges: each inlier edge point is
/// assigned to the nearest side of the tracked outline, a line is fitted to each side (total
/// least squares), and adjacent lines are intersected. A template built from a clicked or
/// coarsely found polygon keeps that polygon's shape errors (an operator's ±3 px on a
/// 30 px facet); refining the corners from the image and restarting the tracker removes
/// them. A side the tracker does not measure ([`ContourTracker::side_measured`]) stays
/// where it is. `None` when a side has too few edges or lines are near parallel. Allocates (once
/// per refinement, while acquiring).
pub fn refine_polygon(t: &ContourTracker) -> Option<Vec<[f64; 2]>> {
    let corners: Vec<Vector2<f64>> = t.corners().collect();
    let k = corners.len();
    if k < 3 {
        return None;
    }
    let mut sides: Vec<Vec<Vector2<f64>>> = vec![Vec::new(); k];
    for e in t.inlier_edges() {
        let mut best = (f64::INFINITY, 0);
        for j in 0..k {
            let (a, b) = (corners[j], corners[(j + 1) % k]);
            let ab = b - a;
            let f = ((e - a).dot(&ab) / ab.norm_squared()).clamp(0.0, 1.0);
            let d = (a + ab * f - e).norm();
            if d < best.0 {
                best = (d, j);
            }
        }
        sides[best.1].push(e);
    }
    // Each side as (point, unit direction); a side the tracker does not measure keeps the
    // line it is placed on.
    let mut lines = Vec::with_capacity(k);
    for (j, pts) in sides.iter().enumerate() {
        if !t.side_measured(j) {
            let (a, b) = (corners[j], corners[(j + 1) % k]);
            lines.push((a, (b - a).normalize()));
            continue;
        }
        if pts.len() < 5 {
            return None;
        }
        let c = pts.iter().sum::<Vector2<f64>>() / pts.len() as f64;
        let mut s = nalgebra::Matrix2::zeros();
        for p in pts {
            let d = p - c;
            s += d * d.transpose();
        }
        let eig = s.symmetric_eigen();
        let i = if eig.eigenvalues[0] > eig.eigenvalues[1] { 0 } else { 1 };
        lines.push((c, eig.eigenvectors.column(i).into_owned()));
    }
    let mut out = Vec::with_capacity(k);
    for j in 0..k {
        let (p, u) = lines[(j + k - 1) % k];
        let (q, v) = lines[j];
        // p + s u = q + r v
        let det = u.x * (-v.y) - u.y * (-v.x);
        if det.abs() < 0.1 {
            return None;
        }
        let w = q - p;
        let s = (w.x * (-v.y) - w.y * (-v.x)) / det;
        let x = p + u * s;
        // A refined corner far from the tracked one means a side latched onto something else.
        if (x - corners[j]).norm() > 8.0 {
            return None;
        }
        out.push([x.x, x.y]);
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::image::ImageBuf;
    use handeye_vision::locate::{Blob, Placement};

    #[test]
    fn template_coordinates_of_the_default_plate() {
        let p = PlateTemplate::new(&GripperModel::default());
        // Reference at the centre; corners at (±½, ±½): a mark at (a, b) = (-0.016, 0.018)
        // is left (s < 0) and up (t < 0, since e2 runs from the top-left corner down).
        assert!(p.reference_st[0].abs() < 1e-12 && p.reference_st[1].abs() < 1e-12);
        assert!((p.marks_st[0][0] + 0.016 / 0.042).abs() < 1e-9, "{:?}", p.marks_st);
        assert!((p.marks_st[0][1] + 0.018 / 0.046).abs() < 1e-9, "{:?}", p.marks_st);
        assert!((p.a_axis_st[0] - 1.0 / 0.042).abs() < 1e-9 && p.a_axis_st[1].abs() < 1e-12);
        assert!((p.b_axis_st[1] + 1.0 / 0.046).abs() < 1e-9);
    }

    /// The moving fingers: one blob at x 105..135, y 100..160.
    fn fingers_moving_below_y100() -> ImageMotion {
        let blob = Blob { area_px: 600, bbox: [105, 100, 135, 160], centroid_px: [120.0, 130.0], axis_rad: 1.5, length_px: 60.0, width_px: 20.0 };
        ImageMotion {
            blobs: vec![blob],
            placement: Placement { centre_px: [120.0, 130.0], axis_rad: 1.5, length_px: 60.0, width_px: 20.0 },
            threshold: 12,
            noise_sigma: 1.0,
            dropped: 0,
        }
    }

    #[test]
    fn finds_a_bordered_plate_above_the_moving_region() {
        // Table grey 110; plate: dark border (10) around a light rectangle (170) at
        // x 100..140, y 40..90; fingers (moving) below it at y 100..160.
        let mut img = ImageBuf::filled(320, 240, 110);
        for y in 32..98 {
            for x in 92..148 {
                img.set(x, y, 10);
            }
        }
        for y in 40..90 {
            for x in 100..140 {
                img.set(x, y, 170);
            }
        }
        let motion = fingers_moving_below_y100();
        let c = find_plate(&img.view(), &motion).unwrap();
        let want = [[99.5, 39.5], [139.5, 39.5], [139.5, 89.5], [99.5, 89.5]];
        for (got, want) in c.iter().zip(want) {
            assert!((got[0] - want[0]).abs() < 1e-9 && (got[1] - want[1]).abs() < 1e-9, "{c:?}");
        }
        // No plate: nothing enclosed above the fingers.
        let blank = ImageBuf::filled(320, 240, 110);
        assert!(matches!(find_plate(&blank.view(), &motion), Err(PlateError::NotFound { .. })));
    }

    /// An axis-aligned rectangle's corners (top-left, top-right, bottom-right, bottom-left).
    fn rect(x0: f64, y0: f64, w: f64, h: f64) -> [[f64; 2]; 4] {
        [[x0, y0], [x0 + w, y0], [x0 + w, y0 + h], [x0, y0 + h]]
    }

    #[test]
    fn every_bordered_light_region_above_the_fingers_is_a_candidate_largest_first() {
        // The plate (40 x 50, border 10) above the fingers, and above it another light face
        // of the housing (60 x 20) with a dark surround of its own.
        let mut img = ImageBuf::filled(320, 240, 110);
        let fill = |img: &mut ImageBuf, x: std::ops::Range<usize>, y: std::ops::Range<usize>, v: u8| {
            for yy in y {
                for xx in x.clone() {
                    img.set(xx, yy, v);
                }
            }
        };
        fill(&mut img, 92..148, 32..98, 10);
        fill(&mut img, 100..140, 40..90, 170);
        fill(&mut img, 82..158, 0..28, 10);
        fill(&mut img, 90..150, 4..24, 170);
        let motion = fingers_moving_below_y100();
        let found = plate_candidates(&img.view(), &motion).unwrap();
        assert_eq!(found.len(), 2, "{found:?}");
        assert_eq!(found[0], [[99.5, 39.5], [139.5, 39.5], [139.5, 89.5], [99.5, 89.5]], "the plate (2000 px²) first");
        assert_eq!(found[1], [[89.5, 3.5], [149.5, 3.5], [149.5, 23.5], [89.5, 23.5]], "then the housing's face (1200 px²)");
        assert_eq!(find_plate(&img.view(), &motion).unwrap(), found[0]);
    }

    #[test]
    fn the_plates_are_paired_so_that_both_views_see_one_plate() {
        let plate_l = rect(100.0, 40.0, 20.0, 28.0); // 560 px²
        let plate_r = rect(300.0, 50.0, 21.0, 28.0); // 588 px²
        let housing_r = rect(290.0, 10.0, 43.0, 30.0); // 1290 px²: 2.3 times the left plate
        // Randomised cell 22: the right view's largest light region is the housing's top.
        assert_eq!(pair_plates(&[plate_l], &[housing_r, plate_r]), Some([plate_l, plate_r]));
        // The two largest agree: they stay, even where a smaller pair agrees better.
        let small = rect(0.0, 0.0, 10.0, 10.0);
        assert_eq!(pair_plates(&[plate_l, small], &[plate_r, small]), Some([plate_l, plate_r]));
        // No pair agrees: the two largest, for the converged trackers' check to refuse.
        assert_eq!(pair_plates(&[small], &[housing_r, plate_r]), Some([small, housing_r]));
        assert_eq!(pair_plates(&[], &[plate_r]), None);
    }

    /// A triangle seen from two sides has a different shape in each view, so each
    /// tracker's own template origin (its polygon's perimeter centroid) is a different point
    /// of the facet. In shared coordinates the plane transfer maps every left corner onto
    /// its right corner; with per-view frames its offset `b` is pixels off.
    #[test]
    fn stereo_frame_puts_both_views_in_shared_coordinates() {
        let left = [[100.0, 300.0], [160.0, 285.0], [155.0, 200.0]];
        let right = [[90.0, 310.0], [185.0, 280.0], [140.0, 190.0]];
        let cfg = handeye_vision::tracker::TrackerConfig::default();
        let (l, r) = (ContourTracker::new(cfg, &left).unwrap(), ContourTracker::new(cfg, &right).unwrap());
        let worst = |frames: &StereoFrame| {
            let t = handeye_vision::servo::PlaneTransfer::from_frames(frames).unwrap();
            left.iter().zip(&right).map(|(a, b)| (v2(t.apply(a)) - v2(*b)).norm()).fold(0.0, f64::max)
        };
        assert!(worst(&stereo_frame(&l, &r)) < 1e-6, "{}", worst(&stereo_frame(&l, &r)));
        let per_view = StereoFrame { left: facet_frame(&l), right: facet_frame(&r) };
        assert!(worst(&per_view) > 1.0, "per-view frames transfer the corners within {} px", worst(&per_view));
        // A corner count that differs between views falls back to per-view frames.
        let quad = ContourTracker::new(cfg, &[[90.0, 310.0], [185.0, 280.0], [180.0, 200.0], [95.0, 190.0]]).unwrap();
        assert_eq!(stereo_frame(&l, &quad).right, facet_frame(&quad));
    }

    #[test]
    fn the_least_plate_area_scales_with_the_plate_found() {
        // The shipped cameras' plate (~2000 px²) must keep 1000 px²; a randomised cell's
        // small plate (200 px²) 100 px²; never under the tracker's floor.
        assert_eq!(least_plate_area_px2(2000.0, 64.0), 1000.0);
        assert_eq!(least_plate_area_px2(200.0, 64.0), 100.0);
        assert_eq!(least_plate_area_px2(90.0, 64.0), 64.0);
    }
}
