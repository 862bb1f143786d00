//! Where a block's far top edge is along a profile of lines behind its front top edge (see
//! `rear_edges_from_image`): the line at each depth, with how both images step across it.
//!
//! Two measures of a step, from `pixels`: [`super::edge_support`] has 3 px of slack across
//! the line (a projected edge is off by a pixel or two), so it stays high over a plateau of
//! depths ~5 px either side of an edge and cannot place it; [`super::edge_strength`] has none,
//! so it peaks where the edge is and falls off within its sampling width (2 px either side).
//! A small top face (13 px deep in the image) puts the front edge's support plateau and the
//! far edge's within a pixel of each other: the far edge is then told from the front edge by
//! its strength rising again after the top face's flat surface, not by the support dropping.

/// The support a line needs in both views to be the far edge (the share of its length with a
/// step of at least 12 grey levels).
pub const MIN_SUPPORT: f64 = 0.7;

/// Below this support the line is clear of the front edge's step.
pub const FRONT_CLEAR_SUPPORT: f64 = 0.3;

/// Past this many pixels from the front edge (in both views) a line's strength no longer
/// sees the front edge's step: [`super::edge_strength`] samples 2 px either side of the line,
/// and sample positions round to whole pixels (one more).
pub const STRENGTH_REACH_PX: f64 = 3.0;

/// The weakest mean step along a line that [`MIN_SUPPORT`] admits: 12 grey levels along
/// `MIN_SUPPORT` of it, grey levels.
pub const MIN_STEP_GREY: f64 = 12.0 * MIN_SUPPORT;

/// One line of the profile, at one depth behind the front edge.
#[derive(Debug, Clone, Copy)]
pub struct DepthSample {
    /// [`super::edge_support`], the weaker view.
    pub support: f64,
    /// [`super::edge_strength`], the weaker view, grey levels.
    pub strength_grey: f64,
    /// How far the line is from the front edge in the image, the nearer view, px.
    pub offset_px: f64,
}

