//! `handeye sim`: run the simulator.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::Args;
use handeye_sim::referee::judge::Verdict;
use handeye_sim::referee::report::{LaidOutBlock, SimDriver, SimMode, SimReport};
use handeye_sim::run::{Driver, RunOptions, Runner, run_lockstep, run_realtime};
use handeye_sim::referee::script::GroundTruthPick;
use handeye_sim::transport::{RobotSide, WireTransport};
use handeye_sim::{Scenario, Simulator};

use super::domain::DomainArgs;
use super::units::parse_seconds;

/// Run the simulator: physics, the robot's controller and stereo rendering.
///
/// Publishes one GRAY8 stereo sample per frame on handeye/stereo and the robot state (every
/// control tick) on handeye/robot/state, and takes commands from handeye/robot/command, like
/// a real camera pair and robot would (see wire/README.md). Ground truth stays inside; the
/// success verdict is printed at the end.
///
/// Modes:
///   --lockstep   publish frame N, wait for the daemon's command stamped N (or
///                --reply-timeout-s), then step physics one frame period; with no daemon
///                attached it steps straight on. Bit-identical frames for a seed.
///   (default)    real time: frames at the scenario's camera rate, stamped with their
///                capture time; commands act at the next physics step.
///
/// With --robot external the simulator is the camera pair only: a robot driver serves the
/// robot services (README, "Connecting a real robot") and the simulator renders the arm where
/// the driver's state says.
///
/// Examples:
///   handeye sim scenarios/pick_cube.toml --lockstep --frames 100 --json
///   handeye sim scenarios/pick_cube_bump.toml
///   cargo run -p handeye-wire --example robot_driver -- --home 0.30,0,0.25 --home-yaw-deg -90 &
///   handeye sim scenarios/pick_cube.toml --robot external
#[derive(Args)]
pub struct SimArgs {
    /// Scenario file (TOML), e.g. scenarios/pick_cube.toml.
    scenario: PathBuf,
    /// Lockstep with the daemon instead of real time.
    #[arg(long)]
    lockstep: bool,
    /// Stop after this many frames (default: run until success, or the scenario's time-out).
    #[arg(long)]
    frames: Option<u64>,
    /// Without --frames, keep running after success until the scenario's time-out.
    #[arg(long)]
    no_stop_on_success: bool,
    /// Lockstep: longest wait for the daemon's command for a frame, seconds.
    #[arg(long, default_value_t = 1.0, value_name = "S", value_parser = parse_seconds)]
    reply_timeout_s: f64,
    /// Drive the arm with a scripted pick that reads the target's pose from ground truth
    /// (open, approach, descend, close, lift 70 mm, hold). A physics demo, not vision: it
    /// shows the arm and gripper can pick the block; the daemon has to find it with cameras.
    /// Its command answers every frame, so no daemon is waited for.
    #[arg(long)]
    scripted_pick: bool,
    /// Print one JSON object at the end: frames, fps, frames_hash (a hash over every
    /// published pixel, hex), commands, reply_timeouts, verdict, daemon (what the daemon's
    /// telemetry claimed, judged from ground truth: phases, converged placement with
    /// final_plane_error_mm and final_angle_error_deg, stop frame), and more.
    #[arg(long)]
    json: bool,
    /// Use this seed for every random choice (noise, hint errors) and move the target block
    /// by a seeded random shift (±20 mm in x and y) and turn (±15°). Default: the scenario's
    /// seed and block poses as written.
    #[arg(long)]
    seed: Option<u64>,
    /// With --seed: a random layout of all the scenario's blocks instead (positions in
    /// x 0.27..0.45 m with the whole block inside, y -0.15..0.15 m, at least 60 mm
    /// between their bounding circles; kinds, sizes and shades as written; any yaw, drawn
    /// once). A task with an indicated point gets a random target and the point within
    /// 15 mm of it. What `handeye batch` runs.
    #[arg(long, requires = "seed")]
    random_layout: bool,
    /// With --seed: draw the whole work cell from the scenario's [randomize] ranges (or the
    /// defaults): cameras, light, shades, 2-5 blocks of every kind, noise, blur and the
    /// indicated point (see scenarios/random.toml). What `handeye batch --randomize` runs.
    #[arg(long, requires = "seed", conflicts_with = "random_layout")]
    randomize: bool,
    /// With --seed: add one seeded random disturbance at a random moment (6-30 s): a camera
    /// knocked 1.5-3°, the target nudged 20-30 mm and 10-20°, the light scaled 0.7-1.3, or a
    /// box crossing between the cameras and the target. What `handeye batch --disturb` runs.
    #[arg(long, requires = "seed")]
    disturb: bool,
    /// Write the operator hint for the target (its best graspable facet in both views, each
    /// corner off by up to ±3 px, and the depth behind it ±2 mm; seeded) to this JSON file
    /// before the first frame, for `handeye daemon --hint`. When the target has no such facet
    /// (a block the grasp rules cannot take), FILE.none says so instead.
    #[arg(long, value_name = "FILE")]
    hint_out: Option<PathBuf>,
    /// Lockstep: before the first frame, wait up to this many seconds for a daemon (a
    /// command publisher) to attach. 0 = do not wait.
    #[arg(long, default_value_t = 0.0, value_name = "S", value_parser = parse_seconds)]
    wait_daemon_s: f64,
    /// Also write the JSON object of --json to this file (the verdict `handeye run` merges).
    #[arg(long, value_name = "FILE")]
    verdict_out: Option<PathBuf>,
    /// Who serves handeye/robot/state and handeye/robot/command: `sim`, the simulator's own
    /// controller; or `external`, a robot driver (e.g. wire/examples/robot_driver.rs, started
    /// at the scenario's arm home): the simulator then poses the arm it renders where the
    /// driver's state says (joints by the simulated arm's IK) and only watches the commands.
    /// The driver keeps wall-clock time, so lockstep frames go out no faster than real time,
    /// and after the daemon's answer to a frame the simulator waits for the driver to report
    /// that command processed.
    #[arg(long, value_enum, default_value_t = RobotArg::Sim, conflicts_with = "scripted_pick")]
    robot: RobotArg,
    /// Ground truth for tests: the --hint-out facet's true corners in both views, one JSON
    /// line per published frame (frame_id, sim_time_ns, block, face, left_px, right_px,
    /// occluded_px: per view, pixels inside the facet that something hides; from a face-id
    /// render of its own). The daemon never reads it. Real time only (in lockstep it would
    /// answer the frames).
    #[arg(long, value_name = "FILE", requires = "hint_out", conflicts_with = "lockstep")]
    truth_out: Option<PathBuf>,
    #[command(flatten)]
    domain: DomainArgs,
}

