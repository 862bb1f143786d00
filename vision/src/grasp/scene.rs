//! From the planner's reconstruction of one stereo pair ([`crate::planner::Plan`]) to the
//! grasp planner's [`GraspScene`]: facets as 3-D polygons with their boundary sides as
//! edges, the reconstructed segments that lie on no facet as loose edges, and one connected
//! component per object.
//!
//! # Choices
//! - **Facet edges are the polygon's sides** (thesis 5.6.2, the facet boundary
//!   description): the planner extends segment ends to their junctions, so the sides reach the
//!   corners where the matched segments stop short of them, and every facet has a complete
//!   boundary to find its top edge on.
//! - **Components** (the thesis's "3-D connected component"): the planner joins facets that
//!   share a segment or meet at a junction seen in both views; a loose segment joins the
//!   component of any facet member (or other loose segment) it meets at such a junction
//!   ("friends"). Then, in 3-D, within `join_m`: a loose segment whose end touches a facet's
//!   outline or another segment joins it, and two facets sharing an edge (two corners of one
//!   on the other's outline) are one object. So an edge seen behind a facet is on its object,
//!   as the rear-edge rule needs, even where a junction was seen in one view only. A loose
//!   segment that meets nothing is an object of its own: an obstacle only.
//! - **Height limit**: features whose lowest point is above `max_height_m` are dropped. The
//!   arm parked above the workspace is in view while the planner looks; it moves away before
//!   the grasp, so it is no obstacle (the gripper itself is masked out of the images before
//!   planning).
//! - A facet whose polygon is degenerate in 3-D (under 1 mm², or with no corner to anchor its
//!   frame) is dropped rather than failing the whole plan; its polygon is rotated so that its
//!   first vertex is a proper corner (the facet frame `facet_st` is anchored there), and the
//!   image polygons are rotated the same way.

use nalgebra::Vector3;

use super::{GraspScene, SceneEdge, SceneFacet, Segment3};
use crate::planner::Plan;
use crate::union_find::UnionFind;

/// A facet of the scene with where it came from.
#[derive(Debug, Clone, PartialEq)]
pub struct FacetSource {
    /// Index into `Plan::facets` (for a hypothesised facet: the top face it hangs from).
    pub plan_facet: usize,
    /// Not seen as a facet but hypothesised below a top face's front edge
    /// ([`hypothesise_front_faces`]).
    pub hypothesised: bool,
    /// The facet's outline in the left and right image, in the planner's pixel convention,
    /// vertex for vertex with the scene facet's `polygon_m` (same first vertex, same order).
    pub left_px: Vec<[f64; 2]>,
    pub right_px: Vec<[f64; 2]>,
    /// A hypothesised face hung from a top face down to a lower top face in front of it
    /// (an L-block's step), not to the table: that lower face's component. Once the face is
    /// seen, the two tops are one object (their join, the step, is this face).
    pub steps_onto: Option<usize>,
}

/// A [`GraspScene`] built from a plan, with the image polygons of its facets.
#[derive(Debug, Clone, PartialEq)]
pub struct PlannedScene {
    pub scene: GraspScene,
    /// One per `scene.facets`.
    pub facets: Vec<FacetSource>,
    /// Index into `Plan::matches` of each of `scene.edges`.
    pub edge_matches: Vec<usize>,
    /// Plan facets left out (no robot coordinates, degenerate, or above the height limit).
    pub dropped_facets: Vec<usize>,
}

/// Facets larger than this (m²) are not joined to what touches them (see the module docs).
const MAX_JOIN_AREA_M2: f64 = 0.01;

/// Distance of point `p` from segment `a`-`b`.
fn point_segment_m(p: &Vector3<f64>, a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    let d = b - a;
    let l2 = d.norm_squared();
    let t = if l2 > 0.0 { ((p - a).dot(&d) / l2).clamp(0.0, 1.0) } else { 0.0 };
    (a + d * t - p).norm()
}

/// Distance of point `p` from a closed polygon's outline.
fn point_outline_m(p: &Vector3<f64>, poly: &[Vector3<f64>]) -> f64 {
    (0..poly.len()).map(|i| point_segment_m(p, &poly[i], &poly[(i + 1) % poly.len()])).fold(f64::INFINITY, f64::min)
}

