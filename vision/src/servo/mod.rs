//! The coplanarity servo (METHOD.md §3): image-based look-and-move control that makes a
//! plate on the gripper coplanar with a target facet, at a chosen place and angle within the
//! facet's plane, from uncalibrated stereo.
//!
//! # Frames, units, signs
//! - **Robot frame**: the controller's Cartesian frame, `x, y, z` in metres, `z` up. The
//!   gripper points down; **yaw** is a rotation about `+z` (counter-clockwise seen from above),
//!   radians. A step is a relative move `(dx, dy, dz)` of the tool point plus `dyaw`, i.e. the
//!   wire's `MoveBy`.
//! - **Images**: pixels, `u` right, `v` down, left and right view. Every image quantity comes
//!   in as a [`StereoPoint`] or a [`StereoFrame`].
//! - **Target**: the facet's affine tracker frames in both views (`o, e1, e2` per view). A
//!   point with affine coordinates `(s, t)` is at `o + s e1 + t e2`.
//! - **Gripper**: three non-collinear marks on one flat face of the gripper (the face that is
//!   to become coplanar with the target), a reference point on that face whose images were
//!   used for the cage calibration (so its reconstruction is the tool point; it is taken as
//!   the yaw centre), and an axis: the images of one 3-D vector lying in the face, in both
//!   views (e.g. the gripper tracker's `e1`).
//! - **Error** `e = [π1 − π1*, π2 − π2*, π3 − π3*, s − s*, t − t*, ρ]`: the marks' parallaxes
//!   against the target plane (px, signed along the right epipolar direction
//!   [`ServoModel::epipolar_right`]); the reference point's affine coordinates in the target
//!   frame, mean of both views; `ρ` the angle of the gripper axis in the target's `(s, t)`
//!   coordinates minus the goal angle (radians, wrapped to `(−π, π]`).
//! - **Goal** [`ServoGoal`]: `(s*, t*)`, the goal angle, and goal parallaxes (0 = coplanar).
//!   [`ServoGoal::offset_by`] shifts a goal by a metric offset (a stand-off out of the plane,
//!   or "30 mm above the grasp site"); [`ServoGoal::teach`] takes the current view as goal.
//!   A goal far from a small facet is better held metrically in the facet's frame,
//!   [`FacetGoal`], and turned into a `ServoGoal` at every step from the target as seen
//!   then: the facet's transfer errors, extrapolated to the plate, then cancel between
//!   measurement and goal ([`FacetGoal::image_goal_at_height`] also takes the goal's height
//!   from the robot rather than through the model).
//!
//! # Control
//! `Δq = −g Ĵ⁺ e` with `Ĵ` the Jacobian from the affine model ([`ServoModel::jacobian`]),
//! optionally refined by Broyden rank-1 updates. Rows are weighted to comparable pixel sizes
//! and yaw is scaled to a distance (`yaw_lever_m`) before the pseudo-inverse, so neither the
//! solution nor the conditioning test depends on units. With a 4-DOF arm the six errors need
//! not all reach zero (a facet tilted from vertical cannot be matched by yaw alone): the loop
//! converges to the least-squares pose, so convergence is judged on `Ĵ⁺ e`, the estimated
//! pose offset, in metres and radians, averaged over the last few steps; the step that
//! reports convergence carries one last move that removes that averaged offset.
//!
//! Because every quantity is measured on gripper and target *together* in the same images, a
//! stale model (a camera knocked mid-servo) only makes `Ĵ` less accurate; the loop still
//! converges. The closed-loop tests (`servo/tests.rs`, perspective cameras 2 m away, 20°
//! apart, model from an 8-point cage) converge in ~12 steps to ~0.3 mm off the plane, and to
//! < 1 mm and < 1° with ±0.3 px contour noise, after 3-5° camera knocks, and with a stand-off.
//! In the pick scenarios' geometry (`servo/testpick.rs`: a wedge's 30-60 px triangle seen
//! 45-65° obliquely, the plate's goal 140 mm above it, a local model, a [`FacetGoal`]) they
//! converge in 4-6 steps to < 1 mm and < 1° with 0.3 px of corner jitter per frame.
//!
//! No heap allocation per step: everything is fixed-size (`vision/tests/servo_no_alloc.rs`).
//!
//! # Use (the daemon's servo phase)
//! ```text
//! let model = ServoModel::new(&affine_stereo)?;              // after the cage calibration
//! let mut servo = CoplanarityServo::new(model, ServoConfig::default())?;
//! let goal = FacetGoal { reference_m, marks_m, axis };       // metric, facet's frame
//! each look, once the previous move is done (look-and-move):
//!     let image_goal = goal.image_goal_at_height(&model, &target_frames, &gripper_view.reference, above_m)?;
//!     let s = servo.step(&target_frames, &gripper_view, &image_goal);
//!     Move      => send MoveBy(s.motion)
//!     Converged => send MoveBy(s.motion), then the open-loop grasp
//!     Failed(f) => send Stop, report f
//! ```

