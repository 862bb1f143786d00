//! Small 2-D image geometry, the one home for it in the workspace: points, total-least-squares
//! line fits, convex hulls, polygon area and containment, a rasterised polygon IoU and overlap
//! share (exact enough for scoring, and valid for non-convex polygons such as the L-shaped
//! faces of L-blocks), and the simplification of a facet's outline into a tracker's corners.

/// A 2-D point or vector in pixels.
pub type P2 = [f64; 2];

#[inline]
pub fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}

#[inline]
pub fn add(a: P2, b: P2) -> P2 {
    [a[0] + b[0], a[1] + b[1]]
}

#[inline]
pub fn scale(a: P2, s: f64) -> P2 {
    [a[0] * s, a[1] * s]
}

#[inline]
pub fn dot(a: P2, b: P2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

/// z component of the 3-D cross product: > 0 when `b` is counter-clockwise of `a` in a
/// y-up frame (clockwise on screen, where y points down).
#[inline]
pub fn cross(a: P2, b: P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

#[inline]
pub fn norm(a: P2) -> f64 {
    (a[0] * a[0] + a[1] * a[1]).sqrt()
}

#[inline]
pub fn dist(a: P2, b: P2) -> f64 {
    norm(sub(a, b))
}

#[inline]
pub fn mid(a: P2, b: P2) -> P2 {
    [(a[0] + b[0]) * 0.5, (a[1] + b[1]) * 0.5]
}

/// Running sums for a total-least-squares line fit (orthogonal regression).
#[derive(Debug, Clone, Copy, Default)]
pub struct LineSums {
    pub n: f64,
    pub sx: f64,
    pub sy: f64,
    pub sxx: f64,
    pub sxy: f64,
    pub syy: f64,
}

impl LineSums {
    #[inline]
    pub fn add(&mut self, p: P2) {
        self.n += 1.0;
        self.sx += p[0];
        self.sy += p[1];
        self.sxx += p[0] * p[0];
        self.sxy += p[0] * p[1];
        self.syy += p[1] * p[1];
    }

    #[inline]
    pub fn merge(&mut self, o: &LineSums) {
        self.n += o.n;
        self.sx += o.sx;
        self.sy += o.sy;
        self.sxx += o.sxx;
        self.sxy += o.sxy;
        self.syy += o.syy;
    }

    /// The best-fit line: centroid, unit direction, and the RMS orthogonal residual. `None`
    /// for fewer than two points.
    pub fn fit(&self) -> Option<(P2, P2, f64)> {
        if self.n < 2.0 {
            return None;
        }
        let c = [self.sx / self.n, self.sy / self.n];
        let a = self.sxx / self.n - c[0] * c[0];
        let b = self.sxy / self.n - c[0] * c[1];
        let d = self.syy / self.n - c[1] * c[1];
        // Eigen-decomposition of the 2x2 covariance [[a b] [b d]].
        let tr = a + d;
        let disc = ((a - d) * (a - d) * 0.25 + b * b).sqrt();
        let l_small = (tr * 0.5 - disc).max(0.0);
        let theta = 0.5 * (2.0 * b).atan2(a - d);
        Some((c, [theta.cos(), theta.sin()], l_small.sqrt()))
    }
}

/// Intersection of the lines `p + s·d` and `q + t·e`; `None` when (nearly) parallel.
/// Returns the point and the parameters `(s, t)`.
pub fn intersect_lines(p: P2, d: P2, q: P2, e: P2) -> Option<(P2, f64, f64)> {
    let den = cross(d, e);
    if den.abs() < 1e-9 * norm(d) * norm(e) {
        return None;
    }
    let w = sub(q, p);
    let s = cross(w, e) / den;
    let t = cross(w, d) / den;
    Some((add(p, scale(d, s)), s, t))
}

/// Signed area of a polygon (positive when counter-clockwise in a y-up frame).
pub fn signed_area(poly: &[P2]) -> f64 {
    let n = poly.len();
    if n < 3 {
        return 0.0;
    }
    let mut s = 0.0;
    for i in 0..n {
        s += cross(poly[i], poly[(i + 1) % n]);
    }
    0.5 * s
}

/// Absolute area of a simple polygon.
pub fn area(poly: &[P2]) -> f64 {
    signed_area(poly).abs()
}

/// Convex hull (Andrew's monotone chain), counter-clockwise in a y-up frame, without
/// collinear points. Returns the indices into `pts`.
pub fn convex_hull(pts: &[P2]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..pts.len()).filter(|&i| pts[i][0].is_finite() && pts[i][1].is_finite()).collect();
    idx.sort_by(|&a, &b| pts[a][0].total_cmp(&pts[b][0]).then(pts[a][1].total_cmp(&pts[b][1])));
    idx.dedup_by(|a, b| pts[*a] == pts[*b]);
    if idx.len() < 3 {
        return idx;
    }
    let turn = |o: usize, a: usize, b: usize| cross(sub(pts[a], pts[o]), sub(pts[b], pts[o]));
    let mut hull: Vec<usize> = Vec::with_capacity(idx.len() * 2);
    for &i in &idx {
        while hull.len() >= 2 && turn(hull[hull.len() - 2], hull[hull.len() - 1], i) <= 0.0 {
            hull.pop();
        }
        hull.push(i);
    }
    let lower = hull.len() + 1;
    for &i in idx.iter().rev().skip(1) {
        while hull.len() >= lower && turn(hull[hull.len() - 2], hull[hull.len() - 1], i) <= 0.0 {
            hull.pop();
        }
        hull.push(i);
    }
    hull.pop();
    hull
}

/// Whether point `p` lies inside (or within `tol_px` of) the polygon. Works for any simple
/// polygon (even-odd rule) with the tolerance measured to the nearest edge.
pub fn contains(poly: &[P2], p: P2, tol_px: f64) -> bool {
    let n = poly.len();
    inside(poly, p) || (tol_px > 0.0 && (0..n).any(|i| point_segment_distance(p, poly[i], poly[(i + 1) % n]) <= tol_px))
}

/// Even-odd test of `p` against the polygon's sides (false for no polygon).
fn inside(poly: &[P2], p: P2) -> bool {
    let mut odd = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            odd = !odd;
        }
    }
    odd
}

