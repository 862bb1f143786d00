//! A source that cannot start, that fails mid-stream, that ends or that goes silent:
//! `handeye camera` reports it by name with GStreamer's text within 500 ms of GStreamer posting
//! it (of the silence exceeding --stall-timeout-s), exits non-zero
//! (subscribers see the publisher gone), or with `--reconnect` rebuilds it and goes on.
#![cfg(feature = "camera")]

mod wire_support;

use std::time::Duration;

use wire_support::*;

/// The bound: from GStreamer's report of the failure to the camera's.
const DETECTION_LIMIT_NS: u64 = 500_000_000;

#[test]
fn a_missing_file_is_reported_by_name_and_the_camera_exits_non_zero() {
    let domain = TestDomain::new("camnofile");
    let out = handeye(&domain)
        .args(["camera", "--mono", "--wait-subscriber-s", "0", "--left", "filesrc location=/nonexistent/cube.mp4 ! decodebin"])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("left source:") && err.contains("/nonexistent/cube.mp4"), "{err}");
}

#[test]
fn a_source_failing_mid_stream_ends_the_run_and_subscribers_see_the_publisher_gone() {
    let domain = TestDomain::new("camfail");
    let mut mon_cmd = handeye(&domain);
    mon_cmd.args(["monitor", "--json", "--timeout-s", "3", "--progress-s", "0"]);
    let mut monitor = Proc::spawn("monitor", mon_cmd);
    monitor.wait_line("listening", Duration::from_secs(20));
    // The right camera breaks after 20 frames (`identity error-after` posts a GStreamer error).
    let mut cam_cmd = handeye(&domain);
    cam_cmd.args([
        "camera",
        "--left",
        "videotestsrc is-live=true ! video/x-raw,framerate=30/1",
        "--right",
        "videotestsrc is-live=true ! video/x-raw,framerate=30/1 ! identity error-after=20",
        "--width-px",
        "160",
        "--height-px",
        "120",
        "--json",
        "--progress-s",
        "0",
        // Not about stalls: a loaded machine must not make one.
        "--stall-timeout-s",
        "5",
    ]);
    let camera = Proc::spawn("camera", cam_cmd);
    let (cam_ok, cam_out, cam_err) = camera.finish(Duration::from_secs(30));
    assert!(!cam_ok, "a failed source must end the camera with an error:\n{cam_err}");
    assert!(cam_err.contains("right source:") && cam_err.contains("identity"), "{cam_err}");
    let c = parse_json(&cam_out);
    let ends = c["source_ends"].as_array().unwrap();
    assert_eq!(ends.len(), 1, "{c}");
    assert_eq!((ends[0]["side"].as_str(), ends[0]["kind"].as_str()), (Some("right"), Some("error")), "{c}");
    assert!(ends[0]["detection_ns"].as_u64().unwrap() < DETECTION_LIMIT_NS, "{c}");
    assert!(c["frames"].as_u64().unwrap() > 0, "frames flowed before the failure: {c}");

    let (mon_ok, mon_out, mon_err) = monitor.finish(Duration::from_secs(30));
    assert!(mon_ok, "{mon_err}");
    let m = parse_json(&mon_out);
    assert_eq!(m["publisher_gone"], 1, "the monitor must see the camera gone: {m}");
    assert!(m["frames"].as_u64().unwrap() > 0, "{m}");
}

