//! Acquire the gripper (METHOD.md §3, "Locating the gripper"): with the arm still, take a
//! frame with the jaws open and one with them closed, locate what moved in both views
//! (`handeye_vision::locate`), find the plate's light rectangle just above the fingers,
//! start a plate tracker in each view, let them converge, and verify them.
//!
//! Copying the two frame pairs and the location itself allocate; they happen once, and the
//! location runs on the worker thread while the loop keeps answering frames.

use std::fmt;

use handeye_vision::image::ImageBuf;
use handeye_vision::locate::{locate_moving, LocateConfig, LocateError};
use handeye_vision::planner::geom;
use handeye_vision::tracker::{ContourTracker, Role, View};
use handeye_wire::report::FailureKind;
use handeye_wire::{robot_flags, GripperCommand};

use super::job::PendingJob;
use super::step::{elapsed_at_least, timed_out, Cmd, Cycle, Step};
use crate::gripper::{pair_plates, plate_candidates, PlateError, MAX_PLATE_AREA_RATIO};
use crate::mission::Mission;

/// The plate's corners in both views (left, right), image pixels.
pub type PlateCorners = [[[f64; 2]; 4]; 2];

/// Why the worker did not locate the plate.
#[derive(Debug, thiserror::Error)]
pub enum LocatePlatesError {
    #[error("{view} view: {source}")]
    Motion { view: &'static str, source: LocateError },
    #[error("{view} view: {source}")]
    Plate { view: &'static str, source: PlateError },
}

enum Stage {
    /// Jaws opening (or open), waiting for them and the arm to be still.
    Open { still: u32 },
    Close { sent_ns: Option<u64>, still: u32 },
    /// Location running on the worker (once submitted); the jaws reopen meanwhile.
    Locating { job: Option<PendingJob<Result<PlateCorners, LocatePlatesError>>> },
    /// `found_px2`: the plate's image area as the locator found it in each view.
    Converging { frames: u32, found_px2: [f64; 2] },
}

/// The stage as the time-out's failure names it (the wording of the stage's fields stays
/// that of the submitted frame and the result).
impl fmt::Debug for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        /// The result as the failure text shows it.
        struct Plate<'a>(Result<&'a PlateCorners, String>);
        impl fmt::Debug for Plate<'_> {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.debug_tuple("Plate").field(&self.0).finish()
            }
        }
        match self {
            Self::Open { still } => f.debug_struct("Open").field("still", still).finish(),
            Self::Close { sent_ns, still } => f.debug_struct("Close").field("sent_ns", sent_ns).field("still", still).finish(),
            Self::Locating { job } => {
                let result = job.as_ref().and_then(PendingJob::collected).map(|r| Plate(r.as_ref().map_err(ToString::to_string)));
                f.debug_struct("Locating").field("submitted", &job.as_ref().map(PendingJob::submitted_frame)).field("result", &result).finish()
            }
            Self::Converging { frames, .. } => f.debug_struct("Converging").field("frames", frames).finish(),
        }
    }
}

pub struct AcquireGripper {
    start_ns: u64,
    stage: Stage,
    open: Option<[ImageBuf; 2]>,
    closed: Option<[ImageBuf; 2]>,
}

/// Arm still and the jaws where asked. Jaws closing on nothing may keep pushing against
/// each other without ever reporting `GRIPPER_SETTLED`; after [`JAW_PATIENCE_S`] of camera
/// time in the asked state they count as still too (the fingers stop moving visibly long
/// before).
fn still(c: &Cycle<'_>, closed: bool, since_ns: u64) -> bool {
    let f = c.robot.flags;
    let jaws = (f & robot_flags::GRIPPER_CLOSED != 0) == closed;
    f & robot_flags::MOVING == 0 && jaws && (f & robot_flags::GRIPPER_SETTLED != 0 || elapsed_at_least(since_ns, c.time_ns, JAW_PATIENCE_S))
}