mod goal;
mod jacobian;
mod measure;

#[cfg(test)]
pub(crate) mod testcam;
#[cfg(test)]
mod testpick;
#[cfg(test)]
mod testscene;
#[cfg(test)]
mod tests;

pub use goal::FacetGoal;
pub use jacobian::{ModelError, ServoModel};
pub use measure::{measure, GeometryError, Measurement, Parallax, PlaneTransfer};

use nalgebra::{Matrix4, Matrix6x4, Vector3, Vector4, Vector6};
use thiserror::Error;

/// One point (or one displacement) seen in both views, pixels.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StereoPoint {
    pub left: [f64; 2],
    pub right: [f64; 2],
}

/// A plane's affine frame in one view, pixels: origin `o` and basis `e1, e2`, as the servo
/// receives it from a tracker (the tracker's own is [`crate::tracker::TemplateFrame`]).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ViewFrame {
    pub o: [f64; 2],
    pub e1: [f64; 2],
    pub e2: [f64; 2],
}

/// A plane's affine frames in both views (e.g. a facet's two trackers).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StereoFrame {
    pub left: ViewFrame,
    pub right: ViewFrame,
}

/// What the servo sees of the gripper each step (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct GripperView {
    /// Three non-collinear points on the gripper face.
    pub marks: [StereoPoint; 3],
    /// The reference point: the one tracked during calibration, on the face.
    pub reference: StereoPoint,
    /// Images of one 3-D vector in the face (a direction, not a point), pixels.
    pub axis: StereoPoint,
}

/// Where the servo should bring the gripper, in image terms relative to the target.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ServoGoal {
    /// Goal of the reference point's affine coordinates in the target frame.
    pub st: [f64; 2],
    /// Goal angle of the gripper axis in the target's `(s, t)` coordinates, from `e1`
    /// towards `e2`, radians.
    pub angle_rad: f64,
    /// Goal parallax of each mark, px. All zero: the face coplanar with the target.
    pub parallax_px: [f64; 3],
}

impl ServoGoal {
    /// "Be where you are now": the goal that the current measurements satisfy exactly. Used to
    /// teach a goal by showing, and by tests.
    pub fn teach(model: &ServoModel, target: &StereoFrame, gripper: &GripperView) -> Result<Self, GeometryError> {
        let m = measure(target, gripper, &ServoGoal::default(), &model.epipolar_right())?;
        Ok(Self {
            st: m.st,
            angle_rad: m.angle_rad,
            parallax_px: [m.parallax[0].along_px, m.parallax[1].along_px, m.parallax[2].along_px],
        })
    }
}

impl ServoGoal {
    /// The same goal with the gripper displaced by `offset_m` (robot frame, metres): each
    /// mark's parallax and the reference point's `(s, t)` shift by what that displacement
    /// would change them. E.g. a stand-off of 10 mm out of the target plane, or "30 mm above
    /// the grasp site". Exact for affine cameras.
    pub fn offset_by(&self, model: &ServoModel, target: &StereoFrame, offset_m: &Vector3<f64>) -> Result<Self, GeometryError> {
        let pi = model.parallax_for_offset(target, offset_m)?;
        let st = model.st_for_offset(target, offset_m)?;
        Ok(Self {
            st: [self.st[0] + st[0], self.st[1] + st[1]],
            angle_rad: self.angle_rad,
            parallax_px: [self.parallax_px[0] + pi, self.parallax_px[1] + pi, self.parallax_px[2] + pi],
        })
    }
}