#[test]
fn a_live_source_that_ends_is_reported_and_is_an_error() {
    let domain = TestDomain::new("cameos");
    let out = handeye(&domain)
        .args([
            "camera",
            "--mono",
            "--wait-subscriber-s",
            "0",
            "--json",
            "--progress-s",
            "0",
            "--width-px",
            "160",
            "--height-px",
            "120",
            "--stall-timeout-s",
            "5",
            "--left",
            "videotestsrc is-live=true num-buffers=15",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("left source: ended (end of stream)"), "{err}");
    let c = parse_json(&String::from_utf8_lossy(&out.stdout));
    // Every frame before the end is published, or (a live source on a busy machine) counted
    // as dropped.
    let (frames, busy) = (c["frames"].as_u64().unwrap(), c["dropped_busy_left"].as_u64().unwrap());
    assert_eq!(frames + busy, 15, "{c}");
    assert!(frames > 0, "{c}");
    let ends = c["source_ends"].as_array().unwrap();
    assert_eq!((ends.len(), ends[0]["kind"].as_str()), (1, Some("eos")), "{c}");
    assert!(ends[0]["detection_ns"].as_u64().unwrap() < DETECTION_LIMIT_NS, "{c}");
}

#[test]
fn a_live_source_that_goes_silent_is_reported_as_stalled() {
    // A camera that hangs without a word: each frame takes 1.5 s to get through.
    let domain = TestDomain::new("camstall");
    let out = handeye(&domain)
        .args([
            "camera",
            "--mono",
            "--wait-subscriber-s",
            "0",
            "--json",
            "--progress-s",
            "0",
            "--width-px",
            "160",
            "--height-px",
            "120",
            "--stall-timeout-s",
            "0.5",
            "--left",
            "videotestsrc is-live=true ! identity sleep-time=1500000",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("left source: stalled: no frame for"), "{err}");
    let c = parse_json(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(c["frames"], 1, "the first frame came through: {c}");
    let ends = c["source_ends"].as_array().unwrap();
    assert_eq!((ends.len(), ends[0]["kind"].as_str()), (1, Some("stalled")), "{c}");
    // From the moment the silence exceeded --stall-timeout-s to the report.
    assert!(ends[0]["detection_ns"].as_u64().unwrap() < DETECTION_LIMIT_NS, "{c}");
}

#[test]
fn with_reconnect_an_ending_source_is_rebuilt_and_ids_keep_counting() {
    let domain = TestDomain::new("camrecon");
    let out = handeye(&domain)
        .args([
            "camera",
            "--mono",
            "--reconnect",
            "--reconnect-delay-s",
            "0.2",
            "--wait-subscriber-s",
            "0",
            "--count",
            "25",
            "--json",
            "--progress-s",
            "0",
            "--width-px",
            "160",
            "--height-px",
            "120",
            "--stall-timeout-s",
            "5",
            "--left",
            "videotestsrc is-live=true num-buffers=10",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    let c = parse_json(&String::from_utf8_lossy(&out.stdout));
    assert_eq!(c["frames"], 25, "{c}");
    // Ids count on across the restarts: one per frame, published or (busy machine) dropped.
    let n = |k: &str| c[k].as_u64().unwrap_or_else(|| panic!("no {k} in {c}"));
    assert_eq!(n("next_frame_id"), n("frames") + n("dropped"), "{c}");
    assert_eq!(n("last_frame_id") + 1, n("next_frame_id"), "{c}");
    assert!(c["reconnects"].as_u64().unwrap() >= 2, "10 frames per pipeline: {c}");
    assert!(err.contains("left source: ended (end of stream)") && err.contains("running again"), "{err}");
}

#[test]
fn with_reconnect_a_source_that_cannot_start_is_retried_until_interrupted() {
    let domain = TestDomain::new("camretry");
    let mut cmd = handeye(&domain);
    cmd.args([
        "camera",
        "--mono",
        "--reconnect",
        "--reconnect-delay-s",
        "0.1",
        "--wait-subscriber-s",
        "0",
        "--left",
        "filesrc location=/nonexistent/cam.mp4 ! decodebin",
    ]);
    let mut camera = Proc::spawn("camera", cmd);
    camera.wait_line("(attempt 1)", Duration::from_secs(20));
    let line = camera.wait_line("(attempt 3)", Duration::from_secs(20));
    assert!(line.contains("left source:") && line.contains("/nonexistent/cam.mp4"), "{line}");
    camera.interrupt();
    let (ok, _, err) = camera.finish(Duration::from_secs(20));
    assert!(ok, "Ctrl-C is a clean stop:\n{err}");
}
