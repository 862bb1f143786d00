//! `handeye batch` as a user runs it, on two seeded random layouts of clutter3: the daemon
//! plans its own grasp in each, and the batch reports the success rate, the failures by
//! phase and kind, and a page per run. (The acceptance run, 30 seeds, is too slow for CI:
//! its numbers are in BENCHMARKS.md, "Closed loop".)

mod e2e_support;

use std::process::Command;

use e2e_support::{one_at_a_time, scenario, TempDir};
use serde_json::{json, Value};

/// Two layouts whose targets differ (seeds 8 and 9: the small cube and the L-block; see
/// BENCHMARKS.md for every seed's target and result).
const FIRST_SEED: &str = "8";

#[test]
fn a_two_seed_batch_lifts_both_targets_and_writes_the_report() {
    let _one = one_at_a_time();
    let out = TempDir::new("batch");
    let o = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .arg("batch")
        .arg(scenario("clutter3.toml"))
        .args(["--seeds", "2", "--first-seed", FIRST_SEED, "--json", "--out"])
        .arg(&out.0)
        .env("HANDEYE_LOG", "warn")
        .output()
        .expect("handeye batch");
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert!(o.status.success(), "stderr: {stderr}");
    let report: Value = serde_json::from_str(stdout.lines().rev().find(|l| l.starts_with('{')).expect("a JSON line")).expect("JSON");
    let why = format!("failed runs: {}\nstderr: {stderr}", report["failed_runs"]);
    assert_eq!(report["runs"], 2, "{why}");
    assert_eq!(report["successes"], 2, "{why}");
    assert_eq!(report["success_rate"], 1.0, "{why}");
    assert_eq!(report["failures"], json!({}), "{why}");
    assert_eq!(report["failure_list"], json!([]), "{why}");
    assert_eq!(report["failed_runs"], json!([]), "{why}");
    assert!(report["median_servo_steps"].as_f64().is_some_and(|s| s >= 1.0), "{why}");
    // Each run planned its own grasp on the block nearest its indicated point, a different
    // block in each layout, tracking the gripper at the camera's rate while it planned.
    let detail = report["runs_detail"].as_array().expect("runs_detail");
    assert_eq!(detail.len(), 2);
    let mut targets = Vec::new();
    for d in detail {
        let s = &d["summary"];
        assert_eq!(s["target_source"], "plan", "{s}");
        assert_eq!((&s["failure"], &s["failure_reason"]), (&Value::Null, &Value::Null), "{s}");
        assert_eq!(s["targeted_block"], s["target_block"], "{s}");
        assert!(s["plan_width_mm"].as_f64().is_some_and(|w| w <= 50.0), "the 50 mm width limit: {s}");
        for rate in s["gripper_update_rate_hz"].as_array().expect("rates") {
            assert!(rate.as_f64().unwrap() >= 15.0, "{s}");
        }
        targets.push(s["target_block"].as_str().unwrap().to_string());
    }
    assert_ne!(targets[0], targets[1], "the layouts should differ in their target: {targets:?}");
    // Progress on stderr (not a terminal: one line per run).
    for seed in [8, 9] {
        assert!(stderr.contains(&format!("clutter3 seed {seed}: lifted")), "{stderr}");
    }
    // The report folder: the same JSON, an index with the table linking each run's page, and
    // each page showing the plan and the servo convergence plot, which exist.
    let saved: Value = serde_json::from_str(&std::fs::read_to_string(out.0.join("batch.json")).unwrap()).unwrap();
    assert_eq!(saved["success_rate"], report["success_rate"]);
    let index = std::fs::read_to_string(out.0.join("index.html")).unwrap();
    assert!(index.contains("servo steps") && index.contains("100%"), "{index}");
    for seed in [8, 9] {
        let dir = out.0.join("clutter3").join(format!("seed-{seed}"));
        assert!(index.contains(&format!("clutter3/seed-{seed}/index.html")));
        let page = std::fs::read_to_string(dir.join("index.html")).unwrap();
        assert!(page.contains("servo_convergence.svg") && page.contains("_plan.png"), "{page}");
        let svg = std::fs::read_to_string(dir.join("servo_convergence.svg")).unwrap();
        assert!(svg.contains("servo step") && svg.contains("remaining translation (mm)"));
        assert!(std::fs::read_dir(&dir).unwrap().any(|e| e.unwrap().file_name().to_string_lossy().ends_with("_plan.png")));
    }
}

/// A bad `--config` stops the batch before any run, naming the file and the key: a typo
/// must not cost 30 closed loops that all fail the same way.
#[test]
fn a_bad_daemon_config_fails_before_the_first_run() {
    let dir = TempDir::new("batch-config");
    let config = dir.0.join("fast.toml");
    std::fs::write(&config, "[tracker]\npasses = 0\n").expect("write config");
    let out = dir.0.join("report");
    let o = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .arg("batch")
        .arg(scenario("clutter3.toml"))
        .args(["--seeds", "30", "--config"])
        .arg(&config)
        .arg("--out")
        .arg(&out)
        .env("HANDEYE_LOG", "warn")
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("handeye batch");
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "a bad config must fail the batch");
    assert!(stderr.contains("fast.toml") && stderr.contains("tracker.passes") && stderr.contains("1..=8"), "stderr: {stderr}");
    assert!(!out.exists(), "no run may start (the report folder was created)");
}
