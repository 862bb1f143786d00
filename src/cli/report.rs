//! The reports the CLI's own processes hand each other: a run's summary (`handeye run --json`,
//! `run.json`), read by `handeye batch`, and a batch's result (`handeye batch --json`,
//! `batch.json`). The simulator's report is [`handeye_sim::referee::report::SimReport`], the daemon's
//! [`handeye_daemon::DaemonOutcome`].
//!
//! Writer and reader share one type, so that a renamed or missing field is an error that
//! names it (unknown fields are refused, and an `Option` field must be present, as `null`
//! when there is no value) instead of a silent `null`.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{Context, Result};
use handeye_daemon::mission::TargetSource;
use handeye_daemon::outcome::{HoldRecord, LossRecord};
use handeye_wire::report::required;
use handeye_wire::report::{Failure, FailureKind};
use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

/// Reads a report another process wrote; an error names the file and the field.
pub fn read_report<T: DeserializeOwned>(path: &Path) -> Result<T> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("reading {}", path.display()))
}

/// A value as its report shows it: compact JSON, `null` for `None`.
pub fn as_json<T: Serialize + ?Sized>(value: &T) -> String {
    serde_json::to_string(value).unwrap_or_else(|e| format!("({e})"))
}

/// A run's pointing: the daemon's answer against the judge's truth.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunPointing {
    /// Where the hand's finger line really met the working plane (the judge's), m.
    pub aim_m: Option<[f64; 3]>,
    /// The daemon's indicated point, m (`null`: no gesture answered).
    pub indicated_m: Option<[f64; 3]>,
    /// Distance between the two on the plane, mm.
    pub error_mm: Option<f64>,
    /// The answer's one-sigma radius, mm.
    pub sigma_mm: Option<f64>,
    /// Gestures that ended (answered or refused), and each refusal in the daemon's words.
    pub gestures: usize,
    pub refusals: Vec<String>,
    /// The block the hand pointed at (the task's target).
    pub pointed_block: Option<String>,
    /// The daemon's target trackers went onto the pointed block (`null`: onto none).
    pub chose_pointed: Option<bool>,
    /// The gesture tracker's update time, median, µs.
    pub update_us_p50: Option<f64>,
}

