//! The daemon's phases (METHOD.md §1, §3, §6): acquire gripper → calibrate → plan (unless
//! an operator hint names the target) → acquire target → servo → grasp → lift → done, each with a time-out and a failure reason; `failed` and
//! `stopped` end a run. One file per phase; this module holds what they share: the
//! [`Mission`] (state that lives across phases), the command a phase asks for ([`Cmd`]),
//! and waiting for a commanded move to finish ([`MoveWait`]).
//!
//! A phase's `step` runs once per frame, after the trackers were updated on that frame, and
//! returns what to send now and whether to move on. Nothing here allocates in the servo's
//! steady state; the moments that do (copying frames for gripper location, snapshots for the
//! report) are marked.

pub mod acquire_gripper;
pub mod acquire_target;
pub mod calibrate;
pub mod grasp;
pub mod plan;
pub mod servo;

use handeye_vision::affine::{AffineStereo, EpipolarConstraint};
use handeye_vision::image::ImageView;
use handeye_vision::servo::ServoModel;
use handeye_vision::tracker::{Role, StereoStates, StereoTrackerSet, TrackerConfig, View};
use handeye_wire::{robot_flags, CommandKind, GripperCommand, Phase, RobotState};
use serde::{Deserialize, Serialize};

use crate::config::DaemonConfig;
use crate::gripper::PlateTemplate;
use handeye_wire::hint::OperatorHint;
use crate::worker::Worker;

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
    /// The phase failed: the arm is stopped and the run ends with this reason.
    Fail(String),
}

/// Everything a phase sees of one cycle.
pub struct Cycle<'a> {
    /// Frames processed since start (0-based), the daemon's clock for time-outs.
    pub frame_index: u64,
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

/// The calibration's result and how good it is.
#[derive(Debug, Clone)]
pub struct Calibration {
    pub model: AffineStereo,
    pub epipolar: EpipolarConstraint,
    pub servo_model: ServoModel,
    pub stats: CalibrationStats,
    /// The cage as measured: tool positions (robot frame, m) and the reference point's
    /// images `(u, v, u', v')` (tracker pixels); the planner fits pinhole cameras to them.
    pub cage_robot_m: Vec<nalgebra::Vector3<f64>>,
    pub cage_image_px: Vec<[f64; 4]>,
}

/// Numbers of the calibration for the outcome and the report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CalibrationStats {
    pub points: usize,
    /// RMS residual of the affine fit over the cage, px.
    pub residual_rms_px: f64,
    /// RMS residual of the epipolar constraint fitted from the images alone, px.
    pub epipolar_rms_px: f64,
    /// Disparity limits of the workspace (`u − u'` over the cage), px.
    pub disparity_range_px: [f64; 2],
}

/// Jobs for the worker thread (work longer than a frame).
pub enum Job {
    /// Locate the moving fingers in both views and find the plate above them.
    LocateGripper { open: [handeye_vision::image::ImageBuf; 2], closed: [handeye_vision::image::ImageBuf; 2] },
    /// Fit the affine stereo model and the epipolar constraint to the cage.
    Calibrate { robot_m: Vec<nalgebra::Vector3<f64>>, image_px: Vec<[f64; 4]> },
    /// Plan a grasp on one stereo pair.
    Plan(Box<crate::planning::PlanRequest>),
}

/// Results from the worker.
#[derive(Debug)]
pub enum JobResult {
    Plate(Result<[[[f64; 2]; 4]; 2], String>),
    Calibration(Result<(AffineStereo, EpipolarConstraint, f64), String>),
    Plan(Box<crate::planning::PlanOutput>),
}

/// Frames after submission at which a worker result is taken (it waits if it is early).
/// A fixed pipeline delay keeps lockstep runs repeatable: the worker's wall-clock speed
/// never decides on which frame the loop moves on. 1 s at 30 frames/s is far more than
/// either job needs, and the loop keeps tracking and answering frames meanwhile.
pub const WORKER_DELAY_FRAMES: u64 = 30;

/// The worker's job function.
pub fn run_job(job: Job) -> JobResult {
    match job {
        Job::LocateGripper { open, closed } => JobResult::Plate(acquire_gripper::locate_plates(&open, &closed)),
        Job::Calibrate { robot_m, image_px } => JobResult::Calibration(calibrate::fit(&robot_m, &image_px)),
        Job::Plan(request) => JobResult::Plan(Box::new(crate::planning::plan(*request))),
    }
}

/// One servo step for the report's plot.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ServoTraceRow {
    pub step: u32,
    pub frame: u64,
    /// `[π1, π2, π3, s − s*, t − t*, ρ]`.
    pub error: [f64; 6],
    /// Estimated remaining offset: translation norm (m) and yaw (rad).
    pub offset_m: f64,
    pub offset_yaw_rad: f64,
}

/// Where the target came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetSource {
    /// The operator clicked the facet in both views (`hint.json`).
    Hint,
    /// The grasp planner chose it.
    Plan,
}

