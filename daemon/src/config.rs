//! The daemon's configuration (`daemon.toml`): everything a user sets up once for a robot
//! and camera pair — loop timing, the gripper model, the calibration cage, gains, time-outs
//! and thresholds. Every table rejects unknown keys; every key has a default (the values
//! that fit the simulator's arm), so a file needs only what differs.
//!
//! Units are in the names. Time-outs are **camera time**, read from the frames' capture
//! stamps (`camera_clock.rs`): the simulator stamps simulated time, so a lockstep run (faster
//! than real time) gets the same time-outs as a real-time one; the stale-stream guard and
//! the start-up wait are the only wall-clock limits.
//!
//! ```
//! use handeye_daemon::config::DaemonConfig;
//! let cfg = DaemonConfig::parse("[servo]\ngain = 0.4\n", "daemon.toml".as_ref()).unwrap();
//! assert_eq!(cfg.servo.control.gain, 0.4);
//! let err = DaemonConfig::parse("[servo]\ngian = 0.4\n", "daemon.toml".as_ref()).unwrap_err();
//! assert!(err.to_string().contains("gian"), "{err}");
//! ```

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// A configuration file that could not be used: the file, and the field with what was wrong.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("{file}: cannot read: {source}")]
    Read { file: PathBuf, source: std::io::Error },
    #[error("{file}: {message}")]
    Parse { file: PathBuf, message: String },
    #[error("{file}: {field} = {value}: {expected}")]
    Invalid { file: PathBuf, field: &'static str, value: String, expected: &'static str },
}

/// `daemon.toml`. The top-level keys are [`RunTiming`]'s (flattened: the file has no
/// `[timing]` table); every other group is a table of its own.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct DaemonConfig {
    #[serde(flatten)]
    pub timing: RunTiming,
    pub gripper: GripperModel,
    pub calibration: CalibrationConfig,
    pub acquire: AcquireConfig,
    pub target: TargetConfig,
    pub plan: PlanSettings,
    /// `[point]`, through [`Self::point`]: a table of its own in the file; kept private so
    /// that the struct stays within the ten public fields `tests/architecture.rs` allows.
    point: PointSettings,
    pub servo: ServoSettings,
    pub grasp: GraspConfig,
    pub safety: SafetyConfig,
    pub tracker: TrackerSettings,
}

/// The run's loop timing and wall-clock limits (the top-level keys of `daemon.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct RunTiming {
    /// Nominal camera frame rate, used only until the capture stamps have measured the
    /// camera's own period, and as the step for a frame whose stamp cannot be believed
    /// (`daemon/src/camera_clock.rs`). Time-outs and the tracker's time step are camera time.
    pub frame_rate_hz: f64,
    /// A cycle (frame received → command sent) longer than this is a deadline miss, µs.
    pub deadline_us: u64,
    /// Stop the arm when no frame arrives for this long (wall clock), ms.
    pub stale_frame_ms: u64,
    /// Longest wait for the first frame at start-up, s (wall clock).
    pub start_timeout_s: f64,
    /// After `done`, keep answering frames (holding) for this long before exiting, s of camera time;
    /// the run also ends when the camera stream goes away.
    pub done_hold_s: f64,
    /// Lockstep only: when a worker result (gripper location, calibration fit, plan) is due
    /// but not in yet, hold the frame's answer up to this long for it, ms. A lockstep camera
    /// waits for the answer anyway, so a loaded machine then gives the same run as a quiet
    /// one instead of moving on a few frames later. 0 (the default): never wait, as with
    /// real cameras, whose frames do not wait for the loop. `handeye run` sets it.
    pub worker_wait_ms: u64,
}

impl Default for RunTiming {
    fn default() -> Self {
        Self { frame_rate_hz: 30.0, deadline_us: 1000, stale_frame_ms: 100, start_timeout_s: 60.0, done_hold_s: 4.0, worker_wait_ms: 0 }
    }
}

/// The gripper as the daemon needs to know it. Plate coordinates: metres on the tracked
/// plate, origin anywhere on it, `a` to the right and `b` up as seen facing the plate, and
/// `n` its outward normal (`a, b, n` right-handed). The plate's normal must be the jaws'
/// closing axis, so that "plate coplanar with the facet" means "jaws closing across it".
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GripperModel {
    /// The tracked rectangle's corners `(a, b)`: top-left, top-right, bottom-right,
    /// bottom-left as seen facing the plate (a parallelogram), metres.
    pub plate_corners_m: [[f64; 2]; 4],
    /// Three non-collinear points on the plate whose parallax the servo drives, `(a, b)`, m.
    pub marks_m: [[f64; 2]; 3],
    /// The reference point tracked during calibration (the servo's gripper position), m.
    pub reference_m: [f64; 2],
    /// The tool point (where the jaws close) relative to the reference point, `(a, b, n)`, m.
    /// The simulator's gripper: 0.10 m below the plate centre, 0.056 m behind the plate.
    pub tool_from_reference_m: [f64; 3],
    /// Widest jaw opening, m.
    pub max_opening_m: f64,
    /// Widest grasp the grasp planner accepts (block width between the jaws), m: the
    /// thesis's 50 mm (issue #7). The simulator's jaws open 80 mm, so a wider limit (up to
    /// `max_opening_m` less room for the fingers to close in) is a deliberate choice for a
    /// scene that needs it; the shipped scenarios' blocks all have a face whose grasp is
    /// within 50 mm (BENCHMARKS.md, "Closed loop").
    pub max_grasp_width_m: f64,
    /// Direction of the plate normal in the robot's x-y plane at tool yaw 0 (it turns with
    /// the yaw). The robot turns the tool about the vertical through the tool point; the
    /// servo turns about the plate's reference point, and this converts one into the other.
    pub normal_at_zero_yaw: [f64; 2],
    /// The tracked rectangle is brighter than its surround (a light plate in a dark
    /// border): its tracker then accepts only edges of that sign, so it can never slide onto
    /// the border's outer edge.
    pub plate_bright_inside: bool,
}

impl Default for GripperModel {
    fn default() -> Self {
        Self {
            plate_corners_m: [[-0.021, 0.023], [0.021, 0.023], [0.021, -0.023], [-0.021, -0.023]],
            marks_m: [[-0.016, 0.018], [0.016, 0.018], [0.0, -0.018]],
            reference_m: [0.0, 0.0],
            tool_from_reference_m: [0.0, -0.100, -0.056],
            max_opening_m: 0.080,
            max_grasp_width_m: 0.050,
            normal_at_zero_yaw: [0.0, 1.0],
            plate_bright_inside: true,
        }
    }
}

