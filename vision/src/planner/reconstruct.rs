//! Hypothesis selection of the final matches, and their reconstruction (thesis 5.6).
//!
//! Each left segment keeps at most one match: the one its accepted planes support, else the
//! best-supported remaining candidate (friends), one-to-one; an unsupported candidate is kept
//! only when it is the sole candidate of both its segments.
//!
//! Reconstruction is in the affine frame `(cyclopean u, cyclopean v, disparity u' − u)`
//! (and in robot coordinates when the affine stereo model is known), using the strongest
//! constraint available:
//! 1. on facets, the facet's transfer gives the correspondence (averaged over all facets the
//!    segment lies on, e.g. a crease between two faces);
//! 2. else the junction points at both ends, matched in both views;
//! 3. else a junction at one end and the epipolar constraint at the other, assuming the
//!    junction's offset from its epipolar line holds along the (short) segment;
//! 4. else the epipolar constraint alone, for segments more than `epipolar_min_angle_deg`
//!    from the epipolar lines in both views; the rest cannot be reconstructed and are dropped.
//!
//! Matched ends need not be the same scene points (edges are truncated differently in the two
//! views), so each segment is reconstructed over the union of its two images: the outermost
//! pair of the four visible end points.

use super::facets::Facet;
use super::geom::{self, P2};
use super::matching::{Candidates, EpipolarFrame, Friendship, EpipolarGeometry};
use super::planes::{coverage, stretches_overlap, Plane};
use super::segments::Segment;
use super::transfer::union_by_transfer;

/// How a match was reconstructed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Method {
    Facet,
    Junctions,
    JunctionAndEpipolar,
    Epipolar,
}

impl Method {
    pub fn name(&self) -> &'static str {
        match self {
            Method::Facet => "facet",
            Method::Junctions => "junctions",
            Method::JunctionAndEpipolar => "junction+epipolar",
            Method::Epipolar => "epipolar",
        }
    }
}

/// A reconstructed segment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reconstruction {
    /// Corresponding end points in the left and right view.
    pub left: [P2; 2],
    pub right: [P2; 2],
    /// `(cyclopean u, cyclopean v, disparity u' − u)` of both ends, pixels.
    pub cyclopean_disparity: [[f64; 3]; 2],
    /// Robot coordinates of both ends, metres (when calibrated).
    pub robot_m: Option<[[f64; 3]; 2]>,
    pub method: Method,
}

/// A selected match.
#[derive(Debug, Clone, PartialEq)]
pub struct Match {
    /// Index into the candidates.
    pub candidate: u32,
    pub left: u32,
    pub right: u32,
    /// Accepted planes supporting it.
    pub planes: Vec<u32>,
    /// Facets it belongs to (filled in once facets are formed).
    pub facets: Vec<u32>,
    /// `None` when it cannot be reconstructed (along the epipolar lines, no other constraint).
    pub reconstruction: Option<Reconstruction>,
}

