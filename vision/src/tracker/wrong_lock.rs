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
use super::search::PointEdges;

/// Bins of the rival histogram: offsets of ±47 px in 1 px steps (the search reaches ±40).
const RIVAL_BINS: usize = 95;

/// The side with the strongest rival edge after a wide pass.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Rival {
    /// Side index (corner `side` to `side + 1`).
    pub side: usize,
    /// Points of the side with an edge within the band of the fitted side.
    pub support: usize,
    /// Points of the side with an edge within the band of the rival line.
    pub rival: usize,
    /// The rival line's offset from the fitted side along the outward normal, px.
    pub offset_px: f64,
    /// Points on the side.
    pub count: usize,
}

/// Per side, a histogram of where the points' candidate edges lie relative to the fitted
/// side (`fitted_px[i]`: the fitted contour's offset along point `i`'s search line, the same
/// axis as the candidates' `h_px`). The side's support is the points with an edge within
/// `band_px` of it; a rival's, the points with an edge within `band_px` of a parallel line at
/// least `min_offset_px` (and more than `2 band_px`) away, so that no edge counts for both.
/// Each point counts once per line. Returns the side whose best rival outnumbers its support
/// the most. Allocates nothing.
pub(crate) fn strongest_rival(
    sides: &[TemplateEdge],
    edges: &[PointEdges],
    fitted_px: &[f64],
    band_px: f64,
    min_offset_px: f64,
) -> Rival {
    let half = (RIVAL_BINS / 2) as i64;
    let half_f = half as f64;
    let min_offset = min_offset_px.max(2.0 * band_px + 1.0).ceil() as i64;
    let mut best = Rival::default();
    let mut best_excess = i64::MIN;
    for (s, side) in sides.iter().enumerate().filter(|(_, s)| s.count > 0) {
        let mut votes = [0u16; RIVAL_BINS];
        // The last point that voted for each line, counted from 1 along the side.
        let mut voter = [0u16; RIVAL_BINS];
        let mut support = 0usize;
        for (j, i) in (side.first..side.first + side.count).enumerate() {
            let (j, fitted) = (j as u16 + 1, fitted_px[i]);
            if !fitted.is_finite() {
                continue;
            }
            let mut on_side = false;
            for c in edges[i].as_slice() {
                let r = f64::from(c.h_px) - fitted;
                on_side |= r.abs() <= band_px;
                // Bins `lo..=hi` (offset + `half`, so never negative here): the lines within
                // `band_px` of this edge. Truncation is `floor` for the positive values kept;
                // `f64::floor` would be a library call on the baseline x86-64 target.
                let (from, to) = (r - band_px + half_f, r + band_px + half_f);
                if to < 0.0 || from > 2.0 * half_f {
                    continue;
                }
                let lo = from.max(0.0) as usize;
                let lo = if (lo as f64) < from { lo + 1 } else { lo };
                let hi = (to.min(2.0 * half_f) as usize).min(RIVAL_BINS - 1);
                for b in lo..=hi {
                    // Without a branch: which point voted last is unpredictable.
                    votes[b] += u16::from(voter[b] != j);
                    voter[b] = j;
                }
            }
            support += usize::from(on_side);
        }
        let (mut rival, mut offset) = (0usize, 0i64);
        for (b, &v) in votes.iter().enumerate() {
            let o = b as i64 - half;
            if o.abs() >= min_offset && usize::from(v) > rival {
                (rival, offset) = (usize::from(v), o);
            }
        }
        let excess = rival as i64 - support as i64;
        if excess > best_excess {
            best_excess = excess;
            best = Rival { side: s, support, rival, offset_px: offset as f64, count: side.count };
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
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0);
        assert_eq!((r.side, r.support), (0, 8), "{r:?}");
        assert!(r.rival >= 19 && (r.offset_px - 7.0).abs() <= 1.0, "{r:?}");
    }

    #[test]
    fn the_other_flank_of_a_thin_line_and_scattered_texture_are_no_rivals() {
        // Every point sees the side's edge; most also see the other flank of a thin dark line
        // 3 px out (nearer than the 5 px a rival must be), and texture edges scattered 5-10 px
        // away that no straight line through them explains.
        let (sides, edges, fitted) = side(24, |i| vec![0.2, 3.1, 5.0 + (i * 7 % 6) as f32, -5.0 - (i * 5 % 6) as f32]);
        let r = strongest_rival(&sides, &edges, &fitted, 1.0, 5.0);
        assert_eq!(r.support, 24, "{r:?}");
        assert!(r.rival < 24, "{r:?}");
        // A point with two candidates on the same line counts once.
        let (sides, edges, fitted) = side(24, |_| vec![6.0, 6.4]);
        assert_eq!(strongest_rival(&sides, &edges, &fitted, 1.0, 5.0).rival, 24);
    }
}
