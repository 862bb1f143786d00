//! The simulator's report: what `handeye sim --json` prints and `--verdict-out` writes
//! (`sim.json` in a run's report folder), and what `handeye run` reads back to judge a run.
//!
//! One type for writer and reader, so that a renamed or missing field is an error that names
//! it rather than a silent `null`: the reader rejects unknown fields and requires every
//! field that is not an `Option`.

use serde::{Deserialize, Serialize};

use crate::referee::graspable::Graspability;
use crate::referee::judge::Verdict;
use crate::referee::watch::DaemonWatch;
use crate::scenario::BlockKind;

/// How the simulator was clocked.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SimMode {
    /// Frame N+1 only after the daemon's command for frame N (or the reply time-out).
    Lockstep,
    /// Frames at the scenario's camera rate, stamped with their capture time.
    Realtime,
}

/// What moved the arm.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimDriver {
    /// `--scripted-pick`: a pick from ground truth, a physics demo.
    ScriptedPick,
    /// Whatever arrives on `handeye/robot/command` (the daemon).
    Commands,
    /// `--robot external`: a robot driver outside the simulator carried out the commands; the
    /// arm followed the state it published.
    ExternalRobot,
}

impl SimDriver {
    /// The driver in words, as the report has always written it.
    pub fn describe(self) -> &'static str {
        match self {
            Self::ScriptedPick => "scripted pick from ground truth (physics demo)",
            Self::Commands => "commands from handeye/robot/command",
            Self::ExternalRobot => "an external robot driver's handeye/robot/state",
        }
    }
}

impl Serialize for SimDriver {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.describe())
    }
}

impl<'de> Deserialize<'de> for SimDriver {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        [Self::ScriptedPick, Self::Commands, Self::ExternalRobot]
            .into_iter()
            .find(|k| k.describe() == text)
            .ok_or_else(|| serde::de::Error::invalid_value(serde::de::Unexpected::Str(&text), &"a driver description"))
    }
}

/// One block as the run laid it out (after `--seed` / `--random-layout`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LaidOutBlock {
    pub name: String,
    pub kind: BlockKind,
    pub size_mm: [f64; 3],
    pub position_m: [f64; 2],
    pub yaw_deg: f64,
}

/// The simulator's verdict on a run, judged from ground truth.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimReport {
    pub scenario: String,
    pub mode: SimMode,
    /// Frames published.
    pub frames: u64,
    /// Frames per wall-clock second.
    pub fps: f64,
    pub wall_s: f64,
    pub sim_time_s: f64,
    /// Hash over every published pixel, 16 hex digits: equal for equal runs.
    pub frames_hash: String,
    /// Robot commands applied.
    pub commands: u64,
    /// Lockstep frames whose reply did not come in time.
    pub reply_timeouts: u64,
    /// Real time: frames published later than their slot.
    pub late_frames: u64,
    pub verdict: Verdict,
    pub driver: SimDriver,
    /// Highest lift of the target above its rest height, mm.
    pub max_lift_mm: f64,
    /// The renderer's graphics adapter.
    pub adapter: String,
    pub domain: String,
    /// Commands the simulator's receiver rejected (malformed).
    pub commands_rejected: u64,
    /// The target was lifted and held (`verdict` is a success).
    pub success: bool,
    pub seed: u64,
    /// The task's target block, by name.
    pub target: String,
    /// The operator's indicated point on the working plane, robot frame, m.
    pub indicated_point_m: [f64; 3],
    pub layout: Vec<LaidOutBlock>,
    /// Whether the target has a grasp the rules allow, judged on its true geometry as laid
    /// out ([`crate::referee::graspable`]).
    pub target_graspability: Graspability,
    /// What the simulator saw of the daemon.
    pub daemon: DaemonWatch,
    /// The operator's pointing gesture and where it really aimed (`[pointer]` scenarios).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pointer: Option<crate::pointer::PointerTruth>,
    /// The gestures before it, when the operator pointed again (`[pointer] repeats`), oldest
    /// first.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub pointer_earlier: Vec<crate::pointer::PointerTruth>,
    /// The scripted disturbances of the run, in words (the scenario's `[[events]]` and a
    /// `--disturb` one), so a batch shows what each run had to ride out.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub events: Vec<String>,
}

