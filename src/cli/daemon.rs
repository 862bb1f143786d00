//! `handeye daemon`: the hard loop against whatever publishes on the services.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use handeye_daemon::observe::service::{run as run_observe, ObserveServiceOptions};
use handeye_daemon::stereo_model::StereoModelFile;
use handeye_daemon::observe::plane::WorkingPlane;
use handeye_daemon::observe::ObserveOptions;
use handeye_daemon::service::{run as run_service, ServiceOptions};
use handeye_daemon::{DaemonConfig, OperatorHint};

use super::domain::DomainArgs;

/// `--help`'s text after the options (the one-line summary lives in main.rs, whose doc
/// comment would replace a struct doc comment here).
const DAEMON_HELP: &str = "\
Run the hard-loop daemon: track the gripper and the target in both views, calibrate,
servo the gripper plate coplanar with the target facet, grasp and lift.

It joins a domain's services (handeye/stereo and handeye/robot/state in,
handeye/robot/command and handeye/telemetry out) and cannot tell a simulator from real
cameras and a robot. It answers every stereo frame with one command stamped with that
frame's id (Hold when there is nothing to do), publishes telemetry every cycle, and stops
the arm with an explicit Stop when a tracker it needs is lost, no frame arrives for
stale_frame_ms (default 100 ms), the camera or robot goes away, or the robot faults.

Phases: acquire_gripper (open/close the jaws, locate the fingers, track the plate) →
calibrate (visit the cage, fit the affine stereo model) → plan (one stereo pair to the
planner on a worker thread, the gripper masked out and still tracked at frame rate:
facets, grasp sites, the site nearest --point-m chosen; skipped with --hint) →
acquire_target (trackers on the chosen facet, or the hint's) → servo (coplanarity,
look-and-move) → grasp → lift → done; or failed / stopped with a reason. Exit status 0
when done, 2 when failed or stopped.

