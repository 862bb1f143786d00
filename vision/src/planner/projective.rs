//! Projective (pinhole) stereo from the same calibration points as the affine model, for
//! metric reconstruction.
//!
//! The affine model (METHOD.md §1) is what the planner matches and groups with, and what the
//! daemon servoes with: both only need it to first order. Mapped back to the robot frame,
//! though, its error is that of weak perspective itself: with cameras ~1.6 m away and a
//! calibration cage 0.2 m across, even exact image points of a block's corners reconstruct
//! 5-9 mm off through the cage's affine fit (the simulator's pick scenarios). Each camera's
//! full 3x4 projection, fitted to the same >= 6 non-coplanar cage points by the direct linear
//! transform, leaves only the image error: ~1 mm across and ~3 mm in depth per pixel of
//! disparity at that distance.
//!
//! ```
//! use handeye_vision::planner::projective::ProjectiveStereo;
//! use nalgebra::{Matrix3x4, Vector3};
//! // Two pinhole cameras 1.6 m away, 0.5 m apart, looking along -x.
//! let cam = |y: f64| Matrix3x4::new(0.0, -1800.0, 0.0, 320.0 * 1.6 + 1800.0 * y,
//!                                   0.0, 0.0, -1800.0, 240.0 * 1.6,
//!                                   -1.0, 0.0, 0.0, 1.6);
//! let (l, r) = (cam(-0.25), cam(0.25));
//! let proj = |p: &Matrix3x4<f64>, x: &Vector3<f64>| { let h = p * x.push(1.0); [h.x / h.z, h.y / h.z] };
//! let cage: Vec<Vector3<f64>> = (0..8)
//!     .map(|i| Vector3::new(0.1 * (i & 1) as f64, -0.1 + 0.2 * ((i >> 1) & 1) as f64, 0.05 + 0.15 * (i >> 2) as f64))
//!     .collect();
//! let seen: Vec<[f64; 4]> = cage.iter().map(|x| { let (a, b) = (proj(&l, x), proj(&r, x)); [a[0], a[1], b[0], b[1]] }).collect();
//! let stereo = ProjectiveStereo::fit(&cage, &seen).unwrap();
//! let x = Vector3::new(0.03, 0.02, 0.01);
//! let (a, b) = (proj(&l, &x), proj(&r, &x));
//! assert!((stereo.reconstruct(&[a[0], a[1], b[0], b[1]]) - x).norm() < 1e-6);
//! ```

use nalgebra::{DMatrix, Matrix2, Matrix3, Matrix3x4, Matrix4, Matrix4x3, Vector2, Vector3, Vector4};

use crate::affine::FitError;

/// Two pinhole cameras `x ~ P X` fitted to calibration points.
#[derive(Debug, Clone, PartialEq)]
pub struct ProjectiveStereo {
    /// Left and right 3x4 projections from robot coordinates (metres) to pixels.
    pub left: Matrix3x4<f64>,
    pub right: Matrix3x4<f64>,
    /// RMS reprojection residual of the fit over all coordinates of the calibration points,
    /// pixels.
    pub residual_rms_px: f64,
}

/// Fewest points the direct linear transform needs (11 unknowns, two equations a point).
pub const MIN_POINTS: usize = 6;

impl ProjectiveStereo {
    /// Fits both cameras to `>= 6` robot points `robot_m`, not all on one plane, and their
    /// images `image_px` (`(u, v, u', v')`): the direct linear transform on normalised
    /// coordinates (centred, mean distance √2 in the image and √3 in space).
    pub fn fit(robot_m: &[Vector3<f64>], image_px: &[[f64; 4]]) -> Result<Self, FitError> {
        if robot_m.len() != image_px.len() {
            return Err(FitError::CountMismatch { robot: robot_m.len(), image: image_px.len() });
        }
        if robot_m.len() < MIN_POINTS {
            return Err(FitError::TooFewPoints { needed: MIN_POINTS, got: robot_m.len() });
        }
        if robot_m.iter().any(|x| !x.iter().all(|v| v.is_finite())) || image_px.iter().flatten().any(|v| !v.is_finite()) {
            return Err(FitError::NotFinite);
        }
        let left_px: Vec<[f64; 2]> = image_px.iter().map(|w| [w[0], w[1]]).collect();
        let right_px: Vec<[f64; 2]> = image_px.iter().map(|w| [w[2], w[3]]).collect();
        let left = dlt(robot_m, &left_px)?;
        let right = dlt(robot_m, &right_px)?;
        let mut sq = 0.0;
        for (x, w) in robot_m.iter().zip(image_px) {
            let (a, b) = (project(&left, x), project(&right, x));
            sq += (a[0] - w[0]).powi(2) + (a[1] - w[1]).powi(2) + (b[0] - w[2]).powi(2) + (b[1] - w[3]).powi(2);
        }
        let residual_rms_px = (sq / (4 * robot_m.len()) as f64).sqrt();
        Ok(Self { left, right, residual_rms_px })
    }

