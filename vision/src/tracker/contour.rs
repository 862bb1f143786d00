//! The contour template: a polygon in affine coordinates `(s, t)` and the sampling points
//! spaced evenly around it.

use nalgebra::Vector2;
use thiserror::Error;

use super::frame::TemplateFrame;

/// Why a polygon cannot become a tracker template.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum TemplateError {
    #[error("a polygon needs at least 3 corners, got {got}")]
    TooFewCorners { got: usize },
    #[error("corner {index} is not finite")]
    NotFinite { index: usize },
    #[error("the polygon is degenerate: {0}")]
    Degenerate(&'static str),
    #[error("the polygon's sides {a} and {b} cross each other")]
    SelfIntersecting { a: usize, b: usize },
    #[error("need at least {min} sampling points, asked for {got}")]
    TooFewPoints { min: usize, got: usize },
}

/// Fewest sampling points a template may have: the fit has 6 unknowns.
pub const MIN_POINTS: usize = 12;

/// One side of the polygon and its run of sampling points.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TemplateEdge {
    /// Index of its first point in [`Template::points`].
    pub first: usize,
    /// Number of points on this side (may be 0 for a very short side).
    pub count: usize,
    /// Template coordinates of the first point.
    pub start: Vector2<f64>,
    /// Template-coordinate step from one point to the next.
    pub step: Vector2<f64>,
    /// Direction of the side (corner `j` to `j+1`) in template coordinates.
    pub tangent: Vector2<f64>,
}

/// A polygon held in affine template coordinates with its sampling points.
///
/// Points are spaced evenly along the perimeter as the polygon looked when the template was
/// made, and kept `corner_margin` (a fraction of each side) away from the corners: close to a
/// corner the normal search would find the neighbouring side.
#[derive(Debug, Clone)]
pub struct Template {
    pub(crate) corners: Vec<Vector2<f64>>,
    pub(crate) edges: Vec<TemplateEdge>,
    pub(crate) points: Vec<Vector2<f64>>,
    /// Sign of the polygon's signed area in template coordinates: with the frame's
    /// determinant it says which side of each edge is outside.
    pub(crate) orientation: f64,
}

impl Template {
    /// A template from a polygon given in image pixels. Returns the template and the affine
    /// frame that places it where it was given.
    ///
    /// The frame's origin is the centroid of the sampling points (this decouples translation
    /// from deformation in the fit, as the thesis advises); `e1` runs from corner 0 to corner
    /// 1 and `e2` from corner 0 to the last corner, so a parallelogram's corners sit at
    /// `(±½, ±½)`. When those two sides are nearly parallel the polygon's principal axes (one
    /// standard deviation long) are used instead.
    pub fn from_polygon_px(
        corners_px: &[[f64; 2]],
        n_points: usize,
        corner_margin: f64,
    ) -> Result<(Self, TemplateFrame), TemplateError> {
        let mut template = Self::with_capacity(corners_px.len(), n_points);
        let frame = template.rebuild_from_polygon_px(corners_px, n_points, corner_margin)?;
        Ok((template, frame))
    }

    /// A template from corners given in template coordinates, with the frame in which its
    /// points are to be spaced evenly (e.g. the gripper's known face in its own frame).
    pub fn from_template_corners(
        corners_st: &[[f64; 2]],
        reference: &TemplateFrame,
        n_points: usize,
        corner_margin: f64,
    ) -> Result<Self, TemplateError> {
        let px: Vec<[f64; 2]> =
            corners_st.iter().map(|c| reference.image_from_template(Vector2::new(c[0], c[1])).into()).collect();
        let mut template = Self::with_capacity(corners_st.len(), n_points);
        template.rebuild(&px, reference, n_points, corner_margin)?;
        Ok(template)
    }

    pub(crate) fn with_capacity(n_corners: usize, n_points: usize) -> Self {
        Self {
            corners: Vec::with_capacity(n_corners),
            edges: Vec::with_capacity(n_corners),
            points: Vec::with_capacity(n_points),
            orientation: 1.0,
        }
    }

