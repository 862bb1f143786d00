//! Small 2-D geometry used across the planner: points, total-least-squares line fits, convex
//! hulls, polygon area and containment, and a rasterised polygon IoU (exact enough for scoring,
//! and valid for non-convex polygons such as the L-shaped faces of L-blocks).

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
    if n == 0 {
        return false;
    }
    let mut inside = false;
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (poly[i], poly[j]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if p[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside || (tol_px > 0.0 && (0..n).any(|i| point_segment_distance(p, poly[i], poly[(i + 1) % n]) <= tol_px))
}

/// Distance from `p` to the segment `a`–`b`.
pub fn point_segment_distance(p: P2, a: P2, b: P2) -> f64 {
    let ab = sub(b, a);
    let l2 = dot(ab, ab);
    let t = if l2 > 0.0 { (dot(sub(p, a), ab) / l2).clamp(0.0, 1.0) } else { 0.0 };
    dist(p, add(a, scale(ab, t)))
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
}
