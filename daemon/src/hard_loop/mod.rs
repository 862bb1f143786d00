//! The hard loop's per-frame work, without I/O: update the trackers over the frame's pixels
//! in place, run the safety checks and the current phase, and produce exactly one command
//! (stamped with the frame's id; `Hold` when there is nothing to do) and one telemetry
//! sample. A cycle hands out everything it produced ([`CycleOutput`]: the command and the
//! report material); the telemetry follows from [`HardLoop::finish_cycle`].
//! `service.rs` wraps it in the shared-memory transport; tests drive it in-process.
//!
//! Everything is allocated up front: in the servo's steady state a cycle allocates nothing
//! (`tests/daemon_inprocess.rs` counts). The exceptions are the moments that are meant to:
//! copying the open/closed frames when locating the gripper, building trackers and the servo
//! on entering a phase, and the failure text.

use handeye_vision::image::ImageView;
use handeye_vision::tracker::{Role, StereoStates, View};
use handeye_wire::hint::OperatorHint;
use handeye_wire::report::{Failure, FailureKind};
use handeye_wire::{
    monotonic_ns, robot_flags, Phase, RobotCommand, RobotState, Telemetry, NO_FRAME, TELEMETRY_CORNERS, WIRE_VERSION,
};

mod hold;
mod shape_watch;

use shape_watch::ShapeWatch;

use crate::camera_clock::{CameraClock, ClockStats, FrameTick};
use crate::config::DaemonConfig;
use crate::fault::Fault;
use crate::mission::{Mission, ReportRequests};
use crate::outcome::{DaemonOutcome, HoldRecord, LoopTiming, LossRecord, RunEnd, TaskRecord, TrackerTiming};
use crate::phase::acquire_gripper::AcquireGripper;
use crate::phase::step::{elapsed_at_least, timed_out, Cmd, Cycle, Step};
use crate::phase::PhaseState;
use crate::recovery::{LastGood, Recovery};
use crate::safety::{check_robot, check_trackers};
use crate::timing::LatencyHistogram;

/// What one cycle produced: the command answering the frame, and what it asked the report
/// for.
#[derive(Debug)]
pub struct CycleOutput {
    pub command: RobotCommand,
    pub reports: ReportRequests,
}

/// The daemon's state between frames.
pub struct HardLoop {
    mission: Mission,
    phase: PhaseState,
    timing: LatencyHistogram,
    /// The stereo tracker update per cycle (all active trackers, summed), in the cycles that
    /// updated one; reported in `daemon.json` and, per tracker, in the telemetry.
    tracker_timing: LatencyHistogram,
    seq: u64,
    frames: u64,
    /// The daemon's time, from the frames' capture stamps.
    clock: CameraClock,
    robot: Option<RobotState>,
    /// A robot state arrived since the last cycle.
    robot_fresh: bool,
    /// Camera time of the cycle that last had a fresh robot state, ns.
    robot_seen_ns: u64,
    robot_states: u64,
    rejected_seq: Option<u64>,
    /// Furthest working phase entered.
    phase_reached: Phase,
    failure: Option<Failure>,
    telemetry: Telemetry,
    stopped_at_frame: Option<u64>,
    /// Holding the arm while lost trackers are searched for.
    recovery: Option<Recovery>,
    /// While holding: the jaws opening and closing to locate a plate the search did not find
    /// (as at start-up), and the camera time it began.
    jaws: Option<(AcquireGripper, u64)>,
    /// The jaws were tried in the hold under way (once a hold).
    jaws_tried: bool,
    /// Losses recovered from, and the camera time the arm held for them, ns.
    recoveries: u32,
    held_ns: u64,
    /// Each tracker's last confident frame (by `recovery::slot_index`): where a search
    /// for it starts.
    last_good: [Option<LastGood>; 4],
    /// Each tracker's shape history: which of its frames may be a search base.
    shapes: [ShapeWatch; 4],
    /// Move commands a phase asked for while a tracker it needs was lost, turned into
    /// holds where commands are stamped (a bug if ever non-zero; see `cycle`).
    moves_refused: u64,
    /// Each hold for lost trackers, for `daemon.json`; the one under way: its phase and the
    /// frame id it began on.
    losses: Vec<LossRecord>,
    loss_began: (Phase, u64),
}

