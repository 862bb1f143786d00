//! From planes to facets (thesis 5.5.4, 5.6.1-5.6.2).
//!
//! Each plane's matched segments are split into connected components by the junction relation
//! (L and Y junctions seen in both views — friends: a T, or a junction that exists in one
//! view only, is an occlusion joining surfaces of different objects) and collinearity (which rejoins an edge broken by texture); each component's convex hull
//! is formed in the cyclopean image (`(x + x')/2`), and components whose hulls intersect are
//! merged into one facet. Only *cores* (two or more junction-connected segments) merge that
//! way; another segment joins a facet when its hull comes within `join_px` of the facet's
//! and it meets a member at a junction in the left view, or lies inside the hull; otherwise
//! it is an accidental coplanarity, as are groups without any core: they are not facets.
//!
//! A facet's boundary is the *modified convex hull*: every hull edge that is not a physical
//! edge, but whose ends lie on the facet's connected edges, is replaced by the chain of
//! connected edges that bridges the gap while still enclosing the facet — the concavity of an
//! L- or C-shaped face. Where the edges are patchy it stays the convex hull. Segment ends are
//! first extended to their junction points, so the polygon's corners are the line
//! intersections rather than the rounded, truncated ends of the segments.

use std::collections::{HashSet, VecDeque};

use super::geom::{self, P2};
use super::matching::{Candidates, EpipolarFrame, Friendship};
use super::planes::{Plane, Transfer, TransferFit};
use super::relations::{End, JunctionKind, Relations};
use super::segments::Segment;
use super::transfer::union_by_transfer;
use crate::union_find::UnionFind;

/// Tolerances of facet formation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FacetConfig {
    /// Fewest segments of a facet.
    pub min_segments: usize,
    /// Smallest cyclopean area of a facet, square pixels.
    pub min_area_px: f64,
    /// Hulls closer than this count as intersecting (segment ends stop short of corners
    /// that no junction restored), pixels.
    pub touch_px: f64,
    /// A segment that is not part of a core joins a core's facet when its hull comes this
    /// close to the core's and one of its segments meets a member at a junction in the left
    /// view, pixels: such an edge ends short of the facet's corner on a weak or dark face (the
    /// junction already says it belongs), so it may stop further off than two cores may.
    pub join_px: f64,
    /// Longest chain of edges that may bridge a concavity.
    pub bridge_max_edges: usize,
    /// Weight of the epipolar rows when refitting a facet's transfer.
    pub epipolar_weight: f64,
    /// Weight of the junction points between members (seen in both views) when refitting a
    /// facet's transfer, relative to the line rows (0: lines only).
    pub junction_weight: f64,
}

impl Default for FacetConfig {
    fn default() -> Self {
        Self { min_segments: 3, min_area_px: 60.0, touch_px: 3.0, join_px: 8.0, bridge_max_edges: 6, epipolar_weight: 0.1, junction_weight: 1.0 }
    }
}

/// A planar facet.
#[derive(Debug, Clone, PartialEq)]
pub struct Facet {
    /// Index of the plane it belongs to.
    pub plane: u32,
    /// The left-to-right transfer re-estimated from the facet's own segments.
    pub transfer: Transfer,
    /// Member candidate indices.
    pub members: Vec<u32>,
    /// Boundary polygon in the left and right view (same vertex order).
    pub left: Vec<P2>,
    pub right: Vec<P2>,
    /// Connected component (object) id: facets sharing a segment or joined by an L or Y
    /// junction have the same id.
    pub component: u32,
}

/// Inputs of facet formation.
pub struct FacetInput<'a> {
    pub left: &'a [Segment],
    pub right: &'a [Segment],
    pub cands: &'a Candidates,
    pub planes: &'a [Plane],
    pub rel_left: &'a Relations,
    pub friends: &'a [Friendship],
    pub epipolar: &'a EpipolarFrame,
}

