//! handeye's simulator: a rapier3d work cell (table, polyhedral blocks, a 5-DOF arm with a
//! parallel-jaw gripper), the arm's own controller, and a headless wgpu renderer of a verged
//! stereo pair. See `sim/README.md` for the robot frame and the scenario format.

pub mod arm;
pub mod camera;
pub mod controller;
pub mod events;
pub mod geometry;
pub mod hash;
pub mod hint;
pub mod judge;
pub mod kinematics;
pub mod render;
pub mod run;
pub mod scenario;
pub mod scene;
pub mod script;
pub mod simulator;
pub mod transport;
pub mod truth;
pub mod watch;
pub mod world;

pub use scenario::{Scenario, ScenarioError};
pub use simulator::{SimError, Simulator};

/// The glam (0.33, the one rapier uses) of every vector and matrix in this crate's API.
pub use glam;
