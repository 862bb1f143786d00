//! Reports that cross a process boundary as files or JSON lines: what went wrong, typed.
//!
//! A failure is a value — the phase it happened in, what kind of failure it is, and the
//! detail in words — so that a reader (`handeye run`, `handeye batch`) can `match` on it
//! instead of parsing text. Its `Display` is the detail alone: the sentence a user reads.
//!
//! ```
//! use handeye_wire::report::{Failure, FailureKind};
//! let f = Failure::new("servo", FailureKind::NotConverged, "servo: not converged after 90 s (60 steps)");
//! assert_eq!(f.to_string(), "servo: not converged after 90 s (60 steps)");
//! let json = serde_json::to_string(&f).unwrap();
//! assert_eq!(serde_json::from_str::<Failure>(&json).unwrap(), f);
//! ```

use serde::{Deserialize, Serialize};

/// What kind of failure ended a run. Readers group failures by `(phase, kind)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FailureKind {
    /// A phase (or one stage of it) ran past its time limit.
    TimedOut,
    /// A tracker the phase relies on lost its contour (or did not run).
    TrackerLost,
    /// A tracker's confidence fell below the configured minimum.
    TrackerUnsure,
    /// The gripper plate could not be located or verified at start-up.
    GripperNotFound,
    /// The calibration fit was refused or unusable.
    Calibration,
    /// The planner found no grasp site near the indicated point, and no block there to
    /// refuse (nothing reconstructed near it).
    NoGraspSite,
    /// The daemon refused the task: the block at the indicated point, as it reconstructed
    /// it, has no grasp the rules allow (the detail says which rules it fails). Not a
    /// failure when the block truly has none: `handeye batch` counts it as a refusal.
    Refused,
    /// The target facet could not be acquired or verified in the images.
    TargetNotAcquired,
    /// The servo could not make a step (geometry unusable) or did not converge in time.
    NotConverged,
    /// The robot controller refused a commanded move (its reject reason in the detail).
    RobotRefused,
    /// The robot reported a fault or its watchdog stopped the arm.
    RobotFault,
    /// The robot state was missing, stale or made no sense.
    RobotState,
    /// The camera stream stopped, went stale, was malformed, or a camera moved and the
    /// trackers could not be re-acquired.
    Camera,
    /// The jaws closed on nothing, or the object slipped out.
    GraspLost,
    /// The run was interrupted (signal) or cut short by a wall-clock limit.
    Interrupted,
    /// The judge (ground truth): the daemon went for another block than the task's target.
    WrongTarget,
    /// The judge (ground truth): the target was not lifted and held.
    NotLifted,
    /// A process of the run could not start, crashed, or reported nothing.
    Process,
    /// A broken invariant inside the daemon (a bug): the arm is stopped.
    Internal,
}

impl FailureKind {
    /// The kind's name as it appears in JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::TimedOut => "timed_out",
            Self::TrackerLost => "tracker_lost",
            Self::TrackerUnsure => "tracker_unsure",
            Self::GripperNotFound => "gripper_not_found",
            Self::Calibration => "calibration",
            Self::NoGraspSite => "no_grasp_site",
            Self::Refused => "refused",
            Self::TargetNotAcquired => "target_not_acquired",
            Self::NotConverged => "not_converged",
            Self::RobotRefused => "robot_refused",
            Self::RobotFault => "robot_fault",
            Self::RobotState => "robot_state",
            Self::Camera => "camera",
            Self::GraspLost => "grasp_lost",
            Self::Interrupted => "interrupted",
            Self::WrongTarget => "wrong_target",
            Self::NotLifted => "not_lifted",
            Self::Process => "process",
            Self::Internal => "internal",
        }
    }
}

impl std::fmt::Display for FailureKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One failure: where, what kind, and the sentence for the user.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Failure {
    /// The phase it happened in, by its telemetry name ([`crate::Phase::name`]); `run` for
    /// failures of the run around the processes.
    pub phase: String,
    pub kind: FailureKind,
    /// What happened, in words (numbers included).
    pub detail: String,
}

impl Failure {
    pub fn new(phase: impl Into<String>, kind: FailureKind, detail: impl Into<String>) -> Self {
        Self { phase: phase.into(), kind, detail: detail.into() }
    }
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.detail)
    }
}

impl std::error::Error for Failure {}

/// `#[serde(deserialize_with = "handeye_wire::report::required")]` on an `Option` field of a
/// report: the key must be there (`null` for `None`). Serde otherwise reads a missing
/// `Option` as `None`, so a renamed field would read as "no value" without a word.
pub fn required<'de, D, T>(d: D) -> Result<Option<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: Deserialize<'de>,
{
    Option::<T>::deserialize(d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_renamed_field_is_an_error_that_names_it() {
        let text = r#"{"phase":"plan","kind":"no_grasp_site","detial":"x"}"#;
        let err = serde_json::from_str::<Failure>(text).unwrap_err().to_string();
        assert!(err.contains("detial"), "{err}");
        let text = r#"{"phase":"plan","kind":"no_such_kind","detail":"x"}"#;
        let err = serde_json::from_str::<Failure>(text).unwrap_err().to_string();
        assert!(err.contains("no_such_kind"), "{err}");
    }

    #[test]
    fn kind_names_match_their_json() {
        for k in [FailureKind::TimedOut, FailureKind::NoGraspSite, FailureKind::Internal, FailureKind::GraspLost] {
            assert_eq!(serde_json::to_string(&k).unwrap(), format!("\"{}\"", k.name()));
        }
    }
}
