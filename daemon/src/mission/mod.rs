//! The state that lives across phases, in parts with one owner each: the shared context
//! (configuration, plate template, trackers, worker), [`Targeting`], the
//! [`CalibrationRecord`], the [`ServoRecord`], the [`PlanRecord`], the [`PointingRecord`]
//! and [`Reporting`]. The
//! phases borrow the parts they work on; the hard loop reads them for telemetry and the
//! outcome.

pub mod calibration;
pub mod plan_record;
pub mod pointing;
pub mod reporting;
pub mod servo_record;
pub mod targeting;

pub use calibration::{Calibration, CalibrationRecord, CalibrationStats};
pub use plan_record::{PlanRecord, PlanningStats};
pub use pointing::{PointingRecord, PointingSummary};
pub use reporting::{ReportRequests, Reporting};
pub use servo_record::{ServoRecord, ServoTraceRow};
pub use targeting::{TargetSource, TargetSpec, Targeting};

use handeye_vision::tracker::{Role, StereoTrackerSet, View};
use handeye_wire::hint::OperatorHint;

use crate::config::DaemonConfig;
use crate::gripper::PlateTemplate;
use crate::phase::job::{spawn_worker, JobWorker};

/// Re-plans a run may make for a moved or unusable target (a nudge, and one more).
pub const MAX_REPLANS: u32 = 2;

/// State shared across phases.
pub struct Mission {
    pub cfg: DaemonConfig,
    pub plate: PlateTemplate,
    pub trackers: StereoTrackerSet,
    /// The worker thread for work longer than a frame.
    pub worker: JobWorker,
    pub targeting: Targeting,
    pub calibration: CalibrationRecord,
    pub servo: ServoRecord,
    pub planning: PlanRecord,
    /// What the point phase saw (the operator's gestures).
    pub pointing: PointingRecord,
    pub reporting: Reporting,
}

impl Mission {
    pub fn new(cfg: DaemonConfig, hint: Option<&OperatorHint>) -> std::io::Result<Self> {
        let plate = PlateTemplate::new(&cfg.gripper);
        let servo = ServoRecord::new(cfg.servo.convergence.max_steps);
        let mut worker = spawn_worker()?;
        worker.set_due_wait(std::time::Duration::from_millis(cfg.timing.worker_wait_ms));
        Ok(Self {
            cfg,
            plate,
            trackers: StereoTrackerSet::new(),
            worker,
            targeting: Targeting::new(hint),
            calibration: CalibrationRecord::default(),
            servo,
            planning: PlanRecord::default(),
            pointing: PointingRecord::default(),
            reporting: Reporting::default(),
        })
    }

    /// A camera moved after the calibration (`view`, its image shifted by about `shift_px`):
    /// the calibration is made again, so what was worked out in the old camera's pixels goes:
    /// the target's trackers, and a planned target with its alternatives (the scene is planned
    /// again). An operator hint's outline in the moved view is shifted with the image (the
    /// operator clicked the old view).
    pub fn camera_moved(&mut self, view: View, shift_px: [f64; 2]) {
        for v in View::ALL {
            self.trackers.remove(Role::Target, v);
        }
        self.targeting.camera_moved(view, shift_px);
        self.calibration.note_camera_moved();
        let side = if view == View::Left { "left" } else { "right" };
        self.reporting.set_status(&format!("{side} camera moved after the calibration: calibrating again"));
        self.reporting.snapshot("camera_moved");
    }

    /// Plans the scene again from a fresh pair, if allowed ([`Targeting::can_replan`], at most
    /// [`MAX_REPLANS`] a run): the target's trackers go, and the indicated point moves by
    /// `moved_m` with the target. `false`: not allowed (the caller fails as before).
    pub fn replan(&mut self, why: &str, moved_m: [f64; 2]) -> bool {
        if !self.targeting.can_replan(MAX_REPLANS) {
            return false;
        }
        tracing::warn!(%why, moved_mm = ?moved_m.map(|v| v * 1e3), "target lost or unusable: planning again from a fresh pair");
        for view in View::ALL {
            self.trackers.remove(Role::Target, view);
        }
        self.targeting.forget_for_replan(moved_m);
        self.reporting.set_status("the target moved or could not be held: planning again");
        self.reporting.snapshot("replan");
        true
    }

    /// Gives up the current target (removing its trackers) for the plan's next grasp site;
    /// `false` when there is none left.
    pub fn next_target(&mut self, why: &str) -> bool {
        if !self.targeting.advance() {
            return false;
        }
        tracing::warn!(%why, left = self.targeting.alternatives_left(), "target given up: trying the plan's next grasp site");
        for view in View::ALL {
            self.trackers.remove(Role::Target, view);
        }
        self.reporting.set_status("acquire target: trying the next grasp site");
        self.reporting.snapshot("target_given_up");
        true
    }
}
