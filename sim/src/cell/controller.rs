//! The robot controller inside the simulator, as a real robot's controller would be: it takes
//! [`RobotCommand`]s (Cartesian target or relative move of the tool point with yaw, gripper
//! open/close, speed limit, stop), plans a smooth Cartesian motion, solves the analytic IK
//! every tick, respects joint limits and joint speed limits, refuses unreachable targets with
//! a [`RejectReason`], and reports [`RobotState`]. Safety first: a watchdog stops the arm when
//! commands stop arriving while it moves, and a large tracking error (a collision) faults it.
//!
//! Motion: the Cartesian set-point follows an online trapezoidal profile (speed limit,
//! acceleration limit, braking curve), so new targets can arrive at any tick without jerks;
//! each tick's set-point is checked against the joint speed limits and slowed if needed. An
//! integral term per joint (active when the set-point is nearly still) removes steady-state
//! sag under a payload, so targets are reached to well under a millimetre.
//!
//! The controller has no clock of its own: every call takes the simulated time in ns.

use glam::DVec3;
use handeye_wire::{CommandKind, GripperCommand, NO_FRAME, RejectReason, RobotCommand, RobotState, WIRE_VERSION, robot_flags};

use crate::cell::arm::{ArmReading, FINGER_CLOSE_TARGET_M, FINGER_TRAVEL_M, MotorTargets};
use crate::cell::kinematics::{IkError, JOINT_MAX_SPEED_RADPS, ToolPose, ik, wrap_angle};
use crate::cell::profile::{profile_1d, profile_3d};

/// Fault codes in [`RobotState::fault`].
pub mod fault {
    /// The tool lagged its set-point by more than the tracking limit (blocked, collision).
    pub const TRACKING: u32 = 1;
    /// The set-point left the reachable workspace mid-motion (should not happen: paths are
    /// checked when accepted).
    pub const PATH: u32 = 2;
    /// The physics reported a non-finite pose (it blew up); the reported numbers are zeroed.
    pub const PHYSICS: u32 = 3;
}

/// Consecutive control ticks within tolerance before `ARRIVED` is reported.
const ARRIVE_TICKS: u32 = 4;

/// Tunables of the controller.
#[derive(Debug, Clone, Copy)]
pub struct ControllerConfig {
    /// Tool speed when a command asks for none (0), m/s.
    pub default_speed_mps: f64,
    /// Highest tool speed any command can ask for, m/s.
    pub max_speed_mps: f64,
    /// Tool acceleration and braking, m/s².
    pub accel_mps2: f64,
    /// Yaw rate limit, rad/s, and yaw acceleration, rad/s².
    pub yaw_rate_radps: f64,
    pub yaw_accel_radps2: f64,
    /// With no command for this long while moving, the watchdog stops the arm.
    pub watchdog_ns: u64,
    /// `ARRIVED` when the tool is this close to the target (metres, radians).
    pub arrive_tol_m: f64,
    pub arrive_tol_rad: f64,
    /// Tracking error that faults the controller when it lasts `fault_after_ns`.
    pub fault_track_err_m: f64,
    pub fault_after_ns: u64,
    /// Speed of each finger's motor set-point, m/s (the jaws close gently, like a real
    /// gripper; slamming 100 g fingers into a 40 g block made it jump).
    pub finger_speed_mps: f64,
    /// Integral gain of the per-joint sag correction, 1/s, and its bound, rad.
    pub integral_gain: f64,
    pub integral_limit_rad: f64,
}

impl Default for ControllerConfig {
    fn default() -> Self {
        Self {
            default_speed_mps: 0.15,
            max_speed_mps: 0.5,
            accel_mps2: 1.0,
            yaw_rate_radps: 1.5,
            yaw_accel_radps2: 6.0,
            watchdog_ns: 200_000_000,
            arrive_tol_m: 0.0005,
            arrive_tol_rad: 0.5f64.to_radians(),
            fault_track_err_m: 0.01,
            fault_after_ns: 200_000_000,
            finger_speed_mps: 0.05,
            integral_gain: 4.0,
            integral_limit_rad: 0.03,
        }
    }
}

