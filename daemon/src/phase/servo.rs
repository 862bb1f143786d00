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
//! above the block. That in-plane offset becomes `(s*, t*)` by [`ServoGoal::offset_by`]; the
//! goal angle is that of the plate's horizontal axis within the facet. The grasp then moves
//! by metric offsets the robot's kinematics make exact: along the plate normal until the
//! jaw centre is `depth/2` behind the facet, and down to the grasp height.
//!
//! **Coarse approach, local cage.** The servo starts from the goal pose as the global model
//! reconstructs it (a `MoveTo`), then visits a small cage around it (±`local_cage_m`) and
//! fits a local affine model: the global model's image scale is the cage's, while near the
//! target it differs by ~10 % (perspective), and the metric stand-off offsets are converted
//! with it. The servo and its goal use the local model.
//!
//! **Yaw centre.** The servo turns about the plate's reference point; the robot turns about
//! the tool point. Each move is converted: `Δtool = Δref + (Rz(Δψ) − I)(tool − ref)`, with
//! `tool − ref` from the gripper model at the current yaw.

use handeye_vision::affine::AffineStereo;
use handeye_vision::servo::{CoplanarityServo, GripperView, Motion, ServoConfig, ServoGoal, ServoModel, StepOutcome, StereoPoint};
use handeye_vision::tracker::{Role, View};
use nalgebra::Vector3;

use super::{reject_text, timed_out, Cmd, Cycle, Mission, MovePoll, MoveWait, ServoTraceRow, Step};
use crate::gripper::{gripper_view, stereo_frame};

/// Offsets of the local cage points from the approach pose, in units of `local_cage_m`.
const LOCAL_CAGE: [[f64; 3]; 7] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]];

#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    /// The coarse approach `MoveTo` is to be sent.
    Approach,
    /// Visiting local cage point `i`; `n` samples taken there.
    LocalCage { i: usize, n: u32 },
    /// Look-and-move; `converging` once the final move was sent.
    Servo { converging: bool },
}

pub struct ServoPhase {
    start_frame: u64,
    stage: Stage,
    wait: Option<MoveWait>,
    servo: CoplanarityServo,
    config: ServoConfig,
    goal: ServoGoal,
    /// Metric offset of the reference point's goal from the facet centre, robot frame.
    offset_m: Vector3<f64>,
    /// Horizontal axis of the plate at the goal (robot frame), for the goal angle.
    plate_a: Vector3<f64>,
    approach_pose: ([f64; 3], f64),
    local_robot_m: Vec<Vector3<f64>>,
    local_image_px: Vec<[f64; 4]>,
    acc: [f64; 7],
    /// The open-loop move from the servo's goal (plate coplanar with the facet) to above the
    /// grasp: along the facet normal until the jaw centre is `depth/2` behind the facet, m.
    /// The grasp then comes straight down.
    pub approach_m: [f64; 3],
}

fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    a - t * ((a + std::f64::consts::PI) / t).floor()
}

/// `tool − reference` in the robot frame at yaw `yaw_rad`.
fn tool_from_reference(m: &Mission, yaw_rad: f64) -> Vector3<f64> {
    let n0 = m.cfg.gripper.normal_at_zero_yaw;
    let (s, c) = yaw_rad.sin_cos();
    let n = Vector3::new(c * n0[0] - s * n0[1], s * n0[0] + c * n0[1], 0.0).normalize();
    let up = Vector3::z();
    let a = up.cross(&n);
    let t = m.cfg.gripper.tool_from_reference_m;
    a * t[0] + up * t[1] + n * t[2]
}

fn views(m: &Mission) -> Result<(handeye_vision::servo::StereoFrame, GripperView), String> {
    let get = |role, view| m.trackers.get(role, view).ok_or_else(|| format!("servo: no {role:?} tracker in the {view:?} view"));
    let target = stereo_frame(get(Role::Target, View::Left)?, get(Role::Target, View::Right)?);
    let gripper = gripper_view(&m.plate, get(Role::Gripper, View::Left)?, get(Role::Gripper, View::Right)?);
    Ok((target, gripper))
}