/// How long jaws in the asked state may keep reporting unsettled, s.
const JAW_PATIENCE_S: f64 = 1.0;

impl AcquireGripper {
    pub fn new(time_ns: u64) -> Self {
        Self { start_ns: time_ns, stage: Stage::Open { still: 0 }, open: None, closed: None }
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(self.start_ns, c.time_ns, m.cfg.acquire.timeout_s) {
            return Step::fail(FailureKind::TimedOut, format!("acquire_gripper: timed out after {} s in stage {:?}", m.cfg.acquire.timeout_s, self.stage));
        }
        let settle = m.cfg.acquire.settle_frames;
        match &mut self.stage {
            Stage::Open { still: n } => {
                *n = if still(c, false, self.start_ns) { *n + 1 } else { 0 };
                if *n > settle {
                    // Allocates once: the open pair, kept for the difference.
                    self.open = Some([c.left.to_owned(), c.right.to_owned()]);
                    self.stage = Stage::Close { sent_ns: None, still: 0 };
                    m.reporting.set_status("acquire gripper: jaws open, closing");
                }
                Step::Stay(Cmd::gripper(GripperCommand::Open))
            }
            Stage::Close { sent_ns, still: n } => {
                let Some(sent) = *sent_ns else {
                    *sent_ns = Some(c.time_ns);
                    return Step::Stay(Cmd::gripper(GripperCommand::Close));
                };
                *n = if still(c, true, sent) { *n + 1 } else { 0 };
                if *n > settle {
                    self.closed = Some([c.left.to_owned(), c.right.to_owned()]);
                    self.stage = Stage::Locating { job: None };
                    m.reporting.set_status("acquire gripper: locating the moving fingers");
                    return Step::Stay(Cmd::gripper(GripperCommand::Open));
                }
                Step::Stay(Cmd::HOLD)
            }
            Stage::Locating { job } => {
                let Some(job) = job else {
                    // A refused job would lose the frames: submit only when there is room.
                    if m.worker.has_room()
                        && let (Some(open), Some(closed)) = (self.open.take(), self.closed.take())
                    {
                        *job = PendingJob::submit(&mut m.worker, c.frame_index, move || locate_plates(&open, &closed));
                    }
                    return Step::Stay(Cmd::HOLD);
                };
                // Taken off the worker as soon as it is done, handed out when due.
                job.collect(&mut m.worker);
                match job.poll(&mut m.worker, c.frame_index) {
                    None => Step::Stay(Cmd::HOLD),
                    Some(Ok(plates)) => {
                        let found_px2 = plates.map(|corners| geom::area(&corners));
                        for (view, corners) in [View::Left, View::Right].into_iter().zip(plates) {
                            match ContourTracker::new(m.cfg.plate_tracker_config(), &corners) {
                                Ok(t) => {
                                    m.trackers.insert(Role::Gripper, view, t);
                                }
                                Err(e) => return Step::fail(FailureKind::GripperNotFound, format!("acquire_gripper: plate tracker: {e}")),
                            }
                        }
                        self.stage = Stage::Converging { frames: 0, found_px2 };
                        m.reporting.set_status("acquire gripper: plate trackers converging");
                        Step::Stay(Cmd::HOLD)
                    }
                    Some(Err(e)) => Step::fail(FailureKind::GripperNotFound, format!("acquire_gripper: {e}")),
                }
            }
            Stage::Converging { frames, found_px2 } => {
                if !c.states.pair_tracking(Role::Gripper) {
                    return Step::fail(FailureKind::TrackerLost, "acquire_gripper: a plate tracker was lost while converging");
                }
                *frames += 1;
                // Refine the found corners from the plate's edges, twice (see
                // `gripper::refine_polygon`): the marks' accuracy rests on this outline.
                let third = m.cfg.acquire.converge_frames / 3;
                if third > 0 && (*frames == third || *frames == 2 * third) {
                    for view in View::ALL {
                        let Some(t) = m.trackers.get_mut(Role::Gripper, view) else { continue };
                        if let Some(corners) = crate::gripper::refine_polygon(t) {
                            let _ = t.reinit(&corners);
                        }
                    }
                }
                if *frames < m.cfg.acquire.converge_frames {
                    return Step::Stay(Cmd::HOLD);
                }
                // Verify: both confident, big enough, and of similar size in both views.
                let mut areas = [0.0; 2];
                for (i, view) in [View::Left, View::Right].into_iter().enumerate() {
                    let Some(t) = m.trackers.get(Role::Gripper, view) else { return Step::fail(FailureKind::Internal, "acquire_gripper: tracker missing") };
                    let score = t.confidence().score;
                    if score < m.cfg.acquire.min_score {
                        return Step::fail(FailureKind::TrackerUnsure, format!("acquire_gripper: plate tracker ({view:?}) confidence {score:.2} < {}", m.cfg.acquire.min_score));
                    }
                    let corners: Vec<_> = t.corners().collect();
                    areas[i] = geom::area(&corners.iter().map(|p| [p.x, p.y]).collect::<Vec<_>>());
                    let least = crate::gripper::least_plate_area_px2(found_px2[i], m.cfg.acquire.min_plate_area_px2);
                    if areas[i] < least {
                        return Step::fail(FailureKind::GripperNotFound, format!(
                            "acquire_gripper: plate ({view:?}) only {:.0} px², less than {least:.0} px² (half the {:.0} px² the locator found)",
                            areas[i], found_px2[i]
                        ));
                    }
                }
                let ratio = areas[0].max(areas[1]) / areas[0].min(areas[1]);
                if ratio > MAX_PLATE_AREA_RATIO {
                    return Step::fail(FailureKind::GripperNotFound, format!("acquire_gripper: plate areas differ between views ({:.0} vs {:.0} px²)", areas[0], areas[1]));
                }
                m.reporting.snapshot("gripper_acquired");
                m.reporting.set_status("gripper acquired");
                Step::Next(Cmd::HOLD)
            }
        }
    }
}