    /// Image coordinates `(u, v, u', v')` of robot point `x_m`.
    pub fn project(&self, x_m: &Vector3<f64>) -> [f64; 4] {
        let (a, b) = (project(&self.left, x_m), project(&self.right, x_m));
        [a[0], a[1], b[0], b[1]]
    }

    /// The robot point at height `z_m` that the left camera sees at `(u, v)`, with its depth
    /// in each camera (the projections' third coordinates: their sign says which side of the
    /// camera it is on, in the fit's own sign). `None` when the ray runs along the plane.
    pub fn left_ray_at_height(&self, u: f64, v: f64, z_m: f64) -> Option<(Vector3<f64>, [f64; 2])> {
        let p = &self.left;
        let r0 = p.row(0) - p.row(2) * u;
        let r1 = p.row(1) - p.row(2) * v;
        let a = Matrix2::new(r0[0], r0[1], r1[0], r1[1]);
        let b = Vector2::new(-(r0[2] * z_m + r0[3]), -(r1[2] * z_m + r1[3]));
        let xy = a.try_inverse()? * b;
        let x = Vector3::new(xy.x, xy.y, z_m);
        let depth = |p: &Matrix3x4<f64>| (p.row(2) * x.push(1.0))[0];
        Some((x, [depth(&self.left), depth(&self.right)]))
    }

    /// The robot point seen at `w = (u, v, u', v')`: linear triangulation, re-weighted once by
    /// each camera's depth so that the residuals it balances are (nearly) pixels.
    pub fn reconstruct(&self, w: &[f64; 4]) -> Vector3<f64> {
        let rows = |p: &Matrix3x4<f64>, u: f64, v: f64| [p.row(2) * u - p.row(0), p.row(2) * v - p.row(1)];
        let [a0, a1] = rows(&self.left, w[0], w[1]);
        let [b0, b1] = rows(&self.right, w[2], w[3]);
        let mut weights = [1.0, 1.0];
        let mut x = Vector3::zeros();
        for _ in 0..2 {
            let (wl, wr) = (weights[0], weights[1]);
            let a = Matrix4::from_rows(&[a0 * wl, a1 * wl, b0 * wr, b1 * wr]);
            let lhs: Matrix4x3<f64> = a.fixed_columns::<3>(0).into_owned();
            let rhs: Vector4<f64> = -a.column(3);
            let ata: Matrix3<f64> = lhs.transpose() * lhs;
            match ata.try_inverse() {
                Some(inv) => x = inv * lhs.transpose() * rhs,
                None => break,
            }
            let depth = |p: &Matrix3x4<f64>| (p.row(2) * x.push(1.0))[0].abs().max(1e-9);
            weights = [1.0 / depth(&self.left), 1.0 / depth(&self.right)];
        }
        x
    }
}

fn project(p: &Matrix3x4<f64>, x: &Vector3<f64>) -> [f64; 2] {
    let h = p * x.push(1.0);
    [h.x / h.z, h.y / h.z]
}

