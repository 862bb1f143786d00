//! Grasp planning for a parallel-jaw gripper approaching from above (thesis chapter 6,
//! METHOD.md §6), on facets and edges reconstructed from one stereo pair.
//!
//! # Rules
//! 1. A facet is graspable when it is within 20° of vertical; its *top edges* (edges with the
//!    facet below them) must be within 30° of horizontal.
//! 2. Only one side of an object is seen, so the opposite face is hypothesised: a *rear edge*
//!    parallel to the top edge, on the same connected component, behind the facet (as seen
//!    from the cameras), not one of the facet's own edges. The top edge itself may serve
//!    (zero width: a thin wall) only as far as the collision tests; it is never grasped, as
//!    nothing measured says the block is that thin (a block whose top falls away behind the
//!    face, or whose top face was missed, looks the same). A thin wall is grasped across its
//!    measured rear edge.
//! 3. Of each (top edge, rear edge) pair only the most central site is tried: the middle of
//!    the stretch where both edges overlap along the top edge. Its width (horizontal distance
//!    between the two surfaces) must be at most 50 mm.
//! 4. Collisions, in plan view: the two fingers' swept rectangles against every feature
//!    above the *low-water mark* (the finger-tip plane, 25 mm below the site); then a
//!    40 x 100 mm body rectangle against every feature above the *high-water mark* (25 mm
//!    above the site).
//! 5. The highest collision-free site of each facet is kept; the one nearest the indicated
//!    point (in plan view) is chosen (of sites within 5 mm as near, the one on the face
//!    that looks most towards the cameras).
//!
//! Optionally (`max_view_angle_rad`) facets turned too far from the viewer in plan view are
//! left out: a gripper whose tracked face is normal to the jaws' closing axis ends up as
//! oblique to the cameras as the facet it grasps.
//!
//! Every site that fails a rule is kept in [`GraspPlan::rejected`] with its reason.
//!
//! # Choices the thesis leaves open
//! - The grasped facet and its edges, and the rear edge, are the *contact* surfaces: they are
//!   left out of the finger test (a finger pressing on them is the grasp, not a collision),
//!   and the finger rectangles start `contact_tolerance_m` outside the two contact planes.
//! - Features of the grasped object itself (same component) count against a finger only
//!   when they reach more than `object_tolerance_m` past a contact plane: its other faces
//!   end there up to the reconstruction's error.
//! - The rear edge must lie within `max_rear_drop_m` of the top edge's height (default: the
//!   finger depth), so the fingers reach the face it bounds.
//! - Parallel means within `parallel_tolerance_rad` (10°) in 3-D.
//! - Of sites on one facet within 2 mm of the same height, the widest is kept: a parallel
//!   rear edge is evidence of the object's thickness, while the zero-width pairing of a top
//!   edge with itself is only the thin-wall hypothesis.
//!
//! # Frames and units
//! Robot frame, metres, `z` up. Yaw is about `+z`; a grasp's yaw is the direction of its jaw
//! axis (the line the fingers close along), reduced to `(−90°, 90°]` because the gripper is
//! symmetric: yaw 0 closes the jaws along robot `x`.

pub mod explain;
mod planview;
pub mod scene;
#[cfg(test)]
mod tests;

pub use explain::{refusal_grounded, sloping_top_rad, why_no_grasp};
pub use scene::{hypothesise_front_faces, scene_from_plan, FacetSource, PlannedScene};

use nalgebra::{Vector2, Vector3};
use thiserror::Error;

use planview::{clip_polygon_above, clip_segment_above, Rect};

/// A 3-D line segment, robot frame, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Segment3 {
    pub a_m: Vector3<f64>,
    pub b_m: Vector3<f64>,
}

impl Segment3 {
    pub fn new(a_m: Vector3<f64>, b_m: Vector3<f64>) -> Self {
        Self { a_m, b_m }
    }

    pub fn length_m(&self) -> f64 {
        (self.b_m - self.a_m).norm()
    }

    fn midpoint(&self) -> Vector3<f64> {
        0.5 * (self.a_m + self.b_m)
    }
}

/// A reconstructed planar facet: its outline, the reconstructed edge segments on its
/// boundary, and the connected component (object) it belongs to.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneFacet {
    /// Corners in order around the outline (either direction), robot frame, metres.
    pub polygon_m: Vec<Vector3<f64>>,
    /// Edge segments on the facet's boundary.
    pub edges: Vec<Segment3>,
    /// Connected-component id: facets and edges with the same id are one object.
    pub component: usize,
}

/// A reconstructed edge on no facet: still an obstacle, and possibly a rear edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SceneEdge {
    pub segment: Segment3,
    pub component: usize,
}