/// The self-calibration: the cage of points the gripper visits.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CalibrationConfig {
    /// Tool positions to visit, robot frame, metres (>= 4 non-coplanar; the thesis uses the
    /// eight corners of a box, the lower four a few cm above the table).
    pub cage_m: Vec<[f64; 3]>,
    /// Tool speed between cage points, m/s.
    pub speed_mps: f64,
    /// Frames to wait after the arm reports arrival before sampling.
    pub settle_frames: u32,
    /// Frames averaged per cage point.
    pub samples: u32,
    /// Refuse a fit whose RMS residual exceeds this, px.
    pub max_residual_px: f64,
    /// Refuse an epipolar constraint whose RMS residual exceeds this, px.
    pub max_epipolar_px: f64,
    /// Time-out per cage point, s.
    pub point_timeout_s: f64,
    /// Where to put the tool after calibrating (out of the target's way), robot frame, m;
    /// empty = back where it started.
    pub park_m: Vec<f64>,
}

impl Default for CalibrationConfig {
    fn default() -> Self {
        Self {
            cage_m: vec![
                [0.27, -0.10, 0.06],
                [0.45, -0.10, 0.06],
                [0.45, 0.10, 0.06],
                [0.27, 0.10, 0.06],
                [0.27, -0.10, 0.20],
                [0.45, -0.10, 0.20],
                [0.45, 0.10, 0.20],
                [0.27, 0.10, 0.20],
            ],
            speed_mps: 0.10,
            settle_frames: 3,
            samples: 3,
            max_residual_px: 8.0,
            max_epipolar_px: 2.0,
            point_timeout_s: 8.0,
            park_m: Vec::new(),
        }
    }
}

/// Acquiring the gripper by opening and closing the jaws.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AcquireConfig {
    /// Frames to wait, arm and jaws still, before taking each of the open and closed frames.
    pub settle_frames: u32,
    /// Frames the new plate trackers must track before they are trusted.
    pub converge_frames: u32,
    /// Smallest tracker confidence score accepted at the end of the convergence.
    pub min_score: f64,
    /// Smallest plate image a converged plate tracker may have, px² (each view), whatever
    /// the plate's size as found: the least a contour tracker can follow (an 8 x 8 px
    /// plate). Above it, half the area the locator found counts
    /// (`gripper::least_plate_area_px2`).
    pub min_plate_area_px2: f64,
    /// Whole phase time-out, s.
    pub timeout_s: f64,
}

impl Default for AcquireConfig {
    fn default() -> Self {
        Self { settle_frames: 4, converge_frames: 15, min_score: 0.5, min_plate_area_px2: 64.0, timeout_s: 20.0 }
    }
}

/// Acquiring the target from the operator hint.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TargetConfig {
    /// Frames the target trackers must track (arm still) before the servo starts.
    pub converge_frames: u32,
    pub min_score: f64,
    /// Refuse a hint whose corners break the epipolar constraint by more than this (RMS), px.
    pub max_epipolar_px: f64,
    pub timeout_s: f64,
}

impl Default for TargetConfig {
    fn default() -> Self {
        Self { converge_frames: 15, min_score: 0.35, max_epipolar_px: 8.0, timeout_s: 10.0 }
    }
}

/// The plan phase: one stereo pair to the planner, the grasp chosen (thesis ch. 5-6). The
/// groups are flattened: all their keys are in the `[plan]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PlanSettings {
    /// Where the tool waits while the planner looks, robot frame, m: clear of the blocks, the
    /// gripper still in view (its trackers keep running). Empty = where the calibration
    /// parked it.
    pub park_m: Vec<f64>,
    /// Frames the arm must be still before the stereo pair is taken.
    pub settle_frames: u32,
    /// Pairs the plan may look at: a plan that finds no grasp site, or none that settles
    /// whether the pointed block can be grasped, looks again at a fresh pair (another frame's
    /// noise decides many marginal edges), and a refusal is claimed only when two looks refuse
    /// (one when this is 1).
    pub max_looks: u32,
    #[serde(flatten)]
    pub stereo: PlanStereo,
    #[serde(flatten)]
    pub mask: PlanMask,
    #[serde(flatten)]
    pub scene: PlanScene,
    #[serde(flatten)]
    pub grasp: PlanGraspRules,
    /// Time-out of the phase (park, settle, plan), s.
    pub timeout_s: f64,
}

impl Default for PlanSettings {
    fn default() -> Self {
        Self {
            park_m: Vec::new(),
            settle_frames: 5,
            max_looks: 3,
            stereo: PlanStereo::default(),
            mask: PlanMask::default(),
            scene: PlanScene::default(),
            grasp: PlanGraspRules::default(),
            timeout_s: 20.0,
        }
    }
}

/// The point phase (thesis ch. 4, issue 19): without an indicated point the daemon parks the
/// arm out of the operator's way and waits for a pointing gesture.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PointSettings {
    /// Where the tool waits while the operator points, robot frame, m: back towards the
    /// arm's base, where no hand comes from, low enough that the plate stays in view (its
    /// trackers keep running) and behind the hand as the cameras see it. Empty = where the
    /// calibration parked it.
    pub park_m: Vec<f64>,
    /// Frames the arm must be still before the scene without the hand is taken.
    pub settle_frames: u32,
    /// Largest one-sigma radius of an indicated point that is answered, m (a less certain
    /// one is refused as uncertain, and the daemon waits for the next gesture). An answered
    /// point must also pick one block: the plan asks the operator to point again when a
    /// site on another block is within the point's uncertainty (`planning::point_ambiguity`).
    pub max_sigma_m: f64,
    /// Time-out of the whole phase (park, settle, the gestures), s of camera time: the
    /// failure names every gesture seen and why it was refused.
    pub timeout_s: f64,
}

impl Default for PointSettings {
    fn default() -> Self {
        Self { park_m: vec![0.18, 0.0, 0.14], settle_frames: 5, max_sigma_m: 0.015, timeout_s: 90.0 }
    }
}

/// The planner's stereo matching: the epipolar tolerance and the disparity range.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PlanStereo {
    /// Tolerance of the weak epipolar constraint for stereo matches, px.
    pub epipolar_tol_px: f64,
    /// The cage's disparity range is widened by this fraction of it on each side, plus
    /// `disparity_margin_px` (the blocks lie below the cage).
    pub disparity_margin: f64,
    pub disparity_margin_px: f64,
}

