//! Servo (METHOD.md §3): look-and-move coplanarity servo. Each step measures on a fresh
//! frame after the previous move has arrived and settled, asks
//! [`CoplanarityServo::step`](handeye_vision::servo::CoplanarityServo::step) for a move, and
//! sends it as a `MoveBy`. On convergence the step's last small move is made and, once it
//! has arrived, the phase hands over to the grasp (telemetry then says `grasp`: that moment
//! is when the simulator judges the placement).
//!
//! **Goal** (thesis §6.3.4). The plate (normal = the jaws' closing axis) is made *coplanar*
//! with the facet: zero parallax for all three marks, which no error of the model's scale
//! can shift. Within the plane, the reference point goes straight above the facet's centre,
//! high enough that the tool point is `grasp_height_m + standoff_above_m` above the table:
//! the jaws, `tool_from_reference` behind the plate, then hang behind the facet plane and
//! above the block. The goal is held in the facet's frame in metres ([`FacetGoal`]: the
//! reference point and the marks relative to the facet origin, the plate axis along the
//! facet) and turned into image terms at every step, with the target frames averaged since
//! the last step, so that the facet's transfer errors (extrapolated ~140 px from a facet
//! 30-60 px across) are the same in measurement and goal and cancel. Its height comes from
//! the robot's kinematics ([`FacetGoal::image_goal_at_height`]). The facet's normal is the
//! direction of the model's parallax gradient through the facet's transfer, so the marks'
//! goal parallaxes differ only by what the images say. The grasp then moves by metric
//! offsets the robot's kinematics make exact: along the plate normal (as the servo left it)
//! until the jaw centre is `depth/2` behind the facet, and down to the grasp height.
//!
//! **Coarse approach, local cage.** The servo starts from the goal pose as the global model
//! reconstructs it (a `MoveTo`), then visits a small cage around it (`local_cage_m`
//! sideways and up, never down: the jaws hang over the block) and fits a local affine model:
//! the global model's image scale is the cage's, while near the target it differs by ~10 %
//! (perspective). The servo's Jacobian, the facet's normal and the image goal use the local
//! model. A camera knocked before the local fit restarts the cage.
//!
//! **Yaw centre.** The servo turns about the plate's reference point; the robot turns about
//! the tool point. Each move is converted: `Δtool = Δref + (Rz(Δψ) − I)(tool − ref)`, with
//! `tool − ref` from the gripper model at the current yaw.

use handeye_vision::affine::AffineStereo;
use handeye_vision::servo::{
    CoplanarityServo, FacetGoal, GripperView, ToolMotion, PlaneTransfer, ServoConfig, ServoModel, StepOutcome, StereoFrame, StereoPoint,
};
use handeye_vision::tracker::{Role, View};
use handeye_wire::report::FailureKind;
use handeye_wire::RejectReason;
use nalgebra::Vector3;

use super::step::{timed_out, Cmd, Cycle, MovePoll, MoveWait, Resumed, Step};
use crate::fault::Fault;
use crate::gripper::{gripper_view, plate_normal, stereo_frame, tool_from_reference};
use crate::mission::{Mission, ServoTraceRow};

/// Offsets of the local cage points from the approach pose, in units of `local_cage_m`:
/// sideways at the approach height and upwards, never down (the jaws hang right above the
/// block there).
const LOCAL_CAGE: [[f64; 3]; 7] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 2.0]];

/// A target frame further than this from the running mean (any of its origin or basis
/// vectors' ends, px) means the target moved: the mean starts again from it.
const TARGET_JUMP_PX: f64 = 3.0;

/// A target re-found further than this from where it was lost moved (a nudged block), px.
pub const TARGET_MOVED_PX: f64 = 4.0;

#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    /// The coarse approach `MoveTo` is to be sent.
    Approach,
    /// Visiting local cage point `i`; `n` samples taken there.
    LocalCage { i: usize, n: u32 },
    /// Look-and-move; `converging` once the final move was sent.
    Servo { converging: bool },
}

