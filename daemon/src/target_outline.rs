//! The target facet's outline held to the plan while it is acquired.
//!
//! The planned facet's corners (thesis §6.3.4) start the target's trackers, and acquisition
//! refines them from the image's edges ([`crate::gripper::refine_polygon`]). Where two faces
//! of a block have one shade in a view, the crease between them is no edge there (a 2-3 grey
//! level step), and the nearest edge within the tracker's reach is the *neighbouring* face's
//! outer edge: the side slides onto it in the first updates, and the facet the two views then
//! give turns by tens of degrees (clutter3 seed 28: 28° from vertical, the servo refuses it).
//! Refining cannot tell, since that edge is the only one there is.
//!
//! The plan can: its corners come from edges matched in both views, so each planned side lies
//! within the planner's epipolar tolerance of its edge, and the tracker then finds that edge
//! within its inlier band. A refined side further than both from the planned one, while most
//! sides stay within them, is on some other edge: it is put back on the planned side's line,
//! and its tracker stops searching it, so the face is held by the sides the view does see.
//! When most sides moved, the face itself moved since the stereo pair (a nudged block): the
//! tracker followed it, and nothing is held. A held side is placed by the sides still
//! measured; where they do not hold the face (seed 108: a bottom side held, the crease along
//! the top weak), the outline drifts and the held side with it, off its line by more than the
//! same tolerance: it is then measured again ([`release_adrift`]).

use handeye_vision::tracker::ContourTracker;
use nalgebra::Vector2;

/// A refined outline checked against the planned one.
#[derive(Debug, Clone, PartialEq)]
pub struct HeldOutline {
    /// The corners to track: the refined ones, with every held side on its planned line.
    pub corners_px: Vec<[f64; 2]>,
    /// The sides (corner `j` to `j + 1`) put back on the plan.
    pub held_sides: Vec<usize>,
}

fn v(p: [f64; 2]) -> Vector2<f64> {
    Vector2::new(p[0], p[1])
}

/// Signed distance of `p` from the line through `a` and `b`, positive on the side away from
/// `inside` (a point inside the polygon).
fn outward_px(p: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>, inside: Vector2<f64>) -> f64 {
    let d = b - a;
    let n = d.norm();
    if n <= 0.0 {
        return 0.0;
    }
    let cross = |q: Vector2<f64>| (d.x * (q.y - a.y) - d.y * (q.x - a.x)) / n;
    let s = cross(p);
    if cross(inside) > 0.0 { -s } else { s }
}

/// Where the lines `p + s u` and `q + r w` meet (`None` when near parallel).
fn meet(p: Vector2<f64>, u: Vector2<f64>, q: Vector2<f64>, w: Vector2<f64>) -> Option<Vector2<f64>> {
    let det = u.x * (-w.y) - u.y * (-w.x);
    if det.abs() < 0.1 * u.norm() * w.norm() {
        return None;
    }
    let d = q - p;
    let s = (d.x * (-w.y) - d.y * (-w.x)) / det;
    Some(p + u * s)
}

/// The sides of `refined_px` (corner `j` to `j + 1`) with an end more than `max_shift_px`
/// *outside* the planned side's line (`planned_px`: the same corners, in order): a
/// neighbouring face's outer edge lies beyond the crease, so a side slides outwards (a
/// side found inside the plan is on an edge within the planned face). Empty when they
/// are half the sides or more: then the face moved since the stereo pair (a median shift
/// would not tell, since one side's slide moves half the corners), and the tracker followed
/// it. Empty also when the outlines differ in corner count.
pub fn sides_off_plan(refined_px: &[[f64; 2]], planned_px: &[[f64; 2]], max_shift_px: f64) -> Vec<usize> {
    let k = planned_px.len();
    if refined_px.len() != k || k < 3 {
        return Vec::new();
    }
    let planned = |j: usize| v(planned_px[j % k]);
    let refined = |j: usize| v(refined_px[j % k]);
    let inside = (0..k).map(planned).sum::<Vector2<f64>>() / k as f64;
    let off: Vec<usize> = (0..k)
        .filter(|&j| {
            let (a, b) = (planned(j), planned(j + 1));
            outward_px(refined(j), a, b, inside).max(outward_px(refined(j + 1), a, b, inside)) > max_shift_px
        })
        .collect();
    if 2 * off.len() >= k { Vec::new() } else { off }
}

/// Of each view's sides off the plan ([`sides_off_plan`]), those to hold: a side off in
/// one view only. A side off in both views is where the two views' edges agree with each
/// other against the plan (the plan's outline was off there); a side that slid onto a
/// same-shade neighbour's edge did so in the view that sees the two faces alike.
pub fn sides_to_hold(off: [&[usize]; 2]) -> [Vec<usize>; 2] {
    let only = |a: &[usize], b: &[usize]| a.iter().copied().filter(|j| !b.contains(j)).collect();
    [only(off[0], off[1]), only(off[1], off[0])]
}

