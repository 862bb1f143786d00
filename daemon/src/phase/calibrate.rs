//! Calibrate (METHOD.md §1): the gripper visits the cage points while its plate is tracked;
//! at each, once the arm has arrived and settled, the reference point's images are averaged
//! over a few frames and paired with the robot's reported tool position. The affine stereo
//! model `w = M X + c` is fitted (on the worker thread) while the arm returns to where it
//! started; the linear epipolar constraint is fitted from the images alone, and the
//! disparity limits taken from the cage. A fit with residuals over the configured limits is
//! refused: the run fails with the numbers.

use std::fmt;

use handeye_vision::affine::{AffineStereo, EpipolarConstraint, FitError};
use handeye_vision::servo::ServoModel;
use handeye_vision::tracker::{Role, View};
use handeye_wire::report::FailureKind;
use handeye_wire::RejectReason;
use nalgebra::Vector3;

use super::job::PendingJob;
use super::step::{timed_out, Cmd, Cycle, MovePoll, MoveWait, Step};
use crate::mission::{Calibration, CalibrationStats, Mission};

/// What the worker fits: the affine model, the epipolar constraint and its RMS residual, px.
pub type Fitted = (AffineStereo, EpipolarConstraint, f64);

/// Why the worker's fit failed.
#[derive(Debug, thiserror::Error)]
pub enum CalibrationFitError {
    #[error("affine fit: {0}")]
    Affine(#[source] FitError),
    #[error("epipolar fit: {0}")]
    Epipolar(#[source] FitError),
}

enum Stage {
    /// Moving to cage point `i`.
    Moving { i: usize, wait: Option<MoveWait> },
    /// Averaging samples at point `i`.
    Sampling { i: usize, n: u32 },
    /// Fit submitted (once the worker took it); the arm moves back.
    Fitting { wait: Option<MoveWait>, job: Option<PendingJob<Result<Fitted, CalibrationFitError>>> },
}

/// The stage as the time-out's failure names it (the fit job by the frame it was submitted).
impl fmt::Debug for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Moving { i, wait } => f.debug_struct("Moving").field("i", i).field("wait", wait).finish(),
            Self::Sampling { i, n } => f.debug_struct("Sampling").field("i", i).field("n", n).finish(),
            Self::Fitting { wait, job } => {
                f.debug_struct("Fitting").field("wait", wait).field("submitted", &job.as_ref().map(PendingJob::submitted_frame)).finish()
            }
        }
    }
}

/// The calibration settings a cycle needs, copied (no allocation).
#[derive(Debug, Clone, Copy)]
struct CalibrationView {
    points: usize,
    speed_mps: f64,
    settle_frames: u32,
    point_timeout_s: f64,
    max_residual_px: f64,
    max_epipolar_px: f64,
    park: Option<[f64; 3]>,
}

impl CalibrationView {
    fn of(c: &crate::config::CalibrationConfig) -> Self {
        Self {
            points: c.cage_m.len(),
            speed_mps: c.speed_mps,
            settle_frames: c.settle_frames,
            point_timeout_s: c.point_timeout_s,
            max_residual_px: c.max_residual_px,
            max_epipolar_px: c.max_epipolar_px,
            park: (c.park_m.len() == 3).then(|| [c.park_m[0], c.park_m[1], c.park_m[2]]),
        }
    }
}

/// A plate re-found further than this from where it was lost (the arm held) means its
/// camera moved, px (a stopping arm drifts a few pixels at most).
pub const CAMERA_MOVED_PX: f64 = 15.0;

/// Cage points sampled before a loss from which the affine model is fitted to say where the
/// plate should be: the model has 4 unknowns a coordinate, so 5 points leave one to check the
/// fit by its residual.
const MIN_POINTS_TO_PREDICT: usize = 5;

/// Whether the cage points sampled so far (`robot_m`, `image_px`) put the plate, with the arm
/// at `tool_m`, within [`CAMERA_MOVED_PX`] of where it was found again (`plate_px`, both
/// views) with a fit residual within `max_residual_px`: then no camera moved, whatever the
/// plate's shift from its search base (a base from before the arm stopped, or a squeezed one,
/// is far from where the plate stands). Too few points, a failed or poor fit, or one view off
/// the prediction: `false` (a camera may have moved, and the cage is visited again).
pub fn samples_place_the_plate(robot_m: &[Vector3<f64>], image_px: &[[f64; 4]], tool_m: &Vector3<f64>, plate_px: &[f64; 4], max_residual_px: f64) -> bool {
    if robot_m.len() < MIN_POINTS_TO_PREDICT {
        return false;
    }
    let Ok(model) = AffineStereo::fit(robot_m, image_px) else { return false };
    if model.residual_rms_px > max_residual_px {
        return false;
    }
    let p = model.project(tool_m);
    let off = |k: usize| (p[k] - plate_px[k]).hypot(p[k + 1] - plate_px[k + 1]);
    off(0) <= CAMERA_MOVED_PX && off(2) <= CAMERA_MOVED_PX
}