/// Running mean of the target's stereo frame. The target stands still while the servo
/// works, so its trackers' frame-to-frame jitter (tenths of a pixel per corner, amplified
/// some fivefold at the plate) averages out; a jump starts the mean again. No allocation.
#[derive(Debug, Clone, Copy, Default)]
struct TargetMean {
    sum: [f64; 12],
    n: u32,
}

impl TargetMean {
    fn flat(f: &StereoFrame) -> [f64; 12] {
        let (l, r) = (&f.left, &f.right);
        [l.o[0], l.o[1], l.e1[0], l.e1[1], l.e2[0], l.e2[1], r.o[0], r.o[1], r.e1[0], r.e1[1], r.e2[0], r.e2[1]]
    }

    fn add(&mut self, f: &StereoFrame) {
        let x = Self::flat(f);
        if !x.iter().all(|v| v.is_finite()) {
            return;
        }
        if let Some(mean) = self.mean() {
            let m = Self::flat(&mean);
            // Origin and the ends of the basis vectors (origin + e), each view.
            let far = |k: usize| {
                let d = |i: usize| (x[k + i] - m[k + i], x[k + i + 1] - m[k + i + 1]);
                let (o, e1, e2) = (d(0), d(2), d(4));
                let len = |a: (f64, f64)| a.0.hypot(a.1);
                len(o).max(len((o.0 + e1.0, o.1 + e1.1))).max(len((o.0 + e2.0, o.1 + e2.1))) > TARGET_JUMP_PX
            };
            if far(0) || far(6) {
                *self = Self::default();
            }
        }
        for (s, v) in self.sum.iter_mut().zip(x) {
            *s += v;
        }
        self.n += 1;
    }

    fn mean(&self) -> Option<StereoFrame> {
        if self.n == 0 {
            return None;
        }
        let k = f64::from(self.n);
        let s = self.sum.map(|v| v / k);
        let frame = |i: usize| handeye_vision::servo::ViewFrame { o: [s[i], s[i + 1]], e1: [s[i + 2], s[i + 3]], e2: [s[i + 4], s[i + 5]] };
        Some(StereoFrame { left: frame(0), right: frame(6) })
    }
}

pub struct ServoPhase {
    start_ns: u64,
    stage: Stage,
    wait: Option<MoveWait>,
    servo: CoplanarityServo,
    config: ServoConfig,
    /// The goal in the facet's frame, metric; turned into image terms at every step with
    /// the target as seen then (see `FacetGoal`).
    goal: FacetGoal,
    /// Metric offset of the reference point's goal from the facet origin, robot frame.
    offset_m: Vector3<f64>,
    /// Target frames since the last servo step (for the step's measurement and goal)...
    target_recent: TargetMean,
    /// ...and since the local cage began (for the facet's orientation in the local model).
    target_cage: TargetMean,
    approach_pose: ([f64; 3], f64),
    local_robot_m: Vec<Vector3<f64>>,
    local_image_px: Vec<[f64; 4]>,
    acc: [f64; 7],
    /// The planned grasp site in the target trackers' templates (left, right), if planned.
    site_template: Option<[[f64; 2]; 2]>,
    /// Depth of the block behind the facet, m.
    depth_m: f64,
    /// The open-loop move from the servo's goal (plate coplanar with the facet) to above the
    /// grasp: along the plate normal until the jaw centre is `depth/2` behind the facet, m.
    /// Set again from the plate's final yaw when the servo converges. The grasp then comes
    /// straight down.
    pub approach_m: [f64; 3],
    /// The target moved while lost: the next cycle starts the phase afresh on it.
    restart: bool,
}

fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    a - t * ((a + std::f64::consts::PI) / t).floor()
}

/// Geometry the servo cannot work with: its goal, its model or its step.
fn unusable(detail: String) -> Fault {
    Fault::new(FailureKind::NotConverged, detail)
}

