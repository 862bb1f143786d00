//! The plan phase's work on the worker thread (thesis ch. 5-6): mask the gripper out of one
//! stereo pair, find facets with the planner, turn them into a grasp scene in robot
//! coordinates through the calibrated affine model, plan grasps, and pick the one nearest
//! the indicated point. Pure (no I/O); the plan phase (`phase/plan.rs`) runs it and takes the result.
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

use handeye_vision::planner::geom::{self, simplify_closed, tracker_order};
use handeye_vision::affine::AffineStereo;
use handeye_vision::grasp::{hypothesise_front_faces, plan_grasps, refusal_grounded, scene_from_plan, sloping_top_rad, why_no_grasp, EdgeRef, FeatureRef, Grasp, GraspConfig, PlannedScene, RejectReason, Rejection};
use handeye_vision::image::ImageBuf;
use handeye_vision::planner::{Planner, PlannerConfig, EpipolarGeometry};
use nalgebra::{Vector3, Vector4};
use serde::{Deserialize, Serialize};

mod one_view_face;
mod pixels;
mod rear_edge;
mod request;
pub use pixels::{bottom_edge_offset, edge_support, mask_and_fill};
pub use request::{plan_request, replay_request, PlanMoment, ReplayError};

/// Planner pixel coordinates minus tracker pixel coordinates.
pub const PLANNER_FROM_TRACKER_PX: f64 = 0.5;

/// A planner facet with at least this share of its image area inside a hypothesised face of
/// the same object, in both views, is that face reconstructed off (see [`plan`]).
pub const SUPERSEDED_SHARE: f64 = 0.6;

/// Grasps narrower than this near the indicated point send the plan looking for rear edges
/// in the images (see [`plan`]), m.
pub const MIN_SOLID_WIDTH_M: f64 = 0.005;

/// `PlannedScene::edge_matches` entry of a rear edge found in the images (no planner match).
pub const IMAGE_REAR_EDGE: usize = usize::MAX;

/// How far below the table a reconstructed corner may lie before its facet is taken for a
/// false match, m: the plan's heights are good to a few millimetres with the pinhole
/// cameras (seed 106's top face at 30-32 mm on a 30 mm cube).
const BELOW_TABLE_M: f64 = 0.015;

/// Everything the worker needs for one plan.
pub struct PlanRequest {
    /// The stereo pair, as taken with the arm parked (left, right).
    pub images: [ImageBuf; 2],
    pub calibration: PlanCalibration,
    /// The gripper's image region in each view (tracker pixels), masked before planning.
    pub masks: [Vec<[f64; 2]>; 2],
    pub mask_margin_px: f64,
    pub scene: SceneLimits,
    pub planner: PlannerConfig,
    pub grasp: GraspConfig,
    pub disparity_margin: f64,
    pub disparity_margin_px: f64,
}

/// The calibration as the planner uses it.
pub struct PlanCalibration {
    /// Tool positions to the reference point's images (tracker pixels).
    pub model: AffineStereo,
    /// The cage it was fitted to: tool positions (m) and reference-point images (tracker
    /// pixels). With >= 6 points the planner reconstructs through pinhole cameras fitted to
    /// them (the affine model alone is several mm off at 1.6 m).
    pub cage_robot_m: Vec<Vector3<f64>>,
    pub cage_image_px: Vec<[f64; 4]>,
    /// `tool − reference` at the calibration's yaw, robot frame, m.
    pub lever_m: [f64; 3],
}

/// Where to look for the operator's object and what counts as one.
pub struct SceneLimits {
    /// The operator's indicated point, robot frame, m.
    pub indicated_m: Option<[f64; 3]>,
    /// Its one-sigma radius, m: 0 for a point given as a coordinate; a pointed point with a
    /// radius must pick one block (see [`point_ambiguity`]).
    pub indicated_sigma_m: f64,
    /// How many sigmas off a pointed point may be (`plan.point_ambiguity_sigmas`).
    pub ambiguity_sigmas: f64,
    /// Features entirely above this height are the arm, m.
    pub max_height_m: f64,
    /// Features closer than this in 3-D are one object, m.
    pub join_m: f64,
    /// The table's height, robot frame, m: the pinhole cameras' epipolar geometry is fitted
    /// for the heights of objects on it (`EpipolarGeometry::correct_from_cameras`).
    pub table_z_m: f64,
    /// Hypothesise the vertical faces below top faces' front edges that the planner missed,
    /// down to the table at this height (robot frame, m); `None`: do not.
    pub front_faces_to_table_z_m: Option<f64>,
    /// When no site is near the indicated point, look in the images for rear edges behind
    /// the vertical faces there (see `rear_edges_from_image`).
    pub rear_edges_from_image: bool,
    /// A grasp whose centre is farther than this from the indicated point (plan view) is
    /// not on the block the operator meant: no grasp then, m.
    pub max_distance_m: f64,
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
#[derive(Debug, Clone, Serialize, Deserialize)]
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

/// A grasp site, as the report shows it. One flat JSON object: the groups are flattened.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SiteSummary {
    pub plan_facet: usize,
    /// The site's facet was hypothesised below the top face `plan_facet`.
    pub hypothesised_facet: bool,
    #[serde(flatten)]
    pub grasp: SiteGrasp,
    #[serde(flatten)]
    pub place: SitePlace,
    /// Why it was rejected (`None` for a candidate).
    pub reason: Option<String>,
}

/// The grasp at a site: its width and, for a candidate, the tool pose.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SiteGrasp {
    pub width_mm: f64,
    pub tool_m: Option<[f64; 3]>,
    pub yaw_deg: Option<f64>,
}

/// Where a site is: robot frame, both views, and how far from the indicated point.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SitePlace {
    pub site_m: [f64; 3],
    pub centre_m: [f64; 3],
    pub site_left_px: [f64; 2],
    pub site_right_px: [f64; 2],
    /// Plan-view distance of the grasp centre from the indicated point, mm.
    pub distance_mm: Option<f64>,
}

/// What the planner found and decided (`plan.json`, and the outcome's `plan`). One flat
/// JSON object: the groups are flattened.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct PlanSummary {
    #[serde(flatten)]
    pub counts: PlannerCounts,
    #[serde(flatten)]
    pub scene: SceneRecord,
    #[serde(flatten)]
    pub sites: SiteRecord,
    #[serde(flatten)]
    pub inputs: PlanInputs,
    #[serde(flatten)]
    pub geometry: PlanGeometry,
    #[serde(flatten)]
    pub timing: PlanTiming,
}

/// How much the planner found: segments in each view, stereo matches, planes.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct PlannerCounts {
    pub segments: [usize; 2],
    pub matches: usize,
    pub planes: usize,
}

/// The grasp scene: the planner's facets and hypothesised faces, what was left out of it,
/// and the rear edges found in the images.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct SceneRecord {
    pub facets: Vec<FacetSummary>,
    /// Planner facets left out for a hypothesised face that covers them in both views.
    pub superseded_facets: Vec<usize>,
    /// Rear edges found in the images behind vertical faces near the indicated point:
    /// `(plan facet of the face, depth behind it in mm, edge support 0..1 in the weaker view)`.
    pub image_rear_edges: Vec<(usize, f64, f64)>,
}

