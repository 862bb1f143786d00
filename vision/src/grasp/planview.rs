//! Plan-view geometry for collision tests: features clipped above a horizontal plane and
//! projected onto it, tested against axis-aligned rectangles of the grasp frame.

use nalgebra::{Vector2, Vector3};

/// An axis-aligned rectangle in grasp-frame plan coordinates `(g, h)`, metres: `g` along the
/// jaw axis from the grasp centre, `h` along the edge.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Rect {
    pub g: [f64; 2],
    pub h: [f64; 2],
}

impl Rect {
    fn contains(&self, p: &Vector2<f64>) -> bool {
        p[0] >= self.g[0] && p[0] <= self.g[1] && p[1] >= self.h[0] && p[1] <= self.h[1]
    }

    /// Does the closed segment `a`-`b` meet the closed rectangle? (Liang-Barsky clipping.)
    pub fn meets_segment(&self, a: &Vector2<f64>, b: &Vector2<f64>) -> bool {
        let d = b - a;
        let (mut t0, mut t1) = (0.0f64, 1.0f64);
        for (p, q) in [(-d[0], a[0] - self.g[0]), (d[0], self.g[1] - a[0]), (-d[1], a[1] - self.h[0]), (d[1], self.h[1] - a[1])] {
            if p == 0.0 {
                if q < 0.0 {
                    return false;
                }
            } else {
                let r = q / p;
                if p < 0.0 {
                    t0 = t0.max(r);
                } else {
                    t1 = t1.min(r);
                }
                if t0 > t1 {
                    return false;
                }
            }
        }
        true
    }

    /// Does the closed polygon (any simple polygon, possibly degenerate to a line) meet the
    /// rectangle? Either an edge crosses it, or the rectangle lies inside the polygon.
    pub fn meets_polygon(&self, poly: &[Vector2<f64>]) -> bool {
        match poly.len() {
            0 => false,
            1 => self.contains(&poly[0]),
            n => {
                if (0..n).any(|i| self.meets_segment(&poly[i], &poly[(i + 1) % n])) {
                    return true;
                }
                let centre = Vector2::new(0.5 * (self.g[0] + self.g[1]), 0.5 * (self.h[0] + self.h[1]));
                inside(poly, &centre)
            }
        }
    }
}

/// Crossing-number point-in-polygon test.
fn inside(poly: &[Vector2<f64>], p: &Vector2<f64>) -> bool {
    let mut odd = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                odd = !odd;
            }
        }
    }
    odd
}

/// The part of segment `a`-`b` at or above height `z_min`, or `None`.
pub(crate) fn clip_segment_above(a: &Vector3<f64>, b: &Vector3<f64>, z_min: f64) -> Option<(Vector3<f64>, Vector3<f64>)> {
    match (a[2] >= z_min, b[2] >= z_min) {
        (true, true) => Some((*a, *b)),
        (false, false) => None,
        (a_up, _) => {
            let t = (z_min - a[2]) / (b[2] - a[2]);
            let cut = a + t * (b - a);
            Some(if a_up { (*a, cut) } else { (cut, *b) })
        }
    }
}

/// The part of a planar polygon at or above height `z_min` (Sutherland-Hodgman against one
/// plane), written into `out` (cleared first).
pub(crate) fn clip_polygon_above(poly: &[Vector3<f64>], z_min: f64, out: &mut Vec<Vector3<f64>>) {
    out.clear();
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        let (a_up, b_up) = (a[2] >= z_min, b[2] >= z_min);
        if a_up {
            out.push(a);
        }
        if a_up != b_up {
            let t = (z_min - a[2]) / (b[2] - a[2]);
            out.push(a + t * (b - a));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64) -> Vector2<f64> {
        Vector2::new(x, y)
    }

    #[test]
    fn segment_rectangle_cases() {
        let r = Rect { g: [0.0, 2.0], h: [0.0, 1.0] };
        assert!(r.meets_segment(&v(-1.0, 0.5), &v(3.0, 0.5)), "crossing");
        assert!(r.meets_segment(&v(0.5, 0.5), &v(0.6, 0.6)), "inside");
        assert!(r.meets_segment(&v(-1.0, 1.0), &v(3.0, 1.0)), "along the boundary counts");
        assert!(!r.meets_segment(&v(-1.0, 1.01), &v(3.0, 1.01)), "just above");
        assert!(!r.meets_segment(&v(2.5, -1.0), &v(3.5, 2.0)), "beside");
        assert!(!r.meets_segment(&v(-1.0, 0.0), &v(0.0, -1.0)), "diagonal past the corner");
        assert!(r.meets_segment(&v(-1.0, 1.0), &v(1.0, -1.0)), "diagonal touching the corner");
    }

    #[test]
    fn polygon_rectangle_cases() {
        let r = Rect { g: [0.0, 1.0], h: [0.0, 1.0] };
        let big = [v(-5.0, -5.0), v(5.0, -5.0), v(5.0, 5.0), v(-5.0, 5.0)];
        assert!(r.meets_polygon(&big), "rectangle inside the polygon");
        let apart = [v(2.0, 2.0), v(3.0, 2.0), v(3.0, 3.0)];
        assert!(!r.meets_polygon(&apart));
        let line = [v(0.5, -1.0), v(0.5, 2.0)];
        assert!(r.meets_polygon(&line), "a vertical facet seen from above is a line");
        // A U-shape whose notch holds the rectangle: no contact.
        let u = [v(-1.0, -1.0), v(2.0, -1.0), v(2.0, 2.0), v(1.5, 2.0), v(1.5, -0.5), v(-0.5, -0.5), v(-0.5, 2.0), v(-1.0, 2.0)];
        assert!(!r.meets_polygon(&u));
    }

    #[test]
    fn clipping_above_a_height() {
        let (a, b) = (Vector3::new(0.0, 0.0, 0.0), Vector3::new(1.0, 0.0, 1.0));
        let (p, q) = clip_segment_above(&a, &b, 0.25).unwrap();
        assert!((p - Vector3::new(0.25, 0.0, 0.25)).norm() < 1e-12 && q == b);
        assert!(clip_segment_above(&a, &b, 1.5).is_none());
        let square = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(1.0, 0.0, 0.0), Vector3::new(1.0, 0.0, 1.0), Vector3::new(0.0, 0.0, 1.0)];
        let mut out = Vec::new();
        clip_polygon_above(&square, 0.6, &mut out);
        assert_eq!(out.len(), 4);
        assert!(out.iter().all(|p| p[2] >= 0.6 - 1e-12));
        clip_polygon_above(&square, 2.0, &mut out);
        assert!(out.is_empty());
    }
}