/// Forms the facets of all planes.
pub fn find_facets(inp: &FacetInput, cfg: &FacetConfig) -> Vec<Facet> {
    // Junctions count only when they are seen in both views (friends): a junction that is an
    // accident of one viewpoint (an edge ending where another object's corner hides it) has
    // no consistent partner in the other view.
    let friends: HashSet<(u32, u32)> = inp.friends.iter().map(|f| (f.a, f.b)).collect();
    let friendly = |a: u32, b: u32| friends.contains(&(a.min(b), a.max(b)));
    let mut facets = Vec::new();
    // Position of each left segment in the current plane's member list.
    let mut slot = vec![usize::MAX; inp.left.len()];
    for (pi, plane) in inp.planes.iter().enumerate() {
        let members = &plane.members;
        for (k, &m) in members.iter().enumerate() {
            slot[inp.cands.list[m as usize].left as usize] = k;
        }
        let mut uf = UnionFind::new(members.len());
        let mut connected = vec![false; members.len()];
        // Joined to a fellow member by an L or Y junction in the left view only.
        let mut touching = vec![false; members.len()];
        // L and Y junctions only: a T is where one surface occludes another.
        for j in inp.rel_left.junctions.iter().filter(|j| j.kind != JunctionKind::T) {
            let (a, b) = (slot[j.a as usize], slot[j.b as usize]);
            if a != usize::MAX && b != usize::MAX {
                touching[a] = true;
                touching[b] = true;
            }
            if a != usize::MAX && b != usize::MAX && friendly(members[a], members[b]) {
                uf.union(a, b);
                connected[a] = true;
                connected[b] = true;
            }
        }
        for &(a, b) in &inp.rel_left.collinears {
            let (a, b) = (slot[a as usize], slot[b as usize]);
            if a != usize::MAX && b != usize::MAX {
                uf.union(a, b);
            }
        }
        // Components and their cyclopean hulls.
        let ends: Vec<[P2; 2]> = members.iter().map(|&m| extended_ends(inp, &plane.transfer, m, &slot, members, &friendly)).collect();
        let mut groups: Vec<Vec<usize>> = Vec::new();
        let mut root_group = vec![usize::MAX; members.len()];
        for k in 0..members.len() {
            let r = uf.find(k);
            if root_group[r] == usize::MAX {
                root_group[r] = groups.len();
                groups.push(Vec::new());
            }
            groups[root_group[r]].push(k);
        }
        let hull_of = |g: &[usize]| -> Vec<P2> {
            let pts: Vec<P2> = g.iter().flat_map(|&k| ends[k]).map(|p| plane.transfer.cyclopean(p)).collect();
            geom::convex_hull(&pts).into_iter().map(|i| pts[i]).collect()
        };
        let mut hulls: Vec<Vec<P2>> = groups.iter().map(|g| hull_of(g)).collect();
        // Cores: components of two or more segments joined by junctions seen in both views.
        // Cores merge when their hulls intersect. Any other segment joins a core when its
        // hull touches the core's and it forms a junction with a fellow member in the left
        // view (an edge whose corner the right view did not show), or when it lies inside
        // the core's hull (texture on the face); otherwise it is an accidental coplanarity
        // and must not stretch the facet over a neighbouring surface.
        let core: Vec<bool> = groups.iter().map(|g| g.len() >= 2 && g.iter().any(|&k| connected[k])).collect();
        let mut alive = core.clone();
        loop {
            let mut merged = false;
            for i in 0..groups.len() {
                if !alive[i] {
                    continue;
                }
                for j in i + 1..groups.len() {
                    if alive[j] && geom::convex_intersect(&hulls[i], &hulls[j], cfg.touch_px) {
                        let gj = std::mem::take(&mut groups[j]);
                        groups[i].extend(gj);
                        alive[j] = false;
                        hulls[i] = hull_of(&groups[i]);
                        merged = true;
                    }
                }
            }
            if !merged {
                break;
            }
        }
        for j in 0..groups.len() {
            if core[j] {
                continue;
            }
            let pts: Vec<P2> = groups[j].iter().flat_map(|&k| ends[k]).map(|p| plane.transfer.cyclopean(p)).collect();
            let loose = groups[j].iter().any(|&k| touching[k]);
            let joins = |i: usize| {
                alive[i] && if loose { geom::convex_intersect(&hulls[i], &hulls[j], cfg.join_px) } else { pts.iter().all(|&p| geom::contains(&hulls[i], p, cfg.touch_px)) }
            };
            if let Some(i) = (0..groups.len()).find(|&i| joins(i)) {
                let gj = std::mem::take(&mut groups[j]);
                groups[i].extend(gj);
            }
        }
        for (gi, g) in groups.iter().enumerate() {
            if !alive[gi] || g.len() < cfg.min_segments || !g.iter().any(|&k| connected[k]) {
                continue;
            }
            if geom::area(&hulls[gi]) < cfg.min_area_px {
                continue;
            }
            let fm: Vec<u32> = g.iter().map(|&k| members[k]).collect();
            let transfer = refit(inp, &fm, cfg).unwrap_or(plane.transfer);
            // Recompute ends with the facet's own transfer, then the boundary.
            let fends: Vec<[P2; 2]> = fm.iter().map(|&m| extended_ends(inp, &transfer, m, &slot, members, &friendly)).collect();
            let cyc: Vec<[P2; 2]> = fends.iter().map(|e| [transfer.cyclopean(e[0]), transfer.cyclopean(e[1])]).collect();
            let boundary = modified_hull(&cyc, cfg.bridge_max_edges);
            let left: Vec<P2> = boundary.iter().filter_map(|&c| transfer.from_cyclopean(c)).collect();
            if left.len() != boundary.len() || left.len() < 3 {
                continue;
            }
            let right = left.iter().map(|&x| transfer.apply(x)).collect();
            facets.push(Facet { plane: pi as u32, transfer, members: fm, left, right, component: 0 });
        }
        for &m in members {
            slot[inp.cands.list[m as usize].left as usize] = usize::MAX;
        }
    }
    let mut facets = drop_duplicates(inp, facets);
    assign_components(inp, &mut facets, &friendly);
    facets
}

