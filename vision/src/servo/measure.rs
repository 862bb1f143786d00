//! Image measurements of the coplanarity servo: plane transfer, plane + parallax, and the
//! error vector `e = [π1, π2, π3, s − s*, t − t*, ρ]` (METHOD.md §3).

use nalgebra::{Matrix2, Vector2, Vector6};
use thiserror::Error;

use super::{ViewFrame, GripperView, ServoGoal, StereoFrame, StereoPoint};

/// Why a set of image measurements cannot be used.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum GeometryError {
    /// A coordinate is NaN or infinite.
    #[error("{what} has a coordinate that is not finite")]
    NotFinite { what: &'static str },
    /// An affine frame's basis vectors are (nearly) parallel or zero, so the frame cannot be
    /// inverted: the tracker that produced it has collapsed.
    #[error("the {view} target frame is degenerate (|det [e1 e2]| = {det_px2:.3e} px²)")]
    DegenerateFrame { view: &'static str, det_px2: f64 },
    /// The gripper axis has (nearly) zero length in one view.
    #[error("the gripper axis in the {view} view has zero length")]
    DegenerateAxis { view: &'static str },
    /// A goal's horizontal and vertical directions (nearly) coincide in the target's frame
    /// (the facet is seen edge-on, or lies flat), so its height cannot be set apart.
    #[error("the goal's horizontal and vertical directions look alike in the target's frame (facet edge-on or flat)")]
    DegenerateGoal,
}

/// Smallest `|det [e1 e2]|` of a usable frame, px². A tracker frame is tens of pixels on a
/// side (hundreds of px²); below 1 px² it has collapsed to a line or a point.
const MIN_FRAME_DET_PX2: f64 = 1.0;

/// Shortest usable gripper axis, px. Its direction is all that matters, but a (near-)zero
/// vector has none.
const MIN_AXIS_PX: f64 = 1e-6;

pub(crate) fn v2(p: &[f64; 2]) -> Vector2<f64> {
    Vector2::new(p[0], p[1])
}

pub(crate) fn finite2(p: &[f64; 2]) -> bool {
    p[0].is_finite() && p[1].is_finite()
}

impl ViewFrame {
    /// `[e1 e2]` as the columns of a 2x2 matrix.
    pub fn basis(&self) -> Matrix2<f64> {
        Matrix2::new(self.e1[0], self.e2[0], self.e1[1], self.e2[1])
    }

    /// Image point of affine coordinates `(s, t)`: `o + s e1 + t e2`.
    pub fn point(&self, st: &[f64; 2]) -> [f64; 2] {
        (v2(&self.o) + self.basis() * v2(st)).into()
    }

    /// Inverse of the basis, or why there is none.
    pub(crate) fn basis_inverse(&self, view: &'static str) -> Result<Matrix2<f64>, GeometryError> {
        if !(finite2(&self.o) && finite2(&self.e1) && finite2(&self.e2)) {
            return Err(GeometryError::NotFinite { what: "target frame" });
        }
        let b = self.basis();
        let det = b.determinant();
        if det.abs() < MIN_FRAME_DET_PX2 {
            return Err(GeometryError::DegenerateFrame { view, det_px2: det });
        }
        Ok(Matrix2::new(b[(1, 1)], -b[(0, 1)], -b[(1, 0)], b[(0, 0)]) / det)
    }

    /// Affine coordinates `(s, t)` of image point `x` in this frame.
    pub fn coordinates(&self, x: &[f64; 2]) -> Result<[f64; 2], GeometryError> {
        Ok((self.basis_inverse("given")? * (v2(x) - v2(&self.o))).into())
    }
}

/// The affine transfer `x' = A x + b` of a plane from the left to the right image, from the
/// plane's affine frames in both views: `A = [e1' e2'][e1 e2]⁻¹`, `b = o' − A o`.
///
/// ```
/// use handeye_vision::servo::{ViewFrame, PlaneTransfer, StereoFrame};
/// let frames = StereoFrame {
///     left: ViewFrame { o: [100.0, 200.0], e1: [40.0, 0.0], e2: [0.0, 40.0] },
///     right: ViewFrame { o: [130.0, 198.0], e1: [36.0, 2.0], e2: [1.0, 41.0] },
/// };
/// let t = PlaneTransfer::from_frames(&frames).unwrap();
/// // The frame's own corner (s, t) = (1, 1) transfers exactly.
/// let x = t.apply(&[140.0, 240.0]);
/// assert!((x[0] - 167.0).abs() < 1e-12 && (x[1] - 241.0).abs() < 1e-12);
/// ```
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneTransfer {
    pub a: Matrix2<f64>,
    pub b: Vector2<f64>,
}

impl PlaneTransfer {
    pub fn from_frames(frames: &StereoFrame) -> Result<Self, GeometryError> {
        let inv = frames.left.basis_inverse("left")?;
        frames.right.basis_inverse("right")?;
        let a = frames.right.basis() * inv;
        let b = v2(&frames.right.o) - a * v2(&frames.left.o);
        Ok(Self { a, b })
    }

    /// Where left-image point `x` of the plane appears in the right image.
    pub fn apply(&self, x: &[f64; 2]) -> [f64; 2] {
        (self.a * v2(x) + self.b).into()
    }
}

/// Parallax of a point against a plane: `p = x' − (A x + b)`, split into its component along
/// the right epipolar direction (signed, proportional to the point's distance from the plane)
/// and across it (should be ~0; a quality check of trackers and epipolar geometry).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Parallax {
    /// `π = ê_r·p`, pixels.
    pub along_px: f64,
    /// `ê_r⊥·p`, pixels, with `ê_r⊥` the epipolar direction turned +90°.
    pub across_px: f64,
}

impl Parallax {
    /// Parallax of `point` against the plane of `transfer`, with `epipolar_right` the unit
    /// direction of the right image's epipolar lines (it fixes the sign of `along_px`).
    pub fn of(transfer: &PlaneTransfer, epipolar_right: &Vector2<f64>, point: &StereoPoint) -> Self {
        let p = v2(&point.right) - (transfer.a * v2(&point.left) + transfer.b);
        Self {
            along_px: epipolar_right.dot(&p),
            across_px: epipolar_right[0] * p[1] - epipolar_right[1] * p[0],
        }
    }
}

/// One evaluation of the servo's image error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Measurement {
    /// `[π1 − π1*, π2 − π2*, π3 − π3*, s − s*, t − t*, ρ]`: pixels, pixels, pixels, target
    /// frame units, target frame units, radians.
    pub error: Vector6<f64>,
    /// Raw parallaxes of the three marks against the target plane (goal not subtracted).
    pub parallax: [Parallax; 3],
    /// Gripper reference point in the target's affine frame (mean of both views).
    pub st: [f64; 2],
    /// Angle of the gripper axis in the target's affine frame, from `e1` towards `e2`
    /// (mean of both views), radians.
    pub angle_rad: f64,
    /// Row weights that turn `error` into comparable pixel-sized numbers: 1 for the
    /// parallaxes, the mean target basis length (px) for `s, t`, the mean mark distance from
    /// the reference point (px) for `ρ`.
    pub row_weights: Vector6<f64>,
}

