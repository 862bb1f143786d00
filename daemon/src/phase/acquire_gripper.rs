//! Acquire the gripper (METHOD.md §3, "Locating the gripper"): with the arm still, take a
//! frame with the jaws open and one with them closed, locate what moved in both views
//! (`handeye_vision::locate`), find the plate's light rectangle just above the fingers,
//! start a plate tracker in each view, let them converge, and verify them.
//!
//! Copying the two frame pairs and the location itself allocate; they happen once, and the
//! location runs on the worker thread while the loop keeps answering frames.

use handeye_vision::image::ImageBuf;
use handeye_vision::locate::{locate_moving, LocateConfig};
use handeye_vision::planner::geom;
use handeye_vision::tracker::{ContourTracker, Role, View};
use handeye_wire::{robot_flags, GripperCommand};

use super::{timed_out, Cmd, Cycle, Job, JobResult, Mission, Step};
use crate::gripper::find_plate;

#[derive(Debug)]
enum Stage {
    /// Jaws opening (or open), waiting for them and the arm to be still.
    Open { still: u32 },
    Close { sent_frame: Option<u64>, still: u32 },
    /// Location running on the worker; the jaws reopen meanwhile.
    Locating { submitted: Option<u64>, result: Option<Box<JobResult>> },
    Converging { frames: u32 },
}

pub struct AcquireGripper {
    start_frame: u64,
    stage: Stage,
    open: Option<[ImageBuf; 2]>,
    closed: Option<[ImageBuf; 2]>,
}

/// Arm still and the jaws where asked. Jaws closing on nothing may keep pushing against
/// each other without ever reporting `GRIPPER_SETTLED`; after `patience` frames in the asked
/// state they count as still too (the fingers stop moving visibly long before).
fn still(c: &Cycle<'_>, closed: bool, frames_in_state: u64, patience: u64) -> bool {
    let f = c.robot.flags;
    let jaws = (f & robot_flags::GRIPPER_CLOSED != 0) == closed;
    f & robot_flags::MOVING == 0 && jaws && (f & robot_flags::GRIPPER_SETTLED != 0 || frames_in_state >= patience)
}

