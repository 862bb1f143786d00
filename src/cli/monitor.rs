//! `handeye monitor`: subscribes to `handeye/stereo` and reports what arrives; with
//! `--telemetry`, shows the daemon's telemetry live instead (`super::telemetry`).

use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_wire::checksum::PixelChecksum;
use handeye_wire::stereo::{StereoEvent, StereoStats, StereoSubscriber};
use handeye_wire::{monotonic_ns, WireNode};
use serde_json::json;

use super::domain::DomainArgs;
use super::stats::percentile_sorted as percentile;
use super::units::parse_seconds;

const EXAMPLES: &str = "\
Progress lines and publisher events (\"publisher up at <ns> ns\", \"publisher gone at <ns> ns\")
go to stderr as they happen; the summary goes to stdout at the end: after --count frames, after
--timeout-s without frames, or on Ctrl-C. Latency is the publisher's publish stamp to the moment
this process holds the validated frame (CLOCK_MONOTONIC, same host).

Examples:
  handeye monitor                                 # report once a second until Ctrl-C
  handeye monitor --count 200 --json --checksum   # 200 frames, then one JSON object
  handeye monitor --timeout-s 0                   # wait for frames forever
  handeye monitor --telemetry                     # the daemon, live: phase, trackers, timing
  handeye monitor --telemetry --json > tel.jsonl  # one JSON object per telemetry sample

JSON keys: frames, rejected (total), rejected_by_reason {version, pixel_format, zero_size,
too_large, stride, payload_length, frame_id}, missed, fps, latency_ns_p50, latency_ns_p99,
latency_ns_max (null without frames), receive_errors, publisher_up, publisher_gone, events
[{event, time_ns, last_frame_id, frames}], completed (--count reached), duration_s, and with
--checksum: checksum (16 hex digits, FNV-1a 64 over every frame's pixels in order, rows
without stride padding, left then right; see handeye_wire::checksum).