/// A relative move of the tool in the robot frame: the servo's output (wire `MoveBy`).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ToolMotion {
    /// Tool point displacement, robot frame, metres.
    pub translation_m: Vector3<f64>,
    /// Change of yaw about `+z`, radians.
    pub yaw_rad: f64,
}

impl ToolMotion {
    fn from_q(q: &Vector4<f64>) -> Self {
        Self { translation_m: Vector3::new(q[0], q[1], q[2]), yaw_rad: q[3] }
    }

    fn q(&self) -> Vector4<f64> {
        Vector4::new(self.translation_m[0], self.translation_m[1], self.translation_m[2], self.yaw_rad)
    }
}

/// Most steps the convergence test can average.
const WINDOW: usize = 16;

/// Tuning of the servo. `Default` is what the closed-loop tests use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoConfig {
    /// Loop gain `g`, `0 < g < 1`: the fraction of the estimated offset corrected per step.
    pub gain: f64,
    /// Largest translation per step, metres; a longer step is scaled down (direction kept).
    pub max_step_m: f64,
    /// Largest yaw per step, radians.
    pub max_yaw_step_rad: f64,
    /// Converged when the estimated remaining translation is below this, metres...
    pub converged_m: f64,
    /// ...and the estimated remaining yaw below this, radians, both averaged over the last
    /// `converged_steps` steps (each step's estimate carried forward by the motion sent
    /// since, so the average is of the current offset and image noise drops by √k). The
    /// averaged offset is then removed by one last move; see [`StepOutcome::Converged`].
    pub converged_rad: f64,
    /// Steps averaged for the convergence test and the final move, 1..=16.
    pub converged_steps: u32,
    /// The averaged estimates must also agree: each (carried forward) within this many
    /// times `converged_m` / `converged_rad` of their mean. Estimates that scatter more
    /// (a loop chasing measurement noise, or oscillating) average to a small number that
    /// means nothing, and the servo goes on instead of converging on it.
    pub converged_spread: f64,
    /// Give up after this many steps.
    pub max_steps: u32,
    /// Smallest ratio of least to largest singular value of the weighted, scaled Jacobian
    /// (every entry px per metre); below it the step is refused as singular. A 70 mm mark
    /// triangle at 2 m gives ~0.46; marks on the yaw axis (yaw unobservable) ~0.015.
    pub min_condition: f64,
    /// Diverged when the estimated remaining offset grows this many steps in a row (growth
    /// inside the convergence zone's noise, `4 x converged_m`, does not count; one jump, as
    /// when the target is nudged, does not either).
    pub divergence_steps: u32,
    /// Refuse to move when the estimated offset (yaw scaled by `yaw_lever_m`) exceeds this,
    /// metres: no servo should start that far off.
    pub max_offset_m: f64,
    /// A mark's parallax may leave the epipolar direction by at most
    /// `max_across_px + max_across_ratio · |π|` pixels; more means a tracker is wrong.
    pub max_across_px: f64,
    pub max_across_ratio: f64,
    /// Length that turns yaw into a distance for the step's metric (`yaw · lever`), metres:
    /// about the gripper face's size.
    pub yaw_lever_m: f64,
    /// Refine the Jacobian online by Broyden rank-1 updates.
    pub broyden: bool,
    /// Only steps longer than this (metres, yaw scaled by `yaw_lever_m`) update the Jacobian:
    /// shorter ones are dominated by image noise.
    pub broyden_min_step_m: f64,
    /// The learned correction of each Jacobian row stays below this fraction of the row's
    /// norm, so noise can never turn the model around.
    pub broyden_max_fraction: f64,
    /// Weight of the angle row `ρ` relative to its natural one (the marks' mean distance
    /// from the reference point, so that an angle counts as the displacement of a mark).
    /// With a 4-DOF arm and a vertical facet, `ρ` (a rotation about the facet's normal) is
    /// out of reach and responds to yaw only through the obliquity of the view, relative to
    /// a goal angle that comes from the model; the marks' parallaxes measure the same yaw by
    /// stereo. 0 leaves the yaw to the parallaxes alone.
    pub angle_weight: f64,
}