/// The image goal for a metric `offset` of the reference point from the facet centre, and
/// the plate's horizontal axis `a` lying along the facet.
fn goal_for(model: &ServoModel, m_full: &nalgebra::Matrix4x3<f64>, m: &Mission, offset: &Vector3<f64>, a: &Vector3<f64>) -> Result<ServoGoal, String> {
    let (target, gripper) = views(m)?;
    let ma = m_full * a;
    let axis_view = GripperView { axis: StereoPoint { left: [ma[0], ma[1]], right: [ma[2], ma[3]] }, ..gripper };
    let angle_rad = ServoGoal::teach(model, &target, &axis_view).map_err(|e| format!("servo: goal angle: {e}"))?.angle_rad;
    // The offset is in the facet's plane, yet its parallax through the model is not quite
    // zero: the model's view of the plane carries the perspective of the scene, and so does
    // the affine plane transfer extrapolated from the small facet up to the plate. Keeping
    // the model's parallax cancels much of that bias (forcing zero left the plate 3-9 mm off
    // the plane over ten seeds, against 0.1-1.9 mm).
    let goal = ServoGoal { st: [0.0, 0.0], angle_rad, parallax_px: [0.0; 3] }.offset_by(model, &target, offset).map_err(|e| format!("servo: goal: {e}"))?;
    // Per mark, at the mark's own place in the plane (the model's bias is not uniform).
    let g = &m.cfg.gripper;
    let mut parallax_px = [0.0; 3];
    for (p, mark) in parallax_px.iter_mut().zip(g.marks_m) {
        let d = offset + a * (mark[0] - g.reference_m[0]) + Vector3::z() * (mark[1] - g.reference_m[1]);
        *p = model.parallax_for_offset(&target, &d).map_err(|e| format!("servo: goal: {e}"))?;
    }
    Ok(ServoGoal { parallax_px, ..goal })
}

