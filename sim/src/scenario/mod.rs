//! Scenarios: the work cell, the cameras, the task and the scripted disturbances, as a TOML
//! file describes them (see `scenarios/*.toml` and `sim/README.md`).
//!
//! - `config`: the file's format, plain data (depends on nothing else of the crate);
//! - `load`, `locate`, `validate`, `error`: reading a file, checking it, and saying where in
//!   the file a problem is ([`ScenarioError`]: `file:line:column: field.path: message`);
//! - `shades`: every block face's albedo, as written or seeded;
//! - `layout`: seeded random layouts for batches, whose yaw check uses the renderer's
//!   shading model ([`crate::render::shading`]) and the block shapes of the work cell
//!   ([`crate::cell::geometry`]).
//!
//! Everything else in the crate builds on these types; they build on nothing of it but the
//! seeded generator.

mod config;
mod error;
mod layout;
mod load;
mod locate;
mod shades;
mod validate;

pub use config::{
    ArmConfig, BlockConfig, BlockKind, Cage, CameraConfig, Event, LightConfig, PhysicsConfig, RenderConfig, Scenario, SuccessRule,
    TableConfig, Task, s_to_ns,
};
pub use error::ScenarioError;
