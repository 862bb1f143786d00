//! The plan phase's work on the worker thread (thesis ch. 5-6): mask the gripper out of one
//! stereo pair, find facets with the planner, turn them into a grasp scene in robot
//! coordinates through the calibrated affine model, plan grasps, and pick the one nearest
//! the indicated point. Pure (no I/O); [`crate::phase::plan`] runs it and takes the result.
//!
//! **Coordinates.** The calibration maps *tool* positions to the images of the plate's
//! reference point: `w = M X_tool + c`. A scene point `P` seen at `w` is where the reference
//! point would be with the tool at `P + L`, `L = tool − reference` at the calibration's yaw,
//! so `w = M P + (c + M L)`: the planner gets that model (and +0.5 px: its pixel `(i, j)`
//! covers `[i, i+1)`, the trackers' has its centre at `(i, j)`), and its facets come out in
//! robot coordinates.
//!
//! **Masking.** The gripper (plate, palm and open fingers) is in view while the planner
//! looks: its pixels are replaced by a harmonic fill (Laplace's equation with the pixels
//! around the mask as boundary values), which leaves no step at the mask's border and no
//! edge inside it, so no edges come from the gripper or the mask. The rest of the arm
//! is above the parked tool point; features that high are dropped from the grasp scene.
//!
//! **Target polygons.** The chosen facet's outline initialises the target trackers: its
//! image polygons, simplified (Douglas-Peucker, 1.5 px on the cyclopean polygon, the same
//! vertices kept in both views) so that a corner the planner split into slivers does not
//! become a tracker side of two pixels.

use std::collections::BTreeMap;
use std::time::Instant;

use handeye_vision::affine::AffineStereo;
use handeye_vision::grasp::{hypothesise_front_faces, plan_grasps, scene_from_plan, EdgeRef, FeatureRef, Grasp, GraspConfig, RejectReason};
use handeye_vision::image::ImageBuf;
use handeye_vision::planner::{Planner, PlannerConfig, StereoGeometry};
use nalgebra::{Vector3, Vector4};
use serde::Serialize;

/// Planner pixel coordinates minus tracker pixel coordinates.
pub const PLANNER_FROM_TRACKER_PX: f64 = 0.5;

/// Everything the worker needs for one plan.
pub struct PlanRequest {
    /// The stereo pair, as taken with the arm parked (left, right).
    pub images: [ImageBuf; 2],
    /// The calibration: tool positions to the reference point's images (tracker pixels).
    pub model: AffineStereo,
    /// The cage it was fitted to: tool positions (m) and reference-point images (tracker
    /// pixels). With >= 6 points the planner reconstructs through pinhole cameras fitted to
    /// them (the affine model alone is several mm off at 1.6 m).
    pub cage_robot_m: Vec<Vector3<f64>>,
    pub cage_image_px: Vec<[f64; 4]>,
    /// `tool − reference` at the calibration's yaw, robot frame, m.
    pub lever_m: [f64; 3],
    /// The gripper's image region in each view (tracker pixels), masked before planning.
    pub masks: [Vec<[f64; 2]>; 2],
    pub mask_margin_px: f64,
    /// The operator's indicated point, robot frame, m.
    pub indicated_m: Option<[f64; 3]>,
    /// Features entirely above this height are the arm, m.
    pub max_height_m: f64,
    /// Features closer than this in 3-D are one object, m.
    pub join_m: f64,
    /// Hypothesise the vertical faces below top faces' front edges that the planner missed,
    /// down to the table at this height (robot frame, m); `None`: do not.
    pub front_faces_to_table_z_m: Option<f64>,
    /// A grasp whose centre is farther than this from the indicated point (plan view) is
    /// not on the block the operator meant: no grasp then, m.
    pub max_distance_m: f64,
    pub planner: PlannerConfig,
    pub grasp: GraspConfig,
    pub disparity_margin: f64,
    pub disparity_margin_px: f64,
}

/// The grasp to execute, in the terms the later phases need.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedTarget {
    /// The facet's outline for the target trackers, tracker pixels, vertex for vertex.
    pub left_px: Vec<[f64; 2]>,
    pub right_px: Vec<[f64; 2]>,
    /// Grasp width (between the front and the hypothesised rear surface), m, >= 0.
    pub width_m: f64,
    /// The grasp site (on the facet's top edge) in both views, tracker pixels.
    pub site_px: [[f64; 2]; 2],
    pub site_m: [f64; 3],
    /// Tool point at the grasp: between the fingers at the low-water mark, m.
    pub tool_m: [f64; 3],
}

