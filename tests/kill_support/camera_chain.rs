//! The camera chain under a random kill: `handeye camera` on a live GStreamer test pattern
//! (`videotestsrc`, 30 frames/s, 160x120, as both views), with `handeye record` and
//! `handeye monitor` subscribed, and the test's own subscriber beside them.
//!
//! Killing the camera: the monitor must report the publisher gone and the recorder must end
//! its recording (`ended_by: publisher_gone`) within 500 ms; a fresh camera in the same domain
//! must reach the monitor that is still running. Killing a subscriber (record or monitor):
//! the camera must not stall on the dead reader, so frames keep reaching the other
//! subscribers (no gap over 500 ms), and a fresh one in the same domain must receive frames.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use handeye_wire::stereo::{StereoEvent, StereoSubscriber};
use handeye_wire::{monotonic_ns, WireNode};

use super::*;
use crate::e2e_support::TempDir;
use crate::wire_support::{handeye, parse_json, Proc, TestDomain};

fn camera(domain: &TestDomain) -> Proc {
    let mut c = handeye(domain);
    c.args([
        "camera",
        "--mono",
        "--left",
        "videotestsrc is-live=true ! video/x-raw,framerate=30/1",
        "--width-px",
        "160",
        "--height-px",
        "120",
        "--progress-s",
        "0",
        "--json",
        // Not about stalls: a loaded machine must not make one.
        "--stall-timeout-s",
        "5",
    ]);
    Proc::spawn("camera", c)
}

fn record(domain: &TestDomain, out: &Path, count: u32) -> Proc {
    let mut c = handeye(domain);
    c.args(["record", "--json", "--progress-s", "0", "--timeout-s", "60", "--count", &count.to_string(), "--out"]).arg(out);
    Proc::spawn("record", c)
}

fn monitor(domain: &TestDomain, count: u32) -> Proc {
    let mut c: Command = handeye(domain);
    c.args(["monitor", "--json", "--progress-s", "0", "--timeout-s", "60", "--count", &count.to_string()]);
    let mut p = Proc::spawn("monitor", c);
    p.wait_line("listening", Duration::from_secs(20));
    p
}

/// Frames reaching the test's own subscriber from now on for `span`: how many, and the
/// longest time without one (from now to the first, between frames, from the last to the end).
fn frame_flow(sub: &mut StereoSubscriber, span: Duration) -> (u64, Duration) {
    let t0 = Instant::now();
    let (mut n, mut last, mut gap) = (0, t0, Duration::ZERO);
    while t0.elapsed() < span {
        if let StereoEvent::Frame(f) = sub.wait(Duration::from_millis(20)).unwrap() {
            drop(f);
            gap = gap.max(last.elapsed());
            last = Instant::now();
            n += 1;
        }
    }
    (n, gap.max(last.elapsed()))
}

pub fn run(plan: Plan) -> CaseResult {
    let mut result = CaseResult::new(plan);
    result.at = "streaming".into();
    let dir = TempDir::new(&format!("killcam{}", plan.seed));
    let domain = TestDomain::new(&format!("killcam{}", plan.seed));
    let node = WireNode::create(&domain.0, "kill-test").unwrap();
    let mut sub = StereoSubscriber::create(&node, 1).unwrap();
    let mut mon = monitor(&domain, 0);
    let mut rec = record(&domain, &dir.0.join("rec"), 0);
    let mut cam = camera(&domain);
    let (n, _) = frame_flow(&mut sub, Duration::from_secs(2));
    if n == 0 {
        let (n, _) = frame_flow(&mut sub, Duration::from_secs(30));
        assert!(n > 0, "seed {}: no camera frame within 32 s", plan.seed);
    }
    mon.wait_line("publisher up", Duration::from_secs(10));
    frame_flow(&mut sub, plan.camera_delay());

    match plan.victim {
        Victim::Camera => {
            let killed_ns = monotonic_ns();
            cam.child.kill().unwrap();
            let _ = cam.child.wait();
            let line = mon.wait_line("publisher gone at", Duration::from_secs(5));
            let gone_ns: u64 = line.split("gone at ").nth(1).and_then(|t| t.split(' ').next()).and_then(|t| t.parse().ok()).unwrap_or(u64::MAX);
            result.detections.push(Detection::new("monitor", "publisher gone", ms_between(killed_ns, gone_ns), PUBLISHER_GONE_MS));
            let ended = poll(Duration::from_secs(10), || rec.child.try_wait().unwrap().map(|_| monotonic_ns()));
            let (_, out, err) = rec.finish(Duration::from_secs(1));
            let summary = parse_json(&out);
            let ended_by = summary["ended_by"].as_str().unwrap_or("-").to_owned();
            let measured = match ended {
                Some(t) if ended_by == "publisher_gone" => ms_between(killed_ns, t),
                _ => {
                    result.notes.push(format!("record ended by {ended_by}: {err}"));
                    f64::INFINITY
                }
            };
            result.detections.push(Detection::new("record", "recording ended, publisher gone", measured, PUBLISHER_GONE_MS));
            // The same domain, a fresh camera: the monitor that stayed sees it, frames flow.
            let _cam = camera(&domain);
            mon.wait_line("publisher up", Duration::from_secs(30));
            let (n, _) = frame_flow(&mut sub, Duration::from_secs(3));
            result.restart_ok = n > 0;
        }
        Victim::Record | Victim::Monitor => {
            let victim = if plan.victim == Victim::Record { &mut rec } else { &mut mon };
            victim.child.kill().unwrap();
            let _ = victim.child.wait();
            let (n, gap) = frame_flow(&mut sub, Duration::from_millis(1500));
            let camera_alive = cam.child.try_wait().unwrap().is_none();
            let gap_ms = if camera_alive && n > 0 { gap.as_secs_f64() * 1e3 } else { f64::INFINITY };
            result.detections.push(Detection::new("camera", "frames keep flowing (longest gap)", gap_ms, PUBLISHER_GONE_MS));
            if camera_alive && gap_ms > PUBLISHER_GONE_MS {
                // What the camera saw meanwhile: frames it could not hand over, or none to hand.
                cam.interrupt();
                let (_, out, _) = std::mem::replace(&mut cam, camera(&domain)).finish(Duration::from_secs(10));
                let c = parse_json(&out);
                result.notes.push(format!(
                    "camera: {} published, {} dropped for want of a slot, {} dropped busy",
                    c["frames"], c["dropped_publish"], c["dropped_busy_left"]
                ));
            }
            // A fresh one of the same kind in the same domain receives frames.
            let fresh = if plan.victim == Victim::Record { record(&domain, &dir.0.join("rec2"), 10) } else { monitor(&domain, 10) };
            let (ok, out, err) = fresh.finish(Duration::from_secs(30));
            result.restart_ok = ok && parse_json(&out)["frames"].as_u64().is_some_and(|f| f >= 1);
            if !result.restart_ok {
                result.notes.push(format!("fresh {}: {err}", plan.victim.name()));
            }
        }
        _ => unreachable!("not a camera-chain process"),
    }
    drop((sub, node));
    result
}