fn views(m: &Mission) -> Result<(StereoFrame, GripperView), Fault> {
    let get = |role, view| {
        m.trackers.get(role, view).ok_or_else(|| Fault::new(FailureKind::Internal, format!("servo: no {role:?} tracker in the {view:?} view")))
    };
    let target = stereo_frame(get(Role::Target, View::Left)?, get(Role::Target, View::Right)?);
    let gripper = gripper_view(&m.plate, get(Role::Gripper, View::Left)?, get(Role::Gripper, View::Right)?);
    Ok((target, gripper))
}

/// The facet's horizontal unit normal, towards the cameras, as the model sees the target:
/// the direction of the parallax gradient `ê_rᵀ (M_r − A M_l)`, the one motion that moves a
/// point off the facet's plane in the images. Directions in the facet then have zero
/// parallax by construction, so the marks' goal parallaxes differ only by the facet's own
/// measured transfer, not by the model's reconstruction of the facet's tilt (which under
/// perspective is off by a degree or more, and would leave the plate turned by as much).
fn facet_normal(model: &ServoModel, toward_cameras: &Vector3<f64>, target: &StereoFrame) -> Result<Vector3<f64>, Fault> {
    let transfer = PlaneTransfer::from_frames(target).map_err(|e| unusable(format!("servo: target: {e}")))?;
    let mut n: Vector3<f64> = model.parallax_gradient(&transfer).transpose();
    if n.norm().is_nan() || n.norm() <= 1e-9 {
        return Err(unusable("servo: the target facet has no parallax gradient (seen edge-on?)".into()));
    }
    n /= n.norm();
    if n.dot(toward_cameras) < 0.0 {
        n = -n;
    }
    if n.z.abs() > 25f64.to_radians().sin() {
        return Err(unusable(format!("servo: the target facet is {:.0}° from vertical; the jaws close horizontally", n.z.abs().asin().to_degrees())));
    }
    Ok(Vector3::new(n.x, n.y, 0.0).normalize())
}

/// The metric goal for a reference-point `offset` from the facet origin, with the plate's
/// horizontal axis `a` lying along the facet: every mark at its place in the facet's plane.
fn facet_goal(m: &Mission, offset: &Vector3<f64>, a: &Vector3<f64>) -> FacetGoal {
    let g = &m.cfg.gripper;
    let at = |p: [f64; 2]| offset + a * (p[0] - g.reference_m[0]) + Vector3::z() * (p[1] - g.reference_m[1]);
    FacetGoal { reference_m: *offset, marks_m: g.marks_m.map(at), axis: *a }
}

/// How far the planned grasp site (template points `st`, left and right view) lies from the
/// target's frame origin along the facet's horizontal axis `a`, m, as `model` reconstructs
/// both from the target trackers now (the calibration lever cancels in the difference).
fn site_along_m(m: &Mission, model: &ServoModel, st: &[[f64; 2]; 2], a: &Vector3<f64>) -> Result<f64, Fault> {
    let (target, _) = views(m)?;
    let at = |view, k: usize| m.trackers.get(Role::Target, view).map(|t| t.image_from_template(nalgebra::Vector2::new(st[k][0], st[k][1])));
    let (Some(l), Some(r)) = (at(View::Left, 0), at(View::Right, 1)) else { return Err(Fault::new(FailureKind::Internal, "servo: no target trackers")) };
    let site = model.reconstruct(&StereoPoint { left: [l.x, l.y], right: [r.x, r.y] });
    let origin = model.reconstruct(&StereoPoint { left: target.left.o, right: target.right.o });
    Ok(a.dot(&(site - origin)))
}