/// The plate's reference point in both views now, px (`None` without both gripper trackers).
pub fn plate_px(m: &Mission) -> Option<[f64; 4]> {
    let (l, r) = (m.trackers.get(Role::Gripper, View::Left)?, m.trackers.get(Role::Gripper, View::Right)?);
    let st = nalgebra::Vector2::new(m.plate.reference_st[0], m.plate.reference_st[1]);
    let (pl, pr) = (l.image_from_template(st), r.image_from_template(st));
    Some([pl.x, pl.y, pr.x, pr.y])
}

pub struct Calibrate {
    start_ns: u64,
    stage_ns: u64,
    stage: Stage,
    yaw_rad: f64,
    robot_m: Vec<Vector3<f64>>,
    image_px: Vec<[f64; 4]>,
    acc_w: [f64; 4],
    acc_x: [f64; 3],
    fitted: Option<Fitted>,
    arrived_back: bool,
}

impl Calibrate {
    pub fn new(time_ns: u64) -> Self {
        Self {
            start_ns: time_ns,
            stage_ns: time_ns,
            stage: Stage::Moving { i: 0, wait: None },
            yaw_rad: f64::NAN,
            robot_m: Vec::with_capacity(16),
            image_px: Vec::with_capacity(16),
            acc_w: [0.0; 4],
            acc_x: [0.0; 3],
            fitted: None,
            arrived_back: false,
        }
    }

