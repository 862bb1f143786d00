//! `handeye camera` on a video file (an H.264 MP4 made from the real `visp-cube` frames) with
//! `handeye monitor` in another process: every frame arrives, its pixels are GStreamer's own
//! decoding of the file, and ids and capture times increase.
#![cfg(feature = "camera")]

mod camera_support;
mod data_support;
mod wire_support;

use std::time::Duration;

use handeye_wire::stereo::{StereoEvent, StereoSubscriber};
use handeye_wire::WireNode;
use wire_support::*;

#[test]
fn a_video_file_arrives_whole_with_gstreamers_own_pixels() {
    let Some(cube) = data_support::visp_cube(&["image0000.png", "image0119.png"]) else { return };
    let tmp = TempDir::new("camera-file");
    let video = tmp.0.join("cube.mp4");
    camera_support::make_cube_video(&cube, 120, &video);
    let (expected, decoded) = camera_support::decoded_checksum(&video, 100, 640, 480);
    assert_eq!(decoded, 120, "the test video should hold 120 frames");

    let domain = TestDomain::new("camfile");
    // A subscriber of our own, to see ids and capture times; the monitor is the acceptance's.
    let node = WireNode::create(&domain.0, "camera-test").unwrap();
    let mut sub = StereoSubscriber::create(&node, 2).unwrap();
    let mut mon_cmd = handeye(&domain);
    mon_cmd.args(["monitor", "--count", "100", "--json", "--checksum", "--timeout-s", "60", "--progress-s", "0"]);
    let mut monitor = Proc::spawn("monitor", mon_cmd);
    monitor.wait_line("listening", Duration::from_secs(20));
    let mut cam_cmd = handeye(&domain);
    cam_cmd
        .args(["camera", "--mono", "--count", "100", "--json", "--progress-s", "0", "--left"])
        .arg(format!("filesrc location={} ! decodebin", video.display()));
    let camera = Proc::spawn("camera", cam_cmd);

    // (frame id, capture ns, publish ns) of every frame, taken while the camera runs.
    let mut seen: Vec<(u64, u64, u64)> = Vec::new();
    let deadline = std::time::Instant::now() + Duration::from_secs(90);
    while seen.len() < 100 && std::time::Instant::now() < deadline {
        if let StereoEvent::Frame(f) = sub.wait(Duration::from_millis(200)).unwrap() {
            let h = f.header();
            seen.push((h.frame_id, h.capture_time_ns, h.publish_time_ns));
        }
    }
    let (cam_ok, cam_out, cam_err) = camera.finish(Duration::from_secs(60));
    let (mon_ok, mon_out, mon_err) = monitor.finish(Duration::from_secs(30));
    assert!(cam_ok, "camera failed:\n{cam_err}");
    assert!(mon_ok, "monitor failed:\n{mon_err}");

    let m = parse_json(&mon_out);
    assert_eq!((m["frames"].as_u64(), m["rejected"].as_u64(), m["missed"].as_u64()), (Some(100), Some(0), Some(0)), "{m}");
    assert_eq!(m["checksum"].as_str(), Some(expected.as_str()), "the monitor's pixels differ from GStreamer's decoding of the file");

    let c = parse_json(&cam_out);
    assert_eq!(c["delivery"], "lossless", "a file is not live: {c}");
    assert_eq!((c["frames"].as_u64(), c["dropped"].as_u64()), (Some(100), Some(0)), "{c}");
    assert_eq!((c["first_frame_id"].as_u64(), c["last_frame_id"].as_u64()), (Some(0), Some(99)), "{c}");
    assert_eq!(c["arrival_stamped"], 0, "every buffer of a file has a timestamp: {c}");

    assert_eq!(seen.len(), 100, "our subscriber got {} frames", seen.len());
    for (i, w) in seen.windows(2).enumerate() {
        assert_eq!(w[1].0, w[0].0 + 1, "ids at {i}: {w:?}");
        // 30 frames/s: capture times ~33 ms apart, increasing.
        assert!(w[1].1 > w[0].1, "capture times at {i} do not increase: {w:?}");
        assert!(w[1].2 >= w[0].2, "publish times at {i} go back: {w:?}");
    }
    let span_s = (seen[99].1 - seen[0].1) as f64 / 1e9;
    assert!((span_s - 99.0 / 30.0).abs() < 0.05, "capture times span {span_s} s, the file's frame times 3.3 s");
    // Capture times are CLOCK_MONOTONIC: not after the publish time, and recent.
    assert!(seen.iter().all(|&(_, cap, publ)| cap <= publ + 1_000_000), "{:?}", &seen[..3]);
}
