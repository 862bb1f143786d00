//! The pointing interface (METHOD.md §4): where on the working plane is the operator
//! pointing? Each camera's view of the plane is a 3x3 projective map, fitted from >= 4 points
//! on the plane; the pointing finger's image line in each view is carried onto the plane by
//! that map, and the two plane lines meet at the indicated point. No 3-D reconstruction.
//!
//! Plane coordinates are the robot `x, y` (metres) of points on the working plane (e.g. the
//! calibration cage's lower four corners); the plane's height is whatever those points share.
//!
//! ```
//! use handeye_vision::pointing::{ImageLine, PlaneHomography, Pointing};
//! // Two views of the plane: (x, y) metres -> pixels, here simple projective maps.
//! let plane = [[0.4, -0.1], [0.6, -0.1], [0.6, 0.1], [0.4, 0.1]];
//! let see = |h: [[f64; 3]; 3], p: [f64; 2]| {
//!     let w = h[2][0] * p[0] + h[2][1] * p[1] + h[2][2];
//!     [(h[0][0] * p[0] + h[0][1] * p[1] + h[0][2]) / w, (h[1][0] * p[0] + h[1][1] * p[1] + h[1][2]) / w]
//! };
//! let hl = [[900.0, 150.0, -150.0], [60.0, -800.0, 420.0], [0.2, 0.1, 1.0]];
//! let hr = [[850.0, -200.0, -60.0], [-40.0, -780.0, 400.0], [-0.1, 0.2, 1.0]];
//! let fit = |h| PlaneHomography::fit(&plane, &plane.map(|p| see(h, p))).unwrap();
//! let pointing = Pointing::new(fit(hl), fit(hr));
//! // The finger's image lines: here, images of a plane line through the target (0.5, 0.02)
//! // in the left view and of a different one in the right view.
//! let (target, a, b) = ([0.5, 0.02], [0.45, -0.05], [0.58, 0.0]);
//! let left = ImageLine::through(&see(hl, a), &see(hl, target)).unwrap();
//! let right = ImageLine::through(&see(hr, b), &see(hr, target)).unwrap();
//! let hit = pointing.indicate(&left, &right).unwrap();
//! assert!((hit.point_m[0] - 0.5).abs() < 1e-9 && (hit.point_m[1] - 0.02).abs() < 1e-9);
//! ```

use nalgebra::{Matrix3, SMatrix, SVector, Vector3};
use thiserror::Error;

/// Why a homography could not be fitted or a point not found.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum PointingError {
    #[error("need at least 4 point pairs, got {got}")]
    TooFewPoints { got: usize },
    #[error("plane and image point counts differ ({plane} vs {image})")]
    CountMismatch { plane: usize, image: usize },
    #[error("a coordinate of {what} is not finite")]
    NotFinite { what: &'static str },
    #[error("the fit points are degenerate (three or more in line): the plane's map is undetermined")]
    DegeneratePoints,
    #[error("an image line needs two distinct points")]
    DegenerateLine,
    #[error("the two views' plane lines cross at only {angle_rad:.4} rad: the pointing line is nearly in a plane through both cameras")]
    NearlyParallel { angle_rad: f64 },
}

/// A line `a u + b v + c = 0` in an image, `(a, b)` a unit vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ImageLine(pub Vector3<f64>);

impl ImageLine {
    /// The line through two image points, pixels.
    pub fn through(p: &[f64; 2], q: &[f64; 2]) -> Result<Self, PointingError> {
        if !p.iter().chain(q).all(|x| x.is_finite()) {
            return Err(PointingError::NotFinite { what: "an image line point" });
        }
        let l = Vector3::new(p[0], p[1], 1.0).cross(&Vector3::new(q[0], q[1], 1.0));
        let n = l.xy().norm();
        if n < 1e-9 {
            return Err(PointingError::DegenerateLine);
        }
        Ok(Self(l / n))
    }

    /// The line through `p` along `direction` (e.g. a tracker's origin and axis).
    pub fn along(p: &[f64; 2], direction: &[f64; 2]) -> Result<Self, PointingError> {
        Self::through(p, &[p[0] + direction[0], p[1] + direction[1]])
    }
}

/// The projective map from the working plane to one image: `u ~ H (x, y, 1)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneHomography {
    /// `image_from_plane`, scaled to unit Frobenius norm.
    pub h: Matrix3<f64>,
    /// RMS distance between the fit's image points and the map of their plane points, px.
    pub residual_rms_px: f64,
}

