//! `handeye daemon --observe` on a replayed simulator recording, judged against ground
//! truth. The simulator runs a static scene in real time (pick_cube, no daemon, no driver:
//! the arm stays parked) and writes the operator hint (`--hint-out`) and, beside the
//! recording, the hinted facet's true corners in both views and how many of its pixels
//! something hides, for every frame (`--truth-out`), which the daemon never sees. `handeye record` records
//! it; `handeye feed --dir --rate-hz recorded` replays it into the daemon in observe mode.
//! From the frame each view's target tracker was verified on, its corners stay within
//! 1.5 px of the true ones on every frame where the facet is unoccluded, in both views
//! (here: every frame, which the truth confirms).

mod e2e_support;
mod wire_support;

use std::collections::HashMap;
use std::fs::File;
use std::process::Stdio;
use std::time::{Duration, Instant};

use serde_json::Value;
use wire_support::{handeye, json_lines, parse_json, Kid, Proc, TempDir, TestDomain};

/// Frames the simulator publishes.
const SIM_FRAMES: u64 = 75;
/// Largest distance of a tracked corner from the true one, px.
const MAX_CORNER_ERROR_PX: f64 = 1.5;

fn corners(v: &Value) -> Vec<[f64; 2]> {
    v.as_array().unwrap().iter().map(|p| [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()]).collect()
}

/// The largest distance from a true corner to the tracked corner nearest it, px.
fn worst_corner_px(truth: &[[f64; 2]], tracked: &[[f64; 2]]) -> f64 {
    truth.iter().map(|t| tracked.iter().map(|c| (c[0] - t[0]).hypot(c[1] - t[1])).fold(f64::INFINITY, f64::min)).fold(0.0, f64::max)
}

