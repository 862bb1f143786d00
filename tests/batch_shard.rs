//! `handeye batch --shard K/N` and `handeye batch merge` as a cluster runs them: a batch's
//! three shards, run as separate processes into their own folders and merged, give the table
//! and the decisions in batch.json of the same batch run unsharded, from real runs.

mod e2e_support;

use std::path::Path;
use std::process::{Command, Output};

use e2e_support::{one_at_a_time, scenario, TempDir};
use serde_json::Value;

fn handeye(args: &[&str], paths: &[&Path]) -> Output {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_handeye"));
    cmd.args(args).args(paths).env("HANDEYE_LOG", "warn").env_remove("RUST_BACKTRACE");
    cmd.output().expect("handeye")
}

fn ok(o: &Output) -> String {
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "stderr: {stderr}");
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The table without what depends on the machine's speed: the run-wall column, the total
/// wall time and the report's path.
fn table_without_wall_times(table: &str) -> String {
    table
        .lines()
        .filter(|l| !l.starts_with("wall time:") && !l.starts_with("report:"))
        .map(|l| if l.starts_with("pick_cube ") || l.starts_with("all ") { l[..l.len() - 10].trim_end() } else { l })
        .collect::<Vec<_>>()
        .join("\n")
}

/// What a batch decided, from its batch.json: the totals, the failure groups and failed runs,
/// the batch's identity, and per run what it did (lifted or not, the phase and failure, the
/// target and the facet, the plan's counts, the servo steps). Left out: wall times, and what
/// follows from how long the daemon's worker took (the frames it planned over, and so the
/// final errors to the micrometre): on a loaded machine a plan can be taken a few frames
/// later than its 30, in a sharded and an unsharded run alike.
fn decisions(v: &Value) -> Value {
    let pick = |v: &Value, keys: &[&str]| Value::Object(keys.iter().map(|k| (k.to_string(), v[*k].clone())).collect());
    let mut scenarios = v["scenarios"].clone();
    for g in scenarios.as_object_mut().expect("scenarios").values_mut() {
        *g = pick(g, &["runs", "successes", "success_rate", "failures", "failure_list", "median_servo_steps"]);
    }
    let run_keys = ["success", "phase_reached", "final_phase", "failure", "target_block", "targeted_block", "targeted_face", "plan_facets", "plan_candidates", "servo_steps"];
    let runs: Vec<Value> = v["runs_detail"].as_array().expect("runs_detail").iter().map(|d| serde_json::json!([d["scenario"], d["seed"], pick(&d["summary"], &run_keys)])).collect();
    let mut top = pick(v, &["batch", "runs", "successes", "success_rate", "failures", "failure_list", "failed_runs", "median_servo_steps", "daemon_config"]);
    top["scenarios"] = scenarios;
    top["runs_detail"] = Value::Array(runs);
    top
}

fn batch_json(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("batch.json")).expect("batch.json")).expect("JSON")
}

#[test]
fn three_shards_merged_give_the_table_and_json_of_the_unsharded_batch() {
    let _one = one_at_a_time();
    let tmp = TempDir::new("shard");
    let pick = scenario("pick_cube.toml");
    let common = ["batch", "--seeds", "3", "--first-seed", "4"];
    let whole = tmp.0.join("whole");
    let whole_table = ok(&handeye(&[&common[..], &["--out"]].concat(), &[&whole, &pick]));
    let shards: Vec<_> = (1..=3).map(|k| tmp.0.join(format!("shard-{k}"))).collect();
    for (k, dir) in shards.iter().enumerate() {
        let spec = format!("{}/3", k + 1);
        ok(&handeye(&[&common[..], &["--shard", &spec, "--out"]].concat(), &[dir, &pick]));
        // Each shard ran its one seed: 4, 5 and 6.
        let json = batch_json(dir);
        assert_eq!((&json["runs"], &json["runs_detail"][0]["seed"]), (&Value::from(1), &Value::from(4 + k as u64)), "shard {spec}");
    }
    // Two of three shards: refused, naming the missing one.
    let o = handeye(&["batch", "merge"], &[&shards[0], &shards[2]]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("incomplete") && stderr.contains("2/3") && stderr.contains("pick_cube#5"), "{stderr}");
    // All three, given in any order.
    let merged = tmp.0.join("merged");
    let merged_table = ok(&handeye(&["batch", "merge", "--out"], &[&merged, &shards[2], &shards[0], &shards[1]]));
    assert_eq!(table_without_wall_times(&merged_table), table_without_wall_times(&whole_table), "merged:\n{merged_table}\nwhole:\n{whole_table}");
    let (w, m) = (batch_json(&whole), batch_json(&merged));
    assert_eq!(m["runs"], 3);
    assert_eq!(m["batch"]["shard"], Value::Null);
    assert_eq!(decisions(&m), decisions(&w));
    // The merge itself loses nothing: its runs are the shards' runs to the last digit,
    // wall times included, in the batch's order.
    let from_shards: Vec<Value> = shards.iter().map(|d| batch_json(d)["runs_detail"][0].clone()).collect();
    assert_eq!(m["runs_detail"], Value::Array(from_shards));
    // The merged report folder: the index links each run's page, copied with its report.
    let index = std::fs::read_to_string(merged.join("index.html")).expect("index.html");
    for seed in 4..=6 {
        assert!(index.contains(&format!("pick_cube/seed-{seed}/index.html")), "{index}");
        let run = merged.join("pick_cube").join(format!("seed-{seed}"));
        assert!(run.join("index.html").is_file() && run.join("run.json").is_file(), "{}", run.display());
    }
}

#[test]
fn a_bad_shard_is_refused_before_any_run() {
    let tmp = TempDir::new("shard-bad");
    let out = tmp.0.join("out");
    let o = handeye(&["batch", "--seeds", "3", "--shard", "4/3", "--out"], &[&out, &scenario("pick_cube.toml")]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("--shard") && stderr.contains("between 1 and 3"), "{stderr}");
    // More shards than seeds: this shard would run nothing, which is a mistake worth saying.
    let o = handeye(&["batch", "--seeds", "2", "--shard", "3/3", "--out"], &[&out, &scenario("pick_cube.toml")]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("no seeds"), "{stderr}");
    assert!(!out.exists(), "no run may start");
    // A folder that is no batch's.
    let o = handeye(&["batch", "merge"], &[&tmp.0]);
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && stderr.contains("no batch.json") && stderr.contains(&tmp.0.display().to_string()), "{stderr}");
}
