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