/// What the planner sees: the reconstruction of one stereo pair.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspScene {
    pub facets: Vec<SceneFacet>,
    pub edges: Vec<SceneEdge>,
    /// A direction from the scene towards the cameras (any length), robot frame: it says which
    /// side of a facet is its front. [`crate::affine::AffineStereo::toward_cameras`] gives it.
    pub toward_viewer: Vector3<f64>,
}

/// Which edge of the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EdgeRef {
    /// `edges[edge]` of `facets[facet]`.
    Facet { facet: usize, edge: usize },
    /// `edges[index]` of the scene.
    Loose(usize),
}

/// Which feature of the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FeatureRef {
    /// A facet's polygon.
    Facet(usize),
    Edge(EdgeRef),
}

/// The conservative gripper model of the thesis's figure 6.4, metres. Defaults are the
/// thesis's (25 mm water marks, 40 x 100 mm body, 50 mm widest grasp) and a finger size
/// that fits the simulator's gripper.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GripperModel {
    /// Low-water mark: finger tips this far below the site.
    pub finger_depth_m: f64,
    /// High-water mark: the body starts this far above the site.
    pub body_clearance_m: f64,
    /// Body rectangle, along the jaw axis.
    pub body_length_m: f64,
    /// Body rectangle, across the jaw axis.
    pub body_thickness_m: f64,
    /// Finger size along the jaw axis.
    pub finger_thickness_m: f64,
    /// Finger size along the edge.
    pub finger_breadth_m: f64,
    /// How far each finger opens beyond its contact surface before closing.
    pub finger_clearance_m: f64,
    /// A gripper that can only open fully: the jaws' inner faces are this far apart before
    /// closing, whatever the width, and each finger's clearance is what is left beside the
    /// grasp (`finger_clearance_m` is then unused). `None`: width plus both clearances.
    pub jaw_opening_m: Option<f64>,
    /// Widest grasp.
    pub max_width_m: f64,
}

impl Default for GripperModel {
    fn default() -> Self {
        Self {
            finger_depth_m: 0.025,
            body_clearance_m: 0.025,
            body_length_m: 0.100,
            body_thickness_m: 0.040,
            finger_thickness_m: 0.010,
            finger_breadth_m: 0.020,
            finger_clearance_m: 0.010,
            jaw_opening_m: None,
            max_width_m: 0.050,
        }
    }
}

/// Planner rules and tolerances.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GraspConfig {
    pub gripper: GripperModel,
    /// Largest angle of a graspable facet from vertical.
    pub max_facet_tilt_rad: f64,
    /// Largest angle of a usable top edge from horizontal.
    pub max_edge_slope_rad: f64,
    /// Largest angle between a top edge and its rear edge.
    pub parallel_tolerance_rad: f64,
    /// Shortest overlap of top and rear edge along the top edge, metres.
    pub min_overlap_m: f64,
    /// How far in front of the facet a rear edge may lie (noise), and how far the finger
    /// rectangles stay off the contact planes, metres.
    pub contact_tolerance_m: f64,
    /// Largest height difference between the top edge and the rear edge at the site, metres.
    pub max_rear_drop_m: f64,
    /// How far features of the grasped object itself may reach past the two contact planes
    /// into the fingers' swept rectangles before they count as a collision, metres. The
    /// object's other faces end at the contact planes up to the reconstruction's error
    /// (a visible side face reaches as far back as the rear surface the rear edge stands
    /// for); a face reaching much further means the object is wider than the site's width.
    pub object_tolerance_m: f64,
    /// Largest angle, in plan view, between a facet's normal and the direction towards the
    /// viewer. Not a rule of the thesis: a gripper whose tracked face turns with the jaws
    /// (the simulator's plate is normal to the closing axis) can only be servoed onto a
    /// facet that the cameras see well. `FRAC_PI_2` (the default) allows any facet that
    /// faces the viewer at all.
    pub max_view_angle_rad: f64,
    /// One-sigma error of a reconstructed point's height, metres: how far a rule's measure
    /// may be off. 0 (the default) for exact geometry (the simulator's judge); the daemon
    /// sets it from the calibrated model's residuals. A top edge's slope is refused only when
    /// it is past the limit by more than [`ERROR_SIGMAS`] of its error, used only when it is
    /// within the limit by as much, and otherwise left unsettled (neither).
    pub point_sigma_m: f64,
    /// One-sigma radius of the indicated point, metres: 0 (the default) for a point given as
    /// a coordinate; a pointed point's (the operator's finger line) is centimetres. Of the
    /// sites on the nearest site's object, those nearer than the nearest plus what the
    /// point's error can change ([`ERROR_SIGMAS`] of it) are as near, and the one facing the
    /// cameras most is chosen: the point picks the block, the uncertain point does not pick
    /// a face of it that the cameras see edge-on.
    pub indicated_sigma_m: f64,
}

/// How many sigmas of a measure's error a rule's verdict must clear: about 95 % one-sided.
pub const ERROR_SIGMAS: f64 = 2.0;

