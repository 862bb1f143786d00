//! The simulated scene of the servo's closed-loop tests (METHOD.md §3): pinhole cameras, an
//! affine model fitted from an eight-point cage, a gripper plate with three marks tracked as
//! an affine contour, a target facet; the robot executes each step exactly.

use nalgebra::Vector3;

use super::testcam::{cage, fit_frame, PinholeCamera, Rig};
use crate::rng::SplitMix64;
use super::*;
use crate::affine::AffineStereo;

/// The gripper plate (the face the servo aligns), in tool coordinates: x along the jaw axis,
/// y along the plate, z up; metres from the tool point. An 80 x 70 mm rectangle whose affine
/// frame has its origin at the top-left corner, `e1` along y (80 mm), `e2` down (70 mm).
pub(super) const PLATE_ORIGIN_LOCAL: [f64; 3] = [-0.02, -0.04, 0.09];
pub(super) const PLATE_E1_LOCAL: [f64; 3] = [0.0, 0.08, 0.0];
pub(super) const PLATE_E2_LOCAL: [f64; 3] = [0.0, 0.0, -0.07];
/// Marks and reference point in the plate's affine frame: the daemon reads them off the
/// gripper tracker's frame the same way. Marks 70 mm apart at 30 mm above the tool point and
/// one at 80 mm; the reference point 50 mm above the tool point, 20 mm off the yaw axis (so
/// the servo's yaw centre is off by 20 mm, as it will be on the real gripper).
pub(super) const MARKS_ST: [[f64; 2]; 3] = [[0.0625, 6.0 / 7.0], [0.9375, 6.0 / 7.0], [0.5, 1.0 / 7.0]];
pub(super) const REF_ST: [f64; 2] = [0.5, 4.0 / 7.0];
/// Contour points per tracker (the thesis's trackers use about 100).
pub(super) const CONTOUR_POINTS: usize = 100;

pub(super) fn plate_local(st: &[f64; 2]) -> [f64; 3] {
    let p = |k: usize| PLATE_ORIGIN_LOCAL[k] + st[0] * PLATE_E1_LOCAL[k] + st[1] * PLATE_E2_LOCAL[k];
    [p(0), p(1), p(2)]
}

pub(super) fn marks_local() -> [[f64; 3]; 3] {
    [plate_local(&MARKS_ST[0]), plate_local(&MARKS_ST[1]), plate_local(&MARKS_ST[2])]
}

pub(super) fn ref_local() -> [f64; 3] {
    plate_local(&REF_ST)
}

/// `(s, t)` of `n` points evenly spaced around the unit square's outline.
pub(super) fn outline_st(n: usize) -> Vec<[f64; 2]> {
    (0..n)
        .map(|i| {
            let u = 4.0 * i as f64 / n as f64;
            match u as usize {
                0 => [u, 0.0],
                1 => [1.0, u - 1.0],
                2 => [3.0 - u, 1.0],
                _ => [0.0, 4.0 - u],
            }
        })
        .collect()
}

/// The reference point's goal: this far above the facet's top edge, in its plane (stand-off).
pub(super) const ABOVE_TOP_M: f64 = 0.04;

/// A square target facet (a block's face).
#[derive(Debug, Clone, Copy)]
pub(super) struct Facet {
    pub(super) centre: Vector3<f64>,
    /// Unit normal, towards the cameras.
    pub(super) normal: Vector3<f64>,
    /// Horizontal unit vector in the plane.
    pub(super) along: Vector3<f64>,
    /// Unit vector in the plane, perpendicular to `along`, upwards.
    pub(super) up: Vector3<f64>,
    pub(super) half_m: f64,
}

impl Facet {
    /// The front face of a 40 mm cube at `block`, turned by `yaw_deg`, leaning back by `tilt_deg`.
    pub(super) fn new(block: Vector3<f64>, yaw_deg: f64, tilt_deg: f64) -> Self {
        let (yaw, tilt) = (yaw_deg.to_radians(), tilt_deg.to_radians());
        let normal = Vector3::new(tilt.cos() * yaw.cos(), tilt.cos() * yaw.sin(), tilt.sin());
        let along = Vector3::z().cross(&normal).normalize();
        let up = normal.cross(&along);
        Self { centre: block + 0.02 * Vector3::new(yaw.cos(), yaw.sin(), 0.0), normal, along, up, half_m: 0.02 }
    }

    pub(super) fn standard() -> Self {
        Self::new(Vector3::new(0.52, 0.03, 0.02), 20.0, 0.0)
    }

    /// Corners at `(s, t)` = CORNER_ST: top-left, top-right, bottom-right, bottom-left.
    pub(super) fn corners(&self) -> [Vector3<f64>; 4] {
        let (a, u, h) = (self.half_m, self.up, self.along);
        [self.centre - a * h + a * u, self.centre + a * h + a * u, self.centre + a * h - a * u, self.centre - a * h - a * u]
    }

