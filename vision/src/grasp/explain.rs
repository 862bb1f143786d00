//! Why a block has no grasp, in words a user understands ("its top edges slope 34°"), from
//! the planner's rejections. One function for the simulator's judge (on true geometry) and
//! the daemon's refusal (on its own reconstruction), so that the two say the same thing the
//! same way.

use super::{EdgeRef, FeatureRef, GraspConfig, GraspScene, RejectReason, Rejection};

/// How far a rejection got through the rules: of a facet's rejections the furthest says best
/// why it failed. A collision of the zero-width pairing (the thesis's thin wall: a top edge
/// with itself) says only that the block is no thin wall, so it counts for little.
fn progress(r: &Rejection) -> u8 {
    let thin_wall = r.site.is_some_and(|s| s.width_m.abs() < 1e-3);
    match &r.reason {
        RejectReason::FingerCollision { .. } | RejectReason::BodyCollision { .. } if thin_wall => 1,
        RejectReason::FacetNotVertical { .. } => 0,
        RejectReason::TurnedFromViewer { .. } | RejectReason::NoTopEdge | RejectReason::TopEdgeSlopeUnsettled { .. } | RejectReason::ThicknessUnmeasured => 1,
        RejectReason::TopEdgeTooSteep { .. } => 2,
        RejectReason::NoOverlap | RejectReason::RearInFront { .. } => 3,
        RejectReason::RearOutOfReach { .. } => 4,
        RejectReason::TooWide { .. } => 5,
        RejectReason::FingerCollision { .. } => 6,
        RejectReason::BodyCollision { .. } | RejectReason::NotHighest => 7,
    }
}

/// The number a reason turns on, for choosing the nearest miss among equally far ones.
fn magnitude(r: &RejectReason) -> f64 {
    match r {
        RejectReason::TopEdgeTooSteep { slope_rad } => *slope_rad,
        RejectReason::RearOutOfReach { drop_m } => drop_m.abs(),
        RejectReason::TooWide { width_m } => *width_m,
        _ => 0.0,
    }
}

/// Whether the rejections of the facets that `facet_name` names ground a refusal. Each
/// facet is judged by its furthest rejection (the one [`why_no_grasp`] states): a facet that
/// got past a rule with one edge pairing is not refused by that rule on another. A refusal
/// needs some facet whose furthest rule is one the judge on true geometry also applies, on
/// geometry a single view gets right: a steep top edge, no parallel edge behind within
/// reach, too wide, a collision with a *facet* of another object. Not grounded: the stages
/// that say only what the cameras saw (no vertical face, no top edge, a face turned from the
/// cameras, the thin-wall pairing of a top edge with itself); collisions with the block's
/// own other faces: those are the faces one stereo pair reconstructs worst (seen obliquely
/// or barely, a top face skewed by 20°, a false match spanning two levels of an L-block), so
/// a finger "hitting" one says more about the reconstruction than the block; and collisions
/// with a loose edge (one matched segment pair on no plane: a false match as often as a
/// surface in the way).
/// A block seen only from its top, or only by faces the daemon's view-angle rule leaves
/// out, has not been judged, so it is no refusal.
pub fn refusal_grounded(scene: &GraspScene, rejected: &[Rejection], facet_name: impl Fn(usize) -> Option<String>) -> bool {
    furthest_per_facet(rejected, &facet_name).into_iter().any(|(facet, r)| {
        let weak_collision = match r.reason {
            RejectReason::FingerCollision { feature } | RejectReason::BodyCollision { feature } => {
                matches!(feature, FeatureRef::Edge(EdgeRef::Loose(_))) || scene.component_of(feature) == scene.facets[facet].component
            }
            _ => false,
        };
        progress(r) >= 2 && !weak_collision
    })
}