/// `x` wrapped into `(−π, π]`.
pub(crate) fn wrap_angle(x: f64) -> f64 {
    let y = x.rem_euclid(std::f64::consts::TAU);
    if y > std::f64::consts::PI { y - std::f64::consts::TAU } else { y }
}

fn check_point(p: &StereoPoint, what: &'static str) -> Result<(), GeometryError> {
    if finite2(&p.left) && finite2(&p.right) { Ok(()) } else { Err(GeometryError::NotFinite { what }) }
}

/// Measures the error vector of `gripper` against `target` and `goal`; `epipolar_right` is the
/// unit right epipolar direction.
pub fn measure(
    target: &StereoFrame,
    gripper: &GripperView,
    goal: &ServoGoal,
    epipolar_right: &Vector2<f64>,
) -> Result<Measurement, GeometryError> {
    for m in &gripper.marks {
        check_point(m, "gripper mark")?;
    }
    check_point(&gripper.reference, "gripper reference point")?;
    check_point(&gripper.axis, "gripper axis")?;
    if !(goal.st.iter().chain(&goal.parallax_px).all(|x| x.is_finite()) && goal.angle_rad.is_finite()) {
        return Err(GeometryError::NotFinite { what: "servo goal" });
    }
    let inv_l = target.left.basis_inverse("left")?;
    let inv_r = target.right.basis_inverse("right")?;
    let transfer = PlaneTransfer::from_frames(target)?;

    let mut parallax = [Parallax::default(); 3];
    for (p, m) in parallax.iter_mut().zip(&gripper.marks) {
        *p = Parallax::of(&transfer, epipolar_right, m);
    }

    // Position: both views' affine coordinates agree for a point on the target plane; their
    // mean halves the noise of either and treats the two cameras alike.
    let st_l = inv_l * (v2(&gripper.reference.left) - v2(&target.left.o));
    let st_r = inv_r * (v2(&gripper.reference.right) - v2(&target.right.o));
    let st = (st_l + st_r) * 0.5;

    if v2(&gripper.axis.left).norm() < MIN_AXIS_PX {
        return Err(GeometryError::DegenerateAxis { view: "left" });
    }
    if v2(&gripper.axis.right).norm() < MIN_AXIS_PX {
        return Err(GeometryError::DegenerateAxis { view: "right" });
    }
    let a_l = inv_l * v2(&gripper.axis.left);
    let a_r = inv_r * v2(&gripper.axis.right);
    let th_l = a_l[1].atan2(a_l[0]);
    let th_r = a_r[1].atan2(a_r[0]);
    let angle_rad = wrap_angle(th_l + 0.5 * wrap_angle(th_r - th_l));
    let rho = wrap_angle(angle_rad - goal.angle_rad);

    let basis_px = 0.25
        * (target.left.basis().column(0).norm()
            + target.left.basis().column(1).norm()
            + target.right.basis().column(0).norm()
            + target.right.basis().column(1).norm());
    // An angle times the marks' distance from the reference point is the displacement (px)
    // of a mark: comparable with a parallax, and with about the same noise. (Not the axis's
    // image length: the axis is a direction, its length an arbitrary unit, e.g. per metre.)
    let lever_px = gripper
        .marks
        .iter()
        .map(|m| 0.5 * ((v2(&m.left) - v2(&gripper.reference.left)).norm() + (v2(&m.right) - v2(&gripper.reference.right)).norm()))
        .sum::<f64>()
        / 3.0;

    let error = Vector6::new(
        parallax[0].along_px - goal.parallax_px[0],
        parallax[1].along_px - goal.parallax_px[1],
        parallax[2].along_px - goal.parallax_px[2],
        st[0] - goal.st[0],
        st[1] - goal.st[1],
        rho,
    );
    Ok(Measurement {
        error,
        parallax,
        st: st.into(),
        angle_rad,
        row_weights: Vector6::new(1.0, 1.0, 1.0, basis_px, basis_px, lever_px.max(1.0)),
    })
}