    pub(super) fn horizontal_normal(&self) -> Vector3<f64> {
        Vector3::new(self.normal[0], self.normal[1], 0.0).normalize()
    }

    pub(super) fn distance_m(&self, x: &Vector3<f64>) -> f64 {
        (x - self.centre).dot(&self.normal)
    }
}

#[derive(Debug, Clone, Copy)]
pub(super) struct Pose {
    pub(super) tool_m: Vector3<f64>,
    pub(super) yaw_rad: f64,
}

impl Pose {
    pub(super) fn world(&self, local: &[f64; 3]) -> Vector3<f64> {
        let (s, c) = self.yaw_rad.sin_cos();
        self.tool_m + Vector3::new(c * local[0] - s * local[1], s * local[0] + c * local[1], local[2])
    }

    pub(super) fn jaw_axis(&self) -> Vector3<f64> {
        Vector3::new(self.yaw_rad.cos(), self.yaw_rad.sin(), 0.0)
    }

    pub(super) fn apply(&mut self, m: &ToolMotion) {
        self.tool_m += m.translation_m;
        self.yaw_rad += m.yaw_rad;
    }

    /// Where the plate lies in the facet's plane (the jaw axis into the block), with the
    /// reference point `ABOVE_TOP_M` above the top edge's centre.
    pub(super) fn goal(facet: &Facet) -> Self {
        let n = facet.horizontal_normal();
        let yaw_rad = (-n[1]).atan2(-n[0]);
        let reference = facet.centre + (facet.half_m + ABOVE_TOP_M) * facet.up;
        let mut pose = Self { tool_m: Vector3::zeros(), yaw_rad };
        pose.tool_m = reference - pose.world(&ref_local());
        pose
    }

    pub(super) fn start(facet: &Facet) -> Self {
        let goal = Self::goal(facet);
        Self { tool_m: goal.tool_m + Vector3::new(0.06, -0.05, 0.08), yaw_rad: goal.yaw_rad + 15f64.to_radians() }
    }
}

pub(super) fn noisy(p: [f64; 2], rng: &mut SplitMix64, noise_px: f64) -> [f64; 2] {
    [p[0] + rng.range(-noise_px, noise_px), p[1] + rng.range(-noise_px, noise_px)]
}

/// What an affine contour tracker reports for a planar quadrilateral: the least-squares
/// affine frame of `CONTOUR_POINTS` points around its outline, each seen with uniform
/// `±noise_px` error per coordinate.
pub(super) fn track(cam: &PinholeCamera, at_st: impl Fn(&[f64; 2]) -> Vector3<f64>, rng: &mut SplitMix64, noise_px: f64) -> ViewFrame {
    let st = outline_st(CONTOUR_POINTS);
    let pts: Vec<[f64; 2]> = st.iter().map(|c| noisy(cam.project(&at_st(c)), rng, noise_px)).collect();
    fit_frame(&pts, &st)
}

pub(super) fn observe_target(rig: &Rig, facet: &Facet, rng: &mut SplitMix64, noise_px: f64) -> StereoFrame {
    let c = facet.corners();
    let at = |st: &[f64; 2]| c[0] + st[0] * (c[1] - c[0]) + st[1] * (c[3] - c[0]);
    StereoFrame { left: track(&rig.left, at, rng, noise_px), right: track(&rig.right, at, rng, noise_px) }
}

/// The gripper as the daemon will see it: the plate's tracked frame in each view, and the
/// marks, reference point and axis (`e1`) read off it.
pub(super) fn observe_gripper(rig: &Rig, pose: &Pose, rng: &mut SplitMix64, noise_px: f64) -> GripperView {
    let at = |st: &[f64; 2]| pose.world(&plate_local(st));
    let (l, r) = (track(&rig.left, at, rng, noise_px), track(&rig.right, at, rng, noise_px));
    let see = |st: &[f64; 2]| StereoPoint { left: l.point(st), right: r.point(st) };
    GripperView { marks: [see(&MARKS_ST[0]), see(&MARKS_ST[1]), see(&MARKS_ST[2])], reference: see(&REF_ST), axis: StereoPoint { left: l.e1, right: r.e1 } }
}

/// Self-calibration: the tool visits the cage at yaw `yaw_rad` while the reference point is
/// tracked.
pub(super) fn calibrate(rig: &Rig, yaw_rad: f64, rng: &mut SplitMix64, noise_px: f64) -> AffineStereo {
    let robot = cage();
    let seen: Vec<[f64; 4]> = robot
        .iter()
        .map(|x| {
            let p = rig.project(&Pose { tool_m: *x, yaw_rad }.world(&ref_local()));
            let (l, r) = (noisy(p.left, rng, noise_px), noisy(p.right, rng, noise_px));
            [l[0], l[1], r[0], r[1]]
        })
        .collect();
    AffineStereo::fit(&robot, &seen).unwrap()
}

