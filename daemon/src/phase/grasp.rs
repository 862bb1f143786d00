//! The open-loop grasp (thesis §6.3.4): from the servo's stand-off pose, move by the
//! approach offset (expressed relative to the target facet: straight down by the stand-off,
//! jaws already open and aligned across the facet), close the jaws, check they hold
//! something, then lift and check again.

use handeye_vision::tracker::{Role, View};
use handeye_wire::report::FailureKind;
use handeye_wire::{robot_flags, GripperCommand, RejectReason};

use super::step::{elapsed_at_least, timed_out, Cmd, Cycle, MovePoll, MoveWait, Step};
use crate::mission::Mission;

#[derive(Debug, Clone, Copy, PartialEq)]
enum GraspStage {
    /// Along the facet normal, above the block.
    Forward { wait: Option<MoveWait> },
    /// Straight down to the grasp height.
    Down { wait: Option<MoveWait> },
    Close { since: Option<u64> },
}

pub struct Grasp {
    start_ns: u64,
    stage: GraspStage,
    approach_m: [f64; 3],
}

impl Grasp {
    pub fn new(time_ns: u64, approach_m: [f64; 3]) -> Self {
        Self { start_ns: time_ns, stage: GraspStage::Forward { wait: None }, approach_m }
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(self.start_ns, c.time_ns, m.cfg.grasp.timeout_s) {
            return Step::fail(FailureKind::TimedOut, format!("grasp: timed out after {} s in {:?}", m.cfg.grasp.timeout_s, self.stage));
        }
        let speed = m.cfg.grasp.approach_speed_mps;
        match &mut self.stage {
            GraspStage::Forward { wait } => {
                let Some(w) = wait else {
                    // The fingers now pass in front of the facet: the trackers are done.
                    for role in [Role::Gripper, Role::Target] {
                        for view in View::ALL {
                            m.trackers.set_active(role, view, false);
                        }
                    }
                    *wait = Some(MoveWait::new(c.seq, c.frame_index));
                    m.reporting.set_status("grasp: jaws over the target");
                    return Step::Stay(Cmd::move_by(self.approach_m, 0.0, speed));
                };
                match w.poll(c, 1) {
                    MovePoll::Pending => Step::Stay(Cmd::HOLD),
                    MovePoll::Rejected(code) => {
                        Step::fail(FailureKind::RobotRefused, format!("grasp: the robot refused the approach: {}", RejectReason::text_of(code)))
                    }
                    MovePoll::Done => {
                        self.stage = GraspStage::Down { wait: Some(MoveWait::new(c.seq, c.frame_index)) };
                        m.reporting.set_status("grasp: descending");
                        m.reporting.snapshot("over_target");
                        // Down to the grasp height by the robot's own kinematics: the
                        // configured height above the table, or the planned one (the
                        // fingers' tips at the low-water mark the plan's collision test
                        // cleared) when it is higher.
                        let floor = m.cfg.grasp.table_z_m + m.cfg.servo.approach.grasp_height_m;
                        let z = m.targeting.target().and_then(|t| t.grasp_tool_z_m).map_or(floor, |z| z.max(floor));
                        let dz = z - f64::from(c.robot.tool_pos_m[2]);
                        Step::Stay(Cmd::move_by([0.0, 0.0, dz], 0.0, speed))
                    }
                }
            }
            GraspStage::Down { wait } => {
                let Some(w) = wait else { return Step::fail(FailureKind::Internal, "grasp: lost track of the descent") };
                match w.poll(c, 2) {
                    MovePoll::Pending => Step::Stay(Cmd::HOLD),
                    MovePoll::Rejected(code) => {
                        Step::fail(FailureKind::RobotRefused, format!("grasp: the robot refused the descent: {}", RejectReason::text_of(code)))
                    }
                    MovePoll::Done => {
                        self.stage = GraspStage::Close { since: None };
                        m.reporting.set_status("grasp: closing");
                        m.reporting.snapshot("closing");
                        Step::Stay(Cmd::gripper(GripperCommand::Close))
                    }
                }
            }
            GraspStage::Close { since } => {
                let since = *since.get_or_insert(c.time_ns);
                // Jaws squeezing an object may never report GRIPPER_SETTLED (the fingers keep
                // trembling against it); after twice the closing time the grip is what it is.
                let settled = c.robot.flags & robot_flags::GRIPPER_SETTLED != 0;
                let close_s = m.cfg.grasp.close_s;
                if !elapsed_at_least(since, c.time_ns, close_s) || (!settled && !elapsed_at_least(since, c.time_ns, 2.0 * close_s)) {
                    return Step::Stay(Cmd::HOLD);
                }
                let width = f64::from(c.robot.gripper_width_m);
                m.servo.set_grip_width_m(width);
                if width < m.cfg.grasp.min_grip_width_m {
                    return Step::fail(FailureKind::GraspLost, format!("grasp: the jaws closed on nothing (width {:.1} mm)", width * 1e3));
                }
                m.reporting.snapshot("grasped");
                Step::Next(Cmd::HOLD)
            }
        }
    }
}

pub struct Lift {
    start_ns: u64,
    wait: Option<MoveWait>,
}

impl Lift {
    pub fn new(time_ns: u64) -> Self {
        Self { start_ns: time_ns, wait: None }
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(self.start_ns, c.time_ns, m.cfg.grasp.timeout_s) {
            return Step::fail(FailureKind::TimedOut, format!("lift: timed out after {} s", m.cfg.grasp.timeout_s));
        }
        let Some(w) = self.wait.as_mut() else {
            self.wait = Some(MoveWait::new(c.seq, c.frame_index));
            m.reporting.set_status("lift");
            return Step::Stay(Cmd::move_by([0.0, 0.0, m.cfg.grasp.lift_m], 0.0, m.cfg.grasp.lift_speed_mps));
        };
        match w.poll(c, 2) {
            MovePoll::Pending => Step::Stay(Cmd::HOLD),
            MovePoll::Rejected(code) => Step::fail(FailureKind::RobotRefused, format!("lift: the robot refused the lift: {}", RejectReason::text_of(code))),
            MovePoll::Done => {
                let width = f64::from(c.robot.gripper_width_m);
                if width < m.cfg.grasp.min_grip_width_m {
                    return Step::fail(FailureKind::GraspLost, format!("lift: the object slipped out (jaw width {:.1} mm)", width * 1e3));
                }
                m.reporting.snapshot("lifted");
                m.reporting.set_status("done: target lifted");
                Step::Next(Cmd::HOLD)
            }
        }
    }
}