/// Per facet that `facet_name` names, its furthest rejection (the nearest miss among
/// equally far ones), in the order the facets first appear.
fn furthest_per_facet<'a>(rejected: &'a [Rejection], facet_name: &impl Fn(usize) -> Option<String>) -> Vec<(usize, &'a Rejection)> {
    let mut per_facet: Vec<(usize, &Rejection)> = Vec::new();
    for r in rejected {
        if facet_name(r.facet).is_none() {
            continue;
        }
        match per_facet.iter_mut().find(|(f, _)| *f == r.facet) {
            None => per_facet.push((r.facet, r)),
            Some((_, old)) => {
                let (a, b) = (progress(r), progress(old));
                if a > b || (a == b && magnitude(&r.reason) < magnitude(&old.reason)) {
                    *old = r;
                }
            }
        }
    }
    per_facet
}

/// Why no grasp was found on the facets that `facet_name` names (`None`: a facet of another
/// block, left out): per facet the furthest rule it failed (the nearest miss among equals),
/// each phrase said once, steep top edges first as "its top edges slope N°" (the least
/// slope: the one that came nearest). E.g. "its top edges slope 34°; behind its +x face the
/// nearest parallel edge is 27 mm lower, past the fingers' 25 mm".
pub fn why_no_grasp(rejected: &[Rejection], facet_name: impl Fn(usize) -> Option<String>, config: &GraspConfig) -> String {
    let per_facet = furthest_per_facet(rejected, &facet_name);
    let mut phrases: Vec<String> = Vec::new();
    let mut least_steep: Option<f64> = None;
    for (facet, r) in per_facet {
        let name = facet_name(facet).unwrap_or_default();
        let phrase = match &r.reason {
            RejectReason::FacetNotVertical { .. } => continue,
            RejectReason::TopEdgeTooSteep { slope_rad } => {
                let d = slope_rad.to_degrees();
                least_steep = Some(least_steep.map_or(d, |s: f64| s.min(d)));
                continue;
            }
            RejectReason::NoTopEdge => format!("its {name} has no top edge"),
            RejectReason::TopEdgeSlopeUnsettled { slope_rad, error_rad } => format!(
                "the top edge of its {name} slopes {:.0}° ± {:.0}°, too near the {:.0}° limit to tell",
                slope_rad.to_degrees(),
                error_rad.to_degrees(),
                config.max_edge_slope_rad.to_degrees()
            ),
            RejectReason::TurnedFromViewer { angle_rad } => format!("its {name} turns {:.0}° from the cameras", angle_rad.to_degrees()),
            RejectReason::NoOverlap | RejectReason::RearInFront { .. } => format!("its {name} has no parallel edge behind it"),
            RejectReason::RearOutOfReach { drop_m } => {
                format!("behind its {name} the nearest parallel edge is {:.0} mm lower, past the fingers' {:.0} mm", drop_m.abs() * 1e3, config.max_rear_drop_m * 1e3)
            }
            RejectReason::TooWide { width_m } => format!("across its {name} it is {:.0} mm wide, more than the jaws' {:.0} mm", width_m * 1e3, config.gripper.max_width_m * 1e3),
            RejectReason::FingerCollision { .. } => format!("a finger at its {name} would hit something"),
            RejectReason::BodyCollision { .. } | RejectReason::NotHighest => format!("the gripper's body at its {name} would hit something"),
            RejectReason::ThicknessUnmeasured => format!("nothing seen behind its {name} says how thick it is"),
        };
        if !phrases.contains(&phrase) {
            phrases.push(phrase);
        }
    }
    if let Some(d) = least_steep {
        phrases.insert(0, format!("its top edges slope {d:.0}°, more than {:.0}°", config.max_edge_slope_rad.to_degrees()));
    }
    if phrases.is_empty() {
        return format!("none of its faces is within {:.0}° of vertical", config.max_facet_tilt_rad.to_degrees());
    }
    phrases.join("; ")
}

