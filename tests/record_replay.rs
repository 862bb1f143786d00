//! `handeye record` and `handeye feed --dir` replaying a recording, across processes: a
//! lockstep simulator run is recorded, replayed (losslessly, and at its recorded timing) and
//! recorded again; the pixels and the frame timing (ids, capture-time differences) must come
//! back identical.

mod e2e_support;
mod wire_support;

use std::path::Path;
use std::time::Duration;

use handeye_sim::hash::FramesHash;
use serde_json::Value;
use wire_support::{handeye, parse_json, Proc, TempDir, TestDomain};

/// The frames of a lockstep run: a small number keeps the test short.
const SIM_FRAMES: u64 = 24;

/// `frames.jsonl` of a recording, one JSON object per line.
fn lines(dir: &Path) -> Vec<Value> {
    let text = std::fs::read_to_string(dir.join("frames.jsonl")).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    text.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

fn u(v: &Value, key: &str) -> u64 {
    v[key].as_u64().unwrap_or_else(|| panic!("no {key} in {v}"))
}

/// (id, capture time after the recording's first frame) per line.
fn timing(lines: &[Value]) -> Vec<(u64, u64)> {
    let t0 = u(&lines[0], "capture_time_ns");
    lines.iter().map(|l| (u(l, "id"), u(l, "capture_time_ns") - t0)).collect()
}

/// Starts `handeye record --out DIR [extra]` in `domain` and waits until it listens.
fn start_recorder(domain: &TestDomain, out: &Path, extra: &[&str]) -> Proc {
    let mut cmd = handeye(domain);
    cmd.args(["record", "--json", "--timeout-s", "120", "--progress-s", "0"]).args(extra).arg("--out").arg(out);
    let mut rec = Proc::spawn("record", cmd);
    rec.wait_line("record: listening", Duration::from_secs(30));
    rec
}

/// Waits for the recorder to end by itself (its publisher gone) and returns recording.json.
fn finish_recorder(rec: Proc, out: &Path) -> Value {
    let (ok, stdout, stderr) = rec.finish(Duration::from_secs(120));
    assert!(ok, "record failed:\n{stderr}");
    let printed = parse_json(&stdout);
    let file: Value = serde_json::from_str(&std::fs::read_to_string(out.join("recording.json")).unwrap()).unwrap();
    assert_eq!(printed, file, "--json prints recording.json");
    assert_eq!(file["ended_by"], "publisher_gone", "{file}\n{stderr}");
    file
}

/// Every id between the first and the last line is either a line or counted before one.
fn assert_accounted(summary: &Value, lines: &[Value]) {
    let (first, last) = (u(&lines[0], "id"), u(&lines[lines.len() - 1], "id"));
    let lost: u64 = lines.iter().map(|l| u(l, "missed_before") + u(l, "not_kept_before")).sum();
    assert_eq!(lines.len() as u64 + lost, last - first + 1, "{summary}");
    assert_eq!(u(summary, "frames"), lines.len() as u64, "{summary}");
    assert_eq!(u(summary, "received"), u(summary, "frames") + u(summary, "not_kept"), "{summary}");
    for l in lines {
        for key in ["left", "right"] {
            let file = l[key].as_str().unwrap();
            assert!(file.ends_with(&format!("{:08}.png", u(l, "id"))), "{l}");
        }
    }
}

/// Replays recording `from` with `feed --dir` at `rate` into a fresh recording `to`.
fn replay(from: &Path, to: &Path, rate: &str, stem: &str, record_extra: &[&str]) -> Value {
    let domain = TestDomain::new(stem);
    let rec = start_recorder(&domain, to, record_extra);
    let mut cmd = handeye(&domain);
    cmd.args(["feed", "--rate-hz", rate, "--dir"]).arg(from);
    let (ok, _, stderr) = Proc::spawn("feed", cmd).finish(Duration::from_secs(120));
    assert!(ok, "feed --dir {} failed:\n{stderr}", from.display());
    finish_recorder(rec, to)
}

#[test]
fn a_recorded_simulator_run_replays_to_the_same_pixels_and_timing() {
    let _one = e2e_support::one_at_a_time();
    let tmp = TempDir::new("record-replay");
    let scenario = e2e_support::scenario_without_antialias("pick_cube.toml", &tmp.0);
    let (r1, r2, r3) = (tmp.0.join("r1"), tmp.0.join("r2"), tmp.0.join("r3"));

    // 1. A lockstep simulator with no daemon attached steps on by itself: the recorder is
    //    all it needs besides itself.
    let domain = TestDomain::new("record-sim");
    let rec = start_recorder(&domain, &r1, &[]);
    let mut sim = handeye(&domain);
    sim.args(["sim", scenario.to_str().unwrap(), "--lockstep", "--json", "--frames", &SIM_FRAMES.to_string()]);
    let (ok, sim_out, sim_err) = Proc::spawn("sim", sim).finish(Duration::from_secs(180));
    assert!(ok, "sim failed:\n{sim_err}");
    let sim_report = parse_json(&sim_out);
    let s1 = finish_recorder(rec, &r1);
    let l1 = lines(&r1);
    assert!(!l1.is_empty(), "{s1}");
    assert_accounted(&s1, &l1);
    assert!(u(&l1[l1.len() - 1], "id") < SIM_FRAMES, "{s1}");
    assert!(u(&s1, "robot_states") > 0, "the simulator's robot state is recorded: {s1}");
    assert_eq!(u(&s1, "telemetry"), 0, "no daemon, no telemetry: {s1}");
    assert!(!r1.join("telemetry.jsonl").exists());
    assert_eq!(u(&s1, "cameras"), 2, "{s1}");
    if l1.len() as u64 == SIM_FRAMES {
        // Nothing lost: the PNGs hold exactly the pixels the simulator published.
        let mut hash = FramesHash::default();
        for l in &l1 {
            let left = image::open(r1.join(l["left"].as_str().unwrap())).unwrap().to_luma8();
            let right = image::open(r1.join(l["right"].as_str().unwrap())).unwrap().to_luma8();
            hash.add(&[left.into_raw(), right.into_raw()].concat());
        }
        assert_eq!(format!("{:016x}", hash.value), sim_report["frames_hash"].as_str().unwrap(), "recorded pixels differ from the published ones");
    } else {
        eprintln!("the recorder kept {} of {SIM_FRAMES} frames under this load: {s1}", l1.len());
    }

    // 2. Lossless replay, recorded again: the same frames, pixels, ids, gaps and timing. A
    //    writer queue of two frames: the lossless feed must wait for the PNG writer, not
    //    lose frames to it.
    let s2 = replay(&r1, &r2, "0", "record-replay0", &["--buffer-frames", "2"]);
    let l2 = lines(&r2);
    assert_eq!(u(&s2, "not_kept"), 0, "{s2}");
    assert_eq!(timing(&l2), timing(&l1), "ids and capture-time differences");
    let gaps = |ls: &[Value]| ls.iter().map(|l| u(l, "missed_before") + u(l, "not_kept_before")).collect::<Vec<_>>();
    assert_eq!(gaps(&l2), gaps(&l1));
    assert_eq!(s2["checksum"], s1["checksum"], "pixels");
    assert_eq!((s2["width"].clone(), s2["height"].clone()), (s1["width"].clone(), s1["height"].clone()));

    // 3. Replay at the recorded timing (a camera: a lagging subscriber may lose frames, which
    //    it counts): every frame that arrives has its recorded id and capture-time offset.
    let s3 = replay(&r2, &r3, "recorded", "record-replay-timed", &[]);
    let l3 = lines(&r3);
    assert_accounted(&s3, &l3);
    let recorded: std::collections::HashMap<u64, u64> = timing(&l1).into_iter().collect();
    let first = u(&l3[0], "id");
    for (id, offset) in timing(&l3) {
        let expected = recorded[&id] - recorded[&first];
        assert_eq!(offset, expected, "frame {id}: capture offset");
    }
    if l3.len() == l1.len() {
        assert_eq!(s3["checksum"], s1["checksum"]);
    }
}

#[test]
fn feed_refuses_recorded_timing_for_a_plain_folder_and_names_a_bad_line() {
    let domain = TestDomain::new("record-bad");
    let tmp = TempDir::new("record-bad");
    wire_support::write_pngs(&tmp.0.join("left"), 2, 8, 4, 0);
    wire_support::write_pngs(&tmp.0.join("right"), 2, 8, 4, 1);
    let out = handeye(&domain).args(["feed", "--rate-hz", "recorded", "--dir"]).arg(&tmp.0).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("frames.jsonl"), "{err}");
    std::fs::write(
        tmp.0.join("frames.jsonl"),
        "{\"id\":0,\"capture_time_ns\":5,\"left\":\"left/frame0000.png\",\"right\":\"right/frame0000.png\"}\n\
         {\"id\":1,\"capture_time_ns\":\"late\",\"left\":\"left/frame0001.png\",\"right\":\"right/frame0001.png\"}\n",
    )
    .unwrap();
    let out = handeye(&domain).args(["feed", "--dir"]).arg(&tmp.0).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("frames.jsonl line 2") && err.contains("capture_time_ns"), "{err}");
    let out = handeye(&domain).args(["record", "--out"]).arg(&tmp.0).output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("already holds a recording"), "{err}");
}
