//! handeye's shared-memory wire contract.
//!
//! Four iceoryx2 services connect the processes of handeye (see `wire/README.md` for the
//! contract in full, written for someone who writes a camera or robot driver):
//!
//! | service | payload | from → to |
//! | --- | --- | --- |
//! | `handeye/stereo` | `[u8]` + [`StereoHeader`] | cameras (or the simulator) → daemon |
//! | `handeye/robot/state` | [`RobotState`] | robot controller → daemon |
//! | `handeye/robot/command` | [`RobotCommand`] | daemon → robot controller |
//! | `handeye/telemetry` | [`Telemetry`] | daemon → anyone |

pub mod types;

pub use types::*;
