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
    /// The jaws' narrowest and widest opening during the lift, m.
    width_range_m: [f64; 2],
}

/// Jaw opening change, m, over which the block counts as moved in the jaws: the jaws squeeze
/// a rigid block to a steady width; one that turns or slides between them opens or closes them.
/// Measured (2026-11-26, pick_cube): 0.05 mm of tremble over a steady lift; a cube nudged 4 mm
/// and turned 8° mid-lift opened them 1.6 mm. 1 mm is 20 times the tremble.
const MOVED_IN_JAWS_M: f64 = 0.001;

/// `Some(words)` when the jaws' opening during the lift (`range_m`: narrowest, widest) strayed
/// from the width they closed to on the block (`closed_m`) by more than [`MOVED_IN_JAWS_M`]:
/// the block moved in the jaws while lifted.
pub fn moved_in_jaws(closed_m: f64, range_m: [f64; 2]) -> Option<String> {
    let off_m = (closed_m - range_m[0]).max(range_m[1] - closed_m);
    (closed_m.is_finite() && range_m[0] <= range_m[1] && off_m > MOVED_IN_JAWS_M).then(|| {
        format!(
            "the block moved in the jaws while lifted (the jaws closed on it at {:.1} mm, then opened {:.1}-{:.1} mm)",
            closed_m * 1e3,
            range_m[0] * 1e3,
            range_m[1] * 1e3
        )
    })
}

impl Lift {
    pub fn new(time_ns: u64) -> Self {
        Self { start_ns: time_ns, wait: None, width_range_m: [f64::INFINITY, f64::NEG_INFINITY] }
    }

    /// What the lift saw of the block in the jaws: `Some(words)` when it moved in them.
    fn moved_note(&self, m: &Mission) -> Option<String> {
        moved_in_jaws(m.servo.grip_width_m()?, self.width_range_m)
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
        let width = f64::from(c.robot.gripper_width_m);
        self.width_range_m = [self.width_range_m[0].min(width), self.width_range_m[1].max(width)];
        match w.poll(c, 2) {
            MovePoll::Pending => Step::Stay(Cmd::HOLD),
            MovePoll::Rejected(code) => Step::fail(FailureKind::RobotRefused, format!("lift: the robot refused the lift: {}", RejectReason::text_of(code))),
            MovePoll::Done => {
                if width < m.cfg.grasp.min_grip_width_m {
                    let closed = m.servo.grip_width_m().map(|w| format!(", closed on it at {:.1} mm", w * 1e3)).unwrap_or_default();
                    return Step::fail(
                        FailureKind::GraspLost,
                        format!("lift: the object slipped out: the block moved out of the jaws while lifted (jaw width {:.1} mm{closed})", width * 1e3),
                    );
                }
                m.reporting.snapshot("lifted");
                tracing::info!(closed_m = ?m.servo.grip_width_m(), range_m = ?self.width_range_m, "lift: the jaws' opening");
                // The lift is done either way (the jaws hold the block); one that moved in
                // them is said, for the operator and daemon.json.
                match self.moved_note(m) {
                    Some(note) => {
                        tracing::warn!(%note, "lift");
                        m.reporting.set_status(&format!("done: target lifted; {note}"));
                        m.servo.set_held_block_moved(note);
                    }
                    None => m.reporting.set_status("done: target lifted"),
                }
                Step::Next(Cmd::HOLD)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_block_steady_in_the_jaws_is_not_reported_and_one_that_turned_is() {
        // The jaws closed on a 40 mm block and stayed within the fingers' tremble.
        assert_eq!(moved_in_jaws(0.0400, [0.0395, 0.0408]), None);
        // The block turned between them while lifted: the jaws closed in to 36 mm.
        let words = moved_in_jaws(0.0400, [0.0360, 0.0401]).expect("a block that turned in the jaws is reported");
        assert_eq!(words, "the block moved in the jaws while lifted (the jaws closed on it at 40.0 mm, then opened 36.0-40.1 mm)");
        // ... or pushed them open.
        assert!(moved_in_jaws(0.0400, [0.0399, 0.0431]).is_some());
        // No width seen (a lift of no cycles) or no closing width: nothing said.
        assert_eq!(moved_in_jaws(0.0400, [f64::INFINITY, f64::NEG_INFINITY]), None);
        assert_eq!(moved_in_jaws(f64::NAN, [0.03, 0.05]), None);
    }
}