/// The left segment of candidate `m`, extended to the union of its own extent and its
/// match's (transferred back; see [`union_by_transfer`]), then to its junction points with
/// fellow members.
fn extended_ends(inp: &FacetInput, t: &Transfer, m: u32, slot: &[usize], members: &[u32], friendly: &dyn Fn(u32, u32) -> bool) -> [P2; 2] {
    let c = &inp.cands.list[m as usize];
    let (l, r) = (&inp.left[c.left as usize], &inp.right[c.right as usize]);
    let (mut e, _) = union_by_transfer(t, l, r);
    for &ji in inp.rel_left.junctions_of(c.left) {
        let j = &inp.rel_left.junctions[ji as usize];
        let (other, _) = j.other(c.left);
        let k = slot[other as usize];
        if k == usize::MAX || !friendly(m, members[k]) {
            continue;
        }
        match j.end_of(c.left) {
            End::P0 => e[0] = j.point,
            End::P1 => e[1] = j.point,
            End::Interior => {}
        }
    }
    e
}

/// The facet's own transfer: its members' lines, the (weak) epipolar rows, and the junction
/// points between members seen in both views, which pin the disparity where the lines cannot
/// (edges that run along the epipolar lines fit any disparity).
fn refit(inp: &FacetInput, members: &[u32], cfg: &FacetConfig) -> Option<Transfer> {
    let first = inp.cands.list[*members.first()? as usize].left as usize;
    let mut fit = TransferFit::new(inp.left[first].midpoint());
    for &m in members {
        let c = &inp.cands.list[m as usize];
        let (l, r) = (&inp.left[c.left as usize], &inp.right[c.right as usize]);
        fit.add_line(l, r, 1.0);
        for p in [l.p0, l.p1] {
            fit.add_epipolar(inp.epipolar, p, cfg.epipolar_weight);
        }
    }
    if cfg.junction_weight > 0.0 {
        for f in inp.friends.iter().filter(|f| members.contains(&f.a) && members.contains(&f.b)) {
            fit.add_point(f.left_point, f.right_point, cfg.junction_weight);
        }
    }
    fit.solve().filter(|t| t.det() > 0.0)
}