/// One planner facet, as the report shows it.
#[derive(Debug, Clone, Serialize)]
pub struct FacetSummary {
    pub plan_facet: usize,
    /// Outline in both views, tracker pixels.
    pub left_px: Vec<[f64; 2]>,
    pub right_px: Vec<[f64; 2]>,
    /// Corners in robot coordinates, m.
    pub corners_m: Option<Vec<[f64; 3]>>,
    /// Object id in the grasp scene (`None`: left out of it).
    pub component: Option<usize>,
    /// Hypothesised below the front edge of top face `plan_facet`, not seen as a facet.
    pub hypothesised: bool,
}

/// A grasp site, as the report shows it.
#[derive(Debug, Clone, Serialize)]
pub struct SiteSummary {
    pub plan_facet: usize,
    /// The site's facet was hypothesised below the top face `plan_facet`.
    pub hypothesised_facet: bool,
    pub width_mm: f64,
    pub site_m: [f64; 3],
    pub centre_m: [f64; 3],
    pub tool_m: Option<[f64; 3]>,
    pub yaw_deg: Option<f64>,
    pub site_left_px: [f64; 2],
    pub site_right_px: [f64; 2],
    /// Plan-view distance of the grasp centre from the indicated point, mm.
    pub distance_mm: Option<f64>,
    /// Why it was rejected (`None` for a candidate).
    pub reason: Option<String>,
}

/// What the planner found and decided (`plan.json`, and the outcome's `plan`).
#[derive(Debug, Clone, Serialize, Default)]
pub struct PlanSummary {
    pub segments: [usize; 2],
    pub matches: usize,
    pub planes: usize,
    pub facets: Vec<FacetSummary>,
    /// The highest collision-free site of each facet that has one, preferred first.
    pub candidates: Vec<SiteSummary>,
    pub chosen: Option<SiteSummary>,
    /// Sites that failed a rule (with their place), and facets or edges that failed before a
    /// site existed (counted in `rejected_by_reason` only).
    pub rejected_sites: Vec<SiteSummary>,
    pub rejected_by_reason: BTreeMap<String, usize>,
    /// Facets and top edges that failed a rule before a site existed: `(plan facet, reason)`.
    pub facet_rejections: Vec<(usize, String)>,
    pub indicated_m: Option<[f64; 3]>,
    /// The indicated point in both views, tracker pixels.
    pub indicated_px: Option<[[f64; 2]; 2]>,
    /// The gripper's masked region in both views, tracker pixels.
    pub masks_px: [Vec<[f64; 2]>; 2],
    pub masked_px: [usize; 2],
    /// The model the planner used (scene points to planner pixels: `handeye plan --calib`
    /// reads this object): `m` rows, `c`, `disparity_range_px`, `residual_rms_px`.
    pub model: Option<serde_json::Value>,
    /// Epipolar bootstrap: RMS before and after, px.
    pub bootstrap_rms_px: Option<[f64; 2]>,
    /// RMS residual of the pinhole cameras fitted to the cage (`None`: affine model only), px.
    pub projective_residual_px: Option<f64>,
    pub planner_ms: f64,
    pub total_ms: f64,
}

/// The worker's answer.
#[derive(Debug)]
pub struct PlanOutput {
    pub summary: PlanSummary,
    /// `None` when no site survived the rules.
    pub target: Option<PlannedTarget>,
    /// The other candidates near the indicated point, next best first.
    pub alternatives: Vec<PlannedTarget>,
    /// The images as the planner saw them (masked), for the report.
    pub images: [ImageBuf; 2],
}

/// A short name for a rejection reason.
pub fn reason_name(r: &RejectReason) -> &'static str {
    match r {
        RejectReason::FacetNotVertical { .. } => "facet_not_vertical",
        RejectReason::TurnedFromViewer { .. } => "turned_from_cameras",
        RejectReason::NoTopEdge => "no_top_edge",
        RejectReason::TopEdgeTooSteep { .. } => "top_edge_too_steep",
        RejectReason::NoOverlap => "no_overlap",
        RejectReason::RearInFront { .. } => "rear_in_front",
        RejectReason::RearOutOfReach { .. } => "rear_out_of_reach",
        RejectReason::TooWide { .. } => "too_wide",
        RejectReason::FingerCollision { .. } => "finger_collision",
        RejectReason::BodyCollision { .. } => "body_collision",
        RejectReason::NotHighest => "not_highest",
    }
}

