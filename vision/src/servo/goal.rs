//! A goal held in the target facet's frame in metric terms and turned into image terms
//! afresh at every step, from the frames the target trackers report at that step.
//!
//! Why (METHOD.md §3, "Goal"): the plate's goal is some 100-150 mm from a facet that may be
//! only 30-40 px across, so each mark's parallax against the facet's plane transfer is
//! extrapolated several facet sizes, and a tracker error of a fraction of a pixel in the
//! transfer `A` moves it by pixels. A goal computed once freezes the error of one frame; a
//! goal computed with the same `A` as the measurement carries the same error, and the two
//! cancel: the error of mark `i` is then the parallax of
//! `(x_i − o − M d_i)`, the mark's image offset from the facet origin *less the offset the
//! model predicts*, a few pixels instead of a hundred, so the transfer's error is scaled down
//! by as much. The same holds for the reference point's `(s, t)` and the axis angle.

use nalgebra::{Vector2, Vector3};

use super::measure::{v2, wrap_angle, GeometryError, PlaneTransfer};
use super::{ServoGoal, ServoModel, StereoFrame, StereoPoint};

/// Where the gripper should be relative to the target facet, robot frame, metres. Offsets
/// are from the 3-D point whose images are the target frames' origins `o` (both views must
/// share template coordinates, so that the two origins are one point of the facet).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FacetGoal {
    /// The gripper's reference point relative to the facet origin.
    pub reference_m: Vector3<f64>,
    /// Each mark relative to the facet origin (in the facet's plane for a coplanar goal).
    pub marks_m: [Vector3<f64>; 3],
    /// The direction the gripper axis should have (any length; e.g. the facet's horizontal).
    pub axis: Vector3<f64>,
}

impl FacetGoal {
    /// The image goal for the target as seen now: each mark's parallax, the reference
    /// point's `(s, t)` and the axis angle that the model predicts for the goal pose, all
    /// relative to `target`. With affine cameras and a coplanar goal the parallaxes are zero
    /// whatever the model's errors; under perspective they carry the model's correction.
    ///
    /// ```
    /// use handeye_vision::affine::AffineStereo;
    /// use handeye_vision::servo::{ViewFrame, FacetGoal, ServoModel, StereoFrame};
    /// use nalgebra::{Matrix4x3, Vector3, Vector4};
    /// let m = Matrix4x3::new(800.0, 0.0, 150.0, 0.0, -20.0, -800.0, 780.0, -60.0, -140.0, 0.0, -25.0, -800.0);
    /// let model = ServoModel::new(&AffineStereo { m, c: Vector4::zeros(), residual_rms_px: 0.0, disparity_range_px: [0.0; 2] }).unwrap();
    /// // A facet in the plane x = 0.4, seen through the same (affine) cameras: e1 along y, e2 along z.
    /// let see = |d: Vector3<f64>| { let w = m * d; ([w[0], w[1]], [w[2], w[3]]) };
    /// let (o, e1, e2) = (see(Vector3::new(0.4, 0.0, 0.05)), see(Vector3::new(0.0, 0.04, 0.0)), see(Vector3::new(0.0, 0.0, 0.04)));
    /// let target = StereoFrame {
    ///     left: ViewFrame { o: o.0, e1: e1.0, e2: e2.0 },
    ///     right: ViewFrame { o: o.1, e1: e1.1, e2: e2.1 },
    /// };
    /// // Reference 0.1 m above the facet origin, marks around it, all in the facet's plane.
    /// let up = Vector3::new(0.0, 0.0, 0.1);
    /// let goal = FacetGoal {
    ///     reference_m: up,
    ///     marks_m: [up + Vector3::new(0.0, -0.016, 0.018), up + Vector3::new(0.0, 0.016, 0.018), up - Vector3::new(0.0, 0.0, 0.018)],
    ///     axis: Vector3::new(0.0, 1.0, 0.0),
    /// }
    /// .image_goal(&model, &target)
    /// .unwrap();
    /// // Coplanar: zero parallax; 0.1 m up is 2.5 facet units along e2; the axis lies along e1.
    /// assert!(goal.parallax_px.iter().all(|p| p.abs() < 1e-9), "{goal:?}");
    /// assert!(goal.st[0].abs() < 1e-9 && (goal.st[1] - 2.5).abs() < 1e-9 && goal.angle_rad.abs() < 1e-9);
    /// ```
    pub fn image_goal(&self, model: &ServoModel, target: &StereoFrame) -> Result<ServoGoal, GeometryError> {
        if !(self.reference_m.iter().chain(self.marks_m.iter().flatten()).chain(self.axis.iter()).all(|x| x.is_finite())) {
            return Err(GeometryError::NotFinite { what: "facet goal" });
        }
        let transfer = PlaneTransfer::from_frames(target)?;
        let gradient = model.parallax_gradient(&transfer);
        let st = model.st_for_offset(target, &self.reference_m)?;
        let inv_l = target.left.basis_inverse("left")?;
        let inv_r = target.right.basis_inverse("right")?;
        let axis = model.project_direction(&self.axis);
        let angle = |inv: &nalgebra::Matrix2<f64>, a: &[f64; 2]| -> Result<f64, GeometryError> {
            let v: Vector2<f64> = inv * v2(a);
            if v.norm() < 1e-12 {
                return Err(GeometryError::DegenerateAxis { view: "goal" });
            }
            Ok(v[1].atan2(v[0]))
        };
        let (th_l, th_r) = (angle(&inv_l, &axis.left)?, angle(&inv_r, &axis.right)?);
        Ok(ServoGoal {
            st,
            // As `measure` averages the two views' angles.
            angle_rad: wrap_angle(th_l + 0.5 * wrap_angle(th_r - th_l)),
            parallax_px: self.marks_m.map(|d| (gradient * d)[0]),
        })
    }

