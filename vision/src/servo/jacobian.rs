//! The servo's view of the affine stereo model, and the Jacobian of the error vector with
//! respect to the robot's motion `q = (x, y, z, yaw)` (METHOD.md §3).

use nalgebra::{Matrix2, Matrix2x3, Matrix3x4, Matrix6x4, RowVector3, Vector2, Vector3, Vector4};
use thiserror::Error;

use super::measure::{v2, GeometryError, PlaneTransfer};
use super::{GripperView, StereoFrame, StereoPoint};
use crate::affine::{AffineStereo, EpipolarConstraint};

/// Why an affine stereo model cannot drive the servo.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum ModelError {
    #[error("the affine stereo model has a coefficient that is not finite")]
    NotFinite,
    #[error("the affine stereo model has rank < 3 (MᵀM is singular): it cannot reconstruct")]
    RankDeficient,
    #[error("the epipolar direction has zero length or is not finite")]
    BadEpipolarDirection,
}

/// What the servo needs of the affine stereo model `w = M X + c`: the two cameras' 2x3 blocks,
/// the least-squares inverse, and the right image's epipolar direction. Fixed-size, `Copy`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoModel {
    m_left: Matrix2x3<f64>,
    m_right: Matrix2x3<f64>,
    pinv: Matrix3x4<f64>,
    c: Vector4<f64>,
    epipolar_right: Vector2<f64>,
}

impl ServoModel {
    /// From a fitted model; the epipolar direction is the one the model implies.
    pub fn new(model: &AffineStereo) -> Result<Self, ModelError> {
        if !(model.m.iter().all(|x| x.is_finite()) && model.c.iter().all(|x| x.is_finite())) {
            return Err(ModelError::NotFinite);
        }
        let mtm = model.m.transpose() * model.m;
        let eig = mtm.symmetric_eigenvalues();
        if eig.min().is_nan() || eig.min() <= 1e-12 * eig.max() {
            return Err(ModelError::RankDeficient);
        }
        let pinv = mtm.try_inverse().ok_or(ModelError::RankDeficient)? * model.m.transpose();
        let m_left = model.m.fixed_rows::<2>(0).into_owned();
        let m_right = model.m.fixed_rows::<2>(2).into_owned();
        let ep = model.epipolar();
        Ok(Self { m_left, m_right, pinv, c: model.c, epipolar_right: ep.right_direction() })
    }

    /// Uses the epipolar direction of a separately fitted constraint (e.g. by orthogonal
    /// regression over many correspondences) instead of the model's own.
    pub fn with_epipolar(mut self, constraint: &EpipolarConstraint) -> Result<Self, ModelError> {
        let d = constraint.right_direction();
        if !(d.iter().all(|x| x.is_finite()) && d.norm() > 0.5) {
            return Err(ModelError::BadEpipolarDirection);
        }
        self.epipolar_right = d;
        Ok(self)
    }

    /// The same model with one view's image moved by `shift_px` (the first-order effect of a
    /// small knock of that camera): its offset moves, nothing else changes.
    pub fn shifted(&self, left: bool, shift_px: [f64; 2]) -> Self {
        let mut m = *self;
        let k = if left { 0 } else { 2 };
        m.c[k] += shift_px[0];
        m.c[k + 1] += shift_px[1];
        m
    }

    /// Unit direction of the right image's epipolar lines; the sign of every parallax.
    pub fn epipolar_right(&self) -> Vector2<f64> {
        self.epipolar_right
    }

    /// Affine reconstruction of a point seen in both views, robot frame, metres.
    pub fn reconstruct(&self, p: &StereoPoint) -> Vector3<f64> {
        self.pinv * (Vector4::new(p.left[0], p.left[1], p.right[0], p.right[1]) - self.c)
    }

    /// Affine reconstruction of an image displacement pair (a direction), robot frame.
    pub fn reconstruct_direction(&self, d: &StereoPoint) -> Vector3<f64> {
        self.pinv * Vector4::new(d.left[0], d.left[1], d.right[0], d.right[1])
    }