/// Similarity that moves points' centroid to the origin and their mean distance to √2
/// (Hartley's normalisation), so the DLT is well conditioned in any units.
fn normaliser(points: &[[f64; 2]]) -> Result<Matrix3<f64>, PointingError> {
    let n = points.len() as f64;
    let (cx, cy) = points.iter().fold((0.0, 0.0), |(x, y), p| (x + p[0] / n, y + p[1] / n));
    let mean = points.iter().map(|p| ((p[0] - cx).powi(2) + (p[1] - cy).powi(2)).sqrt()).sum::<f64>() / n;
    if mean.is_nan() || mean <= 0.0 {
        return Err(PointingError::DegeneratePoints);
    }
    let s = std::f64::consts::SQRT_2 / mean;
    Ok(Matrix3::new(s, 0.0, -s * cx, 0.0, s, -s * cy, 0.0, 0.0, 1.0))
}

impl PlaneHomography {
    /// Direct linear transform from >= 4 plane points (robot `x, y`, metres) and their images
    /// (pixels), with normalisation. Degenerate sets (three in line among four, all in line)
    /// are refused.
    pub fn fit(plane_m: &[[f64; 2]], image_px: &[[f64; 2]]) -> Result<Self, PointingError> {
        if plane_m.len() != image_px.len() {
            return Err(PointingError::CountMismatch { plane: plane_m.len(), image: image_px.len() });
        }
        if plane_m.len() < 4 {
            return Err(PointingError::TooFewPoints { got: plane_m.len() });
        }
        if !plane_m.iter().flatten().all(|x| x.is_finite()) {
            return Err(PointingError::NotFinite { what: "plane_m" });
        }
        if !image_px.iter().flatten().all(|x| x.is_finite()) {
            return Err(PointingError::NotFinite { what: "image_px" });
        }
        let (tp, ti) = (normaliser(plane_m)?, normaliser(image_px)?);
        // Normal equations of the DLT: two rows per pair, accumulated into a 9x9 matrix.
        let mut ata = SMatrix::<f64, 9, 9>::zeros();
        for (p, q) in plane_m.iter().zip(image_px) {
            let x = tp * Vector3::new(p[0], p[1], 1.0);
            let u = ti * Vector3::new(q[0], q[1], 1.0);
            let (u, v, w) = (u[0], u[1], u[2]);
            let r1 = SVector::<f64, 9>::from_column_slice(&[0.0, 0.0, 0.0, -w * x[0], -w * x[1], -w * x[2], v * x[0], v * x[1], v * x[2]]);
            let r2 = SVector::<f64, 9>::from_column_slice(&[w * x[0], w * x[1], w * x[2], 0.0, 0.0, 0.0, -u * x[0], -u * x[1], -u * x[2]]);
            ata += r1 * r1.transpose() + r2 * r2.transpose();
        }
        let eig = ata.symmetric_eigen();
        let mut order: [usize; 9] = std::array::from_fn(|i| i);
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        // A second (near-)zero eigenvalue: more than one map fits, the points are degenerate.
        let (l2, lmax) = (eig.eigenvalues[order[1]], eig.eigenvalues[order[8]]);
        if l2.is_nan() || l2 <= 1e-9 * lmax {
            return Err(PointingError::DegeneratePoints);
        }
        let h_vec = eig.eigenvectors.column(order[0]);
        let hn = Matrix3::new(h_vec[0], h_vec[1], h_vec[2], h_vec[3], h_vec[4], h_vec[5], h_vec[6], h_vec[7], h_vec[8]);
        let ti_inv = ti.try_inverse().ok_or(PointingError::DegeneratePoints)?;
        let mut h = ti_inv * hn * tp;
        h /= h.norm();
        let mut out = Self { h, residual_rms_px: 0.0 };
        let mut sq = 0.0;
        for (p, q) in plane_m.iter().zip(image_px) {
            let m = out.project(p).ok_or(PointingError::DegeneratePoints)?;
            sq += (m[0] - q[0]).powi(2) + (m[1] - q[1]).powi(2);
        }
        out.residual_rms_px = (sq / plane_m.len() as f64).sqrt();
        Ok(out)
    }

    /// Image of plane point `p`; `None` on the plane's vanishing line.
    pub fn project(&self, p: &[f64; 2]) -> Option<[f64; 2]> {
        let u = self.h * Vector3::new(p[0], p[1], 1.0);
        (u[2].abs() > 1e-15).then(|| [u[0] / u[2], u[1] / u[2]])
    }