    /// [`Self::image_goal`] with the goal's height within the facet's plane taken from the
    /// robot's own kinematics instead of the images: `above_goal_m` is how far the reference
    /// point is above its goal height now (e.g. tool z minus its goal z). The reference
    /// point's `(s, t)` error is split, through the model, into a horizontal part along the
    /// goal axis (kept: it comes from the images) and a vertical part (replaced by
    /// `above_goal_m`), and `(s*, t*)` is moved to match.
    ///
    /// Why: the goal height is the in-plane offset of the plate above the facet, several
    /// facet sizes, and through an affine model of perspective cameras it comes out some
    /// 5-15 % off (the scale at the plate is not the scale between facet and plate), while
    /// the robot knows its height to a fraction of a millimetre. The marks' parallaxes, the
    /// horizontal position and the angle still come from the images.
    pub fn image_goal_at_height(&self, model: &ServoModel, target: &StereoFrame, reference: &StereoPoint, above_goal_m: f64) -> Result<ServoGoal, GeometryError> {
        if !above_goal_m.is_finite() {
            return Err(GeometryError::NotFinite { what: "height above the goal" });
        }
        let mut goal = self.image_goal(model, target)?;
        let st_now = (v2(&target.left.coordinates(&reference.left)?) + v2(&target.right.coordinates(&reference.right)?)) * 0.5;
        let horizontal = Vector3::new(self.axis.x, self.axis.y, 0.0);
        if horizontal.norm() < 1e-9 {
            return Err(GeometryError::DegenerateGoal);
        }
        let s_a = v2(&model.st_for_offset(target, &horizontal.normalize())?);
        let s_z = v2(&model.st_for_offset(target, &Vector3::z())?);
        let basis = nalgebra::Matrix2::from_columns(&[s_a, s_z]);
        // |det| / (|s_a| |s_z|) is the sine of the angle between the two directions in (s, t).
        let det = basis.determinant().abs();
        if det.is_nan() || det <= 0.05 * s_a.norm() * s_z.norm() {
            return Err(GeometryError::DegenerateGoal);
        }
        let Some(inv) = basis.try_inverse() else { return Err(GeometryError::DegenerateGoal) };
        let horizontal_m = (inv * (st_now - v2(&goal.st)))[0];
        goal.st = (st_now - s_a * horizontal_m - s_z * above_goal_m).into();
        Ok(goal)
    }
}