/// One camera by the normalised direct linear transform.
fn dlt(robot_m: &[Vector3<f64>], px: &[[f64; 2]]) -> Result<Matrix3x4<f64>, FitError> {
    let n = robot_m.len();
    let xm = robot_m.iter().fold(Vector3::zeros(), |a, x| a + x) / n as f64;
    let xs = robot_m.iter().map(|x| (x - xm).norm()).sum::<f64>() / n as f64;
    let um = px.iter().fold([0.0, 0.0], |a, p| [a[0] + p[0] / n as f64, a[1] + p[1] / n as f64]);
    let us = px.iter().map(|p| (p[0] - um[0]).hypot(p[1] - um[1])).sum::<f64>() / n as f64;
    if xs <= 0.0 || us <= 0.0 {
        return Err(FitError::Degenerate("all points coincide"));
    }
    let (kx, ku) = (3f64.sqrt() / xs, 2f64.sqrt() / us);
    // Normalised point X̃ = kx (X − X̄), ũ = ku (u − ū); rows of A p = 0.
    let mut a = DMatrix::<f64>::zeros(2 * n, 12);
    for (i, (x, p)) in robot_m.iter().zip(px).enumerate() {
        let xh = ((x - xm) * kx).push(1.0);
        let (u, v) = ((p[0] - um[0]) * ku, (p[1] - um[1]) * ku);
        for c in 0..4 {
            a[(2 * i, c)] = xh[c];
            a[(2 * i, 8 + c)] = -u * xh[c];
            a[(2 * i + 1, 4 + c)] = xh[c];
            a[(2 * i + 1, 8 + c)] = -v * xh[c];
        }
    }
    // The null vector of A: the eigenvector of AᵀA with the smallest eigenvalue. Points on one
    // plane leave a null space of more than one dimension.
    let eig = (a.transpose() * &a).symmetric_eigen();
    let mut order: Vec<usize> = (0..12).collect();
    order.sort_by(|&i, &j| eig.eigenvalues[i].total_cmp(&eig.eigenvalues[j]));
    let (l1, lmax) = (eig.eigenvalues[order[1]], eig.eigenvalues[order[11]]);
    if l1 <= 1e-10 * lmax {
        return Err(FitError::Degenerate("calibration points on one plane (or a line): the projection is not determined"));
    }
    let p = eig.eigenvectors.column(order[0]);
    let pn = Matrix3x4::from_row_slice(p.as_slice());
    // Undo the normalisations: P = T_u⁻¹ P̃ T_x.
    let tu_inv = Matrix3::new(1.0 / ku, 0.0, um[0], 0.0, 1.0 / ku, um[1], 0.0, 0.0, 1.0);
    let tx = Matrix4::new(kx, 0.0, 0.0, -kx * xm.x, 0.0, kx, 0.0, -kx * xm.y, 0.0, 0.0, kx, -kx * xm.z, 0.0, 0.0, 0.0, 1.0);
    let p = tu_inv * pn * tx;
    // Scale so that points in front of the camera have positive depth (the calibration
    // points are in front).
    let sign = if (p.row(2) * xm.push(1.0))[0] < 0.0 { -1.0 } else { 1.0 };
    let norm = p.row(2).fixed_columns::<3>(0).norm();
    if norm <= 0.0 || !norm.is_finite() {
        return Err(FitError::Degenerate("no finite camera"));
    }
    Ok(p * (sign / norm))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A verged pinhole pair like the simulator's: 1.6 m away, f = 1800 px.
    fn cameras() -> (Matrix3x4<f64>, Matrix3x4<f64>) {
        let cam = |c: Vector3<f64>| {
            let look = (Vector3::new(0.35, 0.0, 0.16) - c).normalize();
            let right = look.cross(&Vector3::z()).normalize();
            let down = look.cross(&right);
            let r = Matrix3::from_rows(&[right.transpose(), down.transpose(), look.transpose()]);
            let k = Matrix3::new(1800.0, 0.0, 320.0, 0.0, 1800.0, 240.0, 0.0, 0.0, 1.0);
            let mut rt = Matrix3x4::zeros();
            rt.fixed_columns_mut::<3>(0).copy_from(&r);
            rt.set_column(3, &(-r * c));
            k * rt
        };
        (cam(Vector3::new(1.695, -0.241, 0.9)), cam(Vector3::new(1.695, 0.241, 0.9)))
    }

    fn cage() -> Vec<Vector3<f64>> {
        (0..8).map(|i| Vector3::new([0.27, 0.45][i & 1], [-0.1, 0.1][(i >> 1) & 1], [0.06, 0.2][i >> 2])).collect()
    }

    fn seen(l: &Matrix3x4<f64>, r: &Matrix3x4<f64>, pts: &[Vector3<f64>]) -> Vec<[f64; 4]> {
        pts.iter().map(|x| { let (a, b) = (project(l, x), project(r, x)); [a[0], a[1], b[0], b[1]] }).collect()
    }

    #[test]
    fn exact_cameras_reconstruct_points_off_the_cage_exactly() {
        let (l, r) = cameras();
        let stereo = ProjectiveStereo::fit(&cage(), &seen(&l, &r, &cage())).unwrap();
        assert!(stereo.residual_rms_px < 1e-6, "{}", stereo.residual_rms_px);
        // On the table, outside the cage's height range.
        for x in [Vector3::new(0.3, -0.12, 0.0), Vector3::new(0.47, 0.14, 0.03), Vector3::new(0.35, 0.0, 0.06)] {
            let w = seen(&l, &r, &[x])[0];
            assert!((stereo.reconstruct(&w) - x).norm() < 1e-6, "{x:?}");
            let back = stereo.project(&x);
            assert!(back.iter().zip(&w).all(|(a, b)| (a - b).abs() < 1e-6));
        }
    }

    #[test]
    fn pixel_noise_costs_millimetres_not_more() {
        let (l, r) = cameras();
        // Deterministic +-0.3 px perturbations of the cage's images.
        let mut w = seen(&l, &r, &cage());
        for (i, p) in w.iter_mut().enumerate() {
            for (k, c) in p.iter_mut().enumerate() {
                *c += 0.3 * (((i * 7 + k * 3) % 5) as f64 / 2.0 - 1.0);
            }
        }
        let stereo = ProjectiveStereo::fit(&cage(), &w).unwrap();
        let x = Vector3::new(0.36, 0.02, 0.02);
        let err = (stereo.reconstruct(&seen(&l, &r, &[x])[0]) - x).norm();
        assert!(err < 3e-3, "{err}");
    }

    #[test]
    fn coplanar_or_too_few_points_are_refused() {
        let (l, r) = cameras();
        let flat: Vec<Vector3<f64>> = (0..8).map(|i| Vector3::new(0.27 + 0.02 * i as f64, [-0.1, 0.1][i & 1], 0.06)).collect();
        assert!(matches!(ProjectiveStereo::fit(&flat, &seen(&l, &r, &flat)), Err(FitError::Degenerate(_))));
        let few = &cage()[..5];
        assert!(matches!(ProjectiveStereo::fit(few, &seen(&l, &r, few)), Err(FitError::TooFewPoints { .. })));
    }
}