/// Hypothesis selection (see the module docs).
pub fn select_matches(cands: &Candidates, friends: &[Friendship], planes: &[Plane], left: &[Segment], right: &[Segment]) -> Vec<Match> {
    let (n_left, n_right) = (left.len(), right.len());
    let n = cands.list.len();
    let mut plane_of: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut plane_score = vec![0.0; n];
    for (pi, p) in planes.iter().enumerate() {
        for &m in &p.members {
            plane_of[m as usize].push(pi as u32);
            plane_score[m as usize] += p.support_px;
        }
    }
    let mut chosen = vec![false; n];
    let mut left_used = vec![false; n_left];
    let mut right_used = vec![false; n_right];
    // Plane-supported matches, best planes first; a left segment takes several only when
    // they cover disjoint stretches of it.
    let mut stretches: Vec<(f64, f64)> = Vec::new();
    for l in 0..n_left as u32 {
        let mut supported: Vec<usize> = cands.of_left(l).filter(|&c| !plane_of[c].is_empty()).collect();
        supported.sort_by(|&a, &b| plane_score[b].total_cmp(&plane_score[a]));
        stretches.clear();
        for c in supported {
            let r = cands.list[c].right;
            let best_plane = plane_of[c].iter().max_by(|&&a, &&b| planes[a as usize].support_px.total_cmp(&planes[b as usize].support_px));
            let Some(&p) = best_plane else { continue };
            let cov = coverage(&planes[p as usize].transfer, &left[l as usize], &right[r as usize]);
            if stretches.iter().all(|s| !stretches_overlap(*s, cov)) {
                stretches.push(cov);
                chosen[c] = true;
                left_used[l as usize] = true;
                right_used[r as usize] = true;
            }
        }
    }
    // Friends of each candidate.
    let mut fr: Vec<Vec<u32>> = vec![Vec::new(); n];
    for f in friends {
        fr[f.a as usize].push(f.b);
        fr[f.b as usize].push(f.a);
    }
    let mut right_count = vec![0u32; n_right];
    for c in &cands.list {
        right_count[c.right as usize] += 1;
    }
    let score = |c: usize, chosen: &[bool], left_used: &[bool]| -> f64 {
        fr[c].iter().map(|&f| if chosen[f as usize] { 2.0 } else if !left_used[cands.list[f as usize].left as usize] { 1.0 } else { 0.0 }).sum()
    };
    let mut rest: Vec<(f64, f64, usize)> = (0..n)
        .filter(|&c| !left_used[cands.list[c].left as usize])
        .map(|c| (score(c, &chosen, &left_used), cands.list[c].overlap_px, c))
        .collect();
    rest.sort_by(|a, b| b.0.total_cmp(&a.0).then(b.1.total_cmp(&a.1)));
    for (s, _, c) in rest {
        let cd = &cands.list[c];
        if left_used[cd.left as usize] || right_used[cd.right as usize] {
            continue;
        }
        let unique = cands.of_left(cd.left).len() == 1 && right_count[cd.right as usize] == 1;
        if s >= 1.0 || unique {
            chosen[c] = true;
            left_used[cd.left as usize] = true;
            right_used[cd.right as usize] = true;
        }
    }
    (0..n)
        .filter(|&c| chosen[c])
        .map(|c| Match { candidate: c as u32, left: cands.list[c].left, right: cands.list[c].right, planes: plane_of[c].clone(), facets: Vec::new(), reconstruction: None })
        .collect()
}

/// Reconstructs every match in place (see the module docs).
#[allow(clippy::too_many_arguments)] // the planner's stage outputs, passed as they are
pub fn reconstruct(matches: &mut [Match], facets: &[Facet], friends: &[Friendship], left: &[Segment], right: &[Segment], geo: &EpipolarGeometry, epipolar_min_angle_deg: f64, junction_gap_px: f64) {
    let ef = geo.frame();
    let mut by_cand = std::collections::HashMap::with_capacity(matches.len());
    for (i, m) in matches.iter().enumerate() {
        by_cand.insert(m.candidate, i);
    }
    for (fi, f) in facets.iter().enumerate() {
        for &c in &f.members {
            if let Some(&i) = by_cand.get(&c) {
                matches[i].facets.push(fi as u32);
            }
        }
    }
    // Junction correspondences at the ends of each match, from friends whose both
    // candidates were selected.
    let mut ends: Vec<[Option<(P2, P2)>; 2]> = vec![[None, None]; matches.len()];
    for f in friends {
        let (Some(&ia), Some(&ib)) = (by_cand.get(&f.a), by_cand.get(&f.b)) else { continue };
        for i in [ia, ib] {
            let l = &left[matches[i].left as usize];
            let (d0, d1) = (geom::dist(f.left_point, l.p0), geom::dist(f.left_point, l.p1));
            let k = if d0 <= d1 { 0 } else { 1 };
            if d0.min(d1) <= junction_gap_px {
                // Of several junctions at one end, keep the one nearest its epipolar line.
                let better = match ends[i][k] {
                    Some((pl, pr)) => ef.residual(f.left_point, f.right_point).abs() < ef.residual(pl, pr).abs(),
                    None => true,
                };
                if better {
                    ends[i][k] = Some((f.left_point, f.right_point));
                }
            }
        }
    }
    let sin_min = epipolar_min_angle_deg.to_radians().sin();
    let (el, er) = (ef.left_dir(), ef.right_dir());
    for (i, m) in matches.iter_mut().enumerate() {
        let (l, r) = (&left[m.left as usize], &right[m.right as usize]);
        let pairs: Option<([P2; 2], [P2; 2], Method)> = if !m.facets.is_empty() {
            let mut acc_l = [[0.0; 2]; 2];
            let mut acc_r = [[0.0; 2]; 2];
            let k = m.facets.len() as f64;
            for &fi in &m.facets {
                let t = &facets[fi as usize].transfer;
                let (xl, xr) = union_by_transfer(t, l, r);
                for e in 0..2 {
                    acc_l[e] = geom::add(acc_l[e], geom::scale(xl[e], 1.0 / k));
                    acc_r[e] = geom::add(acc_r[e], geom::scale(xr[e], 1.0 / k));
                }
            }
            Some((acc_l, acc_r, Method::Facet))
        } else if let [Some(a), Some(b)] = ends[i] {
            Some(([a.0, b.0], [a.1, b.1], Method::Junctions))
        } else if let Some((k, (jl, jr))) = ends[i].iter().enumerate().find_map(|(k, e)| e.map(|e| (k, e))) {
            // The other end: same offset from the epipolar line as the junction.
            let off = ef.residual(jl, jr);
            let far_l = if k == 0 { l.p1 } else { l.p0 };
            if geom::cross(r.dir(), er).abs() < sin_min {
                None
            } else {
                ef.right_point_at(r.p0, r.dir(), ef.eta_left(far_l) + off).map(|far_r| {
                    let mut xl = [jl, far_l];
                    let mut xr = [jr, far_r];
                    if k == 1 {
                        xl.swap(0, 1);
                        xr.swap(0, 1);
                    }
                    (xl, xr, Method::JunctionAndEpipolar)
                })
            }
        } else if geom::cross(l.dir(), el).abs() >= sin_min && geom::cross(r.dir(), er).abs() >= sin_min {
            union_by_epipolar(&ef, l, r).map(|(xl, xr)| (xl, xr, Method::Epipolar))
        } else {
            None
        };
        m.reconstruction = pairs.map(|(xl, xr, method)| make(xl, xr, method, geo));
    }
}