impl Default for PlanStereo {
    fn default() -> Self {
        Self { epipolar_tol_px: 3.0, disparity_margin: 0.5, disparity_margin_px: 10.0 }
    }
}

/// The gripper's region masked out of the images before planning.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PlanMask {
    /// The region of the images masked out before planning: this box around the gripper's
    /// reference point (plate centre), in plate axes `a` (along the plate, horizontal), `b`
    /// (up) and `n` (the plate normal, the jaws' closing axis), each `[min, max]`, m,
    /// projected with the calibrated model and widened by `mask_margin_px`. It covers the
    /// plate, the palm and the open fingers of the simulator's gripper.
    pub mask_box_m: [[f64; 2]; 3],
    pub mask_margin_px: f64,
}

impl Default for PlanMask {
    fn default() -> Self {
        Self { mask_box_m: [[-0.035, 0.035], [-0.11, 0.04], [-0.125, 0.012]], mask_margin_px: 6.0 }
    }
}

/// How the planner's features become the grasp scene: what is the arm, what is one object,
/// which missed faces and edges are looked for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PlanScene {
    /// Features whose lowest point is higher than the parked tool point less this are the arm
    /// (it moves away before the grasp), not obstacles, m.
    pub arm_clearance_m: f64,
    /// Hypothesise the vertical faces the planner missed below the front edges of top faces,
    /// down to the table (`grasp.table_z_m`): blocks rest on the table, and a face towards
    /// the cameras under a seen top edge is seen too; the target trackers check it.
    pub hypothesise_front_faces: bool,
    /// When no grasp site is near the indicated point (or only zero-width ones), look in the
    /// images for the rear edge of the top face behind each vertical face there (a line at
    /// the face's top-edge height, 8-55 mm behind it, that both views show as a step), and
    /// plan again: the planner's top faces seen at a grazing angle come out tilted or are
    /// missed.
    pub rear_edges_from_image: bool,
    /// Reconstructed features closer than this in 3-D belong to one object (the thesis's
    /// "3-D connected component"; the planner's own components need a junction seen in both
    /// views), m.
    pub join_m: f64,
}

impl Default for PlanScene {
    fn default() -> Self {
        Self { arm_clearance_m: 0.02, hypothesise_front_faces: true, rear_edges_from_image: true, join_m: 0.004 }
    }
}

/// The grasp planner's gripper model and the rules a candidate grasp site must pass.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct PlanGraspRules {
    /// Finger cross-section of the grasp planner's gripper model: along the closing axis and
    /// along the edge, m.
    pub finger_thickness_m: f64,
    pub finger_breadth_m: f64,
    /// A rear edge pairs with a top edge when they are parallel within this, degrees. The
    /// grasp planner's default is 10°; the facets reconstructed from the simulator's pairs
    /// turn their short far edges by up to ~15° (a 30 mm cube's top face seen end-on).
    pub parallel_tolerance_deg: f64,
    /// The grasped block's own other faces may reach this far past the contact planes
    /// (reconstruction error) before a finger counts as colliding with them, m.
    pub object_tolerance_m: f64,
    /// Facets facing further than this from the cameras in plan view are not grasped: the
    /// plate, normal to the jaws' closing axis, ends up as oblique as the facet (an L-block
    /// face at 55° was servoed to 0.7 mm and 2.2°), degrees.
    pub max_view_angle_deg: f64,
    /// The grasp nearest the indicated point must be this close to it (plan view, grasp
    /// centre), or the block the operator meant has no grasp site and the plan fails (rather
    /// than grasp another block), m.
    pub max_site_distance_m: f64,
    /// A *pointed* point picks the block of the nearest site only if it lies this many of
    /// its sigmas from the bisector between that site and each site on another object (the
    /// point may be this many sigmas off: it has missed by up to three on rendered gestures);
    /// else the operator is asked to point again. A point given as a coordinate is never
    /// questioned.
    pub point_ambiguity_sigmas: f64,
}

impl Default for PlanGraspRules {
    fn default() -> Self {
        Self {
            finger_thickness_m: 0.012,
            finger_breadth_m: 0.020,
            parallel_tolerance_deg: 15.0,
            object_tolerance_m: 0.008,
            max_view_angle_deg: 60.0,
            max_site_distance_m: 0.06,
            point_ambiguity_sigmas: 3.0,
        }
    }
}

/// The coplanarity servo (see `handeye_vision::servo`). The groups are flattened: all their
/// keys are in the `[servo]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ServoSettings {
    #[serde(flatten)]
    pub control: ServoControl,
    #[serde(flatten)]
    pub limits: ServoLimits,
    #[serde(flatten)]
    pub convergence: ServoConvergence,
    /// Frames to wait after the arm arrives before measuring again.
    pub settle_frames: u32,
    /// Tool speed of servo moves, m/s.
    pub speed_mps: f64,
    #[serde(flatten)]
    pub approach: ServoApproach,
}

impl Default for ServoSettings {
    fn default() -> Self {
        Self {
            control: ServoControl::default(),
            limits: ServoLimits::default(),
            convergence: ServoConvergence::default(),
            settle_frames: 2,
            speed_mps: 0.08,
            approach: ServoApproach::default(),
        }
    }
}

/// The servo's control law: gain, Jacobian update and the weighting of its error.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ServoControl {
    pub gain: f64,
    /// Refine the Jacobian online (Broyden).
    pub broyden: bool,
    /// Length that turns yaw into a distance for the servo's step metric, m: about the
    /// distance of the marks from the reference point.
    pub yaw_lever_m: f64,
    /// Smallest accepted condition of the weighted Jacobian (see `ServoConfig`).
    pub min_condition: f64,
    /// Weight of the in-plane angle error ρ against the marks' parallaxes (see
    /// `ServoConfig::angle_weight`); 0 = yaw from the parallaxes alone.
    pub angle_weight: f64,
}

impl Default for ServoControl {
    fn default() -> Self {
        Self { gain: 0.5, broyden: false, yaw_lever_m: 0.025, min_condition: 0.02, angle_weight: 1.0 }
    }
}

/// The servo's limits: the largest step, and how far a mark's parallax may leave the
/// epipolar direction before a tracker counts as wrong.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ServoLimits {
    pub max_step_m: f64,
    pub max_yaw_step_deg: f64,
    /// A gripper mark's parallax may leave the epipolar direction by this much, px (plus
    /// `max_across_ratio` of its length) before the servo calls a tracker wrong. The facet's
    /// plane transfer is extrapolated a few facet heights up to the plate. Measured over 80
    /// servoed runs (BENCHMARKS, issue 19 ninth pass) it leaves 0.5-4 px across the epipolar
    /// lines on all but three (clutter3 121 and 127: 6-11 px; point_clutter3 35: 20 px, its
    /// target a hypothesised face).
    pub max_across_px: f64,
    pub max_across_ratio: f64,
}

