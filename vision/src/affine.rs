//! Affine stereo: each camera modelled as an affine map of robot space (weak perspective).
//!
//! `w = M X + c`, with `w = (u, v, u', v')` the left and right image coordinates of a point
//! `X` in the robot frame (METHOD.md §1). The model is fitted from a few robot positions and
//! their tracked image positions (self-calibration), needs no camera parameters, and gives:
//! reconstruction (`X = M⁺ (w − c)`), the linear epipolar constraint (`n·w + n0 = 0`), and the
//! disparity limits of the workspace.
//!
//! ```
//! use handeye_vision::affine::AffineStereo;
//! use nalgebra::{Matrix4x3, Vector3, Vector4};
//! // Two affine cameras, seen from a little left and a little right.
//! let m = Matrix4x3::new(800.0, 0.0, 150.0,   0.0, -20.0, -800.0,
//!                        780.0, -60.0, -140.0,  0.0, -25.0, -800.0);
//! let c = Vector4::new(320.0, 240.0, 330.0, 238.0);
//! // A cage of eight points (metres) and what the cameras see of them.
//! let cage: Vec<Vector3<f64>> = (0..8)
//!     .map(|i| Vector3::new(0.3 + 0.1 * (i & 1) as f64, -0.05 + 0.1 * ((i >> 1) & 1) as f64, 0.05 + 0.1 * (i >> 2) as f64))
//!     .collect();
//! let seen: Vec<[f64; 4]> = cage.iter().map(|x| (m * x + c).into()).collect();
//! let model = AffineStereo::fit(&cage, &seen).unwrap();
//! let x = model.reconstruct(&seen[5]);
//! assert!((x - cage[5]).norm() < 1e-9);
//! assert!(model.epipolar().residual_px(&seen[3]).abs() < 1e-9);
//! ```

use nalgebra::{Matrix3, Matrix4, Matrix4x3, Vector2, Vector3, Vector4};
use thiserror::Error;

/// Why a model or constraint could not be fitted.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FitError {
    #[error("need at least {needed} correspondences, got {got}")]
    TooFewPoints { needed: usize, got: usize },
    #[error("robot and image point counts differ ({robot} vs {image})")]
    CountMismatch { robot: usize, image: usize },
    #[error("the points are degenerate (coplanar or collinear): {0}")]
    Degenerate(&'static str),
    #[error("a coordinate is not finite")]
    NotFinite,
}

/// The linear epipolar constraint `n·w + n0 = 0` between the four image coordinates of a
/// correspondence, `|n| = 1`, so the residual is a distance in pixels in `(u, v, u', v')`
/// space. All epipolar lines in one view are parallel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpipolarConstraint {
    /// Unit normal in `(u, v, u', v')` space.
    pub n: Vector4<f64>,
    pub n0: f64,
}

impl EpipolarConstraint {
    /// Fits the constraint to `>= 4` correspondences by orthogonal regression: the eigenvector
    /// of the smallest eigenvalue of the scatter matrix of the centred points.
    pub fn fit(points: &[[f64; 4]]) -> Result<Self, FitError> {
        if points.len() < 4 {
            return Err(FitError::TooFewPoints { needed: 4, got: points.len() });
        }
        if points.iter().flatten().any(|x| !x.is_finite()) {
            return Err(FitError::NotFinite);
        }
        let mean = points.iter().fold(Vector4::zeros(), |acc, p| acc + Vector4::from(*p)) / points.len() as f64;
        let mut scatter = Matrix4::zeros();
        for p in points {
            let d = Vector4::from(*p) - mean;
            scatter += d * d.transpose();
        }
        let eig = scatter.symmetric_eigen();
        let mut order = [0usize, 1, 2, 3];
        order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
        // The points must span at least three dimensions of w-space, or the normal is not
        // determined (e.g. all correspondences on one line).
        let (l1, l3) = (eig.eigenvalues[order[1]], eig.eigenvalues[order[3]]);
        if l3 <= 0.0 || l1 <= 1e-12 * l3 {
            return Err(FitError::Degenerate("points span fewer than three dimensions"));
        }
        let n: Vector4<f64> = eig.eigenvectors.column(order[0]).into_owned().normalize();
        Ok(Self::from_normal(n, -n.dot(&mean)))
    }

    /// A constraint from a (not necessarily unit) normal and offset; normalised, sign fixed so
    /// that the right-image `u'` coefficient is non-negative (so two fits can be compared).
    pub fn from_normal(n: Vector4<f64>, n0: f64) -> Self {
        let norm = n.norm();
        let (mut n, mut n0) = (n / norm, n0 / norm);
        if n[2] < 0.0 {
            n = -n;
            n0 = -n0;
        }
        Self { n, n0 }
    }