    /// Rebuilds this template in place from an image polygon (no allocation when the corner and
    /// point counts fit the existing capacity) and returns the frame that places it.
    pub(crate) fn rebuild_from_polygon_px(
        &mut self,
        corners_px: &[[f64; 2]],
        n_points: usize,
        corner_margin: f64,
    ) -> Result<TemplateFrame, TemplateError> {
        validate_polygon(corners_px)?;
        let n = corners_px.len();
        let c = |i: usize| Vector2::new(corners_px[i % n][0], corners_px[i % n][1]);
        // Centroid of the sampling points = perimeter centroid of the inner part of each side
        // (the margins are symmetric, so each side contributes its midpoint times its length).
        let (mut sum, mut perimeter) = (Vector2::zeros(), 0.0);
        for j in 0..n {
            let len = (c(j + 1) - c(j)).norm();
            sum += (c(j) + c(j + 1)) * 0.5 * len;
            perimeter += len;
        }
        let origin = sum / perimeter;
        let (mut e1, mut e2) = (c(1) - c(0), c(n - 1) - c(0));
        let sin = (e1.x * e2.y - e1.y * e2.x).abs() / (e1.norm() * e2.norm());
        if sin < 0.2 {
            (e1, e2) = principal_axes(corners_px);
        }
        let frame = TemplateFrame::new(origin, e1, e2);
        self.rebuild(corners_px, &frame, n_points, corner_margin)?;
        Ok(frame)
    }

    /// Rebuilds from an image polygon and the frame to express it in.
    fn rebuild(
        &mut self,
        corners_px: &[[f64; 2]],
        frame: &TemplateFrame,
        n_points: usize,
        corner_margin: f64,
    ) -> Result<(), TemplateError> {
        validate_polygon(corners_px)?;
        if n_points < MIN_POINTS {
            return Err(TemplateError::TooFewPoints { min: MIN_POINTS, got: n_points });
        }
        if !frame.is_finite() || frame.anisotropy() > 1e6 {
            return Err(TemplateError::Degenerate("the reference frame is singular"));
        }
        let n = corners_px.len();
        let margin = corner_margin.clamp(0.0, 0.45);
        self.corners.clear();
        for c in corners_px {
            let st = frame.template_from_image(Vector2::new(c[0], c[1])).ok_or(TemplateError::Degenerate("singular frame"))?;
            self.corners.push(st);
        }
        // Split the points between the sides in proportion to their image length (largest
        // remainder), so spacing is even along the perimeter.
        let len = |j: usize| {
            let a = Vector2::new(corners_px[j][0], corners_px[j][1]);
            let b = Vector2::new(corners_px[(j + 1) % n][0], corners_px[(j + 1) % n][1]);
            (b - a).norm()
        };
        let perimeter: f64 = (0..n).map(len).sum();
        self.edges.clear();
        let mut assigned = 0;
        for j in 0..n {
            let ideal = n_points as f64 * len(j) / perimeter;
            let count = ideal.floor() as usize;
            assigned += count;
            self.edges.push(TemplateEdge {
                first: 0,
                count,
                start: Vector2::zeros(),
                step: Vector2::zeros(),
                tangent: Vector2::zeros(),
            });
        }
        while assigned < n_points {
            // The side furthest below its ideal share gets the next point (n is small).
            let mut best = 0;
            let mut best_deficit = f64::NEG_INFINITY;
            for j in 0..n {
                let deficit = n_points as f64 * len(j) / perimeter - self.edges[j].count as f64;
                if deficit > best_deficit {
                    best_deficit = deficit;
                    best = j;
                }
            }
            self.edges[best].count += 1;
            assigned += 1;
        }
        self.points.clear();
        for j in 0..n {
            let a = self.corners[j];
            let b = self.corners[(j + 1) % n];
            let d = b - a;
            let e = &mut self.edges[j];
            e.first = self.points.len();
            e.tangent = d;
            e.step = d * ((1.0 - 2.0 * margin) / e.count.max(1) as f64);
            e.start = a + d * margin + e.step * 0.5;
            for k in 0..e.count {
                self.points.push(e.start + e.step * k as f64);
            }
        }
        let area: f64 = (0..n)
            .map(|j| {
                let (a, b) = (self.corners[j], self.corners[(j + 1) % n]);
                a.x * b.y - a.y * b.x
            })
            .sum();
        self.orientation = area.signum();
        Ok(())
    }