impl AcquireGripper {
    pub fn new(frame_index: u64) -> Self {
        Self { start_frame: frame_index, stage: Stage::Open { still: 0 }, open: None, closed: None }
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(&m.cfg, self.start_frame, c.frame_index, m.cfg.acquire.timeout_s) {
            return Step::Fail(format!("acquire_gripper: timed out after {} s in stage {:?}", m.cfg.acquire.timeout_s, self.stage));
        }
        let settle = m.cfg.acquire.settle_frames;
        let patience = m.cfg.frames(1.0);
        match &mut self.stage {
            Stage::Open { still: n } => {
                let since = c.frame_index - self.start_frame;
                *n = if still(c, false, since, patience) { *n + 1 } else { 0 };
                if *n > settle {
                    // Allocates once: the open pair, kept for the difference.
                    self.open = Some([c.left.to_owned(), c.right.to_owned()]);
                    self.stage = Stage::Close { sent_frame: None, still: 0 };
                    m.set_status("acquire gripper: jaws open, closing");
                }
                Step::Stay(Cmd::gripper(GripperCommand::Open))
            }
            Stage::Close { sent_frame, still: n } => {
                let Some(sent) = *sent_frame else {
                    *sent_frame = Some(c.frame_index);
                    return Step::Stay(Cmd::gripper(GripperCommand::Close));
                };
                *n = if still(c, true, c.frame_index - sent, patience) { *n + 1 } else { 0 };
                if *n > settle {
                    self.closed = Some([c.left.to_owned(), c.right.to_owned()]);
                    self.stage = Stage::Locating { submitted: None, result: None };
                    m.set_status("acquire gripper: locating the moving fingers");
                    return Step::Stay(Cmd::gripper(GripperCommand::Open));
                }
                Step::Stay(Cmd::HOLD)
            }
            Stage::Locating { submitted, result } => {
                if submitted.is_none() {
                    if let (Some(open), Some(closed)) = (self.open.take(), self.closed.take()) {
                        match m.worker.try_submit(Job::LocateGripper { open, closed }) {
                            Ok(()) => *submitted = Some(c.frame_index),
                            Err(Job::LocateGripper { open, closed }) => {
                                self.open = Some(open);
                                self.closed = Some(closed);
                            }
                            Err(_) => {}
                        }
                    }
                    return Step::Stay(Cmd::HOLD);
                }
                if result.is_none() {
                    *result = m.worker.try_result().map(Box::new);
                }
                if submitted.is_some_and(|f| c.frame_index < f + super::WORKER_DELAY_FRAMES) {
                    return Step::Stay(Cmd::HOLD);
                }
                match result.take().map(|r| *r) {
                    None => Step::Stay(Cmd::HOLD),
                    Some(JobResult::Plate(Ok(plates))) => {
                        for (view, corners) in [View::Left, View::Right].into_iter().zip(plates) {
                            match ContourTracker::new(m.cfg.plate_tracker_config(), &corners) {
                                Ok(t) => {
                                    m.trackers.insert(Role::Gripper, view, t);
                                }
                                Err(e) => return Step::Fail(format!("acquire_gripper: plate tracker: {e}")),
                            }
                        }
                        self.stage = Stage::Converging { frames: 0 };
                        m.set_status("acquire gripper: plate trackers converging");
                        Step::Stay(Cmd::HOLD)
                    }
                    Some(JobResult::Plate(Err(e))) => Step::Fail(format!("acquire_gripper: {e}")),
                    Some(_) => Step::Fail("acquire_gripper: unexpected worker result".into()),
                }
            }
            Stage::Converging { frames } => {
                if !c.states.pair_tracking(Role::Gripper) {
                    return Step::Fail("acquire_gripper: a plate tracker was lost while converging".into());
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
                    let Some(t) = m.trackers.get(Role::Gripper, view) else { return Step::Fail("acquire_gripper: tracker missing".into()) };
                    let score = t.confidence().score;
                    if score < m.cfg.acquire.min_score {
                        return Step::Fail(format!("acquire_gripper: plate tracker ({view:?}) confidence {score:.2} < {}", m.cfg.acquire.min_score));
                    }
                    let corners: Vec<_> = t.corners().collect();
                    areas[i] = geom::area(&corners.iter().map(|p| [p.x, p.y]).collect::<Vec<_>>());
                    if areas[i] < m.cfg.acquire.min_plate_area_px2 {
                        return Step::Fail(format!("acquire_gripper: plate ({view:?}) only {:.0} px²", areas[i]));
                    }
                }
                let ratio = areas[0].max(areas[1]) / areas[0].min(areas[1]);
                if ratio > 1.6 {
                    return Step::Fail(format!("acquire_gripper: plate areas differ between views ({:.0} vs {:.0} px²)", areas[0], areas[1]));
                }
                m.snapshot = Some("gripper_acquired");
                m.set_status("gripper acquired");
                Step::Next(Cmd::HOLD)
            }
        }
    }
}

/// Worker job: the plate's corners in both views from the open and closed pairs.
pub fn locate_plates(open: &[ImageBuf; 2], closed: &[ImageBuf; 2]) -> Result<[[[f64; 2]; 4]; 2], String> {
    let mut out = [[[0.0; 2]; 4]; 2];
    for v in 0..2 {
        let name = ["left", "right"][v];
        let motion = locate_moving(&open[v].view(), &closed[v].view(), &LocateConfig::default())
            .map_err(|e| format!("{name} view: {e}"))?;
        out[v] = find_plate(&open[v].view(), &motion).map_err(|e| format!("{name} view: {e}"))?;
    }
    Ok(out)
}