/// The grasp sites: candidates, the chosen one, and what failed which rule.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct SiteRecord {
    /// The highest collision-free site of each facet that has one, preferred first.
    pub candidates: Vec<SiteSummary>,
    pub chosen: Option<SiteSummary>,
    /// Sites that failed a rule (with their place), and facets or edges that failed before a
    /// site existed (counted in `rejected_by_reason` only).
    pub rejected_sites: Vec<SiteSummary>,
    pub rejected_by_reason: BTreeMap<String, usize>,
    /// Facets and top edges that failed a rule before a site existed: `(plan facet, reason)`.
    pub facet_rejections: Vec<(usize, String)>,
}

/// What the planner was given besides the images: the indicated point and the gripper's mask.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct PlanInputs {
    pub indicated_m: Option<[f64; 3]>,
    /// Its one-sigma radius, m: present for a pointed point (absent: given as a coordinate,
    /// or a report written before it was kept).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub indicated_sigma_m: Option<f64>,
    /// The indicated point in both views, tracker pixels.
    pub indicated_px: Option<[[f64; 2]; 2]>,
    /// The gripper's masked region in both views, tracker pixels.
    pub masks_px: [Vec<[f64; 2]>; 2],
    pub masked_px: [usize; 2],
    /// The calibration's cage (tool positions, m, and the reference point's images, tracker
    /// pixels) and the tool-from-reference lever, m: with `model` and the saved pair
    /// (`plan_left.png`, `plan_right.png`, already masked) they are the whole geometry of
    /// the plan, so that it can be rerun from a run's report in seconds. Absent in reports
    /// written before they were kept.
    #[serde(default)]
    pub cage_robot_m: Vec<[f64; 3]>,
    #[serde(default)]
    pub cage_image_px: Vec<[f64; 4]>,
    #[serde(default)]
    pub lever_m: Option<[f64; 3]>,
    /// Features entirely above this height were taken for the arm, m (the parked tool's
    /// height less the clearance). Absent in older reports.
    #[serde(default)]
    pub max_height_m: Option<f64>,
}

/// The stereo geometry the planner used.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct PlanGeometry {
    /// The model the planner used (scene points to planner pixels: `handeye plan --calib`
    /// reads this object): `m` rows, `c`, `disparity_range_px`, `residual_rms_px`.
    pub model: Option<serde_json::Value>,
    /// Epipolar bootstrap: RMS before and after, px.
    pub bootstrap_rms_px: Option<[f64; 2]>,
    /// RMS residual of the pinhole cameras fitted to the cage (`None`: affine model only), px.
    pub projective_residual_px: Option<f64>,
}

/// How long the plan took: the planner alone and the whole plan, ms.
#[derive(Debug, Clone, Serialize, Deserialize, Default)]
pub struct PlanTiming {
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
    /// With no target: why the pointed block (the facets reconstructed near the indicated
    /// point) has no grasp the rules allow, in words, from this plan's own facets and
    /// rejections; `None` when nothing was reconstructed near the point, or when what was
    /// reconstructed fails only rules that say what the cameras saw (see `unjudged`).
    pub refusal: Option<String>,
    /// With no target and no refusal: the pointed block was seen, but not so that the grasp
    /// rules can judge it (only its top, only faces turned past the view-angle rule, or
    /// fingers hitting only its own other faces as reconstructed), in words. Not a refusal:
    /// the judge on true geometry may well find a grasp.
    pub unjudged: Option<String>,
    /// With no target: the pointed point does not pick one block (another block's site is
    /// nearly as near, within the point's uncertainty), in words. The operator is asked to
    /// point again; nothing was refused.
    pub ambiguous: Option<String>,
}

/// Why a pointed point `point_m` with one-sigma radius `sigma_m` does not pick the block of
/// the chosen site at `chosen_m`, given the sites on other objects (plan view, robot x, y,
/// m); `None`: it picks one (always for a point given as a coordinate, `sigma_m` 0).
///
/// The points nearer the chosen site than an other site `o` form a half-plane bounded by the
/// two sites' perpendicular bisector, which lies `(|p - o|² - |p - c|²) / (2 |o - c|)` from
/// the point. The point picks the block when every such bisector is `sigmas` sigmas away:
/// only an error that large, and towards that site, would make another block's site the
/// nearer. (The bound that each distance may change by the whole error, so that the other
/// site must be twice that farther, holds only when the two sites lie on opposite sides of
/// the point; it asked a point 47 mm from its L-block's site and 112 mm from a cube's, 13 mm
/// sigma, to point again, with the bisector 43 mm away.) Three sigmas by default, not one:
/// on rendered gestures the point has missed by up to three times its sigma where a finger's
/// line was biased (BENCHMARKS.md, Pointing).
///
/// ```
/// use handeye_daemon::planning::point_ambiguity;
/// // The chosen site 20 mm to one side of the point, another block's 60 mm to the other:
/// // the bisector lies 20 mm off, under three sigmas of 7 mm.
/// assert!(point_ambiguity([0.0, 0.0], [-0.02, 0.0], [[0.06, 0.0]].into_iter(), 0.007, 3.0).is_some());
/// // The same distances, the other site at right angles: its bisector lies 25 mm off.
/// assert!(point_ambiguity([0.0, 0.0], [-0.02, 0.0], [[0.0, 0.06]].into_iter(), 0.007, 3.0).is_none());
/// ```
pub fn point_ambiguity(point_m: [f64; 2], chosen_m: [f64; 2], others_m: impl Iterator<Item = [f64; 2]>, sigma_m: f64, sigmas: f64) -> Option<String> {
    if sigma_m <= 0.0 {
        return None;
    }
    let chosen_distance_m = geom::dist(point_m, chosen_m);
    // The other site whose bisector with the chosen one lies nearest the point; sites in one
    // place (on two objects) leave no margin at all.
    let (margin_m, other_distance_m) = others_m
        .map(|o| {
            let apart_m = geom::dist(o, chosen_m);
            let d = geom::dist(point_m, o);
            let margin_m = if apart_m > 1e-9 { (d * d - chosen_distance_m * chosen_distance_m) / (2.0 * apart_m) } else { 0.0 };
            (margin_m, d)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))?;
    (margin_m < sigmas * sigma_m).then(|| {
        format!(
            "the point does not pick one block: a site on another ({:.0} mm away, against {:.0} mm) would be the nearer were the point {:.0} mm off towards it, and the point's sigma is {:.1} mm",
            other_distance_m * 1e3,
            chosen_distance_m * 1e3,
            margin_m.max(0.0) * 1e3,
            sigma_m * 1e3
        )
    })
}