    /// Signed residual of a correspondence, in pixels of `(u, v, u', v')` space.
    pub fn residual_px(&self, w: &[f64; 4]) -> f64 {
        self.n.dot(&Vector4::from(*w)) + self.n0
    }

    /// Unit direction of the epipolar lines in the left image.
    pub fn left_direction(&self) -> Vector2<f64> {
        // For a fixed right point, left points satisfy n_l·x = const: lines along perp(n_l).
        Vector2::new(-self.n[1], self.n[0]).normalize()
    }

    /// Unit direction of the epipolar lines in the right image.
    pub fn right_direction(&self) -> Vector2<f64> {
        Vector2::new(-self.n[3], self.n[2]).normalize()
    }

    /// The epipolar line in the right image of left point `x`: returns `(a, b)` with the line
    /// `a·x' + b = 0` (`a` a unit 2-vector), or `None` if `n` has no right-image component.
    pub fn right_line(&self, x: &[f64; 2]) -> Option<(Vector2<f64>, f64)> {
        let a = Vector2::new(self.n[2], self.n[3]);
        let len = a.norm();
        (len > 1e-12).then(|| (a / len, (self.n[0] * x[0] + self.n[1] * x[1] + self.n0) / len))
    }

    /// Distance in pixels of right point `xr` from the epipolar line of left point `xl`.
    pub fn right_distance_px(&self, xl: &[f64; 2], xr: &[f64; 2]) -> Option<f64> {
        self.right_line(xl).map(|(a, b)| a.dot(&Vector2::new(xr[0], xr[1])) + b)
    }
}

/// The affine stereo model `w = M X + c` (METHOD.md §1), fitted by self-calibration.
#[derive(Debug, Clone, PartialEq)]
pub struct AffineStereo {
    /// Rows: `u`, `v`, `u'`, `v'` as linear functions of robot coordinates (pixels per metre).
    pub m: Matrix4x3<f64>,
    /// Image coordinates of the robot origin, pixels.
    pub c: Vector4<f64>,
    /// RMS residual of the fit over all coordinates of the calibration points, pixels. Large
    /// values mean the scene is far from weak perspective.
    pub residual_rms_px: f64,
    /// Smallest and largest horizontal disparity `u' − u` seen over the calibration points,
    /// pixels: the workspace's disparity limits.
    pub disparity_range_px: [f64; 2],
}

impl AffineStereo {
    /// Fits the model to `>= 4` non-coplanar robot points `robot_m` and their images `image_px`.
    /// Each of the four rows is an independent linear least-squares fit; the data are centred
    /// and scaled first for conditioning.
    pub fn fit(robot_m: &[Vector3<f64>], image_px: &[[f64; 4]]) -> Result<Self, FitError> {
        if robot_m.len() != image_px.len() {
            return Err(FitError::CountMismatch { robot: robot_m.len(), image: image_px.len() });
        }
        let n = robot_m.len();
        if n < 4 {
            return Err(FitError::TooFewPoints { needed: 4, got: n });
        }
        if robot_m.iter().any(|x| !x.iter().all(|v| v.is_finite())) || image_px.iter().flatten().any(|v| !v.is_finite()) {
            return Err(FitError::NotFinite);
        }
        let xm = robot_m.iter().fold(Vector3::zeros(), |a, x| a + x) / n as f64;
        let wm = image_px.iter().fold(Vector4::zeros(), |a, w| a + Vector4::from(*w)) / n as f64;
        let scale = (robot_m.iter().map(|x| (x - xm).norm_squared()).sum::<f64>() / n as f64).sqrt();
        if scale <= 0.0 {
            return Err(FitError::Degenerate("all robot points coincide"));
        }
        // Normal equations on the centred, scaled robot points: (Σ d dᵀ) mᵀ = Σ d (w − w̄)ᵀ.
        let mut xtx = Matrix3::zeros();
        let mut xtw = nalgebra::Matrix3x4::zeros();
        for (x, w) in robot_m.iter().zip(image_px) {
            let d = (x - xm) / scale;
            xtx += d * d.transpose();
            xtw += d * (Vector4::from(*w) - wm).transpose();
        }
        let eig = xtx.symmetric_eigenvalues();
        if eig.min() <= 1e-9 * eig.max() {
            return Err(FitError::Degenerate("robot points are coplanar or collinear"));
        }
        let inv = xtx.try_inverse().ok_or(FitError::Degenerate("singular normal equations"))?;
        let m: Matrix4x3<f64> = (inv * xtw).transpose() / scale;
        let c = wm - m * xm;
        let mut sq = 0.0;
        let mut disparity_range_px = [f64::INFINITY, f64::NEG_INFINITY];
        for (x, w) in robot_m.iter().zip(image_px) {
            sq += (m * x + c - Vector4::from(*w)).norm_squared();
            let d = w[2] - w[0];
            disparity_range_px = [disparity_range_px[0].min(d), disparity_range_px[1].max(d)];
        }
        let residual_rms_px = (sq / (4 * n) as f64).sqrt();
        Ok(Self { m, c, residual_rms_px, disparity_range_px })
    }