impl ServoPhase {
    /// Plans the goal and the coarse approach from the current views (called once, on entry).
    pub fn new(m: &mut Mission, c: &Cycle<'_>) -> Result<Self, Fault> {
        let cal = m.calibration.get().cloned().ok_or_else(|| Fault::new(FailureKind::Internal, "servo: not calibrated"))?;
        let target_spec = m.targeting.target().cloned().ok_or_else(|| Fault::new(FailureKind::Internal, "servo: no target"))?;
        let depth_m = target_spec.depth_m.max(0.0);
        let s = m.cfg.servo.clone();
        let config = ServoConfig {
            gain: s.control.gain,
            max_step_m: s.limits.max_step_m,
            max_yaw_step_rad: s.limits.max_yaw_step_deg.to_radians(),
            converged_m: s.convergence.converged_m,
            converged_rad: s.convergence.converged_deg.to_radians(),
            converged_steps: s.convergence.converged_steps,
            max_steps: s.convergence.max_steps,
            broyden: s.control.broyden,
            max_across_px: s.limits.max_across_px,
            max_across_ratio: s.limits.max_across_ratio,
            yaw_lever_m: s.control.yaw_lever_m,
            min_condition: s.control.min_condition,
            angle_weight: s.control.angle_weight,
            ..ServoConfig::default()
        };
        let servo = CoplanarityServo::new(cal.servo_model, config).map_err(|e| unusable(format!("servo: {e}")))?;
        let (target, _) = views(m)?;
        let model = &cal.servo_model;
        let n = facet_normal(model, &cal.model.toward_cameras(), &target)?;
        let up = Vector3::z();
        let a = up.cross(&n);
        // The model maps tool positions to the reference point's images, so a scene point P
        // reconstructs as P − (reference − tool) at the calibration's yaw.
        let yaw_now = f64::from(c.robot.tool_yaw_rad);
        let cal_lever = tool_from_reference(&m.cfg.gripper, m.calibration.yaw_rad().unwrap_or(yaw_now));
        let facet_origin = model.reconstruct(&StereoPoint { left: target.left.o, right: target.right.o }) - cal_lever;
        // A planned grasp site (thesis §6.3.4: "expressed in a coordinate system based on the
        // target facet"): the goal moves along the facet by the site's offset from the facet
        // origin, measured again through the local model once it is fitted.
        let site_template = target_spec.site_template;
        let along_m = match site_template {
            Some(st) => site_along_m(m, model, &st, &a)?,
            None => 0.0,
        };
        // Thesis §6.3.4: make the plate coplanar with the facet (zero parallax: insensitive to
        // the model's scale), the tool above the facet's centre at the stand-off height with
        // the jaws behind the facet plane; the grasp then moves by metric offsets that the
        // robot's own kinematics make exact.
        let tool_z = m.cfg.grasp.table_z_m + s.approach.grasp_height_m + s.approach.standoff_above_m;
        let t = m.cfg.gripper.tool_from_reference_m;
        // Reference point relative to the facet origin: in the facet plane, straight above
        // the planned site (the origin when there is none).
        let offset_m = up * (tool_z - facet_origin.z - t[1]) + a * (along_m - t[0]);
        let tool_rel = offset_m + a * t[0] + up * t[1] + n * t[2];
        let tool_goal = facet_origin + tool_rel;
        let n0 = m.cfg.gripper.normal_at_zero_yaw;
        let yaw_goal = yaw_now + wrap(n.y.atan2(n.x) - n0[1].atan2(n0[0]) - yaw_now);
        m.servo.restart();
        m.reporting.snapshot("servo_start");
        m.reporting.set_status("servo: coarse approach from the reconstruction");
        tracing::info!(?offset_m, along_m, ?tool_goal, yaw_goal, "servo plan");
        let mut target_recent = TargetMean::default();
        target_recent.add(&target);
        Ok(Self {
            start_ns: c.time_ns,
            stage: Stage::Approach,
            wait: None,
            servo,
            config,
            goal: facet_goal(m, &offset_m, &a),
            offset_m,
            target_recent,
            target_cage: TargetMean::default(),
            approach_pose: ([tool_goal.x, tool_goal.y, tool_goal.z], yaw_goal),
            restart: false,
            local_robot_m: Vec::with_capacity(LOCAL_CAGE.len()),
            local_image_px: Vec::with_capacity(LOCAL_CAGE.len()),
            acc: [0.0; 7],
            site_template,
            depth_m,
            approach_m: (n * (-t[2] - depth_m / 2.0)).into(),
        })
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(self.start_ns, c.time_ns, m.cfg.servo.convergence.timeout_s) {
            return Step::fail(FailureKind::NotConverged, format!("servo: not converged after {} s ({} steps)", m.cfg.servo.convergence.timeout_s, m.servo.steps()));
        }
        if self.restart {
            let start_ns = self.start_ns;
            return match ServoPhase::new(m, c) {
                Ok(p) => {
                    *self = p;
                    self.start_ns = start_ns;
                    Step::Stay(Cmd::HOLD)
                }
                Err(fault) => Step::Fail(fault),
            };
        }
        // Every frame adds to the target's running means (it stands still; the arm moves).
        if let Ok((target, _)) = views(m) {
            self.target_recent.add(&target);
            if matches!(self.stage, Stage::LocalCage { .. }) {
                self.target_cage.add(&target);
            }
        }
        if let Some(w) = self.wait.as_mut() {
            match w.poll(c, m.cfg.servo.settle_frames) {
                MovePoll::Pending => return Step::Stay(Cmd::HOLD),
                MovePoll::Rejected(code) => {
                    return Step::fail(FailureKind::RobotRefused, format!("servo: the robot refused a move ({:?}): {}", self.stage, RejectReason::text_of(code)));
                }
                MovePoll::Done => self.wait = None,
            }
        }
        let speed = m.cfg.servo.speed_mps;
        match self.stage {
            Stage::Approach => {
                self.wait = Some(MoveWait::new(c.seq, c.frame_index));
                let (p, yaw) = self.approach_pose;
                self.stage = if m.cfg.servo.approach.local_cage_m > 0.0 {
                    self.target_cage = TargetMean::default();
                    Stage::LocalCage { i: 0, n: 0 }
                } else {
                    m.reporting.set_status("servo: aligning the plate with the facet");
                    Stage::Servo { converging: false }
                };
                Step::Stay(Cmd::move_to(p, yaw, speed))
            }
            Stage::LocalCage { i, n } => self.local_cage(m, c, i, n),
            Stage::Servo { converging: true } => {
                m.reporting.snapshot("servo_converged");
                m.reporting.set_status("servo converged");
                Step::Next(Cmd::HOLD)
            }
            Stage::Servo { converging: false } => self.look_and_move(m, c),
        }
    }