/// The controller's state machine.
#[derive(Debug, Clone)]
pub struct Controller {
    cfg: ControllerConfig,
    /// Where the tool should be now (moves towards `goal`).
    setpoint: ToolPose,
    vel_mps: DVec3,
    yaw_vel_radps: f64,
    /// Where the last accepted command wants the tool.
    goal: ToolPose,
    speed_mps: f64,
    /// IK of the set-point and the integral correction per joint.
    q_cmd: [f64; 5],
    integral: [f64; 5],
    gripper_closed: bool,
    gripper_still_since_ns: Option<u64>,
    /// Finger motor set-point, ramped at `finger_speed_mps` towards open or closed.
    finger_setpoint_m: f64,
    /// The last accepted target has been reached at least once.
    arrived: bool,
    /// A motion is under way towards `goal` that has not been stopped.
    active: bool,
    stopped: bool,
    watchdog_stop: bool,
    rejected: bool,
    reject: RejectReason,
    fault: u32,
    last_command_ns: u64,
    last_command_seq: u64,
    last_command_frame_id: u64,
    state_seq: u64,
    track_err_since_ns: Option<u64>,
    /// Consecutive ticks with the tool within tolerance of the goal.
    ticks_in_tolerance: u32,
}

impl Controller {
    /// A controller holding the tool at `home`, gripper open.
    pub fn new(cfg: ControllerConfig, home: ToolPose) -> Result<Self, IkError> {
        let q = ik(home)?;
        Ok(Self {
            cfg,
            setpoint: home,
            vel_mps: DVec3::ZERO,
            yaw_vel_radps: 0.0,
            goal: home,
            speed_mps: cfg.default_speed_mps,
            q_cmd: q,
            integral: [0.0; 5],
            gripper_closed: false,
            gripper_still_since_ns: None,
            finger_setpoint_m: FINGER_TRAVEL_M,
            arrived: true,
            active: false,
            stopped: false,
            watchdog_stop: false,
            rejected: false,
            reject: RejectReason::None,
            fault: 0,
            last_command_ns: 0,
            last_command_seq: 0,
            last_command_frame_id: NO_FRAME,
            state_seq: 0,
            track_err_since_ns: None,
            ticks_in_tolerance: 0,
        })
    }

    /// Joint angles of the current set-point (the arm is built in this configuration).
    pub fn joint_setpoint(&self) -> [f64; 5] {
        self.q_cmd
    }

    /// The target of the last accepted motion command.
    pub fn goal(&self) -> ToolPose {
        self.goal
    }

    /// Handles one command. Commands take effect at the next tick.
    pub fn command(&mut self, cmd: &RobotCommand, now_ns: u64, reading: &ArmReading) {
        self.last_command_seq = cmd.seq;
        self.last_command_frame_id = cmd.frame_id;
        let kind = CommandKind::from_u32(cmd.kind);
        let gripper = GripperCommand::from_u32(cmd.gripper);
        let finite = cmd.target_m.iter().all(|v| v.is_finite()) && cmd.yaw_rad.is_finite() && cmd.speed_limit_mps.is_finite();
        let (Some(kind), Some(gripper)) = (kind, gripper) else {
            return self.refuse(RejectReason::Malformed);
        };
        if cmd.version != WIRE_VERSION || !finite || cmd.speed_limit_mps < 0.0 {
            return self.refuse(RejectReason::Malformed);
        }
        if self.fault != 0 && !matches!(kind, CommandKind::Stop | CommandKind::ClearFault) {
            return self.refuse(RejectReason::Faulted);
        }
        self.last_command_ns = now_ns;
        match kind {
            CommandKind::Hold => {}
            CommandKind::Stop => {
                self.controlled_stop();
                self.stopped = true;
                self.accept();
                return;
            }
            CommandKind::ClearFault => {
                self.fault = 0;
                self.hold_where_measured(reading);
                self.accept();
                return;
            }
            CommandKind::MoveTo | CommandKind::MoveBy => {
                let target = DVec3::new(f64::from(cmd.target_m[0]), f64::from(cmd.target_m[1]), f64::from(cmd.target_m[2]));
                let yaw = f64::from(cmd.yaw_rad);
                let goal = if kind == CommandKind::MoveTo {
                    ToolPose { pos_m: target, yaw_rad: yaw }
                } else {
                    ToolPose { pos_m: self.goal.pos_m + target, yaw_rad: self.goal.yaw_rad + yaw }
                };
                if let Err(e) = self.check_path(self.setpoint, goal) {
                    return self.refuse(match e {
                        IkError::JointLimit { .. } => RejectReason::JointLimit,
                        IkError::OutOfReach(_) => RejectReason::Unreachable,
                        IkError::NotFinite => RejectReason::Malformed,
                    });
                }
                self.goal = goal;
                self.speed_mps = if cmd.speed_limit_mps > 0.0 {
                    f64::from(cmd.speed_limit_mps).min(self.cfg.max_speed_mps)
                } else {
                    self.cfg.default_speed_mps
                };
                self.active = true;
                self.arrived = false;
                self.stopped = false;
                self.watchdog_stop = false;
            }
        }
        match gripper {
            GripperCommand::Keep => {}
            GripperCommand::Open | GripperCommand::Close => {
                let closed = gripper == GripperCommand::Close;
                if closed != self.gripper_closed {
                    self.gripper_closed = closed;
                    self.gripper_still_since_ns = None;
                }
            }
        }
        self.accept();
    }