/// Distance from `p` to the segment `a`–`b`.
pub fn point_segment_distance(p: P2, a: P2, b: P2) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let l2 = dx * dx + dy * dy;
    let t = if l2 > 0.0 { (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / l2).clamp(0.0, 1.0) } else { 0.0 };
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// Share of polygon `a`'s area (pixel centres inside it) that lies inside polygon `b`; 0
/// when `a` covers no pixel centre.
pub fn covered_share(a: &[P2], b: &[P2]) -> f64 {
    if a.len() < 3 || b.len() < 3 || a.iter().chain(b).flatten().any(|v| !v.is_finite()) {
        return 0.0;
    }
    let lo = |k: usize| a.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min).floor() as i64;
    let hi = |k: usize| a.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max).ceil() as i64;
    let (mut total, mut shared) = (0u64, 0u64);
    for y in lo(1)..=hi(1) {
        for x in lo(0)..=hi(0) {
            let p = [x as f64, y as f64];
            if inside(a, p) {
                total += 1;
                shared += u64::from(inside(b, p));
            }
        }
    }
    if total == 0 { 0.0 } else { shared as f64 / total as f64 }
}

/// Indices of the vertices kept by Douglas-Peucker on a closed polygon (tolerance `tol`),
/// at least three, in order.
pub fn simplify_closed(poly: &[P2], tol: f64) -> Vec<usize> {
    let n = poly.len();
    if n <= 3 {
        return (0..n).collect();
    }
    // Split at vertex 0 and the vertex farthest from it.
    let far = (1..n).max_by(|&a, &b| {
        let d = |i: usize| (poly[i][0] - poly[0][0]).hypot(poly[i][1] - poly[0][1]);
        d(a).total_cmp(&d(b))
    });
    let Some(far) = far else { return (0..n).collect() };
    let mut keep = vec![false; n];
    keep[0] = true;
    keep[far] = true;
    fn dp(poly: &[P2], a: usize, b: usize, tol: f64, keep: &mut [bool]) {
        // Vertices strictly between a and b, going forward (cyclically).
        let n = poly.len();
        let mut best = (0.0, None);
        let mut i = (a + 1) % n;
        while i != b {
            let d = point_segment_distance(poly[i], poly[a], poly[b]);
            if d > best.0 {
                best = (d, Some(i));
            }
            i = (i + 1) % n;
        }
        if let (d, Some(i)) = best
            && d > tol
        {
            keep[i] = true;
            dp(poly, a, i, tol, keep);
            dp(poly, i, b, tol, keep);
        }
    }
    dp(poly, 0, far, tol, &mut keep);
    dp(poly, far, 0, tol, &mut keep);
    let mut out: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
    // Fewer than three: add the vertex farthest from the chord.
    while out.len() < 3 {
        let extra = (0..n).filter(|i| !out.contains(i)).max_by(|&a, &b| {
            let d = |i: usize| point_segment_distance(poly[i], poly[out[0]], poly[out[out.len() - 1]]);
            d(a).total_cmp(&d(b))
        });
        match extra {
            Some(e) => {
                out.push(e);
                out.sort_unstable();
            }
            None => break,
        }
    }
    out
}