    /// The plane line `Hᵀ l` that the image line `l` is the image of.
    pub fn line_to_plane(&self, l: &ImageLine) -> Vector3<f64> {
        self.h.transpose() * l.0
    }
}

/// The indicated point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Indicated {
    /// Robot `x, y` on the working plane, metres.
    pub point_m: [f64; 2],
    /// Angle at which the two plane lines cross, radians: small means ill-conditioned.
    pub crossing_rad: f64,
}

/// Both views' plane maps, ready to intersect pointing lines. Allocation-free per call.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pointing {
    pub left: PlaneHomography,
    pub right: PlaneHomography,
    /// Plane lines crossing at less than this are refused (default 3°).
    pub min_crossing_rad: f64,
}

impl Pointing {
    pub fn new(left: PlaneHomography, right: PlaneHomography) -> Self {
        Self { left, right, min_crossing_rad: 3f64.to_radians() }
    }

    /// Where the pointing line seen as `left` and `right` meets the working plane.
    pub fn indicate(&self, left: &ImageLine, right: &ImageLine) -> Result<Indicated, PointingError> {
        if !left.0.iter().chain(right.0.iter()).all(|x| x.is_finite()) {
            return Err(PointingError::NotFinite { what: "an image line" });
        }
        let (a, b) = (self.left.line_to_plane(left), self.right.line_to_plane(right));
        let (na, nb) = (a.xy(), b.xy());
        let sin = (na[0] * nb[1] - na[1] * nb[0]).abs() / (na.norm() * nb.norm());
        let crossing_rad = sin.min(1.0).asin();
        if crossing_rad.is_nan() || crossing_rad < self.min_crossing_rad {
            return Err(PointingError::NearlyParallel { angle_rad: if crossing_rad.is_finite() { crossing_rad } else { 0.0 } });
        }
        let x = a.cross(&b);
        let point_m = [x[0] / x[2], x[1] / x[2]];
        if !point_m.iter().all(|v| v.is_finite()) {
            return Err(PointingError::NearlyParallel { angle_rad: crossing_rad });
        }
        Ok(Indicated { point_m, crossing_rad })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;
    use crate::servo::testcam::{cage, Rig};
    use nalgebra::Vector3;

    const PLANE_Z_M: f64 = 0.05;

    /// Homographies fitted to the cage's lower four corners, as the daemon will.
    fn pointing(rig: &Rig) -> Pointing {
        let lower: Vec<Vector3<f64>> = cage().into_iter().filter(|p| p.z < 0.1).collect();
        let plane: Vec<[f64; 2]> = lower.iter().map(|p| [p.x, p.y]).collect();
        let fit = |cam: &crate::servo::testcam::PinholeCamera| {
            let image: Vec<[f64; 2]> = lower.iter().map(|p| cam.project(p)).collect();
            PlaneHomography::fit(&plane, &image).unwrap()
        };
        Pointing::new(fit(&rig.left), fit(&rig.right))
    }

    /// The images of a finger: two points on the 3-D pointing line, in each view.
    fn finger_lines(rig: &Rig, hand: Vector3<f64>, target: Vector3<f64>) -> (ImageLine, ImageLine) {
        let tip = hand + 0.15 * (target - hand).normalize();
        let (h, t) = (rig.project(&hand), rig.project(&tip));
        (ImageLine::through(&h.left, &t.left).unwrap(), ImageLine::through(&h.right, &t.right).unwrap())
    }

    #[test]
    fn fitted_maps_are_exact_for_perspective_cameras() {
        let rig = Rig::standard(1500.0);
        let p = pointing(&rig);
        assert!(p.left.residual_rms_px < 1e-9 && p.right.residual_rms_px < 1e-9);
        // Any other point of the plane maps exactly, even outside the fit points.
        for q in [Vector3::new(0.47, 0.03, PLANE_Z_M), Vector3::new(0.7, -0.2, PLANE_Z_M)] {
            let m = p.left.project(&[q.x, q.y]).unwrap();
            let truth = rig.left.project(&q);
            assert!((m[0] - truth[0]).abs() < 1e-8 && (m[1] - truth[1]).abs() < 1e-8, "{m:?} vs {truth:?}");
        }
    }

    #[test]
    fn finds_the_indicated_point_without_reconstruction() {
        let rig = Rig::standard(1500.0);
        let p = pointing(&rig);
        let mut rng = SplitMix64::new(4);
        let mut found = 0;
        for _ in 0..20 {
            let target = Vector3::new(rng.range(0.35, 0.65), rng.range(-0.15, 0.15), PLANE_Z_M);
            // The hand is above and to the side of the workspace, pointing down at the target.
            let hand = Vector3::new(rng.range(0.3, 0.9), rng.range(-0.5, 0.5), rng.range(0.3, 0.5));
            let (l, r) = finger_lines(&rig, hand, target);
            match p.indicate(&l, &r) {
                Ok(hit) => {
                    let err = ((hit.point_m[0] - target.x).powi(2) + (hit.point_m[1] - target.y).powi(2)).sqrt();
                    assert!(err < 1e-9, "{err} m off for hand {hand:?} -> {target:?}");
                    found += 1;
                }
                // Lines close to a plane through both cameras are refused, never answered badly.
                Err(PointingError::NearlyParallel { angle_rad }) => assert!(angle_rad < p.min_crossing_rad),
                Err(e) => panic!("{e}"),
            }
        }
        assert!(found >= 15, "only {found} of 20 pointing lines were usable");
    }

    #[test]
    fn image_noise_of_a_third_of_a_pixel_costs_millimetres() {
        // ±0.3 px on the finger's two image points (~100 px apart), as a tracker would give.
        // The hand points from the cameras' side, across the baseline: well conditioned.
        let rig = Rig::standard(1500.0);
        let p = pointing(&rig);
        let mut rng = SplitMix64::new(9);
        let target = Vector3::new(0.5, 0.02, PLANE_Z_M);
        let hand = Vector3::new(0.8, 0.05, 0.35);
        let tip = hand + 0.15 * (target - hand).normalize();
        let mut worst: f64 = 0.0;
        let mut crossing = 0.0;
        for _ in 0..50 {
            let mut n = |x: [f64; 2]| [x[0] + rng.range(-0.3, 0.3), x[1] + rng.range(-0.3, 0.3)];
            let (h, t) = (rig.project(&hand), rig.project(&tip));
            let l = ImageLine::through(&n(h.left), &n(t.left)).unwrap();
            let r = ImageLine::through(&n(h.right), &n(t.right)).unwrap();
            let hit = p.indicate(&l, &r).unwrap();
            crossing = hit.crossing_rad;
            worst = worst.max(((hit.point_m[0] - target.x).powi(2) + (hit.point_m[1] - target.y).powi(2)).sqrt());
        }
        // The thesis's system was accurate to ~1 cm over a 40 cm workspace.
        assert!(worst < 0.005, "worst error {worst} m, lines crossing at {crossing} rad");
    }

    #[test]
    fn pointing_in_a_plane_through_both_cameras_is_refused() {
        let rig = Rig::standard(1500.0);
        let p = pointing(&rig);
        let target = Vector3::new(0.5, 0.0, PLANE_Z_M);
        // A hand in the plane through the target and both camera centres.
        let hand = target + 0.2 * (rig.left.centre_m - target).normalize() + 0.1 * (rig.right.centre_m - target).normalize();
        let (l, r) = finger_lines(&rig, hand, target);
        assert!(matches!(p.indicate(&l, &r), Err(PointingError::NearlyParallel { angle_rad }) if angle_rad < 1e-6));
    }

    #[test]
    fn degenerate_and_bad_fits_are_errors() {
        let img = [[10.0, 10.0], [200.0, 15.0], [190.0, 220.0], [20.0, 200.0], [100.0, 100.0]];
        let line = [[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [0.3, 0.0]];
        assert_eq!(PlaneHomography::fit(&line, &img[..4]), Err(PointingError::DegeneratePoints));
        let three_in_line = [[0.0, 0.0], [0.1, 0.0], [0.2, 0.0], [0.1, 0.1]];
        assert_eq!(PlaneHomography::fit(&three_in_line, &img[..4]), Err(PointingError::DegeneratePoints));
        let square = [[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]];
        assert_eq!(PlaneHomography::fit(&square[..3], &img[..3]), Err(PointingError::TooFewPoints { got: 3 }));
        assert_eq!(PlaneHomography::fit(&square, &img), Err(PointingError::CountMismatch { plane: 4, image: 5 }));
        let mut nan = img;
        nan[2][1] = f64::NAN;
        assert_eq!(PlaneHomography::fit(&square, &nan[..4]), Err(PointingError::NotFinite { what: "image_px" }));
        assert!(PlaneHomography::fit(&square, &img[..4]).is_ok());
        assert_eq!(ImageLine::through(&[1.0, 2.0], &[1.0, 2.0]), Err(PointingError::DegenerateLine));
    }
}
