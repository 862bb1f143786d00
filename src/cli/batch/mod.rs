//! `handeye batch`: many closed-loop runs (`handeye run` on seeded random layouts), a
//! progress bar, a success-rate table with the failures by phase and kind, and a report
//! page per run.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use handeye_wire::report::{Failure, FailureKind};
use indicatif::{ProgressBar, ProgressStyle};

use super::report::RunSummary;
use shard::{BatchFile, BatchSpec, ScenarioSpec, Shard};
use summary::{summarise, Job, Outcome};
use super::units::parse_seconds;

mod merge;
mod pages;
mod shard;
mod summary;

/// Run many closed-loop grasp scenarios and report how often they succeed.
///
/// Each run is `handeye run SCENARIO --seed S --random-layout --json` (with --randomize:
/// `--randomize` instead, a whole work cell drawn per seed; see below) (simulator and daemon
/// as two processes in their own private shared-memory domain): seed S lays the
/// scenario's blocks out at random (positions in x 0.27..0.45 m with the whole block
/// inside, y -0.15..0.15 m, any yaw, drawn once (a faint edge is not drawn again), 60 mm apart; a task with an indicated point gets a
/// random target with the point within 15 mm of it) and reseeds the sensor noise. The daemon plans its own grasp (with --hint:
/// the operator hint), and the simulator judges success from ground truth: the task's
/// target lifted 50 mm and held 2 s.
///
/// With a [pointer] scenario (scenarios/point_clutter3.toml) the daemon watches the
/// operator's hand point at the seed's block and plans for the point it sees; the table then
/// says how many gestures it answered, whether it went for the pointed block, how far its
/// point was from where the hand really aimed (the judge's), and per run what happened.
/// --given-point gives it the scenario's point instead (the ground-truth operator).
///
/// With --randomize each seed draws the whole work cell from the scenario's [randomize]
/// ranges (default: issue 20's): the camera pair (1.2-1.9 m away, 14-30° vergence, 25-45°
/// elevation, 30-50° horizontal field of view, a little roll), the light, the table's and
/// blocks' shades, 2-5 blocks of every kind (cube, bar, wedge, L-block) and size within the
/// gripper's, their poses, noise and blur, and the indicated point next to a random block.
/// With no scenario, the built-in scenarios/random.toml.
///
/// Every run's target is judged by the simulator on its true geometry: has it a grasp the
/// thesis's rules allow? The table then also gives the success over graspable targets,
/// wrong refusals (the daemon refused a graspable target: failure kind `refused`), correct
/// refusals (it refused an ungraspable one) and attempts on ungraspable targets (it went on
/// past planning).
///
/// A progress bar runs on stderr (one line per finished run when stderr is not a
/// terminal). Then a table on stdout: per scenario the runs, successes, success rate,
/// median servo steps (successful runs) and median wall time per run; the failures grouped
/// by the phase they happened in and their kind (not_converged, no_grasp_site, refused, wrong_target,
/// ...: the `failure` of `handeye run --json`), each group's runs listed with their reasons
/// in full; the total wall time.
///
/// With --json, one object instead: runs, successes, success_rate, failures (phase →
/// kind → count), graspable_runs, graspable_successes, graspable_success_rate,
/// wrong_refusals, ungraspable_runs, correct_refusals, correct_refusal_rate,
/// attempts_on_ungraspable, unjudged_runs (the same per scenario), failure_list (per group: phase, kind, count, runs: run "scenario#seed" and
/// its reason), failed_runs (scenario, seed, phase reached, reason in full, failure: phase,
/// kind, detail), median_servo_steps, median_run_wall_s, wall_s, scenarios (the same per
/// scenario), daemon_config (the --config file or null), and every run's summary
/// (runs_detail: what `handeye run --json` printed, null when it printed nothing).
///
/// With --out DIR: DIR/index.html (the table, a row per run linking its page) and, per run,
/// DIR/<scenario>/seed-<S>/ with `handeye run`'s report (overlays of the tracked contours at
/// key moments, the plan: the planner's facets and grasp sites on both views, the servo
/// convergence plot, the JSONs and logs) and an index.html page showing them; DIR/batch.json
/// holds the --json object.
///
/// The object (and batch.json) also says which batch it is, under `batch`: the scenarios
/// (name, file, a hash of the file), the whole seed list, the shard (null: all of it) and the
/// `handeye run` flags every run got, so that shards can be checked and merged; each run's
/// entry in runs_detail has its wall_s.
///
/// With --shard K/N, only the K-th of N shares of the seeds runs: the seeds at positions
/// K-1, K-1+N, K-1+2N, ... of the list (--shard 2/3 --seeds 7 runs seeds 2 and 5), for every
/// scenario. N shards balance to within one seed and together run every seed once. Give
/// each shard its own --out DIR; `handeye batch merge DIR...` then reads their batch.json
/// files and writes the table, batch.json and index.html the unsharded batch would have
/// (see `handeye batch merge --help`, and README "Batches on a cluster" for Slurm and
/// Kubernetes).
///
/// Examples:
///   handeye batch scenarios/clutter3.toml --seeds 30
///   handeye batch --randomize --seeds 50 --json             # randomised work cells
///   handeye batch --randomize --seeds 20 --first-seed 1000 --out out/cells
///   handeye batch scenarios/random.toml --randomize --seeds 5   # its own [randomize] ranges
///   handeye batch scenarios/clutter3.toml --seeds 30 --disturb  # one random disturbance a run
///   handeye batch scenarios/point_clutter3.toml --seeds 30      # the operator points
///   handeye batch scenarios/point_clutter3.toml --seeds 30 --given-point   # the same, told the point
///   handeye batch scenarios/clutter3.toml --seeds 30 --json --out out/batch
///   handeye batch scenarios --seeds 5 --jobs 2
///   handeye batch scenarios/clutter3.toml --seeds 30 --config fast.toml   # other daemon settings
///   handeye batch scenarios/clutter3.toml --seeds 1000 --shard 3/50 --out shared/shard-3
///   handeye batch merge shared/shard-* --out shared/batch
#[derive(Args)]
#[command(verbatim_doc_comment, args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct BatchArgs {
    #[command(subcommand)]
    command: Option<BatchCommand>,
    /// A scenario file (TOML), or a folder: every `*.toml` in it, in name order. With
    /// --randomize it may be left out: the built-in scenarios/random.toml.
    #[arg(required_unless_present = "randomize")]
    scenarios: Option<PathBuf>,
    /// Runs per scenario, seeds --first-seed .. --first-seed + N - 1.
    #[arg(long, value_name = "N", required = true)]
    seeds: Option<u64>,
    /// Run only the K-th of N shares of the seeds (K from 1 to N; see above).
    #[arg(long, value_name = "K/N", value_parser = shard::parse_shard)]
    shard: Option<Shard>,
    /// The first seed.
    #[arg(long, default_value_t = 1, value_name = "S")]
    first_seed: u64,
    /// Print one JSON object (see above) instead of the table.
    #[arg(long)]
    json: bool,
    /// Report folder (see above). Without it nothing is kept.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Runs at a time. Each run is two processes (simulator and daemon) that want about a
    /// core each in lockstep: more than half the cores only makes every run slower.
    #[arg(long, default_value_t = 1, value_name = "J")]
    jobs: usize,
    /// Draw a whole work cell per seed (`handeye run --randomize`): cameras, light, shades,
    /// 2-5 blocks of every kind, noise, blur and the indicated point, from the scenario's
    /// [randomize] ranges (see scenarios/random.toml and sim/README.md), instead of laying
    /// out the scenario's own blocks.
    #[arg(long)]
    randomize: bool,
    /// Add one seeded random disturbance to every run (`handeye run --disturb`): a camera
    /// knock, a target nudge, a light change or an occluder, at a random moment.
    #[arg(long)]
    disturb: bool,
    /// Give the daemon the operator hint instead of letting it plan (`handeye run --hint`).
    #[arg(long)]
    hint: bool,
    /// With a [pointer] scenario: give every daemon the scenario's indicated point instead of
    /// letting it watch the hand (`handeye run --given-point`): the ground-truth operator,
    /// to compare pointing against on the same seeds.
    #[arg(long, conflicts_with = "hint")]
    given_point: bool,
    /// Kill a run after this many seconds of wall time (`handeye run --timeout-s`).
    #[arg(long, default_value_t = 300.0, value_name = "S", value_parser = parse_seconds)]
    timeout_s: f64,
    /// Daemon configuration (TOML) for every run (`handeye run --config`), e.g. to compare
    /// tracker settings over the same layouts. Checked before the first run starts.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

