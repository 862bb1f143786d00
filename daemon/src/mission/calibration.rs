//! The hand-eye calibration as the calibrate phase left it, with the pose it started from.

use handeye_vision::affine::{AffineStereo, EpipolarConstraint};
use handeye_vision::servo::ServoModel;
use serde::{Deserialize, Serialize};

/// The calibration's result and how good it is.
#[derive(Debug, Clone)]
pub struct Calibration {
    pub model: AffineStereo,
    pub epipolar: EpipolarConstraint,
    pub servo_model: ServoModel,
    pub stats: CalibrationStats,
    /// The cage as measured: tool positions (robot frame, m) and the reference point's
    /// images `(u, v, u', v')` (tracker pixels); the planner fits pinhole cameras to them.
    pub cage_robot_m: Vec<nalgebra::Vector3<f64>>,
    pub cage_image_px: Vec<[f64; 4]>,
}

/// Numbers of the calibration for the outcome and the report.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CalibrationStats {
    pub points: usize,
    /// RMS residual of the affine fit over the cage, px.
    pub residual_rms_px: f64,
    /// RMS residual of the epipolar constraint fitted from the images alone, px.
    pub epipolar_rms_px: f64,
    /// Disparity limits of the workspace (`u − u'` over the cage), px.
    pub disparity_range_px: [f64; 2],
}

/// The calibration (once made), the tool yaw it was made at, and the arm's pose at start-up.
#[derive(Debug, Default)]
pub struct CalibrationRecord {
    calibration: Option<Calibration>,
    /// Tool yaw during the calibration (the model absorbed the plate's offset at this yaw).
    yaw_rad: Option<f64>,
    /// Pose at start-up: where the arm is parked between phases.
    start_pose: Option<([f64; 3], f64)>,
    /// Times a camera was found moved after the calibration, and the cameras calibrated
    /// again.
    recalibrations: u32,
}

impl CalibrationRecord {
    pub fn get(&self) -> Option<&Calibration> {
        self.calibration.as_ref()
    }

    /// The model, to move with a knocked camera's image.
    pub fn get_mut(&mut self) -> Option<&mut Calibration> {
        self.calibration.as_mut()
    }

    /// The calibration made with the tool at `yaw_rad`.
    pub fn set(&mut self, calibration: Calibration, yaw_rad: f64) {
        self.calibration = Some(calibration);
        self.yaw_rad = Some(yaw_rad);
    }

    /// A camera moved after the calibration: it is being made again.
    pub fn note_camera_moved(&mut self) {
        self.recalibrations += 1;
    }

    /// Times the cameras were calibrated again after one moved.
    pub fn recalibrations(&self) -> u32 {
        self.recalibrations
    }

    pub fn stats(&self) -> Option<CalibrationStats> {
        self.calibration.as_ref().map(|c| c.stats)
    }

    pub fn yaw_rad(&self) -> Option<f64> {
        self.yaw_rad
    }

    pub fn start_pose(&self) -> Option<([f64; 3], f64)> {
        self.start_pose
    }

    /// The first robot state's pose is the start pose (later ones change nothing).
    pub fn note_start_pose(&mut self, tool_m: [f64; 3], yaw_rad: f64) {
        if self.start_pose.is_none() {
            self.start_pose = Some((tool_m, yaw_rad));
        }
    }
}
