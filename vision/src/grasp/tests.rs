//! Grasp-planner tests on hand-built scenes, one per rule of chapter 6.

use nalgebra::Vector3;

use super::*;

fn p(x: f64, y: f64, z: f64) -> Vector3<f64> {
    Vector3::new(x, y, z)
}

/// A facet whose edges are its polygon's sides.
fn facet(polygon_m: Vec<Vector3<f64>>, component: usize) -> SceneFacet {
    let n = polygon_m.len();
    let edges = (0..n).map(|i| Segment3::new(polygon_m[i], polygon_m[(i + 1) % n])).collect();
    SceneFacet { polygon_m, edges, component }
}

/// The front (x = x1, facing the cameras) and top faces of the box [x0, x1] x [y0, y1] x [0, h].
/// Front polygon order: bottom-left, bottom-right, top-right, top-left (seen from +x: y grows
/// to the left... the order only fixes the facet frame: o = bottom at y0, e1 along +y, e2 up).
fn block(x: [f64; 2], y: [f64; 2], h: f64, component: usize) -> Vec<SceneFacet> {
    vec![
        facet(vec![p(x[1], y[0], 0.0), p(x[1], y[1], 0.0), p(x[1], y[1], h), p(x[1], y[0], h)], component),
        facet(vec![p(x[0], y[0], h), p(x[1], y[0], h), p(x[1], y[1], h), p(x[0], y[1], h)], component),
    ]
}

/// The cameras are in front (+x), a little to the side and above.
fn scene(facets: Vec<SceneFacet>, edges: Vec<SceneEdge>) -> GraspScene {
    GraspScene { facets, edges, toward_viewer: p(1.0, 0.2, 0.7) }
}

fn plan(s: &GraspScene) -> GraspPlan {
    plan_grasps(s, None, &GraspConfig::default()).unwrap()
}

fn reasons_for(plan: &GraspPlan, facet: usize) -> Vec<RejectReason> {
    plan.rejected.iter().filter(|r| r.facet == facet).map(|r| r.reason).collect()
}

#[test]
fn a_cube_is_grasped_across_its_top() {
    let s = scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![]);
    let plan = plan(&s);
    let g = plan.chosen.expect("a grasp");
    // Front top edge against the top face's back edge: 40 mm across, centred.
    assert_eq!(g.site.facet, 0);
    assert_eq!(g.site.rear_edge, EdgeRef::Facet { facet: 1, edge: 3 });
    assert!((g.site.width_m - 0.04).abs() < 1e-12);
    assert!((g.site.front_m - p(0.04, 0.02, 0.04)).norm() < 1e-12);
    assert!((g.site.centre_m - p(0.02, 0.02, 0.04)).norm() < 1e-12);
    assert!((g.tool_m - p(0.02, 0.02, 0.015)).norm() < 1e-12, "finger tips at the low-water mark");
    assert!((g.site.jaw_axis - p(-1.0, 0.0, 0.0)).norm() < 1e-12, "jaws close from the front face inwards");
    assert!(g.yaw_rad.abs() < 1e-12);
    assert!((g.opening_m - 0.06).abs() < 1e-12);
    assert_eq!(g.approach, p(0.0, 0.0, -1.0));
    // Facet frame: o = (0.04, 0, 0), e1 = +y 40 mm, e2 = up 40 mm; the site is mid-top.
    assert!((g.site.facet_st[0] - 0.5).abs() < 1e-12 && (g.site.facet_st[1] - 1.0).abs() < 1e-12, "{:?}", g.site.facet_st);
    // The zero-width grasp on the front edge alone would put the rear finger on the top face.
    let r = reasons_for(&plan, 0);
    assert!(r.contains(&RejectReason::FingerCollision { feature: FeatureRef::Facet(1) }), "{r:?}");
    // The front face's own bottom edge is parallel, but in the face's plane, not behind it:
    // never paired as a rear edge (it would read as one 40 mm lower).
    assert!(
        !plan.rejected.iter().any(|x| x.facet == 0 && matches!(x.rear_edge, Some(EdgeRef::Facet { facet: 0, edge }) if Some(edge) != x.front_edge)),
        "{:?}",
        plan.rejected
    );
    assert!(!r.iter().any(|x| matches!(x, RejectReason::RearOutOfReach { .. })), "{r:?}");
    // The top face is horizontal: not a graspable facet.
    assert!(matches!(reasons_for(&plan, 1)[..], [RejectReason::FacetNotVertical { tilt_rad }] if (tilt_rad.to_degrees() - 90.0).abs() < 1e-9));
    assert_eq!(plan.candidates.len(), 1);
}

/// A block whose front face leans back by `tilt_deg` (its top edge stays horizontal).
fn leaning_block(tilt_deg: f64) -> GraspScene {
    let h = 0.04;
    let top_x = 0.04 - h * tilt_deg.to_radians().tan();
    let front = facet(vec![p(0.04, 0.0, 0.0), p(0.04, 0.04, 0.0), p(top_x, 0.04, h), p(top_x, 0.0, h)], 0);
    let top = facet(vec![p(0.0, 0.0, h), p(top_x, 0.0, h), p(top_x, 0.04, h), p(0.0, 0.04, h)], 0);
    scene(vec![front, top], vec![])
}

