//! `handeye camera` with two live sources at different frame rates: only pairs within
//! `--max-skew-ms` are published, the other frames are dropped and counted, the counts add
//! up, and each dropped left frame leaves a gap in the ids that a subscriber sees.
#![cfg(feature = "camera")]

mod wire_support;

use std::time::Duration;

use wire_support::*;

#[test]
fn two_rates_publish_only_pairs_within_the_skew_and_count_the_rest() {
    let domain = TestDomain::new("campair");
    let mut mon_cmd = handeye(&domain);
    mon_cmd.args(["monitor", "--count", "20", "--json", "--timeout-s", "30", "--progress-s", "0"]);
    let mut monitor = Proc::spawn("monitor", mon_cmd);
    monitor.wait_line("listening", Duration::from_secs(20));
    // 30 and 20 frames/s on one clock: exposures meet every 100 ms, whatever the two
    // pipelines' start times, within half of 1/60 s (the grids' differences are 16.7 ms
    // apart), so 9 ms always finds pairs and drops the frames in between.
    let mut cam_cmd = handeye(&domain);
    cam_cmd.args([
        "camera",
        "--left",
        "videotestsrc is-live=true ! video/x-raw,framerate=30/1",
        "--right",
        "videotestsrc is-live=true pattern=ball ! video/x-raw,framerate=20/1",
        "--max-skew-ms",
        "9",
        "--width-px",
        "160",
        "--height-px",
        "120",
        "--count",
        "20",
        "--json",
        "--progress-s",
        "0",
        // Not about stalls: a loaded machine must not make one.
        "--stall-timeout-s",
        "5",
    ]);
    let camera = Proc::spawn("camera", cam_cmd);
    let (cam_ok, cam_out, cam_err) = camera.finish(Duration::from_secs(60));
    let (mon_ok, mon_out, mon_err) = monitor.finish(Duration::from_secs(30));
    assert!(cam_ok, "camera failed:\n{cam_err}");
    assert!(mon_ok, "monitor failed:\n{mon_err}");

    let c = parse_json(&cam_out);
    let n = |k: &str| c[k].as_u64().unwrap_or_else(|| panic!("no {k} in {c}"));
    assert_eq!(c["delivery"], "latest", "live sources: {c}");
    assert_eq!((c["left_live"].as_bool(), c["right_live"].as_bool()), (Some(true), Some(true)), "{c}");
    assert_eq!(n("frames"), 20, "{c}");
    assert!(n("skew_ns_max") <= 9_000_000, "a published pair is further apart than --max-skew-ms: {c}");
    // At 30 against 20 frames/s at most one left frame in three has a partner.
    assert!(n("dropped_skew") >= 20, "frames between the meeting points must be dropped: {c}");
    assert!(n("right_unpaired") >= 10, "{c}");
    // Every left frame is published, dropped or still waiting; every id is a left frame.
    assert_eq!(n("left_frames"), n("frames") + n("dropped_skew") + n("dropped_stale") + n("dropped_publish") + n("pending_left"), "{c}");
    assert_eq!(n("right_frames"), n("frames") + n("right_unpaired") + n("pending_right"), "{c}");
    assert_eq!(n("next_frame_id"), n("frames") + n("dropped"), "{c}");
    assert!(n("last_frame_id") < n("next_frame_id"), "{c}");

    // The monitor saw the gaps: every id between the first and last published one that was
    // not published is a dropped frame.
    let m = parse_json(&mon_out);
    assert_eq!((m["frames"].as_u64(), m["rejected"].as_u64()), (Some(20), Some(0)), "{m}");
    let span = n("last_frame_id") - n("first_frame_id") + 1;
    assert_eq!(m["missed"].as_u64(), Some(span - 20), "monitor {m}\ncamera {c}");
}