#[test]
fn observed_target_corners_stay_within_1_5_px_of_the_truth_in_both_views() {
    let _one = e2e_support::one_at_a_time();
    let tmp = TempDir::new("observe-sim");
    let (rec, hint, truth_path, out) = (tmp.0.join("rec"), tmp.0.join("hint.json"), tmp.0.join("truth.jsonl"), tmp.0.join("out"));

    // 1. Record the simulator; the hint and the truth are written beside the recording.
    let domain = TestDomain::new("observe-sim-rec");
    let mut recorder = handeye(&domain);
    recorder.args(["record", "--json", "--timeout-s", "120", "--progress-s", "0", "--out"]).arg(&rec);
    let mut recorder = Proc::spawn("record", recorder);
    recorder.wait_line("record: listening", Duration::from_secs(30));
    let mut sim = handeye(&domain);
    sim.args(["sim", e2e_support::scenario("pick_cube.toml").to_str().unwrap(), "--json", "--frames", &SIM_FRAMES.to_string()])
        .arg("--hint-out")
        .arg(&hint)
        .arg("--truth-out")
        .arg(&truth_path);
    let (ok, sim_out, sim_err) = Proc::spawn("sim", sim).finish(Duration::from_secs(180));
    assert!(ok, "sim failed:\n{sim_err}");
    assert_eq!(parse_json(&sim_out)["frames"].as_u64(), Some(SIM_FRAMES));
    let (ok, _, rec_err) = recorder.finish(Duration::from_secs(60));
    assert!(ok, "record failed:\n{rec_err}");
    let truth: HashMap<u64, Value> = json_lines(&truth_path).into_iter().map(|l| (l["frame_id"].as_u64().unwrap(), l)).collect();
    assert_eq!(truth.len() as u64, SIM_FRAMES, "one truth line per published frame");
    let recorded = json_lines(&rec.join("frames.jsonl"));
    assert!(recorded.len() as u64 > SIM_FRAMES / 2, "the recorder kept {} of {SIM_FRAMES} frames", recorded.len());

    // 2. Replay it at its recorded timing into the daemon in observe mode.
    let domain = TestDomain::new("observe-sim-play");
    let (tel_path, tel_err) = (tmp.0.join("telemetry.jsonl"), tmp.0.join("monitor.log"));
    let mut monitor = handeye(&domain);
    monitor
        .args(["monitor", "--telemetry", "--json", "--timeout-s", "120"])
        .stdin(Stdio::null())
        .stdout(File::create(&tel_path).unwrap())
        .stderr(File::create(&tel_err).unwrap());
    let mut monitor = Kid(monitor.spawn().unwrap());
    let t0 = Instant::now();
    while !std::fs::read_to_string(&tel_err).unwrap_or_default().contains("listening") {
        assert!(t0.elapsed() < Duration::from_secs(30), "the monitor did not start");
        std::thread::sleep(Duration::from_millis(20));
    }
    let mut daemon = handeye(&domain);
    daemon.args(["daemon", "--observe", "--end-after-gone-s", "1", "--hint"]).arg(&hint).arg("--out").arg(&out);
    let mut daemon = Proc::spawn("daemon", daemon);
    daemon.wait_line("observing", Duration::from_secs(30));
    let mut feed = handeye(&domain);
    feed.args(["feed", "--rate-hz", "recorded", "--dir"]).arg(&rec);
    let (ok, _, feed_err) = Proc::spawn("feed", feed).finish(Duration::from_secs(120));
    assert!(ok, "feed failed:\n{feed_err}");
    let (ok, stdout, stderr) = daemon.finish(Duration::from_secs(60));
    assert!(ok, "daemon:\n{stdout}\n{stderr}");
    while monitor.0.try_wait().unwrap().is_none() {
        assert!(t0.elapsed() < Duration::from_secs(120), "the monitor did not end after the daemon");
        std::thread::sleep(Duration::from_millis(50));
    }
    let report: Value = serde_json::from_str(&std::fs::read_to_string(out.join("observe.json")).unwrap()).unwrap();
    let acquired: HashMap<String, u64> = report["trackers"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| (t["name"].as_str().unwrap().to_string(), t["acquired_frame_id"].as_u64().unwrap_or_else(|| panic!("never acquired: {t}"))))
        .collect();

    // 3. Every frame from acquisition on: both views tracking, corners on the truth.
    let samples: Vec<Value> = json_lines(&tel_path).into_iter().filter(|s| s["frame_id"].is_u64()).collect();
    // Every replayed frame answered, or (a loaded machine) counted as dropped.
    let ids: Vec<u64> = samples.iter().map(|s| s["frame_id"].as_u64().unwrap()).collect();
    let recorded_ids: Vec<u64> = recorded.iter().map(|l| l["id"].as_u64().unwrap()).collect();
    assert!(ids.iter().all(|id| recorded_ids.contains(id)), "telemetry answers replayed frames only");
    let span = ids.last().unwrap() - ids[0] + 1;
    assert_eq!(report["camera"]["dropped_frames"].as_u64(), Some(span - ids.len() as u64), "{}", report["camera"]);
    if ids.len() < recorded.len() {
        eprintln!("the daemon answered {} of {} replayed frames under this load", ids.len(), recorded.len());
    }
    let mut judged = 0;
    let mut worst = [0.0f64; 2];
    for s in &samples {
        let id = s["frame_id"].as_u64().unwrap();
        let t = &truth[&id];
        if t["occluded_px"] != serde_json::json!([0, 0]) {
            continue;
        }
        for (k, (slot, key)) in [(2, "left_px"), (3, "right_px")].into_iter().enumerate() {
            let tracker = &s["trackers"][slot];
            let name = tracker["tracker"].as_str().unwrap();
            if id < acquired[name] {
                continue;
            }
            assert_eq!(tracker["state"], "tracking", "frame {id}: {s}");
            let err = worst_corner_px(&corners(&t[key]), &corners(&tracker["corners_px"]));
            worst[k] = worst[k].max(err);
            assert!(err <= MAX_CORNER_ERROR_PX, "frame {id}, {name}: a corner {err:.2} px from the truth\ntruth {}\ntracked {}", t[key], tracker["corners_px"]);
            judged += 1;
        }
    }
    let acquired_at = acquired.values().max().copied().unwrap();
    let after = ids.iter().filter(|&&id| id >= acquired_at).count();
    assert!(judged >= 2 * after, "both views judged on every frame from acquisition on: {judged} < 2 x {after}");
    eprintln!("{judged} corner sets judged from frame {acquired_at}; worst corner error left {:.2} px, right {:.2} px", worst[0], worst[1]);
}