/// `--robot`: who serves the robot services.
#[derive(Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum RobotArg {
    Sim,
    External,
}

/// Mesa's Vulkan driver complains on stderr when XDG_RUNTIME_DIR is unset (it probes for a
/// Wayland display); give it a private directory so headless runs stay quiet.
pub fn quiet_mesa() {
    if std::env::var_os("XDG_RUNTIME_DIR").is_some() {
        return;
    }
    let dir = std::env::temp_dir().join(format!("handeye-xdg-{}", std::process::id()));
    if std::fs::create_dir_all(&dir).is_ok() {
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let _ = std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700));
        }
        // SAFETY: called at the start of a subcommand, before any thread is spawned (no
        // renderer, transport or worker exists yet), so nothing reads the environment
        // concurrently.
        unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
    }
}

/// The scenario as a run with `--seed` lays it out: the target moved a little, every block
/// laid out afresh (`--random-layout`), or a whole work cell drawn (`--randomize`). One
/// function for `handeye sim` and `handeye run`, which must agree on the indicated point.
pub fn lay_out(scenario: &mut Scenario, file: &std::path::Path, seed: Option<u64>, random_layout: bool, randomize: bool, disturb: bool) -> Result<()> {
    let Some(seed) = seed else { return Ok(()) };
    lay_out_blocks(scenario, file, seed, random_layout, randomize)?;
    if disturb {
        // After the layout: the event is drawn from the cell's own cameras, target and light.
        let event = scenario.add_random_disturbance(seed);
        tracing::info!(?event, "disturbance added");
    }
    Ok(())
}