fn v3(p: &[f64; 3]) -> Vector3<f64> {
    Vector3::new(p[0], p[1], p[2])
}

/// Index of the first vertex whose neighbours are not in line with it (a proper corner), if
/// any: the facet frame `polygon[0]`, `polygon[1] − polygon[0]`, `polygon[n−1] − polygon[0]`
/// needs one.
fn anchor_corner(poly: &[Vector3<f64>]) -> Option<usize> {
    let n = poly.len();
    // The most bent corner is the best-conditioned frame; ties keep the earliest.
    let bend = |i: usize| {
        let (o, u, v) = (poly[i], poly[(i + 1) % n], poly[(i + n - 1) % n]);
        let (a, b) = (u - o, v - o);
        let d = a.norm() * b.norm();
        if d > 0.0 { a.cross(&b).norm() / d } else { 0.0 }
    };
    let best = (0..n).max_by(|&a, &b| bend(a).total_cmp(&bend(b)).then(b.cmp(&a)))?;
    (bend(best) > 0.05).then_some(best)
}

/// Newell area (twice the area's norm) of a 3-D polygon, m².
fn area_m2(poly: &[Vector3<f64>]) -> f64 {
    let mut n = Vector3::zeros();
    for i in 0..poly.len() {
        n += poly[i].cross(&poly[(i + 1) % poly.len()]);
    }
    0.5 * n.norm()
}