pub(super) struct Scenario {
    pub(super) f_px: f64,
    pub(super) facet: Facet,
    pub(super) noise_px: f64,
    /// (step, camera 0 = left / 1 = right, axis in camera frame, angle in degrees)
    pub(super) knock: Option<(u32, usize, Vector3<f64>, f64)>,
    pub(super) config: ServoConfig,
    /// Goal parallax: metric offset of the plate from the facet plane (None: coplanar).
    pub(super) standoff_m: Option<f64>,
    pub(super) seed: u64,
}

impl Scenario {
    pub(super) fn new() -> Self {
        Self { f_px: 1500.0, facet: Facet::standard(), noise_px: 0.0, knock: None, config: ServoConfig::default(), standoff_m: None, seed: 1 }
    }
}

pub(super) struct Outcome {
    pub(super) outcome: StepOutcome,
    pub(super) steps: u32,
    pub(super) pose: Pose,
    pub(super) history: Vec<ServoStep>,
    /// Worst distance of a mark from the facet plane, mm.
    pub(super) plane_mm: f64,
    /// Angle between the plate normal and the facet normal, degrees.
    pub(super) angle_deg: f64,
    /// Reference point's in-plane distance from its goal, mm.
    pub(super) in_plane_mm: f64,
    /// Distance of the marks' centroid from the facet plane, mm.
    pub(super) centroid_mm: f64,
    /// Angle between the jaw axis and the facet's horizontal normal, seen from above, degrees.
    pub(super) yaw_deg: f64,
}

pub(super) fn run(sc: &Scenario) -> Outcome {
    let mut rng = SplitMix64::new(sc.seed);
    let mut rig = Rig::standard(sc.f_px);
    let goal_pose = Pose::goal(&sc.facet);
    let mut pose = Pose::start(&sc.facet);
    let model = calibrate(&rig, pose.yaw_rad, &mut rng, sc.noise_px);
    let servo_model = ServoModel::new(&model).unwrap();
    // The goal is taught from noiseless images of the goal pose; coplanar unless a stand-off
    // is asked for.
    let target0 = observe_target(&rig, &sc.facet, &mut rng, 0.0);
    let mut goal = ServoGoal::teach(&servo_model, &target0, &observe_gripper(&rig, &goal_pose, &mut rng, 0.0)).unwrap();
    goal.parallax_px = [0.0; 3];
    if let Some(d) = sc.standoff_m {
        goal = goal.offset_by(&servo_model, &target0, &(d * sc.facet.normal)).unwrap();
    }
    let mut servo = CoplanarityServo::new(servo_model, sc.config).unwrap();
    let mut history = Vec::new();
    let outcome = loop {
        if let Some((at, cam, axis, deg)) = sc.knock
            && servo.steps() == at
        {
            let c = if cam == 0 { &mut rig.left } else { &mut rig.right };
            *c = c.knocked(axis, deg.to_radians());
        }
        let target = observe_target(&rig, &sc.facet, &mut rng, sc.noise_px);
        let gripper = observe_gripper(&rig, &pose, &mut rng, sc.noise_px);
        let step = servo.step(&target, &gripper, &goal);
        history.push(step);
        match step.outcome {
            StepOutcome::Move => pose.apply(&step.motion),
            StepOutcome::Converged => {
                pose.apply(&step.motion);
                break StepOutcome::Converged;
            }
            other => break other,
        }
    };
    let n = sc.facet.normal;
    let plane_mm = marks_local().iter().map(|m| (sc.facet.distance_m(&pose.world(m)) - sc.standoff_m.unwrap_or(0.0)).abs()).fold(0.0, f64::max) * 1e3;
    let angle_deg = pose.jaw_axis().dot(&n).abs().min(1.0).acos().to_degrees();
    let r = pose.world(&ref_local()) - goal_pose.world(&ref_local());
    // A stand-off moves the goal along the normal only.
    let in_plane_mm = (r - r.dot(&n) * n).norm() * 1e3;
    let centroid = marks_local().iter().map(|m| pose.world(m)).sum::<Vector3<f64>>() / 3.0;
    let centroid_mm = sc.facet.distance_m(&centroid).abs() * 1e3;
    let yaw_deg = pose.jaw_axis().dot(&sc.facet.horizontal_normal()).abs().min(1.0).acos().to_degrees();
    Outcome { outcome, steps: servo.steps(), pose, history, plane_mm, angle_deg, in_plane_mm, centroid_mm, yaw_deg }
}