impl HardLoop {
    pub fn new(cfg: DaemonConfig, hint: Option<OperatorHint>) -> std::io::Result<Self> {
        let deadline_ns = cfg.timing.deadline_us * 1000;
        let clock = CameraClock::new(cfg.timing.frame_rate_hz);
        Ok(Self {
            mission: Mission::new(cfg, hint.as_ref())?,
            phase: PhaseState::AcquireGripper(AcquireGripper::new(0)),
            timing: LatencyHistogram::new(deadline_ns),
            tracker_timing: LatencyHistogram::new(u64::MAX),
            seq: 0,
            frames: 0,
            clock,
            robot: None,
            robot_fresh: false,
            robot_seen_ns: 0,
            robot_states: 0,
            rejected_seq: None,
            phase_reached: Phase::AcquireGripper,
            failure: None,
            telemetry: Telemetry::default(),
            stopped_at_frame: None,
            recovery: None,
            jaws: None,
            jaws_tried: false,
            recoveries: 0,
            held_ns: 0,
            last_good: [None; 4],
            shapes: [ShapeWatch::default(); 4],
            moves_refused: 0,
            losses: Vec::new(),
            loss_began: (Phase::AcquireGripper, 0),
        })
    }

    /// The operator's indicated point on the working plane (robot frame, m): the plan phase
    /// executes the grasp site nearest it (without one, the highest).
    pub fn set_indicated_point(&mut self, point_m: Option<[f64; 3]>) {
        self.mission.targeting.set_indicated_m(point_m);
    }

    /// One robot state sample (the transport drains them all before each cycle). A reading
    /// that makes no sense stops the arm at the next cycle.
    pub fn robot_state(&mut self, s: &RobotState) {
        if s.flags & robot_flags::REJECTED != 0 {
            self.rejected_seq = Some(s.last_command_seq);
        }
        if self.failure.is_none()
            && let Err(fault) = check_robot(&self.mission.cfg.safety, self.robot.as_ref(), s)
        {
            self.stop_reason(Phase::Stopped, fault);
        }
        self.mission.calibration.note_start_pose(s.tool_pos_m.map(f64::from), f64::from(s.tool_yaw_rad));
        self.robot = Some(*s);
        self.robot_fresh = true;
        self.robot_states += 1;
    }

    /// Ends the run as `phase` (failed or stopped) with `fault`, raised in the phase current
    /// until now.
    fn stop_reason(&mut self, phase: Phase, fault: Fault) {
        tracing::warn!(phase = phase.name(), reason = %fault, "arm stopped");
        self.failure = Some(fault.in_phase(self.phase.phase()));
        self.phase = if phase == Phase::Failed { PhaseState::Failed } else { PhaseState::Stopped };
        self.mission.reporting.snapshot(if phase == Phase::Failed { "failed" } else { "stopped" });
    }

    /// Processes one stereo frame (its id and `capture_time_ns` from the stereo header) and
    /// returns what it produced: the command answering it and the report requests. Call
    /// [`Self::finish_cycle`] with the cycle's duration before publishing the telemetry.
    pub fn cycle(&mut self, frame_id: u64, capture_time_ns: u64, left: &ImageView<'_>, right: &ImageView<'_>) -> CycleOutput {
        let frame_index = self.frames;
        self.frames += 1;
        let tick = self.clock.tick(frame_id, capture_time_ns);
        if tick.bad_stamp {
            tracing::warn!(frame_id, capture_time_ns, "capture stamp not believed: one frame period assumed");
        }
        if std::mem::take(&mut self.robot_fresh) {
            self.robot_seen_ns = tick.now_ns;
        }
        let (states, update_ns) = self.mission.trackers.update_timed(left, right, tick.dt_s, monotonic_ns);
        self.telemetry.tracker_update_ns = update_ns;
        self.note_good_frames(&states, tick.now_ns);
        let phase_before = self.phase.phase();
        let cmd = self.decide(frame_index, frame_id, tick, left, right, states);
        let cmd = self.refuse_blind_moves(cmd, phase_before, &states);
        let phase = self.phase.phase();
        if !matches!(phase, Phase::Failed | Phase::Stopped) && phase.order() > self.phase_reached.order() {
            self.phase_reached = phase;
        }
        // The first cycle after the run failed or stopped stops the arm explicitly.
        let cmd = if matches!(phase, Phase::Failed | Phase::Stopped) && self.stopped_at_frame.is_none() {
            self.stopped_at_frame = Some(frame_id);
            Cmd::STOP
        } else {
            cmd
        };
        let command = self.stamp(&cmd, frame_id);
        self.fill_telemetry(frame_id, &states);
        // Recorded from what the telemetry says, so a monitor computes the same numbers.
        let stereo_update_ns: u64 = self.telemetry.tracker_update_ns.iter().sum();
        if stereo_update_ns > 0 {
            self.tracker_timing.record_ns(stereo_update_ns);
        }
        CycleOutput { command, reports: self.mission.reporting.take_requests() }
    }

