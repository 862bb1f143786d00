//! Headless stereo rendering with wgpu: both views of the verged pair into one GRAY8 buffer
//! (left rows, then right rows), as published in one `handeye/stereo` sample.
//!
//! Per frame: the CPU places every mesh vertex in the robot frame (a few hundred vertices),
//! one upload, one render pass per view into a two-layer R8 texture (multiview drew only one
//! view on Mesa 22.3's lavapipe), an optional blur/noise pass per view, one copy of both
//! layers, one map. Nothing is allocated or rebuilt per frame.
//!
//! The clip matrices come from [`Camera::clip_from_robot`], derived from the same
//! `pixel_from_robot` projection that ground truth uses.

use glam::DAffine3;

use super::camera::Camera;
use super::error::RenderError;
use super::gpu::{self, Gpu, GpuVertex, PostUniform, ViewUniform};
use super::noise;
use super::scene::Scene;
use super::shading::Lighting;
use handeye_vision::rng::mix64;

/// Per-camera sensor model.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Sensor {
    /// Gaussian noise, grey levels (0..255 scale).
    pub noise_sigma: f64,
    /// Gaussian blur, pixels.
    pub blur_sigma_px: f64,
}

/// What one frame shows.
pub struct FrameInput<'a> {
    pub scene: &'a Scene,
    /// One pose per scene object (`None`: not drawn).
    pub poses: &'a [Option<DAffine3>],
    pub cameras: &'a [Camera; 2],
    pub lighting: &'a Lighting,
    pub background: f64,
    pub sensors: [Sensor; 2],
    /// Seed of this frame's noise (derive it from the scenario seed and the frame id).
    pub noise_seed: u64,
}

/// A headless stereo renderer for one resolution.
pub struct Renderer {
    gpu: Gpu,
    width: u32,
    height: u32,
    staging: Vec<GpuVertex>,
    /// Sensor-noise tables per view (built on first use for that view's sigma).
    noise: [Option<noise::NoiseTable>; 2],
}

impl Renderer {
    /// Opens the graphics device and builds pipelines for `width` x `height` views and
    /// scenes of up to `max_vertices` vertices.
    pub fn new(width: u32, height: u32, max_vertices: usize) -> Result<Self, RenderError> {
        Self::with_antialias(width, height, max_vertices, false)
    }

    /// Like [`Self::new`]; `antialias` renders the grey views with 4x multisampling (edges
    /// with sub-pixel grey, as a camera sees them; ~12 ms more per stereo frame on lavapipe).
    pub fn with_antialias(width: u32, height: u32, max_vertices: usize, antialias: bool) -> Result<Self, RenderError> {
        let samples = if antialias { gpu::ANTIALIAS_SAMPLES } else { 1 };
        let gpu = Gpu::new(width, height, max_vertices, samples)?;
        tracing::info!(adapter = %describe(&gpu.adapter), "renderer ready");
        Ok(Self { gpu, width, height, staging: Vec::with_capacity(max_vertices), noise: [None, None] })
    }

    /// A renderer sized for `scene` seen by `cameras`.
    pub fn for_scene(scene: &Scene, cameras: &[Camera; 2]) -> Result<Self, RenderError> {
        Self::for_scene_with(scene, cameras, false)
    }

    /// A renderer sized for `scene` seen by `cameras`, anti-aliased or not.
    pub fn for_scene_with(scene: &Scene, cameras: &[Camera; 2], antialias: bool) -> Result<Self, RenderError> {
        if cameras[0].width_px != cameras[1].width_px || cameras[0].height_px != cameras[1].height_px {
            return Err(RenderError::ResolutionMismatch);
        }
        Self::with_antialias(cameras[0].width_px, cameras[0].height_px, scene.vertex_count(), antialias)
    }

    /// The adapter in use, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu, driver llvmpipe)`.
    pub fn adapter(&self) -> String {
        describe(&self.gpu.adapter)
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    /// Bytes of one stereo frame (two views, tightly packed rows).
    pub fn frame_bytes(&self) -> usize {
        (self.width * self.height * 2) as usize
    }

    fn prepare(&mut self, frame: &FrameInput<'_>) -> Result<u32, RenderError> {
        self.staging.clear();
        for (object, pose) in frame.scene.objects.iter().zip(frame.poses) {
            let Some(pose) = pose else { continue };
            let rot = pose.matrix3;
            for v in &object.mesh.vertices {
                let p = pose.transform_point3(glam::DVec3::from_array(v.pos.map(f64::from)));
                let n = rot * glam::DVec3::from_array(v.normal.map(f64::from));
                self.staging.push(GpuVertex {
                    position: p.as_vec3().to_array(),
                    normal: n.as_vec3().to_array(),
                    shade: v.shade,
                    id: v.id,
                });
            }
        }
        let l = frame.lighting;
        let view = |c: &Camera| ViewUniform {
            clip_from_robot: c.clip_from_robot().as_mat4().to_cols_array(),
            light: [l.direction.x as f32, l.direction.y as f32, l.direction.z as f32, l.intensity as f32],
            params: [l.ambient as f32, 0.0, 0.0, 0.0],
        };
        let post = |i: usize| {
            let s = frame.sensors[i];
            let radius = (2.0 * s.blur_sigma_px).ceil().min(4.0) as f32;
            PostUniform { params: [s.blur_sigma_px as f32, radius, 0.0, 0.0], layer: [i as u32, 0, 0, 0] }
        };
        self.gpu.upload(&self.staging, &[view(&frame.cameras[0]), view(&frame.cameras[1])], &[post(0), post(1)])?;
        Ok(self.staging.len() as u32)
    }

    /// Renders the stereo pair into `out` (GRAY8, left then right, `width` bytes a row):
    /// scene, optional blur (GPU), then sensor noise (CPU, see [`noise`]).
    pub fn render(&mut self, frame: &FrameInput<'_>, out: &mut [u8]) -> Result<(), RenderError> {
        let n = self.prepare(frame)?;
        let blur = frame.sensors.iter().any(|s| s.blur_sigma_px > 0.0);
        self.gpu.render_gray(n, frame.background, blur, out)?;
        let view = (self.width * self.height) as usize;
        for (i, pixels) in out.chunks_exact_mut(view).enumerate().take(2) {
            let sigma = frame.sensors[i].noise_sigma;
            if sigma > 0.0 {
                let table = match &self.noise[i] {
                    Some(t) if t.sigma() == sigma => &self.noise[i],
                    _ => {
                        self.noise[i] = Some(noise::NoiseTable::new(sigma));
                        &self.noise[i]
                    }
                };
                if let Some(t) = table {
                    t.apply(pixels, self.width as usize, mix64(frame.noise_seed ^ ((i as u64 + 1) << 56)));
                }
            }
        }
        Ok(())
    }

    /// Renders which face covers each pixel (see [`super::scene`] for the ids; 0 = none) in
    /// the same layout as [`Self::render`].
    pub fn render_ids(&mut self, frame: &FrameInput<'_>, out: &mut [u32]) -> Result<(), RenderError> {
        let n = self.prepare(frame)?;
        self.gpu.render_ids(n, out)
    }
}

fn describe(info: &wgpu::AdapterInfo) -> String {
    format!("{} ({:?}, {:?}, driver {} {})", info.name, info.backend, info.device_type, info.driver, info.driver_info)
}
