//! The payload and header types that cross shared memory.
//!
//! Every type here is `#[repr(C)]`, self-contained (no pointers, no `Drop`) and starts with a
//! `version` field equal to [`WIRE_VERSION`]. A receiver checks every sample with the matching
//! `validate` function before it reads anything else, so a bad sample is a counted rejection,
//! never a panic or an out-of-bounds read. Field order keeps every field naturally aligned
//! with no hidden padding, so a C or C++ driver can declare the same structs field by field.

use iceoryx2::prelude::*;

/// Version of the wire contract. Bumped on any change to a type in this module; a receiver
/// rejects samples of any other version.
pub const WIRE_VERSION: u32 = 4;

/// Service names (iceoryx2). The same names are used for the matching event services that
/// wake subscribers (see `wire/README.md`).
pub mod service {
    /// Stereo frames: `[u8]` payload with a [`super::StereoHeader`] user header.
    pub const STEREO: &str = "handeye/stereo";
    /// Robot state, published by the robot controller ([`super::RobotState`]).
    pub const ROBOT_STATE: &str = "handeye/robot/state";
    /// Robot commands, published by the daemon ([`super::RobotCommand`]).
    pub const ROBOT_COMMAND: &str = "handeye/robot/command";
    /// Daemon telemetry ([`super::Telemetry`]).
    pub const TELEMETRY: &str = "handeye/telemetry";
}

/// Pixel formats a stereo sample may carry. Only `Gray8` exists today; the numeric values are
/// part of the contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum PixelFormat {
    /// 8-bit luminance, one byte per pixel, 0 = black.
    Gray8 = 1,
}

impl PixelFormat {
    /// The format for a raw header value, or `None` if it is not one we know.
    pub fn from_u32(raw: u32) -> Option<Self> {
        match raw {
            1 => Some(Self::Gray8),
            _ => None,
        }
    }

    /// Bytes per pixel.
    pub fn bytes_per_pixel(self) -> u32 {
        match self {
            Self::Gray8 => 1,
        }
    }
}

/// User header of a `handeye/stereo` sample. The payload holds `camera_count` images one after
/// the other (camera 0 = left, camera 1 = right), each `height` rows of `stride` bytes, of
/// which the first `width * bytes_per_pixel` are pixels.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, ZeroCopySend)]
#[type_name("handeye::StereoHeader")]
#[repr(C)]
pub struct StereoHeader {
    /// Must equal [`WIRE_VERSION`].
    pub version: u32,
    /// A [`PixelFormat`] value.
    pub pixel_format: u32,
    /// Strictly increasing per publisher; a gap means frames were dropped.
    pub frame_id: u64,
    /// When the images were exposed, `CLOCK_MONOTONIC` nanoseconds of the publishing host.
    pub capture_time_ns: u64,
    /// When the sample was sent, `CLOCK_MONOTONIC` nanoseconds; receivers measure transport
    /// latency against it.
    pub publish_time_ns: u64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Bytes from the start of one row to the start of the next (>= width * bytes per pixel).
    pub stride: u32,
    /// Number of images in the payload; 2 for a stereo pair.
    pub camera_count: u32,
}

/// Bit flags in [`RobotState::flags`].
pub mod robot_flags {
    /// The tool is moving towards a target.
    pub const MOVING: u32 = 1 << 0;
    /// The last accepted target has been reached (within the controller's tolerance).
    pub const ARRIVED: u32 = 1 << 1;
    /// The controller is in a fault state; see [`super::RobotState::fault`]. It holds still.
    pub const FAULT: u32 = 1 << 2;
    /// The last command was refused; see [`super::RobotState::reject`].
    pub const REJECTED: u32 = 1 << 3;
    /// The gripper is commanded closed.
    pub const GRIPPER_CLOSED: u32 = 1 << 4;
    /// The gripper jaws have stopped moving.
    pub const GRIPPER_SETTLED: u32 = 1 << 5;
    /// The arm was stopped by the watchdog (no command for too long while moving).
    pub const WATCHDOG_STOP: u32 = 1 << 6;
    /// The arm was stopped by an explicit stop command.
    pub const STOPPED: u32 = 1 << 7;
}

/// Why a command was refused ([`RobotState::reject`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum RejectReason {
    None = 0,
    /// The target is outside the arm's reach.
    Unreachable = 1,
    /// The target needs a joint beyond its limits.
    JointLimit = 2,
    /// The command was malformed (version, kind, non-finite numbers).
    Malformed = 3,
    /// The controller is in a fault state and accepts only `Stop` and `ClearFault`.
    Faulted = 4,
}