/// Builds the grasp scene of `plan` (which must have been made with an affine model, so that
/// facets and matches carry robot coordinates; without one the scene is empty).
/// `toward_viewer` is [`crate::affine::AffineStereo::toward_cameras`]; features entirely above
/// `max_height_m` are left out; features closer than `join_m` in 3-D are one object (see the
/// module docs).
pub fn scene_from_plan(plan: &Plan, toward_viewer: Vector3<f64>, max_height_m: f64, join_m: f64) -> PlannedScene {
    let n_facets = plan.facets.len();
    let n_matches = plan.matches.len();
    // Nodes: plan facets, then matches. Facets with the planner's component id are joined.
    let mut uf = UnionFind::new(n_facets + n_matches);
    let mut first_of_component: Vec<Option<usize>> = Vec::new();
    for (fi, f) in plan.facets.iter().enumerate() {
        let c = f.facet.component as usize;
        if first_of_component.len() <= c {
            first_of_component.resize(c + 1, None);
        }
        match first_of_component[c] {
            Some(other) => uf.union(fi, other),
            None => first_of_component[c] = Some(fi),
        }
    }
    let mut match_of_candidate = std::collections::HashMap::new();
    for (mi, m) in plan.matches.iter().enumerate() {
        match_of_candidate.insert(m.candidate, mi);
        for &f in &m.facets {
            if (f as usize) < n_facets {
                uf.union(n_facets + mi, f as usize);
            }
        }
    }
    for fr in &plan.friends {
        if let (Some(&a), Some(&b)) = (match_of_candidate.get(&fr.a), match_of_candidate.get(&fr.b)) {
            uf.union(n_facets + a, n_facets + b);
        }
    }

    let mut facets = Vec::new();
    let mut sources = Vec::new();
    let mut dropped = Vec::new();
    for (fi, f) in plan.facets.iter().enumerate() {
        let Some(corners) = &f.corners_robot_m else {
            dropped.push(fi);
            continue;
        };
        let poly: Vec<Vector3<f64>> = corners.iter().map(v3).collect();
        let usable = poly.len() >= 3
            && poly.len() == f.facet.left.len()
            && poly.len() == f.facet.right.len()
            && poly.iter().all(|p| p.iter().all(|x| x.is_finite()))
            && area_m2(&poly) >= 1e-6
            && poly.iter().map(|p| p.z).fold(f64::INFINITY, f64::min) <= max_height_m;
        let Some(start) = usable.then(|| anchor_corner(&poly)).flatten() else {
            dropped.push(fi);
            continue;
        };
        let rotate = |v: &[[f64; 2]]| -> Vec<[f64; 2]> { (0..v.len()).map(|k| v[(start + k) % v.len()]).collect() };
        let polygon_m: Vec<Vector3<f64>> = (0..poly.len()).map(|k| poly[(start + k) % poly.len()]).collect();
        let n = polygon_m.len();
        let edges = (0..n).map(|k| Segment3::new(polygon_m[k], polygon_m[(k + 1) % n])).filter(|s| s.length_m() >= 1e-6).collect();
        facets.push((uf.find(fi), SceneFacet { polygon_m, edges, component: 0 }));
        sources.push(FacetSource { plan_facet: fi, hypothesised: false, left_px: rotate(&f.facet.left), right_px: rotate(&f.facet.right), steps_onto: None });
    }
    let mut edges = Vec::new();
    let mut edge_matches = Vec::new();
    for (mi, m) in plan.matches.iter().enumerate() {
        if !m.facets.is_empty() {
            continue; // on a facet: its polygon's sides stand for it
        }
        let Some(ends) = m.reconstruction.as_ref().and_then(|r| r.robot_m) else { continue };
        let (a, b) = (v3(&ends[0]), v3(&ends[1]));
        if !(a.iter().chain(b.iter()).all(|x| x.is_finite())) || (b - a).norm() < 1e-6 || a.z.min(b.z) > max_height_m {
            continue;
        }
        edges.push((uf.find(n_facets + mi), Segment3::new(a, b)));
        edge_matches.push(mi);
    }
    // 3-D contact: loose segments touching facets or each other, facets sharing an edge.
    // Facets bigger than any block face (a table top, a wall) join nothing: everything
    // touches them.
    let joinable: Vec<bool> = facets.iter().map(|(_, f)| area_m2(&f.polygon_m) <= MAX_JOIN_AREA_M2).collect();
    if join_m > 0.0 {
        for (ei, (_, e)) in edges.iter().enumerate() {
            let node = n_facets + edge_matches[ei];
            for (fk, (_, f)) in facets.iter().enumerate() {
                if joinable[fk] && [e.a_m, e.b_m].iter().any(|p| point_outline_m(p, &f.polygon_m) <= join_m) {
                    uf.union(node, sources[fk].plan_facet);
                }
            }
            for (ej, (_, o)) in edges.iter().enumerate().skip(ei + 1) {
                let touch = [e.a_m, e.b_m].iter().any(|p| point_segment_m(p, &o.a_m, &o.b_m) <= join_m)
                    || [o.a_m, o.b_m].iter().any(|p| point_segment_m(p, &e.a_m, &e.b_m) <= join_m);
                if touch {
                    uf.union(node, n_facets + edge_matches[ej]);
                }
            }
        }
        for (fa, (_, a)) in facets.iter().enumerate() {
            for (fb, (_, b)) in facets.iter().enumerate().skip(fa + 1) {
                let shared = |x: &SceneFacet, y: &SceneFacet| x.polygon_m.iter().filter(|p| point_outline_m(p, &y.polygon_m) <= join_m).count() >= 2;
                if joinable[fa] && joinable[fb] && (shared(a, b) || shared(b, a)) {
                    uf.union(sources[fa].plan_facet, sources[fb].plan_facet);
                }
            }
        }
    }
    let facets: Vec<(usize, SceneFacet)> = facets.into_iter().zip(&sources).map(|((_, f), src)| (uf.find(src.plan_facet), f)).collect();
    let edges: Vec<(usize, Segment3)> = edges.into_iter().zip(&edge_matches).map(|((_, e), &mi)| (uf.find(n_facets + mi), e)).collect();
    // Dense component ids in order of first appearance.
    let mut ids: Vec<usize> = Vec::new();
    let mut id_of = |root: usize| match ids.iter().position(|&r| r == root) {
        Some(i) => i,
        None => {
            ids.push(root);
            ids.len() - 1
        }
    };
    let facets: Vec<SceneFacet> = facets.into_iter().map(|(root, f)| SceneFacet { component: id_of(root), ..f }).collect();
    let edges: Vec<SceneEdge> = edges.into_iter().map(|(root, segment)| SceneEdge { segment, component: id_of(root) }).collect();
    PlannedScene { scene: GraspScene { facets, edges, toward_viewer }, facets: sources, edge_matches, dropped_facets: dropped }
}

