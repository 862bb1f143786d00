//! The arm posed by an external robot driver (`handeye sim --robot external`): instead of the
//! simulator's own [`controller`](crate::cell::controller), the joint motors follow the tool
//! pose and gripper width that the driver publishes on `handeye/robot/state`. The joints are
//! the simulated arm's IK of the driver's tool pose (a driver of another arm reports its own
//! joints; only its tool pose means the same thing here), so the cameras see the arm where the
//! driver says it is.
//!
//! The driver runs on the wall clock and the simulator on simulated time, so each new state is
//! reached over the steps of one camera frame (a straight-line ramp from the pose the motors
//! were last sent to), not in a jump the motors would overshoot.

use glam::DVec3;
use handeye_wire::RobotState;

use crate::cell::arm::{FINGER_TRAVEL_M, MotorTargets};
use crate::cell::kinematics::{IkError, ToolPose, ik};

/// Motor targets that follow an external driver's reported tool pose.
#[derive(Debug, Clone)]
pub struct Follower {
    /// Pose and jaw opening (each finger's offset from the centre line) the motors were sent
    /// at the start of the current ramp, and where the ramp ends.
    from: (ToolPose, f64),
    to: (ToolPose, f64),
    /// Steps taken of the ramp, and its length.
    step: u32,
    steps: u32,
    /// Joint angles of the last reachable pose: held when the driver reports one the
    /// simulated arm cannot take.
    q_rad: [f64; 5],
    /// Driver poses the simulated arm could not take, so far.
    pub unreachable: u64,
    /// Driver states taken, so far.
    pub states: u64,
}

impl Follower {
    /// Following starts where the arm is built: `home`, gripper open.
    pub fn new(home: ToolPose) -> Result<Self, IkError> {
        let q_rad = ik(home)?;
        let open = FINGER_TRAVEL_M;
        Ok(Self { from: (home, open), to: (home, open), step: 0, steps: 1, q_rad, unreachable: 0, states: 0 })
    }

    /// The driver's newest state: reach it over the next `steps` physics steps.
    pub fn follow(&mut self, s: &RobotState, steps: u32) {
        self.states += 1;
        let pose = ToolPose { pos_m: DVec3::from_array(s.tool_pos_m.map(f64::from)), yaw_rad: f64::from(s.tool_yaw_rad) };
        let finger_m = (f64::from(s.gripper_width_m) / 2.0).clamp(0.0, FINGER_TRAVEL_M);
        self.from = self.current();
        self.to = (pose, finger_m);
        self.step = 0;
        self.steps = steps.max(1);
    }

    /// How far the driver's latest pose is from where the ramp began, metres (a driver that
    /// starts far from the simulated arm's home makes the arm jump).
    pub fn jump_m(&self) -> f64 {
        (self.to.0.pos_m - self.from.0.pos_m).length()
    }

    fn current(&self) -> (ToolPose, f64) {
        let s = f64::from(self.step) / f64::from(self.steps);
        let (a, b) = (self.from, self.to);
        let pose = ToolPose { pos_m: a.0.pos_m.lerp(b.0.pos_m, s), yaw_rad: a.0.yaw_rad + (b.0.yaw_rad - a.0.yaw_rad) * s };
        (pose, a.1 + (b.1 - a.1) * s)
    }

    /// Motor targets for the next physics step.
    pub fn tick(&mut self) -> MotorTargets {
        self.step = (self.step + 1).min(self.steps);
        let (pose, finger_m) = self.current();
        match ik(pose) {
            Ok(q) => self.q_rad = q,
            Err(e) => {
                self.unreachable += 1;
                if self.unreachable.is_power_of_two() {
                    tracing::warn!(count = self.unreachable, "the driver's tool pose {pose:?} is beyond the simulated arm ({e}); holding the last pose");
                }
            }
        }
        MotorTargets { q_rad: self.q_rad, finger_m: [finger_m; 2] }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_wire::WIRE_VERSION;

    #[test]
    fn ramps_to_the_drivers_pose_over_the_given_steps_and_holds_what_it_cannot_reach() {
        let home = ToolPose { pos_m: DVec3::new(0.3, 0.0, 0.2), yaw_rad: 0.0 };
        let mut f = Follower::new(home).unwrap();
        let s = RobotState { version: WIRE_VERSION, tool_pos_m: [0.34, 0.0, 0.2], tool_yaw_rad: 0.2, gripper_width_m: 0.02, ..Default::default() };
        f.follow(&s, 4);
        f.tick();
        let mid = f.tick();
        let q_mid = ik(ToolPose { pos_m: DVec3::new(0.32, 0.0, 0.2), yaw_rad: 0.1 }).unwrap();
        assert!(mid.q_rad.iter().zip(q_mid).all(|(a, b)| (a - b).abs() < 1e-6), "{:?} vs {q_mid:?}", mid.q_rad);
        assert!((mid.finger_m[0] - 0.025).abs() < 1e-6, "{mid:?}");
        f.tick();
        let end = f.tick();
        let q_end = ik(ToolPose { pos_m: DVec3::new(0.34, 0.0, 0.2), yaw_rad: 0.2 }).unwrap();
        assert!(end.q_rad.iter().zip(q_end).all(|(a, b)| (a - b).abs() < 1e-6), "{:?} vs {q_end:?}", end.q_rad);
        assert!((end.finger_m[0] - 0.01).abs() < 1e-6);
        assert_eq!(f.tick().q_rad, end.q_rad, "past the ramp it holds");
        // Below the table: the simulated arm keeps its last pose and counts it.
        f.follow(&RobotState { tool_pos_m: [0.34, 0.0, -0.05], ..s }, 1);
        assert_eq!(f.tick().q_rad, end.q_rad);
        assert_eq!(f.unreachable, 1);
    }
}
