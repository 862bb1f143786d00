//! What the cameras see: the pinhole [`camera`] model (shared with ground truth), the
//! [`scene`] of flat-shaded meshes with face ids ([`cell_scene`] builds it from the work
//! cell), the one [`shading`] model, and the headless wgpu [`Renderer`] of the verged stereo
//! pair (with its sensor [`noise`]).
//!
//! Depends on the scenario's data and on the work cell (the scene's meshes follow its bodies);
//! the work cell knows nothing of rendering. Inside: `renderer` → `gpu`, `noise`, `scene`,
//! `camera`, `shading`, `error`; only `cell_scene` reaches into the work cell (its bodies and
//! dimensions); `camera` and `shading` depend on the scenario's data only, so the scenario's
//! layout randomiser can use the shading model without a loop.

pub mod camera;
pub mod cell_scene;
mod error;
mod gpu;
pub mod noise;
mod renderer;
pub mod scene;
pub mod shading;

pub use error::RenderError;
pub use renderer::{FrameInput, Renderer, Sensor};
