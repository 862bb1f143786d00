//! Wrong-lock evidence (issue 18 item 5): a side of the contour that slid onto a texture
//! edge or a neighbouring face's edge while the fit still looks good. Inliers, residual and
//! support all stay normal on such a lock (the wrong edge is a good edge); what gives it away
//! is that the side's own points see, in the wide pass, a *rival*: another straight edge
//! parallel to the side, a few px further out or in, on which more of them found an edge than
//! on the side where the fit put it. A tracker on the face's true outline has no such rival
//! for long: the wide pass pulls a side onto the edge most of its points see within a few
//! updates. One that stays on the weaker edge while the stronger one stays in view is locked on
//! the wrong edge.

use super::contour::TemplateEdge;
use super::search::{PointEdges, MAX_CANDIDATES};

/// Bins of the rival histogram: offsets of ±47 px in 1 px steps (the search reaches ±40).
const RIVAL_BINS: usize = 95;

/// Turns of the rival lines tried, as the difference of their offsets from the fitted side at
/// the side's two ends, px. A side that slid onto another edge need not stay parallel to the
/// face's own: a side that turned onto a texture line, or a contour sheared as a whole by a
/// start on the wrong edge (the left face's far bottom corner 10-13 px up its silhouette on
/// the real sequence), leaves the face's edge beside it at an angle, 5-20 px out of parallel
/// over the side. Steps of 5 px keep any line within 2.5 px of one tried at the side's ends,
/// 1.25 px on average: inside the band a point's edge must fall in.
const TURNS_PX: [f64; 9] = [0.0, -5.0, 5.0, -10.0, 10.0, -15.0, 15.0, -20.0, 20.0];

/// Least displacement of the template's shape towards a rival, px, for the rival to count
/// (see [`strongest_rival`]'s `template_px`): above the sub-px wobble of a steady fit's
/// deformation, below the quarter of a 6 px slide that the shape shows (a quadrilateral's side
/// slid `s` px out stretches the contour, whose nearest similarity puts that side `s / 4` px
/// back towards where it was).
const MIN_TEMPLATE_PULL_PX: f64 = 1.0;

/// The same as a fraction of the rival's mean distance from its side (a far rival needs the
/// shape to show more of the slide).
const MIN_TEMPLATE_PULL_FRACTION: f64 = 0.15;

/// Whether a rival line (offsets `r0`, `r1` from the fitted side at its first and last point)
/// lies where the template's shape pulls the side (`d`: the same offsets of the side of the
/// template's shape under the contour's nearest similarity): their displacement along the
/// rival's, averaged with the rival's offsets as weights, is at least
/// [`MIN_TEMPLATE_PULL_PX`] and [`MIN_TEMPLATE_PULL_FRACTION`] of the rival's mean offset.
#[inline]
fn template_pulls_towards(r0: f64, r1: f64, d: [f64; 2]) -> bool {
    let weight = r0.abs() + r1.abs();
    let pull = (r0 * d[0] + r1 * d[1]) / weight.max(1e-9);
    pull >= MIN_TEMPLATE_PULL_PX.max(MIN_TEMPLATE_PULL_FRACTION * 0.5 * weight)
}

/// The side with the strongest rival edge after a wide pass.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Rival {
    /// Side index (corner `side` to `side + 1`).
    pub side: usize,
    /// Points of the side with an edge within the band of the fitted side.
    pub support: usize,
    /// Points of the side with an edge within the band of the rival line.
    pub rival: usize,
    /// The rival line's offset from the fitted side along the outward normal at the side's
    /// middle, px.
    pub offset_px: f64,
    /// How much further out the rival line lies at the side's end than at its start, px (0:
    /// parallel).
    pub turn_px: f64,
    /// Points on the side.
    pub count: usize,
}

impl Rival {
    /// Whether this rival is evidence of a wrong lock: it outnumbers its side by `margin`
    /// points and holds most of the side's points (a face's edge of low contrast — a crease
    /// between two faces of the same grey — that only some of its points see is no evidence
    /// against it), and the side is on an edge at all (at least `margin` of its points see
    /// one there). A side no edge holds has nothing to slide off: a facet side without
    /// contrast, such as the open side of an L-shaped face the planner gave as a
    /// quadrilateral (the step's edge beside it is then a "rival" every point sees), is
    /// carried by the other sides' fit.
    pub fn outnumbers_its_side(&self, margin: usize) -> bool {
        self.support >= margin && self.rival >= self.support + margin && 2 * self.rival > self.count
    }
}

