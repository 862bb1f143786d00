//! `handeye run`: one closed-loop scenario as two processes (simulator and daemon) in a
//! private shared-memory domain, merged into one verdict.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_daemon::mission::TargetSource;
use handeye_daemon::{DaemonConfig, DaemonOutcome};
use handeye_sim::Scenario;
use handeye_sim::referee::judge::Verdict;
use handeye_sim::referee::report::SimReport;
use handeye_wire::Domain;
use handeye_wire::report::{Failure, FailureKind};

use super::report::{as_json, holds_brief, loss_text, read_report, RunPointing, RunSummary};
use super::units::parse_seconds;

/// Run one closed-loop grasp scenario: `handeye sim SCENARIO --lockstep` and `handeye daemon`
/// as two child processes in a private domain, talking only over shared memory.
///
/// The daemon plans its own grasp (thesis ch. 6): after calibrating it hands one stereo
/// pair to the planner, keeps tracking the gripper meanwhile, and executes the grasp site
/// nearest the operator's indicated point: the scenario's `[task] point_m`, or the named
/// target block's centre (where an operator would point), on the working plane (the lower
/// cage points' height). When the scenario has a [pointer] (an operator's hand that points
/// at the target, e.g. scenarios/point_clutter3.toml) the daemon is given no point: it parks
/// the arm out of the hand's way, watches the gesture in both views and plans for the point
/// it sees (its `point` phase); --point-m X,Y gives it a point instead, and --given-point the
/// scenario's own (the ground-truth operator, as for a scenario without a hand). With --hint
/// it uses the operator hint instead (the target facet
/// clicked in both views, ±3 px per corner, its depth ±2 mm), which the simulator writes
/// before its first frame either way (hint.json).
///
/// The simulator judges the run from ground truth: success (the task's target — the named
/// block, or the block nearest the indicated point — lifted 50 mm and held 2 s); the facet
/// the daemon's target trackers were put on (block, face, whether it is the task's
/// target); at the moment the daemon's telemetry says the servo converged,
/// final_plane_error_mm (distance of the gripper plate's centre from that facet's plane: the
/// servo makes them coplanar) and final_angle_error_deg (angle between the plate's normal,
/// the jaws' closing axis, and the facet's normal). The daemon gets the frames, the robot
/// state, the indicated point (or the hint) and its configuration (the scenario's cage);
/// never ground truth.
///
/// Prints a summary, or with --json one object: success, phase_reached, final_phase,
/// failure_reason (in words), failure (typed: phase, kind, detail; the daemon's own when it
/// gave one, else interrupted (Ctrl-C or --timeout-s), wrong_target, timed_out (the
/// scenario's time-out), process (a child reported nothing) or not_lifted, from what the
/// simulator saw), target_source (plan or hint), target_block, target_graspable and
/// target_ungraspable_reason (the simulator's judge: does the target have a grasp the
/// thesis's rules allow, on its true geometry; why not, in words), targeted_block,
/// targeted_face, indicated_point_m (the task's point: given to the daemon, or the point the
/// hand meant), pointing (with a [pointer] and no point given: aim_m where the hand's line
/// really met the plane, the judge's; indicated_m the daemon's point, null when no gesture
/// was answered; error_mm between them; sigma_mm; gestures and refusals (the daemon's words);
/// pointed_block, the task's target the hand pointed at, and chose_pointed: whether the
/// daemon's target trackers went onto it), plan_candidates, planner_ms, planning_frames,
/// gripper_updates_while_planning, gripper_update_rate_hz (per second of simulated time
/// while the planner worked, as the simulator saw the telemetry), servo_steps, final_plane_error_mm, final_angle_error_deg,
/// grasp_plane_error_mm (jaw-centre plane from the block's mid-plane when the jaws closed),
/// loop_us_p50, loop_us_p99, deadline_misses, calibration_residual_px, sim_frames, wall_s,
/// seed, report (folder or null), recovery (the arm's holds for lost trackers, from
/// daemon.json: recoveries, held_s, recalibrations, moves_refused, and losses, each with
/// its phase, frame id, what (which tracker and why), held_s, search_passes, relapses,
/// outcome (recovered, or why not) and resumed (what the phase did then); null when the
/// daemon reported nothing), held_block_moved (the block moved in the jaws while lifted,
/// in words, from the jaws' opening; null when it held steady).
///
/// The children are always cleaned up: on Ctrl-C, on failure, and after --timeout-s (a hung
/// child is killed). Their stderr is kept in the report folder (sim.stderr.log,
/// daemon.stderr.log). Exit status 0 on success, 2 when the run failed.
///
/// Examples:
///   handeye run scenarios/clutter3.toml --out out/clutter3
///   handeye run scenarios/clutter3.toml --seed 7 --random-layout --json
///   handeye run scenarios/random.toml --seed 7 --randomize --out out/cell7   # a drawn work cell
///   handeye run scenarios/pick_cube.toml --seed 7 --json
///   handeye run scenarios/pick_cube_bump.toml --hint --out out/bump
///   handeye run scenarios/point_clutter3.toml --out out/point    # the operator points
///   handeye run scenarios/point_clutter3.toml --seed 4 --random-layout --given-point --json
#[derive(Args)]
#[command(verbatim_doc_comment)]
pub struct RunArgs {
    /// Scenario file (TOML), e.g. scenarios/pick_cube.toml.
    scenario: PathBuf,
    /// Print one JSON object (see above) instead of the summary.
    #[arg(long)]
    json: bool,
    /// Report folder: overlay PNGs of both views at key moments with the trackers drawn, the
    /// plan (NN_plan.png: facets, grasp sites, the chosen one, the indicated point; plan.json),
    /// servo_convergence.svg, daemon.json, sim.json, run.json, hint.json, daemon.toml, and both
    /// children's stderr. Without it, everything goes to a temporary folder that is removed.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Shared-memory domain for the two processes (default: a fresh private one).
    #[arg(long, value_name = "NAME")]
    domain: Option<Domain>,
    /// Seed: randomises the target block's pose (±20 mm, ±15°), the sensor noise and the
    /// hint's errors. Default: the scenario as written.
    #[arg(long)]
    seed: Option<u64>,
    /// With --seed: a random layout of all the blocks instead (see `handeye sim --help`);
    /// with an indicated point, a random target with the point within 15 mm of it.
    #[arg(long, requires = "seed")]
    random_layout: bool,
    /// With --seed: draw the whole work cell from the scenario's [randomize] ranges (see
    /// `handeye sim --help` and scenarios/random.toml).
    #[arg(long, requires = "seed", conflicts_with = "random_layout")]
    randomize: bool,
    /// With --seed: one seeded random disturbance at a random moment (a camera knock, a
    /// target nudge, a light change or an occluder; see `handeye sim --help`).
    #[arg(long, requires = "seed")]
    disturb: bool,
    /// Give the daemon the operator hint (the target facet clicked in both views) instead of
    /// letting it plan its own grasp.
    #[arg(long)]
    hint: bool,
    /// The operator's indicated point for the daemon, robot frame, metres: `X,Y` (on the
    /// working plane, the lowest cage points' height) or `X,Y,Z`. Overrides the scenario's
    /// point, and the pointing hand's gesture: the daemon does not wait for one.
    #[arg(long, value_name = "X,Y[,Z]", conflicts_with_all = ["hint", "given_point"], value_parser = super::daemon::parse_point)]
    point_m: Option<[f64; 3]>,
    /// With a [pointer] scenario: give the daemon the scenario's own indicated point (the
    /// ground truth an operator would mean) instead of letting it watch the gesture.
    #[arg(long, conflicts_with = "hint")]
    given_point: bool,
    /// Daemon configuration (TOML) to start from; the scenario's cage replaces its
    /// calibration.cage_m.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Kill both children after this many seconds of wall time.
    #[arg(long, default_value_t = 300.0, value_name = "S", value_parser = parse_seconds)]
    timeout_s: f64,
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// A child that is killed (SIGTERM, then SIGKILL) when dropped, unless it has exited.
struct Guarded {
    name: &'static str,
    child: Option<Child>,
    status: Option<std::process::ExitStatus>,
}

impl Guarded {
    fn poll(&mut self) -> Option<std::process::ExitStatus> {
        if self.status.is_none()
            && let Some(c) = self.child.as_mut()
            && let Ok(Some(s)) = c.try_wait()
        {
            self.status = Some(s);
        }
        self.status
    }