    /// Picks up again after the arm held `held_ns` for a lost tracker: the time held does not
    /// count, the pending move is void (the arm stopped where it was), the servo starts
    /// afresh from a new look (its Broyden memory of the interrupted move is dropped).
    /// `knock`: one camera moved, its image by `shift_px`: its affine model's offset moves
    /// with it (the first-order effect of a small knock). The goal, held in the facet's
    /// frame, needs nothing: it is turned into image terms from the re-acquired target.
    ///
    /// A loss before the local model was fitted (during the approach or the local cage)
    /// voids the cage's samples so far: the cage starts again from the approach pose and
    /// fits the local model to the cameras (and the target) as they are now.
    ///
    /// A target re-found more than [`TARGET_MOVED_PX`] from where it was lost (and no
    /// camera moved) has been moved: the servo starts over on it from its approach, with the
    /// goal, the facet's normal and the local model taken again where it is now.
    pub fn resume(&mut self, m: &mut Mission, held_ns: u64, knock: Option<(View, [f64; 2])>, target_shift_px: f64) -> Resumed {
        self.start_ns = self.start_ns.saturating_add(held_ns);
        m.reporting.set_status("servo: resumed after re-acquiring");
        if knock.is_none() && target_shift_px > TARGET_MOVED_PX {
            tracing::warn!(target_shift_px, "servo: the target came back elsewhere: it moved; starting the servo again on it");
            m.reporting.set_status("servo: the target moved; starting again on it");
            self.restart = true;
            return Resumed::TargetMoved { target_shift_px };
        }
        let Some((view, shift_px)) = knock else {
            self.wait = None;
            self.target_recent = TargetMean::default();
            if matches!(self.stage, Stage::Approach | Stage::LocalCage { .. }) {
                self.local_robot_m.clear();
                self.local_image_px.clear();
                self.target_cage = TargetMean::default();
                self.stage = Stage::Approach;
            } else {
                self.stage = Stage::Servo { converging: false };
            }
            self.servo.reset();
            return Resumed::Resumed;
        };
        self.wait = None;
        self.target_recent = TargetMean::default();
        self.stage = if matches!(self.stage, Stage::Approach | Stage::LocalCage { .. }) {
            self.local_robot_m.clear();
            self.local_image_px.clear();
            self.target_cage = TargetMean::default();
            Stage::Approach
        } else {
            Stage::Servo { converging: false }
        };
        let rows = if view == View::Left { [0, 1] } else { [2, 3] };
        if let Some(cal) = m.calibration.get_mut() {
            cal.model.c[rows[0]] += shift_px[0];
            cal.model.c[rows[1]] += shift_px[1];
            if let Ok(model) = ServoModel::new(&cal.model) {
                cal.servo_model = model;
            }
        }
        // The model in use (the local one, when there is one) moves with the image too.
        let model = self.servo.model().shifted(view == View::Left, shift_px);
        match CoplanarityServo::new(model, self.config) {
            Ok(servo) => self.servo = servo,
            Err(_) => self.servo.reset(),
        }
        Resumed::KnockFollowed { view }
    }