fn lay_out_blocks(scenario: &mut Scenario, file: &std::path::Path, seed: u64, random_layout: bool, randomize: bool) -> Result<()> {
    if randomize {
        scenario.randomise_cell(seed).with_context(|| format!("{}: seed {seed}", file.display()))?;
    } else if random_layout {
        if !scenario.randomise_layout(seed) {
            anyhow::bail!("{}: the blocks do not fit a random layout (seed {seed})", file.display());
        }
    } else {
        scenario.randomise_target(seed);
    }
    Ok(())
}

/// Where `--hint-out PATH` says why there is no hint (`PATH.none`): the target has no facet
/// an operator could point at.
pub fn no_hint_path(hint_path: &std::path::Path) -> PathBuf {
    let mut name = hint_path.as_os_str().to_owned();
    name.push(".none");
    PathBuf::from(name)
}

pub fn run(args: SimArgs) -> Result<()> {
    quiet_mesa();
    let mut scenario = Scenario::load(&args.scenario)?;
    lay_out(&mut scenario, &args.scenario, args.seed, args.random_layout, args.randomize, args.disturb)?;
    let name = scenario.name.clone();
    let mut runner = Runner::new(Simulator::new(scenario)?).context("starting the renderer")?;
    let robot = if args.robot == RobotArg::External { RobotSide::External } else { RobotSide::Simulated };
    if robot == RobotSide::External {
        runner.sim.follow_external_robot().context("the arm's home pose")?;
    }
    let adapter = runner.renderer.adapter();
    if !args.json {
        eprintln!("renderer: {adapter}");
    }
    let options = RunOptions {
        frames: args.frames,
        reply_timeout: Duration::from_secs_f64(args.reply_timeout_s),
        stop_on_success: !args.no_stop_on_success,
    };
    let mut truth_facet = None;
    if let Some(path) = &args.hint_out {
        match handeye_sim::referee::hint::operator_hint(&runner.sim, runner.sim.scenario.seed) {
            Ok((hint, facet)) => {
                let text = serde_json::to_string_pretty(&hint)?;
                // Write then rename, so a reader never sees half a file.
                let tmp = path.with_extension("json.tmp");
                std::fs::write(&tmp, text).with_context(|| format!("writing the hint to {}", tmp.display()))?;
                std::fs::rename(&tmp, path).with_context(|| format!("writing the hint to {}", path.display()))?;
                runner.watch.set_facet(facet);
                truth_facet = Some((facet.block, facet.face));
                if runner.sim.scenario.events.iter().any(|e| matches!(e, handeye_sim::scenario::Event::Occluder { .. })) {
                    let px = runner.face_visible_px(facet.block, facet.face)?;
                    runner.watch.set_facet_baseline(px);
                }
            }
            Err(e) => {
                // No facet an operator could click (a block the rules cannot grasp): say so
                // beside the hint's path, so that `handeye run` knows the scene is built; a
                // run without --hint goes on (its daemon plans, and should refuse).
                let none = no_hint_path(path);
                std::fs::write(&none, format!("{e}\n")).with_context(|| format!("writing {}", none.display()))?;
            }
        }
    }
    let (w, h) = (runner.renderer.width(), runner.renderer.height());
    let mut transport = WireTransport::with_robot(&args.domain.domain, w, h, robot)?;
    if args.lockstep && args.wait_daemon_s > 0.0 && !transport.wait_for_daemon(Duration::from_secs_f64(args.wait_daemon_s))? {
        anyhow::bail!("no daemon attached to domain '{}' within {} s", transport.domain(), args.wait_daemon_s);
    }
    if !args.json {
        eprintln!(
            "sim: {name} on handeye/stereo + {} in domain '{}' ({}, 2 x {w}x{h} GRAY8 at {} frames/s of simulated time)",
            if robot == RobotSide::External { "the arm posed by an external driver's handeye/robot/state" } else { "handeye/robot/*" },
            transport.domain(),
            if args.lockstep { "lockstep" } else { "real time" },
            runner.sim.scenario.render.frame_rate_hz
        );
    }
    let mut script = args.scripted_pick.then(|| {
        let target = runner.sim.target_index();
        let hold_s = runner.sim.scenario.success.hold_s + 1.0;
        GroundTruthPick::new(&runner.sim, target, 0.07, hold_s)
    });
    let mut truth = match (&args.truth_out, truth_facet) {
        (Some(path), Some((block, face))) => {
            let inner = script.take().map(|s| Box::new(s) as Box<dyn Driver>);
            Some(super::sim_truth::TruthWriter::create(path, block, face, inner)?)
        }
        (Some(path), None) => anyhow::bail!("--truth-out {}: the target has no hinted facet to write the truth of", path.display()),
        (None, _) => None,
    };
    let driver = match truth.as_mut() {
        Some(t) => Some(t as &mut dyn Driver),
        None => script.as_mut().map(|s| s as &mut dyn Driver),
    };
    let stats = if args.lockstep {
        run_lockstep(&mut runner, &mut transport, &options, driver)?
    } else {
        run_realtime(&mut runner, &mut transport, &options, driver)?
    };
    if let Some(f) = &runner.sim.follower {
        eprintln!("sim: followed {} robot driver states; {} poses beyond the simulated arm", f.states, f.unreachable);
    }
    if let (Some(t), Some(path)) = (truth.take(), &args.truth_out) {
        t.finish(path)?;
    }
    let verdict = runner.sim.verdict();
    let verdict_text = match verdict {
        Verdict::Pending => "pending".to_string(),
        Verdict::Success { at_ns } => format!("success at {:.2} s", at_ns as f64 * 1e-9),
        Verdict::TimedOut => "timed out".to_string(),
    };
    if args.json || args.verdict_out.is_some() {
        let scenario = &runner.sim.scenario;
        let report = SimReport {
            scenario: name.clone(),
            mode: if args.lockstep { SimMode::Lockstep } else { SimMode::Realtime },
            frames: stats.frames,
            fps: stats.fps,
            wall_s: stats.wall_s,
            sim_time_s: runner.sim.now_ns() as f64 * 1e-9,
            frames_hash: format!("{:016x}", stats.frames_hash),
            commands: stats.commands,
            reply_timeouts: stats.reply_timeouts,
            late_frames: stats.late_frames,
            verdict,
            driver: match (args.scripted_pick, robot) {
                (true, _) => SimDriver::ScriptedPick,
                (false, RobotSide::External) => SimDriver::ExternalRobot,
                (false, RobotSide::Simulated) => SimDriver::Commands,
            },
            max_lift_mm: runner.sim.judge().max_lift_m * 1e3,
            adapter,
            domain: transport.domain().to_string(),
            commands_rejected: transport.command_stats().rejected_total(),
            success: matches!(verdict, Verdict::Success { .. }),
            seed: scenario.seed,
            target: scenario.blocks[runner.sim.target_index()].name.clone(),
            indicated_point_m: scenario.indicated_point_m(),
            layout: scenario
                .blocks
                .iter()
                .map(|b| LaidOutBlock { name: b.name.clone(), kind: b.kind, size_mm: b.size_mm, position_m: b.position_m, yaw_deg: b.yaw_deg })
                .collect(),
            target_graspability: handeye_sim::referee::graspable::judge_block(
                &scenario.blocks[runner.sim.target_index()],
                &scenario.cameras.iter().map(|c| c.position_m).collect::<Vec<_>>(),
            ),
            daemon: runner.watch.clone(),
            pointer: runner.sim.pointer.as_ref().map(|p| p.truth(&runner.sim.events.cameras, runner.sim.now_ns())),
            pointer_earlier: runner.sim.operator.as_ref().map_or_else(Vec::new, |o| {
                o.earlier.iter().map(|p| p.truth(&runner.sim.events.cameras, runner.sim.now_ns())).collect()
            }),
            events: scenario.events.iter().map(|e| e.summary()).collect(),
        };
        if let Some(path) = &args.verdict_out {
            // Write then rename, so that `handeye run` never reads half a report.
            let tmp = path.with_extension("json.tmp");
            std::fs::write(&tmp, serde_json::to_string_pretty(&report)?).with_context(|| format!("writing {}", tmp.display()))?;
            std::fs::rename(&tmp, path).with_context(|| format!("writing {}", path.display()))?;
        }
        if args.json {
            println!("{}", serde_json::to_string(&report)?);
        }
    }
    if !args.json {
        println!(
            "{name}: {} frames in {:.2} s ({:.1} fps), {:.2} s simulated; verdict: {verdict_text}; frames hash {:016x}",
            stats.frames,
            stats.wall_s,
            stats.fps,
            runner.sim.now_ns() as f64 * 1e-9,
            stats.frames_hash
        );
    }
    Ok(())
}