/// `keep` (indices into `poly`, in order) rotated to start at the corner whose two sides
/// span the largest parallelogram: a tracker's template frame is `e1 = c1 − c0`,
/// `e2 = c_{n−1} − c0`, and the servo's view of the facet (its `s, t` rows and plane
/// transfer) is only as well conditioned as that frame; a short side at a notch of an L
/// would make it lopsided.
pub fn tracker_order(poly: &[P2], keep: &[usize]) -> Vec<usize> {
    let n = keep.len();
    if n < 3 {
        return keep.to_vec();
    }
    let area = |k: usize| {
        let (o, a, b) = (poly[keep[k]], poly[keep[(k + 1) % n]], poly[keep[(k + n - 1) % n]]);
        ((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])).abs()
    };
    let best = (0..n).max_by(|&a, &b| area(a).total_cmp(&area(b)).then(b.cmp(&a))).unwrap_or(0);
    (0..n).map(|k| keep[(best + k) % n]).collect()
}

/// Whether two convex polygons (any orientation) intersect, by the separating axis test.
/// Degenerate "polygons" (a point or a segment) are allowed.
pub fn convex_intersect(a: &[P2], b: &[P2], tol_px: f64) -> bool {
    if a.is_empty() || b.is_empty() {
        return false;
    }
    for (poly, other) in [(a, b), (b, a)] {
        let n = poly.len();
        let mut axes: Vec<P2> = Vec::with_capacity(n + 1);
        for i in 0..n {
            let e = sub(poly[(i + 1) % n], poly[i]);
            if norm(e) > 1e-12 {
                axes.push([-e[1], e[0]]);
            }
        }
        if n == 2 {
            // A segment also separates along its own direction.
            axes.push(sub(poly[1], poly[0]));
        }
        for ax in axes {
            let l = norm(ax);
            let ax = scale(ax, 1.0 / l);
            let (lo1, hi1) = project(poly, ax);
            let (lo2, hi2) = project(other, ax);
            if hi1 + tol_px < lo2 || hi2 + tol_px < lo1 {
                return false;
            }
        }
    }
    true
}

fn project(poly: &[P2], ax: P2) -> (f64, f64) {
    poly.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
        let d = dot(*p, ax);
        (lo.min(d), hi.max(d))
    })
}