/// One closed-loop run, merged from the simulator's verdict and the daemon's outcome (see
/// `handeye run --help`). `None` (`null`) where the process that knows it reported nothing.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunSummary {
    pub scenario: String,
    /// The simulator judged the task's target lifted and held.
    pub success: bool,
    /// The daemon's furthest phase.
    #[serde(deserialize_with = "required")]
    pub phase_reached: Option<String>,
    #[serde(deserialize_with = "required")]
    pub final_phase: Option<String>,
    /// Why the run failed, in words (`failure.detail`); `null` on success.
    #[serde(deserialize_with = "required")]
    pub failure_reason: Option<String>,
    /// Why the run failed, typed; `null` on success.
    #[serde(deserialize_with = "required")]
    pub failure: Option<Failure>,
    #[serde(deserialize_with = "required")]
    pub target_source: Option<TargetSource>,
    /// The task's target block.
    #[serde(deserialize_with = "required")]
    pub target_block: Option<String>,
    /// Whether the target has a grasp the rules allow (the simulator's judge on its true
    /// geometry); `null` when the simulator reported nothing.
    #[serde(deserialize_with = "required")]
    pub target_graspable: Option<bool>,
    /// Why the target has none, in words; `null` when it has one.
    #[serde(deserialize_with = "required")]
    pub target_ungraspable_reason: Option<String>,
    /// The block and face the daemon's target trackers were put on (ground truth).
    #[serde(deserialize_with = "required")]
    pub targeted_block: Option<String>,
    #[serde(deserialize_with = "required")]
    pub targeted_face: Option<String>,
    /// The operator's indicated point, robot frame, m: the point given to the daemon, or, when
    /// it watched the pointing hand, the task's point the hand meant.
    pub indicated_point_m: [f64; 3],
    /// The operator's pointing gesture as the daemon saw it (`null`: it was given a point or
    /// a hint).
    #[serde(default)]
    pub pointing: Option<RunPointing>,
    #[serde(deserialize_with = "required")]
    pub plan_facets: Option<usize>,
    #[serde(deserialize_with = "required")]
    pub plan_candidates: Option<usize>,
    #[serde(deserialize_with = "required")]
    pub plan_width_mm: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub planner_ms: Option<f64>,
    /// Frames the daemon answered while the planner worked.
    #[serde(deserialize_with = "required")]
    pub planning_frames: Option<u64>,
    /// Gripper tracker updates (left, right) while the planner worked.
    #[serde(deserialize_with = "required")]
    pub gripper_updates_while_planning: Option<[u64; 2]>,
    /// The same per second of simulated time, as the simulator saw the telemetry, Hz.
    #[serde(deserialize_with = "required")]
    pub gripper_update_rate_hz: Option<[f64; 2]>,
    #[serde(deserialize_with = "required")]
    pub servo_steps: Option<u32>,
    #[serde(deserialize_with = "required")]
    pub final_plane_error_mm: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub final_angle_error_deg: Option<f64>,
    /// The jaw-centre plane's distance from the block's mid-plane when the jaws closed, mm.
    #[serde(deserialize_with = "required")]
    pub grasp_plane_error_mm: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub grasp_lateral_error_mm: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub loop_us_p50: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub loop_us_p99: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub loop_us_max: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub deadline_misses: Option<u64>,
    #[serde(deserialize_with = "required")]
    pub calibration_residual_px: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub max_lift_mm: Option<f64>,
    #[serde(deserialize_with = "required")]
    pub sim_frames: Option<u64>,
    #[serde(deserialize_with = "required")]
    pub sim_time_s: Option<f64>,
    pub wall_s: f64,
    #[serde(deserialize_with = "required")]
    pub seed: Option<u64>,
    pub domain: String,
    /// The report folder (`--out`), `null` without one.
    #[serde(deserialize_with = "required")]
    pub report: Option<String>,
    /// The daemon's holds for lost trackers (its `daemon.json`): each loss (phase, which
    /// tracker, why), the search (passes, relapses), how it ended and how the phase resumed,
    /// the time the arm held, recalibrations. `null` when the daemon reported nothing; left
    /// out by files written before it existed (read as `null`).
    #[serde(default)]
    pub recovery: Option<HoldRecord>,
    /// The block moved in the jaws while lifted, in words (the daemon's `held_block_moved`:
    /// the jaws' opening strayed from the width they closed to on it); `null` when it held
    /// steady, or the file predates the field.
    #[serde(default)]
    pub held_block_moved: Option<String>,
}

/// One loss in words, for the run's report and the batch's table: "servo, frame 812: target
/// tracker (left view) lost: ...; held 1.23 s, 3 search passes, 1 relapse; recovered; resumed:
/// ...". The daemon's `what` names the tracker and its reason, `outcome` how the hold ended
/// (or why it did not recover).
pub fn loss_text(l: &LossRecord) -> String {
    let plural = |n: u32, one: &str, many: &str| format!("{n} {}", if n == 1 { one } else { many });
    let mut text = format!(
        "{}, frame {}: {}; held {:.2} s, {}, {}; {}",
        l.phase,
        l.frame_id,
        l.what,
        l.held_s,
        plural(l.search_passes, "search pass", "search passes"),
        plural(l.relapses, "relapse", "relapses"),
        l.outcome
    );
    if !l.resumed.is_empty() {
        text.push_str("; resumed: ");
        text.push_str(&l.resumed);
    }
    text
}

