//! Left-to-right affine transfers: the image-to-image map of a plane under weak
//! perspective, its least-squares fit from matched lines, points and the weak epipolar
//! constraint, and how a matched segment pair relates to a transfer.

use nalgebra::{Matrix6, Vector6};

use super::geom::{self, P2};
use super::matching::EpipolarFrame;
use super::segments::Segment;

/// A left-to-right affine transfer `x' = A x + b`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transfer {
    /// Row-major `A`.
    pub a: [[f64; 2]; 2],
    pub b: P2,
}

impl Transfer {
    pub const IDENTITY: Transfer = Transfer { a: [[1.0, 0.0], [0.0, 1.0]], b: [0.0, 0.0] };

    #[inline]
    pub fn apply(&self, x: P2) -> P2 {
        [self.a[0][0] * x[0] + self.a[0][1] * x[1] + self.b[0], self.a[1][0] * x[0] + self.a[1][1] * x[1] + self.b[1]]
    }

    pub fn det(&self) -> f64 {
        self.a[0][0] * self.a[1][1] - self.a[0][1] * self.a[1][0]
    }

    /// The right-to-left transfer; `None` when `A` is singular.
    pub fn inverse(&self) -> Option<Transfer> {
        let d = self.det();
        if d.abs() < 1e-12 {
            return None;
        }
        let ai = [[self.a[1][1] / d, -self.a[0][1] / d], [-self.a[1][0] / d, self.a[0][0] / d]];
        let b = [-(ai[0][0] * self.b[0] + ai[0][1] * self.b[1]), -(ai[1][0] * self.b[0] + ai[1][1] * self.b[1])];
        Some(Transfer { a: ai, b })
    }

    /// The left point whose cyclopean position `(x + T x)/2` is `c`; `None` when degenerate.
    pub fn from_cyclopean(&self, c: P2) -> Option<P2> {
        // (I + A)/2 · x + b/2 = c
        let m = Transfer { a: [[0.5 * (1.0 + self.a[0][0]), 0.5 * self.a[0][1]], [0.5 * self.a[1][0], 0.5 * (1.0 + self.a[1][1])]], b: [0.5 * self.b[0], 0.5 * self.b[1]] };
        m.inverse().map(|mi| mi.apply(c))
    }

    /// Cyclopean position of left point `x`.
    pub fn cyclopean(&self, x: P2) -> P2 {
        geom::mid(x, self.apply(x))
    }

    /// Singular values of `A` (largest first).
    pub fn singular_values(&self) -> (f64, f64) {
        let [[a, b], [c, d]] = self.a;
        let s1 = a * a + b * b + c * c + d * d;
        let det = (a * d - b * c).abs();
        let disc = (s1 * s1 - 4.0 * det * det).max(0.0).sqrt();
        (((s1 + disc) * 0.5).sqrt(), ((s1 - disc) * 0.5).max(0.0).sqrt())
    }
}

/// Accumulated normal equations of a transfer fit, in coordinates centred on `origin`.
#[derive(Debug, Clone)]
pub struct TransferFit {
    ata: Matrix6<f64>,
    atb: Vector6<f64>,
    origin: P2,
    rows: usize,
}

impl TransferFit {
    pub fn new(origin: P2) -> Self {
        Self { ata: Matrix6::zeros(), atb: Vector6::zeros(), origin, rows: 0 }
    }

    fn row(&mut self, c: [f64; 6], t: f64, w: f64) {
        let v = Vector6::from(c) * w;
        self.ata += v * v.transpose();
        self.atb += v * (t * w);
        self.rows += 1;
    }

    /// Both ends of left segment `l`, transferred, on the line of right segment `r`.
    pub fn add_line(&mut self, l: &Segment, r: &Segment, w: f64) {
        let n = r.bright_normal();
        let d = geom::dot(n, r.p0);
        for a in [l.p0, l.p1] {
            let x = geom::sub(a, self.origin);
            self.row([n[0] * x[0], n[0] * x[1], n[1] * x[0], n[1] * x[1], n[0], n[1]], d, w);
        }
    }