    fn decide(&mut self, frame_index: u64, frame_id: u64, tick: FrameTick, left: &ImageView<'_>, right: &ImageView<'_>, states: StereoStates) -> Cmd {
        if self.phase.is_terminal() {
            return Cmd::HOLD;
        }
        let stale_s = self.mission.cfg.safety.state_stale_ms as f64 * 1e-3;
        let Some(robot) = self.robot else {
            if elapsed_at_least(0, tick.now_ns, stale_s) {
                self.stop_reason(Phase::Stopped, Fault::new(FailureKind::RobotState, "no robot state received"));
            }
            return Cmd::HOLD;
        };
        if timed_out(self.robot_seen_ns, tick.now_ns, stale_s) {
            let detail = format!("no robot state for {:.0} ms of camera time", (tick.now_ns - self.robot_seen_ns) as f64 * 1e-6);
            self.stop_reason(Phase::Stopped, Fault::new(FailureKind::RobotState, detail));
            return Cmd::STOP;
        }
        let phase = self.phase.phase();
        let cycle = Cycle { frame_index, time_ns: tick.now_ns, frame_id, robot: &robot, rejected_seq: self.rejected_seq, seq: self.seq + 1, left, right, states };
        if self.recovery.is_some() {
            self.phase.keep_watching(&mut self.mission, &cycle); // the operator's gesture goes on
            return self.hold_and_search(phase, &cycle);
        }
        if let Err(fault) = check_trackers(&self.mission.cfg.safety, phase, &states, &self.mission.trackers) {
            // A tracker the phase needs is lost: hold the arm and search for it (unless
            // holding is switched off).
            if self.start_hold(phase, frame_id, tick.now_ns, &states) {
                self.phase.keep_watching(&mut self.mission, &cycle);
                return Cmd::STOP;
            }
            self.stop_reason(Phase::Stopped, fault);
            return Cmd::STOP;
        }
        match self.phase.step(&mut self.mission, &cycle) {
            Step::Stay(c) | Step::Next(c) => c,
            Step::Fail(fault) => {
                self.stop_reason(Phase::Failed, fault);
                Cmd::STOP
            }
        }
    }

    fn stamp(&mut self, c: &Cmd, frame_id: u64) -> RobotCommand {
        self.seq += 1;
        let f = |x: f64| if x.is_finite() { x as f32 } else { 0.0 };
        RobotCommand {
            version: WIRE_VERSION,
            kind: c.kind as u32,
            seq: self.seq,
            frame_id,
            time_ns: monotonic_ns(),
            target_m: c.target_m.map(f),
            yaw_rad: f(c.yaw_rad),
            speed_limit_mps: f(c.speed_mps).max(0.0),
            gripper: c.gripper as u32,
        }
    }

    fn fill_telemetry(&mut self, frame_id: u64, states: &StereoStates) {
        let t = &mut self.telemetry;
        let phase = self.phase.phase();
        t.phase = phase as u32;
        t.frame_id = frame_id;
        for (i, (role, view)) in
            [(Role::Gripper, View::Left), (Role::Gripper, View::Right), (Role::Target, View::Left), (Role::Target, View::Right)]
                .into_iter()
                .enumerate()
        {
            t.tracker_corners_px[i] = [[f32::NAN; 2]; TELEMETRY_CORNERS];
            match self.mission.trackers.get(role, view) {
                Some(tr) => {
                    t.tracker_updates[i] = tr.update_count();
                    t.tracker_state[i] = match states.get(role, view) {
                        Some(s) if s.is_tracking() => 1,
                        Some(_) => 2,
                        None if self.recovery.as_ref().is_some_and(|r| r.is_searching(role, view)) => 2,
                        None if self.mission.trackers.is_active(role, view) => 1,
                        None => 0,
                    };
                    let score = tr.confidence().score;
                    t.tracker_confidence[i] = if score.is_finite() { score.clamp(0.0, 1.0) as f32 } else { 0.0 };
                    for (k, c) in tr.corners().take(TELEMETRY_CORNERS).enumerate() {
                        if c.x.is_finite() && c.y.is_finite() {
                            t.tracker_corners_px[i][k] = [c.x as f32, c.y as f32];
                        }
                    }
                }
                None => {
                    t.tracker_state[i] = 0;
                    t.tracker_confidence[i] = 0.0;
                }
            }
            if t.tracker_state[i] == 0 {
                // Removed or deactivated by this cycle's phase: reported off, so not updated.
                t.tracker_update_ns[i] = 0;
            }
        }
        let in_servo = phase == Phase::Servo;
        for (dst, src) in t.servo_error.iter_mut().zip(self.mission.servo.error()) {
            *dst = if in_servo && src.is_finite() { src as f32 } else { f32::NAN };
        }
        t.servo_steps = self.mission.servo.steps();
        t.dropped_frames = self.clock.dropped_frames();
        t.planning = u32::from(self.mission.worker.busy());
        self.mission.pointing.fill_telemetry(t);
        match &self.failure {
            Some(failure) => t.set_reason(&failure.detail),
            None => t.set_reason(self.mission.reporting.status()),
        }
    }