/// A run's holds in one line ("2 losses, 1 recovered, held 3.40 s, 1 recalibration"); `None`
/// when the arm never held.
pub fn holds_brief(h: &HoldRecord) -> Option<String> {
    if h.losses.is_empty() && h.held_s <= 0.0 {
        return None;
    }
    let mut text = format!("{} loss{}, {} recovered, held {:.2} s", h.losses.len(), if h.losses.len() == 1 { "" } else { "es" }, h.recoveries, h.held_s);
    if h.recalibrations > 0 {
        text.push_str(&format!(", {} recalibration{}", h.recalibrations, if h.recalibrations == 1 { "" } else { "s" }));
    }
    if h.moves_refused > 0 {
        text.push_str(&format!(", {} moves on a lost track refused", h.moves_refused));
    }
    Some(text)
}

/// A batch's result (see `handeye batch --help`): the totals over every run, the same per
/// scenario, and every run's summary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchResult {
    #[serde(flatten)]
    pub all: BatchGroup,
    /// Per scenario, by name.
    pub scenarios: BTreeMap<String, BatchGroup>,
    pub failed_runs: Vec<FailedRun>,
    pub runs_detail: Vec<RunDetail>,
    /// The `--config` file given to every run.
    pub daemon_config: Option<String>,
}

/// Counts and medians over a set of runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BatchGroup {
    pub runs: usize,
    pub successes: usize,
    pub success_rate: f64,
    /// Failures counted by phase, then kind.
    pub failures: BTreeMap<String, BTreeMap<FailureKind, usize>>,
    /// The same groups, with their runs and full reasons.
    pub failure_list: Vec<FailureGroup>,
    /// Over the runs that lifted.
    pub median_servo_steps: Option<f64>,
    pub median_run_wall_s: Option<f64>,
    /// The batch's wall time (totals only; `null` per scenario).
    pub wall_s: Option<f64>,
    /// The runs split by whether the target had a grasp the rules allow (the simulator's
    /// judge on its true geometry).
    #[serde(flatten)]
    pub judged: JudgedTallies,
}

/// Successes over graspable targets, and refusals, right and wrong (issue 20): a refusal is
/// a run the daemon ended with `failure.kind = refused`; an attempt is a run that went on
/// past planning (to acquiring the target or further).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JudgedTallies {
    /// Runs whose target has a grasp the rules allow.
    pub graspable_runs: usize,
    /// ... of which lifted.
    pub graspable_successes: usize,
    /// `graspable_successes / graspable_runs`; `null` without graspable runs.
    pub graspable_success_rate: Option<f64>,
    /// Refusals of a graspable target.
    pub wrong_refusals: usize,
    /// Runs whose target has no grasp the rules allow.
    pub ungraspable_runs: usize,
    /// Refusals of an ungraspable target.
    pub correct_refusals: usize,
    /// `correct_refusals / ungraspable_runs`; `null` without ungraspable runs.
    pub correct_refusal_rate: Option<f64>,
    /// Ungraspable targets the daemon went for anyway (past planning).
    pub attempts_on_ungraspable: usize,
    /// Runs the simulator did not judge (it reported nothing).
    pub unjudged_runs: usize,
}

/// Runs that failed in one phase with one kind of failure.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FailureGroup {
    pub phase: String,
    pub kind: FailureKind,
    pub count: usize,
    pub runs: Vec<GroupRun>,
}

/// One run of a failure group.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroupRun {
    /// `scenario#seed`.
    pub run: String,
    /// The reason in full.
    pub reason: String,
}

/// A run that failed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FailedRun {
    pub scenario: String,
    pub seed: u64,
    /// The phase the run got to.
    pub phase: String,
    /// The reason in full (`failure.detail`).
    pub reason: String,
    pub failure: Failure,
}

