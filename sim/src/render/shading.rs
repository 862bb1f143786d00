//! The one shading model of the simulator: flat Lambertian faces under one directional light
//! plus ambient light. A face of albedo `a` whose outward unit normal is `n` shows the grey
//!
//! ```text
//! clamp(a · (ambient + intensity · max(0, n · l)), 0, 1)      (l: unit vector towards the light)
//! ```
//!
//! `shaders/scene.wgsl` evaluates it per fragment on the GPU (in f32) from the [`Lighting`]
//! the renderer uploads; [`Lighting::grey`] is the same formula on the CPU (in f64) for those
//! that must predict what the renderer will draw before anything is rendered (the layout
//! randomiser's edge-contrast check). Change one, change the other.
//!
//! Depends only on the scenario's plain data.

use glam::DVec3;

use crate::scenario::LightConfig;

/// Lighting at one moment: what the scenario's `[light]` sets, as scripted light changes
/// ramp it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lighting {
    /// Unit vector from the scene towards the light.
    pub direction: DVec3,
    pub intensity: f64,
    pub ambient: f64,
}

impl Lighting {
    pub fn from_config(l: &LightConfig) -> Self {
        Self { direction: DVec3::from_array(l.direction).normalize(), intensity: l.intensity, ambient: l.ambient }
    }

    /// The lighting a fraction `s` (0..1) of the way from `self` to `to`.
    pub fn lerp(&self, to: &Self, s: f64) -> Self {
        let d = self.direction.lerp(to.direction, s);
        Self {
            direction: if d.length() > 1e-9 { d.normalize() } else { to.direction },
            intensity: self.intensity + (to.intensity - self.intensity) * s,
            ambient: self.ambient + (to.ambient - self.ambient) * s,
        }
    }

    /// Grey level (0..1) of a face of albedo `albedo` whose outward unit normal (robot frame)
    /// is `normal`: what `shaders/scene.wgsl` draws for it.
    pub fn grey(&self, albedo: f64, normal: DVec3) -> f64 {
        (albedo * (self.ambient + self.intensity * normal.dot(self.direction).max(0.0))).clamp(0.0, 1.0)
    }
}