/// Corresponding end points of the union of `l` and `r` along the epipolar constraint.
fn union_by_epipolar(ef: &EpipolarFrame, l: &Segment, r: &Segment) -> Option<([P2; 2], [P2; 2])> {
    let mut pts: Vec<(f64, P2, P2)> = Vec::with_capacity(4);
    for x in [l.p0, l.p1] {
        let e = ef.eta_left(x);
        pts.push((e, x, ef.right_point_at(r.p0, r.dir(), e)?));
    }
    for x in [r.p0, r.p1] {
        let e = ef.eta_right(x);
        pts.push((e, ef.left_point_at(l.p0, l.dir(), e)?, x));
    }
    let lo = pts.iter().min_by(|a, b| a.0.total_cmp(&b.0))?;
    let hi = pts.iter().max_by(|a, b| a.0.total_cmp(&b.0))?;
    Some(([lo.1, hi.1], [lo.2, hi.2]))
}

/// A point's `(u, v, u', v')` in cyclopean-disparity form.
pub fn cyclopean_disparity(xl: P2, xr: P2) -> [f64; 3] {
    [(xl[0] + xr[0]) * 0.5, (xl[1] + xr[1]) * 0.5, xr[0] - xl[0]]
}

fn make(xl: [P2; 2], xr: [P2; 2], method: Method, geo: &EpipolarGeometry) -> Reconstruction {
    let cd = [cyclopean_disparity(xl[0], xr[0]), cyclopean_disparity(xl[1], xr[1])];
    let p = |k: usize| geo.robot_point(&[xl[k][0], xl[k][1], xr[k][0], xr[k][1]]);
    let robot_m = p(0).zip(p(1)).map(|(a, b)| [a, b]);
    Reconstruction { left: xl, right: xr, cyclopean_disparity: cd, robot_m, method }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn seg(p0: P2, p1: P2) -> Segment {
        Segment { p0, p1, contrast: 10.0, rms_px: 0.1, n_points: 20 }
    }

    #[test]
    fn epipolar_union_for_a_slanted_segment() {
        use crate::affine::EpipolarConstraint;
        use nalgebra::Vector4;
        // Rectified: v' = v. Left segment v in [10, 50], right v in [20, 60].
        let ef = EpipolarFrame::new(&EpipolarConstraint::from_normal(Vector4::new(0.0, -1.0, 0.0, 1.0), 0.0));
        let l = seg([100.0, 10.0], [120.0, 50.0]);
        let r = seg([80.0, 20.0], [100.0, 60.0]);
        let (xl, xr) = union_by_epipolar(&ef, &l, &r).unwrap();
        assert!((xl[0][1] - 10.0).abs() < 1e-9 && (xr[0][1] - 10.0).abs() < 1e-9);
        assert!((xl[1][1] - 60.0).abs() < 1e-9 && (xr[1][1] - 60.0).abs() < 1e-9);
        assert!((xr[0][0] - 75.0).abs() < 1e-9 && (xl[1][0] - 125.0).abs() < 1e-9);
    }
}
