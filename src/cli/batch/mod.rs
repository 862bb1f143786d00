//! `handeye batch`: many closed-loop runs (`handeye run` on seeded random layouts), a
//! progress bar, a success-rate table with the failures by phase and kind, and a report
//! page per run.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_wire::report::{Failure, FailureKind};
use indicatif::{ProgressBar, ProgressStyle};

use super::report::{BatchGroup, BatchResult, FailedRun, FailureGroup, GroupRun, RunDetail, RunSummary};
use super::units::parse_seconds;

mod pages;

/// Run many closed-loop grasp scenarios and report how often they succeed.
///
/// Each run is `handeye run SCENARIO --seed S --random-layout --json` (simulator and daemon
/// as two processes in their own private shared-memory domain): seed S lays the
/// scenario's blocks out at random (positions in x 0.27..0.45 m with the whole block
/// inside, y -0.15..0.15 m, any yaw that shows every seen edge, 60 mm apart; a task with an indicated point gets a
/// random target with the point within 15 mm of it) and reseeds the sensor noise. The daemon plans its own grasp (with --hint:
/// the operator hint), and the simulator judges success from ground truth: the task's
/// target lifted 50 mm and held 2 s.
///
/// A progress bar runs on stderr (one line per finished run when stderr is not a
/// terminal). Then a table on stdout: per scenario the runs, successes, success rate,
/// median servo steps (successful runs) and median wall time per run; the failures grouped
/// by the phase they happened in and their kind (not_converged, no_grasp_site, wrong_target,
/// ...: the `failure` of `handeye run --json`), each group's runs listed with their reasons
/// in full; the total wall time.
///
/// With --json, one object instead: runs, successes, success_rate, failures (phase →
/// kind → count), failure_list (per group: phase, kind, count, runs: run "scenario#seed" and
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
/// Examples:
///   handeye batch scenarios/clutter3.toml --seeds 30
///   handeye batch scenarios/clutter3.toml --seeds 30 --json --out out/batch
///   handeye batch scenarios --seeds 5 --jobs 2
///   handeye batch scenarios/clutter3.toml --seeds 30 --config fast.toml   # other daemon settings
#[derive(Args)]
#[command(verbatim_doc_comment)]
pub struct BatchArgs {
    /// A scenario file (TOML), or a folder: every `*.toml` in it, in name order.
    scenarios: PathBuf,
    /// Runs per scenario, seeds --first-seed .. --first-seed + N - 1.
    #[arg(long, value_name = "N")]
    seeds: u64,
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
    /// Give the daemon the operator hint instead of letting it plan (`handeye run --hint`).
    #[arg(long)]
    hint: bool,
    /// Kill a run after this many seconds of wall time (`handeye run --timeout-s`).
    #[arg(long, default_value_t = 300.0, value_name = "S", value_parser = parse_seconds)]
    timeout_s: f64,
    /// Daemon configuration (TOML) for every run (`handeye run --config`), e.g. to compare
    /// tracker settings over the same layouts. Checked before the first run starts.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
}

static INTERRUPTED: AtomicBool = AtomicBool::new(false);

extern "C" fn on_signal(_: libc::c_int) {
    INTERRUPTED.store(true, Ordering::SeqCst);
}

/// One run to make.
#[derive(Debug, Clone)]
struct Job {
    scenario: PathBuf,
    name: String,
    seed: u64,
    out: Option<PathBuf>,
}

/// What one run gave.
#[derive(Debug, Clone)]
struct Outcome {
    job: Job,
    success: bool,
    /// The working phase the run got to (`run` when `handeye run` itself failed).
    phase: String,
    /// Why it failed (`None` when it lifted).
    failure: Option<Failure>,
    servo_steps: Option<f64>,
    wall_s: f64,
    /// What `handeye run --json` printed (`None`: nothing usable).
    summary: Option<RunSummary>,
}

impl Outcome {
    fn reason(&self) -> Option<&str> {
        self.failure.as_ref().map(|f| f.detail.as_str())
    }
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

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return None;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) })
}

fn tail(text: &str, lines: usize) -> String {
    let l: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    l[l.len().saturating_sub(lines)..].join(" | ")
}

