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
//!
//! Every process joins a [`Domain`] through one [`WireNode`]; the typed ports are
//! [`stereo::StereoPublisher`] / [`stereo::StereoSubscriber`] for frames and
//! [`message::MessagePublisher`] / [`message::MessageSubscriber`] for the fixed-size messages.
//! Receivers validate every sample and count what they reject; subscribers wait on an event
//! service (no polling) and notice a publisher that exits or dies.

pub mod checksum;
pub mod domain;
pub mod hint;
mod liveness;
pub mod message;
pub mod report;
pub mod services;
pub mod stereo;
pub mod types;

pub use domain::{Domain, DomainError, NodeError, WireNode, DEFAULT_DOMAIN, DOMAIN_ENV};
pub use liveness::LivenessChange;
pub use services::LIVENESS_PERIOD;
pub use types::*;