--telemetry reads handeye/telemetry instead of the frames: the daemon's phase and status, each
tracker's state, confidence, corners and update time, the servo error, the cycle time p50/p99
and the trackers' own update time p50/p99 (all active trackers of a cycle summed, over the
cycles that updated one) with the rate that time allows (updates/s), beside the frames/s
actually tracked. In a terminal the panel is redrawn in place; otherwise it is printed every
--progress-s. It ends when the daemon's telemetry publisher goes away, after --count samples,
after --timeout-s without one, or on Ctrl-C. With --json: one object per sample (frame_id,
time_ns, phase, reason, planning, loop_ns, deadline_misses, trackers [{tracker, state,
confidence, updates, update_ns, corners_px}], servo_error, servo_steps, and stats {samples,
cycles, cycle_us_p50/p99, tracker_cycles, tracker_update_us_p50/p99/max, tracker_rate_hz,
cycles_per_s, tracked_fps} over all samples so far: the last line's stats are the run's,
computed like daemon.json's loop_us_* and tracker_update).";

/// Subscribe to `handeye/stereo` and report frames received, rejected samples (by reason),
/// missed frame ids, frame rate and transport latency (publish stamp to receive, ns).
///
/// Progress and publisher events ("publisher up", "publisher gone") go to stderr as they
/// happen; the summary goes to stdout at the end: after --count frames, after --timeout-s
/// without frames, or on Ctrl-C.
#[derive(Args, Debug)]
#[command(after_help = EXAMPLES)]
pub struct MonitorArgs {
    /// Show the daemon's telemetry (handeye/telemetry) live instead of the frames.
    #[arg(long, conflicts_with_all = ["checksum", "queue"])]
    pub telemetry: bool,

    /// Stop after N valid frames, or N telemetry samples (0 = run until Ctrl-C or --timeout-s).
    #[arg(long, default_value_t = 0, value_name = "N")]
    pub count: u64,

    /// Print one JSON object at the end instead of the text summary.
    #[arg(long)]
    pub json: bool,

    /// Also compute an order-sensitive checksum of all pixel bytes received.
    #[arg(long)]
    pub checksum: bool,

    /// Give up after this many seconds without a frame (0 = never). With --count, giving up
    /// before N frames is an error (exit code 1).
    #[arg(long, default_value_t = 10.0, value_name = "S", value_parser = parse_seconds)]
    pub timeout_s: f64,

    /// Subscriber queue length, 1 or 2 frames. 1 = always the newest frame (a lagging
    /// monitor skips frames, counted as missed); 2 absorbs short stalls.
    #[arg(long, default_value_t = 2, value_name = "FRAMES")]
    pub queue: usize,

    /// Also write the JSON object to FILE (whatever the output format).
    #[arg(long, value_name = "FILE")]
    pub report: Option<std::path::PathBuf>,

    /// Seconds between progress lines on stderr (0 = none).
    #[arg(long, default_value_t = 1.0, value_name = "S", value_parser = parse_seconds)]
    pub progress_s: f64,

    #[command(flatten)]
    pub domain: DomainArgs,
}

/// One publisher event, as reported in the JSON `events` list.
struct Event {
    name: &'static str,
    time_ns: u64,
    last_frame_id: Option<u64>,
    /// Valid frames received before the event.
    frames: u64,
}

pub fn run(args: MonitorArgs) -> Result<()> {
    if args.telemetry {
        return super::telemetry::run(&super::telemetry::TelemetryOptions {
            domain: &args.domain.domain,
            count: args.count,
            json: args.json,
            timeout_s: args.timeout_s,
            progress_s: args.progress_s,
            report: args.report.as_deref(),
        });
    }
    let domain = &args.domain.domain;
    let node = WireNode::create(domain, "handeye-monitor")?;
    let mut sub = StereoSubscriber::create(&node, args.queue)?;
    eprintln!("monitor: listening on handeye/stereo in domain '{domain}'");

    let idle_limit = (args.timeout_s > 0.0).then(|| Duration::from_secs_f64(args.timeout_s));
    let progress_every = (args.progress_s > 0.0).then(|| Duration::from_secs_f64(args.progress_s));
    let start = Instant::now();
    let mut last_activity = start;
    let mut next_progress = progress_every.map(|p| start + p);
    let mut latencies: Vec<u64> = Vec::new();
    let mut checksum = PixelChecksum::new();
    let mut first_frame_ns: Option<u64> = None;
    let mut last_frame: Option<(u64, u64)> = None; // (frame id, receive ns)
    let mut events: Vec<Event> = Vec::new();
    let mut timed_out = false;

    while args.count == 0 || sub.stats().received < args.count {
        let mut slice = Duration::from_millis(250);
        if let Some(limit) = idle_limit {
            let left = limit.saturating_sub(last_activity.elapsed());
            if left.is_zero() {
                timed_out = true;
                break;
            }
            slice = slice.min(left);
        }
        match sub.wait(slice)? {
            StereoEvent::Frame(frame) => {
                last_activity = Instant::now();
                if let Some(l) = frame.latency_ns() {
                    latencies.push(l);
                }
                if args.checksum {
                    checksum.add_frame(&frame);
                }
                first_frame_ns.get_or_insert(frame.receive_time_ns());
                last_frame = Some((frame.frame_id(), frame.receive_time_ns()));
            }
            StereoEvent::PublisherUp => {
                let t = monotonic_ns();
                last_activity = Instant::now();
                eprintln!("monitor: publisher up at {t} ns");
                events.push(Event {
                    name: "publisher_up",
                    time_ns: t,
                    last_frame_id: last_frame.map(|f| f.0),
                    frames: sub.stats().received,
                });
            }
            StereoEvent::PublisherGone => {
                let t = monotonic_ns();
                last_activity = Instant::now();
                let last_id = last_frame.map(|f| f.0);
                eprintln!(
                    "monitor: publisher gone at {t} ns (last frame id {})",
                    last_id.map_or("-".to_owned(), |i| i.to_string())
                );
                events.push(Event { name: "publisher_gone", time_ns: t, last_frame_id: last_id, frames: sub.stats().received });
            }
            StereoEvent::Timeout => {}
            StereoEvent::Interrupted => break,
        }
        if let (Some(at), Some(every)) = (next_progress, progress_every)
            && Instant::now() >= at
        {
            next_progress = Some(at + every);
            eprintln!("monitor: {}", progress_line(sub.stats(), &latencies, fps(first_frame_ns, last_frame, sub.stats().received)));
        }
    }

    let stats = sub.stats().clone();
    latencies.sort_unstable();
    let fps = fps(first_frame_ns, last_frame, stats.received);
    let completed = args.count > 0 && stats.received >= args.count;
    let by_reason: serde_json::Map<String, serde_json::Value> =
        stats.rejected_by_reason().map(|(k, v)| (k.to_owned(), json!(v))).collect();
    let mut report = json!({
        "frames": stats.received,
        "rejected": stats.rejected_total(),
        "rejected_by_reason": by_reason,
        "missed": stats.missed,
        "fps": fps,
        "latency_ns_p50": percentile(&latencies, 50.0),
        "latency_ns_p99": percentile(&latencies, 99.0),
        "latency_ns_max": latencies.last(),
        "receive_errors": stats.receive_errors,
        "publisher_up": stats.publisher_up,
        "publisher_gone": stats.publisher_gone,
        "events": events.iter().map(|e| json!({"event": e.name, "time_ns": e.time_ns, "last_frame_id": e.last_frame_id, "frames": e.frames})).collect::<Vec<_>>(),
        "completed": completed,
        "duration_s": start.elapsed().as_secs_f64(),
        "domain": domain.name(),
    });
    if args.checksum {
        report["checksum"] = json!(format!("{:016x}", checksum.value()));
    }
    if let Some(path) = &args.report {
        std::fs::write(path, format!("{report:#}\n")).with_context(|| format!("cannot write the report {}", path.display()))?;
    }
    if args.json {
        println!("{report}");
    } else {
        println!("frames:    {}", stats.received);
        println!("rejected:  {}{}", stats.rejected_total(), reasons_text(&stats));
        println!("missed:    {}", stats.missed);
        println!("fps:       {fps:.1}");
        match (percentile(&latencies, 50.0), percentile(&latencies, 99.0)) {
            (Some(p50), Some(p99)) => println!("latency:   p50 {p50} ns, p99 {p99} ns (publish stamp to receive)"),
            _ => println!("latency:   -"),
        }
        println!("publisher: up {} time(s), gone {} time(s)", stats.publisher_up, stats.publisher_gone);
        if args.checksum {
            println!("checksum:  {:016x}", checksum.value());
        }
    }
    if timed_out && args.count > 0 && !completed {
        bail!(
            "no frame for {} s: got {} of {} frames (is a publisher running in domain '{domain}'?)",
            args.timeout_s,
            stats.received,
            args.count
        );
    }
    Ok(())
}

fn fps(first_ns: Option<u64>, last: Option<(u64, u64)>, frames: u64) -> f64 {
    match (first_ns, last) {
        (Some(a), Some((_, b))) if b > a && frames > 1 => (frames - 1) as f64 * 1e9 / (b - a) as f64,
        _ => 0.0,
    }
}

fn reasons_text(stats: &StereoStats) -> String {
    let parts: Vec<String> = stats.rejected_by_reason().filter(|(_, n)| *n > 0).map(|(k, n)| format!("{k} {n}")).collect();
    if parts.is_empty() { String::new() } else { format!(" ({})", parts.join(", ")) }
}

fn progress_line(stats: &StereoStats, latencies: &[u64], fps: f64) -> String {
    // The last second's latencies are representative enough for a progress line.
    let mut recent: Vec<u64> = latencies.iter().rev().take(1000).copied().collect();
    recent.sort_unstable();
    let lat = match (percentile(&recent, 50.0), percentile(&recent, 99.0)) {
        (Some(a), Some(b)) => format!("latency p50 {:.1} us p99 {:.1} us", a as f64 / 1e3, b as f64 / 1e3),
        _ => "latency -".to_owned(),
    };
    format!(
        "{} frames, {fps:.1} frames/s, rejected {}{}, missed {}, {lat}",
        stats.received,
        stats.rejected_total(),
        reasons_text(stats),
        stats.missed
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_wire::stereo::StereoReject;

    #[test]
    fn fps_counts_intervals_between_first_and_last_frame() {
        // 31 frames over exactly one second = 30 intervals = 30 frames/s.
        assert_eq!(fps(Some(0), Some((30, 1_000_000_000)), 31), 30.0);
        assert_eq!(fps(Some(5), Some((0, 5)), 1), 0.0);
        assert_eq!(fps(None, None, 0), 0.0);
    }

    #[test]
    fn reasons_list_only_nonzero_counters() {
        let mut s = StereoStats::default();
        assert_eq!(reasons_text(&s), "");
        s.rejected[StereoReject::PayloadLength { expected: 0, actual: 0 }.index()] = 2;
        s.rejected[0] = 1;
        assert_eq!(reasons_text(&s), " (version 1, payload_length 2)");
    }
}