    /// Left point `a` and its transfer obey the epipolar constraint: `η(A a + b) = η̂(a)`.
    pub fn add_epipolar(&mut self, ef: &EpipolarFrame, a: P2, w: f64) {
        let (nr, k) = ef.right_normal();
        let x = geom::sub(a, self.origin);
        let c = [nr[0] * x[0], nr[0] * x[1], nr[1] * x[0], nr[1] * x[1], nr[0], nr[1]];
        // Scaled to right pixels.
        self.row(c.map(|v| v * k), ef.eta_left(a), w);
    }

    /// Point correspondence `a` → `a2`.
    pub fn add_point(&mut self, a: P2, a2: P2, w: f64) {
        let x = geom::sub(a, self.origin);
        self.row([x[0], x[1], 0.0, 0.0, 1.0, 0.0], a2[0], w);
        self.row([0.0, 0.0, x[0], x[1], 0.0, 1.0], a2[1], w);
    }

    pub fn solve(&self) -> Option<Transfer> {
        if self.rows < 6 {
            return None;
        }
        let p = self.ata.cholesky()?.solve(&self.atb);
        if !p.iter().all(|v| v.is_finite()) {
            return None;
        }
        let a = [[p[0], p[1]], [p[2], p[3]]];
        // Back from centred coordinates: b = b̃ − A·origin.
        let o = self.origin;
        let b = [p[4] - (a[0][0] * o[0] + a[0][1] * o[1]), p[5] - (a[1][0] * o[0] + a[1][1] * o[1])];
        Some(Transfer { a, b })
    }
}

/// Line residuals (signed, pixels) of left segment `l` transferred onto right segment `r`,
/// and whether the transferred segment overlaps `r` along the line.
pub fn line_residuals(t: &Transfer, l: &Segment, r: &Segment) -> ([f64; 2], bool) {
    let (q0, q1) = (t.apply(l.p0), t.apply(l.p1));
    let res = [r.line_distance(q0), r.line_distance(q1)];
    let (s0, s1) = (r.along(q0), r.along(q1));
    let (lo, hi) = (s0.min(s1), s0.max(s1));
    let len = r.length();
    let ov = hi.min(len) - lo.max(0.0);
    (res, ov >= 0.25 * (hi - lo).min(len) - 2.0)
}

/// The stretch `[lo, hi]` of left segment `l` (as `along` parameters) that right segment `r`
/// covers under `t`; empty (`lo == hi`) when they do not overlap.
pub fn coverage(t: &Transfer, l: &Segment, r: &Segment) -> (f64, f64) {
    let Some(ti) = t.inverse() else { return (0.0, 0.0) };
    let (a, b) = (l.along(ti.apply(r.p0)), l.along(ti.apply(r.p1)));
    let lo = a.min(b).max(0.0);
    let hi = a.max(b).min(l.length());
    if hi > lo { (lo, hi) } else { (lo, lo) }
}

/// Corresponding end points of the union of `l` and `r` under transfer `t`.
///
/// Where one view's segment runs on well beyond the other's, the excess is capped (at
/// `max(4 px, 15%)` of the shorter one): an edge is often truncated differently in the two
/// views, but a large excess usually means the longer segment continues onto another surface
/// (two edges that happen to line up in one view).
pub fn union_by_transfer(t: &Transfer, l: &Segment, r: &Segment) -> ([P2; 2], [P2; 2]) {
    let ll = l.length();
    let (mut rlo, mut rhi) = (0.0, ll);
    if let Some(ti) = t.inverse() {
        let (a, b) = (l.along(ti.apply(r.p0)), l.along(ti.apply(r.p1)));
        rlo = a.min(b);
        rhi = a.max(b);
    }
    let cap = (0.15 * ll.min(rhi - rlo)).max(4.0);
    // Each side: the outer of the two ends, but no more than `cap` beyond the inner one.
    let lo = 0.0f64.min(rlo).max(0.0f64.max(rlo) - cap);
    let hi = ll.max(rhi).min(ll.min(rhi) + cap);
    let d = l.dir();
    let xl = [geom::add(l.p0, geom::scale(d, lo)), geom::add(l.p0, geom::scale(d, hi))];
    (xl, [t.apply(xl[0]), t.apply(xl[1])])
}

