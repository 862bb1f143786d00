//! One module per subcommand; each has an `Args` struct (clap) and a `run` function.

pub mod batch;
pub mod bench;
#[cfg(feature = "camera")]
pub mod camera;
pub mod daemon;
pub mod domain;
pub mod feed;
pub mod hint;
pub mod monitor;
pub mod plan;
pub mod png;
pub mod record;
pub mod recording;
pub mod report;
pub mod run;
pub mod sim;
pub mod sim_truth;
pub mod snapshot;
pub mod stats;
pub mod telemetry;
pub mod track;
pub mod units;