/// Intersection-over-union of two simple polygons (non-convex allowed), computed by sampling
/// both on a grid of `samples_per_px` x `samples_per_px` points per pixel over their common
/// bounding box. With 4 samples per pixel the error is well under 1% for polygons of a few
/// hundred pixels. Zero when either polygon is empty.
pub fn polygon_iou(a: &[P2], b: &[P2], samples_per_px: usize) -> f64 {
    if a.len() < 3 || b.len() < 3 {
        return 0.0;
    }
    let bb = |p: &[P2]| {
        p.iter().fold([f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY], |m, q| {
            [m[0].min(q[0]), m[1].min(q[1]), m[2].max(q[0]), m[3].max(q[1])]
        })
    };
    let (ba, bb_) = (bb(a), bb(b));
    let x0 = ba[0].min(bb_[0]);
    let y0 = ba[1].min(bb_[1]);
    let x1 = ba[2].max(bb_[2]);
    let y1 = ba[3].max(bb_[3]);
    if !(x0.is_finite() && y0.is_finite() && x1.is_finite() && y1.is_finite()) {
        return 0.0;
    }
    let k = samples_per_px.max(1) as f64;
    let step = 1.0 / k;
    let (mut inter, mut uni) = (0u64, 0u64);
    // Scanline: per sample row, the inside intervals of each polygon (even-odd crossings).
    let mut xs_a: Vec<f64> = Vec::new();
    let mut xs_b: Vec<f64> = Vec::new();
    let mut y = y0 + step * 0.5;
    while y < y1 {
        crossings(a, y, &mut xs_a);
        crossings(b, y, &mut xs_b);
        let mut x = x0 + step * 0.5;
        while x < x1 {
            let ia = inside_sorted(&xs_a, x);
            let ib = inside_sorted(&xs_b, x);
            inter += (ia && ib) as u64;
            uni += (ia || ib) as u64;
            x += step;
        }
        y += step;
    }
    if uni == 0 { 0.0 } else { inter as f64 / uni as f64 }
}

fn crossings(poly: &[P2], y: f64, out: &mut Vec<f64>) {
    out.clear();
    let n = poly.len();
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (poly[i], poly[j]);
        if (a[1] > y) != (b[1] > y) {
            out.push(a[0] + (y - a[1]) * (b[0] - a[0]) / (b[1] - a[1]));
        }
        j = i;
    }
    out.sort_by(f64::total_cmp);
}

