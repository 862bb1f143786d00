//! The daemon's account of a run (`daemon.json`, and what `handeye daemon --json` prints).
//!
//! One flat JSON object; in Rust its fields come in groups ([`RunEnd`], [`LoopTiming`],
//! [`TaskRecord`]) flattened into it, so the file keeps its documented shape. Every field a
//! reader relies on is required: a renamed key is an error that names it, not a silent
//! `null` (an `Option` field may be absent, and then reads as `None`).

use serde::{Deserialize, Serialize};

use crate::mission::{CalibrationStats, PlanningStats, ServoTraceRow, TargetSource};
use crate::planning::PlanSummary;

/// The daemon's outcome of one run.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct DaemonOutcome {
    #[serde(flatten)]
    pub end: RunEnd,
    #[serde(flatten)]
    pub timing: LoopTiming,
    #[serde(flatten)]
    pub task: TaskRecord,
    pub servo_trace: Vec<ServoTraceRow>,
    /// Commands stamped with a frame older than the newest the daemon had received (the
    /// service loop counts them, as it alone sees the stream; 0 unless something answers
    /// from a backlog).
    pub stale_frame_commands: u64,
    pub wall_s: f64,
}

/// How the run ended.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunEnd {
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
}

/// How the hard loop kept time.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LoopTiming {
    /// Cycle time (frame received → command sent), µs.
    pub loop_us_p50: f64,
    pub loop_us_p99: f64,
    pub loop_us_max: f64,
    pub loop_us_mean: f64,
    pub deadline_us: u64,
    pub deadline_misses: u64,
    pub cycles: u64,
    pub robot_states: u64,
    /// The trackers' own update time: `"tracker_update": {...}` in `daemon.json`.
    pub tracker_update: TrackerTiming,
    /// The camera clock (`"camera": {...}`): frames, dropped frames (gaps in the ids), bad
    /// stamps, the camera's rate and the filter's time step, all from the capture stamps.
    pub camera: crate::camera_clock::ClockStats,
}

/// The stereo tracker update of a cycle (every active contour, both views, summed) over the
/// cycles that updated at least one tracker. Telemetry's `tracker_update_ns` carries each
/// cycle's per-tracker values, so `handeye monitor --telemetry` computes the same numbers.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrackerTiming {
    /// Percentiles as the loop's histogram reports them (the upper edge of the bucket, at
    /// most 1/16 above the true value), µs.
    pub us_p50: f64,
    pub us_p99: f64,
    pub us_max: f64,
    pub us_mean: f64,
    /// Cycles that updated at least one tracker.
    pub cycles: u64,
}

/// What the phases found and did.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct TaskRecord {
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
    /// The point phase: every gesture seen, the indicated point, the gesture tracker's
    /// update time (`None`: the daemon was given its point or a hint).
    #[serde(default)]
    pub pointing: Option<crate::mission::PointingSummary>,
    /// The block moved in the jaws while lifted, in words: the jaws' opening strayed from the
    /// width they closed to on it (`phase/grasp.rs`); `None` when it held steady.
    #[serde(default)]
    pub held_block_moved: Option<String>,
    /// Frame id answered by the `Stop` command (`18446744073709551615` = outside a frame).
    pub stop_frame_id: Option<u64>,
    /// The holds for lost trackers (flattened: the keys stay top-level).
    #[serde(flatten)]
    pub holds: HoldRecord,
}

/// The arm's holds for lost trackers over the run (issue 18); `handeye run` carries it into
/// `run.json` (`recovery`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct HoldRecord {
    /// Tracker losses recovered from: the arm held, the lost contours were found again and
    /// the phase resumed (a knocked camera is one).
    pub recoveries: u32,
    /// Camera time the arm held for lost trackers, over the run, s.
    #[serde(default)]
    pub held_s: f64,
    /// Moves a phase asked for while a tracker it needed was lost, refused where commands
    /// are stamped (0 unless the daemon has a bug: a lost track never moves the arm).
    #[serde(default)]
    pub moves_refused: u64,
    /// Each time the arm held for lost trackers: what, why, for how long, and how it ended.
    #[serde(default)]
    pub losses: Vec<LossRecord>,
    /// Times a camera was found moved after the calibration (its plate re-found elsewhere
    /// with the arm held) and the cameras were calibrated again.
    #[serde(default)]
    pub recalibrations: u32,
}