/// The target facet and how to grasp it: from the operator hint or from the plan.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetSpec {
    pub source: TargetSource,
    /// The facet's outline in both views, tracker pixels, vertex for vertex.
    pub left_px: Vec<[f64; 2]>,
    pub right_px: Vec<[f64; 2]>,
    /// Extent of the object behind the facet along its normal: the grasp width, m.
    pub depth_m: f64,
    /// The grasp site in both views when the target was chosen, tracker pixels (`None`:
    /// the facet's centre).
    pub site_px: Option<[[f64; 2]; 2]>,
    /// The site in each target tracker's template coordinates, set once they are on the
    /// facet: the site then moves with the tracked facet.
    pub site_template: Option<[[f64; 2]; 2]>,
    /// Tool height at the grasp, robot frame, m (`None`: `servo.grasp_height_m` above the
    /// table).
    pub grasp_tool_z_m: Option<f64>,
}

impl TargetSpec {
    pub fn from_hint(h: &OperatorHint) -> Self {
        Self {
            source: TargetSource::Hint,
            left_px: h.left_px.clone(),
            right_px: h.right_px.clone(),
            depth_m: h.depth_mm * 1e-3,
            site_px: None,
            site_template: None,
            grasp_tool_z_m: None,
        }
    }
}

/// How the loop fared while the planner worked.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlanningStats {
    /// Frames answered between handing the pair over and taking the result.
    pub frames: u64,
    /// Gripper tracker updates (left, right) meanwhile: one per frame when it kept tracking.
    pub gripper_updates: [u64; 2],
    pub planner_ms: f64,
    pub total_ms: f64,
}

/// State shared across phases.
pub struct Mission {
    pub cfg: DaemonConfig,
    pub tracker_config: TrackerConfig,
    pub plate: PlateTemplate,
    pub hint: Option<OperatorHint>,
    /// What to grasp: set from the hint at start-up, or by the plan phase.
    pub target: Option<TargetSpec>,
    /// The operator's indicated point on the working plane, robot frame, m.
    pub indicated_m: Option<[f64; 3]>,
    /// What the planner found (`None` before the plan phase, or with a hint).
    pub plan: Option<crate::planning::PlanSummary>,
    /// The plan's other grasp sites near the indicated point, next best first: tried in turn
    /// when the target trackers cannot hold the chosen facet or it turns out not vertical.
    pub alternatives: Vec<TargetSpec>,
    /// Targets tried (1 when the first one served).
    pub target_attempts: u32,
    /// The plan with its images, for the report (taken by whoever writes it).
    pub plan_report: Option<Box<crate::planning::PlanOutput>>,
    pub planning: Option<PlanningStats>,
    pub trackers: StereoTrackerSet,
    pub worker: Worker<Job, JobResult>,
    pub calibration: Option<Calibration>,
    /// Tool yaw during the calibration (the model absorbed the plate's offset at this yaw).
    pub calibration_yaw_rad: Option<f64>,
    /// Pose at start-up: where the arm is parked between phases.
    pub start_pose: Option<([f64; 3], f64)>,
    pub servo_trace: Vec<ServoTraceRow>,
    pub servo_steps: u32,
    /// Last measured servo error (NaN outside the servo).
    pub servo_error: [f64; 6],
    /// Status text for telemetry.
    pub status: String,
    /// A report snapshot was asked for this cycle, with this label.
    pub snapshot: Option<&'static str>,
    /// Jaw opening after closing on the target, m.
    pub grip_width_m: Option<f64>,
}

impl Mission {
    pub fn new(cfg: DaemonConfig, hint: Option<OperatorHint>) -> std::io::Result<Self> {
        let tracker_config = cfg.tracker.tracker_config();
        let plate = PlateTemplate::new(&cfg.gripper);
        let trace_capacity = cfg.servo.max_steps as usize + 2;
        Ok(Self {
            cfg,
            tracker_config,
            plate,
            target: hint.as_ref().map(TargetSpec::from_hint),
            hint,
            indicated_m: None,
            plan: None,
            alternatives: Vec::new(),
            target_attempts: 0,
            plan_report: None,
            planning: None,
            trackers: StereoTrackerSet::new(),
            worker: Worker::spawn("handeye-worker", 2, run_job)?,
            calibration: None,
            calibration_yaw_rad: None,
            start_pose: None,
            servo_trace: Vec::with_capacity(trace_capacity),
            servo_steps: 0,
            servo_error: [f64::NAN; 6],
            status: String::with_capacity(128),
            snapshot: None,
            grip_width_m: None,
        })
    }

    /// Gives up the current target (removing its trackers) for the plan's next grasp site;
    /// `None` when there is none left.
    pub fn next_target(&mut self, why: &str) -> Option<TargetSpec> {
        if self.alternatives.is_empty() {
            return None;
        }
        let next = self.alternatives.remove(0);
        tracing::warn!(%why, left = self.alternatives.len(), "target given up: trying the plan's next grasp site");
        for view in View::ALL {
            self.trackers.remove(Role::Target, view);
        }
        self.set_status("acquire target: trying the next grasp site");
        self.snapshot = Some("target_given_up");
        Some(next)
    }