/// Whether two stretches of a segment overlap by more than a few pixels.
pub fn stretches_overlap(a: (f64, f64), b: (f64, f64)) -> bool {
    a.1.min(b.1) - a.0.max(b.0) > 3.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transfer_inverse_and_cyclopean_round_trip() {
        let t = Transfer { a: [[0.9, 0.1], [-0.05, 1.1]], b: [-20.0, 3.0] };
        let ti = t.inverse().unwrap();
        let x = [123.0, 45.0];
        let back = ti.apply(t.apply(x));
        assert!(geom::dist(back, x) < 1e-9);
        let c = t.cyclopean(x);
        assert!(geom::dist(t.from_cyclopean(c).unwrap(), x) < 1e-9);
        let (s1, s2) = t.singular_values();
        assert!((s1 * s2 - t.det().abs()).abs() < 1e-9 && s1 >= s2);
    }

    #[test]
    fn fit_from_three_lines_recovers_the_transfer() {
        let truth = Transfer { a: [[0.92, 0.07], [-0.03, 1.04]], b: [-25.0, 4.0] };
        let seg = |p0: P2, p1: P2| Segment { p0, p1, contrast: 10.0, rms_px: 0.1, n_points: 20 };
        // Three non-parallel left segments; their right images are the transferred lines,
        // but with ends truncated differently (only the lines matter).
        let lefts = [seg([100.0, 100.0], [180.0, 110.0]), seg([100.0, 100.0], [90.0, 170.0]), seg([150.0, 160.0], [190.0, 120.0])];
        let mut fit = TransferFit::new([120.0, 120.0]);
        for l in &lefts {
            let (q0, q1) = (truth.apply(l.p0), truth.apply(l.p1));
            let d = geom::sub(q1, q0);
            let r = seg(geom::add(q0, geom::scale(d, 0.1)), geom::add(q0, geom::scale(d, 0.8)));
            fit.add_line(l, &r, 1.0);
            let (res, overlap) = line_residuals(&truth, l, &r);
            assert!(res[0].abs() < 1e-9 && res[1].abs() < 1e-9 && overlap);
        }
        let t = fit.solve().unwrap();
        for x in [[0.0, 0.0], [300.0, 200.0]] {
            assert!(geom::dist(t.apply(x), truth.apply(x)) < 1e-6);
        }
    }

    fn segment(p0: P2, p1: P2) -> Segment {
        Segment { p0, p1, contrast: 10.0, rms_px: 0.1, n_points: 20 }
    }

    #[test]
    fn union_of_truncated_images_under_a_transfer() {
        let t = Transfer { a: [[1.0, 0.0], [0.0, 1.0]], b: [-10.0, 0.0] };
        // Left sees x in [100, 150]; the right view (shifted by −10) sees [95, 170]. The 5 px
        // at the start are within the cap and kept; the 20 px at the end exceed the cap
        // (15% of the shorter, 7.5 px) and are cut there.
        let l = segment([100.0, 50.0], [150.0, 50.0]);
        let r = segment([85.0, 50.0], [160.0, 50.0]);
        let (xl, xr) = union_by_transfer(&t, &l, &r);
        assert!(geom::dist(xl[0], [95.0, 50.0]) < 1e-9, "{xl:?}");
        assert!(geom::dist(xl[1], [157.5, 50.0]) < 1e-9, "{xl:?}");
        assert!(geom::dist(xr[0], [85.0, 50.0]) < 1e-9 && geom::dist(xr[1], [147.5, 50.0]) < 1e-9);
    }
}
