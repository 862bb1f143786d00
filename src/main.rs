//! `handeye`: the command-line front end. Each subcommand lives in `src/cli/<name>.rs`.

use anyhow::Result;
use clap::{Parser, Subcommand};

mod cli;

/// Robot grasping guided by uncalibrated stereo vision.
///
/// Frames, robot state and commands move over iceoryx2 shared memory (see wire/README.md), so
/// the simulator and real cameras are interchangeable. Start with `make demo`, or:
///
///   handeye feed --mono --dir ../shared/data/visp-cube --loop &
///   handeye monitor --count 200
#[derive(Parser)]
#[command(name = "handeye", version, about, long_about, propagate_version = true)]
struct Cli {
    /// Log level filter (error, warn, info, debug, trace, or a tracing filter directive).
    #[arg(long, global = true, env = "HANDEYE_LOG", default_value = "warn")]
    log: String,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Publish stereo frames from image files on `handeye/stereo`.
    Feed(cli::feed::FeedArgs),
    // Its help comes from `CameraArgs`'s doc comment.
    #[cfg(feature = "camera")]
    Camera(cli::camera::CameraArgs),
    /// Subscribe to `handeye/stereo` and report rate, gaps, rejections and latency (or, with
    /// --telemetry, show the daemon's telemetry live).
    Monitor(cli::monitor::MonitorArgs),
    /// Record the stereo stream, robot state and telemetry into a folder `feed` replays.
    Record(cli::record::RecordArgs),
    /// Track one polygon through an image sequence with the affine contour tracker.
    Track(cli::track::TrackArgs),
    /// Run the simulator: physics, stereo rendering, robot controller, over shared memory.
    Sim(cli::sim::SimArgs),
    /// Render a scenario's stereo pair to PNGs with ground truth for testing.
    Snapshot(cli::snapshot::SnapshotArgs),
    /// Run the hard-loop daemon against whatever publishes on the services.
    Daemon(cli::daemon::DaemonArgs),
    // `run` and `batch` take their help (summary, details, examples) from their argument
    // structs' doc comments: a doc comment here would replace it.
    Run(cli::run::RunArgs),
    /// Find planar facets in one stereo pair: polygons in both views, 3-D corners.
    Plan(cli::plan::PlanArgs),
    /// Write hint.json for the planar facet at a left-view pixel, from the planner's facets.
    Hint(cli::hint::HintArgs),
    Batch(cli::batch::BatchArgs),
    /// Measure handeye's parts: transport, tracker, render, planner, loop.
    Bench(cli::bench::BenchArgs),
}

fn main() -> Result<()> {
    let cli = Cli::parse();
    init_logging(&cli.log);
    match cli.command {
        Command::Feed(args) => cli::feed::run(args),
        #[cfg(feature = "camera")]
        Command::Camera(args) => cli::camera::run(args),
        Command::Monitor(args) => cli::monitor::run(args),
        Command::Record(args) => cli::record::run(args),
        Command::Track(args) => cli::track::run(args),
        Command::Sim(args) => cli::sim::run(args),
        Command::Snapshot(args) => cli::snapshot::run(args),
        Command::Daemon(args) => cli::daemon::run(args),
        Command::Run(args) => cli::run::run(args),
        Command::Plan(args) => cli::plan::run(args),
        Command::Hint(args) => cli::hint::run(args),
        Command::Batch(args) => cli::batch::run(args),
        Command::Bench(args) => cli::bench::run(args),
    }
}

fn init_logging(filter: &str) {
    let filter = tracing_subscriber::EnvFilter::try_new(filter)
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn"));
    tracing_subscriber::fmt().with_env_filter(filter).with_writer(std::io::stderr).init();
}