/// The modified convex hull of a set of edges (see the module docs), cyclopean coordinates.
pub fn modified_hull(edges: &[[P2; 2]], max_bridge: usize) -> Vec<P2> {
    // Vertices: edge ends, merged when they coincide (shared junction points).
    let mut verts: Vec<P2> = Vec::new();
    let vid = |p: P2, verts: &mut Vec<P2>| -> usize {
        if let Some(i) = verts.iter().position(|v| geom::dist(*v, p) < 1.0) {
            i
        } else {
            verts.push(p);
            verts.len() - 1
        }
    };
    let mut adj: Vec<Vec<usize>> = Vec::new();
    let mut links: Vec<(usize, usize)> = Vec::new();
    for e in edges {
        let a = vid(e[0], &mut verts);
        let b = vid(e[1], &mut verts);
        if adj.len() < verts.len() {
            adj.resize(verts.len(), Vec::new());
        }
        if a != b {
            adj[a].push(b);
            adj[b].push(a);
            links.push((a, b));
        }
    }
    adj.resize(verts.len(), Vec::new());
    let hull = geom::convex_hull(&verts);
    if hull.len() < 3 {
        return hull.into_iter().map(|i| verts[i]).collect();
    }
    // A hull edge is physical when an edge lies along it.
    let physical = |a: usize, b: usize| {
        let (pa, pb) = (verts[a], verts[b]);
        let len = geom::dist(pa, pb);
        edges.iter().any(|e| {
            let on = geom::point_segment_distance(e[0], pa, pb) < 1.5 && geom::point_segment_distance(e[1], pa, pb) < 1.5;
            on && geom::dist(e[0], e[1]) > 0.5 * len
        })
    };
    let mut poly: Vec<usize> = Vec::with_capacity(hull.len());
    for k in 0..hull.len() {
        let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
        poly.push(a);
        if physical(a, b) {
            continue;
        }
        let hull_pts: Vec<P2> = hull.iter().map(|&i| verts[i]).collect();
        // A concavity's chain runs strictly inside the hull (the long way round the facet's
        // own boundary is not a bridge).
        let inside = |i: usize| {
            !hull.contains(&i)
                && geom::contains(&hull_pts, verts[i], 0.0)
                && (0..hull_pts.len()).all(|k| geom::point_segment_distance(verts[i], hull_pts[k], hull_pts[(k + 1) % hull_pts.len()]) > 0.5)
        };
        if let Some(path) = bridge(&adj, a, b, max_bridge).filter(|p| p[1..p.len() - 1].iter().all(|&i| inside(i))) {
            // Splice tentatively and keep it only if the polygon stays simple and encloses
            // every vertex.
            let mut trial = poly.clone();
            trial.extend(&path[1..path.len() - 1]);
            trial.extend(&hull[k + 1..]);
            let tp: Vec<P2> = trial.iter().map(|&i| verts[i]).collect();
            let encloses = verts.iter().all(|&v| geom::contains(&tp, v, 1.0));
            if encloses && simple(&tp) {
                poly.extend(&path[1..path.len() - 1]);
            }
        }
    }
    poly.into_iter().map(|i| verts[i]).collect()
}

/// Shortest chain of edges from `a` to `b` (not the direct edge), up to `max` edges.
fn bridge(adj: &[Vec<usize>], a: usize, b: usize, max: usize) -> Option<Vec<usize>> {
    let mut prev = vec![usize::MAX; adj.len()];
    let mut depth = vec![usize::MAX; adj.len()];
    let mut q = VecDeque::new();
    depth[a] = 0;
    q.push_back(a);
    while let Some(u) = q.pop_front() {
        if depth[u] >= max {
            continue;
        }
        for &v in &adj[u] {
            if depth[v] != usize::MAX || (u == a && v == b) {
                continue;
            }
            depth[v] = depth[u] + 1;
            prev[v] = u;
            if v == b {
                let mut path = vec![b];
                let mut x = b;
                while x != a {
                    x = prev[x];
                    path.push(x);
                }
                path.reverse();
                return (path.len() > 2).then_some(path);
            }
            q.push_back(v);
        }
    }
    None
}

/// Whether a closed polygon has no two non-adjacent edges crossing.
fn simple(p: &[P2]) -> bool {
    let n = p.len();
    for i in 0..n {
        for j in i + 2..n {
            if i == 0 && j == n - 1 {
                continue;
            }
            if segments_cross(p[i], p[(i + 1) % n], p[j], p[(j + 1) % n]) {
                return false;
            }
        }
    }
    true
}

fn segments_cross(a: P2, b: P2, c: P2, d: P2) -> bool {
    let o = |p: P2, q: P2, r: P2| geom::cross(geom::sub(q, p), geom::sub(r, p));
    let (d1, d2, d3, d4) = (o(c, d, a), o(c, d, b), o(a, b, c), o(a, b, d));
    (d1 * d2 < 0.0) && (d3 * d4 < 0.0)
}

