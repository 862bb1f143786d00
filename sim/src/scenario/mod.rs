//! Scenarios: the work cell, the cameras, the task and the scripted disturbances, as a TOML
//! file describes them (see `scenarios/*.toml` and `sim/README.md`).
//!
//! - `config`: the file's format, plain data (depends on nothing else of the crate);
//! - `load`, `locate`, `validate`, `error`: reading a file, checking it, and saying where in
//!   the file a problem is ([`ScenarioError`]: `file:line:column: field.path: message`);
//! - `shades`: every block face's albedo, as written or seeded;
//! - `layout`: seeded random layouts of the scenario's own blocks, for batches;
//! - `disturb`: one seeded random disturbance per run (`--disturb`);
//! - `cell_draw`: whole random work cells from the `[randomize]` ranges (cameras, light,
//!   shades, blocks, noise), whose physical checks use the renderer's camera model
//!   ([`crate::render::camera`]), the arm's reach ([`crate::cell::kinematics`]) and the block
//!   shapes ([`crate::cell::geometry`]).
//!
//! Everything else in the crate builds on these types; they build on nothing of it but the
//! seeded generator, and the random layouts and cells on the models named above.

mod cell_draw;
mod config;
mod disturb;
mod error;
mod layout;
mod load;
mod locate;
mod pointer_config;
mod shades;
mod validate;

pub use config::{
    ArmConfig, BlockConfig, BlockKind, Cage, CameraConfig, Event, LightConfig, PhysicsConfig, PointerConfig, RandomizeConfig, RenderConfig, Scenario, SuccessRule,
    TableConfig, Task, s_to_ns,
};
pub use cell_draw::CellDrawError;
pub use error::ScenarioError;
