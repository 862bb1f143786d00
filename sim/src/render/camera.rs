//! Pinhole cameras. One model serves the renderer and the ground truth: the renderer's clip
//! matrix is derived from the same `pixel_from_robot` matrix that truth uses to project
//! points, so projected polygons and rendered edges cannot drift apart.
//!
//! Pixel convention: `(u, v)` with u to the right and v down, the centre of the top-left
//! pixel at (0, 0) (so pixel column `i` covers u in [i - 0.5, i + 0.5]). Camera frame:
//! x right, y down, z forward (along the optical axis).

use glam::{DMat3, DMat4, DVec3, DVec4};
use serde::Serialize;

use crate::scenario::CameraConfig;

/// Depth range of the renderer, metres.
pub const NEAR_M: f64 = 0.05;
pub const FAR_M: f64 = 20.0;

/// A perspective camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Camera {
    pub width_px: u32,
    pub height_px: u32,
    pub focal_px: f64,
    /// Principal point (image centre).
    pub cx_px: f64,
    pub cy_px: f64,
    /// Rotation robot → camera (rows: camera x, y, z axes in robot coordinates).
    pub camera_from_robot_rot: DMat3,
    /// Optical centre, robot frame.
    pub position_m: DVec3,
}

impl Camera {
    /// The camera a scenario describes.
    pub fn from_config(c: &CameraConfig) -> Self {
        let [w, h] = c.resolution;
        let focal_px = match (c.focal_px, c.vfov_deg) {
            (Some(f), _) => f,
            (None, Some(v)) => f64::from(h) / 2.0 / (v.to_radians() / 2.0).tan(),
            (None, None) => f64::from(h), // unreachable after validation; a sane default
        };
        Self::look_at(w, h, focal_px, DVec3::from_array(c.position_m), DVec3::from_array(c.look_at_m), DVec3::from_array(c.up))
    }

    /// A camera at `eye` looking at `target`, with `up` appearing up in the image.
    pub fn look_at(width_px: u32, height_px: u32, focal_px: f64, eye: DVec3, target: DVec3, up: DVec3) -> Self {
        let z = (target - eye).normalize();
        let x = z.cross(up).normalize();
        let y = z.cross(x);
        Self {
            width_px,
            height_px,
            focal_px,
            cx_px: (f64::from(width_px) - 1.0) / 2.0,
            cy_px: (f64::from(height_px) - 1.0) / 2.0,
            camera_from_robot_rot: DMat3::from_cols(x, y, z).transpose(),
            position_m: eye,
        }
    }

    /// The camera knocked by a rotation vector `rot_cam_rad` about its own axes (about its
    /// optical centre) and moved by `shift_cam_m` along its own axes.
    pub fn bumped(&self, rot_cam_rad: DVec3, shift_cam_m: DVec3) -> Self {
        let robot_from_camera = self.camera_from_robot_rot.transpose();
        let shift_robot = robot_from_camera * shift_cam_m;
        let r = if rot_cam_rad.length() > 0.0 {
            DMat3::from_axis_angle(rot_cam_rad.normalize(), rot_cam_rad.length())
        } else {
            DMat3::IDENTITY
        };
        // New camera axes = old axes turned by r (expressed in the camera frame).
        let new_robot_from_camera = robot_from_camera * r;
        Self { camera_from_robot_rot: new_robot_from_camera.transpose(), position_m: self.position_m + shift_robot, ..*self }
    }

    /// Point in camera coordinates.
    pub fn to_camera(&self, p_robot: DVec3) -> DVec3 {
        self.camera_from_robot_rot * (p_robot - self.position_m)
    }

    /// Projects a robot-frame point to pixels; `None` behind or too close to the camera.
    pub fn project(&self, p_robot: DVec3) -> Option<[f64; 2]> {
        let m = self.pixel_from_robot();
        let h = DVec4::from((p_robot, 1.0));
        let (u, v, w) = (row(&m, 0).dot(h), row(&m, 1).dot(h), row(&m, 2).dot(h));
        (w > NEAR_M).then(|| [u / w, v / w])
    }

    /// The 3x4 projection matrix robot frame → homogeneous pixels, row-major.
    pub fn pixel_from_robot(&self) -> [[f64; 4]; 3] {
        let r = self.camera_from_robot_rot;
        let t = -(r * self.position_m);
        let k = DMat3::from_cols(
            DVec3::new(self.focal_px, 0.0, 0.0),
            DVec3::new(0.0, self.focal_px, 0.0),
            DVec3::new(self.cx_px, self.cy_px, 1.0),
        );
        let kr = k * r;
        let kt = k * t;
        let mut m = [[0.0; 4]; 3];
        for (i, row) in m.iter_mut().enumerate() {
            let c = kr.row(i);
            *row = [c.x, c.y, c.z, kt[i]];
        }
        m
    }