impl Default for ServoConfig {
    fn default() -> Self {
        Self {
            gain: 0.5,
            max_step_m: 0.02,
            max_yaw_step_rad: 0.1,
            converged_m: 0.0005,
            converged_rad: 0.25f64.to_radians(),
            converged_steps: 4,
            converged_spread: 2.0,
            max_steps: 200,
            min_condition: 0.05,
            divergence_steps: 5,
            max_offset_m: 1.0,
            max_across_px: 4.0,
            max_across_ratio: 0.3,
            yaw_lever_m: 0.05,
            broyden: false,
            broyden_min_step_m: 0.001,
            broyden_max_fraction: 0.5,
            angle_weight: 1.0,
        }
    }
}

/// A [`ServoConfig`] field out of range.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
#[error("servo config: {field} = {value} is out of range ({expected})")]
pub struct ServoConfigError {
    pub field: &'static str,
    pub value: f64,
    pub expected: &'static str,
}

impl ServoConfig {
    pub fn validate(&self) -> Result<(), ServoConfigError> {
        let check = |field, value: f64, ok: bool, expected| if ok && value.is_finite() { Ok(()) } else { Err(ServoConfigError { field, value, expected }) };
        check("gain", self.gain, self.gain > 0.0 && self.gain < 1.0, "0 < gain < 1")?;
        check("max_step_m", self.max_step_m, self.max_step_m > 0.0, "> 0")?;
        check("max_yaw_step_rad", self.max_yaw_step_rad, self.max_yaw_step_rad > 0.0, "> 0")?;
        check("converged_m", self.converged_m, self.converged_m > 0.0, "> 0")?;
        check("converged_rad", self.converged_rad, self.converged_rad > 0.0, "> 0")?;
        check("converged_steps", self.converged_steps as f64, (1..=WINDOW as u32).contains(&self.converged_steps), "1..=16")?;
        check("converged_spread", self.converged_spread, self.converged_spread > 0.0, "> 0")?;
        check("max_steps", self.max_steps as f64, self.max_steps >= 1, ">= 1")?;
        check("min_condition", self.min_condition, self.min_condition > 0.0 && self.min_condition < 1.0, "0 < x < 1")?;
        check("divergence_steps", self.divergence_steps as f64, self.divergence_steps >= 2, ">= 2")?;
        check("max_offset_m", self.max_offset_m, self.max_offset_m > 0.0, "> 0")?;
        check("max_across_px", self.max_across_px, self.max_across_px > 0.0, "> 0")?;
        check("max_across_ratio", self.max_across_ratio, self.max_across_ratio >= 0.0, ">= 0")?;
        check("yaw_lever_m", self.yaw_lever_m, self.yaw_lever_m > 0.0, "> 0")?;
        check("broyden_min_step_m", self.broyden_min_step_m, self.broyden_min_step_m > 0.0, "> 0")?;
        check("broyden_max_fraction", self.broyden_max_fraction, self.broyden_max_fraction >= 0.0, ">= 0")?;
        check("angle_weight", self.angle_weight, self.angle_weight >= 0.0, ">= 0")?;
        Ok(())
    }
}

/// Why the servo stopped. Once failed, it stays failed until [`CoplanarityServo::reset`]:
/// the arm should stop.
#[derive(Debug, Clone, Copy, PartialEq, Error)]
pub enum ServoFailure {
    #[error("unusable measurement: {0}")]
    Geometry(#[from] GeometryError),
    #[error("gripper mark {mark} has parallax {across_px:.1} px across the epipolar lines (along: {along_px:.1} px): a tracker is off")]
    InconsistentParallax { mark: usize, along_px: f64, across_px: f64 },
    #[error("the Jacobian is singular (condition {condition:.2e}): marks collinear or the face edge-on")]
    SingularJacobian { condition: f64 },
    #[error("the servo computed a non-finite step")]
    NotFinite,
    #[error("diverged: estimated offset {offset_m:.4} m after growing {growing_steps} steps in a row")]
    Diverged { offset_m: f64, growing_steps: u32 },
    #[error("estimated offset {offset_m:.3} m is beyond max_offset_m: measurements or model are wrong")]
    ImplausibleOffset { offset_m: f64 },
    #[error("not converged after {steps} steps")]
    StepLimit { steps: u32 },
}

/// What one step decided.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum StepOutcome {
    /// Send [`ServoStep::motion`] and look again.
    Move,
    /// The averaged offset is within tolerance. [`ServoStep::motion`] is a last small move
    /// that removes it (at full gain, from the average of the last `converged_steps`
    /// estimates, so it is more precise than any single step): send it, then grasp.
    Converged,
    /// Stop the arm.
    Failed(ServoFailure),
}

