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
/// calibrate (visit the cage, fit the affine stereo model) → plan (one stereo pair to the
/// planner on a worker thread, the gripper masked out and still tracked at frame rate:
/// facets, grasp sites, the site nearest --point-m chosen; skipped with --hint) →
/// acquire_target (trackers on the chosen facet, or the hint's) → servo (coplanarity,
/// look-and-move) → grasp → lift → done; or failed / stopped with a reason. Exit status 0
/// when done, 2 when failed or stopped.
///
/// Examples:
///   handeye daemon --point-m 0.43,0.05 --out out/report
///   handeye daemon --hint out/hint.json --out out/report
///   handeye daemon --domain lab --config daemon.toml --point-m 0.40,-0.02,0.06 --json
#[derive(Args)]
pub struct DaemonArgs {
    /// Configuration (TOML): gripper model, calibration cage in robot coordinates, gains,
    /// time-outs. Every key is optional (defaults fit the simulator's arm); unknown keys are
    /// errors. `handeye daemon --print-config` shows all of them.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Operator hint (JSON): the target facet's corners in both views and its depth in mm
    /// (`handeye sim --hint-out` writes one). Read once at start-up. With a hint nothing is
    /// planned; without one the daemon plans its own grasp.
    #[arg(long, value_name = "FILE", conflicts_with = "point_m")]
    hint: Option<PathBuf>,
    /// The operator's indicated point on the working plane, robot frame, metres: `X,Y` or
    /// `X,Y,Z` (Z defaults to 0). The plan executes the grasp site whose centre is nearest
    /// it in plan view; without it, the highest site.
    #[arg(long, value_name = "X,Y[,Z]", value_parser = parse_point)]
    point_m: Option<[f64; 3]>,
    /// Report folder: overlay PNGs of both views at key moments (trackers drawn), the plan
    /// (NN_plan.png: facets, grasp sites, the chosen one; plan.json), the servo error plot
    /// (servo_convergence.svg) and daemon.json (the outcome).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print the outcome as one JSON object: success, phase_reached, final_phase,
    /// failure_reason, servo_steps, loop_us_p50/p99/max/mean, deadline_misses, cycles,
    /// tracker_update (us_p50/p99/max/mean, cycles: the trackers' own update time), calibration (residual_rms_px, epipolar_rms_px, disparity_range_px), target_source
    /// (hint or plan), plan (facets, candidates, chosen site, rejected sites and counts by
    /// reason, planner_ms), planning (frames answered and gripper tracker updates while the
    /// planner worked), servo_trace, wall_s.
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
    let result = run_service(ServiceOptions {
        domain: args.domain.domain.clone(),
        config,
        hint,
        indicated_point_m: args.point_m,
        report_dir: args.out.clone(),
    })?;
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
            "daemon: {} (reached {}){}; {} servo steps; loop p50 {:.0} µs, p99 {:.0} µs, {} deadline misses in {} cycles; tracker update p50 {:.0} µs, p99 {:.0} µs",
            o.end.final_phase,
            o.end.phase_reached,
            o.end.failure_reason.as_ref().map(|r| format!(": {r}")).unwrap_or_default(),
            o.end.servo_steps,
            o.timing.loop_us_p50,
            o.timing.loop_us_p99,
            o.timing.deadline_misses,
            o.timing.cycles,
            o.timing.tracker_update.us_p50,
            o.timing.tracker_update.us_p99
        );
    }
    if !o.end.success {
        std::process::exit(2);
    }
    Ok(())
}

/// `X,Y` or `X,Y,Z` in metres.
pub fn parse_point(text: &str) -> Result<[f64; 3], String> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    if !(2..=3).contains(&parts.len()) {
        return Err(format!("'{text}': expected X,Y or X,Y,Z in metres"));
    }
    let mut p = [0.0; 3];
    for (i, s) in parts.iter().enumerate() {
        p[i] = s.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or_else(|| format!("'{s}' in '{text}' is not a number of metres"))?;
    }
    Ok(p)
}