impl Default for ServoLimits {
    fn default() -> Self {
        Self { max_step_m: 0.03, max_yaw_step_deg: 8.0, max_across_px: 25.0, max_across_ratio: 0.3 }
    }
}

/// When the servo has converged, and when it gives up.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ServoConvergence {
    pub converged_m: f64,
    pub converged_deg: f64,
    pub converged_steps: u32,
    pub max_steps: u32,
    pub timeout_s: f64,
}

impl Default for ServoConvergence {
    fn default() -> Self {
        Self { converged_m: 0.0005, converged_deg: 0.3, converged_steps: 3, max_steps: 60, timeout_s: 90.0 }
    }
}

/// Where the servo works relative to the grasp: the local cage, the standoff and the grasp
/// height.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ServoApproach {
    /// Height of the tool point above the table (`grasp.table_z_m`) at the grasp, m.
    pub grasp_height_m: f64,
    /// Size of the local cage visited around the coarse approach pose, m: 7 points, the
    /// pose, ±this along x and y, and this and twice this above (never below: the jaws hang
    /// over the block there). A local affine model there takes out the perspective error of
    /// the global one (the global model's image scale is that of the cage, ~10 % off near
    /// the target). 0 = skip.
    pub local_cage_m: f64,
    /// The servo's goal is this far above the grasp pose (the open-loop approach comes down
    /// by it), m.
    pub standoff_above_m: f64,
}

impl Default for ServoApproach {
    fn default() -> Self {
        Self { grasp_height_m: 0.010, local_cage_m: 0.03, standoff_above_m: 0.06 }
    }
}

/// The open-loop grasp and lift.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GraspConfig {
    /// Height of the table top in robot coordinates, m (measured like the cage): the grasp
    /// comes down to `servo.grasp_height_m` above it by the robot's own kinematics.
    pub table_z_m: f64,
    pub approach_speed_mps: f64,
    /// Time the jaws get to close and settle, s.
    pub close_s: f64,
    pub lift_m: f64,
    pub lift_speed_mps: f64,
    /// Jaws closer than this after closing hold nothing, m.
    pub min_grip_width_m: f64,
    pub timeout_s: f64,
}

impl Default for GraspConfig {
    fn default() -> Self {
        Self { table_z_m: 0.0, approach_speed_mps: 0.04, close_s: 0.8, lift_m: 0.07, lift_speed_mps: 0.05, min_grip_width_m: 0.005, timeout_s: 20.0 }
    }
}

/// What makes the daemon stop the arm.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyConfig {
    /// The tool must stay inside this box, robot frame, m (a reading outside makes no sense).
    pub workspace_min_m: [f64; 3],
    pub workspace_max_m: [f64; 3],
    /// Largest believable tool jump between two consecutive state readings, m.
    pub max_state_jump_m: f64,
    /// Stop when no robot state arrives for this long, ms of camera time (the frames'
    /// capture stamps). Replaces `state_stale_frames` (6 frames at 30 Hz = 200 ms).
    pub state_stale_ms: u64,
    /// In phases that need a tracker, a confidence score below this counts as lost.
    pub min_tracker_score: f64,
    /// The same for the target trackers. Lower: a block face 25-30 mm across is ~30 px,
    /// and one of its sides often has little contrast with the neighbouring face (0.5-0.6
    /// while tracking well); a face hidden or lost drops far below it, or the tracker
    /// reports itself lost.
    pub min_target_score: f64,
    /// How long the arm holds while a lost tracker (any phase that needs one) is searched
    /// for before the run fails naming it, s of camera time (`daemon/src/recovery.rs`). 0:
    /// never hold, a lost tracker stops the run at once. Time held does not count against
    /// the phase's own time-out.
    pub loss_patience_s: f64,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        Self {
            workspace_min_m: [-0.8, -0.8, -0.01],
            workspace_max_m: [0.8, 0.8, 0.8],
            max_state_jump_m: 0.05,
            state_stale_ms: 200,
            min_tracker_score: 0.6,
            min_target_score: 0.45,
            loss_patience_s: 8.0,
        }
    }
}

/// Tracker settings the daemon overrides (the rest are `TrackerConfig`'s defaults).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackerSettings {
    pub points: usize,
    pub search_px: f64,
    pub min_contrast: i32,
    /// Let the contours follow perspective (a homography) instead of an affine map (A.2).
    /// On by default: the affine contour on the small, low-contrast cube face collapsed
    /// while the arm moved nearby; the servo takes the local affine frame at the centre.
    pub projective: bool,
    /// Velocity gain of the target contours' shape prediction. 0 by default: the target
    /// stands still, and a face edge with almost no contrast against the table (the cube's
    /// front face in `pick_cube`) otherwise drifts away at the speed the filter once saw.
    pub target_deformation_velocity_gain: f64,
    /// Search passes per update: 2 (a wide search, then a short refinement) is the robust
    /// default; 1 costs about two thirds as much but loses or misplaces a real face from
    /// perturbed starts far more often (`TrackerConfig::passes`; BENCHMARKS.md, Tracker).
    pub passes: usize,
    /// Half-length of the refinement pass's search, px.
    pub refine_search_px: f64,
    /// Search the short range first and skip the wide pass when that moves no corner this
    /// far, px (0 = never, the default): about half the cost, far less robust
    /// (`TrackerConfig::short_first_px`).
    pub short_first_px: f64,
}

impl Default for TrackerSettings {
    fn default() -> Self {
        let base = handeye_vision::tracker::TrackerConfig::default();
        Self {
            points: 100,
            search_px: 12.0,
            min_contrast: 12,
            projective: true,
            target_deformation_velocity_gain: 0.0,
            passes: base.passes,
            refine_search_px: base.refine_search_px,
            short_first_px: base.short_first_px,
        }
    }
}

impl DaemonConfig {
    /// `[point]`: the point phase's settings.
    pub fn point(&self) -> &PointSettings {
        &self.point
    }

    pub fn point_mut(&mut self) -> &mut PointSettings {
        &mut self.point
    }