/// The error bound of a top edge's slope from horizontal, radians: the two ends' heights
/// each off by `point_sigma_m`, over the edge's horizontal run, [`ERROR_SIGMAS`] wide.
pub fn edge_slope_error_rad(edge: &Segment3, point_sigma_m: f64) -> f64 {
    let d = edge.b_m - edge.a_m;
    let run_m = d.xy().norm().max(1e-6);
    (ERROR_SIGMAS * std::f64::consts::SQRT_2 * point_sigma_m / run_m).atan()
}

impl Default for GraspConfig {
    fn default() -> Self {
        Self {
            gripper: GripperModel::default(),
            max_facet_tilt_rad: 20f64.to_radians(),
            max_edge_slope_rad: 30f64.to_radians(),
            parallel_tolerance_rad: 10f64.to_radians(),
            min_overlap_m: 0.005,
            contact_tolerance_m: 0.003,
            max_rear_drop_m: 0.025,
            object_tolerance_m: 0.003,
            max_view_angle_rad: std::f64::consts::FRAC_PI_2,
            point_sigma_m: 0.0,
            indicated_sigma_m: 0.0,
        }
    }
}

/// Input the planner cannot work with. Never a panic: a bad feature could hide a collision,
/// so the whole plan is refused.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum GraspError {
    #[error("grasp config: {field} = {value} is out of range")]
    Config { field: &'static str, value: f64 },
    #[error("facet {index}: {problem}")]
    InvalidFacet { index: usize, problem: &'static str },
    #[error("edge {index}: {problem}")]
    InvalidEdge { index: usize, problem: &'static str },
    #[error("toward_viewer must be a finite, non-zero vector")]
    InvalidViewDirection,
    #[error("the indicated point has a coordinate that is not finite")]
    InvalidIndicatedPoint,
}

/// Why a facet, edge or site was not used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum RejectReason {
    /// The facet is more than `max_facet_tilt_rad` from vertical.
    FacetNotVertical { tilt_rad: f64 },
    /// In plan view the facet faces more than `max_view_angle_rad` away from the viewer.
    TurnedFromViewer { angle_rad: f64 },
    /// The facet has no edge with the facet below it.
    NoTopEdge,
    /// A top edge more than `max_edge_slope_rad` from horizontal.
    TopEdgeTooSteep { slope_rad: f64 },
    /// A top edge whose slope is within its error bound of `max_edge_slope_rad`: neither
    /// steep enough to refuse nor flat enough to grasp on.
    TopEdgeSlopeUnsettled { slope_rad: f64, error_rad: f64 },
    /// A parallel edge of the component that does not overlap the top edge.
    NoOverlap,
    /// A parallel edge in front of the facet, not behind it.
    RearInFront { width_m: f64 },
    /// A parallel edge too far below or above the top edge for the fingers.
    RearOutOfReach { drop_m: f64 },
    /// Wider than the gripper opens.
    TooWide { width_m: f64 },
    /// A finger's swept rectangle meets a feature above the low-water mark.
    FingerCollision { feature: FeatureRef },
    /// The body rectangle meets a feature above the high-water mark.
    BodyCollision { feature: FeatureRef },
    /// Collision-free, but a higher site on the same facet is kept.
    NotHighest,
    /// The top edge paired with itself (the thin-wall hypothesis), collision-free, but with
    /// no rear edge or face measured behind it: the block's thickness was not seen.
    ThicknessUnmeasured,
}

/// A pair of contact points: where the fingers would close.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GraspSite {
    pub facet: usize,
    /// Index into the facet's `edges`.
    pub front_edge: usize,
    pub rear_edge: EdgeRef,
    /// Contact point on the top edge, metres.
    pub front_m: Vector3<f64>,
    /// Corresponding point on the rear edge, metres.
    pub rear_m: Vector3<f64>,
    /// Between the two surfaces, at the height of `front_m`: the grasp centre, metres.
    pub centre_m: Vector3<f64>,
    /// Horizontal distance between the two surfaces, metres.
    pub width_m: f64,
    /// Unit horizontal vector along which the jaws close, from the front surface to the rear.
    pub jaw_axis: Vector3<f64>,
    /// `front_m` in the facet's own affine frame: origin `polygon[0]`,
    /// `e1 = polygon[1] − polygon[0]`, `e2 = polygon[n−1] − polygon[0]`. Affine coordinates
    /// survive projection, so the same `(s, t)` locate the site in a tracker frame built on
    /// the facet's image corners the same way.
    pub facet_st: [f64; 2],
}

/// A grasp to execute.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grasp {
    pub site: GraspSite,
    /// Tool point (between the finger tips) at the grasp: the site's centre, lowered to the
    /// low-water mark. Metres.
    pub tool_m: Vector3<f64>,
    /// Tool yaw, radians, in `(−π/2, π/2]` (see the module docs).
    pub yaw_rad: f64,
    /// Jaw opening to approach with: width plus the clearance of both fingers, metres.
    pub opening_m: f64,
    /// Unit approach direction: straight down.
    pub approach: Vector3<f64>,
}