    /// At local cage point `i` (arrived and settled): sample, then move on; after the last,
    /// fit the local model and start the servo with it.
    fn local_cage(&mut self, m: &mut Mission, c: &Cycle<'_>, i: usize, n: u32) -> Step {
        let (Some(l), Some(r)) = (m.trackers.get(Role::Gripper, View::Left), m.trackers.get(Role::Gripper, View::Right)) else {
            return Step::fail(FailureKind::Internal, "servo: no gripper trackers");
        };
        let st = nalgebra::Vector2::new(m.plate.reference_st[0], m.plate.reference_st[1]);
        let (pl, pr) = (l.image_from_template(st), r.image_from_template(st));
        let p = c.robot.tool_pos_m.map(f64::from);
        for (acc, v) in self.acc.iter_mut().zip([pl.x, pl.y, pr.x, pr.y, p[0], p[1], p[2]]) {
            *acc = if n == 0 { v } else { *acc + v };
        }
        let n = n + 1;
        if n < m.cfg.calibration.samples {
            self.stage = Stage::LocalCage { i, n };
            return Step::Stay(Cmd::HOLD);
        }
        let k = f64::from(n);
        self.local_image_px.push([self.acc[0] / k, self.acc[1] / k, self.acc[2] / k, self.acc[3] / k]);
        self.local_robot_m.push(Vector3::new(self.acc[4] / k, self.acc[5] / k, self.acc[6] / k));
        let speed = m.cfg.servo.speed_mps;
        if i + 1 < LOCAL_CAGE.len() {
            self.stage = Stage::LocalCage { i: i + 1, n: 0 };
            self.wait = Some(MoveWait::new(c.seq, c.frame_index));
            let d = m.cfg.servo.approach.local_cage_m;
            let (p0, yaw) = self.approach_pose;
            let o = LOCAL_CAGE[i + 1];
            m.reporting.set_status("servo: local cage around the approach pose");
            return Step::Stay(Cmd::move_to([p0[0] + d * o[0], p0[1] + d * o[1], p0[2] + d * o[2]], yaw, speed));
        }
        // Fit (7 points: microseconds, so on the loop), then back to the approach pose.
        let local = AffineStereo::fit(&self.local_robot_m, &self.local_image_px).map_err(|e| format!("servo: local fit: {e}"));
        let local = match local.and_then(|f| ServoModel::new(&f).map(|s| (f, s)).map_err(|e| format!("servo: local model: {e}"))) {
            Ok(x) => x,
            Err(e) => return Step::Fail(unusable(e)),
        };
        if local.0.residual_rms_px > m.cfg.calibration.max_residual_px {
            return Step::Fail(unusable(format!("servo: local cage residual {:.2} px RMS is too large", local.0.residual_rms_px)));
        }
        // The facet's orientation again, through the local model and from the target frames
        // averaged over the whole visit: the plate's marks are placed along it.
        let Some(target) = self.target_cage.mean().or_else(|| self.target_recent.mean()) else {
            return Step::fail(FailureKind::Internal, "servo: no target frames during the local cage");
        };
        let toward = m.calibration.get().map(|cal| cal.model.toward_cameras()).unwrap_or_else(|| local.0.toward_cameras());
        let n = match facet_normal(&local.1, &toward, &target) {
            Ok(n) => n,
            Err(e) => return Step::Fail(e),
        };
        let a = Vector3::z().cross(&n);
        // The offset along the facet follows the new axis (and the planned site's distance
        // along it, through the local model); its height stays.
        if let Some(st) = self.site_template {
            let along_m = match site_along_m(m, &local.1, &st, &a) {
                Ok(x) => x,
                Err(e) => return Step::Fail(e),
            };
            let t0 = m.cfg.gripper.tool_from_reference_m[0];
            self.offset_m = Vector3::z() * self.offset_m.z + a * (along_m - t0);
        }
        self.goal = facet_goal(m, &self.offset_m, &a);
        self.servo = match CoplanarityServo::new(local.1, self.config) {
            Ok(s) => s,
            Err(e) => return Step::Fail(unusable(format!("servo: {e}"))),
        };
        tracing::info!(residual_px = local.0.residual_rms_px, frames = self.target_cage.n, ?n, "local model");
        self.stage = Stage::Servo { converging: false };
        self.wait = Some(MoveWait::new(c.seq, c.frame_index));
        m.reporting.set_status("servo: aligning the plate with the facet");
        let (p0, yaw) = self.approach_pose;
        Step::Stay(Cmd::move_to(p0, yaw, speed))
    }

