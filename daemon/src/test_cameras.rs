//! Pinhole cameras for the daemon's unit tests: the simulator's pair (1800 px focal length,
//! 640x480, principal point at the centre), so tests can project known 3-D points to pixels.

use nalgebra::{Matrix3, Matrix3x4, Vector3, Vector4};

/// A pinhole camera at `eye` looking at `at` (z up, image v downwards).
pub fn camera(eye: Vector3<f64>, at: Vector3<f64>) -> Matrix3x4<f64> {
    let f = (at - eye).normalize();
    let r = f.cross(&Vector3::z()).normalize();
    let d = f.cross(&r);
    let rot = Matrix3::from_rows(&[r.transpose(), d.transpose(), f.transpose()]);
    let k = Matrix3::new(1800.0, 0.0, 320.0, 0.0, 1800.0, 240.0, 0.0, 0.0, 1.0);
    let mut rt = Matrix3x4::zeros();
    rt.fixed_view_mut::<3, 3>(0, 0).copy_from(&rot);
    rt.set_column(3, &(-rot * eye));
    k * rt
}

/// Where camera `p` sees `x`, px.
pub fn px(p: &Matrix3x4<f64>, x: &Vector3<f64>) -> [f64; 2] {
    let h = p * Vector4::new(x.x, x.y, x.z, 1.0);
    [h[0] / h[2], h[1] / h[2]]
}