    /// Clip-space matrix for the renderer, derived from [`Self::pixel_from_robot`]: maps a
    /// robot point to wgpu clip space (x, y in [-1, 1] with the framebuffer's pixel centres
    /// at (i + 0.5), depth in [0, 1] between [`NEAR_M`] and [`FAR_M`]).
    pub fn clip_from_robot(&self) -> DMat4 {
        let p = self.pixel_from_robot();
        let (w, h) = (f64::from(self.width_px), f64::from(self.height_px));
        // Framebuffer x = u + 0.5; ndc_x = 2 x / W - 1; ndc_y = 1 - 2 (v + 0.5) / H.
        let u = DVec4::from_array(p[0]);
        let v = DVec4::from_array(p[1]);
        let s = DVec4::from_array(p[2]); // = camera depth z_c (third row of K is [0 0 1])
        let cx = (u + s * 0.5) * (2.0 / w) - s;
        let cy = s - (v + s * 0.5) * (2.0 / h);
        let a = FAR_M / (FAR_M - NEAR_M);
        let cz = s * a - DVec4::new(0.0, 0.0, 0.0, 1.0) * (a * NEAR_M);
        DMat4::from_cols(cx, cy, cz, s).transpose()
    }

    /// Serialisable description for `truth.json`.
    pub fn info(&self, name: &str) -> CameraInfo {
        CameraInfo {
            name: name.to_string(),
            width_px: self.width_px,
            height_px: self.height_px,
            focal_px: self.focal_px,
            principal_point_px: [self.cx_px, self.cy_px],
            position_m: self.position_m.to_array(),
            pixel_from_robot: self.pixel_from_robot(),
        }
    }
}

fn row(m: &[[f64; 4]; 3], i: usize) -> DVec4 {
    DVec4::from_array(m[i])
}

/// A camera as written to `truth.json`.
#[derive(Debug, Clone, Serialize)]
pub struct CameraInfo {
    pub name: String,
    pub width_px: u32,
    pub height_px: u32,
    pub focal_px: f64,
    pub principal_point_px: [f64; 2],
    pub position_m: [f64; 3],
    /// 3x4, row-major: `[u w, v w, w] = P [x, y, z, 1]` with pixel centres at integers.
    pub pixel_from_robot: [[f64; 4]; 3],
}

/// Signed area of a polygon in the image (the shoelace formula over its corners in order),
/// pixels²; its sign says which way the corners wind.
pub fn signed_area_px2(polygon_px: &[[f64; 2]]) -> f64 {
    let p = polygon_px;
    let n = p.len();
    (0..n).map(|i| p[i][0] * p[(i + 1) % n][1] - p[(i + 1) % n][0] * p[i][1]).sum::<f64>() / 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::look_at(640, 480, 1350.0, DVec3::new(1.7, -0.24, 0.9), DVec3::new(0.33, 0.0, 0.1), DVec3::Z)
    }

    #[test]
    fn look_at_target_projects_to_the_image_centre_and_up_is_up() {
        let c = cam();
        let [u, v] = c.project(DVec3::new(0.33, 0.0, 0.1)).unwrap();
        assert!((u - 319.5).abs() < 1e-9 && (v - 239.5).abs() < 1e-9);
        let [_, v_up] = c.project(DVec3::new(0.33, 0.0, 0.2)).unwrap();
        assert!(v_up < v, "higher points appear higher (smaller v)");
        // Looking towards -x with z up, robot +y appears to the right.
        let [u_right, _] = c.project(DVec3::new(0.33, 0.1, 0.1)).unwrap();
        assert!(u_right > u);
    }

    #[test]
    fn clip_matrix_agrees_with_pixel_projection() {
        let c = cam();
        let m = c.clip_from_robot();
        for p in [DVec3::new(0.3, 0.1, 0.0), DVec3::new(0.5, -0.2, 0.3), DVec3::new(0.0, 0.0, 0.5)] {
            let [u, v] = c.project(p).unwrap();
            let clip = m * DVec4::from((p, 1.0));
            let ndc = clip / clip.w;
            let fx = (ndc.x + 1.0) / 2.0 * 640.0 - 0.5;
            let fy = (1.0 - ndc.y) / 2.0 * 480.0 - 0.5;
            assert!((fx - u).abs() < 1e-9 && (fy - v).abs() < 1e-9, "{p}: {fx},{fy} vs {u},{v}");
            assert!(ndc.z > 0.0 && ndc.z < 1.0);
            assert!((clip.w - c.to_camera(p).z).abs() < 1e-12);
        }
    }

    #[test]
    fn bump_turns_the_view() {
        let c = cam();
        let b = c.bumped(DVec3::new(0.0, 3f64.to_radians(), 0.0), DVec3::ZERO);
        let p = DVec3::new(0.33, 0.0, 0.1);
        let [u0, _] = c.project(p).unwrap();
        let [u1, _] = b.project(p).unwrap();
        // Panning by 3° about the camera's y axis shifts the image by about f * tan(3°) = 71 px.
        assert!(((u1 - u0).abs() - 1350.0 * 3f64.to_radians().tan()).abs() < 1.0, "{u0} -> {u1}");
        assert_eq!(b.position_m, c.position_m);
    }
}