/// Newell normal (unit) of a 3-D polygon, if it has an area.
fn unit_normal(poly: &[Vector3<f64>]) -> Option<Vector3<f64>> {
    let mut n = Vector3::zeros();
    for i in 0..poly.len() {
        n += poly[i].cross(&poly[(i + 1) % poly.len()]);
    }
    n.try_normalize(1e-12)
}

/// The lower top face in front of the side `a`-`b` of top face `top` (outward horizontal
/// normal `out`), if any: a facet within `max_tilt_rad` of horizontal, at least `min_z_m`
/// high and `min_step_m` below the side, of another component, on the side's outward side,
/// whose outline passes within `join_m` plus the step's height times `tan(max_tilt_rad)` of
/// both ends in plan view. The highest such face (the step the side stands on), with its
/// mean height.
#[allow(clippy::too_many_arguments)]
fn lower_top_in_front(
    facets: &[SceneFacet],
    top: usize,
    (a, b): (Vector3<f64>, Vector3<f64>),
    out: &Vector3<f64>,
    min_z_m: f64,
    min_step_m: f64,
    max_tilt_rad: f64,
    join_m: f64,
) -> Option<(usize, f64)> {
    let flat = |p: &Vector3<f64>| Vector3::new(p.x, p.y, 0.0);
    let mid = 0.5 * (a + b);
    let side_z = a.z.min(b.z);
    facets
        .iter()
        .enumerate()
        .filter(|&(g, f)| g != top && f.component != facets[top].component)
        .filter_map(|(g, f)| {
            let n = unit_normal(&f.polygon_m)?;
            let z = f.polygon_m.iter().map(|p| p.z).sum::<f64>() / f.polygon_m.len() as f64;
            let centroid = f.polygon_m.iter().sum::<Vector3<f64>>() / f.polygon_m.len() as f64;
            let reach = join_m + (side_z - z) * max_tilt_rad.tan();
            let outline: Vec<Vector3<f64>> = f.polygon_m.iter().map(flat).collect();
            let under = [a, b].iter().all(|p| point_outline_m(&flat(p), &outline) <= reach);
            (n.z.abs() >= max_tilt_rad.cos() && z >= min_z_m && side_z - z >= min_step_m && out.xy().dot(&(centroid - mid).xy()) > 0.0 && under).then_some((g, z))
        })
        .max_by(|x, y| x.1.total_cmp(&y.1))
}