impl RejectReason {
    pub fn from_u32(raw: u32) -> Option<Self> {
        Some(match raw {
            0 => Self::None,
            1 => Self::Unreachable,
            2 => Self::JointLimit,
            3 => Self::Malformed,
            4 => Self::Faulted,
            _ => return None,
        })
    }

    /// The reason in words, for a failure's detail (`None`: the controller gave no reason).
    pub fn text(self) -> &'static str {
        match self {
            Self::Unreachable => "unreachable",
            Self::JointLimit => "joint limit",
            Self::Malformed => "malformed",
            Self::Faulted => "robot faulted",
            Self::None => "refused",
        }
    }

    /// The words for a raw [`RobotState::reject`] code; "refused" for a code this version
    /// does not know.
    ///
    /// ```
    /// use handeye_wire::RejectReason;
    /// assert_eq!(RejectReason::text_of(2), "joint limit");
    /// assert_eq!(RejectReason::text_of(99), "refused");
    /// ```
    pub fn text_of(raw: u32) -> &'static str {
        Self::from_u32(raw).map_or("refused", Self::text)
    }
}

/// Number of arm joints reported in [`RobotState::joints_rad`].
pub const ARM_JOINTS: usize = 5;

/// `handeye/robot/state`: what the robot controller reports about itself, in its own
/// Cartesian frame (the robot frame: metres, z up). Published at least once per control tick.
#[derive(Debug, Default, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("handeye::RobotState")]
#[repr(C)]
pub struct RobotState {
    /// Must equal [`WIRE_VERSION`].
    pub version: u32,
    /// [`robot_flags`] bits.
    pub flags: u32,
    /// Increases with every state sample.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` nanoseconds when the state was read.
    pub time_ns: u64,
    /// `seq` of the last command the controller processed.
    pub last_command_seq: u64,
    /// `frame_id` of the last command the controller processed.
    pub last_command_frame_id: u64,
    /// Tool point (between the finger tips) in the robot frame, metres.
    pub tool_pos_m: [f32; 3],
    /// Tool yaw about the robot z axis (gripper pointing down), radians.
    pub tool_yaw_rad: f32,
    /// Joint angles, base to wrist roll, radians.
    pub joints_rad: [f32; ARM_JOINTS],
    /// Distance between the finger pads, metres.
    pub gripper_width_m: f32,
    /// A [`RejectReason`] for the last refused command.
    pub reject: u32,
    /// Controller-specific fault code; 0 when no fault.
    pub fault: u32,
}

/// What a [`RobotCommand`] asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum CommandKind {
    /// Change nothing; acknowledges a frame in lockstep and keeps the watchdog fed.
    Hold = 0,
    /// Move the tool point to `target_m` with yaw `yaw_rad` (gripper pointing down).
    MoveTo = 1,
    /// Move the tool point by `target_m` and yaw by `yaw_rad`, relative to the current target.
    MoveBy = 2,
    /// Stop now and hold the current pose; clears motion targets.
    Stop = 3,
    /// Leave the fault state (after a stop); the arm stays still.
    ClearFault = 4,
}

impl CommandKind {
    pub fn from_u32(raw: u32) -> Option<Self> {
        Some(match raw {
            0 => Self::Hold,
            1 => Self::MoveTo,
            2 => Self::MoveBy,
            3 => Self::Stop,
            4 => Self::ClearFault,
            _ => return None,
        })
    }
}

/// What a [`RobotCommand`] asks of the gripper.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum GripperCommand {
    /// Leave the gripper as it is.
    Keep = 0,
    Open = 1,
    Close = 2,
}

impl GripperCommand {
    pub fn from_u32(raw: u32) -> Option<Self> {
        Some(match raw {
            0 => Self::Keep,
            1 => Self::Open,
            2 => Self::Close,
            _ => return None,
        })
    }
}

/// `frame_id` of a command that answers no particular frame.
pub const NO_FRAME: u64 = u64::MAX;