    /// Records the cycle's duration (frame received → command about to be sent) and stamps
    /// the telemetry with it; returns the telemetry to publish (before the command).
    pub fn finish_cycle(&mut self, loop_ns: u64) -> &Telemetry {
        self.timing.record_ns(loop_ns);
        self.telemetry.loop_ns = loop_ns;
        self.telemetry.deadline_misses = self.timing.deadline_misses();
        self.telemetry.time_ns = monotonic_ns();
        &self.telemetry
    }

    /// Stops the arm outside a frame (stale or vanished camera stream, interrupt): the
    /// command (`Stop`, answering no frame) and the telemetry saying why.
    pub fn safety_stop(&mut self, fault: Fault) -> (RobotCommand, Telemetry) {
        if !self.phase.is_terminal() {
            self.stop_reason(Phase::Stopped, fault);
        }
        if self.stopped_at_frame.is_none() {
            self.stopped_at_frame = Some(NO_FRAME);
        }
        let cmd = self.stamp(&Cmd::STOP, NO_FRAME);
        let states = StereoStates::default();
        self.telemetry.tracker_update_ns = [0; 4]; // no tracker was updated for this sample
        self.fill_telemetry(NO_FRAME, &states);
        self.telemetry.time_ns = monotonic_ns();
        (cmd, self.telemetry)
    }

    /// Whether the run is over: failed or stopped, or done and held long enough.
    pub fn finished(&self) -> bool {
        match self.phase {
            PhaseState::Failed | PhaseState::Stopped => true,
            PhaseState::Done { since_ns } => timed_out(since_ns, self.clock.now_ns(), self.mission.cfg.timing.done_hold_s),
            _ => false,
        }
    }

    pub fn phase(&self) -> Phase {
        self.phase.phase()
    }

    pub fn telemetry(&self) -> &Telemetry {
        &self.telemetry
    }

    pub fn timing(&self) -> &LatencyHistogram {
        &self.timing
    }

    pub fn frames(&self) -> u64 {
        self.frames
    }

    /// What happened, for `daemon.json`.
    pub fn outcome(&self, wall_s: f64) -> DaemonOutcome {
        let t = self.timing();
        let tt = &self.tracker_timing;
        let us = |ns: u64| ns as f64 / 1000.0;
        let phase = self.phase();
        let m = self.mission();
        DaemonOutcome {
            end: RunEnd {
                success: phase == handeye_wire::Phase::Done,
                phase_reached: self.phase_reached().name().to_string(),
                final_phase: phase.name().to_string(),
                failure_reason: self.failure().map(|f| f.detail.clone()),
                failure: self.failure().cloned(),
                servo_steps: m.servo.steps(),
            },
            timing: LoopTiming {
                loop_us_p50: us(t.percentile_ns(50.0)),
                loop_us_p99: us(t.percentile_ns(99.0)),
                loop_us_max: us(t.max_ns()),
                loop_us_mean: t.mean_ns() / 1000.0,
                deadline_us: t.deadline_ns() / 1000,
                deadline_misses: t.deadline_misses(),
                cycles: t.count(),
                robot_states: self.robot_states(),
                tracker_update: TrackerTiming {
                    us_p50: us(tt.percentile_ns(50.0)),
                    us_p99: us(tt.percentile_ns(99.0)),
                    us_max: us(tt.max_ns()),
                    us_mean: tt.mean_ns() / 1000.0,
                    cycles: tt.count(),
                },
                camera: self.clock(),
            },
            task: TaskRecord {
                calibration: m.calibration.stats(),
                target_source: m.targeting.source(),
                plan: m.planning.summary().cloned(),
                planning: m.planning.stats(),
                target_attempts: m.targeting.attempts(),
                grip_width_mm: m.servo.grip_width_m().map(|w| w * 1e3),
                pointing: m.pointing.summary(),
                held_block_moved: m.servo.held_block_moved().map(str::to_owned),
                stop_frame_id: self.stopped_at_frame(),
                holds: HoldRecord {
                    recoveries: self.recoveries(),
                    held_s: self.held_s(),
                    moves_refused: self.moves_refused(),
                    losses: self.losses.clone(),
                    recalibrations: m.calibration.recalibrations(),
                },
            },
            servo_trace: m.servo.trace().to_vec(),
            stale_frame_commands: 0, // counted by the service loop, which sees the stream
            wall_s,
        }
    }