    /// Asks the child to finish (SIGTERM: both children stop cleanly and write their
    /// results), then kills it if it is still there after `grace`.
    fn stop(&mut self, grace: Duration) {
        if self.poll().is_some() {
            return;
        }
        let Some(pid) = self.child.as_ref().map(|c| c.id()) else { return };
        // SAFETY: kill(2) on our own child's pid, which has not been reaped yet.
        unsafe { libc::kill(pid as libc::pid_t, libc::SIGTERM) };
        let until = Instant::now() + grace;
        while Instant::now() < until {
            if self.poll().is_some() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        if let Some(c) = self.child.as_mut() {
            eprintln!("run: {} did not stop in {:.1} s; killing it", self.name, grace.as_secs_f64());
            let _ = c.kill();
            self.status = c.wait().ok();
        }
    }
}

impl Drop for Guarded {
    fn drop(&mut self) {
        self.stop(Duration::from_secs(2));
    }
}

fn spawn(name: &'static str, args: &[String], dir: &Path) -> Result<Guarded> {
    let exe = std::env::current_exe().context("finding the handeye executable")?;
    let stderr = std::fs::File::create(dir.join(format!("{name}.stderr.log")))?;
    let stdout = std::fs::File::create(dir.join(format!("{name}.stdout.log")))?;
    let child = Command::new(exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(stderr)
        .spawn()
        .with_context(|| format!("starting the {name}"))?;
    Ok(Guarded { name, child: Some(child), status: None })
}

fn tail(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap_or_default();
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    lines[lines.len().saturating_sub(5)..].join("\n")
}

pub fn run(args: RunArgs) -> Result<()> {
    let scenario = Scenario::load(&args.scenario)?;
    let start = Instant::now();
    // SAFETY: installs an async-signal-safe handler that only stores to an atomic.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t);
    }
    let temp = args.out.is_none();
    let dir = args.out.clone().unwrap_or_else(|| std::env::temp_dir().join(format!("handeye-run-{}", std::process::id())));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    for stale in ["hint.json", "hint.json.none", "sim.json", "daemon.json", "run.json"] {
        let _ = std::fs::remove_file(dir.join(stale));
    }
    let result = run_in(&args, &scenario, &dir, start);
    if temp {
        let _ = std::fs::remove_dir_all(&dir);
    }
    let summary = result?;
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print_summary(&summary);
    }
    if !summary.success {
        std::process::exit(2);
    }
    Ok(())
}

/// How long the daemon of a run may hold a frame's answer for a due worker result, ms
/// (`timing.worker_wait_ms`); the simulator waits twice that for an answer.
const WORKER_WAIT_MS: u64 = 5000;

fn run_in(args: &RunArgs, scenario: &Scenario, dir: &Path, start: Instant) -> Result<RunSummary> {
    let mut config = match &args.config {
        Some(p) => DaemonConfig::load(p)?,
        None => DaemonConfig::default(),
    };
    config.calibration.cage_m = scenario.cage.points_m.clone();
    config.timing.frame_rate_hz = f64::from(scenario.render.frame_rate_hz);
    // Lockstep: the simulator renders frame N+1 only after the daemon answered frame N, so a
    // slow render on a loaded machine is not a stale camera (2 s was exceeded once on the
    // 2-core machine with other builds running). A simulator that is gone is still
    // noticed within ~100 ms by the stream's liveness check.
    config.timing.stale_frame_ms = config.timing.stale_frame_ms.max(5000);
    // For the same reason a worker result that is due is waited for (up to 5 s, within the
    // simulator's reply time-out below) rather than taken a few frames later than on a quiet
    // machine: the same seed gives the same run under any load.
    config.timing.worker_wait_ms = config.timing.worker_wait_ms.max(WORKER_WAIT_MS);
    config.validate(&dir.join("daemon.toml"))?;
    std::fs::write(dir.join("daemon.toml"), config.to_toml())?;
    let domain = args.domain.clone().unwrap_or_else(|| Domain::unique("run"));
    let s = |p: &Path| p.display().to_string();
    let mut sim_args = vec![
        "sim".to_string(),
        s(&args.scenario),
        "--lockstep".into(),
        "--domain".into(),
        domain.to_string(),
        "--hint-out".into(),
        s(&dir.join("hint.json")),
        "--verdict-out".into(),
        s(&dir.join("sim.json")),
        "--wait-daemon-s".into(),
        "60".into(),
        "--reply-timeout-s".into(),
        (2 * WORKER_WAIT_MS / 1000).to_string(),
        "--json".into(),
    ];
    if let Some(seed) = args.seed {
        sim_args.extend(["--seed".into(), seed.to_string()]);
        if args.random_layout {
            sim_args.push("--random-layout".into());
        }
        if args.randomize {
            sim_args.push("--randomize".into());
        }
        if args.disturb {
            sim_args.push("--disturb".into());
        }
    }
    // The indicated point as the simulator will lay the scene out (the same seeded code).
    let mut laid_out = scenario.clone();
    super::sim::lay_out(&mut laid_out, &args.scenario, args.seed, args.random_layout, args.randomize, args.disturb)?;
    let task_point = laid_out.indicated_point_m();
    // `X,Y` given: on the working plane (parse_point leaves z at 0 for two numbers).
    let given = args.point_m.map(|p| if p[2] == 0.0 { [p[0], p[1], task_point[2]] } else { p });
    // The daemon watches the operator's hand unless it is given a point or a hint.
    let pointing = laid_out.pointer.is_some() && !args.hint && given.is_none() && !args.given_point;
    let point = given.unwrap_or(task_point);
    let mut sim = spawn("sim", &sim_args, dir)?;
    let deadline = start + Duration::from_secs_f64(args.timeout_s);
    // The hint appears once the simulator has built the scene (before its first frame).
    let no_hint = super::sim::no_hint_path(&dir.join("hint.json"));
    while !dir.join("hint.json").exists() && !no_hint.exists() {
        if sim.poll().is_some() {
            bail!("the simulator exited before writing the hint:\n{}", tail(&dir.join("sim.stderr.log")));
        }
        if INTERRUPTED.load(Ordering::SeqCst) || Instant::now() > deadline {
            bail!("interrupted before the simulator was ready");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut daemon_args = vec![
        "daemon".to_string(),
        "--domain".into(),
        domain.to_string(),
        "--config".into(),
        s(&dir.join("daemon.toml")),
        "--out".into(),
        s(dir),
        "--json".into(),
    ];
    if args.hint {
        if no_hint.exists() {
            bail!("--hint: there is no hint to give: {}", std::fs::read_to_string(&no_hint).unwrap_or_default().trim());
        }
        daemon_args.extend(["--hint".into(), s(&dir.join("hint.json"))]);
    } else if !pointing {
        daemon_args.extend(["--point-m".into(), format!("{},{},{}", point[0], point[1], point[2])]);
    }
    let mut daemon = spawn("daemon", &daemon_args, dir)?;
    let mut note = None;
    loop {
        let (d, m) = (daemon.poll(), sim.poll());
        if d.is_some() && m.is_some() {
            break;
        }
        if INTERRUPTED.load(Ordering::SeqCst) {
            note = Some("interrupted".to_string());
            break;
        }
        if Instant::now() > deadline {
            note = Some(format!("timed out after {:.0} s of wall time", args.timeout_s));
            break;
        }
        if let Some(status) = d {
            // The simulator stops by itself on success; otherwise it would step on alone
            // until its time-out, so it is stopped at once when the daemon did not succeed.
            let wait = if status.success() { Duration::from_secs(10) } else { Duration::ZERO };
            let grace = Instant::now() + wait;
            while sim.poll().is_none() && Instant::now() < grace {
                std::thread::sleep(Duration::from_millis(20));
            }
            break;
        }
        if m.is_some() {
            // The daemon notices the camera stream is gone within a few hundred ms.
            let grace = Instant::now() + Duration::from_secs(5);
            while daemon.poll().is_none() && Instant::now() < grace {
                std::thread::sleep(Duration::from_millis(20));
            }
            break;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    daemon.stop(Duration::from_secs(3));
    sim.stop(Duration::from_secs(5));
    let wall_s = start.elapsed().as_secs_f64();
    if args.domain.is_none() {
        // A private domain: nobody else uses its files.
        let _ = handeye_wire::domain::remove_domain_files(&domain);
    }
    let d: Option<DaemonOutcome> = read_if_written(&dir.join("daemon.json"))?;
    let v: Option<SimReport> = read_if_written(&dir.join("sim.json"))?;
    if d.is_none() && v.is_none() {
        bail!(
            "neither child reported{}:\nsim: {}\ndaemon: {}",
            note.map(|n| format!(" ({n})")).unwrap_or_default(),
            tail(&dir.join("sim.stderr.log")),
            tail(&dir.join("daemon.stderr.log"))
        );
    }
    let success = v.as_ref().is_some_and(|v| v.success);
    let failure = if success { None } else { Some(failure(d.as_ref(), v.as_ref(), note, dir)) };
    let watch = v.as_ref().map(|v| &v.daemon);
    let targeted = watch.and_then(|w| w.targeted.as_ref());
    let converged = watch.and_then(|w| w.converged.as_ref());
    let grasped = watch.and_then(|w| w.grasped.as_ref());
    let plan = d.as_ref().and_then(|d| d.task.plan.as_ref());
    let planning = d.as_ref().and_then(|d| d.task.planning.as_ref());
    let summary = RunSummary {
        scenario: scenario.name.clone(),
        success,
        phase_reached: d.as_ref().map(|d| d.end.phase_reached.clone()),
        final_phase: d.as_ref().map(|d| d.end.final_phase.clone()),
        failure_reason: failure.as_ref().map(|f| f.detail.clone()),
        failure,
        target_source: d.as_ref().and_then(|d| d.task.target_source),
        target_block: v.as_ref().map(|v| v.target.clone()),
        target_graspable: v.as_ref().map(|v| v.target_graspability.graspable),
        target_ungraspable_reason: v.as_ref().and_then(|v| v.target_graspability.reason.clone()),
        targeted_block: targeted.map(|t| t.block.clone()),
        targeted_face: targeted.map(|t| t.face.clone()),
        indicated_point_m: point,
        pointing: pointing.then(|| run_pointing(d.as_ref(), v.as_ref(), targeted.map(|t| t.block.as_str()))),
        plan_facets: plan.map(|p| p.scene.facets.len()),
        plan_candidates: plan.map(|p| p.sites.candidates.len()),
        plan_width_mm: plan.and_then(|p| p.sites.chosen.as_ref()).map(|c| c.grasp.width_mm),
        planner_ms: planning.map(|p| p.planner_ms),
        planning_frames: planning.map(|p| p.frames),
        gripper_updates_while_planning: planning.map(|p| p.gripper_updates),
        gripper_update_rate_hz: watch.map(|w| w.plan.gripper_update_rate_hz),
        servo_steps: d.as_ref().map(|d| d.end.servo_steps),
        final_plane_error_mm: converged.map(|c| c.final_plane_error_mm),
        final_angle_error_deg: converged.map(|c| c.final_angle_error_deg),
        grasp_plane_error_mm: grasped.map(|g| g.jaw_plane_offset_mm.abs()),
        grasp_lateral_error_mm: grasped.map(|g| g.lateral_error_mm),
        loop_us_p50: d.as_ref().map(|d| d.timing.loop_us_p50),
        loop_us_p99: d.as_ref().map(|d| d.timing.loop_us_p99),
        loop_us_max: d.as_ref().map(|d| d.timing.loop_us_max),
        deadline_misses: d.as_ref().map(|d| d.timing.deadline_misses),
        calibration_residual_px: d.as_ref().and_then(|d| d.task.calibration.as_ref()).map(|c| c.residual_rms_px),
        max_lift_mm: v.as_ref().map(|v| v.max_lift_mm),
        sim_frames: v.as_ref().map(|v| v.frames),
        sim_time_s: v.as_ref().map(|v| v.sim_time_s),
        wall_s,
        seed: v.as_ref().map(|v| v.seed),
        domain: domain.to_string(),
        report: args.out.is_some().then(|| dir.display().to_string()),
        recovery: d.as_ref().map(|d| d.task.holds.clone()),
        held_block_moved: d.as_ref().and_then(|d| d.task.held_block_moved.clone()),
    };
    std::fs::write(dir.join("run.json"), serde_json::to_string_pretty(&summary)?)?;
    Ok(summary)
}

/// The pointing of a run where the daemon watched the operator's hand: what it answered
/// against where the hand really aimed (the judge's), and whether it went for that block.
fn run_pointing(d: Option<&DaemonOutcome>, v: Option<&SimReport>, targeted_block: Option<&str>) -> RunPointing {
    let p = d.and_then(|d| d.task.pointing.as_ref());
    let indicated_m = p.and_then(|p| p.indicated_m);
    let answer = p.and_then(|p| p.gestures.iter().find(|g| g.outcome == "indicated"));
    // The gesture answered: the one whose hold was on when the answer's frame was taken
    // (frame ids count simulated frames from 0); without an answer, the last one.
    let gestures: Vec<&handeye_sim::pointer::PointerTruth> = v.map(|v| v.pointer_earlier.iter().chain(v.pointer.as_ref()).collect()).unwrap_or_default();
    let frame_s = |id: u64| v.filter(|v| v.frames > 0).map_or(f64::NAN, |v| id as f64 * v.sim_time_s / v.frames as f64);
    let answered = answer.and_then(|a| gestures.iter().find(|g| (g.hold_s[0]..=g.hold_s[1] + 1.0).contains(&frame_s(a.frame_id))));
    let aim_m = answered.or(gestures.last()).map(|g| g.aim_m);
    let pointed_block = v.map(|v| v.target.clone());
    RunPointing {
        aim_m,
        indicated_m,
        error_mm: aim_m.zip(indicated_m).map(|(a, i)| (a[0] - i[0]).hypot(a[1] - i[1]) * 1e3),
        sigma_mm: answer.and_then(|g| g.sigma_mm),
        gestures: p.map_or(0, |p| p.gestures.len()),
        refusals: p.map(|p| p.gestures.iter().filter(|g| g.outcome != "indicated").map(|g| format!("{}: {}", g.outcome, g.detail)).collect()).unwrap_or_default(),
        chose_pointed: targeted_block.zip(pointed_block.as_deref()).map(|(t, p)| t == p),
        pointed_block,
        update_us_p50: p.map(|p| p.update_us_p50),
    }
}

/// A child's report, `None` when it wrote none; one that is there but does not read is an
/// error naming the file and the field.
fn read_if_written<T: serde::de::DeserializeOwned>(path: &Path) -> Result<Option<T>> {
    if path.exists() { read_report(path).map(Some) } else { Ok(None) }
}

/// Why a run failed: the daemon's own failure when it gave one, else what the run itself saw
/// (`note`: it was interrupted or ran out of wall time), else the simulator's judgement.
/// The phase is the daemon's furthest one (`run` when it reported nothing).
fn failure(d: Option<&DaemonOutcome>, v: Option<&SimReport>, note: Option<String>, dir: &Path) -> Failure {
    let phase = d.map_or("run", |d| d.end.phase_reached.as_str());
    if let Some(d) = d {
        if let Some(f) = &d.end.failure {
            return f.clone();
        }
        if let Some(r) = &d.end.failure_reason {
            return Failure::new(phase, FailureKind::Internal, r.clone());
        }
    }
    if let Some(n) = note {
        return Failure::new(phase, FailureKind::Interrupted, n);
    }
    if let Some(v) = v
        && let Some(t) = v.daemon.targeted.as_ref().filter(|t| !t.is_task_target)
    {
        return Failure::new(phase, FailureKind::WrongTarget, format!("the daemon went for block '{}', not the target '{}'", t.block, v.target));
    }
    if v.is_some_and(|v| v.verdict == Verdict::TimedOut) {
        return Failure::new(phase, FailureKind::TimedOut, "the scenario timed out before the target was lifted and held");
    }
    if d.is_none() {
        return Failure::new(phase, FailureKind::Process, format!("the daemon reported nothing: {}", tail(&dir.join("daemon.stderr.log"))));
    }
    Failure::new(phase, FailureKind::NotLifted, "the target was not lifted and held (ground truth)")
}

/// The arm's holds for lost trackers: each loss, its search and how it ended (issue 18).
fn print_holds(h: &handeye_daemon::outcome::HoldRecord) {
    if let Some(brief) = holds_brief(h) {
        println!("  holds: {brief}");
    }
    for l in &h.losses {
        println!("    {}", loss_text(l));
    }
}

fn print_summary(s: &RunSummary) {
    let num = |x: Option<f64>, unit: &str| x.map_or("n/a".to_string(), |x| format!("{x:.2}{unit}"));
    let name = |x: &Option<String>| x.clone().unwrap_or_else(|| "?".to_string());
    println!(
        "{}: {} (phase reached: {}){}",
        s.scenario,
        if s.success { "SUCCESS" } else { "FAILED" },
        name(&s.phase_reached),
        s.failure_reason.as_ref().map(|r| format!(": {r}")).unwrap_or_default()
    );
    if s.target_source == Some(TargetSource::Plan) {
        println!(
            "  plan: {} facets, {} grasp candidates, chosen {} mm wide on block '{}' (face {}; the target is '{}'); planner {}, {} frames answered meanwhile, gripper tracked {} times ({} Hz)",
            as_json(&s.plan_facets),
            as_json(&s.plan_candidates),
            num(s.plan_width_mm, ""),
            name(&s.targeted_block),
            name(&s.targeted_face),
            name(&s.target_block),
            num(s.planner_ms, " ms"),
            as_json(&s.planning_frames),
            as_json(&s.gripper_updates_while_planning),
            as_json(&s.gripper_update_rate_hz)
        );
    }
    if let Some(p) = &s.pointing {
        let mm = |v: Option<[f64; 3]>| v.map_or("none".to_string(), |v| format!("({:.3}, {:.3}) m", v[0], v[1]));
        println!(
            "  pointing: indicated {} (hand aimed at {}; {} off, sigma {}), {} gesture(s){}; went for {} (pointed at '{}')",
            mm(p.indicated_m),
            mm(p.aim_m),
            num(p.error_mm, " mm"),
            num(p.sigma_mm, " mm"),
            p.gestures,
            if p.refusals.is_empty() { String::new() } else { format!(", refused: {}", p.refusals.join("; ")) },
            match p.chose_pointed {
                Some(true) => "the pointed block",
                Some(false) => "ANOTHER block",
                None => "no block",
            },
            name(&p.pointed_block)
        );
    }
    println!(
        "  servo: {} steps; at convergence plate {} off the facet plane, {} off parallel; jaws {} off the block's mid-plane",
        as_json(&s.servo_steps),
        num(s.final_plane_error_mm, " mm"),
        num(s.final_angle_error_deg, "°"),
        num(s.grasp_plane_error_mm, " mm")
    );
    println!(
        "  loop: p50 {}, p99 {}, {} deadline misses; calibration residual {}; {} frames, {}",
        num(s.loop_us_p50, " µs"),
        num(s.loop_us_p99, " µs"),
        as_json(&s.deadline_misses),
        num(s.calibration_residual_px, " px"),
        as_json(&s.sim_frames),
        num(Some(s.wall_s), " s wall")
    );
    if let Some(h) = s.recovery.as_ref() {
        print_holds(h);
    }
    if let Some(words) = &s.held_block_moved {
        println!("  lift: {words}");
    }
    if let Some(r) = &s.report {
        println!("  report: {r}");
    }
}