/// `handeye/robot/command`: one command to the robot controller.
#[derive(Debug, Default, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("handeye::RobotCommand")]
#[repr(C)]
pub struct RobotCommand {
    /// Must equal [`WIRE_VERSION`].
    pub version: u32,
    /// A [`CommandKind`] value.
    pub kind: u32,
    /// Increases with every command from one sender.
    pub seq: u64,
    /// The stereo frame this command answers (lockstep), or [`NO_FRAME`].
    pub frame_id: u64,
    /// `CLOCK_MONOTONIC` nanoseconds when the command was sent.
    pub time_ns: u64,
    /// Target (`MoveTo`) or displacement (`MoveBy`) of the tool point, robot frame, metres.
    pub target_m: [f32; 3],
    /// Target or change of tool yaw, radians.
    pub yaw_rad: f32,
    /// Largest tool speed for this move, m/s; 0 = the controller's default.
    pub speed_limit_mps: f32,
    /// A [`GripperCommand`] value.
    pub gripper: u32,
}

/// Daemon phases as reported in [`Telemetry::phase`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Phase {
    Idle = 0,
    AcquireGripper = 1,
    Calibrate = 2,
    Plan = 3,
    AcquireTarget = 4,
    Servo = 5,
    Grasp = 6,
    Lift = 7,
    Done = 8,
    Failed = 9,
    Stopped = 10,
    /// `handeye daemon --observe`: tracking only, no robot, no commands.
    Observe = 11,
    /// Waiting for the operator's pointing gesture (after calibrate, before plan; since
    /// version 4). Appended, so its number does not give the phases' order.
    Point = 12,
}

impl Phase {
    pub fn from_u32(raw: u32) -> Option<Self> {
        Some(match raw {
            0 => Self::Idle,
            1 => Self::AcquireGripper,
            2 => Self::Calibrate,
            3 => Self::Plan,
            4 => Self::AcquireTarget,
            5 => Self::Servo,
            6 => Self::Grasp,
            7 => Self::Lift,
            8 => Self::Done,
            9 => Self::Failed,
            10 => Self::Stopped,
            11 => Self::Observe,
            12 => Self::Point,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Idle => "idle",
            Self::AcquireGripper => "acquire_gripper",
            Self::Calibrate => "calibrate",
            Self::Plan => "plan",
            Self::AcquireTarget => "acquire_target",
            Self::Servo => "servo",
            Self::Grasp => "grasp",
            Self::Lift => "lift",
            Self::Done => "done",
            Self::Failed => "failed",
            Self::Stopped => "stopped",
            Self::Observe => "observe",
            Self::Point => "point",
        }
    }

    /// Where the phase comes in a run (`point` between `calibrate` and `plan`, whatever its
    /// number): what "furthest phase reached" compares. `idle` and `observe` are 0.
    pub fn order(self) -> u32 {
        match self {
            Self::Idle | Self::Observe => 0,
            Self::AcquireGripper => 1,
            Self::Calibrate => 2,
            Self::Point => 3,
            Self::Plan => 4,
            Self::AcquireTarget => 5,
            Self::Servo => 6,
            Self::Grasp => 7,
            Self::Lift => 8,
            Self::Done => 9,
            Self::Failed => 10,
            Self::Stopped => 11,
        }
    }
}

/// [`Telemetry::pointing_state`]: what the pointing gesture showed on the frame the pointing
/// result is for (since version 4).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum PointingState {
    /// Not watching for a gesture (outside the `point` phase, or not started yet).
    Off = 0,
    /// Watching: no arm in view.
    Absent = 1,
    /// An arm in view, not yet still.
    Moving = 2,
    /// Still, and the two plane lines meet at `pointing_point_m`.
    Indicated = 3,
    /// Refused: the finger's line lies nearly in a plane through both cameras.
    Degenerate = 4,
    /// Refused: the point's uncertainty is over the limit.
    Uncertain = 5,
    /// Refused: in view too long without holding still.
    Unsteady = 6,
    /// Refused: no finger line in one view or both.
    NoLine = 7,
    /// Refused: the views disagree (the point lies behind the fingertip in one view).
    Disagree = 8,
}

impl PointingState {
    pub fn from_u32(raw: u32) -> Option<Self> {
        Some(match raw {
            0 => Self::Off,
            1 => Self::Absent,
            2 => Self::Moving,
            3 => Self::Indicated,
            4 => Self::Degenerate,
            5 => Self::Uncertain,
            6 => Self::Unsteady,
            7 => Self::NoLine,
            8 => Self::Disagree,
            _ => return None,
        })
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Off => "off",
            Self::Absent => "absent",
            Self::Moving => "moving",
            Self::Indicated => "indicated",
            Self::Degenerate => "degenerate",
            Self::Uncertain => "uncertain",
            Self::Unsteady => "unsteady",
            Self::NoLine => "no_line",
            Self::Disagree => "disagree",
        }
    }
}

