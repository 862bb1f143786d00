//! Never a move on a lost track (issue 18), checked from outside the daemon: every move
//! command (`MoveTo`, `MoveBy`) is matched with the telemetry of the frame it answered (the
//! daemon publishes that telemetry first, but the two may be read in either order), and
//! counted when a tracker the daemon's phase moves the arm by was not tracking on that
//! frame: the plate's (left, right) in calibrate, point, plan and acquire_target, all four in the
//! servo.

use std::collections::VecDeque;

use handeye_wire::{CommandKind, Phase, RobotCommand, Telemetry};

/// Telemetry samples remembered for commands that arrive after them.
const REMEMBERED: usize = 64;

/// Telemetry slots (gripper left, right, target left, right) a phase moves the arm by.
fn slots_used(phase: Phase) -> &'static [usize] {
    match phase {
        Phase::Calibrate | Phase::Point | Phase::Plan | Phase::AcquireTarget => &[0, 1],
        Phase::Servo => &[0, 1, 2, 3],
        _ => &[],
    }
}

/// The check's state and its counts.
#[derive(Debug, Clone, Default)]
pub struct BlindMoves {
    /// Moves answering a frame on which a tracker the phase used was not tracking.
    pub count: u64,
    /// The first such frame id.
    pub first_frame: Option<u64>,
    /// Recent telemetry: frame id and whether a tracker its phase uses was not tracking.
    recent: VecDeque<(u64, bool)>,
    /// Frame ids of moves whose frame's telemetry has not been read yet.
    pending: Vec<u64>,
}

impl BlindMoves {
    pub fn telemetry(&mut self, t: &Telemetry) {
        let Some(phase) = Phase::from_u32(t.phase) else { return };
        let blind = slots_used(phase).iter().any(|&i| t.tracker_state[i] != 1);
        if self.recent.len() >= REMEMBERED {
            self.recent.pop_front();
        }
        self.recent.push_back((t.frame_id, blind));
        if let Some(k) = self.pending.iter().position(|&id| id == t.frame_id) {
            self.pending.swap_remove(k);
            self.judge(t.frame_id, blind);
        }
    }

    pub fn command(&mut self, cmd: &RobotCommand) {
        if cmd.kind != CommandKind::MoveTo as u32 && cmd.kind != CommandKind::MoveBy as u32 {
            return;
        }
        match self.recent.iter().find(|(id, _)| *id == cmd.frame_id) {
            Some(&(id, blind)) => self.judge(id, blind),
            None => self.pending.push(cmd.frame_id),
        }
    }

    fn judge(&mut self, frame_id: u64, blind: bool) {
        if blind {
            self.count += 1;
            self.first_frame.get_or_insert(frame_id);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tel(frame_id: u64, phase: Phase, states: [u32; 4]) -> Telemetry {
        Telemetry { frame_id, phase: phase as u32, tracker_state: states, ..Telemetry::default() }
    }

    fn cmd(frame_id: u64, kind: CommandKind) -> RobotCommand {
        RobotCommand { frame_id, kind: kind as u32, ..RobotCommand::default() }
    }

    #[test]
    fn a_move_answering_a_frame_with_a_lost_tracker_in_use_is_counted_in_either_order() {
        let mut b = BlindMoves::default();
        // Servo, all tracking: a move is fine.
        b.telemetry(&tel(1, Phase::Servo, [1, 1, 1, 1]));
        b.command(&cmd(1, CommandKind::MoveBy));
        // Servo, the right target lost: a hold is fine, a move is not.
        b.telemetry(&tel(2, Phase::Servo, [1, 1, 1, 2]));
        b.command(&cmd(2, CommandKind::Hold));
        b.command(&cmd(2, CommandKind::MoveBy));
        assert_eq!((b.count, b.first_frame), (1, Some(2)));
        // Calibrate moves by the plate only: no target trackers is fine, a lost plate is not
        // (here the command is read before its frame's telemetry).
        b.telemetry(&tel(3, Phase::Calibrate, [1, 1, 0, 0]));
        b.command(&cmd(3, CommandKind::MoveTo));
        b.command(&cmd(4, CommandKind::MoveTo));
        assert_eq!(b.count, 1);
        b.telemetry(&tel(4, Phase::Calibrate, [2, 1, 0, 0]));
        assert_eq!((b.count, b.first_frame), (2, Some(2)));
        // The grasp is open-loop: nothing is judged.
        b.telemetry(&tel(5, Phase::Grasp, [2, 2, 2, 2]));
        b.command(&cmd(5, CommandKind::MoveBy));
        assert_eq!(b.count, 2);
    }
}