/// How far the point `point_m` (robot x, y) lies on the working plane from the nearest facet
/// the plan saw: from its outline seen from above (its corners' x, y: a vertical face's is a
/// line), 0 inside a top face's, m; `None` when no facet has corners.
pub fn nearest_facet_distance_m(facets: &[FacetSummary], point_m: [f64; 2]) -> Option<f64> {
    facets
        .iter()
        .filter_map(|f| f.corners_m.as_ref())
        .filter(|c| !c.is_empty())
        .map(|c| {
            let xy: Vec<[f64; 2]> = c.iter().map(|p| [p[0], p[1]]).collect();
            if geom::contains(&xy, point_m, 0.0) {
                return 0.0;
            }
            (0..xy.len()).map(|i| geom::point_segment_distance(point_m, xy[i], xy[(i + 1) % xy.len()])).fold(f64::INFINITY, f64::min)
        })
        .reduce(f64::min)
}

/// A short name for a rejection reason.
pub fn reason_name(r: &RejectReason) -> &'static str {
    match r {
        RejectReason::FacetNotVertical { .. } => "facet_not_vertical",
        RejectReason::TurnedFromViewer { .. } => "turned_from_cameras",
        RejectReason::NoTopEdge => "no_top_edge",
        RejectReason::TopEdgeTooSteep { .. } => "top_edge_too_steep",
        RejectReason::TopEdgeSlopeUnsettled { .. } => "top_edge_slope_unsettled",
        RejectReason::NoOverlap => "no_overlap",
        RejectReason::RearInFront { .. } => "rear_in_front",
        RejectReason::RearOutOfReach { .. } => "rear_out_of_reach",
        RejectReason::TooWide { .. } => "too_wide",
        RejectReason::FingerCollision { .. } => "finger_collision",
        RejectReason::BodyCollision { .. } => "body_collision",
        RejectReason::NotHighest => "not_highest",
        RejectReason::ThicknessUnmeasured => "thickness_unmeasured",
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
fn project_scene(geo: &EpipolarGeometry, model: &AffineStereo, lever_m: &[f64; 3], p: &Vector3<f64>) -> [[f64; 2]; 2] {
    let Some(cams) = &geo.projective else { return project(model, lever_m, p) };
    let h = p.push(1.0);
    let at = |cam: &nalgebra::Matrix3x4<f64>| {
        let x = cam * h;
        [x[0] / x[2] - PLANNER_FROM_TRACKER_PX, x[1] / x[2] - PLANNER_FROM_TRACKER_PX]
    };
    [at(&cams.left), at(&cams.right)]
}

fn to_tracker_px(p: [f64; 2]) -> [f64; 2] {
    [p[0] - PLANNER_FROM_TRACKER_PX, p[1] - PLANNER_FROM_TRACKER_PX]
}

/// Rear edges found in the images, for the vertical faces near the indicated point whose top
/// edge pairs with nothing (the planner reconstructed the top face behind it off, or missed
/// it). A block's top face is horizontal at its front face's top edge; its far edge is a
/// line at that height, parallel to the top edge, some depth behind it, that both images
/// show as a step (the top face is lit, what lies behind is not the same grey). Depths from
/// `MIN_DEPTH_M` to the widest grasp plus 5 mm are tried in 1 mm steps, and the far edge is
/// the strongest step past the front edge's own ([`rear_edge::far_edge`]). The edge
/// joins the face's object, and a top face with that outline supersedes planner facets of
/// the object it covers in both views (misplaced, they would stand in the fingers' way) or
/// that stand above it over its footprint ([`rear_edge::stands_above_top`]).
/// Returns how many edges were added.
fn rear_edges_from_image(
    ps: &mut handeye_vision::grasp::PlannedScene,
    project: &dyn Fn(&Vector3<f64>) -> [[f64; 2]; 2],
    images: &[ImageBuf; 2],
    indicated: &Vector3<f64>,
    max_distance_m: f64,
    max_width_m: f64,
    summary: &mut PlanSummary,
) -> usize {
    const MIN_DEPTH_M: f64 = 0.008;
    // A far edge deeper than the widest grasp (plus the reconstruction's few millimetres)
    // could not be grasped across anyway.
    let max_depth_m = max_width_m + 0.005;
    let toward = ps.scene.toward_viewer;
    let mut added = Vec::new();
    for (k, f) in ps.scene.facets.iter().enumerate() {
        let n = f.polygon_m.len();
        let Some(mut normal) = (0..n).map(|i| f.polygon_m[i].cross(&f.polygon_m[(i + 1) % n])).sum::<Vector3<f64>>().try_normalize(1e-12) else { continue };
        if normal.dot(&toward) < 0.0 {
            normal = -normal;
        }
        if normal.z.abs() > 20f64.to_radians().sin() {
            continue;
        }
        let centroid = f.polygon_m.iter().sum::<Vector3<f64>>() / n as f64;
        if (centroid.xy() - indicated.xy()).norm() > max_distance_m + 0.03 {
            continue;
        }
        let back = -Vector3::new(normal.x, normal.y, 0.0).normalize();
        // The top edge: the highest side within 30° of horizontal, at least 10 mm long.
        let top = (0..n)
            .map(|i| (f.polygon_m[i], f.polygon_m[(i + 1) % n]))
            .filter(|(a, b)| (b - a).norm() >= 0.010 && ((b.z - a.z).abs() / (b - a).norm()) <= 30f64.to_radians().sin())
            .max_by(|x, y| (x.0.z + x.1.z).total_cmp(&(y.0.z + y.1.z)));
        let Some((a, b)) = top else { continue };
        // Along the edge's middle 70 % (its ends meet other faces' edges).
        let (a_in, b_in) = (a + 0.15 * (b - a), b - 0.15 * (b - a));
        let sample_at = |d: f64| {
            let (pa, pb) = (project(&(a_in + back * d)), project(&(b_in + back * d)));
            let (fa, fb) = (project(&a_in), project(&b_in));
            let offset = |k: usize| ((pa[k][0] + pb[k][0] - fa[k][0] - fb[k][0]) / 2.0).hypot((pa[k][1] + pb[k][1] - fa[k][1] - fb[k][1]) / 2.0);
            rear_edge::DepthSample {
                support: edge_support(&images[0], pa[0], pb[0]).min(edge_support(&images[1], pa[1], pb[1])),
                strength_grey: pixels::edge_strength(&images[0], pa[0], pb[0]).min(pixels::edge_strength(&images[1], pa[1], pb[1])),
                offset_px: offset(0).min(offset(1)),
            }
        };
        let steps = ((max_depth_m - MIN_DEPTH_M) * 1e3).round().max(0.0) as usize;
        let depths: Vec<f64> = (0..=steps).map(|i| MIN_DEPTH_M + i as f64 * 1e-3).collect();
        let profile: Vec<rear_edge::DepthSample> = depths.iter().map(|&d| sample_at(d)).collect();
        tracing::debug!(
            plan_facet = ps.facets[k].plan_facet,
            profile = ?depths.iter().zip(&profile).map(|(d, s)| format!("{:.0}mm {:.1}px s{:.2} g{:.0}", d * 1e3, s.offset_px, s.support, s.strength_grey)).collect::<Vec<_>>(),
            "rear-edge profile"
        );
        let Some(i) = rear_edge::far_edge(&profile) else { continue };
        let (d, support) = (MIN_DEPTH_M + i * 1e-3, profile[i.round() as usize].support);
        let (ra, rb) = (a + back * d, b + back * d);
        let top_face = [a, b, rb, ra].map(|p| project(&p));
        added.push((k, f.component, handeye_vision::grasp::Segment3::new(ra, rb), top_face, [a, b, rb, ra], d, support));
    }
    let count = added.len();
    let mut drop = vec![false; ps.scene.facets.len()];
    for (k, component, segment, top_face, top_m, d, support) in added {
        summary.scene.image_rear_edges.push((ps.facets[k].plan_facet, d * 1e3, support));
        ps.scene.edges.push(handeye_vision::grasp::SceneEdge { segment, component });
        ps.edge_matches.push(IMAGE_REAR_EDGE);
        let left: Vec<[f64; 2]> = top_face.iter().map(|p| [p[0][0] + PLANNER_FROM_TRACKER_PX, p[0][1] + PLANNER_FROM_TRACKER_PX]).collect();
        let right: Vec<[f64; 2]> = top_face.iter().map(|p| [p[1][0] + PLANNER_FROM_TRACKER_PX, p[1][1] + PLANNER_FROM_TRACKER_PX]).collect();
        for (j, (src, facet)) in ps.facets.iter().zip(&ps.scene.facets).enumerate() {
            let covered = geom::covered_share(&src.left_px, &left) >= SUPERSEDED_SHARE && geom::covered_share(&src.right_px, &right) >= SUPERSEDED_SHARE;
            if j != k && !src.hypothesised && facet.component == component && (covered || rear_edge::stands_above_top(&facet.polygon_m, &top_m)) {
                drop[j] = true;
            }
        }
    }
    for j in (0..drop.len()).rev() {
        if drop[j] {
            summary.scene.superseded_facets.push(ps.facets[j].plan_facet);
            *summary.sites.rejected_by_reason.entry("superseded_by_image_top_face".into()).or_insert(0) += 1;
            ps.facets.remove(j);
            ps.scene.facets.remove(j);
        }
    }
    count
}

/// The faces of planner facets dropped below the table, rebuilt from one view standing on the
/// table and checked in the other ([`one_view_face`]): left view first, then right. Each
/// joins the scene as a face of its own object (hypothesised, from `plan_facet`).
#[allow(clippy::too_many_arguments)]
fn faces_from_one_view(
    ps: &mut handeye_vision::grasp::PlannedScene,
    plan: &handeye_vision::planner::Plan,
    dropped: &[usize],
    cams: &handeye_vision::planner::projective::ProjectiveStereo,
    images: &[ImageBuf; 2],
    table_z_m: f64,
    max_height_m: f64,
    summary: &mut PlanSummary,
) {
    let project = |cam: &nalgebra::Matrix3x4<f64>, p: &Vector3<f64>| {
        let x = cam * p.push(1.0);
        [x[0] / x[2], x[1] / x[2]]
    };
    let mut next_component = ps.scene.facets.iter().map(|f| f.component).chain(ps.scene.edges.iter().map(|e| e.component)).max().map_or(0, |c| c + 1);
    for &fi in dropped {
        let facet = &plan.facets[fi].facet;
        let views = [(&cams.left, &facet.left, &cams.right, 1usize), (&cams.right, &facet.right, &cams.left, 0usize)];
        let found = views.iter().find_map(|(cam, poly, other_cam, other)| {
            let face = one_view_face::face_on_table(cam, poly, table_z_m, max_height_m)?;
            let other_px = face.map(|p| to_tracker_px(project(other_cam, &p)));
            let seen = one_view_face::seen_in_other_view(&images[*other], &other_px);
            let sides: Vec<f64> = (0..4).map(|i| edge_support(&images[*other], other_px[i], other_px[(i + 1) % 4])).collect();
            tracing::debug!(plan_facet = fi, ?face, ?other_px, ?sides, seen, "a face from one view");
            seen.then_some(face)
        });
        let Some(face) = found else { continue };
        let polygon_m = face.to_vec();
        let edges = (0..4).map(|e| handeye_vision::grasp::Segment3::new(polygon_m[e], polygon_m[(e + 1) % 4])).collect();
        ps.scene.facets.push(handeye_vision::grasp::SceneFacet { polygon_m, edges, component: next_component });
        ps.facets.push(handeye_vision::grasp::FacetSource {
            plan_facet: fi,
            hypothesised: true,
            left_px: face.iter().map(|p| project(&cams.left, p)).collect(),
            right_px: face.iter().map(|p| project(&cams.right, p)).collect(),
            steps_onto: None,
        });
        next_component += 1;
        *summary.sites.rejected_by_reason.entry("face_from_one_view".into()).or_insert(0) += 1;
    }
}

fn arr3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// Runs the plan (see the module docs).
pub fn plan(mut req: PlanRequest) -> PlanOutput {
    let start = Instant::now();
    let mut summary = PlanSummary {
        inputs: PlanInputs {
            indicated_m: req.scene.indicated_m,
            indicated_sigma_m: (req.scene.indicated_sigma_m > 0.0).then_some(req.scene.indicated_sigma_m),
            indicated_px: req.scene.indicated_m.map(|p| project(&req.calibration.model, &req.calibration.lever_m, &Vector3::from(p))),
            masks_px: req.masks.clone(),
            cage_robot_m: req.calibration.cage_robot_m.iter().map(arr3).collect(),
            cage_image_px: req.calibration.cage_image_px.clone(),
            lever_m: Some(req.calibration.lever_m),
            max_height_m: Some(req.scene.max_height_m),
            ..Default::default()
        },
        ..Default::default()
    };
    for (k, img) in req.images.iter_mut().enumerate() {
        summary.inputs.masked_px[k] = mask_and_fill(img, &req.masks[k], req.mask_margin_px);
    }
    let scene_model = scene_model(&req.calibration.model, &req.calibration.lever_m);
    summary.geometry.model = Some(serde_json::json!({
        "m": (0..4).map(|r| [scene_model.m[(r, 0)], scene_model.m[(r, 1)], scene_model.m[(r, 2)]]).collect::<Vec<_>>(),
        "c": [scene_model.c[0], scene_model.c[1], scene_model.c[2], scene_model.c[3]],
        "disparity_range_px": scene_model.disparity_range_px,
        "residual_rms_px": scene_model.residual_rms_px,
    }));
    let toward = req.calibration.model.toward_cameras();
    // Pinhole cameras from the cage, for metric reconstruction: a scene point P images where
    // the reference point does with the tool at P + L, so the cage points become the
    // reference point's own positions, X_tool − L, seen at the planner's pixels.
    let lever = Vector3::from(req.calibration.lever_m);
    let points: Vec<Vector3<f64>> = req.calibration.cage_robot_m.iter().map(|x| x - lever).collect();
    let images: Vec<[f64; 4]> = req.calibration.cage_image_px.iter().map(|w| w.map(|v| v + PLANNER_FROM_TRACKER_PX)).collect();
    let model_residual_px = scene_model.residual_rms_px;
    let mut geo = EpipolarGeometry::from_model(scene_model, req.disparity_margin, req.disparity_margin_px);
    if points.len() >= handeye_vision::planner::projective::MIN_POINTS {
        geo.projective = handeye_vision::planner::projective::ProjectiveStereo::fit(&points, &images).ok();
        // Match along the cameras' own epipolar lines, not only the cage's linear constraint
        // (blocks near the image edges, below the cage, are off it by more than the tolerance).
        let z = req.scene.table_z_m;
        let rms = geo.correct_from_cameras(req.images[0].width, req.images[0].height, &[z, z + 0.03, z + 0.06]);
        tracing::debug!(?rms, "epipolar correction from the pinhole cameras");
    }
    summary.geometry.projective_residual_px = geo.projective.as_ref().map(|p| p.residual_rms_px);
    let t0 = Instant::now();
    let plan = Planner::new(req.planner).plan(&req.images[0].view(), &req.images[1].view(), &geo);
    summary.timing.planner_ms = t0.elapsed().as_secs_f64() * 1e3;
    summary.counts.segments = [plan.left_segments.len(), plan.right_segments.len()];
    summary.counts.matches = plan.matches.len();
    summary.counts.planes = plan.planes.len();
    summary.geometry.bootstrap_rms_px = plan.bootstrap.map(|b| [b.rms_before_px, b.rms_after_px]);
    let mut ps = scene_from_plan(&plan, toward, req.scene.max_height_m, req.scene.join_m);
    // A facet reaching well below the table is a false match, not a block (the corners of a
    // face matched to the wrong edges in the other view): its "steep top edge" would refuse
    // a block for a slope it does not have.
    let mut k = 0;
    let mut below_table = Vec::new();
    while k < ps.facets.len() {
        if ps.scene.facets[k].polygon_m.iter().any(|p| p.z < req.scene.table_z_m - BELOW_TABLE_M) {
            below_table.push(ps.facets[k].plan_facet);
            ps.facets.remove(k);
            ps.scene.facets.remove(k);
            *summary.sites.rejected_by_reason.entry("below_table".into()).or_insert(0) += 1;
        } else {
            k += 1;
        }
    }
    let planned_facets = ps.facets.len();
    if let Some(table_z) = req.scene.front_faces_to_table_z_m {
        let project = |p: &Vector3<f64>| {
            let px = project_scene(&geo, &req.calibration.model, &req.calibration.lever_m, p);
            let ok = px.iter().flatten().all(|v| v.is_finite());
            ok.then(|| px.map(|q| [q[0] + PLANNER_FROM_TRACKER_PX, q[1] + PLANNER_FROM_TRACKER_PX]))
        };
        hypothesise_front_faces(&mut ps, &project, table_z, 0.01, 20f64.to_radians(), req.grasp.max_view_angle_rad, 1.5 * req.scene.join_m);
        // A hypothesised face must show its bottom edge, against the table, in both views,
        // near where the model projects it (the model is extrapolated below the cage and
        // may be a few pixels off there): one hung from a top edge where the block does not
        // go straight down (the tall leg of an L over its low leg) has none there. Its image
        // outline's bottom corners go where the edge is, for the target trackers.
        let mut k = planned_facets;
        while k < ps.facets.len() {
            let src = &ps.facets[k];
            let offsets: Option<Vec<[f64; 2]>> = [(&req.images[0], &src.left_px), (&req.images[1], &src.right_px)]
                .iter()
                .map(|(img, poly)| bottom_edge_offset(img, &poly.iter().copied().map(to_tracker_px).collect::<Vec<_>>(), 0.6))
                .collect();
            if let Some(offsets) = offsets {
                let src = &mut ps.facets[k];
                for (poly, off) in [&mut src.left_px, &mut src.right_px].into_iter().zip(offsets) {
                    for corner in poly.iter_mut().take(2) {
                        *corner = [corner[0] + off[0], corner[1] + off[1]];
                    }
                }
                k += 1;
            } else {
                ps.facets.remove(k);
                ps.scene.facets.remove(k);
                *summary.sites.rejected_by_reason.entry("hypothesised_face_unseen".into()).or_insert(0) += 1;
            }
        }
        // A face seen from a top down to a lower top in front of it (an L-block's step, see
        // `hypothesise_front_faces`) is the join between the two: one object. Without it the
        // L's two legs are two blocks, and a grasp across the whole L sees the tall leg as
        // another block in the rear finger's way.
        let mut merges: Vec<(usize, usize)> =
            ps.facets[planned_facets..].iter().zip(&ps.scene.facets[planned_facets..]).filter_map(|(src, f)| src.steps_onto.map(|c| (c, f.component))).collect();
        while let Some((from, to)) = merges.pop() {
            if from == to {
                continue;
            }
            for c in ps.scene.facets.iter_mut().map(|f| &mut f.component).chain(ps.scene.edges.iter_mut().map(|e| &mut e.component)) {
                if *c == from {
                    *c = to;
                }
            }
            for m in merges.iter_mut().flat_map(|(a, b)| [a, b]) {
                if *m == from {
                    *m = to;
                }
            }
            *summary.sites.rejected_by_reason.entry("tops_joined_by_a_step".into()).or_insert(0) += 1;
        }
        // A hypothesised face (anchored on a top face's edge and the table, its bottom edge
        // seen) that covers a planner facet of the same object in both images is that
        // facet's surface: the planner reconstructed it off the face (else the face would
        // not have been hypothesised, see `hypothesise_front_faces`), and its misplaced
        // corners would stand in the fingers' way. The planner facet is left out.
        let mut j = 0;
        let mut hypothesised_start = planned_facets;
        while j < hypothesised_start {
            let (src, facet) = (&ps.facets[j], &ps.scene.facets[j]);
            let superseded = (hypothesised_start..ps.facets.len()).any(|k| {
                ps.scene.facets[k].component == facet.component
                    && geom::covered_share(&src.left_px, &ps.facets[k].left_px) >= SUPERSEDED_SHARE
                    && geom::covered_share(&src.right_px, &ps.facets[k].right_px) >= SUPERSEDED_SHARE
            });
            if superseded {
                summary.scene.superseded_facets.push(src.plan_facet);
                ps.facets.remove(j);
                ps.scene.facets.remove(j);
                hypothesised_start -= 1;
                *summary.sites.rejected_by_reason.entry("superseded_by_hypothesised_face".into()).or_insert(0) += 1;
            } else {
                j += 1;
            }
        }
    }
    if let (Some(table_z), Some(cams)) = (req.scene.front_faces_to_table_z_m, &geo.projective) {
        faces_from_one_view(&mut ps, &plan, &below_table, cams, &req.images, table_z, req.scene.max_height_m, &mut summary);
    }
    let s = PLANNER_FROM_TRACKER_PX;
    let to_tracker = |p: &[[f64; 2]]| -> Vec<[f64; 2]> { p.iter().map(|q| [q[0] - s, q[1] - s]).collect() };
    for (fi, f) in plan.facets.iter().enumerate() {
        let component = ps.facets.iter().position(|src| !src.hypothesised && src.plan_facet == fi).map(|k| ps.scene.facets[k].component);
        summary.scene.facets.push(FacetSummary {
            plan_facet: fi,
            left_px: to_tracker(&f.facet.left),
            right_px: to_tracker(&f.facet.right),
            corners_m: f.corners_robot_m.clone(),
            component,
            hypothesised: false,
        });
    }
    // Hypothesised faces: after the superseded planner facets went, they no longer start at
    // `planned_facets`.
    for (k, src) in ps.facets.iter().enumerate().filter(|(_, src)| src.hypothesised) {
        summary.scene.facets.push(FacetSummary {
            plan_facet: src.plan_facet,
            left_px: to_tracker(&src.left_px),
            right_px: to_tracker(&src.right_px),
            corners_m: Some(ps.scene.facets[k].polygon_m.iter().map(arr3).collect()),
            component: Some(ps.scene.facets[k].component),
            hypothesised: true,
        });
    }
    let indicated = req.scene.indicated_m.map(Vector3::from);
    // The rules' measures get their error from the calibrated model's residuals (the pinhole
    // cameras' when fitted: they reconstruct the scene; else the affine model's) and the
    // segments' fit, at the indicated point's depth ([`point_sigma_m`]).
    let at = indicated.unwrap_or_else(|| Vector3::new(0.0, 0.0, req.scene.table_z_m));
    req.grasp.indicated_sigma_m = req.scene.indicated_sigma_m;
    req.grasp.point_sigma_m = point_sigma_m(summary.geometry.projective_residual_px.unwrap_or(model_residual_px), &|q| project_scene(&geo, &req.calibration.model, &req.calibration.lever_m, q), &at);
    tracing::debug!(point_sigma_mm = req.grasp.point_sigma_m * 1e3, "height error of a reconstructed point");
    let mut grasps = match plan_grasps(&ps.scene, indicated.as_ref(), &req.grasp) {
        Ok(g) => g,
        Err(e) => {
            summary.sites.rejected_by_reason.insert(format!("invalid scene: {e}"), 1);
            summary.timing.total_ms = start.elapsed().as_secs_f64() * 1e3;
            return PlanOutput { summary, target: None, alternatives: Vec::new(), images: req.images, refusal: None, unjudged: None, ambiguous: None };
        }
    };
    // No site near the point, or only zero-width ones (the thesis's thin wall; among
    // blocks, a top face the planner missed): look in the images for the rear edges behind
    // the vertical faces there (see `rear_edges_from_image`) and plan again.
    let near_point = |g: &Grasp, p: &Vector3<f64>| (g.site.centre_m.xy() - p.xy()).norm() <= req.scene.max_distance_m;
    if req.scene.rear_edges_from_image
        && let Some(p) = indicated
        && !grasps.candidates.iter().any(|g| near_point(g, &p) && g.site.width_m >= MIN_SOLID_WIDTH_M)
    {
        let project = |q: &Vector3<f64>| project_scene(&geo, &req.calibration.model, &req.calibration.lever_m, q);
        let found = rear_edges_from_image(&mut ps, &project, &req.images, &p, req.scene.max_distance_m, req.grasp.gripper.max_width_m, &mut summary);
        if found > 0
            && let Ok(g) = plan_grasps(&ps.scene, indicated.as_ref(), &req.grasp)
        {
            grasps = g;
        }
    }
    let site_summary = |g: Option<&Grasp>, site: &handeye_vision::grasp::GraspSite, reason: Option<String>| {
        let px = project_scene(&geo, &req.calibration.model, &req.calibration.lever_m, &site.front_m);
        SiteSummary {
            plan_facet: ps.facets[site.facet].plan_facet,
            hypothesised_facet: ps.facets[site.facet].hypothesised,
            grasp: SiteGrasp { width_mm: site.width_m * 1e3, tool_m: g.map(|g| arr3(&g.tool_m)), yaw_deg: g.map(|g| g.yaw_rad.to_degrees()) },
            place: SitePlace {
                site_m: arr3(&site.front_m),
                centre_m: arr3(&site.centre_m),
                site_left_px: px[0],
                site_right_px: px[1],
                distance_mm: indicated.map(|p| (site.centre_m.xy() - p.xy()).norm() * 1e3),
            },
            reason,
        }
    };
    for r in &grasps.rejected {
        let name = reason_name(&r.reason);
        *summary.sites.rejected_by_reason.entry(name.to_string()).or_insert(0) += 1;
        if r.site.is_none() {
            let detail = match r.reason {
                RejectReason::FacetNotVertical { tilt_rad } => format!("{name} ({:.0}°)", tilt_rad.to_degrees()),
                RejectReason::TurnedFromViewer { angle_rad } => format!("{name} ({:.0}°)", angle_rad.to_degrees()),
                RejectReason::TopEdgeTooSteep { slope_rad } => format!("{name} ({:.0}°)", slope_rad.to_degrees()),
                RejectReason::TopEdgeSlopeUnsettled { slope_rad, error_rad } => format!("{name} ({:.0}° ± {:.0}°)", slope_rad.to_degrees(), error_rad.to_degrees()),
                _ => name.to_string(),
            };
            summary.sites.facet_rejections.push((ps.facets[r.facet].plan_facet, detail));
        }
        if let Some(site) = &r.site {
            let detail = match r.reason {
                RejectReason::FingerCollision { feature } | RejectReason::BodyCollision { feature } => {
                    let what = match feature {
                        FeatureRef::Facet(i) => format!("facet {}", ps.facets[i].plan_facet),
                        FeatureRef::Edge(EdgeRef::Facet { facet, .. }) => format!("an edge of facet {}", ps.facets[facet].plan_facet),
                        FeatureRef::Edge(EdgeRef::Loose(i)) => match ps.edge_matches.get(i) {
                            Some(&m) if m != IMAGE_REAR_EDGE => format!("edge {m}"),
                            _ => "a rear edge found in the images".to_string(),
                        },
                    };
                    format!("{name} with {what}")
                }
                RejectReason::TooWide { width_m } => format!("{name} ({:.0} mm)", width_m * 1e3),
                _ => name.to_string(),
            };
            summary.sites.rejected_sites.push(site_summary(None, site, Some(detail)));
        }
    }
    summary.sites.candidates = grasps.candidates.iter().map(|g| site_summary(Some(g), &g.site, None)).collect();
    // The block nearest the point has no grasp site if the nearest site is far from it.
    let near = |g: &Grasp| indicated.is_none_or(|p| (g.site.centre_m.xy() - p.xy()).norm() <= req.scene.max_distance_m);
    let mut chosen = grasps.chosen.filter(near);
    // A pointed point must pick one block: no site on another object may become the nearer
    // within the point's uncertainty (`point_ambiguity`).
    let ambiguous = chosen.as_ref().zip(indicated.as_ref()).and_then(|(g, p)| {
        let object = |g: &Grasp| ps.scene.facets.get(g.site.facet).map(|f| f.component);
        let xy = |g: &Grasp| [g.site.centre_m.x, g.site.centre_m.y];
        let others = grasps.candidates.iter().filter(|c| object(c) != object(g)).map(xy);
        point_ambiguity([p.x, p.y], xy(g), others, req.scene.indicated_sigma_m, req.scene.ambiguity_sigmas)
    });
    if ambiguous.is_some() {
        summary.sites.rejected_by_reason.insert("ambiguous_point".into(), grasps.candidates.len());
        chosen = None;
    }
    if grasps.chosen.is_some() && chosen.is_none() {
        summary.sites.rejected_by_reason.insert("far_from_indicated_point".into(), grasps.candidates.len());
    }
    summary.sites.chosen = chosen.as_ref().and_then(|_| summary.sites.candidates.first().cloned());
    let planned = |g: &Grasp| {
        let src = &ps.facets[g.site.facet];
        let cyclopean: Vec<[f64; 2]> = src.left_px.iter().zip(&src.right_px).map(|(l, r)| [(l[0] + r[0]) / 2.0, (l[1] + r[1]) / 2.0]).collect();
        let keep = tracker_order(&cyclopean, &simplify_closed(&cyclopean, 1.5));
        let pick = |poly: &[[f64; 2]]| -> Vec<[f64; 2]> { keep.iter().map(|&i| [poly[i][0] - s, poly[i][1] - s]).collect() };
        PlannedTarget {
            left_px: pick(&src.left_px),
            right_px: pick(&src.right_px),
            width_m: g.site.width_m.max(0.0),
            site_px: project_scene(&geo, &req.calibration.model, &req.calibration.lever_m, &g.site.front_m),
            site_m: arr3(&g.site.front_m),
            tool_m: arr3(&g.tool_m),
        }
    };
    let target = chosen.as_ref().map(planned);
    let alternatives: Vec<PlannedTarget> = if chosen.is_some() { grasps.candidates.iter().skip(1).filter(|g| near(g)).map(planned).collect() } else { Vec::new() };
    let verdict = if target.is_none() && ambiguous.is_none() { pointed_block_verdict(&ps, &grasps.rejected, indicated.as_ref(), &req.grasp, req.scene.max_distance_m) } else { None };
    let (refusal, unjudged) = match verdict {
        Some(PointedBlock::Refused(why)) => (Some(why), None),
        Some(PointedBlock::Unjudged(why)) => (None, Some(why)),
        None => (None, None),
    };
    summary.timing.total_ms = start.elapsed().as_secs_f64() * 1e3;
    PlanOutput { summary, target, alternatives, images: req.images, refusal, unjudged, ambiguous }
}

/// How far an edge detector's segment end may lie off the true edge across it, pixels: the
/// segments' fit. Added (in quadrature) to the calibrated model's residual.
const SEGMENT_FIT_PX: f64 = 0.5;

/// One-sigma error of a reconstructed point's height near `at`, metres: the pixel error
/// (model residual and segment fit) over how many pixels a centimetre of height moves the
/// point in the view that sees height best. Not finite or no parallax: a large error, so
/// that no rule is settled on it.
fn point_sigma_m(residual_px: f64, project: &dyn Fn(&Vector3<f64>) -> [[f64; 2]; 2], at: &Vector3<f64>) -> f64 {
    let error_px = (residual_px.max(0.0).powi(2) + SEGMENT_FIT_PX.powi(2)).sqrt();
    let (a, b) = (project(at), project(&(at + Vector3::new(0.0, 0.0, 0.01))));
    let px_per_m = (0..2).map(|k| ((b[k][0] - a[k][0]).powi(2) + (b[k][1] - a[k][1]).powi(2)).sqrt() / 0.01).fold(0.0, f64::max);
    if !(px_per_m.is_finite() && px_per_m > 1.0) {
        return 0.01;
    }
    error_px / px_per_m
}

/// What the plan says of the pointed block when it has no grasp.
#[derive(Debug, Clone, PartialEq)]
enum PointedBlock {
    /// It fails rules the judge on true geometry also applies: a refusal, with why.
    Refused(String),
    /// Only what was seen of it fails (no vertical face, no top edge, faces turned from the
    /// cameras): what was seen, in words.
    Unjudged(String),
}

/// Why the pointed block has no grasp, in words ([`why_no_grasp`]): the block is the
/// connected component of the facet whose centre lies nearest the indicated point in plan
/// view, within `max_distance_m` (without a point, every facet). `None` when no facet is
/// that near: nothing was seen there, which is not a refusal but a failure to see. A
/// refusal only when a facet of the block fails a rule the judge also applies
/// ([`refusal_grounded`]); a block seen only from the top, or only by faces the view-angle
/// rule leaves out, is [`PointedBlock::Unjudged`].
fn pointed_block_verdict(ps: &PlannedScene, rejected: &[Rejection], indicated: Option<&Vector3<f64>>, config: &GraspConfig, max_distance_m: f64) -> Option<PointedBlock> {
    let facets = &ps.scene.facets;
    let component = match indicated {
        Some(p) => {
            let centre = |k: usize| facets[k].polygon_m.iter().sum::<Vector3<f64>>() / facets[k].polygon_m.len().max(1) as f64;
            let (distance_m, k) = (0..facets.len()).map(|k| ((centre(k).xy() - p.xy()).norm(), k)).min_by(|a, b| a.0.total_cmp(&b.0))?;
            if distance_m > max_distance_m {
                return None;
            }
            Some(facets[k].component)
        }
        None if facets.is_empty() => return None,
        None => None,
    };
    let name = |k: usize| component.is_none_or(|c| facets[k].component == c).then(|| format!("facet {}", ps.facets[k].plan_facet));
    let why = why_no_grasp(rejected, name, config);
    if refusal_grounded(&ps.scene, rejected, name) {
        return Some(PointedBlock::Refused(why));
    }
    // A wedge whose slope faces the cameras: its sloping top, seen, settles it.
    let sloping = (0..facets.len()).filter(|&k| name(k).is_some()).filter_map(|k| sloping_top_rad(&ps.scene, k, config)).reduce(f64::min);
    Some(match sloping {
        Some(slope_rad) => PointedBlock::Refused(format!(
            "its top edges slope {:.0}°, more than {:.0}° (its top face, seen)",
            slope_rad.to_degrees(),
            config.max_edge_slope_rad.to_degrees()
        )),
        None => PointedBlock::Unjudged(why),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pointed_point_picks_a_block_only_with_a_margin_of_its_uncertainty() {
        // The point at the origin, the chosen site 20 mm along -x; other objects' sites 60 mm
        // away: straight across (the bisector at x = 20 mm: 20 mm off), at right angles
        // (25.3 mm off) or behind the chosen one (x = -40 mm: 40 mm off).
        let (p, c) = ([0.0, 0.0], [-20e-3, 0.0]);
        let far = [0.0, -95e-3];
        let across = || [[60e-3, 0.0], far].into_iter();
        let beside = || [[0.0, 60e-3], far].into_iter();
        let behind = || [[-60e-3, 0.0], far].into_iter();
        assert_eq!(point_ambiguity(p, c, across(), 0.0, 3.0), None, "a given point is never ambiguous");
        assert_eq!(point_ambiguity(p, c, across(), 6e-3, 3.0), None, "20 mm > 3 sigma of 6 mm");
        let why = point_ambiguity(p, c, across(), 7e-3, 3.0).expect("20 mm < 3 sigma of 7 mm");
        assert!(why.contains("(60 mm away, against 20 mm)") && why.contains("20 mm off") && why.contains("7.0 mm"), "{why}");
        // Beside or behind, the same distances leave more margin: the old bound (the other
        // site 6 sigma farther: 40 mm against 48) asked both of these to point again.
        assert_eq!(point_ambiguity(p, c, beside(), 8e-3, 3.0), None, "25.3 mm > 3 sigma of 8 mm");
        assert!(point_ambiguity(p, c, beside(), 9e-3, 3.0).is_some(), "25.3 mm < 3 sigma of 9 mm");
        assert_eq!(point_ambiguity(p, c, behind(), 13e-3, 3.0), None, "40 mm > 3 sigma of 13 mm");
        assert!(point_ambiguity(p, c, behind(), 14e-3, 3.0).is_some(), "40 mm < 3 sigma of 14 mm");
        // The nearest bisector counts, not the nearest site: one 65 mm away straight across
        // (22.5 mm off) is the closer call than one 60 mm away at right angles (25.3 mm).
        let why = point_ambiguity(p, c, [[0.0, 60e-3], [65e-3, 0.0]].into_iter(), 8e-3, 3.0).expect("22.5 mm < 24 mm");
        assert!(why.contains("(65 mm away, against 20 mm)"), "{why}");
        // A site on another object in the chosen site's place: no margin at all.
        assert!(point_ambiguity(p, c, [c].into_iter(), 1e-3, 3.0).is_some());
        // No site on another object: nothing to confuse it with.
        assert_eq!(point_ambiguity(p, c, std::iter::empty(), 50e-3, 3.0), None);
    }

    #[test]
    fn a_point_is_measured_to_the_nearest_facet_seen_from_above() {
        let facet = |corners: Vec<[f64; 3]>| FacetSummary { plan_facet: 0, left_px: vec![], right_px: vec![], corners_m: Some(corners), component: None, hypothesised: false };
        // A 40 mm top face at (0.40..0.44, 0..0.04) and a vertical face along x = 0.30.
        let top = facet(vec![[0.40, 0.0, 0.1], [0.44, 0.0, 0.1], [0.44, 0.04, 0.1], [0.40, 0.04, 0.1]]);
        let side = facet(vec![[0.30, -0.02, 0.06], [0.30, 0.02, 0.06], [0.30, 0.02, 0.1], [0.30, -0.02, 0.1]]);
        let near = |p: [f64; 2]| nearest_facet_distance_m(&[top.clone(), side.clone()], p).unwrap();
        assert_eq!(near([0.42, 0.02]), 0.0, "inside the top face");
        assert!((near([0.50, 0.02]) - 0.06).abs() < 1e-12, "60 mm beside the top face: {}", near([0.50, 0.02]));
        assert!((near([0.33, 0.0]) - 0.03).abs() < 1e-12, "30 mm in front of the side face: {}", near([0.33, 0.0]));
        assert_eq!(nearest_facet_distance_m(&[facet(vec![])], [0.0, 0.0]), None);
    }

    #[test]
    fn a_points_height_error_is_the_pixel_error_over_the_pixels_a_height_moves_it() {
        // 1000 px a metre of height in the left view, 600 in the right: the left one counts.
        let project = |q: &Vector3<f64>| [[0.0, -1000.0 * q.z], [0.0, -600.0 * q.z]];
        let sigma_m = point_sigma_m(0.5, &project, &Vector3::zeros());
        let expected_m = (0.5f64.powi(2) + SEGMENT_FIT_PX.powi(2)).sqrt() / 1000.0;
        assert!((sigma_m - expected_m).abs() < 1e-9, "{sigma_m} vs {expected_m}");
        // No parallax (or no finite projection): an error so large that no rule settles.
        assert!(point_sigma_m(0.5, &|_: &Vector3<f64>| [[1.0, 1.0], [1.0, 1.0]], &Vector3::zeros()) >= 0.01);
        assert!(point_sigma_m(0.5, &|_: &Vector3<f64>| [[f64::NAN, 0.0], [0.0, 0.0]], &Vector3::zeros()) >= 0.01);
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

#[cfg(test)]
mod json_shape_tests {
    use super::*;

    fn sorted_keys(value: &serde_json::Value) -> Vec<String> {
        let mut keys: Vec<String> = value.as_object().unwrap().keys().cloned().collect();
        keys.sort();
        keys
    }

    #[test]
    fn plan_json_keeps_its_flat_shape_and_reads_back() {
        let site = SiteSummary {
            plan_facet: 3,
            hypothesised_facet: true,
            grasp: SiteGrasp { width_mm: 30.5, tool_m: Some([0.3, 0.0, 0.02]), yaw_deg: Some(12.0) },
            place: SitePlace { site_m: [0.3, 0.01, 0.03], centre_m: [0.31, 0.01, 0.03], site_left_px: [100.0, 200.0], site_right_px: [90.0, 200.0], distance_mm: None },
            reason: None,
        };
        let mut summary = PlanSummary::default();
        summary.counts.segments = [40, 42];
        summary.sites.candidates = vec![site.clone()];
        summary.sites.chosen = Some(site.clone());
        summary.sites.rejected_by_reason.insert("too_wide".into(), 2);
        summary.sites.facet_rejections.push((1, "no_top_edge".into()));
        summary.scene.image_rear_edges.push((3, 25.0, 0.8));
        summary.geometry.model = Some(serde_json::json!({ "c": [1.0, 2.0, 3.0, 4.0] }));
        summary.timing.total_ms = 12.5;
        let value = serde_json::to_value(&summary).unwrap();
        // The keys of plan.json before its fields were grouped, and the cage kept since.
        let mut expected = vec![
            "segments", "matches", "planes", "facets", "candidates", "chosen", "rejected_sites", "rejected_by_reason",
            "facet_rejections", "superseded_facets", "image_rear_edges", "indicated_m", "indicated_px", "masks_px", "masked_px",
            "cage_robot_m", "cage_image_px", "lever_m", "max_height_m",
            "model", "bootstrap_rms_px", "projective_residual_px", "planner_ms", "total_ms",
        ];
        expected.sort_unstable();
        assert_eq!(sorted_keys(&value), expected);
        let mut site_keys = vec![
            "plan_facet", "hypothesised_facet", "width_mm", "site_m", "centre_m", "tool_m", "yaw_deg", "site_left_px",
            "site_right_px", "distance_mm", "reason",
        ];
        site_keys.sort_unstable();
        assert_eq!(sorted_keys(&value["chosen"]), site_keys);
        assert_eq!(value["chosen"]["distance_mm"], serde_json::Value::Null);
        let back: PlanSummary = serde_json::from_value(value.clone()).unwrap();
        assert_eq!(serde_json::to_value(&back).unwrap(), value);
        // Reports written before the cage was kept still read.
        let mut old = value.clone();
        for key in ["cage_robot_m", "cage_image_px", "lever_m", "max_height_m"] {
            old.as_object_mut().unwrap().remove(key);
        }
        assert!(serde_json::from_value::<PlanSummary>(old).is_ok());
    }
}