/// `refined_px` with each side of `held_sides` put back on its planned line (corners where
/// the neighbouring sides' lines meet it). `None` when the outlines differ in corner count
/// or a held side is parallel to a neighbour.
pub fn hold_to_plan(refined_px: &[[f64; 2]], planned_px: &[[f64; 2]], held_sides: &[usize]) -> Option<HeldOutline> {
    let k = planned_px.len();
    if refined_px.len() != k || k < 3 {
        return None;
    }
    let planned = |j: usize| v(planned_px[j % k]);
    let refined = |j: usize| v(refined_px[j % k]);
    // Each side's line as (point, direction): the planned one where held.
    let line = |j: usize| {
        let j = j % k;
        if held_sides.contains(&j) { (planned(j), planned(j + 1) - planned(j)) } else { (refined(j), refined(j + 1) - refined(j)) }
    };
    let mut corners_px = Vec::with_capacity(k);
    for (j, &corner) in refined_px.iter().enumerate() {
        let before = (j + k - 1) % k;
        if !held_sides.contains(&before) && !held_sides.contains(&j) {
            corners_px.push(corner);
            continue;
        }
        let ((p, u), (q, w)) = (line(before), line(j));
        let c = meet(p, u, q, w)?;
        corners_px.push([c.x, c.y]);
    }
    Some(HeldOutline { corners_px, held_sides: held_sides.to_vec() })
}

/// The sides of `t` it no longer measures (held to the plan, [`restart_held`]) whose ends now
/// lie more than `max_shift_px` from their planned line (`planned_px`, in either direction).
/// A held side is placed by the sides the tracker still measures; where those hold the face
/// (clutter3 seed 28: the square's three other sides on strong edges) it stays on its line.
/// Where they do not (seed 108: a face's bottom side held, the sides left to place it
/// vertically the short ones and the weak crease along its top), the outline drifts off the
/// face, and the held side with it, past the tolerance the hold was granted on (the planner's
/// epipolar tolerance plus the tracker's inlier band): the plan's line no longer holds
/// anything there, and the side must be measured again.
pub fn held_sides_adrift(t: &ContourTracker, planned_px: &[[f64; 2]], max_shift_px: f64) -> Vec<usize> {
    let k = planned_px.len();
    let corners: Vec<Vector2<f64>> = t.corners().collect();
    if corners.len() != k || k < 3 {
        return Vec::new();
    }
    let planned = |j: usize| v(planned_px[j % k]);
    (0..k)
        .filter(|&j| !t.side_measured(j))
        .filter(|&j| {
            let (a, b) = (planned(j), planned(j + 1));
            let d = b - a;
            let n = d.norm();
            let off = |p: Vector2<f64>| if n > 0.0 { (d.x * (p.y - a.y) - d.y * (p.x - a.x)).abs() / n } else { (p - a).norm() };
            off(corners[j]).max(off(corners[(j + 1) % k])) > max_shift_px
        })
        .collect()
}

/// Measures again every held side of `t` that drifted off its planned line
/// ([`held_sides_adrift`]). Returns the sides released.
pub fn release_adrift(t: &mut ContourTracker, planned_px: &[[f64; 2]], max_shift_px: f64) -> Vec<usize> {
    let adrift = held_sides_adrift(t, planned_px, max_shift_px);
    for &j in &adrift {
        t.set_side_measured(j, true);
    }
    adrift
}

/// A target tracker's corners refined from its edges ([`crate::gripper::refine_polygon`]),
/// or its current corners (and `false`) when that finds no outline.
pub fn refined_outline(t: &ContourTracker) -> (Vec<[f64; 2]>, bool) {
    match crate::gripper::refine_polygon(t) {
        Some(c) => (c, true),
        None => (t.corners().map(|c| [c.x, c.y]).collect(), false),
    }
}

/// Restarts the tracker on `refined_px` with `held_sides` back on the plan
/// ([`hold_to_plan`]) and no longer searched; with nothing held and nothing refined it is
/// left as it is. Returns the sides held (empty also when the held outline cannot be made
/// or the tracker restarted on it: it then keeps its track).
pub fn restart_held(t: &mut ContourTracker, refined_px: &[[f64; 2]], was_refined: bool, planned_px: &[[f64; 2]], held_sides: &[usize]) -> Vec<usize> {
    if held_sides.is_empty() && !was_refined {
        return Vec::new();
    }
    let Some(held) = hold_to_plan(refined_px, planned_px, held_sides) else {
        return Vec::new();
    };
    if t.reinit(&held.corners_px).is_err() {
        return Vec::new();
    }
    for &j in &held.held_sides {
        t.set_side_measured(j, false);
    }
    held.held_sides
}

