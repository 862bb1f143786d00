//! Calibrate (METHOD.md §1): the gripper visits the cage points while its plate is tracked;
//! at each, once the arm has arrived and settled, the reference point's images are averaged
//! over a few frames and paired with the robot's reported tool position. The affine stereo
//! model `w = M X + c` is fitted (on the worker thread) while the arm returns to where it
//! started; the linear epipolar constraint is fitted from the images alone, and the
//! disparity limits taken from the cage. A fit with residuals over the configured limits is
//! refused: the run fails with the numbers.

use handeye_vision::affine::{AffineStereo, EpipolarConstraint};
use handeye_vision::servo::ServoModel;
use handeye_vision::tracker::{Role, View};
use nalgebra::Vector3;

use super::{reject_text, timed_out, Calibration, CalibrationStats, Cmd, Cycle, Job, JobResult, Mission, MovePoll, MoveWait, Step};

#[derive(Debug, Clone, Copy, PartialEq)]
enum Stage {
    /// Moving to cage point `i`.
    Moving { i: usize, wait: Option<MoveWait> },
    /// Averaging samples at point `i`.
    Sampling { i: usize, n: u32 },
    /// Fit submitted; the arm moves back.
    Fitting { wait: Option<MoveWait>, submitted: Option<u64> },
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

pub struct Calibrate {
    start_frame: u64,
    stage_frame: u64,
    stage: Stage,
    yaw_rad: f64,
    robot_m: Vec<Vector3<f64>>,
    image_px: Vec<[f64; 4]>,
    acc_w: [f64; 4],
    acc_x: [f64; 3],
    fitted: Option<(AffineStereo, EpipolarConstraint, f64)>,
    arrived_back: bool,
}

impl Calibrate {
    pub fn new(frame_index: u64) -> Self {
        Self {
            start_frame: frame_index,
            stage_frame: frame_index,
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

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        // Scalars copied out so that `m` stays free to borrow mutably (no allocation).
        let cfg = CalibrationView::of(&m.cfg.calibration);
        let points = cfg.points;
        let limit = cfg.point_timeout_s * (points as f64 + 2.0);
        if timed_out(&m.cfg, self.start_frame, c.frame_index, limit) {
            return Step::Fail(format!("calibrate: timed out after {limit:.0} s at {:?}", self.stage));
        }
        if self.yaw_rad.is_nan() {
            self.yaw_rad = f64::from(c.robot.tool_yaw_rad);
        }
        match &mut self.stage {
            Stage::Moving { i, wait } => {
                let i = *i;
                let Some(w) = wait else {
                    *wait = Some(MoveWait::new(c.seq, c.frame_index));
                    self.stage_frame = c.frame_index;
                    m.set_status("calibrate: visiting the cage");
                    return Step::Stay(Cmd::move_to(m.cfg.calibration.cage_m[i], self.yaw_rad, cfg.speed_mps));
                };
                if timed_out(&m.cfg, self.stage_frame, c.frame_index, cfg.point_timeout_s) {
                    return Step::Fail(format!("calibrate: cage point {i} {:?} not reached in {} s", m.cfg.calibration.cage_m[i], cfg.point_timeout_s));
                }
                match w.poll(c, cfg.settle_frames) {
                    MovePoll::Pending => Step::Stay(Cmd::HOLD),
                    MovePoll::Rejected(code) => {
                        Step::Fail(format!("calibrate: the robot refused cage point {i} {:?}: {}", m.cfg.calibration.cage_m[i], reject_text(code)))
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
            Stage::Fitting { wait, submitted } => {
                if submitted.is_none() {
                    let job = Job::Calibrate { robot_m: self.robot_m.clone(), image_px: self.image_px.clone() };
                    if m.worker.try_submit(job).is_ok() {
                        *submitted = Some(c.frame_index);
                    }
                }
                let ready = submitted.is_some_and(|f| c.frame_index >= f + super::WORKER_DELAY_FRAMES);
                let Some(w) = wait else {
                    *wait = Some(MoveWait::new(c.seq, c.frame_index));
                    m.set_status("calibrate: fitting; arm returning");
                    let (p, yaw) = m.start_pose.unwrap_or(([0.3, 0.0, 0.18], self.yaw_rad));
                    let park = cfg.park.unwrap_or(p);
                    return Step::Stay(Cmd::move_to(park, yaw, cfg.speed_mps));
                };
                match w.poll(c, cfg.settle_frames) {
                    MovePoll::Rejected(code) => return Step::Fail(format!("calibrate: the robot refused the park pose: {}", reject_text(code))),
                    MovePoll::Done => self.arrived_back = true,
                    MovePoll::Pending => {}
                }
                if self.fitted.is_none() && ready {
                    match m.worker.try_result() {
                        None => {}
                        Some(JobResult::Calibration(Ok(fit))) => self.fitted = Some(fit),
                        Some(JobResult::Calibration(Err(e))) => return Step::Fail(format!("calibrate: {e}")),
                        Some(_) => return Step::Fail("calibrate: unexpected worker result".into()),
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
                    return Step::Fail(format!(
                        "calibrate: refused: affine fit residual {:.2} px RMS > {} px (a tracker slipped, or the cameras are far from weak perspective)",
                        stats.residual_rms_px, cfg.max_residual_px
                    ));
                }
                if stats.epipolar_rms_px > cfg.max_epipolar_px {
                    return Step::Fail(format!("calibrate: refused: epipolar residual {:.2} px RMS > {} px", stats.epipolar_rms_px, cfg.max_epipolar_px));
                }
                let servo_model = match ServoModel::new(&model) {
                    Ok(s) => s,
                    Err(e) => return Step::Fail(format!("calibrate: unusable model: {e}")),
                };
                m.calibration = Some(Calibration {
                    model,
                    epipolar,
                    servo_model,
                    stats,
                    cage_robot_m: self.robot_m.clone(),
                    cage_image_px: self.image_px.clone(),
                });
                m.calibration_yaw_rad = Some(self.yaw_rad);
                m.snapshot = Some("calibrated");
                m.set_status("calibrated");
                Step::Next(Cmd::HOLD)
            }
        }
    }

    fn sample(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        let Stage::Sampling { i, n } = &mut self.stage else { return Step::Stay(Cmd::HOLD) };
        let (Some(l), Some(r)) = (m.trackers.get(Role::Gripper, View::Left), m.trackers.get(Role::Gripper, View::Right)) else {
            return Step::Fail("calibrate: no gripper trackers".into());
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
            Stage::Fitting { wait: None, submitted: None }
        };
        Step::Stay(Cmd::HOLD)
    }
}

/// Worker job: the affine model (which carries its residual and disparity limits) and the
/// epipolar constraint fitted from the images alone, with that constraint's RMS residual.
pub fn fit(robot_m: &[Vector3<f64>], image_px: &[[f64; 4]]) -> Result<(AffineStereo, EpipolarConstraint, f64), String> {
    let model = AffineStereo::fit(robot_m, image_px).map_err(|e| format!("affine fit: {e}"))?;
    let epipolar = EpipolarConstraint::fit(image_px).map_err(|e| format!("epipolar fit: {e}"))?;
    let rms = (image_px.iter().map(|w| epipolar.residual_px(w).powi(2)).sum::<f64>() / image_px.len() as f64).sqrt();
    Ok((model, epipolar, rms))
}