fn run_one(job: &Job, args: &BatchArgs) -> Outcome {
    let start = Instant::now();
    let exe = std::env::current_exe();
    let mut cmd_args: Vec<String> = vec![
        "run".into(),
        job.scenario.display().to_string(),
        "--seed".into(),
        job.seed.to_string(),
        "--random-layout".into(),
        "--json".into(),
        "--timeout-s".into(),
        args.timeout_s.to_string(),
    ];
    if args.hint {
        cmd_args.push("--hint".into());
    }
    if let Some(config) = &args.config {
        cmd_args.extend(["--config".into(), config.display().to_string()]);
    }
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
    if args.seeds == 0 {
        bail!("--seeds must be at least 1");
    }
    if args.jobs == 0 {
        bail!("--jobs must be at least 1");
    }
    if let Some(config) = &args.config {
        // A bad file fails here, with its key, rather than in every run.
        handeye_daemon::DaemonConfig::load(config)?;
    }
    let files = collect_scenarios(&args.scenarios)?;
    let mut jobs = Vec::new();
    for file in &files {
        let name = scenario_name(file)?;
        for seed in args.first_seed..args.first_seed + args.seeds {
            let out = args.out.as_ref().map(|d| d.join(&name).join(format!("seed-{seed}")));
            jobs.push(Job { scenario: file.clone(), name: name.clone(), seed, out });
        }
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
            let (queue, results, bar, successes, args) = (queue.clone(), results.clone(), bar.clone(), successes.clone(), &args);
            scope.spawn(move || loop {
                if INTERRUPTED.load(Ordering::SeqCst) {
                    break;
                }
                let Some((i, job)) = queue.lock().ok().and_then(|mut q| q.pop()) else { break };
                let o = run_one(&job, args);
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
    if let Some(out) = &args.out {
        std::fs::write(out.join("batch.json"), serde_json::to_string_pretty(&report)?).with_context(|| format!("writing {}", out.join("batch.json").display()))?;
        pages::write_pages(out, &outcomes, &report)?;
    }
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", table(&report));
        if let Some(out) = &args.out {
            println!("report: {}", out.join("index.html").display());
        }
    }
    if INTERRUPTED.load(Ordering::SeqCst) {
        eprintln!("batch: interrupted after {} of the runs", outcomes.len());
    }
    Ok(())
}

/// Counts and medians over `outcomes`; failures grouped by the phase they happened in and
/// their kind.
fn group(outcomes: &[&Outcome], wall_s: Option<f64>) -> BatchGroup {
    let runs = outcomes.len();
    let successes = outcomes.iter().filter(|o| o.success).count();
    let mut groups: BTreeMap<(String, FailureKind), Vec<GroupRun>> = BTreeMap::new();
    for o in outcomes {
        if let Some(f) = &o.failure {
            groups.entry((f.phase.clone(), f.kind)).or_default().push(GroupRun { run: format!("{}#{}", o.job.name, o.job.seed), reason: f.detail.clone() });
        }
    }
    let mut failures: BTreeMap<String, BTreeMap<FailureKind, usize>> = BTreeMap::new();
    for ((phase, kind), runs) in &groups {
        failures.entry(phase.clone()).or_default().insert(*kind, runs.len());
    }
    BatchGroup {
        runs,
        successes,
        success_rate: if runs > 0 { successes as f64 / runs as f64 } else { 0.0 },
        failures,
        failure_list: groups.into_iter().map(|((phase, kind), runs)| FailureGroup { phase, kind, count: runs.len(), runs }).collect(),
        median_servo_steps: median(outcomes.iter().filter(|o| o.success).filter_map(|o| o.servo_steps).collect()),
        median_run_wall_s: median(outcomes.iter().map(|o| o.wall_s).collect()),
        wall_s,
    }
}

fn summarise(outcomes: &[Outcome], wall_s: f64, daemon_config: Option<String>) -> BatchResult {
    let all: Vec<&Outcome> = outcomes.iter().collect();
    let mut names: Vec<&str> = outcomes.iter().map(|o| o.job.name.as_str()).collect();
    names.dedup();
    BatchResult {
        all: group(&all, Some(wall_s)),
        scenarios: names.iter().map(|n| (n.to_string(), group(&outcomes.iter().filter(|o| o.job.name == *n).collect::<Vec<_>>(), None))).collect(),
        failed_runs: outcomes
            .iter()
            .filter_map(|o| {
                let failure = o.failure.clone()?;
                Some(FailedRun { scenario: o.job.name.clone(), seed: o.job.seed, phase: o.phase.clone(), reason: failure.detail.clone(), failure })
            })
            .collect(),
        runs_detail: outcomes.iter().map(|o| RunDetail { scenario: o.job.name.clone(), seed: o.job.seed, summary: o.summary.clone() }).collect(),
        daemon_config,
    }
}

fn table(report: &BatchResult) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let f = |v: Option<f64>, unit: &str| v.map_or("-".to_string(), |x| format!("{x:.1}{unit}"));
    let _ = writeln!(s, "{:<24} {:>5} {:>9} {:>8} {:>12} {:>10}", "scenario", "runs", "lifted", "rate", "servo steps", "run wall");
    let row = |s: &mut String, name: &str, g: &BatchGroup| {
        let _ = writeln!(
            s,
            "{:<24} {:>5} {:>9} {:>7.0}% {:>12} {:>10}",
            name,
            g.runs,
            g.successes,
            100.0 * g.success_rate,
            f(g.median_servo_steps, ""),
            f(g.median_run_wall_s, " s")
        );
    };
    for (name, g) in &report.scenarios {
        row(&mut s, name, g);
    }
    row(&mut s, "all", &report.all);
    if !report.all.failure_list.is_empty() {
        let _ = writeln!(s, "\nfailures by phase and kind:");
        for g in &report.all.failure_list {
            let runs: Vec<&str> = g.runs.iter().map(|r| r.run.as_str()).collect();
            let _ = writeln!(s, "  {:>3} x {}: {} ({})", g.count, g.phase, g.kind, runs.join(", "));
            for r in &g.runs {
                let _ = writeln!(s, "          {}: {}", r.run, r.reason);
            }
        }
    }
    let _ = writeln!(s, "\nwall time: {:.1} s in all; median servo steps over the runs that lifted; run wall: median per run", report.all.wall_s.unwrap_or(0.0));
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn outcome(seed: u64, failure: Option<(&str, FailureKind, &str)>, steps: Option<f64>) -> Outcome {
        Outcome {
            job: Job { scenario: PathBuf::from("c.toml"), name: "c".into(), seed, out: None },
            success: failure.is_none(),
            phase: failure.map_or("done", |f| f.0).into(),
            failure: failure.map(|(phase, kind, detail)| Failure::new(phase, kind, detail)),
            servo_steps: steps,
            wall_s: 40.0 + seed as f64,
            summary: None,
        }
    }

    #[test]
    fn the_summary_counts_failures_by_phase_and_kind() {
        let not_converged = |steps| format!("servo: not converged after 90 s ({steps} steps)");
        let (c2, c4) = (not_converged(60), not_converged(61));
        let runs = [
            outcome(1, None, Some(3.0)),
            outcome(2, Some(("servo", FailureKind::NotConverged, &c2)), Some(60.0)),
            outcome(3, None, Some(5.0)),
            outcome(4, Some(("servo", FailureKind::NotConverged, &c4)), None),
            outcome(5, Some(("plan", FailureKind::NoGraspSite, "plan: no grasp site within 60 mm of the indicated point (the nearest is 75 mm away)")), None),
            // Same phase, another kind: a group of its own, whatever the words.
            outcome(6, Some(("servo", FailureKind::TrackerLost, "servo: not converged: the target tracker was lost")), None),
        ];
        let r = summarise(&runs, 210.0, None);
        assert_eq!((r.all.runs, r.all.successes), (6, 2));
        assert!((r.all.success_rate - 2.0 / 6.0).abs() < 1e-12);
        assert_eq!(r.all.failures["servo"][&FailureKind::NotConverged], 2);
        assert_eq!(r.all.failures["servo"][&FailureKind::TrackerLost], 1);
        assert_eq!(r.all.failures["plan"].len(), 1);
        // One group per (phase, kind), with each run's reason in full.
        assert_eq!(r.all.failure_list.len(), 3);
        let servo = r.all.failure_list.iter().find(|g| g.phase == "servo" && g.kind == FailureKind::NotConverged).unwrap();
        assert_eq!(servo.count, 2);
        assert_eq!(servo.runs, vec![GroupRun { run: "c#2".into(), reason: c2.clone() }, GroupRun { run: "c#4".into(), reason: c4.clone() }]);
        // Median servo steps over the runs that lifted only; wall times over all.
        assert_eq!(r.all.median_servo_steps, Some(4.0));
        assert_eq!(r.all.median_run_wall_s, Some(43.5));
        assert_eq!(r.all.wall_s, Some(210.0));
        assert_eq!(r.failed_runs.len(), 4);
        assert_eq!(r.failed_runs[0].reason, c2);
        assert_eq!(r.scenarios["c"].runs, 6);
        assert_eq!(r.scenarios["c"].wall_s, None);
        assert_eq!(r.runs_detail.len(), 6);
        let t = table(&r);
        assert!(t.contains("  2 x servo: not_converged (c#2, c#4)"), "{t}");
        assert!(t.contains(&format!("c#4: {c4}")), "{t}");
        assert!(t.contains("  1 x servo: tracker_lost (c#6)"), "{t}");
        assert!(t.contains("33%"), "{t}");
    }

    #[test]
    fn medians() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(vec![f64::NAN]), None);
    }
}