    fn look_and_move(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        let (now, gripper) = match views(m) {
            Ok(v) => v,
            Err(e) => return Step::Fail(e),
        };
        // The target as seen over the frames since the last step (it stood still), and the
        // goal turned into image terms with that same view of it.
        let target = self.target_recent.mean().unwrap_or(now);
        self.target_recent = TargetMean::default();
        // The goal's height comes from the robot's kinematics (see `image_goal_at_height`).
        let above_goal_m = f64::from(c.robot.tool_pos_m[2]) - self.approach_pose.0[2];
        let goal = match self.goal.image_goal_at_height(self.servo.model(), &target, &gripper.reference, above_goal_m) {
            Ok(g) => g,
            Err(e) => return Step::Fail(unusable(format!("servo: goal: {e}"))),
        };
        if tracing::enabled!(tracing::Level::TRACE) {
            let corners = |role, view| m.trackers.get(role, view).map(|t| t.corners().map(|p| [p.x, p.y]).collect::<Vec<_>>());
            tracing::trace!(frame = c.frame_index, target_l = ?corners(Role::Target, View::Left), target_r = ?corners(Role::Target, View::Right), plate_l = ?corners(Role::Gripper, View::Left), plate_r = ?corners(Role::Gripper, View::Right), "servo corners");
        }
        let step = self.servo.step(&target, &gripper, &goal);
        m.servo.set_steps(step.step);
        if let Some(meas) = step.measurement {
            m.servo.set_error(meas.error.as_slice());
            tracing::debug!(
                step = step.step,
                frame = c.frame_index,
                error = ?meas.error.as_slice(),
                across = ?meas.parallax.map(|p| p.across_px),
                offset_m = ?step.offset.translation_m.as_slice(),
                offset_yaw_deg = step.offset.yaw_rad.to_degrees(),
                condition = step.condition,
                tool_m = ?c.robot.tool_pos_m,
                tool_yaw_deg = f64::from(c.robot.tool_yaw_rad).to_degrees(),
                "servo step"
            );
        }
        m.servo.push(ServoTraceRow {
            step: step.step,
            frame: c.frame_index,
            error: m.servo.error(),
            offset_m: step.offset.translation_m.norm(),
            offset_yaw_rad: step.offset.yaw_rad,
        });
        match step.outcome {
            StepOutcome::Failed(f) => {
                if let Ok(j) = self.servo.model().jacobian(&target, &gripper) {
                    tracing::warn!(jacobian = ?j, ?target, ?gripper, measurement = ?step.measurement, "servo failed");
                }
                Step::Fail(unusable(format!("servo: {f}")))
            }
            StepOutcome::Move | StepOutcome::Converged => {
                if step.outcome == StepOutcome::Converged {
                    self.stage = Stage::Servo { converging: true };
                    // Coplanar now: the plate's normal is the best estimate of the facet's,
                    // and the open-loop approach goes along it.
                    let n = plate_normal(&m.cfg.gripper, f64::from(c.robot.tool_yaw_rad) + step.motion.yaw_rad);
                    self.approach_m = (n * (-m.cfg.gripper.tool_from_reference_m[2] - self.depth_m / 2.0)).into();
                }
                let cmd = self.tool_move(m, c, &step.motion);
                self.wait = Some(MoveWait::new(c.seq, c.frame_index));
                Step::Stay(cmd)
            }
        }
    }