    fn accept(&mut self) {
        self.rejected = false;
        self.reject = RejectReason::None;
    }

    fn refuse(&mut self, why: RejectReason) {
        self.rejected = true;
        self.reject = why;
    }

    /// Checks the straight path from `from` to `to` (position and yaw) in small steps: every
    /// point must have an IK solution, and the wrist roll must not wrap around on the way.
    fn check_path(&self, from: ToolPose, to: ToolPose) -> Result<(), IkError> {
        let dist = (to.pos_m - from.pos_m).length();
        let turn = (to.yaw_rad - from.yaw_rad).abs();
        let n = ((dist / 0.005).max(turn / 3f64.to_radians()).ceil() as usize).clamp(1, 2000);
        let mut prev_roll: Option<f64> = None;
        for k in 0..=n {
            let s = k as f64 / n as f64;
            let pose = ToolPose { pos_m: from.pos_m.lerp(to.pos_m, s), yaw_rad: from.yaw_rad + (to.yaw_rad - from.yaw_rad) * s };
            let q = ik(pose)?;
            if let Some(r) = prev_roll
                && (q[4] - r).abs() > std::f64::consts::FRAC_PI_2
            {
                return Err(IkError::JointLimit { joint: 4, angle_deg: q[4].to_degrees() });
            }
            prev_roll = Some(q[4]);
        }
        Ok(())
    }

    /// Brakes to a halt along the current velocity at the normal deceleration.
    fn controlled_stop(&mut self) {
        let v = self.vel_mps.length();
        let w = self.yaw_vel_radps;
        let stop_pos = self.setpoint.pos_m + self.vel_mps * (v / (2.0 * self.cfg.accel_mps2));
        let stop_yaw = self.setpoint.yaw_rad + w * (w.abs() / (2.0 * self.cfg.yaw_accel_radps2));
        let stop = ToolPose { pos_m: stop_pos, yaw_rad: stop_yaw };
        if self.check_path(self.setpoint, stop).is_ok() {
            self.goal = stop;
        } else {
            self.freeze();
        }
        self.active = false;
    }

    fn freeze(&mut self) {
        self.goal = self.setpoint;
        self.vel_mps = DVec3::ZERO;
        self.yaw_vel_radps = 0.0;
        self.active = false;
    }

    fn hold_where_measured(&mut self, reading: &ArmReading) {
        let here = ToolPose { pos_m: reading.tool_m, yaw_rad: reading.yaw_rad() };
        if let Ok(q) = ik(here) {
            self.setpoint = here;
            self.q_cmd = q;
        }
        self.integral = [0.0; 5];
        self.track_err_since_ns = None;
        self.freeze();
    }