With --observe it only watches: no robot is needed and no command is ever sent (the
command service is not even opened). It acquires the target (and with --gripper-hint
the gripper plate) from the hints, tracks them in both views (the left one with --mono),
checks the views against --stereo-model if given, and publishes telemetry every frame:
corners, confidence, state (a lost track is searched for and picked up when it
reappears), reason, tracker update time. A camera that goes away is reported (\"camera
gone\") within stale_frame_ms, and the daemon waits for it to come back. It ends on
Ctrl-C or SIGTERM (exit 0), or --end-after-gone-s after the camera left; --out writes
observe.json, observe_plot.svg and overlays (acquired, lost, refound, end).

With --observe --plane FILE it also reads the operator's pointing gestures from the frames
(the point phase's gesture tracker, on its own thread; the tracking never waits for it) and
reports where on the working plane the finger points, live: telemetry pointing_* (state,
point, sigma, both views' finger lines), a log line per gesture, observe.json \"pointing\"
(every answer with its sigma, frame id and capture time, every refusal with its reason, the
update time) and overlays (pointed, point_refused: the finger lines and the point). FILE
(TOML) gives four or more points of the working plane, each with its plane coordinates and
its pixel in both views (README, \"Pointing at camera frames\"; an example:
scenarios/planes/point_clutter3.toml). Start with the hand out of view: the first frame is the
scene without it. --hint is then optional; --mono cannot be used (pointing needs both views).

Every time-out and the tracker's time step are camera time: the frames' capture stamps
(a gap in the frame ids is counted as dropped frames; daemon.json \"camera\").

Examples:
  handeye daemon --point-m 0.43,0.05 --out out/report
  handeye daemon --hint out/hint.json --out out/report
  handeye daemon --domain lab --config daemon.toml --point-m 0.40,-0.02,0.06 --json
  # watch a face of the cube, one camera, report into obs/ (stop with Ctrl-C)
  handeye feed --mono --dir ../shared/data/visp-cube --loop &
  handeye daemon --observe --mono --hint top-face.json --out obs
  # two cameras, target and gripper, views checked against a calibrated stereo model
  handeye daemon --observe --hint hint.json --gripper-hint plate.json --stereo-model out/report/stereo_model.json
  # where does the operator point? (the plane's points measured in both views)
  handeye daemon --observe --plane scenarios/planes/point_clutter3.toml --out obs
  handeye monitor --telemetry      # another terminal: the pointed point, live";

/// The daemon's arguments; the help text is [`DAEMON_HELP`].
#[derive(Args)]
#[command(after_help = DAEMON_HELP)]
pub struct DaemonArgs {
    /// Configuration (TOML): gripper model, calibration cage in robot coordinates, gains,
    /// time-outs. Every key is optional (defaults fit the simulator's arm); unknown keys are
    /// errors. `handeye daemon --print-config` shows all of them.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Operator hint (JSON): the target facet's corners in both views and its depth in mm
    /// (`handeye sim --hint-out` writes one; `handeye hint` makes one from a pixel on a
    /// stereo pair). Read once at start-up. With a hint nothing is planned; without one the
    /// daemon plans its own grasp.
    #[arg(long, value_name = "FILE", conflicts_with = "point_m")]
    hint: Option<PathBuf>,
    /// The operator's indicated point on the working plane, robot frame, metres: `X,Y` or
    /// `X,Y,Z` (Z defaults to 0). The plan executes the grasp site whose centre is nearest
    /// it in plan view; without it, the highest site.
    #[arg(long, value_name = "X,Y[,Z]", value_parser = parse_point)]
    point_m: Option<[f64; 3]>,
    /// Report folder: overlay PNGs of both views at key moments (trackers drawn), the plan
    /// (NN_plan.png: facets, grasp sites, the chosen one; plan.json), the servo error plot
    /// (servo_convergence.svg), stereo_model.json (the calibrated camera model, for
    /// --observe --stereo-model) and daemon.json (the outcome). With --observe:
    /// observe.json, observe_plot.svg and overlays (acquired, lost, refound, end; pointed,
    /// point_refused with --plane).
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print the outcome as one JSON object: success, phase_reached, final_phase,
    /// failure_reason, servo_steps, loop_us_p50/p99/max/mean, deadline_misses, cycles,
    /// tracker_update (us_p50/p99/max/mean, cycles: the trackers' own update time), camera
    /// (frames, dropped_frames, bad_stamps, camera_rate_hz, dt_ms_p50/max: from the capture
    /// stamps), calibration (residual_rms_px, epipolar_rms_px, disparity_range_px), target_source
    /// (hint or plan), plan (facets, candidates, chosen site, rejected sites and counts by
    /// reason, planner_ms), planning (frames answered and gripper tracker updates while the
    /// planner worked), servo_trace, wall_s.
    #[arg(long)]
    json: bool,
    /// Print the effective configuration as TOML and exit.
    #[arg(long)]
    print_config: bool,
    /// Observe only: no robot, no commands; track the --hint target (and --gripper-hint
    /// plate), read pointing gestures with --plane, and publish telemetry every frame until
    /// stopped. Needs --hint, --plane or both.
    #[arg(long, conflicts_with = "point_m")]
    observe: bool,
    /// With --observe: the working plane's points (TOML: four or more [[points]], each with
    /// plane_m = [x, y] in metres and its pixel in both views, left_px and right_px;
    /// optional plane_z_m): read the operator's pointing gestures and report the pointed
    /// point live. Needs both views (not --mono).
    #[arg(long, value_name = "FILE", requires = "observe")]
    plane: Option<PathBuf>,
    /// With --observe: the gripper plate's outline in both views (hint.json format; its
    /// depth_mm is not used).
    #[arg(long, value_name = "FILE", requires = "observe")]
    gripper_hint: Option<PathBuf>,
    /// With --observe: the stream's two views are one camera (`feed --mono`, `camera
    /// --mono`): track the left view only (the hint's left_px).
    #[arg(long, requires = "observe")]
    mono: bool,
    /// With --observe: the camera pair's stereo model (stereo_model.json, written by a
    /// calibrated run into its --out folder): the two views' tracks are checked against its
    /// epipolar constraint (telemetry says when they disagree by more than
    /// target.max_epipolar_px; observe.json "epipolar").
    #[arg(long, value_name = "FILE", requires = "observe", conflicts_with = "mono")]
    stereo_model: Option<PathBuf>,
    /// With --observe: end when the camera has been gone this long (the stream ended);
    /// without it, run until Ctrl-C / SIGTERM.
    #[arg(long, value_name = "S", requires = "observe", value_parser = super::units::parse_seconds)]
    end_after_gone_s: Option<f64>,
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
    if args.observe {
        return observe(&args, config, hint);
    }
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

/// `handeye daemon --observe`.
fn observe(args: &DaemonArgs, config: DaemonConfig, hint: Option<OperatorHint>) -> Result<()> {
    if hint.is_none() && args.plane.is_none() {
        anyhow::bail!("--observe needs --hint (a target to track), --plane (pointing gestures to read), or both");
    }
    if args.plane.is_some() && args.mono {
        anyhow::bail!("--plane needs both views (the pointed point is where the finger's lines of the two views meet on the plane): it cannot be used with --mono");
    }
    let plane = args.plane.as_deref().map(WorkingPlane::load).transpose()?;
    let gripper_hint = args.gripper_hint.as_deref().map(OperatorHint::load).transpose()?;
    let epipolar = args.stereo_model.as_deref().map(StereoModelFile::load).transpose()?.map(|m| m.epipolar());
    if !args.json {
        eprintln!("daemon: observing in domain '{}' (no robot, no commands); Ctrl-C ends it", args.domain.domain);
    }
    let result = run_observe(ObserveServiceOptions {
        domain: args.domain.domain.clone(),
        config,
        observe: ObserveOptions { hint, gripper_hint, mono: args.mono, epipolar, plane },
        report_dir: args.out.clone(),
        end_after_gone: args.end_after_gone_s.map(std::time::Duration::from_secs_f64),
    })?;
    for e in &result.report_errors {
        eprintln!("daemon: report: {e}");
    }
    let r = &result.report;
    if args.json {
        println!("{}", serde_json::to_string(r)?);
    } else {
        let trackers: Vec<String> = r
            .trackers
            .iter()
            .map(|t| format!("{} tracked {} lost {} ({} losses, {} re-found)", t.name, t.tracked_frames, t.lost_frames, t.losses.len(), t.refinds.len()))
            .collect();
        // No contour watched (--plane alone): no tracker counts to print.
        let tracking = if trackers.is_empty() {
            String::new()
        } else {
            format!("; {}; tracker update p50 {:.0} µs, p99 {:.0} µs", trackers.join("; "), r.tracker_update.us_p50, r.tracker_update.us_p99)
        };
        println!(
            "daemon: observed {} frames ({}), {} dropped, camera {:.1} frames/s{tracking}",
            r.frames, r.end, r.camera.dropped_frames, r.camera.camera_rate_hz,
        );
        if let Some(p) = &r.pointing {
            let last = p.answered.last().and_then(|g| g.point_m.map(|m| format!(" (the last at ({:.3}, {:.3}) m, sigma {:.1} mm)", m[0], m[1], g.sigma_mm.unwrap_or(f64::NAN))));
            println!(
                "daemon: pointing: {} gesture(s) seen, {} answered{}, {} refused; gesture update p50 {:.0} µs over {} frames ({} not handed over)",
                p.gestures_seen,
                p.answered.len(),
                last.unwrap_or_default(),
                p.refused.len(),
                p.update.us_p50,
                p.update.cycles,
                p.frames_not_submitted
            );
        }
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