/// The same group of segments can form a facet on two planes (two hypotheses that agree
/// where the segments are but not elsewhere): keep the facet with more segments (or, equal,
/// the better fitting transfer) and drop those whose left segments are mostly (3/4) its.
fn drop_duplicates(inp: &FacetInput, mut facets: Vec<Facet>) -> Vec<Facet> {
    let lefts = |f: &Facet| -> Vec<u32> {
        let mut v: Vec<u32> = f.members.iter().map(|&m| inp.cands.list[m as usize].left).collect();
        v.sort_unstable();
        v.dedup();
        v
    };
    let rms = |f: &Facet| -> f64 {
        let s: f64 = f
            .members
            .iter()
            .map(|&m| {
                let c = &inp.cands.list[m as usize];
                let (r, _) = super::planes::line_residuals(&f.transfer, &inp.left[c.left as usize], &inp.right[c.right as usize]);
                r[0] * r[0] + r[1] * r[1]
            })
            .sum();
        s / f.members.len().max(1) as f64
    };
    let sets: Vec<Vec<u32>> = facets.iter().map(lefts).collect();
    let fits: Vec<f64> = facets.iter().map(rms).collect();
    let mut keep = vec![true; facets.len()];
    for i in 0..facets.len() {
        for j in 0..facets.len() {
            if i == j || !keep[j] {
                continue;
            }
            let better = (sets[j].len(), -fits[j]) > (sets[i].len(), -fits[i]) || ((sets[j].len(), -fits[j]) == (sets[i].len(), -fits[i]) && j < i);
            let shared = sets[i].iter().filter(|s| sets[j].binary_search(s).is_ok()).count();
            if better && 4 * shared >= 3 * sets[i].len() {
                keep[i] = false;
                break;
            }
        }
    }
    let mut k = 0;
    facets.retain(|_| {
        k += 1;
        keep[k - 1]
    });
    facets
}

/// Connected component ids: facets sharing a left segment or joined by a junction seen in both
/// views.
fn assign_components(inp: &FacetInput, facets: &mut [Facet], friendly: &dyn Fn(u32, u32) -> bool) {
    // Per left segment: (facet, candidate) of the facets it belongs to.
    let mut owner: Vec<Vec<(usize, u32)>> = vec![Vec::new(); inp.left.len()];
    for (fi, f) in facets.iter().enumerate() {
        for &m in &f.members {
            owner[inp.cands.list[m as usize].left as usize].push((fi, m));
        }
    }
    let mut uf = UnionFind::new(facets.len());
    for o in &owner {
        for w in o.windows(2) {
            uf.union(w[0].0, w[1].0);
        }
    }
    for j in inp.rel_left.junctions.iter().filter(|j| j.kind != JunctionKind::T) {
        for &(fa, ma) in &owner[j.a as usize] {
            for &(fb, mb) in &owner[j.b as usize] {
                if friendly(ma, mb) {
                    uf.union(fa, fb);
                }
            }
        }
    }
    let mut ids = vec![u32::MAX; facets.len()];
    let mut next = 0;
    for fi in 0..facets.len() {
        let r = uf.find(fi);
        if ids[r] == u32::MAX {
            ids[r] = next;
            next += 1;
        }
        facets[fi].component = ids[r];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn modified_hull_bridges_an_l_concavity() {
        // An L-shaped face: six edges meeting at six corners.
        let l = [[0.0, 0.0], [40.0, 0.0], [40.0, 20.0], [20.0, 20.0], [20.0, 40.0], [0.0, 40.0]];
        let edges: Vec<[P2; 2]> = (0..6).map(|i| [l[i], l[(i + 1) % 6]]).collect();
        let poly = modified_hull(&edges, 6);
        assert_eq!(poly.len(), 6, "{poly:?}");
        assert!((geom::area(&poly) - 1200.0).abs() < 1e-9);
        // Without the two concave edges the boundary cannot be bridged: convex hull.
        let patchy: Vec<[P2; 2]> = vec![edges[0], edges[1], edges[4], edges[5]];
        let poly = modified_hull(&patchy, 6);
        assert!((geom::area(&poly) - 1400.0).abs() < 1e-9, "area {}", geom::area(&poly));
    }

    #[test]
    fn convex_face_keeps_its_hull() {
        let q = [[0.0, 0.0], [30.0, 2.0], [28.0, 25.0], [1.0, 22.0]];
        let mut edges: Vec<[P2; 2]> = (0..4).map(|i| [q[i], q[(i + 1) % 4]]).collect();
        // An inner texture line connected to a corner must not be used as a "bridge".
        edges.push([q[0], [15.0, 12.0]]);
        let poly = modified_hull(&edges, 6);
        assert_eq!(poly.len(), 4);
        assert!((geom::area(&poly) - geom::area(&q)).abs() < 1e-9);
    }
}
