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
//! tracker followed it, and nothing is held.

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

/// Distance of `p` from the line through `a` and `b`.
fn off_line_px(p: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>) -> f64 {
    let d = b - a;
    let n = d.norm();
    if n <= 0.0 {
        return (p - a).norm();
    }
    (d.x * (p.y - a.y) - d.y * (p.x - a.x)).abs() / n
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

/// Checks `refined_px` against `planned_px` (the same corners, in order): each side with an
/// end more than `max_shift_px` from the planned side's line is put back on that line, if
/// they are fewer than half the sides (else the face moved, and nothing is held; a median
/// shift would not tell, since one side's slide moves half the corners). `None` when the
/// two outlines differ in corner count or a held side's corners cannot be placed (a held
/// side parallel to a neighbour).
pub fn hold_to_plan(refined_px: &[[f64; 2]], planned_px: &[[f64; 2]], max_shift_px: f64) -> Option<HeldOutline> {
    let k = planned_px.len();
    if refined_px.len() != k || k < 3 {
        return None;
    }
    let planned = |j: usize| v(planned_px[j % k]);
    let refined = |j: usize| v(refined_px[j % k]);
    let mut held_sides: Vec<usize> = (0..k)
        .filter(|&j| {
            let (a, b) = (planned(j), planned(j + 1));
            off_line_px(refined(j), a, b).max(off_line_px(refined(j + 1), a, b)) > max_shift_px
        })
        .collect();
    if 2 * held_sides.len() >= k {
        held_sides.clear();
    }
    // Each side's line as (point, direction): the planned one where held.
    let line = |j: usize| {
        let j = j % k;
        if held_sides.contains(&j) { (planned(j), planned(j + 1) - planned(j)) } else { (refined(j), refined(j + 1) - refined(j)) }
    };
    let mut corners_px = Vec::with_capacity(k);
    for j in 0..k {
        let before = (j + k - 1) % k;
        if !held_sides.contains(&before) && !held_sides.contains(&j) {
            corners_px.push(refined_px[j]);
            continue;
        }
        let ((p, u), (q, w)) = (line(before), line(j));
        let c = meet(p, u, q, w)?;
        corners_px.push([c.x, c.y]);
    }
    Some(HeldOutline { corners_px, held_sides })
}

/// Refines a target tracker's corners ([`crate::gripper::refine_polygon`], or its current
/// corners when that finds no outline), holds them to the plan ([`hold_to_plan`]), and
/// restarts the tracker on the result with every held side no longer searched (with none
/// held and no refined outline, the tracker is left as it is). Returns the sides held (empty
/// when every side stayed within `max_shift_px` of its plan, or when the tracker could not
/// be restarted on the held outline; it then keeps its track).
pub fn refine_held_to_plan(t: &mut ContourTracker, planned_px: &[[f64; 2]], max_shift_px: f64) -> Vec<usize> {
    let refined = crate::gripper::refine_polygon(t);
    let was_refined = refined.is_some();
    let refined = refined.unwrap_or_else(|| t.corners().map(|c| [c.x, c.y]).collect());
    let Some(held) = hold_to_plan(&refined, planned_px, max_shift_px) else {
        return Vec::new();
    };
    if (held.held_sides.is_empty() && !was_refined) || t.reinit(&held.corners_px).is_err() {
        return Vec::new();
    }
    for &j in &held.held_sides {
        t.set_side_measured(j, false);
    }
    held.held_sides
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
    /// longer searched.
    #[test]
    fn a_side_on_a_crease_with_no_edge_is_held_to_the_plan() {
        let img = same_shade_faces();
        let config = crate::config::TrackerSettings::default().target_tracker_config();
        let mut free = ContourTracker::new(config, &FRONT).unwrap();
        track(&mut free, &img, 15);
        assert!(worst_corner_px(&free, &FRONT) > 5.0, "the unheld tracker should slide; it is {} px off", worst_corner_px(&free, &FRONT));

        // What acquire_target does: refine and hold at frames 5 and 10 of 15.
        let max_shift_px = 3.0 + config.inlier_px;
        let mut held = ContourTracker::new(config, &FRONT).unwrap();
        track(&mut held, &img, 5);
        assert_eq!(refine_held_to_plan(&mut held, &FRONT, max_shift_px), vec![3], "the left side (corner 3 to 0) is held");
        track(&mut held, &img, 5);
        assert!(refine_held_to_plan(&mut held, &FRONT, max_shift_px).is_empty(), "once held, the side stays on the plan");
        assert!(!held.side_measured(3) && held.side_measured(0));
        track(&mut held, &img, 5);
        assert!(worst_corner_px(&held, &FRONT) < 1.0, "the held face is {} px off", worst_corner_px(&held, &FRONT));
        assert!(held.confidence().score > 0.8, "confidence over the sides it measures: {}", held.confidence().score);
    }

    /// A block moved since the plan moves every side: that is not a slide, and nothing is
    /// held; a plan a couple of pixels off is refined, not held.
    #[test]
    fn a_common_shift_or_small_plan_errors_hold_nothing() {
        let moved: Vec<[f64; 2]> = FRONT.iter().map(|c| [c[0] + 9.0, c[1] - 7.0]).collect();
        let h = hold_to_plan(&moved, &FRONT, 5.0).unwrap();
        assert!(h.held_sides.is_empty() && h.corners_px == moved, "{h:?}");
        let refined = [[98.0, 141.0], [140.5, 139.0], [139.0, 100.5], [101.0, 98.0]];
        let h = hold_to_plan(&refined, &FRONT, 5.0).unwrap();
        assert!(h.held_sides.is_empty(), "{h:?}");
    }

    /// A side 9 px off at one end is put back on its planned line; its corners move along the
    /// neighbouring sides' refined lines.
    #[test]
    fn a_slid_side_goes_back_on_its_planned_line() {
        // The left side (corner 3 to 0) slid out at its top: corner 3 at x 90.5 instead of 99.5.
        let refined = [[99.5, 139.5], [139.5, 139.5], [139.5, 99.5], [90.5, 99.5]];
        let h = hold_to_plan(&refined, &FRONT, 5.0).unwrap();
        assert_eq!(h.held_sides, vec![3]);
        for (got, want) in h.corners_px.iter().zip(FRONT) {
            assert!((v(*got) - v(want)).norm() < 1e-9, "{:?}", h.corners_px);
        }
        assert!(hold_to_plan(&refined[..3], &FRONT, 5.0).is_none());
    }
}