/// One step's result: the decision plus everything worth logging.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoStep {
    /// 1-based count of steps since the last reset.
    pub step: u32,
    pub outcome: StepOutcome,
    /// The move to send (zero when `outcome` is `Failed`).
    pub motion: ToolMotion,
    /// The image error, when it could be measured.
    pub measurement: Option<Measurement>,
    /// `Ĵ⁺ e`: estimated offset of the gripper from the goal pose (NaN when not computed).
    pub offset: ToolMotion,
    /// Weighted residual `|W (e − Ĵ Ĵ⁺ e)|`, px: the part of the error no (x, y, z, yaw) move
    /// can remove (e.g. a facet tilted from vertical).
    pub unreachable_px: f64,
    /// Condition of the weighted, scaled Jacobian (NaN when not computed).
    pub condition: f64,
    /// The step was shortened to `max_step_m` / `max_yaw_step_rad`.
    pub clamped: bool,
}

/// The coplanarity servo's state between steps. See the module docs for the conventions.
///
/// ```
/// use handeye_vision::affine::AffineStereo;
/// use handeye_vision::servo::{CoplanarityServo, ServoConfig, ServoModel};
/// use nalgebra::{Matrix4x3, Vector4};
/// let model = AffineStereo {
///     m: Matrix4x3::new(800.0, 0.0, 150.0, 0.0, -20.0, -800.0, 780.0, -60.0, -140.0, 0.0, -25.0, -800.0),
///     c: Vector4::new(320.0, 240.0, 330.0, 238.0),
///     residual_rms_px: 0.0,
///     disparity_range_px: [0.0, 0.0],
/// };
/// let servo = CoplanarityServo::new(ServoModel::new(&model).unwrap(), ServoConfig::default()).unwrap();
/// assert_eq!(servo.steps(), 0);
/// ```
#[derive(Debug, Clone)]
pub struct CoplanarityServo {
    model: ServoModel,
    config: ServoConfig,
    /// Broyden's learned correction to the model Jacobian, in scaled columns
    /// `(x, y, z, yaw · yaw_lever_m)`.
    correction: Matrix6x4<f64>,
    /// Error measured and motion sent at the previous step.
    previous: Option<(Vector6<f64>, Vector4<f64>)>,
    steps: u32,
    /// Ring of the last offset estimates, each with the motion sent up to its step.
    window: [(Vector4<f64>, Vector4<f64>); WINDOW],
    /// Sum of all motions sent since the last reset, `(x, y, z, yaw)`.
    moved: Vector4<f64>,
    growing: u32,
    last_offset_m: f64,
    failed: Option<ServoFailure>,
}

impl CoplanarityServo {
    pub fn new(model: ServoModel, config: ServoConfig) -> Result<Self, ServoConfigError> {
        config.validate()?;
        Ok(Self::fresh(model, config))
    }

    fn fresh(model: ServoModel, config: ServoConfig) -> Self {
        Self {
            model,
            config,
            correction: Matrix6x4::zeros(),
            previous: None,
            steps: 0,
            window: [(Vector4::zeros(), Vector4::zeros()); WINDOW],
            moved: Vector4::zeros(),
            growing: 0,
            last_offset_m: f64::INFINITY,
            failed: None,
        }
    }

    pub fn model(&self) -> &ServoModel {
        &self.model
    }

    pub fn config(&self) -> &ServoConfig {
        &self.config
    }

    /// Steps taken since the last reset.
    pub fn steps(&self) -> u32 {
        self.steps
    }

    /// Broyden's current correction to the model Jacobian, in the units of
    /// [`ServoModel::jacobian`] (zero when Broyden is off): the Jacobian used is the sum.
    pub fn jacobian_correction(&self) -> Matrix6x4<f64> {
        self.correction * Matrix4::from_diagonal(&self.scale().map(|x| 1.0 / x))
    }