    /// Corners in template coordinates `(s, t)`.
    pub fn corners(&self) -> &[Vector2<f64>] {
        &self.corners
    }

    /// Sampling points in template coordinates `(s, t)`, grouped by side (side `j` runs from
    /// corner `j` to corner `j + 1`).
    pub fn points(&self) -> &[Vector2<f64>] {
        &self.points
    }

    /// Number of polygon sides (= corners).
    pub fn sides(&self) -> usize {
        self.corners.len()
    }
}

/// Checks a polygon: >= 3 finite corners, non-zero area, no two sides crossing.
pub(crate) fn validate_polygon(corners: &[[f64; 2]]) -> Result<(), TemplateError> {
    let n = corners.len();
    if n < 3 {
        return Err(TemplateError::TooFewCorners { got: n });
    }
    if let Some(index) = corners.iter().position(|c| !(c[0].is_finite() && c[1].is_finite())) {
        return Err(TemplateError::NotFinite { index });
    }
    let v = |i: usize| Vector2::new(corners[i % n][0], corners[i % n][1]);
    let perimeter: f64 = (0..n).map(|j| (v(j + 1) - v(j)).norm()).sum();
    let area = 0.5 * (0..n).map(|j| v(j).x * v(j + 1).y - v(j).y * v(j + 1).x).sum::<f64>();
    // Area relative to a square of the same perimeter: a sliver is no surface to track.
    if perimeter.is_nan() || perimeter <= 1e-9 || area.abs() < 1e-3 * (perimeter / 4.0).powi(2) {
        return Err(TemplateError::Degenerate("zero area or collinear corners"));
    }
    if (0..n).any(|j| (v(j + 1) - v(j)).norm() < 1e-9) {
        return Err(TemplateError::Degenerate("two consecutive corners coincide"));
    }
    for a in 0..n {
        for b in a + 2..n {
            if a == 0 && b == n - 1 {
                continue; // neighbours through corner 0
            }
            if segments_cross(v(a), v(a + 1), v(b), v(b + 1)) {
                return Err(TemplateError::SelfIntersecting { a, b });
            }
        }
    }
    Ok(())
}

fn segments_cross(p1: Vector2<f64>, p2: Vector2<f64>, q1: Vector2<f64>, q2: Vector2<f64>) -> bool {
    let cross = |o: Vector2<f64>, a: Vector2<f64>, b: Vector2<f64>| (a - o).x * (b - o).y - (a - o).y * (b - o).x;
    let d1 = cross(q1, q2, p1);
    let d2 = cross(q1, q2, p2);
    let d3 = cross(p1, p2, q1);
    let d4 = cross(p1, p2, q2);
    (d1 * d2 < 0.0) && (d3 * d4 < 0.0)
}

