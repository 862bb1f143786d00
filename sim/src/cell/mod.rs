//! The physical work cell: the table and the blocks ([`world`], shaped by [`geometry`]), the
//! 5-DOF arm with its gripper ([`arm`], dimensioned by [`kinematics`]) and the arm's own
//! [`controller`] (or, with an external robot driver, the [`follower`] of the driver's reported
//! pose), stepped by rapier at the scenario's fixed rate.
//!
//! Depends only on the scenario's data (and the wire contract's command and state types, for
//! the controller). Inside: `world` → `arm`, `geometry`; `controller` → `arm`, `kinematics`
//! and `profile` (its motion profile); `follower` → `arm`, `kinematics`; `arm` → `kinematics`; `kinematics` and `profile` depend
//! on nothing of the crate, `geometry` only on the scenario's block kinds.

pub mod arm;
pub mod controller;
pub mod follower;
pub mod geometry;
pub mod kinematics;
pub mod profile;
pub mod world;