    /// One control tick: advance the set-point by `dt_s`, run the watchdog and fault checks,
    /// and return the motor targets.
    pub fn tick(&mut self, now_ns: u64, dt_s: f64, reading: &ArmReading) -> MotorTargets {
        let moving = self.trajectory_running();
        if moving && self.active && now_ns.saturating_sub(self.last_command_ns) > self.cfg.watchdog_ns {
            self.controlled_stop();
            self.watchdog_stop = true;
        }
        if self.fault == 0 {
            self.advance_setpoint(dt_s);
        }

        // Tracking-error fault: the tool far from where it should be, for too long.
        let err = (reading.tool_m - self.setpoint.pos_m).length();
        if self.fault == 0 && err > self.cfg.fault_track_err_m {
            let since = *self.track_err_since_ns.get_or_insert(now_ns);
            if now_ns.saturating_sub(since) >= self.cfg.fault_after_ns {
                self.fault = fault::TRACKING;
                self.hold_where_measured(reading);
            }
        } else {
            self.track_err_since_ns = None;
        }

        // Sag correction: integrate joint errors while the set-point is (nearly) still, so
        // motion lag does not wind the integral up.
        let still = self.vel_mps.length() < 0.005 && self.yaw_vel_radps.abs() < 0.02;
        for j in 0..5 {
            if still && self.fault == 0 {
                let e = self.q_cmd[j] - reading.q_rad[j];
                self.integral[j] = (self.integral[j] + self.cfg.integral_gain * e * dt_s)
                    .clamp(-self.cfg.integral_limit_rad, self.cfg.integral_limit_rad);
            }
        }
        // Arrived: the set-point is at the goal and the tool has stayed within tolerance of it
        // for a few ticks (a single tick could be a bounce).
        if !self.trajectory_running() && self.fault == 0 && self.within_tolerance(reading, self.goal) {
            self.ticks_in_tolerance = self.ticks_in_tolerance.saturating_add(1);
        } else {
            self.ticks_in_tolerance = 0;
        }
        if !self.arrived && !self.stopped && !self.watchdog_stop && self.ticks_in_tolerance >= ARRIVE_TICKS {
            self.arrived = true;
        }

        // Gripper settling: both fingers still for 50 ms.
        let still_fingers = reading.finger_vel_mps.iter().all(|v| v.abs() < 0.002);
        if still_fingers {
            self.gripper_still_since_ns.get_or_insert(now_ns);
        } else {
            self.gripper_still_since_ns = None;
        }

        let finger_goal = if self.gripper_closed { FINGER_CLOSE_TARGET_M } else { FINGER_TRAVEL_M };
        let step = self.cfg.finger_speed_mps * dt_s;
        self.finger_setpoint_m += (finger_goal - self.finger_setpoint_m).clamp(-step, step);
        let finger = self.finger_setpoint_m;
        let mut q = self.q_cmd;
        for (qj, ij) in q.iter_mut().zip(self.integral) {
            *qj += ij;
        }
        MotorTargets { q_rad: q, finger_m: [finger; 2] }
    }

    fn trajectory_running(&self) -> bool {
        self.setpoint != self.goal || self.vel_mps != DVec3::ZERO || self.yaw_vel_radps != 0.0
    }

    fn within_tolerance(&self, reading: &ArmReading, pose: ToolPose) -> bool {
        (reading.tool_m - pose.pos_m).length() <= self.cfg.arrive_tol_m
            && wrap_angle(reading.yaw_rad() - pose.yaw_rad).abs() <= self.cfg.arrive_tol_rad
    }

    /// Online trapezoidal profile towards the goal, then the joint speed limits.
    fn advance_setpoint(&mut self, dt: f64) {
        if !self.trajectory_running() {
            return;
        }
        let (pos, vel) = profile_3d(self.setpoint.pos_m, self.vel_mps, self.goal.pos_m, self.speed_mps, self.cfg.accel_mps2, dt);
        let (yaw, yaw_vel) = profile_1d(
            self.setpoint.yaw_rad,
            self.yaw_vel_radps,
            self.goal.yaw_rad,
            self.cfg.yaw_rate_radps,
            self.cfg.yaw_accel_radps2,
            dt,
        );
        let mut next = ToolPose { pos_m: pos, yaw_rad: yaw };
        let (mut vel, mut yaw_vel) = (vel, yaw_vel);
        let Ok(mut q) = ik(next) else {
            self.fault = fault::PATH;
            self.freeze();
            return;
        };
        // Joint speed limits: shrink this tick's step (and the velocity) to fit.
        let mut k: f64 = 1.0;
        for j in 0..5 {
            let dq = (q[j] - self.q_cmd[j]).abs();
            if dq > 0.0 {
                k = k.min(JOINT_MAX_SPEED_RADPS[j] * dt / dq);
            }
        }
        if k < 1.0 {
            next = ToolPose {
                pos_m: self.setpoint.pos_m.lerp(next.pos_m, k),
                yaw_rad: self.setpoint.yaw_rad + (next.yaw_rad - self.setpoint.yaw_rad) * k,
            };
            vel *= k;
            yaw_vel *= k;
            match ik(next) {
                Ok(qq) => q = qq,
                Err(_) => {
                    self.fault = fault::PATH;
                    self.freeze();
                    return;
                }
            }
        }
        self.setpoint = next;
        self.vel_mps = vel;
        self.yaw_vel_radps = yaw_vel;
        self.q_cmd = q;
        if !self.trajectory_running() {
            self.active = false;
        }
    }

