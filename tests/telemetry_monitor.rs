//! `handeye monitor --telemetry --json` beside a closed-loop run (`handeye run`): the
//! daemon's phases appear in order, and the tracker update time the monitor computes from
//! the telemetry agrees with what the daemon writes into `daemon.json`.

mod e2e_support;
mod wire_support;

use std::fs::File;
use std::process::Stdio;
use std::time::{Duration, Instant};

use serde_json::Value;
use wire_support::{handeye, Kid, TempDir, TestDomain};

const PHASES: [&str; 8] = ["acquire_gripper", "calibrate", "plan", "acquire_target", "servo", "grasp", "lift", "done"];

#[test]
fn monitor_shows_the_phases_in_order_and_the_tracker_time_the_daemon_reports() {
    let _one = e2e_support::one_at_a_time();
    let domain = TestDomain::new("telemetry-run");
    let tmp = TempDir::new("telemetry-run");
    // The monitor writes one line per cycle (thousands): into a file, not a pipe.
    let (out_path, err_path) = (tmp.0.join("monitor.jsonl"), tmp.0.join("monitor.stderr.log"));
    let mut cmd = handeye(&domain);
    cmd.args(["monitor", "--telemetry", "--json", "--timeout-s", "300"])
        .stdin(Stdio::null())
        .stdout(File::create(&out_path).unwrap())
        .stderr(File::create(&err_path).unwrap());
    let mut monitor = Kid(cmd.spawn().unwrap());
    let t0 = Instant::now();
    while !std::fs::read_to_string(&err_path).unwrap_or_default().contains("listening") {
        assert!(t0.elapsed() < Duration::from_secs(30), "the monitor did not start");
        std::thread::sleep(Duration::from_millis(20));
    }

    let run_out = tmp.0.join("run");
    let run = handeye(&domain)
        .args(["run", e2e_support::scenario("pick_cube.toml").to_str().unwrap(), "--hint", "--json", "--domain", domain.name(), "--out"])
        .arg(&run_out)
        .output()
        .unwrap();
    let summary = String::from_utf8_lossy(&run.stdout);
    // The monitor ends by itself when the daemon's telemetry publisher goes away.
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = monitor.0.try_wait().unwrap() {
            break s;
        }
        assert!(t0.elapsed() < Duration::from_secs(30), "the monitor did not end after the daemon");
        std::thread::sleep(Duration::from_millis(50));
    };
    let err = std::fs::read_to_string(&err_path).unwrap();
    assert!(status.success(), "monitor failed:\n{err}");
    assert!(err.contains("ended by publisher_gone"), "{err}");

    let samples: Vec<Value> =
        std::fs::read_to_string(&out_path).unwrap().lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let daemon: Value = serde_json::from_str(&std::fs::read_to_string(run_out.join("daemon.json")).unwrap()).unwrap();
    let why = format!("run: {summary}\ndaemon.json phase_reached {} tracker_update {}", daemon["phase_reached"], daemon["tracker_update"]);
    assert!(run.status.success() && daemon["success"] == true, "{why}");

    // Phases: each new one comes later in the mission than the one before, ending in done.
    let mut seen: Vec<&str> = Vec::new();
    for s in &samples {
        let p = s["phase"].as_str().unwrap();
        if seen.last() != Some(&p) {
            seen.push(p);
        }
    }
    let index = |p: &str| PHASES.iter().position(|&q| q == p).unwrap_or_else(|| panic!("unexpected phase {p}: {seen:?}"));
    assert!(seen.windows(2).all(|w| index(w[0]) < index(w[1])), "phases out of order: {seen:?}");
    for p in ["acquire_gripper", "calibrate", "acquire_target", "servo", "grasp", "lift", "done"] {
        assert!(seen.contains(&p), "{p} never shown: {seen:?}");
    }

    // Tracker and cycle time: the last sample's stats are over every sample the monitor saw,
    // the daemon's over every cycle.
    let stats = &samples.last().unwrap()["stats"];
    let reported = &daemon["tracker_update"];
    let count = |v: &Value| v.as_u64().unwrap();
    let (mine, theirs) = (count(&stats["tracker_cycles"]), count(&reported["cycles"]));
    assert!(theirs > 100 && mine <= theirs, "{stats}\n{why}");
    let pairs = [
        ("tracker_update_us_p50", &reported["us_p50"], mine, theirs),
        ("tracker_update_us_p99", &reported["us_p99"], mine, theirs),
        ("cycle_us_p50", &daemon["loop_us_p50"], count(&stats["cycles"]), count(&daemon["cycles"])),
        ("cycle_us_p99", &daemon["loop_us_p99"], count(&stats["cycles"]), count(&daemon["cycles"])),
    ];
    for (key, daemon_value, seen, all) in pairs {
        let (a, b) = (stats[key].as_f64().unwrap(), daemon_value.as_f64().unwrap());
        assert!(a > 0.0, "{stats}");
        if seen == all {
            // Every cycle seen: the same values in the same histogram.
            assert_eq!(a, b, "{key}: monitor {stats}\n{why}");
        } else if key.ends_with("p50") {
            // A few samples lost to a busy machine (the telemetry queue holds 8): the median
            // may move by a bucket (1/16) or so; the tail depends on which were lost.
            eprintln!("{key}: the monitor saw {seen} of {all} cycles");
            assert!((a - b).abs() <= 0.15 * b, "{key}: monitor {a} µs, daemon {b} µs\n{stats}\n{why}");
        }
    }
    let rate = stats["tracker_rate_hz"].as_f64().unwrap();
    assert!((rate - 1e6 / stats["tracker_update_us_p50"].as_f64().unwrap()).abs() < 1e-6 * rate, "{stats}");
    // The frames/s tracked is live (the last two seconds); while the trackers ran it was up.
    let tracked = samples.iter().filter_map(|s| s["stats"]["tracked_fps"].as_f64()).fold(0.0, f64::max);
    assert!(tracked > 0.0, "{stats}");
    eprintln!("monitor: {mine} tracking cycles (daemon {theirs}), p50 {} µs, up to {tracked:.1} frames/s tracked", stats["tracker_update_us_p50"]);
    // Per tracker: a tracker that is off took no time; one that tracks was timed (all but
    // the cycle that started it).
    let (mut tracking, mut timed) = (0, 0);
    for s in &samples {
        for t in s["trackers"].as_array().unwrap() {
            if t["state"] == "off" {
                assert_eq!(t["update_ns"], 0, "{t}");
            } else if t["state"] == "tracking" {
                tracking += 1;
                timed += u32::from(t["update_ns"].as_u64().unwrap() > 0);
            }
        }
    }
    assert!(tracking > 0 && timed * 10 >= tracking * 9, "{timed} of {tracking} tracking samples timed");
}