/// A facet, edge or site that was not used, and why.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rejection {
    pub facet: usize,
    pub front_edge: Option<usize>,
    pub rear_edge: Option<EdgeRef>,
    /// The site, when the rule that failed came after it was computed.
    pub site: Option<GraspSite>,
    pub reason: RejectReason,
}

/// The planner's answer.
#[derive(Debug, Clone, PartialEq)]
pub struct GraspPlan {
    /// The grasp to execute: the candidate nearest the indicated point (or the highest one
    /// when no point was indicated). `None` when every site was rejected.
    pub chosen: Option<Grasp>,
    /// The highest collision-free grasp of each facet that has one, in order of preference
    /// (`candidates[0]` is `chosen`).
    pub candidates: Vec<Grasp>,
    pub rejected: Vec<Rejection>,
}

impl GraspConfig {
    pub fn validate(&self) -> Result<(), GraspError> {
        let g = &self.gripper;
        let positive = [
            ("gripper.finger_depth_m", g.finger_depth_m),
            ("gripper.body_clearance_m", g.body_clearance_m),
            ("gripper.body_length_m", g.body_length_m),
            ("gripper.body_thickness_m", g.body_thickness_m),
            ("gripper.finger_thickness_m", g.finger_thickness_m),
            ("gripper.finger_breadth_m", g.finger_breadth_m),
            ("gripper.max_width_m", g.max_width_m),
            ("max_facet_tilt_rad", self.max_facet_tilt_rad),
            ("max_edge_slope_rad", self.max_edge_slope_rad),
            ("parallel_tolerance_rad", self.parallel_tolerance_rad),
        ];
        let non_negative = [
            ("gripper.finger_clearance_m", g.finger_clearance_m),
            ("min_overlap_m", self.min_overlap_m),
            ("contact_tolerance_m", self.contact_tolerance_m),
            ("max_rear_drop_m", self.max_rear_drop_m),
            ("object_tolerance_m", self.object_tolerance_m),
            ("point_sigma_m", self.point_sigma_m),
            ("indicated_sigma_m", self.indicated_sigma_m),
        ];
        if let Some(o) = g.jaw_opening_m
            && !(o > 0.0 && o.is_finite() && o >= g.max_width_m)
        {
            return Err(GraspError::Config { field: "gripper.jaw_opening_m", value: o });
        }
        for (field, value) in positive {
            if !(value > 0.0 && value.is_finite()) {
                return Err(GraspError::Config { field, value });
            }
        }
        for (field, value) in non_negative {
            if !(value >= 0.0 && value.is_finite()) {
                return Err(GraspError::Config { field, value });
            }
        }
        for (field, value) in [("max_facet_tilt_rad", self.max_facet_tilt_rad), ("max_edge_slope_rad", self.max_edge_slope_rad), ("parallel_tolerance_rad", self.parallel_tolerance_rad)] {
            if value >= std::f64::consts::FRAC_PI_2 {
                return Err(GraspError::Config { field, value });
            }
        }
        if !(self.max_view_angle_rad > 0.0 && self.max_view_angle_rad <= std::f64::consts::FRAC_PI_2) {
            return Err(GraspError::Config { field: "max_view_angle_rad", value: self.max_view_angle_rad });
        }
        Ok(())
    }
}

fn finite3(v: &Vector3<f64>) -> bool {
    v.iter().all(|x| x.is_finite())
}

/// Newell's normal of a polygon (unit), or `None` when it has no area.
fn polygon_normal(poly: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    let mut n = Vector3::zeros();
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        n += Vector3::new((a[1] - b[1]) * (a[2] + b[2]), (a[2] - b[2]) * (a[0] + b[0]), (a[0] - b[0]) * (a[1] + b[1]));
    }
    let len = n.norm();
    // Area below 1 mm²: a sliver, not a facet.
    (len > 2e-6).then(|| n / len)
}