fn inside_sorted(xs: &[f64], x: f64) -> bool {
    xs.partition_point(|&c| c <= x) % 2 == 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn line_fit_recovers_direction_and_residual() {
        let mut s = LineSums::default();
        for i in 0..20 {
            let t = i as f64;
            // Points on y = 0.5 x + 3, in pairs 0.1 above and below.
            for off in [0.1, -0.1] {
                let n = [-0.5f64, 1.0];
                let nn = norm(n);
                s.add([t + off * n[0] / nn, 0.5 * t + 3.0 + off * n[1] / nn]);
            }
        }
        let (c, d, rms) = s.fit().unwrap();
        assert!((d[1] / d[0] - 0.5).abs() < 1e-9);
        assert!((c[1] - (0.5 * c[0] + 3.0)).abs() < 1e-9);
        assert!((rms - 0.1).abs() < 1e-9);
    }

    #[test]
    fn hull_area_containment_and_intersection() {
        let pts = [[0.0, 0.0], [4.0, 0.0], [4.0, 3.0], [0.0, 3.0], [2.0, 1.0], [2.0, 0.0]];
        let h = convex_hull(&pts);
        assert_eq!(h.len(), 4, "interior and collinear points are dropped: {h:?}");
        let poly: Vec<P2> = h.iter().map(|&i| pts[i]).collect();
        assert!((area(&poly) - 12.0).abs() < 1e-12);
        assert!(contains(&poly, [1.0, 1.0], 0.0));
        assert!(!contains(&poly, [5.0, 1.0], 0.0));
        assert!(contains(&poly, [4.5, 1.0], 0.6));
        let moved: Vec<P2> = poly.iter().map(|p| [p[0] + 3.9, p[1]]).collect();
        assert!(convex_intersect(&poly, &moved, 0.0));
        let far: Vec<P2> = poly.iter().map(|p| [p[0] + 4.5, p[1]]).collect();
        assert!(!convex_intersect(&poly, &far, 0.0));
        // A segment crossing the box, and one beside it.
        assert!(convex_intersect(&poly, &[[-1.0, 1.0], [5.0, 2.0]], 0.0));
        assert!(!convex_intersect(&poly, &[[-1.0, 4.0], [5.0, 5.0]], 0.0));
    }

    #[test]
    fn iou_of_shifted_squares_and_an_l_shape() {
        let sq = |x: f64, y: f64, s: f64| vec![[x, y], [x + s, y], [x + s, y + s], [x, y + s]];
        // 20x20 squares shifted by 2 px: inter 18*20 = 360, union 440.
        let iou = polygon_iou(&sq(0.0, 0.0, 20.0), &sq(2.0, 0.0, 20.0), 4);
        assert!((iou - 360.0 / 440.0).abs() < 0.01, "iou {iou}");
        assert!((polygon_iou(&sq(0.0, 0.0, 20.0), &sq(0.0, 0.0, 20.0), 4) - 1.0).abs() < 1e-12);
        assert_eq!(polygon_iou(&sq(0.0, 0.0, 10.0), &sq(30.0, 0.0, 10.0), 4), 0.0);
        // L shape (area 300) against its bounding square (400): IoU 0.75 — a convex hull
        // would have scored 1.0 here.
        let l = vec![[0.0, 0.0], [20.0, 0.0], [20.0, 10.0], [10.0, 10.0], [10.0, 20.0], [0.0, 20.0]];
        let iou = polygon_iou(&l, &sq(0.0, 0.0, 20.0), 4);
        assert!((iou - 0.75).abs() < 0.01, "iou {iou}");
        assert!((area(&l) - 300.0).abs() < 1e-12);
    }

    #[test]
    fn lines_intersect_where_expected() {
        let (p, s, t) = intersect_lines([0.0, 0.0], [1.0, 0.0], [3.0, -2.0], [0.0, 2.0]).unwrap();
        assert!((p[0] - 3.0).abs() < 1e-12 && p[1].abs() < 1e-12);
        assert!((s - 3.0).abs() < 1e-12 && (t - 1.0).abs() < 1e-12);
        assert!(intersect_lines([0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [2.0, 0.0]).is_none());
    }

    #[test]
    fn covered_share_is_the_share_of_the_first_polygon_inside_the_second() {
        let square = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let left_half = [[-1.0, -1.0], [4.9, -1.0], [4.9, 11.0], [-1.0, 11.0]];
        assert_eq!(covered_share(&square, &square), 1.0);
        // Pixel centres 0..=4 of the ten columns inside the square (0..10).
        let half = covered_share(&square, &left_half);
        assert!((half - 0.5).abs() < 0.01, "{half}");
        assert_eq!(covered_share(&left_half, &[[20.0, 0.0], [30.0, 0.0], [30.0, 10.0]]), 0.0);
        assert_eq!(covered_share(&square, &[[0.0, 0.0], [1.0, 1.0]]), 0.0, "not a polygon");
        assert_eq!(covered_share(&[[f64::NAN, 0.0], [1.0, 0.0], [1.0, 1.0]], &square), 0.0);
    }

    #[test]
    fn simplification_drops_slivers_and_keeps_corners() {
        // A square whose corner (10, 0) is split into two vertices 1 px apart, plus a point
        // in the middle of a side.
        let poly = [[0.0, 0.0], [9.0, 0.0], [10.0, 1.0], [10.0, 10.0], [5.0, 10.2], [0.0, 10.0]];
        let keep = simplify_closed(&poly, 1.5);
        assert_eq!(keep.len(), 4, "{keep:?}");
        assert!(keep.contains(&0) && keep.contains(&5));
        // A triangle stays a triangle.
        assert_eq!(simplify_closed(&[[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]], 1.5), vec![0, 1, 2]);
        // An L (tall leg on the right): the frame starts at the corner with the longest
        // sides, the bottom-right one (40 across, 40 up).
        let l = [[0.0, 0.0], [0.0, -20.0], [20.0, -20.0], [20.0, -40.0], [40.0, -40.0], [40.0, 0.0]];
        assert_eq!(tracker_order(&l, &[0, 1, 2, 3, 4, 5]), vec![5, 0, 1, 2, 3, 4]);
    }
}