/// Trackers reported in telemetry: gripper left/right, target left/right.
pub const TELEMETRY_TRACKERS: usize = 4;
/// Corners per tracker polygon reported in telemetry (unused ones are NaN).
pub const TELEMETRY_CORNERS: usize = 8;
/// Length of the servo error vector `[pi1, pi2, pi3, s - s*, t - t*, rho]`.
pub const SERVO_ERROR_LEN: usize = 6;
/// Bytes of UTF-8 text in [`Telemetry::reason`] (NUL-padded).
pub const REASON_LEN: usize = 96;

/// `handeye/telemetry`: the daemon's view of itself, once per loop cycle.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("handeye::Telemetry")]
#[repr(C)]
pub struct Telemetry {
    /// Must equal [`WIRE_VERSION`].
    pub version: u32,
    /// A [`Phase`] value.
    pub phase: u32,
    /// The stereo frame this cycle processed.
    pub frame_id: u64,
    /// `CLOCK_MONOTONIC` nanoseconds at the end of the cycle.
    pub time_ns: u64,
    /// Frame receive to command send, this cycle, nanoseconds.
    pub loop_ns: u64,
    /// Loop cycles that overran their deadline so far.
    pub deadline_misses: u64,
    /// Tracker updates so far, per tracker (rises at frame rate while a tracker runs).
    pub tracker_updates: [u64; TELEMETRY_TRACKERS],
    /// How long each tracker's update took this cycle, nanoseconds of the daemon's
    /// `CLOCK_MONOTONIC`; 0 for a tracker not updated this cycle. Their sum is the cycle's
    /// stereo tracker update, the time `daemon.json`'s `tracker_update` percentiles are over.
    pub tracker_update_ns: [u64; TELEMETRY_TRACKERS],
    /// 0 = off, 1 = tracking, 2 = lost, per tracker.
    pub tracker_state: [u32; TELEMETRY_TRACKERS],
    /// Tracker confidence in [0, 1], per tracker.
    pub tracker_confidence: [f32; TELEMETRY_TRACKERS],
    /// Tracker polygon corners in pixels, `[tracker][corner][u, v]`; NaN where unused.
    pub tracker_corners_px: [[[f32; 2]; TELEMETRY_CORNERS]; TELEMETRY_TRACKERS],
    /// Servo error vector (pixels and radians); NaN outside the servo phase.
    pub servo_error: [f32; SERVO_ERROR_LEN],
    /// Servo steps taken so far.
    pub servo_steps: u32,
    /// 1 while the planner worker is busy.
    pub planning: u32,
    /// Human-readable status or failure reason, UTF-8, NUL-padded.
    pub reason: [u8; REASON_LEN],
    /// Frames dropped before reaching the daemon so far: the gaps in the frame ids it saw
    /// (since version 3).
    pub dropped_frames: u64,
    /// The pointing update (both views) whose result this cycle took, nanoseconds of the
    /// pointing thread's `CLOCK_MONOTONIC`; 0 when none was taken (since version 4).
    pub pointing_update_ns: u64,
    /// A [`PointingState`] value.
    pub pointing_state: u32,
    /// The frame id the pointing result is for (it lags the cycle by a fixed number of
    /// frames), low 32 bits; 0 with `pointing_state` off.
    pub pointing_frame: u32,
    /// The indicated point on the working plane, robot `x, y`, metres; NaN unless
    /// `pointing_state` is indicated.
    pub pointing_point_m: [f32; 2],
    /// Its one-sigma radius, metres (uncertain: the refused value), and the angle at which
    /// the two plane lines cross, radians (degenerate: the refused value); NaN when unknown.
    pub pointing_sigma_m: f32,
    pub pointing_crossing_rad: f32,
    /// The fingertip in the left and right views, pixels; NaN when not seen.
    pub pointing_tip_px: [[f32; 2]; 2],
    /// The finger's axis line in the left and right views, `a u + b v + c = 0` with
    /// `a² + b² = 1`; NaN when not fitted.
    pub pointing_line_px: [[f32; 3]; 2],
}