    /// Image coordinates `(u, v, u', v')` of robot point `x_m`.
    pub fn project(&self, x_m: &Vector3<f64>) -> [f64; 4] {
        (self.m * x_m + self.c).into()
    }

    /// `M⁺ = (MᵀM)⁻¹Mᵀ`, the least-squares inverse of `M`.
    pub fn pseudo_inverse(&self) -> nalgebra::Matrix3x4<f64> {
        let mtm = self.m.transpose() * self.m;
        // fit() guarantees full column rank, so MᵀM is invertible.
        mtm.try_inverse().unwrap_or_else(Matrix3::zeros) * self.m.transpose()
    }

    /// Least-squares robot point for image coordinates `w`.
    pub fn reconstruct(&self, w: &[f64; 4]) -> Vector3<f64> {
        self.pseudo_inverse() * (Vector4::from(*w) - self.c)
    }

    /// Robot-frame direction of an image displacement pair `(e, e')` (left, right).
    pub fn reconstruct_direction(&self, e_left: &[f64; 2], e_right: &[f64; 2]) -> Vector3<f64> {
        self.pseudo_inverse() * Vector4::new(e_left[0], e_left[1], e_right[0], e_right[1])
    }

    /// Unit direction from the workspace towards the cameras (the mean of both cameras'),
    /// robot frame. Each affine camera looks along `r_u × r_v` (its two rows), for images with
    /// `u` right and `v` down; the grasp planner uses this to tell a facet's front from its back.
    pub fn toward_cameras(&self) -> Vector3<f64> {
        let look = |r: usize| {
            let (ru, rv) = (self.m.row(r).transpose(), self.m.row(r + 1).transpose());
            ru.cross(&rv).normalize()
        };
        -(look(0) + look(2)).normalize()
    }

