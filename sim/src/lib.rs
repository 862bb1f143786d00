//! handeye's simulator: a rapier3d work cell (table, polyhedral blocks, a 5-DOF arm with a
//! parallel-jaw gripper), the arm's own controller, and a headless wgpu renderer of a verged
//! stereo pair. See `sim/README.md` for the robot frame and the scenario format.
//!
//! The crate is a tree of domains, each depending only on those listed before it:
//!
//! - [`scenario`]: the scenario file, its checks and seeded layouts (plain data);
//! - [`cell`]: the physical work cell (world, arm, kinematics, controller, block geometry);
//! - [`render`]: what the cameras see (camera model, scene, shading, the wgpu renderer);
//! - [`events`]: the scripted disturbances, which change the cell and the views;
//! - [`pointer`]: the operator's pointing gesture (a hand that is seen, not felt);
//! - [`simulator`]: the cell, the controller, the events and the success judge stepped in
//!   simulated time, without I/O;
//! - [`referee`]: ground truth and judging, read from the simulator;
//! - [`run`], [`transport`], [`hash`]: the simulator against a transport (lockstep or real
//!   time), the iceoryx2 services, and the hash over every published frame.
//!
//! Two exceptions to the order, both one-way: the layout randomiser (in `scenario`) predicts
//! edge contrast with the renderer's shading model and the cell's block shapes, and the
//! simulator judges success with the referee's judge.

pub mod cell;
pub mod events;
pub mod hash;
pub mod pointer;
pub mod referee;
pub mod render;
pub mod run;
pub mod scenario;
pub mod simulator;
pub mod transport;

pub use scenario::{Scenario, ScenarioError};
pub use simulator::{SimError, Simulator};

/// The glam (0.33, the one rapier uses) of every vector and matrix in this crate's API.
pub use glam;
