//! Servo (METHOD.md §3): look-and-move coplanarity servo. Each step measures on a fresh
//! frame after the previous move has arrived and settled, asks
//! [`CoplanarityServo::step`](handeye_vision::servo::CoplanarityServo::step) for a move, and
//! sends it as a `MoveBy`. On convergence the step's last small move is made and, once it
//! has arrived, the phase hands over to the grasp (telemetry then says `grasp`: that moment
//! is when the simulator judges the placement).
//!
//! **Goal.** The grasp closes the jaws across the facet and the face behind it, so the plate
//! (normal = closing axis) must end up parallel to the facet, `depth/2` of the plate-to-jaw
//! offset in front of it, with the tool point above the facet's centre line and
//! `grasp_height_m + standoff_above_m` above the facet's lowest corner. That pose is turned
//! into image terms relative to the target: `(s*, t*) = (0, 0)` (the facet centre) and zero
//! parallax, shifted by [`ServoGoal::offset_by`] by the metric offset of the plate's
//! reference point from the facet centre, with the facet normal and heights from the affine
//! reconstruction. The goal angle is that of the plate's horizontal axis within the facet.
//!
//! **Yaw centre.** The servo turns about the plate's reference point; the robot turns about
//! the tool point. Each move is converted: `Δtool = Δref + (Rz(Δψ) − I)(tool − ref)`, with
//! `tool − ref` from the gripper model at the current yaw.

use handeye_vision::servo::{CoplanarityServo, GripperView, Motion, ServoConfig, ServoGoal, StepOutcome};
use handeye_vision::tracker::{Role, View};
use nalgebra::Vector3;

use super::{reject_text, timed_out, Cmd, Cycle, Mission, MovePoll, MoveWait, ServoTraceRow, Step};
use crate::gripper::{gripper_view, stereo_frame};