    /// Sets the status text without allocating (when it fits the buffer).
    pub fn set_status(&mut self, text: &str) {
        self.status.clear();
        self.status.push_str(text);
    }

    /// Whether both trackers of `role` exist and are active.
    pub fn has_pair(&self, role: Role) -> bool {
        View::ALL.iter().all(|&v| self.trackers.is_active(role, v))
    }
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
    /// The controller refused it.
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

/// Text for a controller's reject code.
pub fn reject_text(code: u32) -> &'static str {
    match code {
        1 => "unreachable",
        2 => "joint limit",
        3 => "malformed",
        4 => "robot faulted",
        _ => "refused",
    }
}

/// Which phases need which trackers tracking (a lost one stops the arm).
pub fn needs_trackers(phase: Phase) -> (bool, bool) {
    match phase {
        // While the target trackers converge the arm holds still: acquire_target judges them
        // itself at the end (and may try the plan's next grasp site instead).
        Phase::Calibrate | Phase::Plan | Phase::AcquireTarget => (true, false),
        Phase::Servo => (true, true),
        _ => (false, false),
    }
}

/// The phase state machine's current phase with its local state.
pub enum PhaseState {
    AcquireGripper(acquire_gripper::AcquireGripper),
    Calibrate(calibrate::Calibrate),
    Plan(plan::PlanPhase),
    AcquireTarget(acquire_target::AcquireTarget),
    Servo(Box<servo::ServoPhase>),
    Grasp(grasp::Grasp),
    Lift(grasp::Lift),
    Done { since_frame: u64 },
    Failed,
    Stopped,
}

impl PhaseState {
    pub fn phase(&self) -> Phase {
        match self {
            Self::AcquireGripper(_) => Phase::AcquireGripper,
            Self::Calibrate(_) => Phase::Calibrate,
            Self::Plan(_) => Phase::Plan,
            Self::AcquireTarget(_) => Phase::AcquireTarget,
            Self::Servo(_) => Phase::Servo,
            Self::Grasp(_) => Phase::Grasp,
            Self::Lift(_) => Phase::Lift,
            Self::Done { .. } => Phase::Done,
            Self::Failed => Phase::Failed,
            Self::Stopped => Phase::Stopped,
        }
    }

    pub fn is_terminal(&self) -> bool {
        matches!(self, Self::Done { .. } | Self::Failed | Self::Stopped)
    }

    /// Runs the current phase for one cycle; on `Next` builds the following phase.
    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        let step = match self {
            Self::AcquireGripper(p) => p.step(m, c),
            Self::Calibrate(p) => p.step(m, c),
            Self::Plan(p) => p.step(m, c),
            Self::AcquireTarget(p) => p.step(m, c),
            Self::Servo(p) => p.step(m, c),
            Self::Grasp(p) => p.step(m, c),
            Self::Lift(p) => p.step(m, c),
            Self::Done { .. } | Self::Failed | Self::Stopped => return Step::Stay(Cmd::HOLD),
        };
        // A target that cannot be acquired or served: the plan's next grasp site, if any.
        if let Step::Fail(reason) = &step
            && matches!(self, Self::AcquireTarget(_))
            && let Some(next) = m.next_target(reason)
        {
            *self = Self::AcquireTarget(acquire_target::AcquireTarget::new(c.frame_index));
            m.target = Some(next);
            return Step::Stay(Cmd::HOLD);
        }
        if let Step::Next(_) = step {
            *self = match self {
                Self::AcquireGripper(_) => Self::Calibrate(calibrate::Calibrate::new(c.frame_index)),
                // With a target from the operator hint there is nothing to plan.
                Self::Calibrate(_) if m.target.is_some() => Self::AcquireTarget(acquire_target::AcquireTarget::new(c.frame_index)),
                Self::Calibrate(_) => Self::Plan(plan::PlanPhase::new(c.frame_index)),
                Self::Plan(_) => Self::AcquireTarget(acquire_target::AcquireTarget::new(c.frame_index)),
                Self::AcquireTarget(_) => match servo::ServoPhase::new(m, c) {
                    Ok(p) => Self::Servo(Box::new(p)),
                    Err(reason) => match m.next_target(&reason) {
                        Some(next) => {
                            m.target = Some(next);
                            Self::AcquireTarget(acquire_target::AcquireTarget::new(c.frame_index))
                        }
                        None => return Step::Fail(reason),
                    },
                },
                Self::Servo(p) => Self::Grasp(grasp::Grasp::new(c.frame_index, p.approach_m)),
                Self::Grasp(_) => Self::Lift(grasp::Lift::new(c.frame_index)),
                Self::Lift(_) => Self::Done { since_frame: c.frame_index },
                Self::Done { .. } | Self::Failed | Self::Stopped => Self::Failed,
            };
        }
        step
    }
}

/// `true` when `frame_index` is past `start + timeout_s` frames.
pub fn timed_out(cfg: &DaemonConfig, start_frame: u64, frame_index: u64, timeout_s: f64) -> bool {
    frame_index.saturating_sub(start_frame) > cfg.frames(timeout_s)
}