impl ServoPhase {
    /// Plans the goal and the coarse approach from the current views (called once, on entry).
    pub fn new(m: &mut Mission, c: &Cycle<'_>) -> Result<Self, String> {
        let cal = m.calibration.clone().ok_or("servo: not calibrated")?;
        let hint = m.hint.as_ref().ok_or("servo: no operator hint")?;
        let depth_m = hint.depth_mm * 1e-3;
        let s = m.cfg.servo.clone();
        let config = ServoConfig {
            gain: s.gain,
            max_step_m: s.max_step_m,
            max_yaw_step_rad: s.max_yaw_step_deg.to_radians(),
            converged_m: s.converged_m,
            converged_rad: s.converged_deg.to_radians(),
            converged_steps: s.converged_steps,
            max_steps: s.max_steps,
            broyden: s.broyden,
            max_across_px: s.max_across_px,
            max_across_ratio: s.max_across_ratio,
            yaw_lever_m: s.yaw_lever_m,
            min_condition: s.min_condition,
            ..ServoConfig::default()
        };
        let servo = CoplanarityServo::new(cal.servo_model, config).map_err(|e| format!("servo: {e}"))?;
        let (target, _) = views(m)?;
        let model = &cal.servo_model;
        // Facet normal from the reconstructed basis, horizontal, towards the cameras.
        let d1 = model.reconstruct_direction(&StereoPoint { left: target.left.e1, right: target.right.e1 });
        let d2 = model.reconstruct_direction(&StereoPoint { left: target.left.e2, right: target.right.e2 });
        let mut n = d1.cross(&d2);
        if n.norm().is_nan() || n.norm() <= 1e-12 {
            return Err("servo: the target facet reconstructs as a line".into());
        }
        n /= n.norm();
        if n.dot(&cal.model.toward_cameras()) < 0.0 {
            n = -n;
        }
        if n.z.abs() > 25f64.to_radians().sin() {
            return Err(format!("servo: the target facet is {:.0}° from vertical; the jaws close horizontally", n.z.abs().asin().to_degrees()));
        }
        let n = Vector3::new(n.x, n.y, 0.0).normalize();
        let up = Vector3::z();
        let a = up.cross(&n);
        // The model maps tool positions to the reference point's images, so a scene point P
        // reconstructs as P − (reference − tool) at the calibration's yaw.
        let yaw_now = f64::from(c.robot.tool_yaw_rad);
        let cal_lever = tool_from_reference(m, m.calibration_yaw_rad.unwrap_or(yaw_now));
        let facet_centre = model.reconstruct(&StereoPoint { left: target.left.o, right: target.right.o }) - cal_lever;
        // Thesis §6.3.4: make the plate coplanar with the facet (zero parallax: insensitive to
        // the model's scale), the tool above the facet's centre at the stand-off height with
        // the jaws behind the facet plane; the grasp then moves by metric offsets that the
        // robot's own kinematics make exact.
        let tool_z = m.cfg.grasp.table_z_m + s.grasp_height_m + s.standoff_above_m;
        let t = m.cfg.gripper.tool_from_reference_m;
        // Reference point relative to the facet centre: in the facet plane, straight above.
        let offset_m = up * (tool_z - facet_centre.z - t[1]) - a * t[0];
        let tool_rel = offset_m + a * t[0] + up * t[1] + n * t[2];
        let goal = goal_for(model, &cal.model.m, m, &offset_m, &a)?;
        let tool_goal = facet_centre + tool_rel;
        let n0 = m.cfg.gripper.normal_at_zero_yaw;
        let yaw_goal = yaw_now + wrap(n.y.atan2(n.x) - n0[1].atan2(n0[0]) - yaw_now);
        m.servo_trace.clear();
        m.servo_steps = 0;
        m.snapshot = Some("servo_start");
        m.set_status("servo: coarse approach from the reconstruction");
        tracing::info!(?offset_m, ?tool_goal, yaw_goal, "servo plan");
        Ok(Self {
            start_frame: c.frame_index,
            stage: Stage::Approach,
            wait: None,
            servo,
            config,
            goal,
            offset_m,
            plate_a: a,
            approach_pose: ([tool_goal.x, tool_goal.y, tool_goal.z], yaw_goal),
            local_robot_m: Vec::with_capacity(LOCAL_CAGE.len()),
            local_image_px: Vec::with_capacity(LOCAL_CAGE.len()),
            acc: [0.0; 7],
            approach_m: (n * (-t[2] - depth_m / 2.0)).into(),
        })
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(&m.cfg, self.start_frame, c.frame_index, m.cfg.servo.timeout_s) {
            return Step::Fail(format!("servo: not converged after {} s ({} steps)", m.cfg.servo.timeout_s, m.servo_steps));
        }
        if let Some(w) = self.wait.as_mut() {
            match w.poll(c, m.cfg.servo.settle_frames) {
                MovePoll::Pending => return Step::Stay(Cmd::HOLD),
                MovePoll::Rejected(code) => return Step::Fail(format!("servo: the robot refused a move ({:?}): {}", self.stage, reject_text(code))),
                MovePoll::Done => self.wait = None,
            }
        }
        let speed = m.cfg.servo.speed_mps;
        match self.stage {
            Stage::Approach => {
                self.wait = Some(MoveWait::new(c.seq, c.frame_index));
                let (p, yaw) = self.approach_pose;
                self.stage = if m.cfg.servo.local_cage_m > 0.0 {
                    Stage::LocalCage { i: 0, n: 0 }
                } else {
                    m.set_status("servo: aligning the plate with the facet");
                    Stage::Servo { converging: false }
                };
                Step::Stay(Cmd::move_to(p, yaw, speed))
            }
            Stage::LocalCage { i, n } => self.local_cage(m, c, i, n),
            Stage::Servo { converging: true } => {
                m.snapshot = Some("servo_converged");
                m.set_status("servo converged");
                Step::Next(Cmd::HOLD)
            }
            Stage::Servo { converging: false } => self.look_and_move(m, c),
        }
    }

    /// Picks up again after the arm was stopped for a re-acquisition: the pending move is
    /// void (the arm stopped where it was), the servo starts afresh from a new look.
    /// `shift_px` is how far the moved camera's image went: its affine model's offset moves
    /// with it (the first-order effect of a small knock), and the goal is recomputed with the
    /// corrected model and the re-acquired target.
    pub fn resume(&mut self, m: &mut Mission, view: View, shift_px: [f64; 2]) {
        self.wait = None;
        self.stage = Stage::Servo { converging: false };
        let rows = if view == View::Left { [0, 1] } else { [2, 3] };
        if let Some(cal) = m.calibration.as_mut() {
            cal.model.c[rows[0]] += shift_px[0];
            cal.model.c[rows[1]] += shift_px[1];
            if let Ok(model) = ServoModel::new(&cal.model) {
                cal.servo_model = model;
            }
        }
        if let Some(cal) = m.calibration.clone()
            && let Ok(goal) = goal_for(&cal.servo_model, &cal.model.m, m, &self.offset_m, &self.plate_a)
            && let Ok(servo) = CoplanarityServo::new(cal.servo_model, self.config)
        {
            self.goal = goal;
            self.servo = servo;
        } else {
            self.servo.reset();
        }
        m.set_status("servo: resumed after re-acquiring");
    }

