//! Closed-loop tests in the geometry of the daemon's pick scenarios (`scenarios/pick_*.toml`):
//! the same two perspective cameras 1.55 m away, the same calibration cage, the daemon's
//! gripper (plate marks, reference point 100 mm above and 56 mm in front of the tool point)
//! and its servo plan: a goal held in the facet's frame ([`FacetGoal`]), 140 mm above a small
//! facet, turned into image terms at every step with the target frames averaged since the
//! last step, the height from the robot's kinematics, a local model from a 3 cm cage around
//! the approach pose. The facet's corners are seen with per-frame noise (and optionally a
//! fixed bias), as a contour tracker reports them; the robot makes every move exactly.

use nalgebra::{Matrix2, Vector2, Vector3};

use super::testcam::{fit_frame, PinholeCamera, Rig};
use crate::rng::SplitMix64;
use super::*;
use crate::affine::AffineStereo;

fn rig() -> Rig {
    let look_at = Vector3::new(0.35, 0.0, 0.16);
    Rig {
        left: PinholeCamera::look_at(Vector3::new(1.695, -0.241, 0.9), look_at, 1800.0),
        right: PinholeCamera::look_at(Vector3::new(1.695, 0.241, 0.9), look_at, 1800.0),
    }
}

const CAGE: [[f64; 3]; 8] = [
    [0.27, -0.10, 0.06],
    [0.45, -0.10, 0.06],
    [0.45, 0.10, 0.06],
    [0.27, 0.10, 0.06],
    [0.27, -0.10, 0.20],
    [0.45, -0.10, 0.20],
    [0.45, 0.10, 0.20],
    [0.27, 0.10, 0.20],
];
/// The daemon's default gripper: marks in plate coordinates `(a, b)` from the reference
/// point (the plate centre), and the tool point relative to it `(a, b, n)`.
const MARKS_AB: [[f64; 2]; 3] = [[-0.016, 0.018], [0.016, 0.018], [0.0, -0.018]];
const TOOL_FROM_REF: [f64; 3] = [0.0, -0.100, -0.056];
/// Tool height at the goal (the daemon's grasp height + stand-off), m.
const TOOL_Z_GOAL: f64 = 0.070;
const CALIBRATION_YAW_RAD: f64 = -std::f64::consts::FRAC_PI_2;

/// Tool pose: position and yaw; the plate normal is `(−sin ψ, cos ψ, 0)`.
#[derive(Debug, Clone, Copy)]
struct Pose {
    tool: Vector3<f64>,
    yaw: f64,
}

impl Pose {
    fn n(&self) -> Vector3<f64> {
        Vector3::new(-self.yaw.sin(), self.yaw.cos(), 0.0)
    }
    fn a(&self) -> Vector3<f64> {
        Vector3::z().cross(&self.n())
    }
    fn lever(&self) -> Vector3<f64> {
        let t = TOOL_FROM_REF;
        self.a() * t[0] + Vector3::z() * t[1] + self.n() * t[2]
    }
    fn reference(&self) -> Vector3<f64> {
        self.tool - self.lever()
    }
    fn plate(&self, ab: [f64; 2]) -> Vector3<f64> {
        self.reference() + self.a() * ab[0] + Vector3::z() * ab[1]
    }
    /// The servo's motion: the reference point translated, the yaw turned about it.
    fn apply(&mut self, m: &ToolMotion) {
        let r = self.reference() + m.translation_m;
        self.yaw += m.yaw_rad;
        self.tool = r + self.lever();
    }
}

/// A block face: its corners (in the order the operator clicks them).
#[derive(Debug, Clone)]
pub(super) struct Face(Vec<Vector3<f64>>);

impl Face {
    /// The `-y` triangle of the scenarios' 50 x 40 x 35 mm wedge at `xy`, turned by `yaw_deg`.
    pub(super) fn wedge_triangle(xy: [f64; 2], yaw_deg: f64) -> Self {
        Self::on_block(xy, yaw_deg, 0.0175, &[[-0.025, -0.020, -0.0175], [0.025, -0.020, -0.0175], [0.025, -0.020, 0.0175]])
    }

    /// The `+x` face of a 40 mm cube at `xy`, turned by `yaw_deg`.
    pub(super) fn cube_face(xy: [f64; 2], yaw_deg: f64) -> Self {
        Self::on_block(xy, yaw_deg, 0.02, &[[0.02, -0.02, 0.02], [0.02, -0.02, -0.02], [0.02, 0.02, -0.02], [0.02, 0.02, 0.02]])
    }

    fn on_block(xy: [f64; 2], yaw_deg: f64, centre_z: f64, local: &[[f64; 3]]) -> Self {
        let (s, c) = yaw_deg.to_radians().sin_cos();
        Self(local.iter().map(|p| Vector3::new(xy[0] + c * p[0] - s * p[1], xy[1] + s * p[0] + c * p[1], centre_z + p[2])).collect())
    }