    /// The configuration of the plate's contours.
    pub fn plate_tracker_config(&self) -> handeye_vision::tracker::TrackerConfig {
        let base = self.tracker.tracker_config();
        if self.gripper.plate_bright_inside {
            handeye_vision::tracker::TrackerConfig {
                edge_sign: handeye_vision::tracker::EdgeSign::Fixed(handeye_vision::tracker::Polarity::BrightInside),
                ..base
            }
        } else {
            base
        }
    }
}

impl TrackerSettings {
    /// The configuration of the target's contours.
    pub fn target_tracker_config(&self) -> handeye_vision::tracker::TrackerConfig {
        // The target stands still before still cameras: the plan's shape is its shape, and
        // a wrong-lock rival must be one the contour bent away from it to slide off.
        handeye_vision::tracker::TrackerConfig {
            deformation_velocity_gain: self.target_deformation_velocity_gain,
            shape_is_fixed: true,
            ..self.tracker_config()
        }
    }

    pub fn tracker_config(&self) -> handeye_vision::tracker::TrackerConfig {
        handeye_vision::tracker::TrackerConfig {
            points: self.points,
            search_px: self.search_px,
            min_contrast: self.min_contrast,
            passes: self.passes,
            refine_search_px: self.refine_search_px,
            short_first_px: self.short_first_px,
            model: if self.projective {
                handeye_vision::tracker::DeformationModel::Projective
            } else {
                handeye_vision::tracker::DeformationModel::NormalOnly
            },
            ..Default::default()
        }
    }
}

