//! What the plan phase found and how the loop fared while the planner worked.

use serde::{Deserialize, Serialize};

use crate::planning::PlanSummary;

/// How the loop fared while the planner worked.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PlanningStats {
    /// Frames answered between handing the pair over and taking the result.
    pub frames: u64,
    /// Gripper tracker updates (left, right) meanwhile: one per frame when it kept tracking.
    pub gripper_updates: [u64; 2],
    pub planner_ms: f64,
    pub total_ms: f64,
    /// Pairs planned on: a plan that settled no grasp site looks again at a fresh pair, up to
    /// `plan.max_looks` (absent in reports written before: one).
    #[serde(default = "one")]
    pub looks: u32,
}

fn one() -> u32 {
    1
}

/// The plan's summary and the loop's numbers while planning (`None` before the plan phase,
/// or with a hint).
#[derive(Debug, Default)]
pub struct PlanRecord {
    summary: Option<PlanSummary>,
    stats: Option<PlanningStats>,
}

impl PlanRecord {
    pub fn record(&mut self, summary: PlanSummary, stats: PlanningStats) {
        self.summary = Some(summary);
        self.stats = Some(stats);
    }

    pub fn summary(&self) -> Option<&PlanSummary> {
        self.summary.as_ref()
    }

    pub fn stats(&self) -> Option<PlanningStats> {
        self.stats
    }
}