/// The model the planner uses: scene points (robot frame) to planner pixels (module docs).
pub fn scene_model(model: &AffineStereo, lever_m: &[f64; 3]) -> AffineStereo {
    let shift = model.m * Vector3::from(*lever_m) + Vector4::repeat(PLANNER_FROM_TRACKER_PX);
    AffineStereo { c: model.c + shift, ..model.clone() }
}

/// Projects a robot-frame scene point into both views, tracker pixels.
fn project(model: &AffineStereo, lever_m: &[f64; 3], p: &Vector3<f64>) -> [[f64; 2]; 2] {
    let w = model.m * (p + Vector3::from(*lever_m)) + model.c;
    [[w[0], w[1]], [w[2], w[3]]]
}

/// Projects a scene point through the pinhole cameras when there are any (planner pixels in,
/// tracker pixels out), else through the affine model.
fn project_scene(geo: &StereoGeometry, model: &AffineStereo, lever_m: &[f64; 3], p: &Vector3<f64>) -> [[f64; 2]; 2] {
    let Some(cams) = &geo.projective else { return project(model, lever_m, p) };
    let h = p.push(1.0);
    let at = |cam: &nalgebra::Matrix3x4<f64>| {
        let x = cam * h;
        [x[0] / x[2] - PLANNER_FROM_TRACKER_PX, x[1] / x[2] - PLANNER_FROM_TRACKER_PX]
    };
    [at(&cams.left), at(&cams.right)]
}

fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0) } else { 0.0 };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

fn inside(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut odd = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            odd = !odd;
        }
    }
    odd
}

/// Replaces the pixels inside `poly` (or within `margin_px` of it; tracker pixels) with a
/// smooth fill from the unmasked pixels around (module docs). Returns how many were masked.
pub fn mask_and_fill(img: &mut ImageBuf, poly: &[[f64; 2]], margin_px: f64) -> usize {
    let (w, h) = (img.width, img.height);
    if poly.len() < 3 || w == 0 || h == 0 || poly.iter().flatten().any(|v| !v.is_finite()) {
        return 0;
    }
    let lo = |k: usize| poly.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min) - margin_px;
    let hi = |k: usize| poly.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max) + margin_px;
    let clamp = |v: f64, n: usize| v.clamp(0.0, n as f64 - 1.0) as usize;
    let (x0, x1, y0, y1) = (clamp(lo(0).floor(), w), clamp(hi(0).ceil(), w), clamp(lo(1).floor(), h), clamp(hi(1).ceil(), h));
    let mut masked = vec![false; w * h];
    let mut count = 0;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let p = [x as f64, y as f64];
            let near = inside(poly, p) || (0..poly.len()).any(|i| point_segment_distance(p, poly[i], poly[(i + 1) % poly.len()]) <= margin_px);
            if near {
                masked[y * w + x] = true;
                count += 1;
            }
        }
    }
    if count == 0 || count == w * h {
        return count;
    }
    // Harmonic fill: the masked pixels solve Laplace's equation with the unmasked pixels
    // around as boundary values (over-relaxed Gauss-Seidel, from the row/column
    // interpolation as a start). Smooth inside, no step at the border: a step in the
    // background that crosses the mask (the arm's silhouette) is spread into a gentle ramp
    // that no edge detector takes for an edge.
    let src = img.data.clone();
    let (bw, bh) = (x1 - x0 + 1, y1 - y0 + 1);
    let mut v = vec![0f32; bw * bh];
    for y in y0..=y1 {
        for x in x0..=x1 {
            let i = (y - y0) * bw + (x - x0);
            if !masked[y * w + x] {
                v[i] = f32::from(src[y * w + x]);
                continue;
            }
            let (mut sum, mut wsum) = (0.0, 0.0);
            let mut take = |xx: usize, yy: usize, d: usize| {
                let wt = 1.0 / d as f32;
                sum += wt * f32::from(src[yy * w + xx]);
                wsum += wt;
            };
            if let Some(d) = (1..=x).find(|&d| !masked[y * w + x - d]) {
                take(x - d, y, d);
            }
            if let Some(d) = (1..w - x).find(|&d| !masked[y * w + x + d]) {
                take(x + d, y, d);
            }
            if let Some(d) = (1..=y).find(|&d| !masked[(y - d) * w + x]) {
                take(x, y - d, d);
            }
            if let Some(d) = (1..h - y).find(|&d| !masked[(y + d) * w + x]) {
                take(x, y + d, d);
            }
            v[i] = if wsum > 0.0 { sum / wsum } else { 128.0 };
        }
    }
    // Neighbours outside the box are outside the mask too (the box holds the whole mask),
    // so the box's own border rows and columns are fixed values.
    let cells: Vec<(usize, usize)> = (y0..=y1).flat_map(|y| (x0..=x1).map(move |x| (x, y))).filter(|&(x, y)| masked[y * w + x]).collect();
    let omega = 1.9f32;
    for _ in 0..400 {
        let mut change = 0f32;
        for &(x, y) in &cells {
            let i = (y - y0) * bw + (x - x0);
            let (mut sum, mut n) = (0f32, 0f32);
            if x > x0 {
                sum += v[i - 1];
                n += 1.0;
            } else if x > 0 {
                sum += f32::from(src[y * w + x - 1]);
                n += 1.0;
            }
            if x < x1 {
                sum += v[i + 1];
                n += 1.0;
            } else if x + 1 < w {
                sum += f32::from(src[y * w + x + 1]);
                n += 1.0;
            }
            if y > y0 {
                sum += v[i - bw];
                n += 1.0;
            } else if y > 0 {
                sum += f32::from(src[(y - 1) * w + x]);
                n += 1.0;
            }
            if y < y1 {
                sum += v[i + bw];
                n += 1.0;
            } else if y + 1 < h {
                sum += f32::from(src[(y + 1) * w + x]);
                n += 1.0;
            }
            if n > 0.0 {
                let d = omega * (sum / n - v[i]);
                v[i] += d;
                change = change.max(d.abs());
            }
        }
        if change < 0.05 {
            break;
        }
    }
    for &(x, y) in &cells {
        img.data[y * w + x] = v[(y - y0) * bw + (x - x0)].round().clamp(0.0, 255.0) as u8;
    }
    count
}