    /// Unit normal towards the cameras (+x side).
    fn normal(&self) -> Vector3<f64> {
        let c = &self.0;
        let n = (c[1] - c[0]).cross(&(c[2] - c[0])).normalize();
        if n.x < 0.0 { -n } else { n }
    }

    fn centre(&self) -> Vector3<f64> {
        self.0.iter().sum::<Vector3<f64>>() / self.0.len() as f64
    }
}

#[derive(Debug, Clone)]
pub(super) struct Pick {
    pub(super) face: Face,
    /// Gaussian noise per corner coordinate per frame, px.
    pub(super) noise_px: f64,
    /// A fixed error of the left view's last corner, px, along the side to the first corner.
    pub(super) bias_px: f64,
    /// Frames the target is averaged over per servo step (the daemon: those since the last step).
    pub(super) frames_per_step: usize,
    /// The goal turned into image terms every step (the method) or once, at the start.
    pub(super) goal_every_step: bool,
    /// The goal height from the robot's kinematics (the method) or from the images.
    pub(super) kinematic_height: bool,
    pub(super) seed: u64,
}

impl Pick {
    pub(super) fn new(face: Face) -> Self {
        Self { face, noise_px: 0.0, bias_px: 0.0, frames_per_step: 1, goal_every_step: true, kinematic_height: true, seed: 1 }
    }
}

/// Where the plate ended, judged from ground truth as the simulator judges it.
#[derive(Debug, Clone, Copy)]
pub(super) struct PickOutcome {
    pub(super) outcome: StepOutcome,
    pub(super) steps: u32,
    /// Distance of the plate centre from the facet's plane, mm (signed, + towards the cameras).
    pub(super) plane_mm: f64,
    /// Angle between the plate normal and the facet normal about the vertical, degrees.
    pub(super) yaw_deg: f64,
    /// Tool height minus its goal, mm.
    pub(super) height_mm: f64,
}

/// Per-view template coordinates of an image polygon: the left tracker's template (origin at
/// the perimeter centroid, `e1 = c1 − c0`, `e2 = c(n−1) − c0`), shared by both views as the
/// daemon's `stereo_frame` shares them.
fn template_st(px: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let n = px.len();
    let c = |i: usize| Vector2::new(px[i % n][0], px[i % n][1]);
    let (mut sum, mut perimeter) = (Vector2::zeros(), 0.0);
    for j in 0..n {
        let l = (c(j + 1) - c(j)).norm();
        sum += (c(j) + c(j + 1)) * 0.5 * l;
        perimeter += l;
    }
    let o = sum / perimeter;
    let inv = Matrix2::from_columns(&[c(1) - c(0), c(n - 1) - c(0)]).try_inverse().expect("a polygon");
    (0..n).map(|i| (inv * (c(i) - o)).into()).collect()
}

fn fit_model(rig: &Rig, tool_positions: &[Vector3<f64>], yaw: f64) -> AffineStereo {
    let seen: Vec<[f64; 4]> = tool_positions
        .iter()
        .map(|x| {
            let p = rig.project(&Pose { tool: *x, yaw }.reference());
            [p.left[0], p.left[1], p.right[0], p.right[1]]
        })
        .collect();
    AffineStereo::fit(tool_positions, &seen).unwrap()
}

/// The facet's horizontal normal as the daemon takes it: the parallax gradient's direction.
fn facet_normal(model: &ServoModel, target: &StereoFrame) -> Vector3<f64> {
    let n: Vector3<f64> = model.parallax_gradient(&PlaneTransfer::from_frames(target).unwrap()).transpose();
    let n = Vector3::new(n.x, n.y, 0.0).normalize();
    if n.x < 0.0 { -n } else { n }
}