impl Default for Telemetry {
    fn default() -> Self {
        Self {
            version: WIRE_VERSION,
            phase: Phase::Idle as u32,
            frame_id: NO_FRAME,
            time_ns: 0,
            loop_ns: 0,
            deadline_misses: 0,
            tracker_updates: [0; TELEMETRY_TRACKERS],
            tracker_update_ns: [0; TELEMETRY_TRACKERS],
            tracker_state: [0; TELEMETRY_TRACKERS],
            tracker_confidence: [0.0; TELEMETRY_TRACKERS],
            tracker_corners_px: [[[f32::NAN; 2]; TELEMETRY_CORNERS]; TELEMETRY_TRACKERS],
            servo_error: [f32::NAN; SERVO_ERROR_LEN],
            servo_steps: 0,
            planning: 0,
            reason: [0; REASON_LEN],
            dropped_frames: 0,
            pointing_update_ns: 0,
            pointing_state: PointingState::Off as u32,
            pointing_frame: 0,
            pointing_point_m: [f32::NAN; 2],
            pointing_sigma_m: f32::NAN,
            pointing_crossing_rad: f32::NAN,
            pointing_tip_px: [[f32::NAN; 2]; 2],
            pointing_line_px: [[f32::NAN; 3]; 2],
        }
    }
}

impl Telemetry {
    /// Stores `text` in `reason`, truncated at a character boundary to fit.
    pub fn set_reason(&mut self, text: &str) {
        self.reason = [0; REASON_LEN];
        let mut end = text.len().min(REASON_LEN);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        self.reason[..end].copy_from_slice(&text.as_bytes()[..end]);
    }

    /// The `reason` text up to the first NUL (invalid UTF-8 is replaced).
    pub fn reason_text(&self) -> String {
        let end = self.reason.iter().position(|&b| b == 0).unwrap_or(REASON_LEN);
        String::from_utf8_lossy(&self.reason[..end]).into_owned()
    }
}

/// `CLOCK_MONOTONIC` now, in nanoseconds: the clock every `*_time_ns` field uses. It is shared
/// by all processes on one host, so stamps from another process can be subtracted.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_MONOTONIC is always available on Linux.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    debug_assert_eq!(rc, 0);
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layouts_have_no_hidden_padding() {
        // A C driver declares these field by field; any padding would silently shift fields.
        assert_eq!(std::mem::size_of::<StereoHeader>(), 4 * 2 + 8 * 3 + 4 * 4);
        assert_eq!(std::mem::size_of::<RobotState>(), 4 * 2 + 8 * 4 + 4 * (3 + 1 + 5 + 1 + 2));
        assert_eq!(std::mem::size_of::<RobotCommand>(), 4 * 2 + 8 * 3 + 4 * (3 + 1 + 1 + 1));
        assert_eq!(std::mem::size_of::<Telemetry>(), 4 * 2 + 8 * 4 + 8 * 4 * 2 + 4 * 4 * 2 + 4 * 4 * 8 * 2 + 4 * 6 + 4 * 2 + 96 + 8 + 8 + 4 * 2 + 4 * 2 + 4 * 2 + 4 * 4 + 4 * 6);
        assert_eq!(std::mem::size_of::<Telemetry>(), 600);
    }

    #[test]
    fn reason_round_trips_and_truncates_on_char_boundary() {
        let mut t = Telemetry::default();
        t.set_reason("target tracker lost (left view)");
        assert_eq!(t.reason_text(), "target tracker lost (left view)");
        let long = "é".repeat(REASON_LEN); // 2 bytes each: must cut between characters
        t.set_reason(&long);
        assert_eq!(t.reason_text(), "é".repeat(REASON_LEN / 2));
    }

    #[test]
    fn enums_round_trip_and_reject_unknown_values() {
        for k in 0..5 {
            assert_eq!(CommandKind::from_u32(k).map(|c| c as u32), Some(k));
        }
        assert_eq!(CommandKind::from_u32(5), None);
        assert_eq!(PixelFormat::from_u32(0), None);
        for p in 0..13 {
            assert_eq!(Phase::from_u32(p).map(|x| x as u32), Some(p));
        }
        assert_eq!(Phase::from_u32(13), None);
        for p in 0..9 {
            assert_eq!(PointingState::from_u32(p).map(|x| x as u32), Some(p));
        }
        assert_eq!(PointingState::from_u32(9), None);
        // The point phase comes between calibrate and plan, whatever its number.
        assert!(Phase::Calibrate.order() < Phase::Point.order() && Phase::Point.order() < Phase::Plan.order());
    }

    #[test]
    fn monotonic_clock_advances() {
        let a = monotonic_ns();
        let b = monotonic_ns();
        assert!(b >= a && a > 0);
    }
}