fn to_tracker_px(p: [f64; 2]) -> [f64; 2] {
    [p[0] - PLANNER_FROM_TRACKER_PX, p[1] - PLANNER_FROM_TRACKER_PX]
}

/// Share of the segment `a`-`b` (tracker pixels) along which the image steps by at least
/// 12 grey levels across it, within 3 px of the line (a projected edge is off by a pixel or
/// two): at each pixel along it, the largest difference of the grey levels 2 px either side
/// of points up to 3 px off the line. 0 for a segment off the image or under 4 px.
pub fn edge_support(img: &ImageBuf, a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    if !(len >= 4.0) {
        return 0.0;
    }
    let (nx, ny) = (-dy / len, dx / len);
    let at = |x: f64, y: f64| -> Option<f64> {
        let (xi, yi) = (x.round(), y.round());
        (xi >= 0.0 && yi >= 0.0 && (xi as usize) < img.width && (yi as usize) < img.height).then(|| f64::from(img.get(xi as usize, yi as usize)))
    };
    let steps = len.floor() as usize;
    let mut hits = 0;
    for i in 0..=steps {
        let t = i as f64 / steps as f64;
        let (x, y) = (a[0] + t * dx, a[1] + t * dy);
        let step = |d: f64| -> Option<f64> { Some((at(x + (d + 2.0) * nx, y + (d + 2.0) * ny)? - at(x + (d - 2.0) * nx, y + (d - 2.0) * ny)?).abs()) };
        if (-3..=3).filter_map(|d| step(f64::from(d))).any(|s| s >= 12.0) {
            hits += 1;
        }
    }
    hits as f64 / (steps + 1) as f64
}