/// Principal axes of the corner set, each one standard deviation long.
fn principal_axes(corners: &[[f64; 2]]) -> (Vector2<f64>, Vector2<f64>) {
    let n = corners.len() as f64;
    let mean = corners.iter().fold(Vector2::zeros(), |m, c| m + Vector2::new(c[0], c[1])) / n;
    let (mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0);
    for c in corners {
        let d = Vector2::new(c[0], c[1]) - mean;
        sxx += d.x * d.x;
        sxy += d.x * d.y;
        syy += d.y * d.y;
    }
    let (sxx, sxy, syy) = (sxx / n, sxy / n, syy / n);
    let tr = sxx + syy;
    let disc = ((sxx - syy).powi(2) + 4.0 * sxy * sxy).sqrt();
    let (l1, l2) = ((tr + disc) / 2.0, ((tr - disc) / 2.0).max(0.0));
    let angle = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    let u = Vector2::new(angle.cos(), angle.sin());
    (u * l1.sqrt(), Vector2::new(-u.y, u.x) * l2.sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    const SQUARE: [[f64; 2]; 4] = [[100.0, 100.0], [200.0, 100.0], [200.0, 200.0], [100.0, 200.0]];

    #[test]
    fn polygon_template_reproduces_the_corners_and_spaces_points_evenly() {
        let (t, frame) = Template::from_polygon_px(&SQUARE, 100, 0.05).unwrap();
        assert_eq!(t.points().len(), 100);
        for (st, px) in t.corners().iter().zip(SQUARE) {
            let x = frame.image_from_template(*st);
            assert!((x - Vector2::new(px[0], px[1])).norm() < 1e-9);
        }
        // Square: 25 per side, origin at the centre, corners at (±1/2, ±1/2).
        assert!(t.edges.iter().all(|e| e.count == 25));
        assert!((frame.origin - Vector2::new(150.0, 150.0)).norm() < 1e-9);
        assert!((t.corners()[2] - Vector2::new(0.5, 0.5)).norm() < 1e-12);
        // Points keep 5 % of each side clear of the corners, and are evenly spaced.
        let p: Vec<Vector2<f64>> = t.points().iter().map(|st| frame.image_from_template(*st)).collect();
        assert!((p[0] - Vector2::new(105.0 + 1.8, 100.0)).norm() < 1e-9);
        for k in 1..25 {
            assert!(((p[k] - p[k - 1]).norm() - 3.6).abs() < 1e-9);
        }
    }

    #[test]
    fn unequal_sides_share_points_by_length() {
        let tri = [[0.0, 0.0], [300.0, 0.0], [0.0, 100.0]];
        let (t, _) = Template::from_polygon_px(&tri, 100, 0.0).unwrap();
        let counts: Vec<usize> = t.edges.iter().map(|e| e.count).collect();
        let perim = 300.0 + 100.0 + 10f64.sqrt() * 100.0;
        assert_eq!(counts.iter().sum::<usize>(), 100);
        assert_eq!(counts[0], (100.0 * 300.0 / perim).round() as usize);
        assert_eq!(counts[2], (100.0 * 100.0 / perim).round() as usize);
    }

    #[test]
    fn bad_polygons_are_rejected_with_a_reason() {
        assert_eq!(Template::from_polygon_px(&SQUARE[..2], 100, 0.05).unwrap_err(), TemplateError::TooFewCorners { got: 2 });
        let nan = [[0.0, 0.0], [f64::NAN, 1.0], [1.0, 1.0]];
        assert_eq!(Template::from_polygon_px(&nan, 100, 0.05).unwrap_err(), TemplateError::NotFinite { index: 1 });
        let line = [[0.0, 0.0], [10.0, 10.0], [20.0, 20.0]];
        assert!(matches!(Template::from_polygon_px(&line, 100, 0.05), Err(TemplateError::Degenerate(_))));
        let bowtie = [[0.0, 0.0], [100.0, 100.0], [100.0, 0.0], [0.0, 60.0]];
        assert!(matches!(Template::from_polygon_px(&bowtie, 100, 0.05), Err(TemplateError::SelfIntersecting { .. })));
        assert!(matches!(Template::from_polygon_px(&SQUARE, 5, 0.05), Err(TemplateError::TooFewPoints { .. })));
    }

    #[test]
    fn nearly_parallel_first_sides_fall_back_to_principal_axes() {
        // A hexagon-like shape whose sides at corner 0 are almost collinear.
        let poly = [[0.0, 0.0], [50.0, -2.0], [100.0, 20.0], [50.0, 60.0], [-50.0, 60.0], [-50.0, 2.0]];
        let (t, frame) = Template::from_polygon_px(&poly, 60, 0.05).unwrap();
        assert!(frame.anisotropy() < 10.0);
        for (st, px) in t.corners().iter().zip(poly) {
            assert!((frame.image_from_template(*st) - Vector2::new(px[0], px[1])).norm() < 1e-9);
        }
    }
}