    /// The state to publish now. Always a valid wire message: the finger width is clamped at
    /// 0 (a closed jaw reads a hair below its limit) and a non-finite reading faults the
    /// controller rather than going out.
    pub fn state(&mut self, now_ns: u64, reading: &ArmReading) -> RobotState {
        self.state_seq += 1;
        let finite = reading.tool_m.is_finite()
            && reading.q_rad.iter().all(|q| q.is_finite())
            && reading.finger_m.iter().all(|f| f.is_finite())
            && reading.yaw_rad().is_finite();
        if !finite && self.fault == 0 {
            self.fault = fault::PHYSICS;
            self.freeze();
        }
        let mut flags = 0;
        if self.trajectory_running() || (!self.arrived && !self.stopped && !self.watchdog_stop && self.fault == 0) {
            flags |= robot_flags::MOVING;
        }
        if self.arrived {
            flags |= robot_flags::ARRIVED;
        }
        if self.fault != 0 {
            flags |= robot_flags::FAULT;
        }
        if self.rejected {
            flags |= robot_flags::REJECTED;
        }
        if self.gripper_closed {
            flags |= robot_flags::GRIPPER_CLOSED;
        }
        if self.gripper_still_since_ns.is_some_and(|t| now_ns.saturating_sub(t) >= 50_000_000) {
            flags |= robot_flags::GRIPPER_SETTLED;
        }
        if self.watchdog_stop {
            flags |= robot_flags::WATCHDOG_STOP;
        }
        if self.stopped {
            flags |= robot_flags::STOPPED;
        }
        RobotState {
            version: WIRE_VERSION,
            flags,
            seq: self.state_seq,
            time_ns: now_ns,
            last_command_seq: self.last_command_seq,
            last_command_frame_id: self.last_command_frame_id,
            tool_pos_m: if finite { reading.tool_m.as_vec3().to_array() } else { [0.0; 3] },
            tool_yaw_rad: if finite { reading.yaw_rad() as f32 } else { 0.0 },
            joints_rad: if finite { reading.q_rad.map(|q| q as f32) } else { [0.0; 5] },
            gripper_width_m: if finite { reading.gripper_width_m().max(0.0) as f32 } else { 0.0 },
            reject: self.reject as u32,
            fault: self.fault,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DMat3;
    use handeye_wire::message::WireMessage;

    fn reading_at(pose: ToolPose) -> ArmReading {
        let q = ik(pose).unwrap();
        let arm = crate::cell::kinematics::fk(&q);
        ArmReading {
            q_rad: q,
            dq_radps: [0.0; 5],
            finger_m: [0.04; 2],
            finger_vel_mps: [0.0; 2],
            tool_m: arm.tool_m,
            palm_rot: arm.palm_rot,
        }
    }

    #[test]
    fn published_state_is_always_a_valid_wire_message() {
        let home = ToolPose { pos_m: DVec3::new(0.3, 0.0, 0.18), yaw_rad: 0.0 };
        let mut c = Controller::new(ControllerConfig::default(), home).unwrap();
        let mut r = reading_at(home);
        r.finger_m = [-1e-5, -2e-5]; // closed jaws read a hair below their limit
        let s = c.state(1, &r);
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(s.gripper_width_m, 0.0);
        r.tool_m.x = f64::NAN; // physics blew up
        r.palm_rot = DMat3::IDENTITY;
        let s = c.state(2, &r);
        assert_eq!(s.validate(), Ok(()), "{s:?}");
        assert_eq!(s.fault, fault::PHYSICS);
        assert_ne!(s.flags & robot_flags::FAULT, 0);
        assert_eq!(s.seq, 2);
    }
}