/// Indices of the vertices kept by Douglas-Peucker on a closed polygon (tolerance `tol`),
/// at least three, in order.
pub fn simplify_closed(poly: &[[f64; 2]], tol: f64) -> Vec<usize> {
    let n = poly.len();
    if n <= 3 {
        return (0..n).collect();
    }
    // Split at vertex 0 and the vertex farthest from it.
    let far = (1..n).max_by(|&a, &b| {
        let d = |i: usize| (poly[i][0] - poly[0][0]).hypot(poly[i][1] - poly[0][1]);
        d(a).total_cmp(&d(b))
    });
    let Some(far) = far else { return (0..n).collect() };
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[far] = true;
    fn dp(poly: &[[f64; 2]], a: usize, b: usize, tol: f64, keep: &mut [bool]) {
        // Vertices strictly between a and b, going forward (cyclically).
        let n = poly.len();
        let mut best = (0.0, None);
        let mut i = (a + 1) % n;
        while i != b {
            let d = point_segment_distance(poly[i], poly[a], poly[b]);
            if d > best.0 {
                best = (d, Some(i));
            }
            i = (i + 1) % n;
        }
        if let (d, Some(i)) = best
            && d > tol
        {
            keep[i] = true;
            dp(poly, a, i, tol, keep);
            dp(poly, i, b, tol, keep);
        }
    }
    dp(poly, 0, far, tol, &mut keep);
    dp(poly, far, 0, tol, &mut keep);
    let mut out: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
    // Fewer than three: add the vertex farthest from the chord.
    while out.len() < 3 {
        let extra = (0..n).filter(|i| !out.contains(i)).max_by(|&a, &b| {
            let d = |i: usize| point_segment_distance(poly[i], poly[out[0]], poly[out[out.len() - 1]]);
            d(a).total_cmp(&d(b))
        });
        match extra {
            Some(e) => {
                out.push(e);
                out.sort_unstable();
            }
            None => break,
        }
    }
    out
}

/// `keep` (indices into `poly`, in order) rotated to start at the corner whose two sides
/// span the largest parallelogram: a tracker's template frame is `e1 = c1 − c0`,
/// `e2 = c_{n−1} − c0`, and the servo's view of the facet (its `s, t` rows and plane
/// transfer) is only as well conditioned as that frame; a short side at a notch of an L
/// would make it lopsided.
pub fn tracker_order(poly: &[[f64; 2]], keep: &[usize]) -> Vec<usize> {
    let n = keep.len();
    if n < 3 {
        return keep.to_vec();
    }
    let area = |k: usize| {
        let (o, a, b) = (poly[keep[k]], poly[keep[(k + 1) % n]], poly[keep[(k + n - 1) % n]]);
        ((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])).abs()
    };
    let best = (0..n).max_by(|&a, &b| area(a).total_cmp(&area(b)).then(b.cmp(&a))).unwrap_or(0);
    (0..n).map(|k| keep[(best + k) % n]).collect()
}