/// Per side, a histogram of where the points' candidate edges lie relative to the fitted
/// side (`fitted_px[i]`: the fitted contour's offset along point `i`'s search line, the same
/// axis as the candidates' `h_px`), once per turn in [`TURNS_PX`] (the offsets measured from
/// a line turned that much about the side's middle). The side's support is the points with an
/// edge within `band_px` of it; a rival's, the points with an edge within `band_px` of another
/// line whose offset from the side reaches at least `min_offset_px` (and more than
/// `2 band_px`) at one of the side's ends, so that, parallel, no edge counts for both. Each
/// point counts once per line; only parallel lines unless `turned`. Returns the side whose
/// best rival outnumbers its support the
/// most, among the sides where one could by `margin` points: a side with fewer than `margin`
/// points without its edge, or without an edge at all, is not searched for rivals (the turned
/// lines cost ~9 histograms a side). Allocates
/// nothing.
///
/// `template_px[s]` (when not empty): where the template's own shape, placed by the similarity
/// nearest to the contour's placement, puts side `s`, as offsets from the fitted side at its
/// first and last point. Only a line the template's shape pulls the side towards is a rival:
/// a side that slid off its edge onto another has bent the contour out of the template's
/// shape by the slide, and the shape points back to the edge it left (the edge is the rival);
/// a contour that keeps the template's shape has slid off nothing, and an edge beside its side
/// is a neighbouring face's, the face's own other edge seen through the band, a shadow or the
/// gripper's plate: nothing it could have slid from (clutter3 seed 127: the block's outline
/// 7 px beyond a faint crease the side holds, on every update from the first).
pub(crate) fn strongest_rival(
    sides: &[TemplateEdge],
    edges: &[PointEdges],
    fitted_px: &[f64],
    band_px: f64,
    min_offset_px: f64,
    margin: usize,
    turned: bool,
    template_px: &[[f64; 2]],
) -> Rival {
    let turns = if turned { &TURNS_PX[..] } else { &TURNS_PX[..1] };
    let half = (RIVAL_BINS / 2) as i64;
    let half_f = half as f64;
    let min_offset = min_offset_px.max(2.0 * band_px + 1.0).ceil();
    let mut best = Rival::default();
    let mut best_excess = i64::MIN;
    for (s, side) in sides.iter().enumerate().filter(|(_, s)| s.count > 0) {
        let mid = 0.5 * (side.count as f64 - 1.0);
        let (mut support, mut with_edge) = (0usize, 0usize);
        for i in side.first..side.first + side.count {
            let fitted = fitted_px[i];
            let found = edges[i].as_slice();
            with_edge += usize::from(fitted.is_finite() && !found.is_empty());
            support += usize::from(fitted.is_finite() && found.iter().any(|c| (f64::from(c.h_px) - fitted).abs() <= band_px));
        }
        // A rival holds at most the points with an edge: none can outnumber the side by
        // `margin` and hold most of its points, nor make it the side outnumbered the most
        // (the first of equals stays).
        if with_edge < support + margin || 2 * with_edge <= side.count || with_edge as i64 - support as i64 <= best_excess {
            continue;
        }
        // Only a line with more than `floor` points can make this side the best; the running
        // maximum starts there (the first line with the side's most points is the same).
        let floor = (best_excess.saturating_add(support as i64)).max(0) as usize;
        let (mut rival, mut offset, mut turn) = (floor, 0i64, 0.0);
        for &turn_px in turns {
            // No line holds more than the points with an edge.
            if rival >= with_edge {
                break;
            }
            let slope = if side.count > 1 { turn_px / (side.count as f64 - 1.0) } else { 0.0 };
            // The votes as differences between neighbouring bins: each point adds the union
            // of its edges' bin ranges once, as runs (its edges taken in order along the line,
            // each run starts past the last one's end).
            let mut steps = [0i32; RIVAL_BINS + 1];
            let (mut first, mut last) = (RIVAL_BINS, 0usize);
            for (j, i) in (side.first..side.first + side.count).enumerate() {
                let fitted = fitted_px[i] + slope * (j as f64 - mid);
                if !fitted.is_finite() {
                    continue;
                }
                let (found, mut h) = (edges[i].as_slice(), [0f64; MAX_CANDIDATES]);
                for (k, c) in found.iter().enumerate() {
                    // Insertion into the sorted prefix (at most 4 edges).
                    let v = f64::from(c.h_px);
                    let mut m = k;
                    while m > 0 && h[m - 1] > v {
                        h[m] = h[m - 1];
                        m -= 1;
                    }
                    h[m] = v;
                }
                // The first bin this point has not voted for.
                let mut next = 0usize;
                for &h in &h[..found.len()] {
                    let r = h - fitted;
                    // Bins `lo..=hi` (offset + `half`, so never negative here): the lines
                    // within `band_px` of this edge. Truncation is `floor` for the positive
                    // values kept; `f64::floor` would be a library call on the baseline x86-64
                    // target.
                    let (from, to) = (r - band_px + half_f, r + band_px + half_f);
                    if to < 0.0 || from > 2.0 * half_f {
                        continue;
                    }
                    let lo = from.max(0.0) as usize;
                    let lo = if (lo as f64) < from { lo + 1 } else { lo };
                    let hi = (to.min(2.0 * half_f) as usize).min(RIVAL_BINS - 1);
                    let lo = lo.max(next);
                    if lo > hi {
                        continue;
                    }
                    steps[lo] += 1;
                    steps[hi + 1] -= 1;
                    next = hi + 1;
                    first = first.min(lo);
                    last = last.max(hi);
                }
            }
            // A line qualifies where it is far enough from the side at one end (`o ± turn/2`).
            let reach = 0.5 * turn_px.abs();
            let pull = template_px.get(s).copied();
            let mut votes = 0i32;
            for b in first..=last.min(RIVAL_BINS - 1) {
                votes += steps[b];
                let (o, v) = (b as i64 - half, votes as usize);
                // The count first: most lines hold fewer points than the best so far.
                if v > rival && (o as f64).abs() + reach >= min_offset {
                    let ends = (o as f64 - 0.5 * turn_px, o as f64 + 0.5 * turn_px);
                    if pull.is_none_or(|d| template_pulls_towards(ends.0, ends.1, d)) {
                        (rival, offset, turn) = (v, o, turn_px);
                    }
                }
            }
        }
        let excess = rival as i64 - support as i64;
        if excess > best_excess {
            best_excess = excess;
            best = Rival { side: s, support, rival, offset_px: offset as f64, turn_px: turn, count: side.count };
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use nalgebra::Vector2;

    use super::*;
    use crate::tracker::search::{Candidate, MAX_CANDIDATES};

    /// One side of `count` points, each seeing edges at `offsets` (px from the fitted side,
    /// which sits 0.3 px out from where the points were searched).
    fn side(count: usize, offsets: impl Fn(usize) -> Vec<f32>) -> (Vec<TemplateEdge>, Vec<PointEdges>, Vec<f64>) {
        let z = Vector2::zeros();
        let sides = vec![TemplateEdge { first: 0, count, start: z, step: z, tangent: z }];
        let fitted = vec![0.3; count];
        let edges = (0..count)
            .map(|i| {
                let mut e = PointEdges::default();
                for (k, h) in offsets(i).into_iter().take(MAX_CANDIDATES).enumerate() {
                    e.candidates[k] = Candidate { h_px: h + 0.3, contrast: 30.0, ..Candidate::default() };
                    e.count = k as u8 + 1;
                }
                e
            })
            .collect();
        (sides, edges, fitted)
    }

    #[test]
    fn a_parallel_edge_most_points_see_is_a_rival_that_outnumbers_the_side() {
        // 8 of 24 points see the side's edge; 20 see one 7 px further out (a texture line the
        // side slid off, or the face's edge the side slid off onto texture).
        let (sides, edges, fitted) = side(24, |i| {
            let mut o = vec![7.2 - 0.02 * i as f32];
            if i % 3 == 0 {
                o.push(0.1);
            }
            if i >= 20 {
                o.remove(0);
            }
            o
        });
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[]);
        assert_eq!((r.side, r.support), (0, 8), "{r:?}");
        assert!(r.rival >= 19 && (r.offset_px - 7.0).abs() <= 1.0, "{r:?}");
    }

    #[test]
    fn a_side_on_no_edge_beside_a_step_every_point_sees_is_not_a_wrong_lock() {
        // The clutter3 seed-21 L-block: the planner's quadrilateral's top side lies across
        // the face's open notch, where no edge is (1 of 24 points finds one), with the step
        // 8 px below it that 20 points see: the strongest rival, but nothing slid off.
        let (sides, edges, fitted) = side(24, |i| {
            let mut o = if i < 20 { vec![-8.1] } else { vec![] };
            if i == 5 {
                o.push(0.2);
            }
            o
        });
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[]);
        assert!(r.support == 1 && r.rival >= 19, "{r:?}");
        assert!(!r.outnumbers_its_side(3), "{r:?}");
        // On an edge 8 of its points see, the same rival is a wrong lock.
        let (sides, edges, fitted) = side(24, |i| {
            let mut o = if i < 20 { vec![-8.1] } else { vec![] };
            if i % 3 == 0 {
                o.push(0.2);
            }
            o
        });
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[]);
        assert!(r.support == 8 && r.outnumbers_its_side(3), "{r:?}");
    }

    #[test]
    fn an_edge_beside_a_side_of_a_contour_that_keeps_its_template_shape_is_no_rival() {
        // Clutter3 seed 127: the side holds a faint crease between the target face and a
        // narrow side face of nearly its grey (6 of 24 points see it); the block's outline
        // 7 px further out, every point sees. The contour has the planned face's shape: the
        // template's side lies on the fitted side, so nothing slid off the outline.
        let (sides, edges, fitted) = side(24, |i| {
            let mut o = vec![7.1];
            if i % 4 == 0 {
                o.push(0.2);
            }
            o
        });
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[[0.3, -0.2]]);
        assert!(!r.outnumbers_its_side(3), "{r:?}");
        // The template's shape pulling the other way (inwards) does not make it one either.
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[[-2.0, -2.0]]);
        assert!(!r.outnumbers_its_side(3), "{r:?}");
        // A contour stretched by the side's slide 7 px inwards off the outline: its nearest
        // similarity puts the side ~2 px back out, towards the outline, a rival.
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[[1.8, 1.7]]);
        assert!(r.outnumbers_its_side(3) && (r.offset_px - 7.0).abs() <= 1.0, "{r:?}");
        // A turned rival counts where the shape pulls towards its far end: the line 12 px out
        // at the side's end and 2 px at its start, the shape pulling 3 px out at the end.
        let (sides, edges, fitted) = side(24, |i| {
            let mut o = vec![2.0 + 10.0 * i as f32 / 23.0];
            if i % 4 == 0 {
                o.push(0.2);
            }
            o
        });
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[[0.2, 3.0]]);
        assert!(r.outnumbers_its_side(3) && r.turn_px >= 5.0, "{r:?}");
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[[0.2, -0.3]]);
        assert!(!r.outnumbers_its_side(3), "{r:?}");
    }

    #[test]
    fn an_edge_at_an_angle_to_the_side_that_most_points_see_is_a_rival() {
        // A sheared contour: the face's edge runs 8 px inside the fitted side at its start
        // and 4 px outside at its end (12 px of turn over the side, 6.3° over ~110 px), seen
        // by 20 of 24 points; the side's own edge by 6 of them and by the 4 where the lines
        // cross.
        let (sides, edges, fitted) = side(24, |i| {
            let mut o = vec![-8.0 + 12.0 * i as f32 / 23.0];
            if (7..13).contains(&i) {
                o.push(0.2);
            }
            if i >= 20 {
                o.remove(0);
            }
            o
        });
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[]);
        assert_eq!(r.support, 10, "{r:?}");
        assert!(r.rival >= 18, "{r:?}");
        assert!((r.turn_px - 12.0).abs() <= 2.5 && (r.offset_px + 2.0).abs() <= 1.5, "{r:?}");
        // No parallel line holds as many of its points.
        assert!(r.turn_px != 0.0, "{r:?}");
    }

    #[test]
    fn the_other_flank_of_a_thin_line_and_scattered_texture_are_no_rivals() {
        // Two in three points see the side's edge (a textured face's edge); all see the other
        // flank of a thin dark line 3 px out (nearer than the 5 px a rival must be), and
        // texture edges scattered 5-10 px away that no straight line, parallel or turned,
        // through them explains.
        let (sides, edges, fitted) = side(24, |i| {
            let mut o = vec![3.1, 5.0 + (i * 7 % 6) as f32, -5.0 - (i * 5 % 6) as f32];
            if i % 3 != 0 {
                o.push(0.2);
            }
            o
        });
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[]);
        assert_eq!(r.support, 16, "{r:?}");
        assert!(r.rival < r.support + 3, "{r:?}");
        // A side whose every point sees its edge has no rival to search for.
        let (sides, edges, fitted) = side(24, |i| vec![0.2, 3.1, 5.0 + (i * 7 % 6) as f32, -5.0 - (i * 5 % 6) as f32]);
        assert_eq!(strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[]).rival, 0);
        // A point with two candidates on the same line counts once.
        let (sides, edges, fitted) = side(24, |_| vec![6.0, 6.4]);
        assert_eq!(strongest_rival(&sides, &edges, &fitted, 1.0, 5.0, 3, true, &[]).rival, 24);
    }
}