/// Hypothesises the vertical faces the planner missed below the front edges of top faces:
/// a block resting on the table has a vertical face under each outline edge of its top, and
/// where that face looks towards the viewer the cameras see it. The thesis infers the
/// unseen rear face of a grasp from a parallel edge; this infers a seen-but-unmatched front
/// face from the top face's edge and the table's height (known like the cage, in robot
/// coordinates). The face's image outline comes from `project` (a robot point to both
/// views, planner pixels), so the target trackers can be put on it and will find out
/// whether it is there.
///
/// For every facet within `max_tilt_rad` of horizontal and at least `min_height_m` above
/// `table_z_m`, and every side of it whose outward horizontal normal is within
/// `max_view_angle_rad` of the viewer, unless a facet already runs along that side (its
/// outline within `join_m` of both ends): a quadrilateral from the side down to the table,
/// on the top face's object. Returns how many were added.
///
/// Where a lower top face lies in front of the side, its outline under both of the side's
/// ends in plan view, the face goes down to that top's height instead (an L-block's step
/// between its tall and its low leg; [`FacetSource::steps_onto`]): the reconstructed edges
/// of the two tops may be apart in plan view by the join distance plus what a face within
/// `max_tilt_rad` of vertical leans over the step's height.
pub fn hypothesise_front_faces(
    ps: &mut PlannedScene,
    project: &dyn Fn(&Vector3<f64>) -> Option<[[f64; 2]; 2]>,
    table_z_m: f64,
    min_height_m: f64,
    max_tilt_rad: f64,
    max_view_angle_rad: f64,
    join_m: f64,
) -> usize {
    let toward = Vector3::new(ps.scene.toward_viewer.x, ps.scene.toward_viewer.y, 0.0);
    let Some(toward) = toward.try_normalize(1e-12) else { return 0 };
    let mut added = Vec::new();
    for (fi, f) in ps.scene.facets.iter().enumerate() {
        let Some(n) = unit_normal(&f.polygon_m) else { continue };
        if n.z.abs() < max_tilt_rad.cos() {
            continue;
        }
        let k = f.polygon_m.len();
        let centroid = f.polygon_m.iter().sum::<Vector3<f64>>() / k as f64;
        for i in 0..k {
            let (a, b) = (f.polygon_m[i], f.polygon_m[(i + 1) % k]);
            if a.z.min(b.z) - table_z_m < min_height_m || (b - a).xy().norm() < 0.005 {
                continue;
            }
            let along = (b - a).xy().normalize();
            let mut out = Vector3::new(along.y, -along.x, 0.0);
            if out.xy().dot(&(0.5 * (a + b) - centroid).xy()) < 0.0 {
                out = -out;
            }
            if out.dot(&toward) < max_view_angle_rad.cos() {
                continue;
            }
            let covered = ps.scene.facets.iter().enumerate().any(|(j, g)| {
                j != fi && unit_normal(&g.polygon_m).is_some_and(|m| m.z.abs() < 0.5) && [a, b].iter().all(|p| point_outline_m(p, &g.polygon_m) <= join_m)
            });
            if covered {
                continue;
            }
            let step = lower_top_in_front(&ps.scene.facets, fi, (a, b), &out, table_z_m + min_height_m, min_height_m, max_tilt_rad, join_m);
            let bottom_z = step.map_or(table_z_m, |(_, z)| z);
            let (a0, b0) = (Vector3::new(a.x, a.y, bottom_z), Vector3::new(b.x, b.y, bottom_z));
            // Bottom corners first: the facet frame anchors at a corner with both sides long.
            let polygon_m = vec![a0, b0, b, a];
            let Some(px) = polygon_m.iter().map(project).collect::<Option<Vec<[[f64; 2]; 2]>>>() else { continue };
            let edges = (0..4).map(|e| Segment3::new(polygon_m[e], polygon_m[(e + 1) % 4])).collect();
            added.push((
                SceneFacet { polygon_m, edges, component: f.component },
                FacetSource {
                    plan_facet: ps.facets[fi].plan_facet,
                    hypothesised: true,
                    left_px: px.iter().map(|p| p[0]).collect(),
                    right_px: px.iter().map(|p| p[1]).collect(),
                    steps_onto: step.map(|(g, _)| ps.scene.facets[g].component),
                },
            ));
        }
    }
    let n = added.len();
    for (facet, source) in added {
        ps.scene.facets.push(facet);
        ps.facets.push(source);
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::affine::AffineStereo;
    use crate::grasp::{plan_grasps, GraspConfig};
    use crate::planner::synth::{BoxSpec, SynthScene};
    use crate::planner::{Planner, PlannerConfig, EpipolarGeometry};

    fn plan_scene(boxes: Vec<BoxSpec>, seed: u64) -> (PlannedScene, Plan) {
        let synth = SynthScene::new(boxes);
        let pair = synth.render(seed);
        let robot: Vec<Vector3<f64>> = pair.cage.iter().map(|c| Vector3::from(c.0)).collect();
        let image: Vec<[f64; 4]> = pair.cage.iter().map(|c| c.1).collect();
        let model = AffineStereo::fit(&robot, &image).unwrap();
        let toward = model.toward_cameras();
        let geo = EpipolarGeometry::from_model(model, 0.5, 10.0);
        let plan = Planner::new(PlannerConfig::default()).plan(&pair.left.view(), &pair.right.view(), &geo);
        (scene_from_plan(&plan, toward, 1.0, 0.004), plan)
    }

    /// The grasp rules on real planner output: a 40 x 30 x 45 mm box seen by the synthetic
    /// rig (cameras towards −y, above). Its two visible side faces are graspable, across the
    /// box's other dimension, and the whole chain holds: facets and their top edges, rear edge
    /// on the top face of the same component, width within a few mm of the box, tool at the
    /// low-water mark, the image polygons vertex for vertex with the 3-D ones.
    #[test]
    fn a_planned_box_is_grasped_across_a_side() {
        let b = BoxSpec { center_m: [0.0, 0.0, 0.0225], size_m: [0.040, 0.030, 0.045], yaw_rad: 0.5 };
        let (ps, plan) = plan_scene(vec![b], 3);
        assert_eq!(plan.facets.len(), 3, "top and two sides");
        assert_eq!(ps.scene.facets.len(), 3, "dropped {:?}", ps.dropped_facets);
        assert!(ps.scene.facets.iter().all(|f| f.component == ps.scene.facets[0].component), "one object");
        for (f, s) in ps.scene.facets.iter().zip(&ps.facets) {
            assert_eq!(f.polygon_m.len(), s.left_px.len());
            assert_eq!(f.polygon_m.len(), s.right_px.len());
        }
        let grasps = plan_grasps(&ps.scene, None, &GraspConfig::default()).unwrap();
        assert_eq!(grasps.candidates.len(), 2, "both side faces: {:?}", grasps.rejected);
        for g in &grasps.candidates {
            // Across the 40 mm or the 30 mm extent, whichever is behind the face.
            let n = g.site.jaw_axis;
            let ax = Vector3::new(0.5f64.cos(), 0.5f64.sin(), 0.0);
            let expected = if n.dot(&ax).abs() > 0.7 { 0.040 } else { 0.030 };
            assert!((g.site.width_m - expected).abs() < 0.004, "width {:.1} mm, expected {expected}", g.site.width_m * 1e3);
            assert!((g.site.front_m.z - 0.045).abs() < 0.003, "site on the top edge: {:?}", g.site.front_m);
            assert!((g.tool_m.z - 0.020).abs() < 0.003, "tool at the low-water mark");
            let c = g.site.centre_m;
            assert!(c.x.hypot(c.y) < 0.006, "centred on the box: {c:?}");
        }
        // The horizontal top face is a facet, but not a graspable one.
        assert!(grasps.rejected.iter().any(|r| matches!(r.reason, crate::grasp::RejectReason::FacetNotVertical { .. })));
    }

    /// Two boxes apart: a separate component each, and the indicated point picks the grasp.
    #[test]
    fn the_box_nearest_the_indicated_point_is_chosen_from_planner_output() {
        let a = BoxSpec { center_m: [-0.05, 0.0, 0.02], size_m: [0.035, 0.035, 0.04], yaw_rad: 0.4 };
        let b = BoxSpec { center_m: [0.05, 0.01, 0.02], size_m: [0.03, 0.04, 0.04], yaw_rad: -0.3 };
        let (ps, _) = plan_scene(vec![a, b], 5);
        let comps: std::collections::BTreeSet<usize> = ps.scene.facets.iter().map(|f| f.component).collect();
        assert_eq!(comps.len(), 2, "two objects");
        let cfg = GraspConfig::default();
        for (target, point) in [(a, Vector3::new(-0.07, -0.01, 0.06)), (b, Vector3::new(0.07, 0.02, 0.06))] {
            let g = plan_grasps(&ps.scene, Some(&point), &cfg).unwrap().chosen.expect("a grasp");
            let c = g.site.centre_m;
            let d = (c.x - target.center_m[0]).hypot(c.y - target.center_m[1]);
            assert!(d < 0.008, "grasp centre {c:?} is {:.1} mm from the box nearest {point:?}", d * 1e3);
        }
    }

    /// Two boxes whose facets the planner gave separate components (a junction seen in one
    /// view only) are still one object when they share an edge in 3-D; apart, they are two.
    #[test]
    fn facets_sharing_an_edge_in_3d_are_one_object() {
        let b = BoxSpec { center_m: [0.0, 0.0, 0.0225], size_m: [0.040, 0.030, 0.045], yaw_rad: 0.5 };
        let (_, mut plan) = plan_scene(vec![b], 3);
        for (i, f) in plan.facets.iter_mut().enumerate() {
            f.facet.component = i as u32;
        }
        plan.friends.clear();
        for m in plan.matches.iter_mut() {
            m.facets.truncate(1); // a crease on two facets would join them
        }
        let apart = scene_from_plan(&plan, Vector3::new(0.0, -1.0, 1.0), 1.0, 0.0);
        let comps: std::collections::BTreeSet<usize> = apart.scene.facets.iter().map(|f| f.component).collect();
        assert_eq!(comps.len(), 3, "without 3-D joining, as the planner said");
        let joined = scene_from_plan(&plan, Vector3::new(0.0, -1.0, 1.0), 1.0, 0.004);
        assert!(joined.scene.facets.iter().all(|f| f.component == joined.scene.facets[0].component));
    }

    /// The planner's side faces taken away, the box's top face still hangs two faces down to
    /// the table where they face the viewer: where the real ones are, and grasped as they
    /// would be.
    #[test]
    fn front_faces_hypothesised_below_a_top_face_stand_where_the_sides_are() {
        let b = BoxSpec { center_m: [0.0, 0.0, 0.0225], size_m: [0.040, 0.030, 0.045], yaw_rad: 0.5 };
        let synth = SynthScene::new(vec![b]);
        let pair = synth.render(3);
        let robot: Vec<Vector3<f64>> = pair.cage.iter().map(|c| Vector3::from(c.0)).collect();
        let image: Vec<[f64; 4]> = pair.cage.iter().map(|c| c.1).collect();
        let model = AffineStereo::fit(&robot, &image).unwrap();
        let toward = model.toward_cameras();
        let geo = EpipolarGeometry::from_model(model.clone(), 0.5, 10.0);
        let plan = Planner::new(PlannerConfig::default()).plan(&pair.left.view(), &pair.right.view(), &geo);
        let full = scene_from_plan(&plan, toward, 1.0, 0.004);
        let mut ps = full.clone();
        let keep: Vec<usize> = (0..ps.scene.facets.len()).filter(|&i| unit_normal(&ps.scene.facets[i].polygon_m).unwrap().z.abs() > 0.9).collect();
        assert_eq!(keep.len(), 1, "one top face");
        ps.scene.facets = keep.iter().map(|&i| full.scene.facets[i].clone()).collect();
        ps.facets = keep.iter().map(|&i| full.facets[i].clone()).collect();
        let cams = &pair.cameras;
        let project = |p: &Vector3<f64>| Some([cams[0].project([p.x, p.y, p.z]), cams[1].project([p.x, p.y, p.z])]);
        let n = hypothesise_front_faces(&mut ps, &project, 0.0, 0.01, 20f64.to_radians(), 80f64.to_radians(), 0.004);
        assert_eq!(n, 2, "two sides face the viewer");
        // Each hypothesised face lies in the plane of a true side face, within a few mm.
        let truth: Vec<([f64; 3], [[f64; 3]; 4])> = b.faces();
        for f in ps.scene.facets.iter().skip(1) {
            let best = truth
                .iter()
                .filter(|(n, _)| n[2].abs() < 0.1)
                .map(|(n, c)| f.polygon_m.iter().map(|p| (p - Vector3::from(c[0])).dot(&Vector3::from(*n)).abs()).fold(0.0, f64::max))
                .fold(f64::INFINITY, f64::min);
            assert!(best < 0.004, "hypothesised face {:.1} mm off the nearest side", best * 1e3);
        }
        // And the grasp planner finds the same grasps as on the planner's own side faces.
        let grasps = plan_grasps(&ps.scene, None, &GraspConfig::default()).unwrap();
        assert_eq!(grasps.candidates.len(), 2, "{:?}", grasps.rejected);
        assert!(ps.facets.iter().skip(1).all(|s| s.hypothesised && s.left_px.len() == 4));
        // Where the planner did find the sides, nothing is hypothesised.
        let mut again = full.clone();
        assert_eq!(hypothesise_front_faces(&mut again, &project, 0.0, 0.01, 20f64.to_radians(), 80f64.to_radians(), 0.004), 0);
    }

    /// Seed 120 of clutter3: an L-block with its low leg towards the cameras (+x). The planner
    /// found the two tops, 7 mm apart in plan view and as two objects (the step between them
    /// unmatched). The tall top's front face goes down to the low top, not to the table (where
    /// the low leg stands in front of it), and says which top it steps onto; the low top's
    /// front face goes down to the table.
    #[test]
    fn a_top_face_over_a_lower_one_in_front_hangs_its_face_down_to_the_step() {
        let p = |x: f64, y: f64, z: f64| Vector3::new(x, y, z);
        let top = |x0: f64, x1: f64, z: f64| vec![p(x0, 0.0, z), p(x1, 0.0, z), p(x1, 0.03, z), p(x0, 0.03, z)];
        let facet = |polygon_m: Vec<Vector3<f64>>, component: usize| {
            let n = polygon_m.len();
            let edges = (0..n).map(|i| Segment3::new(polygon_m[i], polygon_m[(i + 1) % n])).collect();
            SceneFacet { polygon_m, edges, component }
        };
        let source = |plan_facet: usize| FacetSource { plan_facet, hypothesised: false, left_px: vec![[0.0; 2]; 4], right_px: vec![[0.0; 2]; 4], steps_onto: None };
        // Tall top x 0..25 mm at 40 mm (its front edge 5 mm past the true step at 20 mm, as
        // reconstructed), low top x 18..40 mm at 20 mm.
        let mut ps = PlannedScene {
            scene: GraspScene { facets: vec![facet(top(0.0, 0.025, 0.04), 0), facet(top(0.018, 0.04, 0.02), 1)], edges: Vec::new(), toward_viewer: p(1.0, 0.0, 0.8) },
            facets: vec![source(0), source(1)],
            edge_matches: Vec::new(),
            dropped_facets: Vec::new(),
        };
        let project = |q: &Vector3<f64>| Some([[1000.0 * q.y, -1000.0 * q.z], [1000.0 * q.y + 5.0, -1000.0 * q.z]]);
        let n = hypothesise_front_faces(&mut ps, &project, 0.0, 0.01, 20f64.to_radians(), 80f64.to_radians(), 0.006);
        assert_eq!(n, 2, "one face under each top's +x side");
        let hung: Vec<(&SceneFacet, &FacetSource)> = ps.scene.facets.iter().zip(&ps.facets).filter(|(_, s)| s.hypothesised).collect();
        let bottom = |f: &SceneFacet| f.polygon_m.iter().map(|q| q.z).fold(f64::INFINITY, f64::min);
        let (riser, riser_src) = hung.iter().find(|(f, _)| f.component == 0).expect("the tall top's face");
        assert!((bottom(riser) - 0.02).abs() < 1e-12, "down to the low top, not the table: {:?}", riser.polygon_m);
        assert_eq!(riser_src.steps_onto, Some(1));
        let (front, front_src) = hung.iter().find(|(f, _)| f.component == 1).expect("the low top's face");
        assert!(bottom(front).abs() < 1e-12);
        assert_eq!(front_src.steps_onto, None);
        // Two tops farther apart than a face within 20° of vertical leans over the 20 mm step
        // (7.3 mm) plus the join distance are not a step: the face goes to the table.
        let mut apart = ps.clone();
        apart.scene.facets.truncate(2);
        apart.facets.truncate(2);
        apart.scene.facets[1] = facet(top(0.04, 0.06, 0.02), 1);
        hypothesise_front_faces(&mut apart, &project, 0.0, 0.01, 20f64.to_radians(), 80f64.to_radians(), 0.006);
        let tall = apart.scene.facets.iter().zip(&apart.facets).find(|(f, s)| s.hypothesised && f.component == 0).unwrap();
        assert_eq!((bottom(tall.0), tall.1.steps_onto), (0.0, None));
    }

    #[test]
    fn features_above_the_height_limit_are_left_out() {
        let b = BoxSpec { center_m: [0.0, 0.0, 0.0225], size_m: [0.040, 0.030, 0.045], yaw_rad: 0.5 };
        let (_, plan) = plan_scene(vec![b], 3);
        let low = scene_from_plan(&plan, Vector3::new(0.0, -1.0, 1.0), 0.030, 0.004);
        // The top face (z = 45 mm) goes; the sides reach down to the table and stay.
        assert_eq!(low.scene.facets.len(), 2, "{:?}", low.dropped_facets);
        assert_eq!(low.dropped_facets.len(), 1);
        assert!(low.scene.facets.iter().all(|f| f.polygon_m.iter().any(|p| p.z < 0.01)));
    }
}
