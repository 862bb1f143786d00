//! A publisher killed mid-stream: the subscriber notices within 500 ms, reports it, and picks
//! up a restarted publisher without being restarted itself.

mod wire_support;

use std::time::Duration;

use handeye_wire::monotonic_ns;
use wire_support::*;

/// The `... at <ns> ns` stamp of a monitor event line.
fn stamp(line: &str) -> u64 {
    let after = line.split(" at ").nth(1).unwrap_or_else(|| panic!("no stamp in {line:?}"));
    after.split_whitespace().next().unwrap().parse().unwrap_or_else(|e| panic!("bad stamp in {line:?}: {e}"))
}

#[test]
fn killed_publisher_is_noticed_within_500_ms_and_a_restarted_one_is_picked_up() {
    let domain = TestDomain::new("liveness");
    let tmp = TempDir::new("liveness");
    write_pngs(&tmp.0, 8, 48, 32, 0);
    let feed = || {
        let mut c = handeye(&domain);
        c.args(["feed", "--mono", "--loop", "--rate-hz", "100", "--dir"]).arg(&tmp.0);
        c
    };
    let mut mon_cmd = handeye(&domain);
    mon_cmd.args(["monitor", "--json", "--timeout-s", "60", "--progress-s", "0"]);
    let mut monitor = Proc::spawn("monitor", mon_cmd);
    monitor.wait_line("listening", Duration::from_secs(20));

    let mut first = Proc::spawn("feed 1", feed());
    monitor.wait_line("publisher up", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(400)); // frames flow

    let killed_at = monotonic_ns();
    first.child.kill().unwrap(); // SIGKILL: no chance to say goodbye
    let _ = first.child.wait();
    let gone = monitor.wait_line("publisher gone", Duration::from_secs(5));
    let noticed_ns = stamp(&gone).saturating_sub(killed_at);
    eprintln!("killed publisher noticed after {:.1} ms", noticed_ns as f64 / 1e6);
    assert!(noticed_ns <= 500_000_000, "killed publisher noticed after {} ms: {gone}", noticed_ns / 1_000_000);

    // The same monitor picks up a new publisher.
    let second = Proc::spawn("feed 2", feed());
    monitor.wait_line("publisher up", Duration::from_secs(20));
    std::thread::sleep(Duration::from_millis(400));
    // A clean exit (Ctrl-C) is reported too, and the feed exits successfully.
    second.interrupt();
    let (feed_ok, _, feed_err) = second.finish(Duration::from_secs(10));
    assert!(feed_ok, "feed 2 did not end cleanly on Ctrl-C:\n{feed_err}");
    monitor.wait_line("publisher gone", Duration::from_secs(5));

    monitor.interrupt();
    let (ok, out, err) = monitor.finish(Duration::from_secs(10));
    assert!(ok, "monitor did not end cleanly on Ctrl-C:\n{err}");
    let j = parse_json(&out);
    assert_eq!((j["publisher_up"].as_u64(), j["publisher_gone"].as_u64()), (Some(2), Some(2)), "{j}");
    assert_eq!(j["rejected"], 0, "{j}");
    let events = j["events"].as_array().unwrap();
    let kinds: Vec<&str> = events.iter().map(|e| e["event"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["publisher_up", "publisher_gone", "publisher_up", "publisher_gone"], "{j}");
    // Frames arrived from both publishers: the second one's frames are counted after the first's.
    let frames_at = |i: usize| events[i]["frames"].as_u64().unwrap();
    assert!(frames_at(1) > 0, "no frames from the first publisher: {j}");
    assert!(frames_at(3) > frames_at(1), "no frames from the restarted publisher: {j}");
    assert_eq!(j["frames"].as_u64(), Some(frames_at(3)), "{j}");
}
