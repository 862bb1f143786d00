//! handeye's daemon: the hard loop that closes hand-eye coordination over shared memory.
//!
//! Per stereo frame ([`hard_loop::HardLoop::cycle`]): update the gripper and target trackers
//! over the frame's pixels in place, check safety, run the current [`phase`], answer the
//! frame with exactly one robot command and publish one telemetry sample. Phases: acquire
//! gripper → calibrate → plan (the grasp planner on one stereo pair, while the gripper stays
//! tracked; skipped when an operator hint names the target) → acquire target → coplanarity
//! servo → grasp → lift → done (or failed / stopped, with a reason). Work longer than a frame runs on a
//! [`worker`] thread; report images are encoded on another ([`report`]). [`service`] runs it
//! all against the `handeye/*` services of a domain, whoever publishes them.

pub mod camera_clock;
pub mod candidate_check;
pub mod config;
pub mod fault;
pub mod gesture_thread;
pub mod gripper;
pub mod hard_loop;
pub mod mission;
pub mod observe;
pub mod outcome;
pub mod phase;
pub mod planning;
pub mod recovery;
pub mod report;
pub mod safety;
pub mod service;
pub mod stereo_model;
pub mod target_outline;
#[cfg(test)]
mod test_cameras;
pub mod servo_plot;
pub mod timing;
pub mod track_search;
pub mod worker;

pub use config::DaemonConfig;
pub use fault::Fault;
pub use hard_loop::{CycleOutput, HardLoop};
pub use handeye_wire::hint::OperatorHint;
pub use outcome::DaemonOutcome;