/// Where the far edge is in a profile ordered by depth, as a fractional index, or `None`.
///
/// Past the front edge (its strength's reach, or its support dropping), the first line that
/// is a separate step: supported in both views, at least [`MIN_STEP_GREY`] strong and twice
/// as strong as the weakest line since the front edge (the top face's surface between the
/// two). From there, along the support plateau it starts, the strongest line, until the
/// strength falls below half of it (past the step's own hump): where the edge is, not where
/// the plateau of support ends (that is up to 5 px, on a small top 7 mm, too deep). A sharp
/// step is as strong over the few lines the 2 px sampling straddles: the middle of the run
/// within 5 % of the strongest (as `strongest_shift`).
pub fn far_edge(profile: &[DepthSample]) -> Option<f64> {
    let clear = profile.iter().position(|s| s.offset_px >= STRENGTH_REACH_PX || s.support < FRONT_CLEAR_SUPPORT)?;
    let mut valley = f64::INFINITY;
    let mut first = None;
    for (i, s) in profile.iter().enumerate().skip(clear) {
        valley = valley.min(s.strength_grey);
        if s.support >= MIN_SUPPORT && s.strength_grey >= MIN_STEP_GREY && s.strength_grey >= 2.0 * valley {
            first = Some(i);
            break;
        }
    }
    let first = first?;
    let mut best = first;
    for (i, s) in profile.iter().enumerate().skip(first + 1) {
        if s.support < MIN_SUPPORT || s.strength_grey < 0.5 * profile[best].strength_grey {
            break;
        }
        if s.strength_grey > profile[best].strength_grey {
            best = i;
        }
    }
    let strong = |i: usize| profile[i].strength_grey >= 0.95 * profile[best].strength_grey;
    let (mut lo, mut hi) = (best, best);
    while lo > first && strong(lo - 1) {
        lo -= 1;
    }
    while hi + 1 < profile.len() && profile[hi + 1].support >= MIN_SUPPORT && strong(hi + 1) {
        hi += 1;
    }
    Some((lo + hi) as f64 / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(rows: &[(f64, f64, f64)]) -> Vec<DepthSample> {
        rows.iter().map(|&(support, strength_grey, offset_px)| DepthSample { support, strength_grey, offset_px }).collect()
    }

    #[test]
    fn a_far_edge_whose_support_meets_the_front_edges_is_found() {
        // A 13 px top at ~0.8 px per mm: the front edge's support reaches 5 px, the far edge's
        // from 8 px; the support never drops below 0.3 between them (clutter3 seed 23).
        let rows: Vec<(f64, f64, f64)> = (0..20)
            .map(|i| {
                let px = 0.8 * f64::from(i) + 1.0;
                let near_front = px < 5.0;
                let near_far = (px - 13.0).abs() < 5.0;
                let support = if near_front || near_far { 0.95 } else { 0.6 };
                let strength = if (px - 13.0).abs() < 1.0 { 40.0 } else if (px - 13.0).abs() < 2.0 { 25.0 } else if px < 3.0 { 30.0 } else { 2.0 };
                (support, strength, px)
            })
            .collect();
        let p = profile(&rows);
        let i = far_edge(&p).expect("the far edge is a separate step");
        let px = 0.8 * i + 1.0;
        assert!((px - 13.0).abs() < 1.0, "found at {px} px");
    }

    #[test]
    fn the_far_edge_is_the_strongest_line_of_its_plateau_not_its_end() {
        // Support stays 1.0 for 5 px past the edge (its slack); the edge is where the strength
        // peaks (clutter3 seed 26: found 37 mm deep on a 30 mm block).
        let rows: Vec<(f64, f64, f64)> = (0..40)
            .map(|i| {
                let px = f64::from(i);
                let support = if px < 5.0 || (px - 30.0).abs() <= 5.0 { 1.0 } else { 0.1 };
                let strength = if px < 3.0 { 30.0 } else { (35.0 - 12.0 * (px - 30.0).abs()).max(3.0) };
                (support, strength, px)
            })
            .collect();
        let p = profile(&rows);
        assert_eq!(far_edge(&p), Some(30.0));
    }

    #[test]
    fn the_front_edges_own_tail_is_not_a_far_edge() {
        // Only the front edge: strength falls off, support stays up to 5 px, then nothing.
        let rows: Vec<(f64, f64, f64)> = (0..30).map(|i| {
            let px = f64::from(i) * 0.5;
            let support = if px <= 5.0 { 1.0 } else { 0.05 };
            let strength = (40.0 - 10.0 * px).max(2.0);
            (support, strength, px)
        }).collect();
        assert_eq!(far_edge(&profile(&rows)), None);
    }

    #[test]
    fn a_faint_texture_on_the_top_is_not_a_far_edge() {
        // Supported lines (the front edge's slack) with noise-level strength only.
        let rows: Vec<(f64, f64, f64)> = (0..30).map(|i| {
            let px = f64::from(i);
            (if px <= 6.0 { 0.9 } else { 0.2 }, if px < 2.0 { 40.0 } else { 3.0 + (i % 3) as f64 }, px)
        }).collect();
        assert_eq!(far_edge(&profile(&rows)), None);
    }
}

#[cfg(test)]
mod plateau_tests {
    use super::*;

    #[test]
    fn a_step_as_strong_over_two_lines_is_placed_between_them() {
        let strength = [2.0, 2.0, 150.0, 189.0, 189.0, 150.0, 2.0];
        let p: Vec<DepthSample> = strength.iter().enumerate().map(|(i, &g)| DepthSample { support: 1.0, strength_grey: g, offset_px: 4.0 + i as f64 }).collect();
        assert_eq!(far_edge(&p), Some(3.5));
    }
}

/// How far above a top face found in the images another facet of its object may stand over
/// the face's footprint before it is taken for a false match, m: the bound the plan puts on
/// its heights below the table too (`BELOW_TABLE_M`).
pub const ABOVE_TOP_M: f64 = 0.015;

/// Whether the planar polygon `facet` (robot frame, m) stands more than [`ABOVE_TOP_M`] above
/// the horizontal top face `top` (its four corners, m, at one height up to the reconstruction's
/// noise) anywhere over the top's footprint in plan view. The top was seen from above in both
/// views, its far edge a step at its front edge's height: nothing of the same block stands
/// over it (the cameras would see that, not a flat top), so such a facet is a false match (an
/// L-block's step matched to the wrong edges: a 45° "facet" 67 mm high on a 40 mm block).
///
/// Facets within 20° of vertical (the grasp rules' vertical faces) are not judged: one at the
/// footprint's border is the face of a taller block touching this one (joined into its object
/// within a few millimetres), which the fingers must keep clear of.
pub fn stands_above_top(facet: &[nalgebra::Vector3<f64>], top: &[nalgebra::Vector3<f64>; 4]) -> bool {
    let n = facet.len();
    let normal: nalgebra::Vector3<f64> = (0..n).map(|i| facet[i].cross(&facet[(i + 1) % n])).sum();
    match normal.try_normalize(1e-12) {
        Some(u) if u.z.abs() > 20f64.to_radians().sin() => {}
        _ => return false,
    }
    let top_z = top.iter().map(|p| p.z).fold(f64::NEG_INFINITY, f64::max);
    let area: f64 = (0..4).map(|i| top[i].x * top[(i + 1) % 4].y - top[(i + 1) % 4].x * top[i].y).sum();
    let mut poly: Vec<nalgebra::Vector3<f64>> = facet.to_vec();
    // Sutherland-Hodgman against each side of the (convex) footprint; a planar polygon's
    // heights interpolate linearly along its sides.
    for i in 0..4 {
        let (p, q) = (top[i], top[(i + 1) % 4]);
        let side = |v: &nalgebra::Vector3<f64>| area.signum() * ((q.x - p.x) * (v.y - p.y) - (q.y - p.y) * (v.x - p.x));
        let mut out = Vec::with_capacity(poly.len() + 2);
        for k in 0..poly.len() {
            let (u, v) = (poly[k], poly[(k + 1) % poly.len()]);
            let (su, sv) = (side(&u), side(&v));
            if su >= 0.0 {
                out.push(u);
            }
            if (su >= 0.0) != (sv >= 0.0) {
                out.push(u + (v - u) * (su / (su - sv)));
            }
        }
        poly = out;
        if poly.is_empty() {
            return false;
        }
    }
    poly.iter().any(|p| p.z > top_z + ABOVE_TOP_M)
}

#[cfg(test)]
mod above_tests {
    use super::*;
    use nalgebra::Vector3;

    fn top() -> [Vector3<f64>; 4] {
        [Vector3::new(0.425, 0.004, 0.040), Vector3::new(0.422, 0.022, 0.040), Vector3::new(0.391, 0.022, 0.040), Vector3::new(0.394, 0.004, 0.040)]
    }

    #[test]
    fn a_false_facet_rising_over_a_seen_top_stands_above_it() {
        // clutter3 seed 26's facet: from the tall top's far side up to 67 mm in front of it.
        let facet = [Vector3::new(0.437, -0.003, 0.067), Vector3::new(0.392, 0.017, 0.040), Vector3::new(0.419, 0.022, 0.039)];
        assert!(stands_above_top(&facet, &top()));
    }

    #[test]
    fn the_top_itself_a_lower_leg_and_a_facet_beside_it_do_not() {
        let t = top();
        let noisy_top: Vec<Vector3<f64>> = t.iter().map(|p| p + Vector3::new(0.0, 0.0, 0.008)).collect();
        assert!(!stands_above_top(&noisy_top, &t));
        let low_leg = [Vector3::new(0.39, 0.022, 0.02), Vector3::new(0.42, 0.022, 0.02), Vector3::new(0.42, 0.042, 0.02), Vector3::new(0.39, 0.042, 0.02)];
        assert!(!stands_above_top(&low_leg, &t));
        let tall_beside = [Vector3::new(0.30, 0.10, 0.0), Vector3::new(0.30, 0.10, 0.09), Vector3::new(0.33, 0.10, 0.09)];
        assert!(!stands_above_top(&tall_beside, &t));
        // A taller block's face touching the top's far edge: vertical, kept (the rear finger
        // must keep clear of it).
        let touching = [Vector3::new(0.391, 0.004, 0.0), Vector3::new(0.391, 0.022, 0.0), Vector3::new(0.391, 0.022, 0.08), Vector3::new(0.391, 0.004, 0.08)];
        assert!(!stands_above_top(&touching, &t));
    }
}
