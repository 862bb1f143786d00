//! The daemon's account of a run (`daemon.json`, and what `handeye daemon --json` prints).

use serde::{Deserialize, Serialize};

use crate::hard_loop::HardLoop;
use crate::phase::{CalibrationStats, PlanningStats, ServoTraceRow, TargetSource};
use crate::planning::PlanSummary;

#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DaemonOutcome {
    /// The daemon finished its task (grasped and lifted; the simulator judges the rest).
    pub success: bool,
    /// Furthest phase entered (`done` on success).
    pub phase_reached: String,
    /// Phase at the end: `done`, `failed`, `stopped` (or the working phase when cut short).
    pub final_phase: String,
    /// The failure's detail (the same text as `failure.detail`), kept for readers of the
    /// documented shape.
    pub failure_reason: Option<String>,
    /// What went wrong, typed: phase, kind, detail.
    pub failure: Option<handeye_wire::report::Failure>,
    pub servo_steps: u32,
    /// Cycle time (frame received → command sent), µs.
    pub loop_us_p50: f64,
    pub loop_us_p99: f64,
    pub loop_us_max: f64,
    pub loop_us_mean: f64,
    pub deadline_us: u64,
    pub deadline_misses: u64,
    pub cycles: u64,
    pub robot_states: u64,
    pub calibration: Option<CalibrationStats>,
    /// Where the target came from: `hint` or `plan` (`None`: never chosen).
    pub target_source: Option<TargetSource>,
    /// The planner's facets, candidates and rejections (plan phase only).
    pub plan: Option<PlanSummary>,
    /// The loop while the planner worked: frames answered, gripper tracker updates.
    pub planning: Option<PlanningStats>,
    /// Targets tried: the plan's next grasp site is tried when one cannot be acquired.
    pub target_attempts: u32,
    pub grip_width_mm: Option<f64>,
    /// Frame id answered by the `Stop` command (`18446744073709551615` = outside a frame).
    pub stop_frame_id: Option<u64>,
    /// Camera knocks the trackers recovered from.
    pub recoveries: u32,
    pub servo_trace: Vec<ServoTraceRow>,
    pub wall_s: f64,
}

impl DaemonOutcome {
    pub fn from_loop(l: &HardLoop, wall_s: f64) -> Self {
        let t = l.timing();
        let us = |ns: u64| ns as f64 / 1000.0;
        let phase = l.phase();
        Self {
            success: phase == handeye_wire::Phase::Done,
            phase_reached: l.phase_reached().name().to_string(),
            final_phase: phase.name().to_string(),
            failure_reason: l.failure().map(str::to_string),
            // Interim: the kind is not classified yet where the failure is raised.
            failure: l.failure().map(|r| handeye_wire::report::Failure::new(l.phase_reached().name(), handeye_wire::report::FailureKind::Internal, r)),
            servo_steps: l.mission.servo_steps,
            loop_us_p50: us(t.percentile_ns(50.0)),
            loop_us_p99: us(t.percentile_ns(99.0)),
            loop_us_max: us(t.max_ns()),
            loop_us_mean: t.mean_ns() / 1000.0,
            deadline_us: t.deadline_ns() / 1000,
            deadline_misses: t.deadline_misses(),
            cycles: t.count(),
            robot_states: l.robot_states(),
            calibration: l.mission.calibration.as_ref().map(|c| c.stats),
            target_source: l.mission.target.as_ref().map(|t| t.source),
            plan: l.mission.plan.clone(),
            planning: l.mission.planning,
            target_attempts: l.mission.target_attempts,
            grip_width_mm: l.mission.grip_width_m.map(|w| w * 1e3),
            stop_frame_id: l.stopped_at_frame(),
            recoveries: l.recoveries,
            servo_trace: l.mission.servo_trace.clone(),
            wall_s,
        }
    }
}