#[test]
fn facets_within_20_degrees_of_vertical_only() {
    let ok = plan(&leaning_block(19.0));
    let g = ok.chosen.expect("19° is graspable");
    assert!((g.site.width_m - (0.04 - 0.04 * 19f64.to_radians().tan())).abs() < 1e-12);
    let no = plan(&leaning_block(21.0));
    assert!(no.chosen.is_none());
    assert!(matches!(reasons_for(&no, 0)[..], [RejectReason::FacetNotVertical { tilt_rad }] if (tilt_rad.to_degrees() - 21.0).abs() < 1e-9), "{:?}", no.rejected);
}

/// A vertical front face whose top edge rises by `slope_deg` along +y, and a loose rear edge
/// parallel to it 30 mm behind.
fn sloped_top(slope_deg: f64) -> GraspScene {
    let rise = 0.04 * slope_deg.to_radians().tan();
    let front = facet(vec![p(0.04, 0.0, 0.0), p(0.04, 0.04, 0.0), p(0.04, 0.04, 0.04 + rise), p(0.04, 0.0, 0.04)], 0);
    let rear = SceneEdge { segment: Segment3::new(p(0.01, 0.0, 0.04), p(0.01, 0.04, 0.04 + rise)), component: 0 };
    scene(vec![front], vec![rear])
}

#[test]
fn top_edges_within_30_degrees_of_horizontal_only() {
    let ok = plan(&sloped_top(29.0));
    let g = ok.chosen.expect("a 29° top edge is usable");
    // The 30 mm pairing, not the top edge's zero-width pairing with itself (never grasped).
    assert_eq!(g.site.rear_edge, EdgeRef::Loose(0));
    assert!(ok.rejected.iter().any(|r| r.reason == RejectReason::ThicknessUnmeasured && r.rear_edge == Some(EdgeRef::Facet { facet: 0, edge: 2 })));
    assert!((g.site.width_m - 0.03).abs() < 1e-12);
    let no = plan(&sloped_top(31.0));
    assert!(no.chosen.is_none());
    let r = reasons_for(&no, 0);
    assert!(matches!(r[..], [RejectReason::TopEdgeTooSteep { slope_rad }] if (slope_rad.to_degrees() - 31.0).abs() < 1e-9), "{r:?}");
    // Side and bottom edges are not top edges: a spire (sides 80° from horizontal, the facet
    // beside them rather than below) has none, and says so.
    let spire = scene(vec![facet(vec![p(0.0, 0.0, 0.0), p(0.0, 0.02, 0.0), p(0.0, 0.01, 0.06)], 0)], vec![]);
    assert_eq!(reasons_for(&plan(&spire), 0), vec![RejectReason::NoTopEdge]);
}

#[test]
fn width_at_most_50_mm() {
    let ok = plan(&scene(block([0.0, 0.049], [0.0, 0.04], 0.04, 0), vec![]));
    assert!((ok.chosen.expect("49 mm fits").site.width_m - 0.049).abs() < 1e-12);
    let no = plan(&scene(block([0.0, 0.051], [0.0, 0.04], 0.04, 0), vec![]));
    assert!(no.chosen.is_none(), "{:?}", no.chosen);
    assert!(reasons_for(&no, 0).iter().any(|r| matches!(r, RejectReason::TooWide { width_m } if (width_m - 0.051).abs() < 1e-12)));
}

#[test]
fn a_thin_wall_is_grasped_only_across_a_measured_rear_edge() {
    // A face 40 mm tall (past the fingers' 25 mm) seen face-on, nothing reconstructed behind
    // it: a wall, or a block whose top falls away behind the face (random seed 12: a wedge
    // whose top drops 33 mm behind it), or whose top face was missed. The top edge paired
    // with itself passes the collision tests only because nothing was seen: never grasped.
    let wall = facet(vec![p(0.0, 0.0, 0.0), p(0.0, 0.06, 0.0), p(0.0, 0.06, 0.04), p(0.0, 0.0, 0.04)], 0);
    let unseen = plan(&scene(vec![wall.clone()], vec![]));
    assert!(unseen.chosen.is_none(), "{:?}", unseen.chosen);
    let r: Vec<_> = unseen.rejected.iter().filter(|x| x.reason == RejectReason::ThicknessUnmeasured).collect();
    assert_eq!(r.len(), 1, "{:?}", unseen.rejected);
    assert_eq!(r[0].rear_edge, Some(EdgeRef::Facet { facet: 0, edge: 2 }));
    assert!(r[0].site.is_some_and(|s| s.width_m.abs() < 1e-12 && (s.front_m - p(0.0, 0.03, 0.04)).norm() < 1e-12));
    // What was seen does not settle it: no refusal, and the user is told why.
    assert!(!refusal_grounded(&scene(vec![wall.clone()], vec![]), &unseen.rejected, |_| Some("+x face".into())));
    assert_eq!(why_no_grasp(&unseen.rejected, |_| Some("+x face".into()), &GraspConfig::default()), "nothing seen behind its +x face says how thick it is");
    // The wall's back edge measured 3 mm behind its face: grasped across it.
    let back = SceneEdge { segment: Segment3::new(p(-0.003, 0.0, 0.04), p(-0.003, 0.06, 0.04)), component: 0 };
    let g = plan(&scene(vec![wall], vec![back])).chosen.expect("a grasp across the measured wall");
    assert_eq!(g.site.rear_edge, EdgeRef::Loose(0));
    assert_eq!(g.site.front_edge, 2);
    assert!((g.site.width_m - 0.003).abs() < 1e-12);
    assert!((g.site.front_m - p(0.0, 0.03, 0.04)).norm() < 1e-12, "the most central site");
    assert!((g.opening_m - 0.023).abs() < 1e-12);
}

