//! What every phase shares: the command a phase asks for ([`Cmd`]), what it decided
//! ([`Step`]), what it sees of one cycle ([`Cycle`]), waiting for a commanded move to finish
//! ([`MoveWait`]) and time-outs on the camera clock ([`crate::camera_clock`]).

use handeye_vision::image::ImageView;
use handeye_vision::tracker::{StereoStates, View};
use handeye_wire::report::FailureKind;
use handeye_wire::{robot_flags, CommandKind, GripperCommand, RobotState};

use crate::fault::Fault;

/// What a phase asks the robot for this frame (the hard loop stamps seq, frame and time).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cmd {
    pub kind: CommandKind,
    pub target_m: [f64; 3],
    pub yaw_rad: f64,
    pub speed_mps: f64,
    pub gripper: GripperCommand,
}

impl Cmd {
    pub const HOLD: Cmd = Cmd { kind: CommandKind::Hold, target_m: [0.0; 3], yaw_rad: 0.0, speed_mps: 0.0, gripper: GripperCommand::Keep };
    pub const STOP: Cmd = Cmd { kind: CommandKind::Stop, ..Cmd::HOLD };

    pub fn gripper(g: GripperCommand) -> Cmd {
        Cmd { gripper: g, ..Cmd::HOLD }
    }

    pub fn move_to(p: [f64; 3], yaw_rad: f64, speed_mps: f64) -> Cmd {
        Cmd { kind: CommandKind::MoveTo, target_m: p, yaw_rad, speed_mps, gripper: GripperCommand::Keep }
    }

    pub fn move_by(d: [f64; 3], dyaw_rad: f64, speed_mps: f64) -> Cmd {
        Cmd { kind: CommandKind::MoveBy, target_m: d, yaw_rad: dyaw_rad, speed_mps, gripper: GripperCommand::Keep }
    }

    pub fn is_move(&self) -> bool {
        matches!(self.kind, CommandKind::MoveTo | CommandKind::MoveBy)
    }
}

/// What a phase decided this frame.
#[derive(Debug, Clone, PartialEq)]
pub enum Step {
    /// Stay; send this.
    Stay(Cmd),
    /// Send this and go on to the next phase.
    Next(Cmd),
    /// The phase failed: the arm is stopped and the run ends with this fault.
    Fail(Fault),
}

impl Step {
    /// The phase failed with a fault of `kind`, worded `detail`.
    pub fn fail(kind: FailureKind, detail: impl Into<String>) -> Step {
        Step::Fail(Fault::new(kind, detail))
    }
}

/// Everything a phase sees of one cycle.
pub struct Cycle<'a> {
    /// Frames processed since start (0-based): what settle and converge counts count.
    pub frame_index: u64,
    /// Camera time of this frame since the first, ns: the daemon's clock for time-outs.
    pub time_ns: u64,
    pub frame_id: u64,
    /// The newest robot state (the hard loop refuses to run phases without one).
    pub robot: &'a RobotState,
    /// `seq` of the most recent state sample that reported `REJECTED`.
    pub rejected_seq: Option<u64>,
    /// `seq` the command sent this cycle will carry.
    pub seq: u64,
    pub left: &'a ImageView<'a>,
    pub right: &'a ImageView<'a>,
    pub states: StereoStates,
}

/// Waiting for one commanded move: sent, processed by the controller, arrived, settled.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveWait {
    pub seq: u64,
    pub sent_frame: u64,
    settled: u32,
}

/// How a move stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MovePoll {
    Pending,
    /// Arrived and still for the asked number of frames.
    Done,
    /// The controller refused it (a raw [`handeye_wire::RejectReason`] code).
    Rejected(u32),
}

impl MoveWait {
    pub fn new(seq: u64, frame_index: u64) -> Self {
        Self { seq, sent_frame: frame_index, settled: 0 }
    }

    /// Checks this cycle's robot state. `settle_frames` frames after arrival count as done.
    pub fn poll(&mut self, c: &Cycle<'_>, settle_frames: u32) -> MovePoll {
        if c.rejected_seq == Some(self.seq) {
            return MovePoll::Rejected(c.robot.reject);
        }
        let processed = c.robot.last_command_seq >= self.seq;
        let flags = c.robot.flags;
        let arrived = flags & robot_flags::ARRIVED != 0 && flags & robot_flags::MOVING == 0;
        // The state of the frame right after sending may predate the move.
        if processed && arrived && c.frame_index >= self.sent_frame + 2 {
            self.settled += 1;
            if self.settled > settle_frames {
                return MovePoll::Done;
            }
        } else {
            self.settled = 0;
        }
        MovePoll::Pending
    }
}

/// Slack for capture stamps rounded to whole nanoseconds (a simulator's 1/30 s), ns.
const STAMP_SLACK_NS: u64 = 1_000;

/// Seconds → ns of camera time (negative or NaN: 0).
fn ns(seconds: f64) -> u64 {
    if seconds.is_finite() && seconds > 0.0 { (seconds * 1e9).min(u64::MAX as f64) as u64 } else { 0 }
}

/// `true` when at least `seconds` of camera time lie between `start_ns` and `now_ns`.
pub fn elapsed_at_least(start_ns: u64, now_ns: u64, seconds: f64) -> bool {
    now_ns.saturating_sub(start_ns).saturating_add(STAMP_SLACK_NS) >= ns(seconds)
}

/// `true` when `now_ns` is past `start_ns + timeout_s` of camera time.
pub fn timed_out(start_ns: u64, now_ns: u64, timeout_s: f64) -> bool {
    now_ns.saturating_sub(start_ns) > ns(timeout_s).saturating_add(STAMP_SLACK_NS)
}

/// What a phase did when it picked up after a hold (the loss's record says it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Resumed {
    /// Went on where it stopped (a move under way sent again, samples being taken afresh).
    Resumed,
    /// Calibrating: the plate came back this far away: a camera moved; the cage from the start.
    CageAgain { plate_shift_px: f64 },
    /// After the calibration: the plate came back shifted in this view: a camera moved;
    /// calibrating again (and planning again, for a planned target).
    Recalibrate { view: View, shift_px: [f64; 2] },
    /// Servoing: a knocked view; the servo's model moved with its image.
    KnockFollowed { view: View },
    /// Servoing: the target came back this far away: it moved; the servo started again on it.
    TargetMoved { target_shift_px: f64 },
}

impl std::fmt::Display for Resumed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let side = |v: &View| if *v == View::Left { "left" } else { "right" };
        match self {
            Self::Resumed => write!(f, "resumed"),
            Self::CageAgain { plate_shift_px } => write!(f, "a camera moved (plate {plate_shift_px:.0} px away): cage visited again"),
            Self::Recalibrate { view, shift_px } => {
                write!(f, "{} camera moved (plate {:.0} px away): calibrated again", side(view), shift_px[0].hypot(shift_px[1]))
            }
            Self::KnockFollowed { view } => write!(f, "{} camera moved: the servo's model follows its image", side(view)),
            Self::TargetMoved { target_shift_px } => write!(f, "the target moved ({target_shift_px:.0} px): servo started again on it"),
        }
    }
}
