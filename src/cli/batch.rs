//! `handeye batch`: many closed-loop runs (`handeye run` on seeded random layouts), a
//! progress bar, a success-rate table with the failures by phase and reason, and a report
//! page per run.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use serde_json::{json, Value};

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
/// by the phase they ended in and their reason (numbers in reasons replaced by #, the seeds
/// listed); the total wall time.
///
/// With --json, one object instead: runs, successes, success_rate, failures (phase →
/// reason → count), failed_runs (scenario, seed, phase, reason in full), median_servo_steps,
/// median_run_wall_s, wall_s, scenarios (the same per scenario), daemon_config (the
/// --config file or null), and every run's summary (runs_detail: what `handeye run --json`
/// printed).
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
    #[arg(long, default_value_t = 300.0, value_name = "S")]
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
    reason: Option<String>,
    servo_steps: Option<f64>,
    wall_s: f64,
    summary: Value,
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

/// A reason with its numbers replaced by `#`, so that runs failing the same way group.
pub fn reason_class(reason: &str) -> String {
    let mut out = String::with_capacity(reason.len());
    let mut chars = reason.chars().peekable();
    while let Some(c) = chars.next() {
        let starts_number = c.is_ascii_digit() || ((c == '-' || c == '.') && chars.peek().is_some_and(|d| d.is_ascii_digit()) && !out.ends_with(|p: char| p.is_alphanumeric()));
        if starts_number {
            while chars.peek().is_some_and(|d| d.is_ascii_digit() || *d == '.' || *d == 'e' || *d == '-') {
                chars.next();
            }
            out.push('#');
        } else {
            out.push(c);
        }
    }
    out
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
        reason: Some(reason),
        servo_steps: None,
        wall_s: start.elapsed().as_secs_f64(),
        summary: Value::Null,
    };
    let output = match exe.and_then(|exe| Command::new(exe).args(&cmd_args).stdin(Stdio::null()).output()) {
        Ok(o) => o,
        Err(e) => return failed(format!("cannot start handeye run: {e}")),
    };
    let stdout = String::from_utf8_lossy(&output.stdout);
    let Some(summary) = stdout.lines().rev().find(|l| l.starts_with('{')).and_then(|l| serde_json::from_str::<Value>(l).ok()) else {
        return failed(format!("handeye run gave no result: {}", tail(&String::from_utf8_lossy(&output.stderr), 2)));
    };
    let success = summary["success"] == true;
    // The working phase the run got to (its final phase is just `failed` or `stopped`).
    let phase = summary["phase_reached"].as_str().unwrap_or("unknown").to_string();
    Outcome {
        job: job.clone(),
        success,
        phase: if success { "done".into() } else { phase },
        reason: if success { None } else { Some(summary["failure_reason"].as_str().unwrap_or("no reason given").to_string()) },
        servo_steps: summary["servo_steps"].as_f64(),
        wall_s: summary["wall_s"].as_f64().unwrap_or_else(|| start.elapsed().as_secs_f64()),
        summary,
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
                    o.reason.as_ref().map(|r| format!(" in {}: {r}", o.phase)).unwrap_or_default()
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
    let mut report = summarise(&outcomes, wall_s);
    report["daemon_config"] = args.config.as_ref().map_or(Value::Null, |c| Value::String(c.display().to_string()));
    if let Some(out) = &args.out {
        std::fs::write(out.join("batch.json"), serde_json::to_string_pretty(&report)?).with_context(|| format!("writing {}", out.join("batch.json").display()))?;
        write_pages(out, &outcomes, &report)?;
    }
    if args.json {
        println!("{report}");
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

fn group(outcomes: &[&Outcome], wall_s: Option<f64>) -> Value {
    let runs = outcomes.len();
    let successes = outcomes.iter().filter(|o| o.success).count();
    let mut failures: BTreeMap<String, BTreeMap<String, u64>> = BTreeMap::new();
    let mut seeds: BTreeMap<(String, String), Vec<String>> = BTreeMap::new();
    for o in outcomes.iter().filter(|o| !o.success) {
        let class = reason_class(o.reason.as_deref().unwrap_or(""));
        *failures.entry(o.phase.clone()).or_default().entry(class.clone()).or_insert(0) += 1;
        seeds.entry((o.phase.clone(), class)).or_default().push(format!("{}#{}", o.job.name, o.job.seed));
    }
    let failure_list: Vec<Value> = seeds.into_iter().map(|((phase, reason), runs)| json!({ "phase": phase, "reason": reason, "count": runs.len(), "runs": runs })).collect();
    json!({
        "runs": runs,
        "successes": successes,
        "success_rate": if runs > 0 { successes as f64 / runs as f64 } else { 0.0 },
        "failures": failures,
        "failure_list": failure_list,
        "median_servo_steps": median(outcomes.iter().filter(|o| o.success).filter_map(|o| o.servo_steps).collect()),
        "median_run_wall_s": median(outcomes.iter().map(|o| o.wall_s).collect()),
        "wall_s": wall_s,
    })
}

fn summarise(outcomes: &[Outcome], wall_s: f64) -> Value {
    let all: Vec<&Outcome> = outcomes.iter().collect();
    let mut report = group(&all, Some(wall_s));
    let mut names: Vec<&str> = outcomes.iter().map(|o| o.job.name.as_str()).collect();
    names.dedup();
    let scenarios: serde_json::Map<String, Value> =
        names.iter().map(|n| (n.to_string(), group(&outcomes.iter().filter(|o| o.job.name == *n).collect::<Vec<_>>(), None))).collect();
    report["scenarios"] = Value::Object(scenarios);
    report["failed_runs"] = outcomes
        .iter()
        .filter(|o| !o.success)
        .map(|o| json!({ "scenario": o.job.name, "seed": o.job.seed, "phase": o.phase, "reason": o.reason }))
        .collect();
    report["runs_detail"] = outcomes.iter().map(|o| json!({ "scenario": o.job.name, "seed": o.job.seed, "summary": o.summary })).collect();
    report
}

fn table(report: &Value) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let f = |v: &Value, unit: &str| v.as_f64().map_or("-".to_string(), |x| format!("{x:.1}{unit}"));
    let _ = writeln!(s, "{:<24} {:>5} {:>9} {:>8} {:>12} {:>10}", "scenario", "runs", "lifted", "rate", "servo steps", "run wall");
    if let Some(scenarios) = report["scenarios"].as_object() {
        for (name, g) in scenarios {
            let _ = writeln!(
                s,
                "{:<24} {:>5} {:>9} {:>7.0}% {:>12} {:>10}",
                name,
                g["runs"].as_u64().unwrap_or(0),
                g["successes"].as_u64().unwrap_or(0),
                100.0 * g["success_rate"].as_f64().unwrap_or(0.0),
                f(&g["median_servo_steps"], ""),
                f(&g["median_run_wall_s"], " s")
            );
        }
    }
    let _ = writeln!(
        s,
        "{:<24} {:>5} {:>9} {:>7.0}% {:>12} {:>10}",
        "all",
        report["runs"].as_u64().unwrap_or(0),
        report["successes"].as_u64().unwrap_or(0),
        100.0 * report["success_rate"].as_f64().unwrap_or(0.0),
        f(&report["median_servo_steps"], ""),
        f(&report["median_run_wall_s"], " s")
    );
    if let Some(list) = report["failure_list"].as_array().filter(|l| !l.is_empty()) {
        let _ = writeln!(s, "\nfailures by phase and reason:");
        for fl in list {
            let runs: Vec<&str> = fl["runs"].as_array().map(|r| r.iter().filter_map(Value::as_str).collect()).unwrap_or_default();
            let _ = writeln!(s, "  {:>3} x {}: {} ({})", fl["count"].as_u64().unwrap_or(0), fl["phase"].as_str().unwrap_or("?"), fl["reason"].as_str().unwrap_or("?"), runs.join(", "));
        }
    }
    let _ = writeln!(s, "\nwall time: {:.1} s in all; median servo steps over the runs that lifted; run wall: median per run", report["wall_s"].as_f64().unwrap_or(0.0));
    s
}

fn esc(text: &str) -> String {
    text.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// The report pages: DIR/index.html and one page per run (see `BatchArgs`).
fn write_pages(out: &Path, outcomes: &[Outcome], report: &Value) -> Result<()> {
    use std::fmt::Write;
    let style = "<style>body{font-family:sans-serif;margin:1.5em}table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:3px 8px;text-align:left}.ok{color:#070}.bad{color:#b00}img{max-width:100%;border:1px solid #ccc;margin:4px 0}</style>";
    let mut index = format!("<!doctype html><meta charset=utf-8><title>handeye batch</title>{style}<h1>handeye batch</h1><pre>{}</pre>", esc(&table(report)));
    let _ = write!(index, "<table><tr><th>scenario</th><th>seed</th><th>result</th><th>phase</th><th>reason</th><th>target</th><th>grasped facet</th><th>servo steps</th><th>wall (s)</th></tr>");
    for o in outcomes {
        let rel = format!("{}/seed-{}/index.html", o.job.name, o.job.seed);
        let s = &o.summary;
        let _ = write!(
            index,
            "<tr><td>{}</td><td><a href=\"{rel}\">{}</a></td><td class={}>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{} {}</td><td>{}</td><td>{:.1}</td></tr>",
            esc(&o.job.name),
            o.job.seed,
            if o.success { "ok" } else { "bad" },
            if o.success { "lifted" } else { "failed" },
            esc(&o.phase),
            esc(o.reason.as_deref().unwrap_or("")),
            esc(s["target_block"].as_str().unwrap_or("")),
            esc(s["targeted_block"].as_str().unwrap_or("")),
            esc(s["targeted_face"].as_str().unwrap_or("")),
            s["servo_steps"],
            o.wall_s
        );
        if let Some(dir) = &o.job.out {
            write_run_page(dir, o, style)?;
        }
    }
    index.push_str("</table>");
    std::fs::write(out.join("index.html"), index).with_context(|| format!("writing {}", out.join("index.html").display()))
}

fn write_run_page(dir: &Path, o: &Outcome, style: &str) -> Result<()> {
    use std::fmt::Write;
    if !dir.is_dir() {
        return Ok(());
    }
    let mut pngs: Vec<String> = std::fs::read_dir(dir)?
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.ends_with(".png") && n.chars().next().is_some_and(|c| c.is_ascii_digit()))
        .collect();
    pngs.sort();
    let s = &o.summary;
    let mut page = format!(
        "<!doctype html><meta charset=utf-8><title>{} seed {}</title>{style}<p><a href=\"../../index.html\">batch</a></p><h1>{} seed {}: <span class={}>{}</span></h1>",
        esc(&o.job.name),
        o.job.seed,
        esc(&o.job.name),
        o.job.seed,
        if o.success { "ok" } else { "bad" },
        if o.success { "lifted and held" } else { "failed" }
    );
    if let Some(r) = &o.reason {
        let _ = write!(page, "<p>in <b>{}</b>: {}</p>", esc(&o.phase), esc(r));
    }
    let _ = write!(page, "<table>");
    for key in [
        "target_block",
        "targeted_block",
        "targeted_face",
        "indicated_point_m",
        "plan_facets",
        "plan_candidates",
        "plan_width_mm",
        "planner_ms",
        "planning_frames",
        "gripper_updates_while_planning",
        "servo_steps",
        "final_plane_error_mm",
        "final_angle_error_deg",
        "grasp_plane_error_mm",
        "max_lift_mm",
        "loop_us_p50",
        "loop_us_p99",
        "calibration_residual_px",
        "sim_frames",
        "wall_s",
    ] {
        let _ = write!(page, "<tr><th>{key}</th><td>{}</td></tr>", esc(&s[key].to_string()));
    }
    let _ = write!(page, "</table><p>Files: <a href=\"run.json\">run.json</a> <a href=\"plan.json\">plan.json</a> <a href=\"daemon.json\">daemon.json</a> <a href=\"sim.json\">sim.json</a> <a href=\"daemon.stderr.log\">daemon log</a> <a href=\"sim.stderr.log\">sim log</a></p>");
    let caption = |name: &str| -> String {
        let label = name.trim_end_matches(".png").trim_start_matches(|c: char| c.is_ascii_digit() || c == '_').replace('_', " ");
        match label.as_str() {
            "plan" => "the plan: the planner's facets (colours; grey: left out; pink: hypothesised below a top face), rejected sites (yellow), candidates (white rings), the chosen site and its facet (red), the indicated point (magenta), the masked gripper (blue)".into(),
            other => format!("{other}: tracked contours (gripper green, target red, lost yellow)"),
        }
    };
    for png in pngs.iter().filter(|p| p.ends_with("_plan.png")) {
        let _ = write!(page, "<h2>Plan</h2><p>{}</p><img src=\"{png}\">", esc(&caption(png)));
    }
    if dir.join("servo_convergence.svg").exists() {
        let _ = write!(page, "<h2>Servo convergence</h2><p>the move the servo still estimated to its goal, per step: translation (mm, upper) and yaw (degrees, lower), log axes; dashed: the convergence tolerances</p><img src=\"servo_convergence.svg\">");
    }
    let _ = write!(page, "<h2>Key moments</h2>");
    for png in pngs.iter().filter(|p| !p.ends_with("_plan.png")) {
        let _ = write!(page, "<p>{}</p><img src=\"{png}\">", esc(&caption(png)));
    }
    std::fs::write(dir.join("index.html"), page).with_context(|| format!("writing {}", dir.join("index.html").display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reasons_group_without_their_numbers() {
        assert_eq!(reason_class("servo: not converged after 90 s (60 steps)"), "servo: not converged after # s (# steps)");
        assert_eq!(reason_class("gripper tracker (left view) confidence 0.43 < 0.6"), "gripper tracker (left view) confidence # < #");
        assert_eq!(reason_class("plan: no grasp site (3 facets; rejected: finger_collision 2)"), "plan: no grasp site (# facets; rejected: finger_collision #)");
        // A hyphen inside a word stays; a minus sign goes with its number.
        assert_eq!(reason_class("acquire_target: wrong-way -5 mm"), "acquire_target: wrong-way # mm");
    }

    fn outcome(seed: u64, success: bool, phase: &str, reason: Option<&str>, steps: Option<f64>) -> Outcome {
        Outcome {
            job: Job { scenario: PathBuf::from("c.toml"), name: "c".into(), seed, out: None },
            success,
            phase: phase.into(),
            reason: reason.map(String::from),
            servo_steps: steps,
            wall_s: 40.0 + seed as f64,
            summary: Value::Null,
        }
    }

    #[test]
    fn the_summary_counts_failures_by_phase_and_reason() {
        let runs = [
            outcome(1, true, "done", None, Some(3.0)),
            outcome(2, false, "servo", Some("servo: not converged after 90 s (60 steps)"), Some(60.0)),
            outcome(3, true, "done", None, Some(5.0)),
            outcome(4, false, "servo", Some("servo: not converged after 90 s (61 steps)"), None),
            outcome(5, false, "plan", Some("plan: no grasp site within 60 mm of the indicated point (the nearest is 75 mm away)"), None),
        ];
        let r = summarise(&runs, 210.0);
        assert_eq!(r["runs"], 5);
        assert_eq!(r["successes"], 2);
        assert_eq!(r["success_rate"], 0.4);
        assert_eq!(r["failures"]["servo"]["servo: not converged after # s (# steps)"], 2);
        assert_eq!(r["failures"]["plan"].as_object().unwrap().len(), 1);
        // Median servo steps over the runs that lifted only; wall times over all.
        assert_eq!(r["median_servo_steps"], 4.0);
        assert_eq!(r["median_run_wall_s"], 43.0);
        assert_eq!(r["failed_runs"].as_array().unwrap().len(), 3);
        assert_eq!(r["scenarios"]["c"]["runs"], 5);
        let t = table(&r);
        assert!(t.contains("  2 x servo: servo: not converged after # s (# steps) (c#2, c#4)"), "{t}");
        assert!(t.contains("40%"), "{t}");
    }

    #[test]
    fn medians() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), Some(2.5));
        assert_eq!(median(vec![f64::NAN]), None);
    }
}