    /// The servo's move (reference point translation, yaw about it) as a tool move.
    fn tool_move(&self, m: &Mission, c: &Cycle<'_>, motion: &ToolMotion) -> Cmd {
        let yaw = f64::from(c.robot.tool_yaw_rad);
        let lever = tool_from_reference(&m.cfg.gripper, yaw);
        let (s, co) = motion.yaw_rad.sin_cos();
        let turned = Vector3::new(co * lever.x - s * lever.y, s * lever.x + co * lever.y, lever.z);
        let d = motion.translation_m + (turned - lever);
        Cmd::move_by([d.x, d.y, d.z], motion.yaw_rad, m.cfg.servo.speed_mps)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::servo::ViewFrame;

    fn frame(dx: f64) -> StereoFrame {
        let f = |o: [f64; 2]| ViewFrame { o: [o[0] + dx, o[1]], e1: [30.0, 2.0], e2: [-3.0, 40.0] };
        StereoFrame { left: f([300.0, 400.0]), right: f([280.0, 410.0]) }
    }

    #[test]
    fn target_mean_averages_jitter_and_restarts_after_a_jump() {
        let mut mean = TargetMean::default();
        assert!(mean.mean().is_none());
        for dx in [0.4, -0.4, 0.2, -0.2] {
            mean.add(&frame(dx));
        }
        let m = mean.mean().unwrap();
        assert!((m.left.o[0] - 300.0).abs() < 1e-12 && (m.right.e2[1] - 40.0).abs() < 1e-12, "{m:?}");
        // Not-finite frames are skipped.
        mean.add(&frame(f64::NAN));
        assert_eq!(mean.n, 4);
        // The target moved 5 px: the old frames no longer describe it.
        mean.add(&frame(5.0));
        assert_eq!(mean.n, 1);
        assert!((mean.mean().unwrap().left.o[0] - 305.0).abs() < 1e-12);
    }
}