pub(super) fn run_pick(p: &Pick) -> PickOutcome {
    let rig = rig();
    let mut rng = SplitMix64::new(p.seed);
    let cage: Vec<Vector3<f64>> = CAGE.iter().map(|x| Vector3::from(*x)).collect();
    let global = ServoModel::new(&fit_model(&rig, &cage, CALIBRATION_YAW_RAD)).unwrap();
    let mut left: Vec<[f64; 2]> = p.face.0.iter().map(|c| rig.left.project(c)).collect();
    let right: Vec<[f64; 2]> = p.face.0.iter().map(|c| rig.right.project(c)).collect();
    let last = left.len() - 1;
    let d = (Vector2::from(left[0]) - Vector2::from(left[last])).normalize() * p.bias_px;
    left[last] = [left[last][0] + d.x, left[last][1] + d.y];
    let st = template_st(&left);
    // The target as a tracker reports it, averaged over `k` frames.
    let observe = |rng: &mut SplitMix64, k: usize| {
        let mut mean = [ViewFrame::default(); 2];
        for _ in 0..k {
            for (m, corners) in mean.iter_mut().zip([&left, &right]) {
                let noisy: Vec<[f64; 2]> = corners.iter().map(|c| [c[0] + p.noise_px * rng.normal(), c[1] + p.noise_px * rng.normal()]).collect();
                let f = fit_frame(&noisy, &st);
                let add = |a: &mut [f64; 2], b: [f64; 2]| {
                    a[0] += b[0] / k as f64;
                    a[1] += b[1] / k as f64;
                };
                add(&mut m.o, f.o);
                add(&mut m.e1, f.e1);
                add(&mut m.e2, f.e2);
            }
        }
        StereoFrame { left: mean[0], right: mean[1] }
    };
    let gripper = |pose: &Pose| {
        let (a, b) = (rig.project(&pose.plate([0.005, 0.0])), rig.project(&pose.plate([-0.005, 0.0])));
        let per_m = |x: [f64; 2], y: [f64; 2]| [(x[0] - y[0]) / 0.01, (x[1] - y[1]) / 0.01];
        GripperView {
            marks: MARKS_AB.map(|m| rig.project(&pose.plate(m))),
            reference: rig.project(&pose.reference()),
            axis: StereoPoint { left: per_m(a.left, b.left), right: per_m(a.right, b.right) },
        }
    };

    // Plan with the global model: the reference point straight above the facet origin.
    let target = observe(&mut rng, 1);
    let n = facet_normal(&global, &target);
    let origin = global.reconstruct(&StereoPoint { left: target.left.o, right: target.right.o }) + Pose { tool: Vector3::zeros(), yaw: CALIBRATION_YAW_RAD }.reference();
    let offset = Vector3::z() * (TOOL_Z_GOAL - origin.z - TOOL_FROM_REF[1]);
    let start = Pose { tool: origin + offset + Vector3::z() * TOOL_FROM_REF[1] + n * TOOL_FROM_REF[2], yaw: (-n.x).atan2(n.y) };
    // The local cage around the approach pose (sideways and up), the facet's orientation
    // again through the local model from the target averaged over the visit.
    let local_cage: Vec<Vector3<f64>> =
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 2.0]].iter().map(|q| start.tool + 0.03 * Vector3::from(*q)).collect();
    let model = ServoModel::new(&fit_model(&rig, &local_cage, start.yaw)).unwrap();
    let a = Vector3::z().cross(&facet_normal(&model, &observe(&mut rng, 30)));
    let goal = FacetGoal { reference_m: offset, marks_m: MARKS_AB.map(|m| offset + a * m[0] + Vector3::z() * m[1]), axis: a };

    let config = ServoConfig {
        max_step_m: 0.03,
        max_yaw_step_rad: 8f64.to_radians(),
        converged_rad: 0.3f64.to_radians(),
        converged_steps: 3,
        max_steps: 60,
        max_across_px: 25.0,
        yaw_lever_m: 0.025,
        min_condition: 0.02,
        ..ServoConfig::default()
    };
    let mut servo = CoplanarityServo::new(model, config).unwrap();
    let mut pose = start;
    let image_goal = |t: &StereoFrame, pose: &Pose| {
        if p.kinematic_height {
            goal.image_goal_at_height(&model, t, &gripper(pose).reference, pose.tool.z - TOOL_Z_GOAL).unwrap()
        } else {
            goal.image_goal(&model, t).unwrap()
        }
    };
    let once = image_goal(&observe(&mut rng, p.frames_per_step), &pose);
    let outcome = loop {
        let t = observe(&mut rng, p.frames_per_step);
        let g = if p.goal_every_step { image_goal(&t, &pose) } else { once };
        let s = servo.step(&t, &gripper(&pose), &g);
        match s.outcome {
            StepOutcome::Move => pose.apply(&s.motion),
            StepOutcome::Converged => {
                pose.apply(&s.motion);
                break s.outcome;
            }
            failed => break failed,
        }
    };
    let fn_ = p.face.normal();
    PickOutcome {
        outcome,
        steps: servo.steps(),
        plane_mm: (pose.reference() - p.face.centre()).dot(&fn_) * 1e3,
        yaw_deg: pose.n().cross(&fn_).z.asin().to_degrees(),
        height_mm: (pose.tool.z - TOOL_Z_GOAL) * 1e3,
    }
}

/// Worst |plane| (mm), |yaw| (°) and |height| (mm) over seeds 1..=`seeds`; panics when one
/// does not converge.
pub(super) fn worst(p: &Pick, seeds: u64) -> (f64, f64, f64) {
    let mut w = (0.0f64, 0.0f64, 0.0f64);
    for seed in 1..=seeds {
        let o = run_pick(&Pick { seed, ..p.clone() });
        assert_eq!(o.outcome, StepOutcome::Converged, "seed {seed}: {o:?}");
        assert!(o.steps <= 25, "seed {seed}: slow: {o:?}");
        w = (w.0.max(o.plane_mm.abs()), w.1.max(o.yaw_deg.abs()), w.2.max(o.height_mm.abs()));
    }
    w
}
