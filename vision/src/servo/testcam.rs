//! Test support: pinhole cameras, so the geometry modules can be tested against
//! *perspective* images (the affine model is only an approximation of them, as with real
//! cameras). Noise comes from [`SplitMix64`](crate::rng::SplitMix64).

use nalgebra::{Matrix3, Rotation3, Unit, Vector3};

use super::{ViewFrame, StereoPoint};

/// A pinhole camera: `x` right, `y` down, `z` forward; pixels.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PinholeCamera {
    /// Rotation camera_from_robot.
    pub camera_from_robot: Matrix3<f64>,
    /// Camera centre in the robot frame, metres.
    pub centre_m: Vector3<f64>,
    pub f_px: f64,
    pub principal_px: [f64; 2],
}

impl PinholeCamera {
    /// A 640x480 camera at `eye` looking at `target`, image `v` pointing down the world `z`.
    pub fn look_at(eye: Vector3<f64>, target: Vector3<f64>, f_px: f64) -> Self {
        let z = (target - eye).normalize();
        let x = z.cross(&Vector3::z()).normalize();
        let y = z.cross(&x);
        Self { camera_from_robot: Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()]), centre_m: eye, f_px, principal_px: [320.0, 240.0] }
    }

    pub fn project(&self, x_m: &Vector3<f64>) -> [f64; 2] {
        let p = self.camera_from_robot * (x_m - self.centre_m);
        [self.f_px * p[0] / p[2] + self.principal_px[0], self.f_px * p[1] / p[2] + self.principal_px[1]]
    }

    /// The camera turned by `angle_rad` about `axis_camera` (camera frame) through its
    /// centre: a knock.
    pub fn knocked(&self, axis_camera: Vector3<f64>, angle_rad: f64) -> Self {
        let r = Rotation3::from_axis_angle(&Unit::new_normalize(axis_camera), angle_rad);
        Self { camera_from_robot: r.matrix() * self.camera_from_robot, ..*self }
    }
}

/// Two verged cameras ~2 m from the workspace, ~20° apart, like the thesis's setup.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Rig {
    pub left: PinholeCamera,
    pub right: PinholeCamera,
}

impl Rig {
    /// Workspace centre.
    pub const WORKSPACE_M: [f64; 3] = [0.5, 0.0, 0.1];

    pub fn standard(f_px: f64) -> Self {
        let w = Vector3::from(Self::WORKSPACE_M);
        let (dist, elev) = (2.0, 25f64.to_radians());
        let eye = |az: f64| w + dist * Vector3::new(elev.cos() * az.cos(), elev.cos() * az.sin(), elev.sin());
        Self {
            left: PinholeCamera::look_at(eye(-10f64.to_radians()), w, f_px),
            right: PinholeCamera::look_at(eye(10f64.to_radians()), w, f_px),
        }
    }

    pub fn project(&self, x_m: &Vector3<f64>) -> StereoPoint {
        StereoPoint { left: self.left.project(x_m), right: self.right.project(x_m) }
    }
}

/// The eight-point calibration cage: a box in the workspace, lower face 5 cm above the table.
pub(crate) fn cage() -> Vec<Vector3<f64>> {
    (0..8)
        .map(|i| Vector3::new(0.4 + 0.2 * (i & 1) as f64, -0.1 + 0.2 * ((i >> 1) & 1) as f64, 0.05 + 0.2 * (i >> 2) as f64))
        .collect()
}

/// Least-squares affine frame `o + s e1 + t e2` through image points with known `(s, t)`:
/// what an affine contour tracker converges to on a perspective image of a polygon.
pub(crate) fn fit_frame(points: &[[f64; 2]], st: &[[f64; 2]]) -> ViewFrame {
    let mut ata = Matrix3::zeros();
    let mut atx = nalgebra::Matrix3x2::zeros();
    for (p, c) in points.iter().zip(st) {
        let a = Vector3::new(1.0, c[0], c[1]);
        ata += a * a.transpose();
        atx += a * nalgebra::RowVector2::new(p[0], p[1]);
    }
    let sol = ata.try_inverse().expect("frame points span a plane") * atx;
    ViewFrame { o: [sol[(0, 0)], sol[(0, 1)]], e1: [sol[(1, 0)], sol[(1, 1)]], e2: [sol[(2, 0)], sol[(2, 1)]] }
}