fn validate(scene: &GraspScene, indicated_m: Option<&Vector3<f64>>) -> Result<(), GraspError> {
    if !(finite3(&scene.toward_viewer) && scene.toward_viewer.norm() > 0.0) {
        return Err(GraspError::InvalidViewDirection);
    }
    if indicated_m.is_some_and(|p| !finite3(p)) {
        return Err(GraspError::InvalidIndicatedPoint);
    }
    for (index, f) in scene.facets.iter().enumerate() {
        let bad = |problem| Err(GraspError::InvalidFacet { index, problem });
        if f.polygon_m.len() < 3 {
            return bad("polygon_m has fewer than 3 corners");
        }
        if !f.polygon_m.iter().all(finite3) {
            return bad("polygon_m has a coordinate that is not finite");
        }
        if polygon_normal(&f.polygon_m).is_none() {
            return bad("polygon_m has no area");
        }
        let (o, u, v) = (f.polygon_m[0], f.polygon_m[1], f.polygon_m[f.polygon_m.len() - 1]);
        if (u - o).cross(&(v - o)).norm() < 1e-9 {
            return bad("polygon_m[0] is not a corner (its neighbours are in line with it): the facet frame is undefined");
        }
        if !f.edges.iter().all(|e| finite3(&e.a_m) && finite3(&e.b_m)) {
            return bad("edges has a coordinate that is not finite");
        }
        if f.edges.iter().any(|e| e.length_m() < 1e-6) {
            return bad("edges has a segment of zero length");
        }
    }
    for (index, e) in scene.edges.iter().enumerate() {
        if !(finite3(&e.segment.a_m) && finite3(&e.segment.b_m)) {
            return Err(GraspError::InvalidEdge { index, problem: "a coordinate is not finite" });
        }
        if e.segment.length_m() < 1e-6 {
            return Err(GraspError::InvalidEdge { index, problem: "zero length" });
        }
    }
    Ok(())
}

impl GraspScene {
    /// The connected component (object) a facet or edge belongs to.
    pub fn component_of(&self, f: FeatureRef) -> usize {
        match f {
            FeatureRef::Facet(i) | FeatureRef::Edge(EdgeRef::Facet { facet: i, .. }) => self.facets[i].component,
            FeatureRef::Edge(EdgeRef::Loose(i)) => self.edges[i].component,
        }
    }

    fn edge(&self, r: EdgeRef) -> &Segment3 {
        match r {
            EdgeRef::Facet { facet, edge } => &self.facets[facet].edges[edge],
            EdgeRef::Loose(i) => &self.edges[i].segment,
        }
    }

    /// Every edge of component `component`: facet edges, then loose edges.
    fn component_edges(&self, component: usize) -> impl Iterator<Item = EdgeRef> + '_ {
        let on_facets = self.facets.iter().enumerate().filter(move |(_, f)| f.component == component).flat_map(|(fi, f)| (0..f.edges.len()).map(move |ei| EdgeRef::Facet { facet: fi, edge: ei }));
        let loose = self.edges.iter().enumerate().filter(move |(_, e)| e.component == component).map(|(i, _)| EdgeRef::Loose(i));
        on_facets.chain(loose)
    }
}

/// Plan-view coordinates `(g, h)` of a point in a grasp frame.
struct PlanFrame {
    centre: Vector3<f64>,
    jaw: Vector3<f64>,
    along: Vector3<f64>,
}

impl PlanFrame {
    fn map(&self, p: &Vector3<f64>) -> Vector2<f64> {
        let d = p - self.centre;
        Vector2::new(d.dot(&self.jaw), d.dot(&self.along))
    }
}

/// The first feature above `z_min` that meets one of `rects` in plan view, skipping the
/// features `skip` says to.
fn first_collision(scene: &GraspScene, frame: &PlanFrame, rects: &[Rect], z_min: f64, skip: impl Fn(FeatureRef) -> bool, scratch: &mut (Vec<Vector3<f64>>, Vec<Vector2<f64>>)) -> Option<FeatureRef> {
    let meets_segment = |s: &Segment3| {
        clip_segment_above(&s.a_m, &s.b_m, z_min).is_some_and(|(a, b)| {
            let (a, b) = (frame.map(&a), frame.map(&b));
            rects.iter().any(|r| r.meets_segment(&a, &b))
        })
    };
    for (fi, f) in scene.facets.iter().enumerate() {
        if !skip(FeatureRef::Facet(fi)) {
            clip_polygon_above(&f.polygon_m, z_min, &mut scratch.0);
            scratch.1.clear();
            scratch.1.extend(scratch.0.iter().map(|p| frame.map(p)));
            if rects.iter().any(|r| r.meets_polygon(&scratch.1)) {
                return Some(FeatureRef::Facet(fi));
            }
        }
        for (ei, e) in f.edges.iter().enumerate() {
            let r = FeatureRef::Edge(EdgeRef::Facet { facet: fi, edge: ei });
            if !skip(r) && meets_segment(e) {
                return Some(r);
            }
        }
    }
    for (i, e) in scene.edges.iter().enumerate() {
        let r = FeatureRef::Edge(EdgeRef::Loose(i));
        if !skip(r) && meets_segment(&e.segment) {
            return Some(r);
        }
    }
    None
}

/// Sites of one facet closer in height than this count as equally high, metres.
const EQUAL_HEIGHT_M: f64 = 0.002;

/// Sites whose distances from the indicated point differ by less than this are equally near
/// it (plan view, m): the reconstruction's error of a block's centre.
const EQUAL_DISTANCE_M: f64 = 0.005;