fn arr3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Runs the plan (see the module docs).
pub fn plan(mut req: PlanRequest) -> PlanOutput {
    let start = Instant::now();
    let mut summary = PlanSummary {
        indicated_m: req.indicated_m,
        indicated_px: req.indicated_m.map(|p| project(&req.model, &req.lever_m, &Vector3::from(p))),
        masks_px: req.masks.clone(),
        ..Default::default()
    };
    for (k, img) in req.images.iter_mut().enumerate() {
        summary.masked_px[k] = mask_and_fill(img, &req.masks[k], req.mask_margin_px);
    }
    let scene_model = scene_model(&req.model, &req.lever_m);
    summary.model = Some(serde_json::json!({
        "m": (0..4).map(|r| [scene_model.m[(r, 0)], scene_model.m[(r, 1)], scene_model.m[(r, 2)]]).collect::<Vec<_>>(),
        "c": [scene_model.c[0], scene_model.c[1], scene_model.c[2], scene_model.c[3]],
        "disparity_range_px": scene_model.disparity_range_px,
        "residual_rms_px": scene_model.residual_rms_px,
    }));
    let toward = req.model.toward_cameras();
    // Pinhole cameras from the cage, for metric reconstruction: a scene point P images where
    // the reference point does with the tool at P + L, so the cage points become the
    // reference point's own positions, X_tool − L, seen at the planner's pixels.
    let lever = Vector3::from(req.lever_m);
    let points: Vec<Vector3<f64>> = req.cage_robot_m.iter().map(|x| x - lever).collect();
    let images: Vec<[f64; 4]> = req.cage_image_px.iter().map(|w| w.map(|v| v + PLANNER_FROM_TRACKER_PX)).collect();
    let mut geo = StereoGeometry::from_model(scene_model, req.disparity_margin, req.disparity_margin_px);
    if points.len() >= handeye_vision::planner::projective::MIN_POINTS {
        geo.projective = handeye_vision::planner::projective::ProjectiveStereo::fit(&points, &images).ok();
    }
    summary.projective_residual_px = geo.projective.as_ref().map(|p| p.residual_rms_px);
    let t0 = Instant::now();
    let plan = Planner::new(req.planner).plan(&req.images[0].view(), &req.images[1].view(), &geo);
    summary.planner_ms = t0.elapsed().as_secs_f64() * 1e3;
    summary.segments = [plan.left_segments.len(), plan.right_segments.len()];
    summary.matches = plan.matches.len();
    summary.planes = plan.planes.len();
    summary.bootstrap_rms_px = plan.bootstrap.map(|b| [b.rms_before_px, b.rms_after_px]);
    let mut ps = scene_from_plan(&plan, toward, req.max_height_m, req.join_m);
    let planned_facets = ps.facets.len();
    if let Some(table_z) = req.front_faces_to_table_z_m {
        let project = |p: &Vector3<f64>| {
            let px = project_scene(&geo, &req.model, &req.lever_m, p);
            let ok = px.iter().flatten().all(|v| v.is_finite());
            ok.then(|| px.map(|q| [q[0] + PLANNER_FROM_TRACKER_PX, q[1] + PLANNER_FROM_TRACKER_PX]))
        };
        hypothesise_front_faces(&mut ps, &project, table_z, 0.01, 20f64.to_radians(), req.grasp.max_view_angle_rad, 1.5 * req.join_m);
        // A hypothesised face must show its bottom edge, against the table, in both views:
        // one hung from a top edge where the block does not go straight down (the tall leg
        // of an L over its low leg) has none there.
        let mut k = planned_facets;
        while k < ps.facets.len() {
            let src = &ps.facets[k];
            let seen = [(&req.images[0], &src.left_px), (&req.images[1], &src.right_px)]
                .iter()
                .all(|(img, poly)| edge_support(img, to_tracker_px(poly[0]), to_tracker_px(poly[1])) >= 0.6);
            if seen {
                k += 1;
            } else {
                ps.facets.remove(k);
                ps.scene.facets.remove(k);
                *summary.rejected_by_reason.entry("hypothesised_face_unseen".into()).or_insert(0) += 1;
            }
        }
    }
    let s = PLANNER_FROM_TRACKER_PX;
    let to_tracker = |p: &[[f64; 2]]| -> Vec<[f64; 2]> { p.iter().map(|q| [q[0] - s, q[1] - s]).collect() };
    for (fi, f) in plan.facets.iter().enumerate() {
        let component = ps.facets.iter().position(|src| src.plan_facet == fi).map(|k| ps.scene.facets[k].component);
        summary.facets.push(FacetSummary {
            plan_facet: fi,
            left_px: to_tracker(&f.facet.left),
            right_px: to_tracker(&f.facet.right),
            corners_m: f.corners_robot_m.clone(),
            component,
            hypothesised: false,
        });
    }
    for (k, src) in ps.facets.iter().enumerate().skip(planned_facets) {
        summary.facets.push(FacetSummary {
            plan_facet: src.plan_facet,
            left_px: to_tracker(&src.left_px),
            right_px: to_tracker(&src.right_px),
            corners_m: Some(ps.scene.facets[k].polygon_m.iter().map(arr3).collect()),
            component: Some(ps.scene.facets[k].component),
            hypothesised: true,
        });
    }
    let indicated = req.indicated_m.map(Vector3::from);
    let grasps = match plan_grasps(&ps.scene, indicated.as_ref(), &req.grasp) {
        Ok(g) => g,
        Err(e) => {
            summary.rejected_by_reason.insert(format!("invalid scene: {e}"), 1);
            summary.total_ms = start.elapsed().as_secs_f64() * 1e3;
            return PlanOutput { summary, target: None, alternatives: Vec::new(), images: req.images };
        }
    };
    let site_summary = |g: Option<&Grasp>, site: &handeye_vision::grasp::GraspSite, reason: Option<String>| {
        let px = project_scene(&geo, &req.model, &req.lever_m, &site.front_m);
        SiteSummary {
            plan_facet: ps.facets[site.facet].plan_facet,
            hypothesised_facet: ps.facets[site.facet].hypothesised,
            width_mm: site.width_m * 1e3,
            site_m: arr3(&site.front_m),
            centre_m: arr3(&site.centre_m),
            tool_m: g.map(|g| arr3(&g.tool_m)),
            yaw_deg: g.map(|g| g.yaw_rad.to_degrees()),
            site_left_px: px[0],
            site_right_px: px[1],
            distance_mm: indicated.map(|p| (site.centre_m.xy() - p.xy()).norm() * 1e3),
            reason,
        }
    };
    for r in &grasps.rejected {
        let name = reason_name(&r.reason);
        *summary.rejected_by_reason.entry(name.to_string()).or_insert(0) += 1;
        if r.site.is_none() {
            let detail = match r.reason {
                RejectReason::FacetNotVertical { tilt_rad } => format!("{name} ({:.0}°)", tilt_rad.to_degrees()),
                RejectReason::TurnedFromViewer { angle_rad } => format!("{name} ({:.0}°)", angle_rad.to_degrees()),
                RejectReason::TopEdgeTooSteep { slope_rad } => format!("{name} ({:.0}°)", slope_rad.to_degrees()),
                _ => name.to_string(),
            };
            summary.facet_rejections.push((ps.facets[r.facet].plan_facet, detail));
        }
        if let Some(site) = &r.site {
            let detail = match r.reason {
                RejectReason::FingerCollision { feature } | RejectReason::BodyCollision { feature } => {
                    let what = match feature {
                        FeatureRef::Facet(i) => format!("facet {}", ps.facets[i].plan_facet),
                        FeatureRef::Edge(EdgeRef::Facet { facet, .. }) => format!("an edge of facet {}", ps.facets[facet].plan_facet),
                        FeatureRef::Edge(EdgeRef::Loose(i)) => format!("edge {}", ps.edge_matches[i]),
                    };
                    format!("{name} with {what}")
                }
                RejectReason::TooWide { width_m } => format!("{name} ({:.0} mm)", width_m * 1e3),
                _ => name.to_string(),
            };
            summary.rejected_sites.push(site_summary(None, site, Some(detail)));
        }
    }
    summary.candidates = grasps.candidates.iter().map(|g| site_summary(Some(g), &g.site, None)).collect();
    // The block nearest the point has no grasp site if the nearest site is far from it.
    let near = |g: &Grasp| indicated.is_none_or(|p| (g.site.centre_m.xy() - p.xy()).norm() <= req.max_distance_m);
    let chosen = grasps.chosen.filter(near);
    if grasps.chosen.is_some() && chosen.is_none() {
        summary.rejected_by_reason.insert("far_from_indicated_point".into(), grasps.candidates.len());
    }
    summary.chosen = chosen.as_ref().and_then(|_| summary.candidates.first().cloned());
    let planned = |g: &Grasp| {
        let src = &ps.facets[g.site.facet];
        let cyclopean: Vec<[f64; 2]> = src.left_px.iter().zip(&src.right_px).map(|(l, r)| [(l[0] + r[0]) / 2.0, (l[1] + r[1]) / 2.0]).collect();
        let keep = tracker_order(&cyclopean, &simplify_closed(&cyclopean, 1.5));
        let pick = |poly: &[[f64; 2]]| -> Vec<[f64; 2]> { keep.iter().map(|&i| [poly[i][0] - s, poly[i][1] - s]).collect() };
        PlannedTarget {
            left_px: pick(&src.left_px),
            right_px: pick(&src.right_px),
            width_m: g.site.width_m.max(0.0),
            site_px: project_scene(&geo, &req.model, &req.lever_m, &g.site.front_m),
            site_m: arr3(&g.site.front_m),
            tool_m: arr3(&g.tool_m),
        }
    };
    let target = chosen.as_ref().map(planned);
    let alternatives: Vec<PlannedTarget> = if chosen.is_some() { grasps.candidates.iter().skip(1).filter(|g| near(g)).map(planned).collect() } else { Vec::new() };
    summary.total_ms = start.elapsed().as_secs_f64() * 1e3;
    PlanOutput { summary, target, alternatives, images: req.images }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fill_leaves_no_step_at_the_mask_border() {
        // A left-to-right ramp with a bright square on it; masking the square gives back the
        // ramp (to rounding), so no edge is left at the mask's border.
        let (w, h) = (60, 40);
        let mut img = ImageBuf::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let inside = (20..35).contains(&x) && (10..25).contains(&y);
                img.set(x, y, if inside { 250 } else { (50 + 2 * x) as u8 });
            }
        }
        let sq = [[20.0, 10.0], [34.0, 10.0], [34.0, 24.0], [20.0, 24.0]];
        let n = mask_and_fill(&mut img, &sq, 1.0);
        assert_eq!(n, 17 * 17 - 4, "the square and 1 px around it, less the far corners");
        for y in 0..h {
            for x in 0..w {
                let want = (50 + 2 * x) as i32;
                assert!((i32::from(img.get(x, y)) - want).abs() <= 1, "({x}, {y}): {} vs {want}", img.get(x, y));
            }
        }
        // Nothing to mask, or a bad polygon: the image is untouched.
        let before = img.clone();
        assert_eq!(mask_and_fill(&mut img, &[[1.0, 1.0], [2.0, 2.0]], 1.0), 0);
        assert_eq!(mask_and_fill(&mut img, &[[f64::NAN, 1.0], [2.0, 2.0], [3.0, 1.0]], 1.0), 0);
        assert_eq!(img, before);
    }

    #[test]
    fn edge_support_sees_a_step_and_not_a_flat_face() {
        // Left half 40, right half 120: a vertical edge at x = 29.5.
        let mut img = ImageBuf::new(60, 40);
        for y in 0..40 {
            for x in 0..60 {
                img.set(x, y, if x < 30 { 40 } else { 120 });
            }
        }
        assert!(edge_support(&img, [29.5, 5.0], [29.5, 35.0]) > 0.95);
        assert!(edge_support(&img, [27.0, 5.0], [27.0, 35.0]) > 0.95, "2.5 px off the edge still finds it");
        assert!(edge_support(&img, [10.0, 5.0], [10.0, 35.0]) < 0.05, "inside a flat region");
        assert!(edge_support(&img, [5.0, 20.0], [55.0, 20.0]) < 0.05, "along the edge's normal");
        assert_eq!(edge_support(&img, [10.0, 5.0], [10.0, 6.0]), 0.0, "too short");
        assert_eq!(edge_support(&img, [-100.0, 5.0], [-100.0, 35.0]), 0.0, "off the image");
    }

    #[test]
    fn simplification_drops_slivers_and_keeps_corners() {
        // A square whose corner (10, 0) is split into two vertices 1 px apart, plus a point
        // in the middle of a side.
        let poly = [[0.0, 0.0], [9.0, 0.0], [10.0, 1.0], [10.0, 10.0], [5.0, 10.2], [0.0, 10.0]];
        let keep = simplify_closed(&poly, 1.5);
        assert_eq!(keep.len(), 4, "{keep:?}");
        assert!(keep.contains(&0) && keep.contains(&5));
        // A triangle stays a triangle.
        assert_eq!(simplify_closed(&[[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]], 1.5), vec![0, 1, 2]);
        // An L (tall leg on the right): the frame starts at the corner with the longest
        // sides, the bottom-right one (40 across, 40 up).
        let l = [[0.0, 0.0], [0.0, -20.0], [20.0, -20.0], [20.0, -40.0], [40.0, -40.0], [40.0, 0.0]];
        assert_eq!(tracker_order(&l, &[0, 1, 2, 3, 4, 5]), vec![5, 0, 1, 2, 3, 4]);
    }

    #[test]
    fn the_scene_model_puts_a_point_where_the_reference_point_would_image_it() {
        // Model: u = 1000 x + 100, v = −1000 z + 200, u' = 1000 x + 50 y + 90, v' = −1000 z + 200.
        let mut m = nalgebra::Matrix4x3::zeros();
        m[(0, 0)] = 1000.0;
        m[(1, 2)] = -1000.0;
        m[(2, 0)] = 1000.0;
        m[(2, 1)] = 50.0;
        m[(3, 2)] = -1000.0;
        let model = AffineStereo { m, c: Vector4::new(100.0, 200.0, 90.0, 200.0), residual_rms_px: 0.0, disparity_range_px: [0.0, 1.0] };
        let lever = [0.0, 0.0, -0.1]; // the tool 0.1 m below the reference point
        // A scene point at (0.1, 0, 0.2) images where the reference point does with the tool
        // at (0.1, 0, 0.1).
        let p = Vector3::new(0.1, 0.0, 0.2);
        let [l, r] = project(&model, &lever, &p);
        let w = model.m * Vector3::new(0.1, 0.0, 0.1) + model.c;
        assert_eq!([l[0], l[1], r[0], r[1]], [w[0], w[1], w[2], w[3]]);
        // The planner's model reconstructs it from planner pixels (+0.5).
        let sm = scene_model(&model, &lever);
        let back = sm.reconstruct(&[l[0] + 0.5, l[1] + 0.5, r[0] + 0.5, r[1] + 0.5]);
        assert!((back - p).norm() < 1e-9, "{back:?}");
    }
}