#[derive(Subcommand)]
enum BatchCommand {
    Merge(merge::MergeArgs),
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

fn scenario_name(path: &Path) -> Result<String> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let scenario = handeye_sim::Scenario::parse(&text, path)?;
    Ok(scenario.name)
}

fn collect_scenarios(path: &Path) -> Result<Vec<PathBuf>> {
    if path.is_dir() {
        let mut files: Vec<PathBuf> = std::fs::read_dir(path)
            .with_context(|| format!("cannot list {}", path.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        files.sort();
        if files.is_empty() {
            bail!("{}: no *.toml scenario files in this folder", path.display());
        }
        Ok(files)
    } else if path.is_file() {
        Ok(vec![path.to_path_buf()])
    } else {
        bail!("{}: no such scenario file or folder", path.display())
    }
}

fn tail(text: &str, lines: usize) -> String {
    let l: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    l[l.len().saturating_sub(lines)..].join(" | ")
}

/// The `handeye run` flags every run of the batch gets (besides its scenario, seed and
/// report folder); shards of one batch must agree on them.
fn run_flags(args: &BatchArgs) -> Vec<String> {
    let layout = if args.randomize { "--randomize" } else { "--random-layout" };
    let mut flags: Vec<String> = vec![layout.into(), "--json".into(), "--timeout-s".into(), args.timeout_s.to_string()];
    if args.hint {
        flags.push("--hint".into());
    }
    if args.given_point {
        flags.push("--given-point".into());
    }
    if args.disturb {
        flags.push("--disturb".into());
    }
    if let Some(config) = &args.config {
        flags.extend(["--config".into(), config.display().to_string()]);
    }
    flags
}

fn run_one(job: &Job, flags: &[String]) -> Outcome {
    let start = Instant::now();
    let exe = std::env::current_exe();
    let mut cmd_args: Vec<String> = vec!["run".into(), job.scenario.display().to_string(), "--seed".into(), job.seed.to_string()];
    cmd_args.extend(flags.iter().cloned());
    if let Some(out) = &job.out {
        cmd_args.extend(["--out".into(), out.display().to_string()]);
    }
    let failed = |reason: String| Outcome {
        job: job.clone(),
        success: false,
        phase: "run".into(),
        failure: Some(Failure::new("run", FailureKind::Process, reason)),
        servo_steps: None,
        wall_s: start.elapsed().as_secs_f64(),
        summary: None,
    };
    let output = match exe.and_then(|exe| Command::new(exe).args(&cmd_args).stdin(Stdio::null()).output()) {
        Ok(o) => o,
        Err(e) => return failed(format!("cannot start handeye run: {e}")),
    };
    let stdout = String::from_utf8_lossy(&output.stdout);
    let Some(line) = stdout.lines().rev().find(|l| l.starts_with('{')) else {
        return failed(format!("handeye run gave no result: {}", tail(&String::from_utf8_lossy(&output.stderr), 2)));
    };
    let summary = match serde_json::from_str::<RunSummary>(line) {
        Ok(s) => s,
        // A summary that does not read is a broken contract between the two commands: said
        // with the field, not read as "no value".
        Err(e) => return failed(format!("handeye run's summary does not read: {e}")),
    };
    let success = summary.success;
    // The working phase the run got to (its final phase is just `failed` or `stopped`).
    let phase = summary.phase_reached.clone().unwrap_or_else(|| "unknown".to_string());
    let failure = (!success).then(|| summary.failure.clone().unwrap_or_else(|| Failure::new(phase.clone(), FailureKind::Process, "no reason given")));
    Outcome {
        job: job.clone(),
        success,
        phase: if success { "done".into() } else { phase },
        failure,
        servo_steps: summary.servo_steps.map(f64::from),
        wall_s: summary.wall_s,
        summary: Some(summary),
    }
}

pub fn run(args: BatchArgs) -> Result<()> {
    if let Some(BatchCommand::Merge(merge)) = args.command {
        return merge::run(merge);
    }
    // clap requires --seeds, and a scenario unless --randomize, without a subcommand.
    let (scenarios, Some(seeds)) = (args.scenarios.clone(), args.seeds) else {
        bail!("handeye batch needs --seeds and a scenario (or --randomize) (see handeye batch --help)");
    };
    if scenarios.is_none() && !args.randomize {
        bail!("handeye batch needs a scenario unless --randomize (see handeye batch --help)");
    }
    if seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    if args.jobs == 0 {
        bail!("--jobs must be at least 1");
    }
    if let Some(config) = &args.config {
        // A bad file fails here, with its key, rather than in every run.
        handeye_daemon::DaemonConfig::load(config)?;
    }
    // Without a scenario (--randomize): the built-in random cell, written where the runs can
    // read it (the report folder, or a temporary one removed at the end).
    let mut built_in_dir = None;
    let scenarios = match &scenarios {
        Some(path) => path.clone(),
        None => {
            let dir = match &args.out {
                Some(out) => out.clone(),
                None => {
                    let dir = std::env::temp_dir().join(format!("handeye-batch-{}", std::process::id()));
                    built_in_dir = Some(dir.clone());
                    dir
                }
            };
            std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
            let path = dir.join("random.toml");
            std::fs::write(&path, RANDOM_SCENARIO).with_context(|| format!("writing {}", path.display()))?;
            path
        }
    };
    let result = run_batch(&args, &scenarios, seeds);
    if let Some(dir) = built_in_dir {
        let _ = std::fs::remove_dir_all(dir);
    }
    result
}

/// The scenario `handeye batch --randomize` runs when given none.
const RANDOM_SCENARIO: &str = include_str!("../../../scenarios/random.toml");

fn run_batch(args: &BatchArgs, scenarios: &Path, seeds: u64) -> Result<()> {
    let files = collect_scenarios(scenarios)?;
    let flags = run_flags(args);
    let mut spec = BatchSpec { scenarios: Vec::new(), seeds: (args.first_seed..args.first_seed + seeds).collect(), shard: args.shard, run_flags: flags.clone() };
    let mut jobs = Vec::new();
    for file in &files {
        let name = scenario_name(file)?;
        for seed in spec.own_seeds() {
            let out = args.out.as_ref().map(|d| d.join(&name).join(format!("seed-{seed}")));
            jobs.push(Job { scenario: file.clone(), name: name.clone(), seed, out });
        }
        spec.scenarios.push(ScenarioSpec::read(file, name)?);
    }
    if jobs.is_empty() {
        let shard = args.shard.map(|s| s.to_string()).unwrap_or_default();
        bail!("--shard {shard}: this shard has no seeds (--seeds {seeds} gives fewer seeds than shards)");
    }
    if let Some(out) = &args.out {
        std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    }
    // SAFETY: installs an async-signal-safe handler that only stores to an atomic. The
    // children see the same Ctrl-C and clean up themselves; no new run starts after it.
    unsafe {
        libc::signal(libc::SIGINT, on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t);
        libc::signal(libc::SIGTERM, on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t);
    }
    let start = Instant::now();
    let bar = ProgressBar::new(jobs.len() as u64);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs, {msg}").map_or_else(|_| ProgressStyle::default_bar(), |s| s.progress_chars("=> ")),
    );
    bar.set_message("starting");
    let queue = Arc::new(Mutex::new(jobs.into_iter().enumerate().collect::<Vec<_>>().into_iter().rev().collect::<Vec<_>>()));
    let results: Arc<Mutex<Vec<(usize, Outcome)>>> = Arc::new(Mutex::new(Vec::new()));
    let successes = Arc::new(std::sync::atomic::AtomicU64::new(0));
    std::thread::scope(|scope| {
        for _ in 0..args.jobs {
            let (queue, results, bar, successes, flags) = (queue.clone(), results.clone(), bar.clone(), successes.clone(), &flags);
            scope.spawn(move || loop {
                if INTERRUPTED.load(Ordering::SeqCst) {
                    break;
                }
                let Some((i, job)) = queue.lock().ok().and_then(|mut q| q.pop()) else { break };
                let o = run_one(&job, flags);
                if o.success {
                    successes.fetch_add(1, Ordering::SeqCst);
                }
                let line = format!(
                    "{} seed {}: {}{}",
                    o.job.name,
                    o.job.seed,
                    if o.success { "lifted" } else { "FAILED" },
                    o.reason().map(|r| format!(" in {}: {r}", o.phase)).unwrap_or_default()
                );
                if bar.is_hidden() {
                    eprintln!("{line}");
                } else {
                    bar.println(&line);
                }
                bar.inc(1);
                let done = bar.position().max(1);
                bar.set_message(format!("{} lifted ({:.0} %)", successes.load(Ordering::SeqCst), 100.0 * successes.load(Ordering::SeqCst) as f64 / done as f64));
                if let Ok(mut r) = results.lock() {
                    r.push((i, o));
                }
            });
        }
    });
    bar.finish_and_clear();
    let mut outcomes: Vec<(usize, Outcome)> = std::mem::take(&mut *results.lock().map_err(|_| anyhow::anyhow!("a run thread panicked"))?);
    outcomes.sort_by_key(|(i, _)| *i);
    let outcomes: Vec<Outcome> = outcomes.into_iter().map(|(_, o)| o).collect();
    let wall_s = start.elapsed().as_secs_f64();
    let report = summarise(&outcomes, wall_s, args.config.as_ref().map(|c| c.display().to_string()));
    pages::write_report(&BatchFile { batch: spec, result: report }, &outcomes, args.out.as_deref(), args.json)?;
    if INTERRUPTED.load(Ordering::SeqCst) {
        eprintln!("batch: interrupted after {} of the runs", outcomes.len());
    }
    Ok(())
}