#[test]
fn rear_edges_must_be_behind_the_facet() {
    // A parallel edge of the same object 20 mm in front of the face (towards the cameras).
    let front_edge = SceneEdge { segment: Segment3::new(p(0.06, 0.0, 0.04), p(0.06, 0.04, 0.04)), component: 0 };
    let plan = plan(&scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![front_edge]));
    let r = reasons_for(&plan, 0);
    assert!(r.iter().any(|x| matches!(x, RejectReason::RearInFront { width_m } if (width_m + 0.02).abs() < 1e-12)), "{r:?}");
    // Edges of another object never pair with this one.
    let other = SceneEdge { segment: Segment3::new(p(0.02, 0.0, 0.04), p(0.02, 0.04, 0.04)), component: 7 };
    let plan2 = plan_grasps(&scene(vec![facet(vec![p(0.04, 0.0, 0.0), p(0.04, 0.04, 0.0), p(0.04, 0.04, 0.04), p(0.04, 0.0, 0.04)], 0)], vec![other]), None, &GraspConfig::default()).unwrap();
    assert!(plan2.rejected.iter().all(|r| r.rear_edge != Some(EdgeRef::Loose(0))));
    assert!(plan2.candidates.iter().all(|g| g.site.rear_edge != EdgeRef::Loose(0)));
}

#[test]
fn fingers_collide_with_features_above_the_low_water_mark_only() {
    // Cube A, and a block B 10 mm behind it: the rear finger sweeps 3..20 mm behind A's back
    // face. B 30 mm tall reaches above the low-water mark (40 − 25 = 15 mm): collision.
    let tall_scene = a_and_b(0.03);
    let tall = plan(&tall_scene);
    let r = reasons_for(&tall, 0);
    assert!(r.iter().any(|x| matches!(x, RejectReason::FingerCollision { feature } if feature_component(&tall_scene, *feature) == 1)), "{r:?}");
    assert!(tall.candidates.iter().all(|g| g.site.facet != 0), "A must not be grasped");
    // B 10 mm tall stays below the low-water mark: no collision, A is grasped.
    let low = plan(&a_and_b(0.01));
    assert!(low.candidates.iter().any(|g| g.site.facet == 0 && (g.site.width_m - 0.04).abs() < 1e-12), "{:?}", low.rejected);
    // The front finger too: a low wall 8 mm in front of A, 20 mm tall.
    let mut f = block([0.0, 0.04], [0.0, 0.04], 0.04, 0);
    f.push(facet(vec![p(0.048, -0.02, 0.0), p(0.048, 0.06, 0.0), p(0.048, 0.06, 0.02), p(0.048, -0.02, 0.02)], 2));
    let front = plan(&scene(f, vec![]));
    assert!(reasons_for(&front, 0).iter().any(|x| matches!(x, RejectReason::FingerCollision { feature: FeatureRef::Facet(2) } | RejectReason::FingerCollision { feature: FeatureRef::Edge(EdgeRef::Facet { facet: 2, .. }) })), "{:?}", front.rejected);
}

/// Cube A (component 0) and block B (component 1) 10 mm behind it, `b_height` tall.
fn a_and_b(b_height: f64) -> GraspScene {
    let mut f = block([0.0, 0.04], [0.0, 0.04], 0.04, 0);
    f.extend(block([-0.05, -0.01], [-0.01, 0.05], b_height, 1));
    scene(f, vec![])
}

fn feature_component(s: &GraspScene, f: FeatureRef) -> usize {
    match f {
        FeatureRef::Facet(i) | FeatureRef::Edge(EdgeRef::Facet { facet: i, .. }) => s.facets[i].component,
        FeatureRef::Edge(EdgeRef::Loose(i)) => s.edges[i].component,
    }
}

#[test]
fn the_body_collides_with_features_above_the_high_water_mark() {
    // A thin post C 25 mm behind cube A: beyond the fingers (they reach 40 mm from the grasp
    // centre), inside the 100 mm body (50 mm). A post taller than the high-water mark
    // (40 + 25 = 65 mm) hits the body; a shorter one does not.
    let post = |h: f64| SceneEdge { segment: Segment3::new(p(-0.025, 0.02, 0.0), p(-0.025, 0.02, h)), component: 3 };
    let hit = plan(&scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![post(0.08)]));
    assert!(reasons_for(&hit, 0).contains(&RejectReason::BodyCollision { feature: FeatureRef::Edge(EdgeRef::Loose(0)) }), "{:?}", hit.rejected);
    assert!(hit.chosen.is_none());
    let clear = plan(&scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![post(0.06)]));
    assert!(clear.chosen.is_some_and(|g| g.site.facet == 0), "{:?}", clear.rejected);
    // Across the jaw axis the body is only 40 mm thick: the tall post 25 mm to the side of
    // the grasp centre misses it.
    let beside = SceneEdge { segment: Segment3::new(p(0.02, 0.045, 0.0), p(0.02, 0.045, 0.08)), component: 3 };
    assert!(plan(&scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![beside])).chosen.is_some());
}