/// One hold for lost trackers (issue 18 item 7).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LossRecord {
    /// The phase it happened in.
    pub phase: String,
    /// Frame id on which the arm was stopped for it.
    pub frame_id: u64,
    /// Each lost tracker and what it said ("target tracker (left view) lost: ...").
    pub what: String,
    /// Camera time the arm held, s.
    pub held_s: f64,
    /// `recovered`, or why not.
    pub outcome: String,
    /// Each re-found contour's shift from its last good frame, px (gripper left, gripper
    /// right, target left, target right; `null`: not lost, or not found).
    pub shifts_px: [Option<[f64; 2]>; 4],
    /// What the phase did on resuming ("resumed", "right camera moved (plate 58 px away):
    /// calibrated again", ...; empty when it did not recover).
    #[serde(default)]
    pub resumed: String,
    /// Search passes over the widest lost contour's grid, and contours re-found that then
    /// did not hold while confirming (searched for again).
    #[serde(default)]
    pub search_passes: u32,
    #[serde(default)]
    pub relapses: u32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_wire::report::{Failure, FailureKind};

    fn outcome() -> DaemonOutcome {
        DaemonOutcome {
            end: RunEnd {
                success: false,
                phase_reached: "servo".into(),
                final_phase: "failed".into(),
                failure_reason: Some("servo: not converged after 90 s (60 steps)".into()),
                failure: Some(Failure::new("servo", FailureKind::NotConverged, "servo: not converged after 90 s (60 steps)")),
                servo_steps: 60,
            },
            timing: LoopTiming {
                loop_us_p50: 40.0,
                loop_us_p99: 90.0,
                loop_us_max: 120.0,
                loop_us_mean: 45.0,
                deadline_us: 5000,
                deadline_misses: 0,
                cycles: 900,
                robot_states: 1800,
                tracker_update: TrackerTiming { us_p50: 60.0, us_p99: 85.0, us_max: 140.0, us_mean: 62.0, cycles: 880 },
                camera: crate::camera_clock::ClockStats::default(),
            },
            task: TaskRecord {
                calibration: None,
                target_source: Some(TargetSource::Plan),
                plan: None,
                planning: None,
                target_attempts: 1,
                grip_width_mm: None,
                pointing: None,
                held_block_moved: None,
                stop_frame_id: Some(u64::MAX),
                holds: HoldRecord::default(),
            },
            servo_trace: vec![ServoTraceRow { step: 1, frame: 400, error: [0.5; 6], offset_m: 0.01, offset_yaw_rad: 0.02 }],
            stale_frame_commands: 0,
            wall_s: 31.5,
        }
    }

    #[test]
    fn daemon_json_is_one_flat_object_that_reads_back() {
        let o = outcome();
        let value = serde_json::to_value(&o).unwrap();
        let keys: Vec<&str> = value.as_object().unwrap().keys().map(String::as_str).collect();
        let mut expected = vec![
            "success", "phase_reached", "final_phase", "failure_reason", "failure", "servo_steps", "loop_us_p50", "loop_us_p99",
            "loop_us_max", "loop_us_mean", "deadline_us", "deadline_misses", "stale_frame_commands", "cycles", "robot_states", "tracker_update", "camera", "calibration",
            "target_source", "plan", "planning", "target_attempts", "grip_width_mm", "pointing", "held_block_moved", "stop_frame_id", "recoveries", "held_s", "moves_refused", "losses", "recalibrations",
            "servo_trace", "wall_s",
        ];
        expected.sort_unstable();
        let mut keys = keys;
        keys.sort_unstable();
        assert_eq!(keys, expected);
        assert_eq!(value["failure"]["kind"], "not_converged");
        let back: DaemonOutcome = serde_json::from_value(value).unwrap();
        assert_eq!((back.end, back.timing), (o.end, o.timing));
        assert_eq!((back.task.target_source, back.task.stop_frame_id), (o.task.target_source, o.task.stop_frame_id));
        assert_eq!(back.servo_trace, o.servo_trace);
    }

    #[test]
    fn a_renamed_key_is_an_error_that_names_it() {
        let text = serde_json::to_string(&outcome()).unwrap().replace("\"phase_reached\"", "\"phase_reachd\"");
        let err = serde_json::from_str::<DaemonOutcome>(&text).unwrap_err().to_string();
        assert!(err.contains("phase_reached"), "{err}");
        let text = serde_json::to_string(&outcome()).unwrap().replace("\"loop_us_p99\"", "\"loop_p99_us\"");
        let err = serde_json::from_str::<DaemonOutcome>(&text).unwrap_err().to_string();
        assert!(err.contains("loop_us_p99"), "{err}");
    }
}