    /// Picks up after the arm held `held_ns` for a lost tracker: the time held does not count
    /// against the phase; the move under way is sent again (the arm stopped short of it), and
    /// a point being sampled is visited and sampled afresh (its samples may have included the
    /// frames that lost the plate). A plate found `plate_shift_px` or more from where it was
    /// lost, with the arm held still, means the camera moved: the samples so far belong to
    /// the camera as it was, and the cage starts again (at `now_ns`, with a fresh time-out):
    /// `true` then. Unless the points sampled so far place the plate (`plate_px`, with the arm
    /// at `tool_m`) where it was found ([`samples_place_the_plate`]): a shift from a search
    /// base the camera did not cause.
    pub fn resume(&mut self, now_ns: u64, held_ns: u64, plate_shift_px: f64, plate_px: Option<[f64; 4]>, tool_m: Vector3<f64>, max_residual_px: f64) -> bool {
        let placed = || plate_px.is_some_and(|p| samples_place_the_plate(&self.robot_m, &self.image_px, &tool_m, &p, max_residual_px));
        if plate_shift_px > CAMERA_MOVED_PX && self.fitted.is_none() && !placed() {
            tracing::warn!(plate_shift_px, "calibrate: the plate came back elsewhere: a camera moved; visiting the cage again");
            self.robot_m.clear();
            self.image_px.clear();
            self.start_ns = now_ns;
            self.stage_ns = now_ns;
            self.stage = Stage::Moving { i: 0, wait: None };
            return true;
        }
        self.start_ns = self.start_ns.saturating_add(held_ns);
        self.stage_ns = self.stage_ns.saturating_add(held_ns);
        match &mut self.stage {
            Stage::Moving { wait, .. } | Stage::Fitting { wait, .. } => *wait = None,
            Stage::Sampling { i, .. } => self.stage = Stage::Moving { i: *i, wait: None },
        }
        false
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        // Scalars copied out so that `m` stays free to borrow mutably (no allocation).
        let cfg = CalibrationView::of(&m.cfg.calibration);
        let points = cfg.points;
        let limit = cfg.point_timeout_s * (points as f64 + 2.0);
        if timed_out(self.start_ns, c.time_ns, limit) {
            return Step::fail(FailureKind::TimedOut, format!("calibrate: timed out after {limit:.0} s at {:?}", self.stage));
        }
        if self.yaw_rad.is_nan() {
            self.yaw_rad = f64::from(c.robot.tool_yaw_rad);
        }
        match &mut self.stage {
            Stage::Moving { i, wait } => {
                let i = *i;
                let Some(w) = wait else {
                    *wait = Some(MoveWait::new(c.seq, c.frame_index));
                    self.stage_ns = c.time_ns;
                    m.reporting.set_status("calibrate: visiting the cage");
                    return Step::Stay(Cmd::move_to(m.cfg.calibration.cage_m[i], self.yaw_rad, cfg.speed_mps));
                };
                if timed_out(self.stage_ns, c.time_ns, cfg.point_timeout_s) {
                    return Step::fail(FailureKind::TimedOut, format!("calibrate: cage point {i} {:?} not reached in {} s", m.cfg.calibration.cage_m[i], cfg.point_timeout_s));
                }
                match w.poll(c, cfg.settle_frames) {
                    MovePoll::Pending => Step::Stay(Cmd::HOLD),
                    MovePoll::Rejected(code) => {
                        Step::fail(
                            FailureKind::RobotRefused,
                            format!("calibrate: the robot refused cage point {i} {:?}: {}", m.cfg.calibration.cage_m[i], RejectReason::text_of(code)),
                        )
                    }
                    MovePoll::Done => {
                        self.acc_w = [0.0; 4];
                        self.acc_x = [0.0; 3];
                        self.stage = Stage::Sampling { i, n: 0 };
                        self.sample(m, c)
                    }
                }
            }
            Stage::Sampling { .. } => self.sample(m, c),
            Stage::Fitting { wait, job } => {
                if job.is_none() {
                    let (robot_m, image_px) = (self.robot_m.clone(), self.image_px.clone());
                    *job = PendingJob::submit(&mut m.worker, c.frame_index, move || fit(&robot_m, &image_px));
                }
                let Some(w) = wait else {
                    *wait = Some(MoveWait::new(c.seq, c.frame_index));
                    m.reporting.set_status("calibrate: fitting; arm returning");
                    let (p, yaw) = m.calibration.start_pose().unwrap_or(([0.3, 0.0, 0.18], self.yaw_rad));
                    let park = cfg.park.unwrap_or(p);
                    return Step::Stay(Cmd::move_to(park, yaw, cfg.speed_mps));
                };
                match w.poll(c, cfg.settle_frames) {
                    MovePoll::Rejected(code) => {
                        return Step::fail(FailureKind::RobotRefused, format!("calibrate: the robot refused the park pose: {}", RejectReason::text_of(code)));
                    }
                    MovePoll::Done => self.arrived_back = true,
                    MovePoll::Pending => {}
                }
                if self.fitted.is_none()
                    && let Some(result) = job.as_mut().and_then(|j| j.poll(&mut m.worker, c.frame_index))
                {
                    match result {
                        Ok(fit) => self.fitted = Some(fit),
                        Err(e) => return Step::fail(FailureKind::Calibration, format!("calibrate: {e}")),
                    }
                }
                let (Some((model, epipolar, epi_rms)), true) = (self.fitted.clone(), self.arrived_back) else { return Step::Stay(Cmd::HOLD) };
                let stats = CalibrationStats {
                    points: self.robot_m.len(),
                    residual_rms_px: model.residual_rms_px,
                    epipolar_rms_px: epi_rms,
                    disparity_range_px: model.disparity_range_px,
                };
                if stats.residual_rms_px > cfg.max_residual_px {
                    return Step::fail(
                        FailureKind::Calibration,
                        format!(
                        "calibrate: refused: affine fit residual {:.2} px RMS > {} px (a tracker slipped, or the cameras are far from weak perspective)",
                        stats.residual_rms_px, cfg.max_residual_px
                    ),
                    );
                }
                if stats.epipolar_rms_px > cfg.max_epipolar_px {
                    return Step::fail(FailureKind::Calibration, format!("calibrate: refused: epipolar residual {:.2} px RMS > {} px", stats.epipolar_rms_px, cfg.max_epipolar_px));
                }
                let servo_model = match ServoModel::new(&model) {
                    Ok(s) => s,
                    Err(e) => return Step::fail(FailureKind::Calibration, format!("calibrate: unusable model: {e}")),
                };
                m.calibration.set(
                    Calibration { model, epipolar, servo_model, stats, cage_robot_m: self.robot_m.clone(), cage_image_px: self.image_px.clone() },
                    self.yaw_rad,
                );
                m.reporting.snapshot("calibrated");
                m.reporting.set_status("calibrated");
                Step::Next(Cmd::HOLD)
            }
        }
    }

    fn sample(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        let Stage::Sampling { i, n } = &mut self.stage else { return Step::Stay(Cmd::HOLD) };
        let (Some(l), Some(r)) = (m.trackers.get(Role::Gripper, View::Left), m.trackers.get(Role::Gripper, View::Right)) else {
            return Step::fail(FailureKind::Internal, "calibrate: no gripper trackers");
        };
        let st = nalgebra::Vector2::new(m.plate.reference_st[0], m.plate.reference_st[1]);
        let (pl, pr) = (l.image_from_template(st), r.image_from_template(st));
        for (a, v) in self.acc_w.iter_mut().zip([pl.x, pl.y, pr.x, pr.y]) {
            *a += v;
        }
        for (a, v) in self.acc_x.iter_mut().zip(c.robot.tool_pos_m) {
            *a += f64::from(v);
        }
        *n += 1;
        if *n < m.cfg.calibration.samples {
            return Step::Stay(Cmd::HOLD);
        }
        let k = f64::from(*n);
        self.image_px.push(self.acc_w.map(|v| v / k));
        self.robot_m.push(Vector3::from(self.acc_x.map(|v| v / k)));
        let next = *i + 1;
        self.stage = if next < m.cfg.calibration.cage_m.len() {
            Stage::Moving { i: next, wait: None }
        } else {
            Stage::Fitting { wait: None, job: None }
        };
        Step::Stay(Cmd::HOLD)
    }
}

