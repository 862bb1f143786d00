//! `handeye bench`: one module per measured part. Benchmarks print numbers; tests never
//! assert timings.

use std::path::PathBuf;

use anyhow::Result;
use clap::{Args, Subcommand};

mod transport;
mod tracker;
mod render;
mod planner;
mod pointing;

#[derive(Args)]
pub struct BenchArgs {
    #[command(subcommand)]
    what: BenchWhat,
}

#[derive(Subcommand)]
enum BenchWhat {
    /// Shared-memory transport latency of a 2 x 640x480 GRAY8 stereo sample.
    Transport(transport::TransportArgs),
    /// Tracker update time: one contour and a 4-contour stereo set, on real frames.
    Tracker(tracker::TrackerArgs),
    /// Simulator stereo frames per second in lockstep (physics + render + publish).
    Render(render::RenderArgs),
    /// Planner time per stage on a 640x480 stereo pair.
    Planner(planner::PlannerArgs),
    /// Pointing gesture tracker time per stereo frame (issue 19).
    Pointing(pointing::PointingArgs),
}

pub fn run(args: BenchArgs) -> Result<()> {
    match args.what {
        BenchWhat::Transport(args) => transport::run(args),
        BenchWhat::Tracker(args) => tracker::run(args),
        BenchWhat::Render(args) => render::run(args),
        BenchWhat::Planner(args) => planner::run(args),
        BenchWhat::Pointing(args) => pointing::run(args),
    }
}

/// The real `visp-cube` frames' default folder: `$HANDEYE_DATA/visp-cube`, with
/// `HANDEYE_DATA` defaulting to `../shared/data` (README.md, "Test data"; the tests use the
/// same setting).
fn visp_cube_dir() -> PathBuf {
    let data = std::env::var_os("HANDEYE_DATA").filter(|d| !d.is_empty()).map_or_else(|| PathBuf::from("../shared/data"), PathBuf::from);
    data.join("visp-cube")
}