#[test]
fn the_highest_collision_free_site_of_a_facet_is_kept() {
    // A stepped front face: top edges at 40 mm (y 0..30 mm) and 60 mm (y 30..60 mm), with
    // the top faces of both steps.
    let front = facet(vec![p(0.04, 0.0, 0.0), p(0.04, 0.06, 0.0), p(0.04, 0.06, 0.06), p(0.04, 0.03, 0.06), p(0.04, 0.03, 0.04), p(0.04, 0.0, 0.04)], 0);
    let low_top = facet(vec![p(0.0, 0.0, 0.04), p(0.04, 0.0, 0.04), p(0.04, 0.03, 0.04), p(0.0, 0.03, 0.04)], 0);
    let high_top = facet(vec![p(0.0, 0.03, 0.06), p(0.04, 0.03, 0.06), p(0.04, 0.06, 0.06), p(0.0, 0.06, 0.06)], 0);
    let plan = plan(&scene(vec![front, low_top, high_top], vec![]));
    let g = plan.chosen.expect("a grasp");
    assert!((g.site.front_m - p(0.04, 0.045, 0.06)).norm() < 1e-12, "{:?}", g.site);
    let lower: Vec<_> = plan.rejected.iter().filter(|r| r.reason == RejectReason::NotHighest).collect();
    assert_eq!(lower.len(), 1, "{:?}", plan.rejected);
    let site = lower[0].site.unwrap();
    assert!((site.front_m - p(0.04, 0.015, 0.04)).norm() < 1e-12 && (site.width_m - 0.04).abs() < 1e-12, "{site:?}");
}

#[test]
fn the_site_nearest_the_indicated_point_is_chosen() {
    // Two cubes 200 mm apart; the right one 5 mm taller.
    let mut f = block([0.0, 0.04], [-0.12, -0.08], 0.04, 0);
    f.extend(block([0.0, 0.04], [0.08, 0.12], 0.045, 1));
    let s = scene(f, vec![]);
    let cfg = GraspConfig::default();
    let near_left = plan_grasps(&s, Some(&p(0.1, -0.13, 0.05)), &cfg).unwrap();
    assert_eq!(near_left.candidates.len(), 2);
    assert_eq!(near_left.chosen.unwrap().site.facet, 0);
    let near_right = plan_grasps(&s, Some(&p(0.0, 0.05, 0.05)), &cfg).unwrap();
    assert_eq!(near_right.chosen.unwrap().site.facet, 2);
    assert_eq!(near_right.candidates[1].site.facet, 0);
    // Nothing indicated: the highest.
    assert_eq!(plan_grasps(&s, None, &cfg).unwrap().chosen.unwrap().site.facet, 2);
}

#[test]
fn yaw_follows_the_jaw_axis_modulo_half_a_turn() {
    // A cube turned 30° about z, its front face towards the cameras.
    let (c, s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let r = |x: f64, y: f64, z: f64| p(c * x - s * y, s * x + c * y, z);
    let front = facet(vec![r(0.02, -0.02, 0.0), r(0.02, 0.02, 0.0), r(0.02, 0.02, 0.04), r(0.02, -0.02, 0.04)], 0);
    let top = facet(vec![r(-0.02, -0.02, 0.04), r(0.02, -0.02, 0.04), r(0.02, 0.02, 0.04), r(-0.02, 0.02, 0.04)], 0);
    let g = plan(&scene(vec![front, top], vec![])).chosen.unwrap();
    // The jaw axis points from the front face inwards, at 210°; the symmetric yaw is 30°.
    assert!((g.site.jaw_axis - r(-1.0, 0.0, 0.0)).norm() < 1e-12);
    assert!((g.yaw_rad.to_degrees() - 30.0).abs() < 1e-9, "{}", g.yaw_rad.to_degrees());
    assert!((g.tool_m - p(0.0, 0.0, 0.015)).norm() < 1e-12);
    assert!(symmetric_yaw(std::f64::consts::FRAC_PI_2) == std::f64::consts::FRAC_PI_2);
    assert!((symmetric_yaw(-std::f64::consts::FRAC_PI_2) - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
}

#[test]
fn bad_input_is_a_named_error() {
    let cfg = GraspConfig::default();
    let mut f = block([0.0, 0.04], [0.0, 0.04], 0.04, 0);
    f[1].polygon_m[2].z = f64::NAN;
    assert_eq!(plan_grasps(&scene(f, vec![]), None, &cfg), Err(GraspError::InvalidFacet { index: 1, problem: "polygon_m has a coordinate that is not finite" }));
    let line = facet(vec![p(0.0, 0.0, 0.0), p(0.0, 0.01, 0.0), p(0.0, 0.02, 0.0)], 0);
    assert!(matches!(plan_grasps(&scene(vec![line], vec![]), None, &cfg), Err(GraspError::InvalidFacet { index: 0, .. })));
    let dot = SceneEdge { segment: Segment3::new(p(0.0, 0.0, 0.0), p(0.0, 0.0, 0.0)), component: 0 };
    assert!(matches!(plan_grasps(&scene(vec![], vec![dot]), None, &cfg), Err(GraspError::InvalidEdge { index: 0, .. })));
    let s = scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![]);
    assert_eq!(plan_grasps(&s, Some(&p(f64::NAN, 0.0, 0.0)), &cfg), Err(GraspError::InvalidIndicatedPoint));
    assert_eq!(plan_grasps(&GraspScene { toward_viewer: Vector3::zeros(), ..s.clone() }, None, &cfg), Err(GraspError::InvalidViewDirection));
    let bad = GraspConfig { gripper: GripperModel { max_width_m: -1.0, ..Default::default() }, ..cfg };
    assert!(matches!(plan_grasps(&s, None, &bad), Err(GraspError::Config { field: "gripper.max_width_m", .. })));
    // An empty scene is no error, just no grasp.
    assert!(plan_grasps(&scene(vec![], vec![]), None, &cfg).unwrap().chosen.is_none());
}

#[test]
fn loose_edges_hit_fingers_and_facets_hit_the_body() {
    // A loose edge of another object 10 mm behind cube A, 30 mm up (above the 15 mm
    // low-water mark), across the rear finger's path: a finger collision with that edge.
    let bar = SceneEdge { segment: Segment3::new(p(-0.01, -0.02, 0.03), p(-0.01, 0.06, 0.03)), component: 5 };
    let hit = plan(&scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![bar]));
    assert!(reasons_for(&hit, 0).contains(&RejectReason::FingerCollision { feature: FeatureRef::Edge(EdgeRef::Loose(0)) }), "{:?}", hit.rejected);
    assert!(hit.chosen.is_none());
    // The same edge 10 mm up stays below the low-water mark.
    let low = SceneEdge { segment: Segment3::new(p(-0.01, -0.02, 0.01), p(-0.01, 0.06, 0.01)), component: 5 };
    assert!(plan(&scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![low])).chosen.is_some());
    // A wall 25 mm behind A: past the fingers (they reach 20 mm behind the back face), inside
    // the body's 100 mm. Taller than the high-water mark (65 mm) its facet hits the body.
    let wall = |h: f64| facet(vec![p(-0.025, -0.03, 0.0), p(-0.025, 0.07, 0.0), p(-0.025, 0.07, h), p(-0.025, -0.03, h)], 6);
    let mut f = block([0.0, 0.04], [0.0, 0.04], 0.04, 0);
    f.push(wall(0.08));
    let tall = plan(&scene(f, vec![]));
    assert!(reasons_for(&tall, 0).contains(&RejectReason::BodyCollision { feature: FeatureRef::Facet(2) }), "{:?}", tall.rejected);
    let mut f = block([0.0, 0.04], [0.0, 0.04], 0.04, 0);
    f.push(wall(0.06));
    assert!(plan(&scene(f, vec![])).candidates.iter().any(|g| g.site.facet == 0));
}