/// One run's summary as `handeye run --json` printed it (`null`: it printed none).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunDetail {
    pub scenario: String,
    pub seed: u64,
    #[serde(deserialize_with = "required")]
    pub summary: Option<RunSummary>,
    /// The run's wall time as the batch counts it (the summary's, or how long `handeye run`
    /// took when it printed none), s: what `handeye batch merge` needs for the medians.
    pub wall_s: f64,
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use handeye_daemon::DaemonOutcome;
    use handeye_sim::referee::report::SimReport;

    /// `text` with the first occurrence of the key `"from"` renamed to `"to"`.
    fn rename(text: &str, from: &str, to: &str) -> String {
        let key = format!("\"{from}\":");
        assert!(text.contains(&key), "{from} is not a key of {text}");
        text.replacen(&key, &format!("\"{to}\":"), 1)
    }

    /// A report read across a process boundary refuses a renamed field with an error that
    /// names it and the file, never reading it as `null`.
    fn renamed_field_fails<T: DeserializeOwned + std::fmt::Debug>(text: &str, field: &str) {
        // Tests run in parallel and may rename the same field of different reports: one file
        // per call.
        static CALLS: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("handeye-report-test-{}-{call}-{field}.json", std::process::id()));
        std::fs::write(&path, rename(text, field, &format!("{field}_renamed"))).unwrap();
        let err = format!("{:#}", read_report::<T>(&path).unwrap_err());
        let _ = std::fs::remove_file(&path);
        assert!(err.contains(&format!("`{field}_renamed`")) || err.contains(&format!("missing field `{field}`")), "{err}");
        assert!(err.contains(&path.display().to_string()), "the error names the file: {err}");
    }

    /// A top-level field left out is an error that names it, `Option` fields included.
    fn missing_field_fails<T: DeserializeOwned + std::fmt::Debug>(text: &str, field: &str) {
        let mut value: serde_json::Value = serde_json::from_str(text).unwrap();
        assert!(value.as_object_mut().unwrap().remove(field).is_some(), "{field}");
        let err = serde_json::from_value::<T>(value).unwrap_err().to_string();
        assert!(err.contains(&format!("missing field `{field}`")), "{err}");
    }

    /// A run summary with every field set, for tests of what reads it.
    pub(crate) fn summary() -> RunSummary {
        RunSummary {
            scenario: "pick_cube".into(),
            success: false,
            phase_reached: Some("servo".into()),
            final_phase: Some("failed".into()),
            failure_reason: Some("servo: not converged after 90 s (60 steps)".into()),
            failure: Some(Failure::new("servo", FailureKind::NotConverged, "servo: not converged after 90 s (60 steps)")),
            target_source: Some(TargetSource::Plan),
            target_block: Some("cube".into()),
            target_graspable: Some(true),
            target_ungraspable_reason: None,
            targeted_block: Some("cube".into()),
            targeted_face: Some("+x".into()),
            indicated_point_m: [0.36, 0.02, 0.06],
            pointing: None,
            plan_facets: Some(2),
            plan_candidates: Some(1),
            plan_width_mm: Some(40.1),
            planner_ms: Some(3.7),
            planning_frames: Some(30),
            gripper_updates_while_planning: Some([30, 30]),
            gripper_update_rate_hz: Some([30.0, 30.0]),
            servo_steps: Some(60),
            final_plane_error_mm: None,
            final_angle_error_deg: None,
            grasp_plane_error_mm: None,
            grasp_lateral_error_mm: None,
            loop_us_p50: Some(77.8),
            loop_us_p99: Some(524.3),
            loop_us_max: Some(1460.8),
            deadline_misses: Some(1),
            calibration_residual_px: Some(5.35),
            max_lift_mm: Some(0.0),
            sim_frames: Some(1158),
            sim_time_s: Some(38.6),
            wall_s: 13.8,
            seed: Some(1),
            domain: "run-1".into(),
            report: None,
            recovery: Some(HoldRecord {
                recoveries: 1,
                held_s: 1.25,
                moves_refused: 0,
                losses: vec![LossRecord {
                    phase: "servo".into(),
                    frame_id: 812,
                    what: "target tracker (left view) lost: support 0.21 below 0.35".into(),
                    held_s: 1.25,
                    outcome: "recovered".into(),
                    shifts_px: [None, None, Some([3.0, -1.5]), None],
                    resumed: "servo from fresh frames".into(),
                    search_passes: 3,
                    relapses: 1,
                }],
                recalibrations: 0,
            }),
            held_block_moved: None,
        }
    }

    #[test]
    fn a_run_summary_reads_back_as_written() {
        let s = summary();
        let text = serde_json::to_string(&s).unwrap();
        assert_eq!(serde_json::from_str::<RunSummary>(&text).unwrap(), s);
        // `null` stays `null`: a value that is not there is written, not left out.
        assert!(text.contains("\"final_plane_error_mm\":null"), "{text}");
    }

    #[test]
    fn a_run_summary_carries_each_loss_and_the_hold() {
        let s = summary();
        let value = serde_json::to_value(&s).unwrap();
        let loss = &value["recovery"]["losses"][0];
        assert_eq!(loss["phase"], "servo");
        assert!(loss["what"].as_str().unwrap().starts_with("target tracker (left view) lost"), "{loss}");
        assert_eq!((loss["search_passes"].as_u64(), loss["relapses"].as_u64()), (Some(3), Some(1)));
        assert_eq!(loss["outcome"], "recovered");
        assert_eq!(value["recovery"]["held_s"], 1.25);
        let h = s.recovery.as_ref().unwrap();
        assert_eq!(
            loss_text(&h.losses[0]),
            "servo, frame 812: target tracker (left view) lost: support 0.21 below 0.35; held 1.25 s, 3 search passes, 1 relapse; recovered; resumed: servo from fresh frames"
        );
        assert_eq!(holds_brief(h).as_deref(), Some("1 loss, 1 recovered, held 1.25 s"));
        assert_eq!(holds_brief(&HoldRecord::default()), None);
        // A run.json written before the field existed reads, as `null`.
        let mut old = value.clone();
        old.as_object_mut().unwrap().remove("recovery");
        old.as_object_mut().unwrap().remove("held_block_moved");
        let old = serde_json::from_value::<RunSummary>(old).unwrap();
        assert_eq!((old.recovery, old.held_block_moved), (None, None));
        // A renamed key inside it is refused with its name, not dropped.
        let text = serde_json::to_string(&s).unwrap().replace("\"search_passes\"", "\"search_pass\"");
        let err = serde_json::from_str::<RunSummary>(&text).unwrap_err().to_string();
        assert!(err.contains("search_pass"), "{err}");
    }

    #[test]
    fn a_renamed_or_missing_run_summary_field_is_an_error_naming_it() {
        let text = serde_json::to_string_pretty(&summary()).unwrap();
        for field in ["success", "failure_reason", "failure", "servo_steps", "final_plane_error_mm", "wall_s", "report"] {
            renamed_field_fails::<RunSummary>(&text, field);
            missing_field_fails::<RunSummary>(&text, field);
        }
    }

    #[test]
    fn a_renamed_batch_result_field_is_an_error_naming_it() {
        let group = BatchGroup {
            runs: 1,
            successes: 0,
            success_rate: 0.0,
            failures: BTreeMap::from([("servo".to_string(), BTreeMap::from([(FailureKind::NotConverged, 1)]))]),
            failure_list: vec![FailureGroup {
                phase: "servo".into(),
                kind: FailureKind::NotConverged,
                count: 1,
                runs: vec![GroupRun { run: "pick_cube#1".into(), reason: "servo: not converged".into() }],
            }],
            median_servo_steps: None,
            median_run_wall_s: Some(13.8),
            wall_s: Some(14.0),
            judged: JudgedTallies { graspable_runs: 1, graspable_success_rate: Some(0.0), ..JudgedTallies::default() },
        };
        let failure = Failure::new("servo", FailureKind::NotConverged, "servo: not converged");
        let batch = BatchResult {
            all: group.clone(),
            scenarios: BTreeMap::from([("pick_cube".to_string(), BatchGroup { wall_s: None, ..group })]),
            failed_runs: vec![FailedRun { scenario: "pick_cube".into(), seed: 1, phase: "servo".into(), reason: failure.detail.clone(), failure }],
            runs_detail: vec![RunDetail { scenario: "pick_cube".into(), seed: 1, summary: Some(summary()), wall_s: 13.8 }],
            daemon_config: None,
        };
        let text = serde_json::to_string(&batch).unwrap();
        assert_eq!(serde_json::from_str::<BatchResult>(&text).unwrap(), batch);
        for field in ["successes", "failure_list", "failed_runs", "runs_detail", "kind", "graspable_runs", "correct_refusals", "attempts_on_ungraspable"] {
            renamed_field_fails::<BatchResult>(&text, field);
        }
    }

    /// The simulator's verdict, as `handeye sim --verdict-out` writes it (pick_cube, seed 1).
    const SIM_JSON: &str = r#"{"scenario":"pick_cube","mode":"lockstep","frames":1158,"fps":84.2,"wall_s":13.7,"sim_time_s":38.6,
        "frames_hash":"0123456789abcdef","commands":1158,"reply_timeouts":0,"late_frames":0,"verdict":{"success":{"at_ns":38600000000}},
        "driver":"commands from handeye/robot/command","max_lift_mm":69.4,"adapter":"llvmpipe","domain":"run-1","commands_rejected":0,
        "success":true,"seed":1,"target":"cube","indicated_point_m":[0.36,0.02,0.06],
        "layout":[{"name":"cube","kind":"cube","size_mm":[40.0,40.0,40.0],"position_m":[0.36,0.02],"yaw_deg":0.0}],
        "target_graspability":{"graspable":true,"reason":null},
        "daemon":{"phases":[["acquire_gripper",0],["servo",700]],"converged":{"frame":900,"final_plane_error_mm":0.06,"final_angle_error_deg":0.18,
        "plate_offset_mm":0.06,"jaw_plane_offset_mm":0.04,"lateral_error_mm":0.3,"tool_z_mm":80.0},"grasped":null,"stopped_frame":null,
        "stop_reason":null,"first_stop_command_frame":null,"target_hidden_frame":null,"telemetry":1158,
        "targeted":{"frame":600,"block":"cube","face":"+x","is_task_target":true,"outline_error_px":0.4},
        "plan":{"frames":40,"planning_frames":30,"gripper_updates_while_planning":[30,30],"max_update_step":1,"planning_window_s":1.0,
        "gripper_update_rate_hz":[30.0,30.0],"frame_rate_hz":30.0}}}"#;

    #[test]
    fn a_renamed_sim_report_field_is_an_error_naming_it() {
        let report: SimReport = serde_json::from_str(SIM_JSON).unwrap();
        assert!(report.success);
        assert_eq!(report.daemon.targeted.as_ref().map(|t| t.face.as_str()), Some("+x"));
        for field in ["success", "target", "verdict", "targeted", "is_task_target", "gripper_update_rate_hz", "grasped", "stop_reason", "target_graspability", "graspable"] {
            renamed_field_fails::<SimReport>(SIM_JSON, field);
        }
        for field in ["success", "max_lift_mm", "daemon"] {
            missing_field_fails::<SimReport>(SIM_JSON, field);
        }
        // The watch's optional parts too: `null` when nothing was seen, but never left out.
        let mut value: serde_json::Value = serde_json::from_str(SIM_JSON).unwrap();
        value.as_object_mut().unwrap()["daemon"].as_object_mut().unwrap().remove("targeted");
        let err = serde_json::from_value::<SimReport>(value).unwrap_err().to_string();
        assert!(err.contains("missing field `targeted`"), "{err}");
    }

    #[test]
    fn a_renamed_daemon_outcome_field_is_an_error_naming_it() {
        // daemon.json of `handeye run scenarios/pick_cube.toml` (its servo trace cut to two rows).
        let text = include_str!("testdata/daemon_outcome.json");
        serde_json::from_str::<DaemonOutcome>(text).unwrap();
        // Fields `handeye run` reads; the daemon's type requires each of them.
        for field in ["phase_reached", "servo_steps", "loop_us_p50", "deadline_misses", "dropped_frames"] {
            renamed_field_fails::<DaemonOutcome>(text, field);
        }
    }
}