    /// Images of a 3-D direction (or displacement) `d`, robot frame: `M d` in each view.
    pub fn project_direction(&self, d: &Vector3<f64>) -> StereoPoint {
        let (l, r) = (self.m_left * d, self.m_right * d);
        StereoPoint { left: [l[0], l[1]], right: [r[0], r[1]] }
    }

    /// `∂π/∂X = ê_rᵀ (M_r − A_T M_l)`: parallax (px) per metre of motion of a point.
    pub fn parallax_gradient(&self, transfer: &PlaneTransfer) -> RowVector3<f64> {
        self.epipolar_right.transpose() * (self.m_right - transfer.a * self.m_left)
    }

    /// `∂(s, t)/∂X`: the mean over both views of `[e1 e2]⁻¹ M`, target-frame units per metre.
    fn st_gradient(&self, inv_l: &Matrix2<f64>, inv_r: &Matrix2<f64>) -> Matrix2x3<f64> {
        (inv_l * self.m_left + inv_r * self.m_right) * 0.5
    }

    /// Goal parallax (px) that holds a mark at `offset_m` (robot frame, metres) from the target
    /// plane: a stand-off. Only the offset's component normal to the plane counts.
    pub fn parallax_for_offset(&self, target: &StereoFrame, offset_m: &Vector3<f64>) -> Result<f64, GeometryError> {
        let transfer = PlaneTransfer::from_frames(target)?;
        Ok((self.parallax_gradient(&transfer) * offset_m)[0])
    }

    /// Change of the reference point's `(s, t)` when it moves by `offset_m` (robot frame,
    /// metres): turns a metric in-plane offset (e.g. "30 mm above the grasp site") into a goal.
    pub fn st_for_offset(&self, target: &StereoFrame, offset_m: &Vector3<f64>) -> Result<[f64; 2], GeometryError> {
        let inv_l = target.left.basis_inverse("left")?;
        let inv_r = target.right.basis_inverse("right")?;
        Ok((self.st_gradient(&inv_l, &inv_r) * offset_m).into())
    }

    /// The 6x4 Jacobian of the error vector with respect to `(x, y, z, yaw)`: columns in
    /// units per metre (x, y, z) and per radian (yaw); rows as in [`super::Measurement::error`].
    ///
    /// Translation block exact for affine cameras. Yaw turns the gripper about the vertical
    /// axis through its reference point; the marks' lever arms and the axis direction come
    /// from the affine reconstruction (METHOD.md §3). An error in the lever arms (the reference
    /// point off the true yaw axis, a stale model) only adds a translation-like term that the
    /// integrating loop absorbs.
    pub fn jacobian(&self, target: &StereoFrame, gripper: &GripperView) -> Result<Matrix6x4<f64>, GeometryError> {
        let inv_l = target.left.basis_inverse("left")?;
        let inv_r = target.right.basis_inverse("right")?;
        let transfer = PlaneTransfer::from_frames(target)?;
        let b = self.parallax_gradient(&transfer);
        let s = self.st_gradient(&inv_l, &inv_r);
        let centre = self.reconstruct(&gripper.reference);
        let about_z = |r: Vector3<f64>| Vector3::new(-r[1], r[0], 0.0);

        let mut j = Matrix6x4::zeros();
        for (i, mark) in gripper.marks.iter().enumerate() {
            j.fixed_view_mut::<1, 3>(i, 0).copy_from(&b);
            j[(i, 3)] = (b * about_z(self.reconstruct(mark) - centre))[0];
        }
        // The reference point is the rotation centre: yaw does not move it.
        j.fixed_view_mut::<2, 3>(3, 0).copy_from(&s);

        // ρ: yaw turns the axis direction d about z; its image in each view turns with it.
        let d_dot = about_z(self.reconstruct_direction(&gripper.axis));
        let rate = |inv: &Matrix2<f64>, m: &Matrix2x3<f64>, axis: &[f64; 2]| {
            let a = inv * v2(axis);
            let a_dot = inv * (m * d_dot);
            (a[0] * a_dot[1] - a[1] * a_dot[0]) / a.norm_squared()
        };
        j[(5, 3)] = 0.5 * (rate(&inv_l, &self.m_left, &gripper.axis.left) + rate(&inv_r, &self.m_right, &gripper.axis.right));
        Ok(j)
    }
}