/// Plans grasps on `scene`; `indicated_m` (robot frame) picks among the candidates.
///
/// ```
/// use handeye_vision::grasp::{plan_grasps, GraspConfig, GraspScene, SceneFacet, Segment3};
/// use nalgebra::Vector3;
/// // A 40 mm cube on the table, front face towards +x (the cameras), top face visible.
/// let p = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
/// let front = vec![p(0.04, 0.0, 0.0), p(0.04, 0.04, 0.0), p(0.04, 0.04, 0.04), p(0.04, 0.0, 0.04)];
/// let top = vec![p(0.0, 0.0, 0.04), p(0.04, 0.0, 0.04), p(0.04, 0.04, 0.04), p(0.0, 0.04, 0.04)];
/// let sides = |poly: &Vec<Vector3<f64>>| (0..4).map(|i| Segment3::new(poly[i], poly[(i + 1) % 4])).collect();
/// let scene = GraspScene {
///     facets: vec![
///         SceneFacet { edges: sides(&front), polygon_m: front, component: 0 },
///         SceneFacet { edges: sides(&top), polygon_m: top, component: 0 },
///     ],
///     edges: vec![],
///     toward_viewer: Vector3::new(1.0, 0.0, 0.5),
/// };
/// let plan = plan_grasps(&scene, None, &GraspConfig::default()).unwrap();
/// let grasp = plan.chosen.unwrap();
/// assert!((grasp.site.width_m - 0.04).abs() < 1e-9);       // across the cube
/// assert!((grasp.tool_m - p(0.02, 0.02, 0.015)).norm() < 1e-9); // finger tips 25 mm down
/// assert!(grasp.yaw_rad.abs() < 1e-9);                     // jaws close along x
/// ```
pub fn plan_grasps(scene: &GraspScene, indicated_m: Option<&Vector3<f64>>, config: &GraspConfig) -> Result<GraspPlan, GraspError> {
    config.validate()?;
    validate(scene, indicated_m)?;
    let g = &config.gripper;
    let mut rejected = Vec::new();
    let mut candidates: Vec<Grasp> = Vec::new();
    let mut scratch = (Vec::new(), Vec::new());
    let cos_parallel = config.parallel_tolerance_rad.cos();

    for (fi, facet) in scene.facets.iter().enumerate() {
        let reject = |front_edge, rear_edge, site, reason| Rejection { facet: fi, front_edge, rear_edge, site, reason };
        // validate() guarantees an area, hence a normal.
        let Some(mut n) = polygon_normal(&facet.polygon_m) else { continue };
        if n.dot(&scene.toward_viewer) < 0.0 {
            n = -n;
        }
        let tilt_rad = n[2].abs().min(1.0).asin();
        if tilt_rad > config.max_facet_tilt_rad {
            rejected.push(reject(None, None, None, RejectReason::FacetNotVertical { tilt_rad }));
            continue;
        }
        let jaw = -Vector3::new(n[0], n[1], 0.0).normalize();
        let toward = Vector3::new(scene.toward_viewer[0], scene.toward_viewer[1], 0.0);
        if config.max_view_angle_rad < std::f64::consts::FRAC_PI_2 && toward.norm() > 1e-12 {
            let angle_rad = (-jaw).dot(&toward.normalize()).clamp(-1.0, 1.0).acos();
            if angle_rad > config.max_view_angle_rad {
                rejected.push(reject(None, None, None, RejectReason::TurnedFromViewer { angle_rad }));
                continue;
            }
        }
        let along = Vector3::z().cross(&jaw);
        let centroid = facet.polygon_m.iter().sum::<Vector3<f64>>() / facet.polygon_m.len() as f64;
        let mut facet_sites: Vec<Grasp> = Vec::new();
        let mut any_top = false;

        for (ei, front) in facet.edges.iter().enumerate() {
            let d = (front.b_m - front.a_m) / front.length_m();
            // In the facet's plane, perpendicular to the edge, towards the facet: a top edge
            // has the facet below it (by more than 30°, so side edges never count).
            let mut inward = n.cross(&d);
            if inward.dot(&(centroid - front.midpoint())) < 0.0 {
                inward = -inward;
            }
            if inward[2] > -0.5 {
                continue;
            }
            any_top = true;
            let slope_rad = d[2].abs().min(1.0).asin();
            let error_rad = edge_slope_error_rad(front, config.point_sigma_m);
            if slope_rad - error_rad > config.max_edge_slope_rad {
                rejected.push(reject(Some(ei), None, None, RejectReason::TopEdgeTooSteep { slope_rad }));
                continue;
            }
            if slope_rad + error_rad > config.max_edge_slope_rad {
                rejected.push(reject(Some(ei), None, None, RejectReason::TopEdgeSlopeUnsettled { slope_rad, error_rad }));
                continue;
            }
            for rear_ref in scene.component_edges(facet.component) {
                // The facet's own other edges lie in its plane, not behind it: paired with
                // the top edge they say nothing of the block's thickness (its bottom edge
                // would read as a rear edge a block's height lower). The top edge with
                // itself is the thin-wall hypothesis and stays.
                if matches!(rear_ref, EdgeRef::Facet { facet, edge } if facet == fi && edge != ei) {
                    continue;
                }
                let rear = scene.edge(rear_ref);
                let dr = (rear.b_m - rear.a_m) / rear.length_m();
                if d.dot(&dr).abs() < cos_parallel {
                    continue;
                }
                let reject = |site, reason| reject(Some(ei), Some(rear_ref), site, reason);
                // Overlap of the rear edge with the top edge, along the top edge.
                let (ta, tb) = ((rear.a_m - front.a_m).dot(&d), (rear.b_m - front.a_m).dot(&d));
                let (lo, hi) = (ta.min(tb).max(0.0), ta.max(tb).min(front.length_m()));
                if hi - lo < config.min_overlap_m.max(1e-9) {
                    rejected.push(reject(None, RejectReason::NoOverlap));
                    continue;
                }
                let front_m = front.a_m + 0.5 * (lo + hi) * d;
                // The rear point in the plane through front_m normal to the top edge.
                let denom = (rear.b_m - rear.a_m).dot(&d);
                let rear_m = rear.a_m + ((front_m - rear.a_m).dot(&d) / denom) * (rear.b_m - rear.a_m);
                let width_m = (rear_m - front_m).dot(&jaw);
                let centre_m = front_m + 0.5 * width_m * jaw;
                let site = GraspSite { facet: fi, front_edge: ei, rear_edge: rear_ref, front_m, rear_m, centre_m, width_m, jaw_axis: jaw, facet_st: facet_coordinates(&facet.polygon_m, &front_m) };
                if width_m < -config.contact_tolerance_m {
                    rejected.push(reject(Some(site), RejectReason::RearInFront { width_m }));
                    continue;
                }
                let drop_m = front_m[2] - rear_m[2];
                if drop_m.abs() > config.max_rear_drop_m {
                    rejected.push(reject(Some(site), RejectReason::RearOutOfReach { drop_m }));
                    continue;
                }
                if width_m > g.max_width_m {
                    rejected.push(reject(Some(site), RejectReason::TooWide { width_m }));
                    continue;
                }
                let w = width_m.max(0.0);
                let clearance = g.jaw_opening_m.map_or(g.finger_clearance_m, |o| (0.5 * (o - w)).max(0.0));
                let frame = PlanFrame { centre: centre_m, jaw, along };
                let (inner, outer, half_b) = (0.5 * w + config.contact_tolerance_m, 0.5 * w + clearance + g.finger_thickness_m, 0.5 * g.finger_breadth_m);
                let fingers = [Rect { g: [-outer, -inner], h: [-half_b, half_b] }, Rect { g: [inner, outer], h: [-half_b, half_b] }];
                let contact = |f: FeatureRef| match f {
                    FeatureRef::Facet(i) => i == fi,
                    FeatureRef::Edge(e) => e == rear_ref || matches!(e, EdgeRef::Facet { facet, .. } if facet == fi),
                };
                // Other objects against the fingers' full sweep; the grasped object's own other
                // features with `object_tolerance_m` past the contact planes.
                let low_water = front_m[2] - g.finger_depth_m;
                let own = |f: FeatureRef| scene.component_of(f) == facet.component;
                let inner_own = 0.5 * w + config.object_tolerance_m.max(config.contact_tolerance_m);
                let own_fingers = [Rect { g: [-outer, -inner_own], h: [-half_b, half_b] }, Rect { g: [inner_own, outer], h: [-half_b, half_b] }];
                let hit = first_collision(scene, &frame, &fingers, low_water, |f| contact(f) || own(f), &mut scratch)
                    .or_else(|| if inner_own < outer { first_collision(scene, &frame, &own_fingers, low_water, |f| contact(f) || !own(f), &mut scratch) } else { None });
                if let Some(feature) = hit {
                    rejected.push(reject(Some(site), RejectReason::FingerCollision { feature }));
                    continue;
                }
                let body = [Rect { g: [-0.5 * g.body_length_m, 0.5 * g.body_length_m], h: [-0.5 * g.body_thickness_m, 0.5 * g.body_thickness_m] }];
                if let Some(feature) = first_collision(scene, &frame, &body, front_m[2] + g.body_clearance_m, |_| false, &mut scratch) {
                    rejected.push(reject(Some(site), RejectReason::BodyCollision { feature }));
                    continue;
                }
                // The thin-wall pairing passes the collision tests only because nothing was seen
                // behind the face; a top sloping away or a top face the reconstruction missed
                // is as likely as a wall, and the rear finger would come down on it.
                if rear_ref == (EdgeRef::Facet { facet: fi, edge: ei }) {
                    rejected.push(reject(Some(site), RejectReason::ThicknessUnmeasured));
                    continue;
                }
                facet_sites.push(Grasp {
                    site,
                    tool_m: centre_m - Vector3::new(0.0, 0.0, g.finger_depth_m),
                    yaw_rad: symmetric_yaw(jaw[1].atan2(jaw[0])),
                    opening_m: w + 2.0 * clearance,
                    approach: -Vector3::z(),
                });
            }
        }
        if !any_top {
            rejected.push(reject(None, None, None, RejectReason::NoTopEdge));
        }
        // The highest site of the facet is kept; of sites equally high (within
        // `EQUAL_HEIGHT_M`), the widest: a rear edge is evidence of how thick the object
        // is, and a zero-width grasp on a thick object would drive a finger into it.
        let better = |a: &Grasp, b: &Grasp| {
            let dz = a.site.front_m[2] - b.site.front_m[2];
            if dz.abs() > EQUAL_HEIGHT_M { dz > 0.0 } else { a.site.width_m > b.site.width_m }
        };
        if let Some(best) = (0..facet_sites.len()).reduce(|b, i| if better(&facet_sites[i], &facet_sites[b]) { i } else { b }) {
            for (i, s) in facet_sites.iter().enumerate() {
                if i != best {
                    rejected.push(Rejection { facet: fi, front_edge: Some(s.site.front_edge), rear_edge: Some(s.site.rear_edge), site: Some(s.site), reason: RejectReason::NotHighest });
                }
            }
            candidates.push(facet_sites[best]);
        }
    }

    match indicated_m {
        Some(p) => {
            let plan_distance = |g: &Grasp| (g.site.centre_m.xy() - p.xy()).norm();
            candidates.sort_by(|a, b| plan_distance(a).total_cmp(&plan_distance(b)));
            // Of sites as near the point as the nearest (two faces of one block: an across-
            // the-block grasp is centred on the block whichever face it is servoed on), the
            // one on the face that looks most towards the cameras: a face seen edge-on is a
            // few pixels wide, and its trackers cannot hold it. On the nearest site's own
            // object, "as near" also takes in the indicated point's own error.
            let toward = Vector3::new(scene.toward_viewer[0], scene.toward_viewer[1], 0.0).try_normalize(1e-12);
            if let (Some(first), Some(toward)) = (candidates.first(), toward) {
                let object = |g: &Grasp| scene.facets[g.site.facet].component;
                let reach = plan_distance(first) + EQUAL_DISTANCE_M;
                // At least `reach`: the point's error only adds to the reconstruction's.
                let own_reach = plan_distance(first) + EQUAL_DISTANCE_M.hypot(ERROR_SIGMAS * config.indicated_sigma_m);
                let as_near = |g: &Grasp| plan_distance(g) <= if object(g) == object(first) { own_reach } else { reach };
                let facing = |g: &Grasp| polygon_normal(&scene.facets[g.site.facet].polygon_m).map_or(0.0, |n| Vector3::new(n[0], n[1], 0.0).normalize().dot(&toward).abs());
                let best = (0..candidates.len())
                    .take_while(|&i| plan_distance(&candidates[i]) <= own_reach)
                    .filter(|&i| as_near(&candidates[i]))
                    .reduce(|b, i| if facing(&candidates[i]) > facing(&candidates[b]) + 1e-9 { i } else { b });
                if let Some(best) = best {
                    candidates[..=best].rotate_right(1);
                }
            }
        }
        None => candidates.sort_by(|a, b| b.site.front_m[2].total_cmp(&a.site.front_m[2])),
    }
    Ok(GraspPlan { chosen: candidates.first().copied(), candidates, rejected })
}

/// Yaw of a symmetric parallel gripper: the same grasp every 180°, reduced to `(−π/2, π/2]`.
fn symmetric_yaw(yaw: f64) -> f64 {
    let y = yaw.rem_euclid(std::f64::consts::PI);
    if y > std::f64::consts::FRAC_PI_2 { y - std::f64::consts::PI } else { y }
}

/// Affine coordinates of point `p` (in the polygon's plane) in the frame `polygon[0]`,
/// `polygon[1] − polygon[0]`, `polygon[n−1] − polygon[0]`, by least squares.
fn facet_coordinates(poly: &[Vector3<f64>], p: &Vector3<f64>) -> [f64; 2] {
    let o = poly[0];
    let (u, v) = (poly[1] - o, poly[poly.len() - 1] - o);
    let q = p - o;
    let (uu, uv, vv) = (u.dot(&u), u.dot(&v), v.dot(&v));
    // validate() made sure u and v are not parallel.
    let det = uu * vv - uv * uv;
    [(vv * u.dot(&q) - uv * v.dot(&q)) / det, (uu * v.dot(&q) - uv * u.dot(&q)) / det]
}