impl DaemonConfig {
    /// Reads and checks a file.
    pub fn load(path: &Path) -> Result<Self, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read { file: path.to_path_buf(), source })?;
        Self::parse(&text, path)
    }

    /// Parses and checks TOML text; `file` names it in errors.
    pub fn parse(text: &str, file: &Path) -> Result<Self, ConfigError> {
        let parse_error = |message: String| ConfigError::Parse { file: file.to_path_buf(), message };
        let table: toml::Table = toml::from_str(text).map_err(|e| parse_error(e.to_string()))?;
        if let Some((old, new)) = renamed_key(&table) {
            return Err(parse_error(format!("{old} is no longer read: set {new} instead")));
        }
        if let Some(key) = unknown_key(&table, &Self::known_keys(), "") {
            return Err(parse_error(format!("unknown key {key}")));
        }
        let cfg: Self = toml::from_str(text).map_err(|e| match bad_value(&table) {
            // A value of the wrong type in a flattened group is reported at its table, not
            // its key: name the key.
            Some((key, reason)) => parse_error(format!("{key}: {reason}")),
            None => parse_error(e.to_string()),
        })?;
        cfg.validate(file)?;
        Ok(cfg)
    }

    /// Every key a file may set, as the default configuration's TOML table: every key has a
    /// default and every default serialises (the `Vec` fields as arrays, possibly empty; no
    /// field is an `Option`), so the table holds each known key at its place.
    fn known_keys() -> toml::Table {
        toml::Table::try_from(Self::default()).expect("the default configuration serialises to a TOML table")
    }

    /// The configuration as TOML (what `handeye run` writes for the daemon).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_default()
    }

    /// Checks every value; the error names the first bad field.
    pub fn validate(&self, file: &Path) -> Result<(), ConfigError> {
        let bad = |field: &'static str, value: String, expected: &'static str| {
            Err(ConfigError::Invalid { file: file.to_path_buf(), field, value, expected })
        };
        let pos = |x: f64| x.is_finite() && x > 0.0;
        if !pos(self.timing.frame_rate_hz) {
            return bad("frame_rate_hz", self.timing.frame_rate_hz.to_string(), "> 0");
        }
        if self.timing.stale_frame_ms == 0 {
            return bad("stale_frame_ms", "0".into(), ">= 1");
        }
        for (field, v) in [
            ("start_timeout_s", self.timing.start_timeout_s),
            ("calibration.speed_mps", self.calibration.speed_mps),
            ("calibration.max_residual_px", self.calibration.max_residual_px),
            ("calibration.max_epipolar_px", self.calibration.max_epipolar_px),
            ("calibration.point_timeout_s", self.calibration.point_timeout_s),
            ("acquire.timeout_s", self.acquire.timeout_s),
            ("target.timeout_s", self.target.timeout_s),
            ("plan.timeout_s", self.plan.timeout_s),
            ("point.timeout_s", self.point.timeout_s),
            ("point.max_sigma_m", self.point.max_sigma_m),
            ("plan.epipolar_tol_px", self.plan.stereo.epipolar_tol_px),
            ("plan.finger_thickness_m", self.plan.grasp.finger_thickness_m),
            ("plan.finger_breadth_m", self.plan.grasp.finger_breadth_m),
            ("gripper.max_grasp_width_m", self.gripper.max_grasp_width_m),
            ("plan.max_view_angle_deg", self.plan.grasp.max_view_angle_deg),
            ("plan.parallel_tolerance_deg", self.plan.grasp.parallel_tolerance_deg),
            ("plan.max_site_distance_m", self.plan.grasp.max_site_distance_m),
            ("plan.point_ambiguity_sigmas", self.plan.grasp.point_ambiguity_sigmas),
            ("servo.max_step_m", self.servo.limits.max_step_m),
            ("servo.speed_mps", self.servo.speed_mps),
            ("servo.timeout_s", self.servo.convergence.timeout_s),
            ("grasp.approach_speed_mps", self.grasp.approach_speed_mps),
            ("grasp.lift_speed_mps", self.grasp.lift_speed_mps),
            ("grasp.timeout_s", self.grasp.timeout_s),
            ("gripper.max_opening_m", self.gripper.max_opening_m),
            ("safety.max_state_jump_m", self.safety.max_state_jump_m),
        ] {
            if !pos(v) {
                return bad(field, v.to_string(), "a finite number > 0");
            }
        }
        if !(self.safety.loss_patience_s.is_finite() && self.safety.loss_patience_s >= 0.0) {
            return bad("safety.loss_patience_s", self.safety.loss_patience_s.to_string(), "a finite number >= 0 (0: never hold)");
        }
        if !(self.timing.done_hold_s.is_finite() && self.timing.done_hold_s >= 0.0) {
            return bad("done_hold_s", self.timing.done_hold_s.to_string(), ">= 0");
        }
        if !(self.servo.control.gain > 0.0 && self.servo.control.gain < 1.0) {
            return bad("servo.gain", self.servo.control.gain.to_string(), "0 < gain < 1");
        }
        if self.calibration.cage_m.len() < 4 {
            return bad("calibration.cage_m", format!("{} points", self.calibration.cage_m.len()), "at least 4 non-coplanar points");
        }
        if self.calibration.cage_m.iter().flatten().any(|v| !v.is_finite()) {
            return bad("calibration.cage_m", "non-finite".into(), "finite coordinates");
        }
        if !(self.calibration.park_m.is_empty() || self.calibration.park_m.len() == 3) {
            return bad("calibration.park_m", format!("{:?}", self.calibration.park_m), "empty or [x, y, z]");
        }
        if !(1..=10).contains(&self.plan.max_looks) {
            return bad("plan.max_looks", self.plan.max_looks.to_string(), "1 (one pair) to 10 pairs");
        }
        if !(self.plan.park_m.is_empty() || self.plan.park_m.len() == 3) {
            return bad("plan.park_m", format!("{:?}", self.plan.park_m), "empty or [x, y, z]");
        }
        if !(self.point.park_m.is_empty() || self.point.park_m.len() == 3) || self.point.park_m.iter().any(|v| !v.is_finite()) {
            return bad("point.park_m", format!("{:?}", self.point.park_m), "empty or [x, y, z], finite");
        }
        if self.plan.mask.mask_box_m.iter().flatten().any(|v| !v.is_finite()) || self.plan.mask.mask_box_m.iter().any(|r| r[0] > r[1]) {
            return bad("plan.mask_box_m", format!("{:?}", self.plan.mask.mask_box_m), "three finite [min, max] ranges");
        }
        for (field, v) in [
            ("plan.disparity_margin", self.plan.stereo.disparity_margin),
            ("plan.disparity_margin_px", self.plan.stereo.disparity_margin_px),
            ("plan.mask_margin_px", self.plan.mask.mask_margin_px),
            ("plan.arm_clearance_m", self.plan.scene.arm_clearance_m),
            ("plan.object_tolerance_m", self.plan.grasp.object_tolerance_m),
            ("plan.join_m", self.plan.scene.join_m),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return bad(field, v.to_string(), "a finite number >= 0");
            }
        }
        if self.calibration.samples == 0 {
            return bad("calibration.samples", "0".into(), ">= 1");
        }
        let g = &self.gripper;
        let c = &g.plate_corners_m;
        let area = (c[1][0] - c[0][0]) * (c[3][1] - c[0][1]) - (c[1][1] - c[0][1]) * (c[3][0] - c[0][0]);
        if !area.is_finite() || area.abs() < 1e-6 {
            return bad("gripper.plate_corners_m", format!("{c:?}"), "a parallelogram of at least 1 cm²");
        }
        let m = &g.marks_m;
        let marks_area = (m[1][0] - m[0][0]) * (m[2][1] - m[0][1]) - (m[1][1] - m[0][1]) * (m[2][0] - m[0][0]);
        if !marks_area.is_finite() || marks_area.abs() < 1e-5 {
            return bad("gripper.marks_m", format!("{m:?}"), "three non-collinear points spread over the plate");
        }
        if g.tool_from_reference_m.iter().chain(&g.reference_m).any(|v| !v.is_finite()) {
            return bad("gripper.tool_from_reference_m", format!("{:?}", g.tool_from_reference_m), "finite");
        }
        if g.max_grasp_width_m > g.max_opening_m {
            return bad("gripper.max_grasp_width_m", g.max_grasp_width_m.to_string(), "at most gripper.max_opening_m (the jaws must open past the block)");
        }
        if !(1..=16).contains(&self.servo.convergence.converged_steps) {
            return bad("servo.converged_steps", self.servo.convergence.converged_steps.to_string(), "1..=16");
        }
        if self.servo.convergence.max_steps == 0 {
            return bad("servo.max_steps", "0".into(), ">= 1");
        }
        if !(self.servo.control.angle_weight.is_finite() && self.servo.control.angle_weight >= 0.0) {
            return bad("servo.angle_weight", self.servo.control.angle_weight.to_string(), ">= 0");
        }
        if !(self.servo.approach.local_cage_m.is_finite() && self.servo.approach.local_cage_m >= 0.0) {
            return bad("servo.local_cage_m", self.servo.approach.local_cage_m.to_string(), ">= 0 (0 = no local cage)");
        }
        if !(self.servo.approach.standoff_above_m.is_finite() && self.servo.approach.standoff_above_m >= 0.0) {
            return bad("servo.standoff_above_m", self.servo.approach.standoff_above_m.to_string(), ">= 0");
        }
        if let Err(e) = self.tracker.tracker_config().validate().and_then(|_| self.tracker.target_tracker_config().validate()) {
            // The daemon's names for the settings it exposes.
            let field = match e.field {
                "points" => "tracker.points",
                "search_px" => "tracker.search_px",
                "min_contrast" => "tracker.min_contrast",
                "passes" => "tracker.passes",
                "refine_search_px" => "tracker.refine_search_px",
                "short_first_px" => "tracker.short_first_px",
                "deformation_velocity_gain" => "tracker.target_deformation_velocity_gain",
                _ => "tracker",
            };
            return Err(ConfigError::Invalid { file: file.to_path_buf(), field, value: e.value.to_string(), expected: e.expected });
        }
        if (0..3).any(|i| self.safety.workspace_min_m[i] >= self.safety.workspace_max_m[i]) {
            return bad("safety.workspace_min_m", format!("{:?}", self.safety.workspace_min_m), "below workspace_max_m on every axis");
        }
        Ok(())
    }
}

/// Keys that counted frames at `frame_rate_hz` and now are camera time: (old, new).
const RENAMED: [(&str, &str, &str); 1] = [("safety", "state_stale_frames", "safety.state_stale_ms (milliseconds of camera time)")];

/// The first renamed key a file still sets, with what replaces it.
fn renamed_key(table: &toml::Table) -> Option<(String, &'static str)> {
    RENAMED.iter().find_map(|&(group, key, new)| {
        table.get(group).and_then(toml::Value::as_table).filter(|t| t.contains_key(key)).map(|_| (format!("{group}.{key}"), new))
    })
}

/// The first key of `table` (a file's) that `known` lacks, as a dotted path (`servo.gian`).
/// The groups are flattened into their tables, so serde's `deny_unknown_fields` cannot be
/// used; this check takes its place before the file is deserialised. Tables are compared
/// key by key; a value that is no table in `known` is a leaf (its type is serde's to check).
fn unknown_key(table: &toml::Table, known: &toml::Table, prefix: &str) -> Option<String> {
    table.iter().find_map(|(key, value)| {
        let path = if prefix.is_empty() { key.clone() } else { format!("{prefix}.{key}") };
        match (value, known.get(key)) {
            (_, None) => Some(path),
            (toml::Value::Table(inner), Some(toml::Value::Table(known_inner))) => unknown_key(inner, known_inner, &path),
            _ => None,
        }
    })
}