#[test]
fn a_gripper_that_only_opens_fully_sweeps_its_fingers_out_to_the_full_opening() {
    // Cube A and a block B 25 mm behind it, 30 mm tall (above the low-water mark). With the
    // default 10 mm clearance the rear finger reaches 20 mm behind A: clear. Opening fully
    // to 80 mm it reaches 20 + 12 mm behind A and hits B.
    let mut f = block([0.0, 0.04], [0.0, 0.04], 0.04, 0);
    f.extend(block([-0.065, -0.025], [-0.01, 0.05], 0.03, 1));
    let s = scene(f, vec![]);
    assert!(plan(&s).candidates.iter().any(|g| g.site.facet == 0 && (g.opening_m - 0.06).abs() < 1e-12));
    let full = GraspConfig { gripper: GripperModel { jaw_opening_m: Some(0.08), finger_thickness_m: 0.012, ..Default::default() }, ..Default::default() };
    let p = plan_grasps(&s, None, &full).unwrap();
    assert!(p.candidates.iter().all(|g| g.site.facet != 0), "{:?}", p.candidates);
    assert!(reasons_for(&p, 0).iter().any(|r| matches!(r, RejectReason::FingerCollision { .. })));
    // Without B, the grasp opens to 80 mm.
    let alone = plan_grasps(&scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![]), None, &full).unwrap();
    assert!((alone.chosen.unwrap().opening_m - 0.08).abs() < 1e-12);
    let bad = GraspConfig { gripper: GripperModel { jaw_opening_m: Some(0.03), ..Default::default() }, ..Default::default() };
    assert!(matches!(plan_grasps(&s, None, &bad), Err(GraspError::Config { field: "gripper.jaw_opening_m", .. })));
}

#[test]
fn facets_turned_from_the_viewer_can_be_left_out() {
    // A cube turned 50° about z, the viewer along +x: its two visible sides face 50° and
    // 40° away from it in plan view.
    let (c, s) = (50f64.to_radians().cos(), 50f64.to_radians().sin());
    let r = |x: f64, y: f64, z: f64| p(c * x - s * y, s * x + c * y, z);
    let side = |a: [f64; 2], b: [f64; 2]| facet(vec![r(a[0], a[1], 0.0), r(b[0], b[1], 0.0), r(b[0], b[1], 0.04), r(a[0], a[1], 0.04)], 0);
    let facets = vec![
        side([0.02, -0.02], [0.02, 0.02]),   // normal at 50°
        side([-0.02, -0.02], [0.02, -0.02]), // normal at −40°
        facet(vec![r(-0.02, -0.02, 0.04), r(0.02, -0.02, 0.04), r(0.02, 0.02, 0.04), r(-0.02, 0.02, 0.04)], 0),
    ];
    let s = GraspScene { facets, edges: vec![], toward_viewer: p(1.0, 0.0, 0.6) };
    assert_eq!(plan(&s).candidates.len(), 2, "by default both sides");
    let cfg = GraspConfig { max_view_angle_rad: 45f64.to_radians(), ..Default::default() };
    let limited = plan_grasps(&s, None, &cfg).unwrap();
    assert_eq!(limited.candidates.len(), 1);
    assert_eq!(limited.chosen.unwrap().site.facet, 1);
    assert!(matches!(reasons_for(&limited, 0)[..], [RejectReason::TurnedFromViewer { angle_rad }] if (angle_rad.to_degrees() - 50.0).abs() < 1e-9));
}