/// Worker job: the affine model (which carries its residual and disparity limits) and the
/// epipolar constraint fitted from the images alone, with that constraint's RMS residual.
pub fn fit(robot_m: &[Vector3<f64>], image_px: &[[f64; 4]]) -> Result<Fitted, CalibrationFitError> {
    let model = AffineStereo::fit(robot_m, image_px).map_err(CalibrationFitError::Affine)?;
    let epipolar = EpipolarConstraint::fit(image_px).map_err(CalibrationFitError::Epipolar)?;
    let rms = (image_px.iter().map(|w| epipolar.residual_px(w).powi(2)).sum::<f64>() / image_px.len() as f64).sqrt();
    Ok((model, epipolar, rms))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_time_out_names_the_stage_as_before() {
        let wait = Some(MoveWait::new(3, 10));
        assert_eq!(format!("{:?}", Stage::Fitting { wait, job: None }), "Fitting { wait: Some(MoveWait { seq: 3, sent_frame: 10, settled: 0 }), submitted: None }");
        assert_eq!(format!("{:?}", Stage::Moving { i: 2, wait: None }), "Moving { i: 2, wait: None }");
        assert_eq!(format!("{:?}", Stage::Sampling { i: 1, n: 4 }), "Sampling { i: 1, n: 4 }");
    }

    /// Two weak-perspective views of the cage (about 1000 px per metre, the right one turned).
    fn image_of(x: &Vector3<f64>) -> [f64; 4] {
        [320.0 + 1000.0 * x.y, 240.0 - 1000.0 * x.z + 200.0 * x.x, 300.0 + 900.0 * x.y + 300.0 * x.x, 250.0 - 1000.0 * x.z + 150.0 * x.x]
    }

    fn cage() -> Vec<Vector3<f64>> {
        let mut c = Vec::new();
        for (x, y, z) in [(0.3, -0.1, 0.1), (0.3, 0.1, 0.1), (0.4, 0.1, 0.1), (0.4, -0.1, 0.1), (0.3, -0.1, 0.25), (0.3, 0.1, 0.25), (0.4, 0.1, 0.25), (0.4, -0.1, 0.25)] {
            c.push(Vector3::new(x, y, z));
        }
        c
    }

    /// Seeds 16 and 26 of the `--disturb` batch: an occluder in calibration, the plate found
    /// again far from its search base though no camera moved, and the cage visited again for
    /// nothing. With enough cage points sampled, the plate where they put it keeps the
    /// samples; a plate off their prediction in one view (a knocked camera), or too few
    /// points to tell, starts the cage again.
    #[test]
    fn a_far_plate_restarts_the_cage_only_where_the_samples_do_not_place_it() {
        let arm = Vector3::new(0.35, 0.05, 0.2);
        let here = image_of(&arm);
        let sampled = |n: usize| {
            let mut c = Calibrate::new(0);
            c.robot_m = cage()[..n].to_vec();
            c.image_px = c.robot_m.iter().map(image_of).collect();
            c
        };
        // Six points sampled, the plate 40 px from its base but where the samples put it.
        let mut c = sampled(6);
        assert!(!c.resume(1_000, 100, 40.0, Some(here), arm, 8.0));
        assert_eq!(c.robot_m.len(), 6, "the samples are kept");
        // The right view 30 px off (its camera knocked): the cage starts again.
        let knocked = [here[0], here[1], here[2] + 30.0, here[3]];
        let mut c = sampled(6);
        assert!(c.resume(1_000, 100, 40.0, Some(knocked), arm, 8.0));
        assert!(c.robot_m.is_empty());
        // Four points (no check on the fit) or no plate: as before, a far plate restarts.
        assert!(sampled(4).resume(1_000, 100, 40.0, Some(here), arm, 8.0));
        assert!(sampled(6).resume(1_000, 100, 40.0, None, arm, 8.0));
        // A near plate never restarts the cage.
        assert!(!sampled(0).resume(1_000, 100, 5.0, None, arm, 8.0));
    }
}