/// Worker job: the plate's corners in both views from the open and closed pairs: each
/// view's plate candidates, paired so that both views see one plate ([`pair_plates`]).
pub fn locate_plates(open: &[ImageBuf; 2], closed: &[ImageBuf; 2]) -> Result<PlateCorners, LocatePlatesError> {
    let mut candidates: [Vec<[[f64; 2]; 4]>; 2] = Default::default();
    for v in 0..2 {
        let view = ["left", "right"][v];
        let motion = locate_moving(&open[v].view(), &closed[v].view(), &LocateConfig::default())
            .map_err(|source| LocatePlatesError::Motion { view, source })?;
        candidates[v] = plate_candidates(&open[v].view(), &motion).map_err(|source| LocatePlatesError::Plate { view, source })?;
    }
    let [left, right] = candidates;
    // `plate_candidates` errs rather than return none, so a pair is always found.
    Ok(pair_plates(&left, &right).unwrap_or([left[0], right[0]]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_out_names_the_stage_as_before() {
        assert_eq!(format!("{:?}", Stage::Locating { job: None }), "Locating { submitted: None, result: None }");
        assert_eq!(format!("{:?}", Stage::Close { sent_ns: Some(4), still: 2 }), "Close { sent_ns: Some(4), still: 2 }");
        let mut worker = crate::phase::job::spawn_worker().unwrap();
        let mut job = PendingJob::submit(&mut worker, 7, || Err(LocatePlatesError::Plate { view: "left", source: PlateError::NoMotion }));
        while job.as_ref().is_some_and(|j| j.collected().is_none()) {
            job.as_mut().unwrap().collect(&mut worker);
            std::thread::yield_now();
        }
        assert_eq!(
            format!("{:?}", Stage::Locating { job }),
            r#"Locating { submitted: Some(7), result: Some(Plate(Err("left view: nothing moved"))) }"#
        );
    }
}