    /// At local cage point `i` (arrived and settled): sample, then move on; after the last,
    /// fit the local model and start the servo with it.
    fn local_cage(&mut self, m: &mut Mission, c: &Cycle<'_>, i: usize, n: u32) -> Step {
        let (Some(l), Some(r)) = (m.trackers.get(Role::Gripper, View::Left), m.trackers.get(Role::Gripper, View::Right)) else {
            return Step::Fail("servo: no gripper trackers".into());
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
            let d = m.cfg.servo.local_cage_m;
            let (p0, yaw) = self.approach_pose;
            let o = LOCAL_CAGE[i + 1];
            m.set_status("servo: local cage around the approach pose");
            return Step::Stay(Cmd::move_to([p0[0] + d * o[0], p0[1] + d * o[1], p0[2] + d * o[2]], yaw, speed));
        }
        // Fit (7 points: microseconds, so on the loop), then back to the approach pose.
        let local = AffineStereo::fit(&self.local_robot_m, &self.local_image_px).map_err(|e| format!("servo: local fit: {e}"));
        let local = match local.and_then(|f| ServoModel::new(&f).map(|s| (f, s)).map_err(|e| format!("servo: local model: {e}"))) {
            Ok(x) => x,
            Err(e) => return Step::Fail(e),
        };
        if local.0.residual_rms_px > m.cfg.calibration.max_residual_px {
            return Step::Fail(format!("servo: local cage residual {:.2} px RMS is too large", local.0.residual_rms_px));
        }
        self.goal = match goal_for(&local.1, &local.0.m, m, &self.offset_m, &self.plate_a) {
            Ok(g) => g,
            Err(e) => return Step::Fail(e),
        };
        self.servo = match CoplanarityServo::new(local.1, self.config) {
            Ok(s) => s,
            Err(e) => return Step::Fail(format!("servo: {e}")),
        };
        tracing::info!(residual_px = local.0.residual_rms_px, goal = ?self.goal, "local model");
        self.stage = Stage::Servo { converging: false };
        self.wait = Some(MoveWait::new(c.seq, c.frame_index));
        m.set_status("servo: aligning the plate with the facet");
        let (p0, yaw) = self.approach_pose;
        Step::Stay(Cmd::move_to(p0, yaw, speed))
    }

    fn look_and_move(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        let (target, gripper) = match views(m) {
            Ok(v) => v,
            Err(e) => return Step::Fail(e),
        };
        let step = self.servo.step(&target, &gripper, &self.goal);
        m.servo_steps = step.step;
        if let Some(meas) = step.measurement {
            for (dst, src) in m.servo_error.iter_mut().zip(meas.error.iter()) {
                *dst = *src;
            }
            tracing::debug!(step = step.step, error = ?meas.error, across = ?meas.parallax.map(|p| p.across_px), "servo step");
        }
        if m.servo_trace.len() < m.servo_trace.capacity() {
            m.servo_trace.push(ServoTraceRow {
                step: step.step,
                frame: c.frame_index,
                error: m.servo_error,
                offset_m: step.offset.translation_m.norm(),
                offset_yaw_rad: step.offset.yaw_rad,
            });
        }
        match step.outcome {
            StepOutcome::Failed(f) => Step::Fail(format!("servo: {f}")),
            StepOutcome::Move | StepOutcome::Converged => {
                if step.outcome == StepOutcome::Converged {
                    self.stage = Stage::Servo { converging: true };
                }
                let cmd = self.tool_move(m, c, &step.motion);
                self.wait = Some(MoveWait::new(c.seq, c.frame_index));
                Step::Stay(cmd)
            }
        }
    }

    /// The servo's move (reference point translation, yaw about it) as a tool move.
    fn tool_move(&self, m: &Mission, c: &Cycle<'_>, motion: &Motion) -> Cmd {
        let yaw = f64::from(c.robot.tool_yaw_rad);
        let lever = tool_from_reference(m, yaw);
        let (s, co) = motion.yaw_rad.sin_cos();
        let turned = Vector3::new(co * lever.x - s * lever.y, s * lever.x + co * lever.y, lever.z);
        let d = motion.translation_m + (turned - lever);
        Cmd::move_by([d.x, d.y, d.z], motion.yaw_rad, m.cfg.servo.speed_mps)
    }
}