#[test]
fn the_grasped_objects_own_faces_collide_only_past_the_object_tolerance() {
    // Cube A's front and top faces, and its right side face (y = 0.04) reconstructed 6 mm
    // too deep: it pokes 6 mm past the back face, into the rear finger's sweep (the fingers
    // are 20 mm broad along the edge, so shift the side face to the middle, y = 0.02, to
    // put it under them).
    let mut f = block([0.0, 0.04], [0.0, 0.04], 0.04, 0);
    f.push(facet(vec![p(0.04, 0.02, 0.0), p(-0.006, 0.02, 0.0), p(-0.006, 0.02, 0.04), p(0.04, 0.02, 0.04)], 0));
    let s = scene(f, vec![]);
    let strict = plan(&s);
    assert!(reasons_for(&strict, 0).iter().any(|r| matches!(r, RejectReason::FingerCollision { feature: FeatureRef::Facet(2) })), "{:?}", strict.rejected);
    assert!(strict.candidates.iter().all(|g| g.site.facet != 0));
    let tolerant = plan_grasps(&s, None, &GraspConfig { object_tolerance_m: 0.008, ..Default::default() }).unwrap();
    assert!(tolerant.candidates.iter().any(|g| g.site.facet == 0 && (g.site.width_m - 0.04).abs() < 1e-12), "{:?}", tolerant.rejected);
    // Another object 6 mm behind the back face still collides at that tolerance.
    let mut f = block([0.0, 0.04], [0.0, 0.04], 0.04, 0);
    f.push(facet(vec![p(-0.006, -0.02, 0.0), p(-0.006, 0.06, 0.0), p(-0.006, 0.06, 0.04), p(-0.006, -0.02, 0.04)], 3));
    let other = plan_grasps(&scene(f, vec![]), None, &GraspConfig { object_tolerance_m: 0.008, ..Default::default() }).unwrap();
    assert!(other.candidates.iter().all(|g| g.site.facet != 0));
}

#[test]
fn the_site_is_the_middle_of_the_overlap_of_top_and_rear_edge() {
    // A face 60 mm along y with its top edge at 40 mm; a loose rear edge of the same object
    // 30 mm behind, from y = 30 to 90 mm: they overlap over y 30..60 mm, and the site is
    // the overlap's middle (the most central site of the pair), not the face's.
    let front = facet(vec![p(0.04, 0.0, 0.0), p(0.04, 0.06, 0.0), p(0.04, 0.06, 0.04), p(0.04, 0.0, 0.04)], 0);
    let rear = SceneEdge { segment: Segment3::new(p(0.01, 0.03, 0.04), p(0.01, 0.09, 0.04)), component: 0 };
    let g = plan(&scene(vec![front], vec![rear])).chosen.expect("a grasp");
    assert_eq!(g.site.rear_edge, EdgeRef::Loose(0));
    assert!((g.site.front_m - p(0.04, 0.045, 0.04)).norm() < 1e-12, "{:?}", g.site.front_m);
    assert!((g.site.rear_m - p(0.01, 0.045, 0.04)).norm() < 1e-12, "{:?}", g.site.rear_m);
    assert!((g.site.centre_m - p(0.025, 0.045, 0.04)).norm() < 1e-12);
    assert!((g.site.facet_st[0] - 0.75).abs() < 1e-12 && (g.site.facet_st[1] - 1.0).abs() < 1e-12, "{:?}", g.site.facet_st);
    // Pairs that overlap by less than `min_overlap_m` are no pairs.
    let front = facet(vec![p(0.04, 0.0, 0.0), p(0.04, 0.06, 0.0), p(0.04, 0.06, 0.04), p(0.04, 0.0, 0.04)], 0);
    let sliver = SceneEdge { segment: Segment3::new(p(0.01, 0.057, 0.04), p(0.01, 0.09, 0.04)), component: 0 };
    let r = plan(&scene(vec![front], vec![sliver]));
    assert!(r.rejected.iter().any(|x| x.reason == RejectReason::NoOverlap && x.rear_edge == Some(EdgeRef::Loose(0))), "{:?}", r.rejected);
}

#[test]
fn rejected_sites_keep_their_place_width_and_reason() {
    // Cube A with a tall block B 10 mm behind it (the finger case above): the site across A
    // is rejected, and the rejection says where it was, how wide, against which rear edge,
    // and what it hit.
    let s = a_and_b(0.03);
    let r = plan(&s);
    let hit = r
        .rejected
        .iter()
        .find(|x| x.facet == 0 && matches!(x.reason, RejectReason::FingerCollision { .. }) && x.site.is_some_and(|s| (s.width_m - 0.04).abs() < 1e-12))
        .unwrap_or_else(|| panic!("{:?}", r.rejected));
    let site = hit.site.unwrap();
    assert!((site.front_m - p(0.04, 0.02, 0.04)).norm() < 1e-12, "{site:?}");
    assert_eq!(hit.front_edge, Some(site.front_edge));
    assert_eq!(hit.rear_edge, Some(site.rear_edge));
    let RejectReason::FingerCollision { feature } = hit.reason else { unreachable!() };
    assert_eq!(feature_component(&s, feature), 1, "the feature hit is B's");
    // Too wide: the site and its width are kept as well.
    let wide = plan(&scene(block([0.0, 0.06], [0.0, 0.04], 0.04, 0), vec![]));
    let too_wide = wide.rejected.iter().find(|x| matches!(x.reason, RejectReason::TooWide { .. })).expect("a too-wide site");
    assert!(too_wide.site.is_some_and(|s| (s.width_m - 0.06).abs() < 1e-12 && (s.front_m - p(0.06, 0.02, 0.04)).norm() < 1e-12), "{too_wide:?}");
    // Facet-level rules reject before a site exists, with the measured angle.
    let leaning = plan(&leaning_block(25.0));
    assert!(leaning.rejected.iter().any(|x| x.site.is_none() && matches!(x.reason, RejectReason::FacetNotVertical { tilt_rad } if (tilt_rad.to_degrees() - 25.0).abs() < 1e-9)));
}