/// The first key of a file's table whose value cannot be read (wrong type, out of its type's
/// range), with serde's reason: each key is read alone (every other key has a default).
fn bad_value(table: &toml::Table) -> Option<(String, String)> {
    fn leaves<'a>(table: &'a toml::Table, prefix: &[&'a str], out: &mut Vec<(Vec<&'a str>, &'a toml::Value)>) {
        for (key, value) in table {
            let mut path = prefix.to_vec();
            path.push(key);
            match value {
                toml::Value::Table(inner) => leaves(inner, &path, out),
                _ => out.push((path, value)),
            }
        }
    }
    let mut all = Vec::new();
    leaves(table, &[], &mut all);
    all.into_iter().find_map(|(path, value)| {
        let (last, tables) = path.split_last()?;
        let mut alone = toml::Table::new();
        alone.insert((*last).to_string(), value.clone());
        for key in tables.iter().rev() {
            let mut outer = toml::Table::new();
            outer.insert((*key).to_string(), toml::Value::Table(alone));
            alone = outer;
        }
        toml::Value::Table(alone).try_into::<DaemonConfig>().err().map(|e| (path.join("."), e.message().trim().to_string()))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_round_trip_through_toml() {
        let cfg = DaemonConfig::default();
        cfg.validate(Path::new("x")).unwrap();
        let back = DaemonConfig::parse(&cfg.to_toml(), Path::new("x")).unwrap();
        assert_eq!(back, cfg);
    }

    /// The dotted paths of every key in a TOML text, sorted.
    fn key_paths(text: &str) -> Vec<String> {
        fn walk(table: &toml::Table, prefix: &str, out: &mut Vec<String>) {
            for (key, value) in table {
                let path = if prefix.is_empty() { key.clone() } else { format!("{prefix}.{key}") };
                match value {
                    toml::Value::Table(inner) => walk(inner, &path, out),
                    _ => out.push(path),
                }
            }
        }
        let mut out = Vec::new();
        walk(&toml::from_str(text).unwrap(), "", &mut out);
        out.sort();
        out
    }

    #[test]
    fn the_written_file_keeps_its_keys_and_tables() {
        // `DaemonConfig::default().to_toml()`'s keys before the groups were flattened into
        // their tables: a user's file, and `handeye run`'s, must keep meaning the same.
        let mut before = vec![
            "frame_rate_hz",
            "deadline_us",
            "stale_frame_ms",
            "start_timeout_s",
            "done_hold_s",
            "worker_wait_ms",
            "gripper.plate_corners_m",
            "gripper.marks_m",
            "gripper.reference_m",
            "gripper.tool_from_reference_m",
            "gripper.max_opening_m",
            "gripper.max_grasp_width_m",
            "gripper.normal_at_zero_yaw",
            "gripper.plate_bright_inside",
            "calibration.cage_m",
            "calibration.speed_mps",
            "calibration.settle_frames",
            "calibration.samples",
            "calibration.max_residual_px",
            "calibration.max_epipolar_px",
            "calibration.point_timeout_s",
            "calibration.park_m",
            "acquire.settle_frames",
            "acquire.converge_frames",
            "acquire.min_score",
            "acquire.min_plate_area_px2",
            "acquire.timeout_s",
            "target.converge_frames",
            "target.min_score",
            "target.max_epipolar_px",
            "target.timeout_s",
            "plan.park_m",
            "plan.settle_frames",
            "plan.max_looks",
            "plan.epipolar_tol_px",
            "plan.disparity_margin",
            "plan.disparity_margin_px",
            "plan.mask_box_m",
            "plan.mask_margin_px",
            "plan.arm_clearance_m",
            "plan.finger_thickness_m",
            "plan.finger_breadth_m",
            "plan.parallel_tolerance_deg",
            "plan.object_tolerance_m",
            "plan.max_view_angle_deg",
            "plan.hypothesise_front_faces",
            "plan.rear_edges_from_image",
            "plan.join_m",
            "plan.max_site_distance_m",
            "plan.point_ambiguity_sigmas",
            "plan.timeout_s",
            "point.park_m",
            "point.settle_frames",
            "point.max_sigma_m",
            "point.timeout_s",
            "servo.gain",
            "servo.max_step_m",
            "servo.max_yaw_step_deg",
            "servo.converged_m",
            "servo.converged_deg",
            "servo.converged_steps",
            "servo.max_steps",
            "servo.broyden",
            "servo.max_across_px",
            "servo.max_across_ratio",
            "servo.yaw_lever_m",
            "servo.min_condition",
            "servo.angle_weight",
            "servo.settle_frames",
            "servo.speed_mps",
            "servo.grasp_height_m",
            "servo.local_cage_m",
            "servo.standoff_above_m",
            "servo.timeout_s",
            "grasp.table_z_m",
            "grasp.approach_speed_mps",
            "grasp.close_s",
            "grasp.lift_m",
            "grasp.lift_speed_mps",
            "grasp.min_grip_width_m",
            "grasp.timeout_s",
            "safety.workspace_min_m",
            "safety.workspace_max_m",
            "safety.max_state_jump_m",
            "safety.state_stale_ms",
            "safety.min_tracker_score",
            "safety.min_target_score",
            "safety.loss_patience_s",
            "tracker.points",
            "tracker.search_px",
            "tracker.min_contrast",
            "tracker.projective",
            "tracker.target_deformation_velocity_gain",
            "tracker.passes",
            "tracker.refine_search_px",
            "tracker.short_first_px",
        ];
        before.sort();
        assert_eq!(key_paths(&DaemonConfig::default().to_toml()), before);
    }

    #[test]
    fn a_changed_file_round_trips_through_every_group() {
        let mut cfg = DaemonConfig::default();
        cfg.timing.done_hold_s = 1.5;
        cfg.plan.park_m = vec![0.3, 0.0, 0.2];
        cfg.plan.stereo.disparity_margin_px = 12.0;
        cfg.plan.mask.mask_margin_px = 4.0;
        cfg.plan.scene.rear_edges_from_image = false;
        cfg.plan.grasp.max_site_distance_m = 0.05;
        cfg.servo.control.gain = 0.4;
        cfg.servo.limits.max_across_px = 20.0;
        cfg.servo.convergence.max_steps = 40;
        cfg.servo.approach.local_cage_m = 0.0;
        let back = DaemonConfig::parse(&cfg.to_toml(), Path::new("x")).unwrap();
        assert_eq!(back, cfg);
        // The flattened keys are read from their table.
        let cfg = DaemonConfig::parse("deadline_us = 2000\n[plan]\njoin_m = 0.006\n[servo]\nconverged_steps = 4\nspeed_mps = 0.05\n", Path::new("x")).unwrap();
        assert_eq!((cfg.timing.deadline_us, cfg.plan.scene.join_m), (2000, 0.006));
        assert_eq!((cfg.servo.convergence.converged_steps, cfg.servo.speed_mps), (4, 0.05));
        assert_eq!(cfg.servo.control.gain, DaemonConfig::default().servo.control.gain);
    }

    #[test]
    fn an_unknown_key_is_an_error_that_names_it_and_the_file() {
        for (text, key) in [
            ("[servo]\nconverged_mm = 0.5\n", "servo.converged_mm"),
            ("[servo]\ngain = 0.4\ngian = 0.4\n", "servo.gian"),
            ("[plan]\nmask_box = [[0.0, 1.0]]\n", "plan.mask_box"),
            ("frame_rate = 30.0\n", "frame_rate"),
            ("[gripper]\nmax_grip_m = 0.05\n", "gripper.max_grip_m"),
            ("[servo.control]\ngain = 0.4\n", "servo.control"),
            ("[timing]\nframe_rate_hz = 30.0\n", "timing"),
            ("[vision]\n", "vision"),
        ] {
            let err = DaemonConfig::parse(text, Path::new("my.toml")).unwrap_err().to_string();
            assert!(err.contains("my.toml") && err.contains(&format!("unknown key {key}")), "{text:?}: {err}");
        }
        // A value of the wrong type is named by its key, in a flattened group too.
        for (text, key) in [
            ("[servo]\nsettle_frames = 2\ngain = \"x\"\n", "servo.gain"),
            ("[plan]\njoin_m = true\n", "plan.join_m"),
            ("deadline_us = 10\nframe_rate_hz = \"fast\"\n[servo]\ngain = 0.4\n", "frame_rate_hz"),
            ("[gripper]\nmax_opening_m = \"x\"\n", "gripper.max_opening_m"),
            ("[servo]\nmax_steps = -1\n", "servo.max_steps"),
        ] {
            let err = DaemonConfig::parse(text, Path::new("my.toml")).unwrap_err().to_string();
            assert!(err.contains("my.toml") && err.contains(&format!("{key}: ")), "{text:?}: {err}");
        }
        // A key that counted frames names the key that replaced it.
        let err = DaemonConfig::parse("[safety]\nstate_stale_frames = 6\n", Path::new("my.toml")).unwrap_err().to_string();
        assert!(err.contains("my.toml") && err.contains("safety.state_stale_frames") && err.contains("safety.state_stale_ms"), "{err}");
        // A key that is a table's name used as a value is a type error, not an unknown key.
        assert!(DaemonConfig::parse("servo = 1\n", Path::new("my.toml")).is_err());
    }

    #[test]
    fn bad_values_name_the_file_and_field() {
        let err = DaemonConfig::parse("[servo]\ngain = 1.5\n", Path::new("my.toml")).unwrap_err().to_string();
        assert!(err.contains("my.toml") && err.contains("servo.gain"), "{err}");
        let err = DaemonConfig::parse("[calibration]\ncage_m = [[0.1, 0.2, 0.3]]\n", Path::new("c.toml")).unwrap_err().to_string();
        assert!(err.contains("calibration.cage_m"), "{err}");
        let err = DaemonConfig::parse("[gripper]\nmarks_m = [[0.0, 0.0], [0.01, 0.0], [0.02, 0.0]]\n", Path::new("g.toml"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("gripper.marks_m"), "{err}");
        // The grasp width limit is the gripper's: 50 mm unless set, never past the jaws.
        assert_eq!(DaemonConfig::default().gripper.max_grasp_width_m, 0.050);
        let wide = DaemonConfig::parse("[gripper]\nmax_grasp_width_m = 0.064\n", Path::new("w.toml")).unwrap();
        assert_eq!(wide.gripper.max_grasp_width_m, 0.064);
        let err = DaemonConfig::parse("[gripper]\nmax_grasp_width_m = 0.09\n", Path::new("w.toml")).unwrap_err().to_string();
        assert!(err.contains("w.toml") && err.contains("gripper.max_grasp_width_m"), "{err}");
        let err = DaemonConfig::parse("frame_rate_hz = \"fast\"\n", Path::new("f.toml")).unwrap_err().to_string();
        assert!(err.contains("f.toml") && err.contains("frame_rate_hz"), "{err}");
        // Tracker settings are named as the daemon's file names them, with the valid range.
        let err = DaemonConfig::parse("[tracker]\npasses = 0\n", Path::new("t.toml")).unwrap_err().to_string();
        assert!(err.contains("t.toml") && err.contains("tracker.passes") && err.contains("1..=8"), "{err}");
        let err = DaemonConfig::parse("[tracker]\nrefine_search_px = 0.5\n", Path::new("t.toml")).unwrap_err().to_string();
        assert!(err.contains("tracker.refine_search_px"), "{err}");
        let err = DaemonConfig::parse("[safety]\nloss_patience_s = -1.0\n", Path::new("s.toml")).unwrap_err().to_string();
        assert!(err.contains("s.toml") && err.contains("safety.loss_patience_s") && err.contains(">= 0"), "{err}");
    }

    #[test]
    fn tracker_speed_settings_reach_every_contour() {
        let cfg = DaemonConfig::parse("[tracker]\npasses = 1\nshort_first_px = 0.5\nrefine_search_px = 3.0\n", Path::new("t.toml")).unwrap();
        for t in [cfg.plate_tracker_config(), cfg.tracker.target_tracker_config()] {
            assert_eq!((t.passes, t.short_first_px, t.refine_search_px), (1, 0.5, 3.0));
        }
        // Unset, they are the tracker's own defaults.
        let d = DaemonConfig::default().tracker.tracker_config();
        let base = handeye_vision::tracker::TrackerConfig::default();
        assert_eq!((d.passes, d.short_first_px, d.refine_search_px), (base.passes, base.short_first_px, base.refine_search_px));
    }
}