    /// Starts afresh (new target, or after a failure), keeping model and config.
    pub fn reset(&mut self) {
        *self = Self::fresh(self.model, self.config);
    }

    /// Replaces the model (after re-calibration); the Broyden correction is dropped.
    pub fn set_model(&mut self, model: ServoModel) {
        self.model = model;
        self.correction = Matrix6x4::zeros();
        self.previous = None;
    }

    /// Tells the servo the motion the robot really made since the last step, when it differs
    /// from the one commanded (e.g. clipped by the controller). Used by the Broyden update and
    /// the convergence average.
    pub fn set_executed_motion(&mut self, motion: &ToolMotion) {
        if let Some((_, q)) = self.previous.as_mut() {
            self.moved += motion.q() - *q;
            *q = motion.q();
        }
    }

    fn scale(&self) -> Vector4<f64> {
        Vector4::new(1.0, 1.0, 1.0, 1.0 / self.config.yaw_lever_m)
    }

    fn outcome(&mut self, step: ServoStep) -> ServoStep {
        if let StepOutcome::Failed(f) = step.outcome {
            self.failed = Some(f);
        }
        step
    }

    /// One look-and-move step: measure, decide, return the move to make.
    pub fn step(&mut self, target: &StereoFrame, gripper: &GripperView, goal: &ServoGoal) -> ServoStep {
        let nan_motion = ToolMotion { translation_m: Vector3::repeat(f64::NAN), yaw_rad: f64::NAN };
        let mut out = ServoStep {
            step: self.steps,
            outcome: StepOutcome::Move,
            motion: ToolMotion::default(),
            measurement: None,
            offset: nan_motion,
            unreachable_px: f64::NAN,
            condition: f64::NAN,
            clamped: false,
        };
        if let Some(f) = self.failed {
            out.outcome = StepOutcome::Failed(f);
            return out;
        }
        self.steps += 1;
        out.step = self.steps;
        if self.steps > self.config.max_steps {
            out.outcome = StepOutcome::Failed(ServoFailure::StepLimit { steps: self.config.max_steps });
            return self.outcome(out);
        }
        let fail = |mut out: ServoStep, f: ServoFailure| {
            out.outcome = StepOutcome::Failed(f);
            out
        };

        let m = match measure(target, gripper, goal, &self.model.epipolar_right()) {
            Ok(m) => m,
            Err(e) => return self.outcome(fail(out, e.into())),
        };
        out.measurement = Some(m);
        for (mark, p) in m.parallax.iter().enumerate() {
            if p.across_px.abs() > self.config.max_across_px + self.config.max_across_ratio * p.along_px.abs() {
                let f = ServoFailure::InconsistentParallax { mark, along_px: p.along_px, across_px: p.across_px };
                return self.outcome(fail(out, f));
            }
        }
        let j_model = match self.model.jacobian(target, gripper) {
            Ok(j) => j,
            Err(e) => return self.outcome(fail(out, e.into())),
        };

        // Scaled columns q̃ = (x, y, z, yaw · lever): all in metres.
        let scale = self.scale();
        let j_scaled_model = j_model * Matrix4::from_diagonal(&scale);
        if self.config.broyden {
            self.broyden_update(&j_scaled_model, &m.error);
        }
        let j_scaled = j_scaled_model + self.correction;

        // Rows weighted to pixel-sized numbers and columns all in metres (yaw scaled by the
        // lever): every entry is pixels per metre, so the singular values compare how well
        // each direction of motion is seen, whatever the units of the rows and columns.
        let mut weights = m.row_weights;
        weights[5] *= self.config.angle_weight;
        let mut jw = j_scaled;
        for r in 0..6 {
            jw.row_mut(r).scale_mut(weights[r]);
        }
        let ew = m.error.component_mul(&weights);
        let svd = jw.svd(true, true);
        let (smax, smin) = (svd.singular_values.max(), svd.singular_values.min());
        let condition = smin / smax;
        out.condition = condition;
        if condition.is_nan() || condition < self.config.min_condition {
            let f = if condition.is_finite() || smax == 0.0 { ServoFailure::SingularJacobian { condition: if smax == 0.0 { 0.0 } else { condition } } } else { ServoFailure::NotFinite };
            return self.outcome(fail(out, f));
        }
        let pinv = match svd.pseudo_inverse(0.0) {
            Ok(p) => p,
            Err(_) => return self.outcome(fail(out, ServoFailure::NotFinite)),
        };
        let q_scaled = pinv * ew;
        out.unreachable_px = (ew - jw * q_scaled).norm();
        let q_offset = q_scaled.component_mul(&scale);
        if !q_offset.iter().all(|x| x.is_finite()) {
            return self.outcome(fail(out, ServoFailure::NotFinite));
        }
        out.offset = ToolMotion::from_q(&q_offset);

        // Convergence and divergence, judged on the estimated pose offset.
        let offset_m = q_scaled.norm();
        if offset_m > self.last_offset_m && offset_m > 4.0 * self.config.converged_m {
            self.growing += 1;
        } else {
            self.growing = 0;
        }
        self.last_offset_m = offset_m;
        if offset_m > self.config.max_offset_m {
            return self.outcome(fail(out, ServoFailure::ImplausibleOffset { offset_m }));
        }
        if self.growing >= self.config.divergence_steps {
            let f = ServoFailure::Diverged { offset_m, growing_steps: self.growing };
            return self.outcome(fail(out, f));
        }
        self.window[(self.steps as usize - 1) % WINDOW] = (q_offset, self.moved);
        let k = self.config.converged_steps as usize;
        if self.steps as usize >= k {
            // Each estimate, carried forward by what was sent since, estimates the offset now.
            let now = |i: usize| {
                let (est, moved_then) = self.window[(self.steps as usize - 1 - i) % WINDOW];
                est + (self.moved - moved_then)
            };
            let mut mean = Vector4::zeros();
            for i in 0..k {
                mean += now(i);
            }
            mean /= k as f64;
            let (mut spread_m, mut spread_rad) = (0.0f64, 0.0f64);
            for i in 0..k {
                let d = now(i) - mean;
                spread_m = spread_m.max(Vector3::new(d[0], d[1], d[2]).norm());
                spread_rad = spread_rad.max(d[3].abs());
            }
            let t = Vector3::new(mean[0], mean[1], mean[2]).norm();
            let agree = spread_m <= self.config.converged_spread * self.config.converged_m && spread_rad <= self.config.converged_spread * self.config.converged_rad;
            if t <= self.config.converged_m && mean[3].abs() <= self.config.converged_rad && agree {
                out.outcome = StepOutcome::Converged;
                out.motion = ToolMotion::from_q(&-mean);
                self.moved -= mean;
                self.previous = Some((m.error, -mean));
                return out;
            }
        }

        let mut q = -self.config.gain * q_offset;
        let t = Vector3::new(q[0], q[1], q[2]).norm();
        let shrink = (self.config.max_step_m / t).min(self.config.max_yaw_step_rad / q[3].abs()).min(1.0);
        if shrink < 1.0 {
            q *= shrink;
            out.clamped = true;
        }
        out.motion = ToolMotion::from_q(&q);
        self.moved += q;
        self.previous = Some((m.error, q));
        out
    }

    /// Broyden rank-1 update of the correction from the last step's motion and the error
    /// change it caused: `C += (Δe − Ĵ Δq̃) Δq̃ᵀ / |Δq̃|²`, each row bounded.
    fn broyden_update(&mut self, j_scaled_model: &Matrix6x4<f64>, error: &Vector6<f64>) {
        let Some((e_prev, q_prev)) = self.previous else { return };
        let dq = q_prev.component_div(&self.scale());
        let len2 = dq.norm_squared();
        if len2.sqrt() < self.config.broyden_min_step_m {
            return;
        }
        let j = j_scaled_model + self.correction;
        let r = (error - e_prev) - j * dq;
        let updated = self.correction + r * dq.transpose() / len2;
        for row in 0..6 {
            let limit = self.config.broyden_max_fraction * j_scaled_model.row(row).norm();
            let mut c = updated.row(row).into_owned();
            let n = c.norm();
            if n > limit {
                c *= limit / n;
            }
            if c.iter().all(|x| x.is_finite()) {
                self.correction.set_row(row, &c);
            }
        }
    }
}