#[test]
fn the_width_limit_is_the_gripper_models() {
    // A 60 mm deep block: over the default 50 mm, within a gripper model allowing 64 mm.
    let s = scene(block([0.0, 0.06], [0.0, 0.04], 0.04, 0), vec![]);
    assert!(plan(&s).chosen.is_none());
    let wide = GraspConfig { gripper: GripperModel { max_width_m: 0.064, ..Default::default() }, ..Default::default() };
    let g = plan_grasps(&s, None, &wide).unwrap().chosen.expect("60 mm within a 64 mm limit");
    assert!((g.site.width_m - 0.06).abs() < 1e-12);
    assert!((g.opening_m - 0.08).abs() < 1e-12, "width plus both fingers' clearance");
}

#[test]
fn a_pointed_points_error_widens_as_near_on_its_own_object_only() {
    // Two 25 x 42 x 30 mm bars 58 mm apart along y. Bar A offers its +y end face (seen nearly
    // edge-on from the cameras at +x), bar B its +x face. The point lies 46 mm from A's site
    // and 54 mm from B's.
    let (x1, h) = (0.025, 0.03);
    let bars = |b_component: usize| {
        let (a0, a1, b0, b1) = (0.0, 0.042, 0.1, 0.142);
        let a_end = facet(vec![p(0.0, a1, 0.0), p(x1, a1, 0.0), p(x1, a1, h), p(0.0, a1, h)], 0);
        let a_top = facet(vec![p(0.0, a0, h), p(x1, a0, h), p(x1, a1, h), p(0.0, a1, h)], 0);
        let b_front = facet(vec![p(x1, b0, 0.0), p(x1, b1, 0.0), p(x1, b1, h), p(x1, b0, h)], b_component);
        let b_top = facet(vec![p(0.0, b0, h), p(x1, b0, h), p(x1, b1, h), p(0.0, b1, h)], b_component);
        scene(vec![a_end, a_top, b_front, b_top], vec![])
    };
    let point = p(0.0125, 0.067, 0.0);
    let chosen = |s: &GraspScene, sigma_m: f64| {
        let cfg = GraspConfig { indicated_sigma_m: sigma_m, ..GraspConfig::default() };
        plan_grasps(s, Some(&point), &cfg).unwrap().chosen.expect("a site").site.facet
    };
    // A point given as a coordinate: the nearest site, A's end face (8 mm nearer).
    assert_eq!(chosen(&bars(0), 0.0), 0);
    // A pointed point with a 6.5 mm sigma cannot tell 8 mm apart: of its object's sites,
    // the one facing the cameras.
    assert_eq!(chosen(&bars(0), 0.0065), 2);
    // A site on another object is not drawn in by the point's error: the point picks the
    // object (and the plan judges elsewhere whether it picks one at all).
    assert_eq!(chosen(&bars(1), 0.0065), 0);
    // A 2 mm sigma does not reach 8 mm either.
    assert_eq!(chosen(&bars(0), 0.002), 0);
}

#[test]
fn of_two_faces_as_near_the_point_the_one_facing_the_cameras_is_chosen() {
    // A 25 x 42 x 30 mm bar: its +y end face listed first, its long +x face (towards the
    // cameras at +x) second, and its top. Both grasps are centred on the bar, as near the
    // point as each other; the end face is seen nearly edge-on.
    let (x1, y1, h) = (0.025, 0.042, 0.03);
    let side = facet(vec![p(0.0, y1, 0.0), p(x1, y1, 0.0), p(x1, y1, h), p(0.0, y1, h)], 0);
    let front = facet(vec![p(x1, 0.0, 0.0), p(x1, y1, 0.0), p(x1, y1, h), p(x1, 0.0, h)], 0);
    let top = facet(vec![p(0.0, 0.0, h), p(x1, 0.0, h), p(x1, y1, h), p(0.0, y1, h)], 0);
    let s = scene(vec![side, front, top], vec![]);
    let plan = plan_grasps(&s, Some(&p(0.0125, 0.021, 0.0)), &GraspConfig::default()).unwrap();
    let sites: Vec<usize> = plan.candidates.iter().map(|g| g.site.facet).collect();
    assert!(sites.contains(&0) && sites.contains(&1), "both faces graspable: {sites:?}");
    let g = plan.chosen.unwrap();
    assert_eq!(g.site.facet, 1, "the face towards the cameras");
    assert!((g.site.width_m - x1).abs() < 1e-9);
}

/// A face towards the cameras (+x) 40 mm along y whose top edge rises from 20 mm by
/// `slope_deg`, on a block 30 mm deep.
fn sloped_front(slope_deg: f64) -> GraspScene {
    let rise = 0.04 * slope_deg.to_radians().tan();
    let front = facet(vec![p(0.03, 0.0, 0.0), p(0.03, 0.04, 0.0), p(0.03, 0.04, 0.02 + rise), p(0.03, 0.0, 0.02)], 0);
    scene(vec![front], vec![SceneEdge { segment: Segment3::new(p(0.0, 0.0, 0.02), p(0.0, 0.04, 0.02 + rise)), component: 0 }])
}