    /// What ended the run, typed (`None` while it runs, or when it succeeded).
    pub fn failure(&self) -> Option<&Failure> {
        self.failure.as_ref()
    }

    /// The state across phases, to read (tests, the outcome).
    pub fn mission(&self) -> &Mission {
        &self.mission
    }

    /// Tracker losses recovered from (searched for and found again while the arm held).
    pub fn recoveries(&self) -> u32 {
        self.recoveries
    }

    /// Camera time the arm held for lost trackers, over the whole run, s.
    pub fn held_s(&self) -> f64 {
        self.held_ns as f64 * 1e-9
    }

    /// Moves refused because a tracker the phase needed was lost (see `refuse_blind_moves`).
    pub fn moves_refused(&self) -> u64 {
        self.moves_refused
    }

    /// The configuration the loop runs with.
    pub fn config(&self) -> &DaemonConfig {
        &self.mission.cfg
    }

    pub fn phase_reached(&self) -> Phase {
        self.phase_reached
    }

    pub fn stopped_at_frame(&self) -> Option<u64> {
        self.stopped_at_frame
    }

    /// The camera clock's counts: frames, dropped frames, bad stamps, rates, time steps.
    pub fn clock(&self) -> ClockStats {
        self.clock.stats()
    }

    pub fn robot_states(&self) -> u64 {
        self.robot_states
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::image::ImageBuf;

    /// Runs frames `(id, capture_time_ns)` with no robot state; the index of the frame at
    /// which the run stopped, if it did.
    fn stop_frame(frames: &[(u64, u64)]) -> (Option<usize>, HardLoop) {
        let mut hl = HardLoop::new(DaemonConfig::default(), None).unwrap();
        let img = ImageBuf::filled(64, 48, 100);
        for (i, &(id, t)) in frames.iter().enumerate() {
            hl.cycle(id, t, &img.view(), &img.view());
            if hl.phase() == Phase::Stopped {
                assert_eq!(hl.failure().map(|f| f.detail.as_str()), Some("no robot state received"));
                return (Some(i), hl);
            }
        }
        (None, hl)
    }

    #[test]
    fn time_outs_run_on_the_capture_stamps_not_on_frame_counts() {
        // safety.state_stale_ms = 200: a 30 Hz camera reaches it at its 7th frame (200 ms)...
        let t0 = 5_000_000_000;
        let at_30hz: Vec<(u64, u64)> = (0..10).map(|i| (i, t0 + i * 33_333_333)).collect();
        assert_eq!(stop_frame(&at_30hz).0, Some(6));
        // ... a 10 Hz camera at its 3rd, whatever frame_rate_hz says.
        let at_10hz: Vec<(u64, u64)> = (0..10).map(|i| (i, t0 + i * 100_000_000)).collect();
        assert_eq!(stop_frame(&at_10hz).0, Some(2));
        // Every other frame dropped at 30 Hz: the ids skip, the time is the stamps' (frame
        // id 6 at 200 ms is the 4th frame received), and the drops are counted.
        let gapped: Vec<(u64, u64)> = (0..10).map(|i| (2 * i, t0 + 2 * i * 33_333_333)).collect();
        let (stopped, hl) = stop_frame(&gapped);
        assert_eq!(stopped, Some(3));
        let c = hl.clock();
        assert_eq!((c.frames, c.dropped_frames), (4, 3));
        assert!((c.dt_ms_max - 66.7).abs() < 0.1, "{c:?}");
        // Stamps that go back are not believed: the clock goes on by the measured period,
        // so the time-out still comes (at 30 Hz frames: the 7th).
        let mut stuck = at_30hz.clone();
        for f in stuck.iter_mut().skip(3) {
            f.1 = t0;
        }
        let (stopped, hl) = stop_frame(&stuck);
        assert_eq!(stopped, Some(6));
        assert_eq!(hl.clock().bad_stamps, 4);
    }
}