/// The slope from horizontal of a seen face that is the block's sloping top, when the rules
/// settle that it leaves no grasp: the face looks up (it is a top, not a side), it slopes
/// more than `max_edge_slope_rad` beyond its error (so the faces beside it have top edges as
/// steep: its own slope), it is more than `max_facet_tilt_rad` from vertical beyond its error
/// (no grasp on it), and it rises more than `max_rear_drop_m` beyond its error from its low
/// end to its high end (no pairing across it), and it is the block's top: no corner of the
/// block's other faces rises above its plane beyond the error. A wedge whose slope faces the
/// cameras is seen this way: the judge refuses it for its steep top edges. `None` when any of
/// these is within the error: what was seen does not settle it.
///
/// The last rule is what a face rebuilt at the wrong tilt fails: point_clutter3 seed 72's
/// L-block, whose front face's two vertical edges were each matched with the far edge of a
/// face seen edge-on in one view, came out 33° from vertical with the block's own high top
/// 15-21 mm above it.
pub fn sloping_top_rad(scene: &GraspScene, facet: usize, config: &GraspConfig) -> Option<f64> {
    let own = scene.facets.get(facet)?;
    let polygon = &own.polygon_m;
    let mut n = super::polygon_normal(polygon)?;
    if n.dot(&scene.toward_viewer) < 0.0 {
        n = -n;
    }
    if n[2] <= 0.0 {
        return None;
    }
    let slope_rad = n[2].min(1.0).acos();
    // The face's extent down its slope (horizontal run) and its rise.
    let dip = nalgebra::Vector2::new(n[0], n[1]);
    let dip = if dip.norm() > 1e-9 { dip.normalize() } else { return None };
    let along: Vec<f64> = polygon.iter().map(|p| p.xy().dot(&dip)).collect();
    let run_m = along.iter().cloned().fold(f64::MIN, f64::max) - along.iter().cloned().fold(f64::MAX, f64::min);
    let (z_lo, z_hi) = polygon.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| (lo.min(p.z), hi.max(p.z)));
    let error_rad = (super::ERROR_SIGMAS * std::f64::consts::SQRT_2 * config.point_sigma_m / run_m.max(1e-6)).atan();
    let rise_error_m = super::ERROR_SIGMAS * std::f64::consts::SQRT_2 * config.point_sigma_m;
    let steep = slope_rad - error_rad > config.max_edge_slope_rad;
    let not_vertical = std::f64::consts::FRAC_PI_2 - slope_rad - error_rad > config.max_facet_tilt_rad;
    let rises = z_hi - z_lo - rise_error_m > config.max_rear_drop_m;
    // Above the plane: along its upward normal from any of its corners.
    let on_plane = polygon[0];
    let rises_above = scene
        .facets
        .iter()
        .enumerate()
        .filter(|&(k, f)| k != facet && f.component == own.component)
        .flat_map(|(_, f)| f.polygon_m.iter())
        .any(|q| (q - on_plane).dot(&n) > rise_error_m);
    (steep && not_vertical && rises && !rises_above).then_some(slope_rad)
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector3;

    use super::*;
    use crate::grasp::{SceneEdge, SceneFacet, Segment3};

    fn rejection(facet: usize, reason: RejectReason) -> Rejection {
        Rejection { facet, front_edge: None, rear_edge: None, site: None, reason }
    }

    #[test]
    fn the_furthest_rule_per_facet_is_said_once_and_steep_edges_first() {
        let c = GraspConfig::default();
        let rejected = [
            rejection(0, RejectReason::TopEdgeTooSteep { slope_rad: 36f64.to_radians() }),
            rejection(1, RejectReason::TopEdgeTooSteep { slope_rad: 34f64.to_radians() }),
            rejection(2, RejectReason::TopEdgeTooSteep { slope_rad: 5f64.to_radians() }),
            rejection(2, RejectReason::RearOutOfReach { drop_m: 0.027 }),
            rejection(3, RejectReason::FacetNotVertical { tilt_rad: 1.0 }),
            rejection(4, RejectReason::TooWide { width_m: 0.07 }),
        ];
        let name = |f: usize| (f != 4).then(|| format!("face {f}"));
        assert_eq!(
            why_no_grasp(&rejected, name, &c),
            "its top edges slope 34°, more than 30°; behind its face 2 the nearest parallel edge is 27 mm lower, past the fingers' 25 mm"
        );
        assert_eq!(why_no_grasp(&rejected[3..4], |_| Some("x".into()), &c), "behind its x the nearest parallel edge is 27 mm lower, past the fingers' 25 mm");
        assert_eq!(why_no_grasp(&rejected[4..5], |_| Some("x".into()), &c), "none of its faces is within 20° of vertical");
    }

    /// Facets 0-4 one block (component 0), facet 5 and a loose edge another (component 1);
    /// only the components matter here.
    fn two_blocks() -> GraspScene {
        let square = |x: f64| vec![Vector3::new(x, 0.0, 0.0), Vector3::new(x, 0.03, 0.0), Vector3::new(x, 0.03, 0.03), Vector3::new(x, 0.0, 0.03)];
        let facets = (0..6).map(|k| SceneFacet { polygon_m: square(0.1 * k as f64), edges: Vec::new(), component: usize::from(k == 5) }).collect();
        let edges = vec![SceneEdge { segment: Segment3::new(Vector3::new(0.6, 0.0, 0.05), Vector3::new(0.6, 0.03, 0.05)), component: 1 }];
        GraspScene { facets, edges, toward_viewer: Vector3::new(1.0, 0.0, 1.0) }
    }

    #[test]
    fn only_rules_the_judge_applies_ground_a_refusal() {
        let scene = two_blocks();
        let all = |_: usize| Some("x".to_string());
        // Seen only from the top, or by a face turned past the daemon's view-angle rule, or
        // with no top edge: not judged.
        let unseen = [
            rejection(0, RejectReason::FacetNotVertical { tilt_rad: 1.5 }),
            rejection(1, RejectReason::TurnedFromViewer { angle_rad: 1.1 }),
            rejection(2, RejectReason::NoTopEdge),
        ];
        assert!(!refusal_grounded(&scene, &unseen, all));
        // A steep top edge, or a rear edge out of reach, is the block's own geometry.
        let mut judged = unseen.to_vec();
        judged.push(rejection(3, RejectReason::TopEdgeTooSteep { slope_rad: 0.7 }));
        assert!(refusal_grounded(&scene, &judged, all));
        assert!(refusal_grounded(&scene, &[rejection(0, RejectReason::RearOutOfReach { drop_m: 0.03 })], all));
        // ... but not on a facet of another block.
        assert!(!refusal_grounded(&scene, &judged, |f| (f != 3).then(|| "x".to_string())));
    }

    #[test]
    fn a_finger_on_the_blocks_own_faces_grounds_no_refusal() {
        let scene = two_blocks();
        let all = |_: usize| Some("x".to_string());
        let finger = |facet: usize, on: usize| rejection(facet, RejectReason::FingerCollision { feature: FeatureRef::Facet(on) });
        // Another block in the fingers' way is the world's geometry: a refusal.
        assert!(refusal_grounded(&scene, &[finger(0, 5)], all));
        // The block's own other face (as reconstructed from one pair) is not.
        assert!(!refusal_grounded(&scene, &[finger(0, 4)], all));
        let body = rejection(0, RejectReason::BodyCollision { feature: FeatureRef::Edge(EdgeRef::Facet { facet: 2, edge: 0 }) });
        assert!(!refusal_grounded(&scene, &[body], all));
        // A loose edge of another object (one matched segment pair, on no plane) is not
        // enough (clutter3 seed 120: the body "hit" such an edge above an L-block).
        let loose = rejection(0, RejectReason::BodyCollision { feature: FeatureRef::Edge(EdgeRef::Loose(0)) });
        assert!(!refusal_grounded(&scene, &[loose], all));
        // Seed 26 (--disturb): the L-block's side face has one top edge at the step, cut into a
        // 38° slope, and a flat one whose pairing got as far as a finger on a false facet of
        // the block. The facet is judged by its furthest rule: no refusal.
        let l_side = [rejection(0, RejectReason::TopEdgeTooSteep { slope_rad: 38f64.to_radians() }), finger(0, 4)];
        assert!(!refusal_grounded(&scene, &l_side, all));
    }
}