#[test]
fn a_top_edge_slope_within_its_error_of_the_limit_is_neither_grasped_nor_refused() {
    let sigma = GraspConfig { point_sigma_m: 0.001, ..Default::default() };
    // 32°: past 30° on exact geometry, within 30° plus its error (~4° over a 40 mm run).
    let s = sloped_front(32.0);
    let exact = plan_grasps(&s, None, &GraspConfig::default()).unwrap();
    assert!(reasons_for(&exact, 0).iter().any(|r| matches!(r, RejectReason::TopEdgeTooSteep { .. })));
    let measured = plan_grasps(&s, None, &sigma).unwrap();
    assert!(measured.chosen.is_none(), "never attempt on a slope that passes only within its error");
    assert!(reasons_for(&measured, 0).iter().any(|r| matches!(r, RejectReason::TopEdgeSlopeUnsettled { .. })), "{:?}", measured.rejected);
    assert!(!refusal_grounded(&s, &measured.rejected, |_| Some("face".into())), "unsettled is not a refusal");
    // 28°: within 30° on exact geometry (grasped), but not beyond its error: not grasped.
    let s = sloped_front(28.0);
    assert!(plan_grasps(&s, None, &GraspConfig::default()).unwrap().chosen.is_some());
    assert!(plan_grasps(&s, None, &sigma).unwrap().chosen.is_none());
    // 40°: past 30° beyond its error: steep, a grounded refusal.
    let s = sloped_front(40.0);
    let steep = plan_grasps(&s, None, &sigma).unwrap();
    assert!(reasons_for(&steep, 0).iter().any(|r| matches!(r, RejectReason::TopEdgeTooSteep { .. })));
    assert!(refusal_grounded(&s, &steep.rejected, |_| Some("face".into())));
}

/// A wedge's slope facing the cameras (+x): from z = `rise` at x = 0 down to 0 at x = `run`.
fn wedge_slope(run_m: f64, rise_m: f64) -> GraspScene {
    scene(vec![facet(vec![p(run_m, 0.0, 0.0), p(run_m, 0.04, 0.0), p(0.0, 0.04, rise_m), p(0.0, 0.0, rise_m)], 0)], vec![])
}

#[test]
fn a_seen_sloping_top_refuses_only_when_every_rule_fails_beyond_the_error() {
    let sigma = GraspConfig { point_sigma_m: 0.001, ..Default::default() };
    // 45 mm over 30 mm: 56° from horizontal, 34° from vertical, rising 45 mm.
    let slope = sloping_top_rad(&wedge_slope(0.03, 0.045), 0, &sigma).expect("a refusal");
    assert!((slope.to_degrees() - 56.3).abs() < 0.5, "{}", slope.to_degrees());
    // Rising 27 mm: past the fingers' 25 mm only within the error: not settled.
    assert_eq!(sloping_top_rad(&wedge_slope(0.02, 0.027), 0, &sigma), None);
    // 25° from horizontal: its top edges are within 30°: no refusal.
    assert_eq!(sloping_top_rad(&wedge_slope(0.07, 0.07 * 25f64.to_radians().tan()), 0, &sigma), None);
    // 75° from horizontal (15° from vertical): the face itself may be graspable.
    assert_eq!(sloping_top_rad(&wedge_slope(0.01, 0.01 * 75f64.to_radians().tan()), 0, &sigma), None);
    // A flat top is no sloping top.
    assert_eq!(sloping_top_rad(&scene(block([0.0, 0.04], [0.0, 0.04], 0.04, 0), vec![]), 1, &sigma), None);
}

#[test]
fn a_sloping_face_with_its_own_block_above_it_is_not_the_blocks_top() {
    let sigma = GraspConfig { point_sigma_m: 0.001, ..Default::default() };
    // The wedge of the test above (45 mm over 30 mm) with its vertical back (x = 0) and one
    // triangular side (y = 0): their corners lie on or under the slope, and it still refuses.
    let mut wedge = wedge_slope(0.03, 0.045);
    wedge.facets.push(facet(vec![p(0.0, 0.0, 0.0), p(0.0, 0.04, 0.0), p(0.0, 0.04, 0.045), p(0.0, 0.0, 0.045)], 0));
    wedge.facets.push(facet(vec![p(0.0, 0.0, 0.0), p(0.03, 0.0, 0.0), p(0.0, 0.0, 0.045)], 0));
    assert!(sloping_top_rad(&wedge, 0, &sigma).is_some(), "a wedge's own sides never rise above its slope");
    // A level face of the same block at 25 mm over x = 15..25 mm, where the slope is 22.5 to
    // 7.5 mm high: up to 10 mm above its plane (the error 4 mm). The slope is not the block's
    // top, and nothing is settled.
    let level = |component| facet(vec![p(0.015, 0.0, 0.025), p(0.025, 0.0, 0.025), p(0.025, 0.04, 0.025), p(0.015, 0.04, 0.025)], component);
    let mut above = wedge.clone();
    above.facets.push(level(0));
    assert_eq!(sloping_top_rad(&above, 0, &sigma), None);
    // The same face on another block (another component) does not count.
    let mut beside = wedge.clone();
    beside.facets.push(level(1));
    assert!(sloping_top_rad(&beside, 0, &sigma).is_some());
}
