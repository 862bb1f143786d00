//! `handeye daemon`: the hard loop against whatever publishes on the services.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use handeye_daemon::service::{run as run_service, ServiceOptions};
use handeye_daemon::{DaemonConfig, OperatorHint};

use super::domain::DomainArgs;

/// Run the hard-loop daemon: track the gripper and the target in both views, calibrate,
/// servo the gripper plate coplanar with the target facet, grasp and lift.
///
/// It joins a domain's services (handeye/stereo and handeye/robot/state in,
/// handeye/robot/command and handeye/telemetry out) and cannot tell a simulator from real
/// cameras and a robot. It answers every stereo frame with one command stamped with that
/// frame's id (Hold when there is nothing to do), publishes telemetry every cycle, and stops
/// the arm with an explicit Stop when a tracker it needs is lost, no frame arrives for
/// stale_frame_ms (default 100 ms), the camera or robot goes away, or the robot faults.
///
/// Phases: acquire_gripper (open/close the jaws, locate the fingers, track the plate) →
/// calibrate (visit the cage, fit the affine stereo model) → acquire_target (trackers on the
/// operator hint's facet) → servo (coplanarity, look-and-move) → grasp → lift → done; or
/// failed / stopped with a reason. Exit status 0 when done, 2 when failed or stopped.
///
/// Examples:
///   handeye daemon --hint out/hint.json --out out/report
///   handeye daemon --domain lab --config daemon.toml --hint hint.json --json
#[derive(Args)]
pub struct DaemonArgs {
    /// Configuration (TOML): gripper model, calibration cage in robot coordinates, gains,
    /// time-outs. Every key is optional (defaults fit the simulator's arm); unknown keys are
    /// errors. `handeye daemon --print-config` shows all of them.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Operator hint (JSON): the target facet's corners in both views and its depth in mm
    /// (`handeye sim --hint-out` writes one). Read once at start-up.
    #[arg(long, value_name = "FILE")]
    hint: Option<PathBuf>,
    /// Report folder: overlay PNGs of both views at key moments (trackers drawn), the servo
    /// error plot (servo_error.png) and daemon.json (the outcome).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print the outcome as one JSON object: success, phase_reached, final_phase,
    /// failure_reason, servo_steps, loop_us_p50/p99/max/mean, deadline_misses, cycles,
    /// calibration (residual_rms_px, epipolar_rms_px, disparity_range_px), servo_trace, wall_s.
    #[arg(long)]
    json: bool,
    /// Print the effective configuration as TOML and exit.
    #[arg(long)]
    print_config: bool,
    #[command(flatten)]
    domain: DomainArgs,
}

pub fn run(args: DaemonArgs) -> Result<()> {
    let config = match &args.config {
        Some(path) => DaemonConfig::load(path)?,
        None => DaemonConfig::default(),
    };
    if args.print_config {
        print!("{}", config.to_toml());
        return Ok(());
    }
    let hint = args.hint.as_deref().map(OperatorHint::load).transpose()?;
    if !args.json {
        eprintln!("daemon: waiting for frames in domain '{}'", args.domain.domain);
    }
    let result = run_service(ServiceOptions { domain: args.domain.domain.clone(), config, hint, report_dir: args.out.clone() })?;
    let o = &result.outcome;
    if let Some(dir) = &args.out {
        let path = dir.join("daemon.json");
        std::fs::write(&path, serde_json::to_string_pretty(o)?).with_context(|| format!("writing {}", path.display()))?;
    }
    for e in &result.report_errors {
        eprintln!("daemon: report: {e}");
    }
    if args.json {
        println!("{}", serde_json::to_string(o)?);
    } else {
        println!(
            "daemon: {} (reached {}){}; {} servo steps; loop p50 {:.0} µs, p99 {:.0} µs, {} deadline misses in {} cycles",
            o.final_phase,
            o.phase_reached,
            o.failure_reason.as_ref().map(|r| format!(": {r}")).unwrap_or_default(),
            o.servo_steps,
            o.loop_us_p50,
            o.loop_us_p99,
            o.deadline_misses,
            o.cycles
        );
    }
    if !o.success {
        std::process::exit(2);
    }
    Ok(())
}
