//! `handeye feed` and `handeye monitor` in two processes: every frame arrives, intact, in order.

mod data_support;
mod wire_support;

use std::path::PathBuf;
use std::time::Duration;

use wire_support::*;

#[test]
fn cube_sequence_200_frames_lossless_with_matching_checksum() {
    let Some(cube) = data_support::visp_cube(&["image0000.png"]) else { return };
    let domain = TestDomain::new("feedmon");
    // The feed starts first and waits for its subscriber.
    let mut feed_cmd = handeye(&domain);
    feed_cmd.args(["feed", "--mono", "--count", "200", "--rate-hz", "0", "--dir"]).arg(&cube);
    let mut feed = Proc::spawn("feed", feed_cmd);
    feed.wait_line("waiting up to", Duration::from_secs(20));
    let mut mon_cmd = handeye(&domain);
    mon_cmd.args(["monitor", "--count", "200", "--json", "--checksum", "--timeout-s", "30", "--progress-s", "0"]);
    let monitor = Proc::spawn("monitor", mon_cmd);

    let (mon_ok, out, mon_err) = monitor.finish(Duration::from_secs(120));
    let (feed_ok, _, feed_err) = feed.finish(Duration::from_secs(30));
    assert!(mon_ok, "monitor failed:\n{mon_err}");
    assert!(feed_ok, "feed failed:\n{feed_err}");
    let j = parse_json(&out);
    assert_eq!(j["frames"], 200, "{j}");
    assert_eq!(j["rejected"], 0, "{j}");
    assert_eq!(j["missed"], 0, "{j}");
    assert_eq!(j["completed"], true, "{j}");
    let files: Vec<(PathBuf, PathBuf)> = pngs(&cube).into_iter().take(200).map(|p| (p.clone(), p)).collect();
    assert_eq!(files.len(), 200);
    assert_eq!(j["checksum"], checksum_of_pairs(&files), "monitor checksum differs from the PNG files'");
    assert!(j["latency_ns_p50"].as_u64().is_some() && j["latency_ns_p99"].as_u64() >= j["latency_ns_p50"].as_u64(), "{j}");
}

#[test]
fn stereo_folders_arrive_left_then_right_with_the_monitor_started_first() {
    let domain = TestDomain::new("stereo-lr");
    let tmp = TempDir::new("stereo-lr");
    let lefts = write_pngs(&tmp.0.join("left"), 12, 40, 30, 0x00);
    let rights = write_pngs(&tmp.0.join("right"), 12, 40, 30, 0xA5);
    // The monitor starts first and waits for frames.
    let mut mon_cmd = handeye(&domain);
    mon_cmd.args(["monitor", "--count", "12", "--json", "--checksum", "--timeout-s", "30", "--progress-s", "0"]);
    let mut monitor = Proc::spawn("monitor", mon_cmd);
    monitor.wait_line("listening", Duration::from_secs(20));
    let mut feed_cmd = handeye(&domain);
    feed_cmd.args(["feed", "--rate-hz", "0", "--dir"]).arg(&tmp.0);
    let feed = Proc::spawn("feed", feed_cmd);

    let (mon_ok, out, mon_err) = monitor.finish(Duration::from_secs(60));
    let (feed_ok, _, feed_err) = feed.finish(Duration::from_secs(30));
    assert!(mon_ok && feed_ok, "monitor:\n{mon_err}\nfeed:\n{feed_err}");
    let j = parse_json(&out);
    assert_eq!((j["frames"].as_u64(), j["rejected"].as_u64(), j["missed"].as_u64()), (Some(12), Some(0), Some(0)), "{j}");
    let pairs: Vec<(PathBuf, PathBuf)> = lefts.into_iter().zip(rights).collect();
    assert_eq!(j["checksum"], checksum_of_pairs(&pairs));
    // Swapping left and right must change the checksum: the test can tell the views apart.
    let swapped: Vec<(PathBuf, PathBuf)> = pairs.iter().map(|(l, r)| (r.clone(), l.clone())).collect();
    assert_ne!(j["checksum"], checksum_of_pairs(&swapped));
}

#[test]
fn a_size_mismatch_is_an_error_naming_the_file() {
    let domain = TestDomain::new("feed-size");
    let tmp = TempDir::new("feed-size");
    write_pngs(&tmp.0, 3, 20, 10, 0);
    image::GrayImage::new(21, 10).save(tmp.0.join("frame0002.png")).unwrap();
    let out = handeye(&domain).args(["feed", "--mono", "--dir"]).arg(&tmp.0).output().unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("frame0002.png") && err.contains("21x10"), "{err}");
}