    /// The epipolar constraint implied by the model: `n` is the left null vector of `M`.
    pub fn epipolar(&self) -> EpipolarConstraint {
        let full = Matrix4::from_columns(&[
            self.m.column(0).into_owned(),
            self.m.column(1).into_owned(),
            self.m.column(2).into_owned(),
            Vector4::zeros(),
        ]);
        // The null vector of Mᵀ is the eigenvector of M Mᵀ with the smallest eigenvalue.
        let eig = (full * full.transpose()).symmetric_eigen();
        let i = eig.eigenvalues.imin();
        let n: Vector4<f64> = eig.eigenvectors.column(i).into_owned();
        EpipolarConstraint::from_normal(n, -n.dot(&self.c))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cameras() -> (Matrix4x3<f64>, Vector4<f64>) {
        let m = Matrix4x3::new(
            800.0, 0.0, 150.0, 0.0, -20.0, -800.0, //
            780.0, -60.0, -140.0, 0.0, -25.0, -800.0,
        );
        (m, Vector4::new(320.0, 240.0, 330.0, 238.0))
    }

    fn cage() -> Vec<Vector3<f64>> {
        (0..8)
            .map(|i| Vector3::new(0.3 + 0.1 * (i & 1) as f64, -0.05 + 0.1 * ((i >> 1) & 1) as f64, 0.05 + 0.1 * (i >> 2) as f64))
            .collect()
    }

    #[test]
    fn fit_recovers_model_and_epipolar_constraint_holds_for_new_points() {
        let (m, c) = cameras();
        let seen: Vec<[f64; 4]> = cage().iter().map(|x| (m * x + c).into()).collect();
        let model = AffineStereo::fit(&cage(), &seen).unwrap();
        assert!((model.m - m).norm() < 1e-6 && (model.c - c).norm() < 1e-6);
        assert!(model.residual_rms_px < 1e-9);
        let ep = model.epipolar();
        let w: [f64; 4] = (m * Vector3::new(0.42, 0.01, 0.2) + c).into();
        assert!(ep.residual_px(&w).abs() < 1e-9);
        // A point off the constraint: shift u' by 5 px → residual n[2] * 5.
        let off = [w[0], w[1], w[2] + 5.0, w[3]];
        assert!((ep.residual_px(&off) - 5.0 * ep.n[2]).abs() < 1e-9);
    }

    #[test]
    fn orthogonal_regression_matches_model_constraint_under_noise() {
        let (m, c) = cameras();
        let model = AffineStereo::fit(&cage(), &cage().iter().map(|x| (m * x + c).into()).collect::<Vec<_>>()).unwrap();
        // Deterministic "noise" of +-0.3 px.
        let pts: Vec<[f64; 4]> = cage()
            .iter()
            .enumerate()
            .map(|(i, x)| {
                let w = m * x + c;
                let e = |k: usize| 0.3 * (((i * 7 + k * 3) % 5) as f64 - 2.0) / 2.0;
                [w[0] + e(0), w[1] + e(1), w[2] + e(2), w[3] + e(3)]
            })
            .collect();
        let fitted = EpipolarConstraint::fit(&pts).unwrap();
        let truth = model.epipolar();
        // What matters to the matcher: true correspondences anywhere in the workspace stay
        // within a fraction of a pixel of the fitted constraint.
        for i in 0..27 {
            let x = Vector3::new(0.3 + 0.05 * (i % 3) as f64, -0.05 + 0.05 * ((i / 3) % 3) as f64, 0.05 + 0.05 * (i / 9) as f64);
            let w: [f64; 4] = (m * x + c).into();
            assert!(truth.residual_px(&w).abs() < 1e-9);
            assert!(fitted.residual_px(&w).abs() < 0.5, "residual {} at {x:?}", fitted.residual_px(&w));
        }
    }

    #[test]
    fn degenerate_and_bad_input_are_errors() {
        let flat: Vec<Vector3<f64>> = (0..6).map(|i| Vector3::new(i as f64, (i * i) as f64, 0.0)).collect();
        let w = vec![[0.0; 4]; 6];
        assert!(matches!(AffineStereo::fit(&flat, &w), Err(FitError::Degenerate(_))));
        assert!(matches!(AffineStereo::fit(&flat[..3], &w[..3]), Err(FitError::TooFewPoints { .. })));
        assert!(matches!(AffineStereo::fit(&flat, &w[..5]), Err(FitError::CountMismatch { .. })));
        let mut nan = cage();
        nan[0].x = f64::NAN;
        assert!(matches!(AffineStereo::fit(&nan, &vec![[0.0; 4]; 8]), Err(FitError::NotFinite)));
        assert!(matches!(EpipolarConstraint::fit(&[[1.0; 4]; 5]), Err(FitError::Degenerate(_))));
    }

    #[test]
    fn toward_cameras_points_at_the_cameras() {
        // These cameras look along +y (u grows with x, v with −z), so the cameras are at −y.
        let (m, c) = cameras();
        let model = AffineStereo { m, c, residual_rms_px: 0.0, disparity_range_px: [0.0; 2] };
        let t = model.toward_cameras();
        assert!(t[1] < -0.95 && (t.norm() - 1.0).abs() < 1e-12, "{t:?}");
        // A model fitted to perspective cameras 2 m away, up 25°, in front along +x.
        let rig = crate::servo::testcam::Rig::standard(1500.0);
        let seen: Vec<[f64; 4]> = cage().iter().map(|x| {
            let p = rig.project(x);
            [p.left[0], p.left[1], p.right[0], p.right[1]]
        }).collect();
        let t = AffineStereo::fit(&cage(), &seen).unwrap().toward_cameras();
        let mid = 0.5 * (rig.left.centre_m + rig.right.centre_m) - Vector3::new(0.5, 0.0, 0.1);
        let angle = t.dot(&mid.normalize()).acos().to_degrees();
        assert!(angle < 3.0, "{angle}° from the true direction: {t:?}");
    }

    #[test]
    fn reconstruct_direction_and_epipolar_lines() {
        let (m, c) = cameras();
        let seen: Vec<[f64; 4]> = cage().iter().map(|x| (m * x + c).into()).collect();
        let model = AffineStereo::fit(&cage(), &seen).unwrap();
        let d = Vector3::new(0.0, 0.0, 0.01);
        let img = m * d;
        let back = model.reconstruct_direction(&[img[0], img[1]], &[img[2], img[3]]);
        assert!((back - d).norm() < 1e-9);
        // The right epipolar line of a left point passes through its true match.
        let ep = model.epipolar();
        let w = seen[6];
        assert!(ep.right_distance_px(&[w[0], w[1]], &[w[2], w[3]]).unwrap().abs() < 1e-9);
        // Moving along the right epipolar direction stays on the line.
        let dir = ep.right_direction();
        let moved = [w[2] + 7.0 * dir[0], w[3] + 7.0 * dir[1]];
        assert!(ep.right_distance_px(&[w[0], w[1]], &moved).unwrap().abs() < 1e-9);
        assert!(model.disparity_range_px[0] <= model.disparity_range_px[1]);
    }
}