/// Both views' target trackers refined and held to the plan: [`refined_outline`],
/// [`sides_off_plan`] within `max_shift_px`, [`sides_to_hold`], [`restart_held`]. Returns
/// the sides held per view.
pub fn refine_held_to_plan(trackers: [&mut ContourTracker; 2], planned_px: [&[[f64; 2]]; 2], max_shift_px: f64) -> [Vec<usize>; 2] {
    let [left, right] = trackers;
    let (l, r) = (refined_outline(left), refined_outline(right));
    let off = [sides_off_plan(&l.0, planned_px[0], max_shift_px), sides_off_plan(&r.0, planned_px[1], max_shift_px)];
    let [hold_l, hold_r] = sides_to_hold([&off[0], &off[1]]);
    [restart_held(left, &l.0, l.1, planned_px[0], &hold_l), restart_held(right, &r.0, r.1, planned_px[1], &hold_r)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::image::ImageBuf;

    /// Seed 28's left view, schematically: a cube's front face (grey 137, x 100..140, y
    /// 100..140) beside its left face (grey 135: the crease a 2-level step, no edge), both
    /// on a dark table (23), and the top face above (240). The left face is a sliver seen
    /// obliquely: its outer edge (135 against 23) runs from 9 px outside the front face's
    /// left side at the top to 1 px at the bottom.
    fn same_shade_faces() -> ImageBuf {
        let mut img = ImageBuf::filled(240, 200, 23);
        for y in 100..140 {
            for x in 91 + (y - 100) / 5..100 {
                img.set(x, y, 135);
            }
            for x in 100..140 {
                img.set(x, y, 137);
            }
        }
        for y in 80..100 {
            for x in 90..140 {
                img.set(x, y, 240);
            }
        }
        img
    }

    /// The right view of the same cube: the front face meets the top face and the table
    /// only (the left face is out of sight): every side has its edge.
    fn front_face_alone() -> ImageBuf {
        let mut img = ImageBuf::filled(240, 200, 23);
        for y in 100..140 {
            for x in 100..140 {
                img.set(x, y, 137);
            }
        }
        for y in 80..100 {
            for x in 100..150 {
                img.set(x, y, 240);
            }
        }
        img
    }

    const FRONT: [[f64; 2]; 4] = [[99.5, 139.5], [139.5, 139.5], [139.5, 99.5], [99.5, 99.5]];

    fn track(t: &mut ContourTracker, img: &ImageBuf, frames: usize) {
        for _ in 0..frames {
            assert!(t.update(&img.view(), 1.0 / 30.0).is_tracking());
        }
    }

    fn worst_corner_px(t: &ContourTracker, want: &[[f64; 2]]) -> f64 {
        t.corners().zip(want).map(|(c, w)| (c - v(*w)).norm()).fold(0.0, f64::max)
    }

    /// The tracker alone, started on the planned front face, slides its left side onto the
    /// left face's outer edge (the failure); refined and held to the plan at acquisition's
    /// refinements, the front face stays where the plan put it and its left side is no
    /// longer searched; the right view, where the side has its edge, holds nothing.
    #[test]
    fn a_side_on_a_crease_with_no_edge_is_held_to_the_plan() {
        let (left_img, right_img) = (same_shade_faces(), front_face_alone());
        let config = crate::config::TrackerSettings::default().target_tracker_config();
        let mut free = ContourTracker::new(config, &FRONT).unwrap();
        track(&mut free, &left_img, 15);
        assert!(worst_corner_px(&free, &FRONT) > 5.0, "the unheld tracker should slide; it is {} px off", worst_corner_px(&free, &FRONT));

        // What acquire_target does: refine and hold at frames 5 and 10 of 15.
        let max_shift_px = 3.0 + config.inlier_px;
        let (mut left, mut right) = (ContourTracker::new(config, &FRONT).unwrap(), ContourTracker::new(config, &FRONT).unwrap());
        let step = |l: &mut ContourTracker, r: &mut ContourTracker| {
            track(l, &left_img, 5);
            track(r, &right_img, 5);
        };
        step(&mut left, &mut right);
        let held = refine_held_to_plan([&mut left, &mut right], [&FRONT, &FRONT], max_shift_px);
        assert_eq!(held, [vec![3], Vec::<usize>::new()], "the left view's left side (corner 3 to 0) is held");
        step(&mut left, &mut right);
        let held = refine_held_to_plan([&mut left, &mut right], [&FRONT, &FRONT], max_shift_px);
        assert!(held.iter().all(Vec::is_empty), "once held, the side stays on the plan");
        assert!(!left.side_measured(3) && left.side_measured(0) && right.side_measured(3));
        step(&mut left, &mut right);
        assert!(release_adrift(&mut left, &FRONT, max_shift_px).is_empty(), "the held side stays on its line: the hold stands");
        for t in [&left, &right] {
            assert!(worst_corner_px(t, &FRONT) < 1.0, "the face is {} px off", worst_corner_px(t, &FRONT));
            assert!(t.confidence().score > 0.8, "confidence over the sides it measures: {}", t.confidence().score);
        }
    }

    /// A held side is placed by the sides still measured; one that went with the outline more
    /// than the tolerance off its planned line (clutter3 seed 108: the bottom side held, the
    /// outline drifted 7 px up within a frame) is measured again; a held side on its line, and
    /// a measured side off it, are not touched.
    #[test]
    fn a_held_side_adrift_from_the_plan_is_measured_again() {
        let config = crate::config::TrackerSettings::default().target_tracker_config();
        let max_shift_px = 3.0 + config.inlier_px;
        let mut t = ContourTracker::new(config, &FRONT).unwrap();
        t.set_side_measured(0, false);
        assert!(held_sides_adrift(&t, &FRONT, max_shift_px).is_empty());
        // The whole outline 7 px up: the held bottom side (corner 0 to 1) with it, and the
        // measured sides too (those are the tracker's to follow, not the hold's).
        let drifted: Vec<[f64; 2]> = FRONT.iter().map(|c| [c[0], c[1] - 7.0]).collect();
        t.reinit(&drifted).unwrap();
        assert!(!t.side_measured(0), "reinit keeps the held side unmeasured");
        assert_eq!(held_sides_adrift(&t, &FRONT, max_shift_px), vec![0]);
        assert_eq!(release_adrift(&mut t, &FRONT, max_shift_px), vec![0]);
        assert!((0..4).all(|j| t.side_measured(j)), "the drifted side is measured again");
        assert!(release_adrift(&mut t, &FRONT, max_shift_px).is_empty(), "released once");
        // Within the tolerance (4 px at one end) the hold stands.
        let tilted = [[99.5, 135.5], [139.5, 139.5], [139.5, 99.5], [99.5, 99.5]];
        let mut t = ContourTracker::new(config, &tilted).unwrap();
        t.set_side_measured(0, false);
        assert!(release_adrift(&mut t, &FRONT, max_shift_px).is_empty());
        assert!(!t.side_measured(0));
    }

    /// A block moved since the plan moves every side: that is not a slide; a plan a couple of
    /// pixels off is refined, not held; a side 9 px out at one end is off, 9 px in is not.
    #[test]
    fn sides_off_the_plan_are_a_minority_beyond_the_tolerance() {
        let moved: Vec<[f64; 2]> = FRONT.iter().map(|c| [c[0] + 9.0, c[1] - 7.0]).collect();
        assert!(sides_off_plan(&moved, &FRONT, 5.0).is_empty());
        let refined = [[98.0, 141.0], [140.5, 139.0], [139.0, 100.5], [101.0, 98.0]];
        assert!(sides_off_plan(&refined, &FRONT, 5.0).is_empty());
        let slid = [[99.5, 139.5], [139.5, 139.5], [139.5, 99.5], [90.5, 99.5]];
        assert_eq!(sides_off_plan(&slid, &FRONT, 5.0), vec![3]);
        let inwards = [[99.5, 139.5], [139.5, 139.5], [139.5, 99.5], [108.5, 99.5]];
        assert!(sides_off_plan(&inwards, &FRONT, 5.0).is_empty());
        assert!(sides_off_plan(&slid[..3], &FRONT, 5.0).is_empty());
    }

    /// A side off in one view is held there; off in both (clutter3 seed 105: both views'
    /// edges agree, the plan's side was off), it is held in neither.
    #[test]
    fn a_side_off_in_both_views_is_the_plans_error() {
        assert_eq!(sides_to_hold([&[3], &[]]), [vec![3], Vec::<usize>::new()]);
        assert_eq!(sides_to_hold([&[1], &[0, 1]]), [Vec::<usize>::new(), vec![0]]);
    }

    /// A held side goes back on its planned line; its corners move along the neighbouring
    /// sides' refined lines.
    #[test]
    fn a_slid_side_goes_back_on_its_planned_line() {
        // The left side (corner 3 to 0) slid out at its top: corner 3 at x 90.5 instead of 99.5.
        let refined = [[99.5, 139.5], [139.5, 139.5], [139.5, 99.5], [90.5, 99.5]];
        let h = hold_to_plan(&refined, &FRONT, &[3]).unwrap();
        assert_eq!(h.held_sides, vec![3]);
        for (got, want) in h.corners_px.iter().zip(FRONT) {
            assert!((v(*got) - v(want)).norm() < 1e-9, "{:?}", h.corners_px);
        }
        assert_eq!(hold_to_plan(&refined, &FRONT, &[]).unwrap().corners_px, refined);
        assert!(hold_to_plan(&refined[..3], &FRONT, &[3]).is_none());
    }
}
