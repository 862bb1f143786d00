//! Malformed stereo samples from another process: each one is rejected with its reason, and
//! the monitor keeps receiving good frames afterwards.

mod wire_support;

use std::time::Duration;

use handeye_wire::checksum::PixelChecksum;
use handeye_wire::stereo::{Delivery, StereoFormat, StereoPublisher, StereoPublisherOptions};
use handeye_wire::{StereoHeader, WireNode, WIRE_VERSION};
use wire_support::*;

#[test]
fn each_malformed_sample_is_rejected_with_its_reason_and_the_monitor_keeps_working() {
    let domain = TestDomain::new("malformed");
    let mut mon_cmd = handeye(&domain);
    mon_cmd.args(["monitor", "--count", "3", "--json", "--checksum", "--timeout-s", "30", "--progress-s", "0"]);
    let monitor = Proc::spawn("monitor", mon_cmd);

    let node = WireNode::create(&domain.0, "bad-camera").unwrap();
    let geometry = StereoFormat::gray8_pair(32, 16);
    let len = 32 * 16 * 2;
    // Lossless: every sample waits until the monitor has taken the previous one, so none is
    // lost to queue overflow and every counter must come out exact.
    let options = StereoPublisherOptions {
        delivery: Delivery::Lossless { in_flight: 1, timeout: Duration::from_secs(20) },
        ..Default::default()
    };
    let mut p = StereoPublisher::create_raw(&node, geometry, 4 * len, options).unwrap();
    assert!(p.wait_for_subscribers(1, Duration::from_secs(20)).unwrap(), "monitor did not subscribe");

    let good = |id: u64| StereoHeader { frame_id: id, ..geometry.header() };
    let mut expected = PixelChecksum::new();
    let mut send_good = |p: &mut StereoPublisher, id: u64| {
        let fill = |b: &mut [u8]| b.iter_mut().enumerate().for_each(|(i, x)| *x = (i as u64 * 31 + id) as u8);
        let mut bytes = vec![0u8; len];
        fill(&mut bytes);
        expected.add_bytes(&bytes);
        p.publish_raw(good(id), len, fill).unwrap();
    };
    send_good(&mut p, 0);
    let bad: Vec<(&str, StereoHeader, usize)> = vec![
        ("version", StereoHeader { version: WIRE_VERSION + 1, ..good(1) }, len),
        ("payload_length", good(2), len - 7),
        ("zero_size", StereoHeader { width: 0, ..good(3) }, len),
        ("pixel_format", StereoHeader { pixel_format: 0xBAD, ..good(4) }, len),
        ("too_large", StereoHeader { width: 70_000, height: 70_000, stride: 70_000, ..good(5) }, len),
        ("stride", StereoHeader { stride: 31, ..good(6) }, 31 * 16 * 2),
    ];
    for (_, h, l) in &bad {
        p.publish_raw(*h, *l, |b| b.fill(0xFF)).unwrap();
    }
    send_good(&mut p, 7);
    send_good(&mut p, 8);
    assert!(p.flush(Duration::from_secs(20)).unwrap(), "monitor did not take the last frame");

    let (ok, out, err) = monitor.finish(Duration::from_secs(60));
    assert!(ok, "monitor failed:\n{err}");
    let j = parse_json(&out);
    assert_eq!(j["frames"], 3, "{j}");
    assert_eq!(j["rejected"], bad.len(), "{j}");
    for (key, _, _) in &bad {
        assert_eq!(j["rejected_by_reason"][key], 1, "reason {key}: {j}");
    }
    assert_eq!(j["rejected_by_reason"]["frame_id"], 0, "{j}");
    // Ids 1..=6 never arrived as valid frames.
    assert_eq!(j["missed"], 6, "{j}");
    assert_eq!(j["checksum"], format!("{:016x}", expected.value()), "the good frames must arrive intact");
    // Each reason was logged (rate-limited, so at least once).
    assert!(err.contains("rejected stereo sample"), "{err}");
}