pub struct ServoPhase {
    start_frame: u64,
    /// The coarse approach (a `MoveTo` to the goal pose as the affine model reconstructs it)
    /// is still to be sent / under way.
    approach: Option<([f64; 3], f64)>,
    approaching: bool,
    servo: CoplanarityServo,
    goal: ServoGoal,
    wait: Option<MoveWait>,
    /// The final move after convergence is under way.
    converging: bool,
    /// The open-loop approach from the servo's goal to the grasp pose, robot frame, m.
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

impl ServoPhase {
    /// Builds the servo and its goal from the current views (called once, on entry).
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
        let (target, gripper) = views(m)?;
        let model = &cal.servo_model;
        // Facet normal from the reconstructed basis, horizontal, towards the cameras.
        let d1 = model.reconstruct_direction(&handeye_vision::servo::StereoPoint { left: target.left.e1, right: target.right.e1 });
        let d2 = model.reconstruct_direction(&handeye_vision::servo::StereoPoint { left: target.left.e2, right: target.right.e2 });
        let mut n = d1.cross(&d2);
        if n.norm() < 1e-12 {
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
        // Heights from reconstructed image points (differences only: the calibration's
        // constant offset between reference point and tool point cancels).
        let centre_z = model.reconstruct(&handeye_vision::servo::StereoPoint { left: target.left.o, right: target.right.o }).z;
        let (l, r) = (
            m.trackers.get(Role::Target, View::Left).ok_or("servo: no target tracker")?,
            m.trackers.get(Role::Target, View::Right).ok_or("servo: no target tracker")?,
        );
        let bottom_z = l
            .corners()
            .zip(r.corners())
            .map(|(a, b)| model.reconstruct(&handeye_vision::servo::StereoPoint { left: [a.x, a.y], right: [b.x, b.y] }).z)
            .fold(f64::INFINITY, f64::min);
        let up = Vector3::z();
        let a = up.cross(&n);
        let t = m.cfg.gripper.tool_from_reference_m;
        // Plate reference point at the goal, relative to the facet centre.
        let tool_rel = -n * (depth_m / 2.0) + up * (bottom_z + s.grasp_height_m + s.standoff_above_m - centre_z);
        let offset = tool_rel - (a * t[0] + up * t[1] + n * t[2]);
        // Goal angle: the plate's horizontal axis `a` lies along the facet's horizontal.
        let ma = cal.model.m * a;
        let axis_view = GripperView { axis: handeye_vision::servo::StereoPoint { left: [ma[0], ma[1]], right: [ma[2], ma[3]] }, ..gripper };
        let angle_rad = ServoGoal::teach(model, &target, &axis_view).map_err(|e| format!("servo: goal angle: {e}"))?.angle_rad;
        let goal = ServoGoal { st: [0.0, 0.0], angle_rad, parallax_px: [0.0; 3] }
            .offset_by(model, &target, &offset)
            .map_err(|e| format!("servo: goal: {e}"))?;
        // The coarse approach: the goal pose in robot coordinates, from the reconstruction.
        // The model maps tool positions to the reference point's images, so a scene point P
        // reconstructs as P − (reference − tool) at the calibration's yaw.
        let yaw_now = f64::from(c.robot.tool_yaw_rad);
        let cal_lever = tool_from_reference(m, m.calibration_yaw_rad.unwrap_or(yaw_now));
        let facet_centre = model.reconstruct(&handeye_vision::servo::StereoPoint { left: target.left.o, right: target.right.o }) - cal_lever;
        let tool_goal = facet_centre + tool_rel;
        let n0 = m.cfg.gripper.normal_at_zero_yaw;
        let yaw_goal = yaw_now + wrap(n.y.atan2(n.x) - n0[1].atan2(n0[0]) - yaw_now);
        m.servo_trace.clear();
        m.servo_steps = 0;
        m.snapshot = Some("servo_start");
        m.set_status("servo: aligning the plate with the facet");
        tracing::info!(?offset, ?goal, "servo goal");
        Ok(Self {
            start_frame: c.frame_index,
            approach: Some(([tool_goal.x, tool_goal.y, tool_goal.z], yaw_goal)),
            approaching: false,
            servo,
            goal,
            wait: None,
            converging: false,
            approach_m: [0.0, 0.0, -s.standoff_above_m],
        })
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(&m.cfg, self.start_frame, c.frame_index, m.cfg.servo.timeout_s) {
            return Step::Fail(format!("servo: not converged after {} s ({} steps)", m.cfg.servo.timeout_s, m.servo_steps));
        }
        if let Some((p, yaw)) = self.approach.take() {
            self.wait = Some(MoveWait::new(c.seq, c.frame_index));
            self.approaching = true;
            m.set_status("servo: coarse approach from the reconstruction");
            return Step::Stay(Cmd::move_to(p, yaw, m.cfg.servo.speed_mps));
        }
        if let Some(w) = self.wait.as_mut() {
            match w.poll(c, m.cfg.servo.settle_frames) {
                MovePoll::Pending => return Step::Stay(Cmd::HOLD),
                MovePoll::Rejected(code) if self.approaching => {
                    return Step::Fail(format!("servo: the robot refused the coarse approach: {}", reject_text(code)));
                }
                MovePoll::Rejected(code) => return Step::Fail(format!("servo: the robot refused a servo move: {}", reject_text(code))),
                MovePoll::Done => self.wait = None,
            }
            if self.approaching {
                self.approaching = false;
                m.set_status("servo: aligning the plate with the facet");
            }
            if self.converging {
                m.snapshot = Some("servo_converged");
                m.set_status("servo converged");
                return Step::Next(Cmd::HOLD);
            }
        }
        // A fresh frame with the arm settled: look, then move.
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
        if let Some(meas) = step.measurement {
            tracing::debug!(step = step.step, error = ?meas.error, across = ?meas.parallax.map(|p| p.across_px), offset = ?step.offset, "servo step");
        }
        match step.outcome {
            StepOutcome::Failed(f) => Step::Fail(format!("servo: {f}")),
            StepOutcome::Move | StepOutcome::Converged => {
                self.converging = step.outcome == StepOutcome::Converged;
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
