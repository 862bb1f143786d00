//! `handeye monitor --telemetry`: what the daemon is doing, live, from `handeye/telemetry`:
//! its phase, each tracker's state, confidence, corners and update time, the servo error, the
//! cycle time and the trackers' own update time with the rate that time allows, beside the
//! frames per second actually tracked.
//!
//! The percentiles use the daemon's own histogram ([`LatencyHistogram`]) over the per-cycle
//! values the telemetry carries, so a monitor that saw every cycle prints exactly the numbers
//! the daemon writes into `daemon.json` (`loop_us_*`, `tracker_update`).

use std::collections::VecDeque;
use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use handeye_daemon::timing::LatencyHistogram;
use handeye_wire::message::{MessageEvent, MessageSubscriber};
use handeye_wire::{Phase, Telemetry, WireNode, NO_FRAME, SERVO_ERROR_LEN, TELEMETRY_TRACKERS};
use serde_json::{json, Value};

/// What `handeye monitor --telemetry` was asked for (its flags).
pub struct TelemetryOptions<'a> {
    pub domain: &'a handeye_wire::Domain,
    /// Stop after this many samples (0 = no limit).
    pub count: u64,
    /// One JSON object per sample on stdout instead of the panel.
    pub json: bool,
    /// Give up after this long without a sample (0 = never).
    pub timeout_s: f64,
    /// Seconds between panels when stdout is not a terminal (0 = only at the end).
    pub progress_s: f64,
    /// Also write the final statistics (JSON) to this file.
    pub report: Option<&'a std::path::Path>,
}

/// Tracker slots in telemetry order.
pub const TRACKER_NAMES: [&str; TELEMETRY_TRACKERS] = ["gripper_left", "gripper_right", "target_left", "target_right"];

/// Seconds over which the frame rates are measured.
const RATE_WINDOW_NS: u64 = 2_000_000_000;

fn state_name(state: u32) -> &'static str {
    match state {
        1 => "tracking",
        2 => "lost",
        _ => "off",
    }
}

fn finite_or_null(v: f32) -> Value {
    if v.is_finite() { json!(v) } else { Value::Null }
}

/// One telemetry sample as JSON (the same object `handeye record` writes to
/// `telemetry.jsonl`): NaN (unused) numbers become `null`, unused corners are left out.
pub fn telemetry_json(t: &Telemetry) -> Value {
    let trackers: Vec<Value> = (0..TELEMETRY_TRACKERS)
        .map(|i| {
            let corners: Vec<[f32; 2]> =
                t.tracker_corners_px[i].iter().filter(|c| c[0].is_finite() && c[1].is_finite()).copied().collect();
            json!({
                "tracker": TRACKER_NAMES[i],
                "state": state_name(t.tracker_state[i]),
                "confidence": t.tracker_confidence[i],
                "updates": t.tracker_updates[i],
                "update_ns": t.tracker_update_ns[i],
                "corners_px": corners,
            })
        })
        .collect();
    json!({
        "frame_id": (t.frame_id != NO_FRAME).then_some(t.frame_id),
        "time_ns": t.time_ns,
        "phase": Phase::from_u32(t.phase).map_or("unknown", Phase::name),
        "reason": t.reason_text(),
        "planning": t.planning == 1,
        "loop_ns": t.loop_ns,
        "deadline_misses": t.deadline_misses,
        "dropped_frames": t.dropped_frames,
        "trackers": trackers,
        "servo_error": t.servo_error.iter().map(|&v| finite_or_null(v)).collect::<Vec<_>>(),
        "servo_steps": t.servo_steps,
        "pointing": {
            "state": handeye_wire::PointingState::from_u32(t.pointing_state).map_or("unknown", handeye_wire::PointingState::name),
            "frame": t.pointing_frame,
            "update_ns": t.pointing_update_ns,
            "point_m": t.pointing_point_m.iter().map(|&v| finite_or_null(v)).collect::<Vec<_>>(),
            "sigma_m": finite_or_null(t.pointing_sigma_m),
            "crossing_rad": finite_or_null(t.pointing_crossing_rad),
            "tip_px": t.pointing_tip_px.iter().map(|p| p.iter().map(|&v| finite_or_null(v)).collect::<Vec<_>>()).collect::<Vec<_>>(),
            "line_px": t.pointing_line_px.iter().map(|p| p.iter().map(|&v| finite_or_null(v)).collect::<Vec<_>>()).collect::<Vec<_>>(),
        },
    })
}

/// Running statistics over the samples seen.
pub struct TelemetryStats {
    pub samples: u64,
    cycle: LatencyHistogram,
    tracker: LatencyHistogram,
    /// `time_ns` of the recent cycles, and whether each updated a tracker.
    recent: VecDeque<(u64, bool)>,
}

impl Default for TelemetryStats {
    fn default() -> Self {
        Self { samples: 0, cycle: LatencyHistogram::new(u64::MAX), tracker: LatencyHistogram::new(u64::MAX), recent: VecDeque::new() }
    }
}

impl TelemetryStats {
    /// Adds one sample. A sample outside a frame (a safety stop) has no cycle to count.
    pub fn add(&mut self, t: &Telemetry) {
        self.samples += 1;
        if t.frame_id == NO_FRAME {
            return;
        }
        self.cycle.record_ns(t.loop_ns);
        let stereo_ns: u64 = t.tracker_update_ns.iter().sum();
        if stereo_ns > 0 {
            self.tracker.record_ns(stereo_ns);
        }
        self.recent.push_back((t.time_ns, stereo_ns > 0));
        while self.recent.front().is_some_and(|&(old, _)| t.time_ns.saturating_sub(old) > RATE_WINDOW_NS) {
            self.recent.pop_front();
        }
    }

    /// Cycles per second over the recent window: all of them, or those that tracked.
    fn rate(&self, tracked_only: bool) -> f64 {
        let times: Vec<u64> = self.recent.iter().filter(|(_, tracked)| *tracked || !tracked_only).map(|(t, _)| *t).collect();
        match (times.first(), times.last()) {
            (Some(&a), Some(&b)) if b > a => (times.len() - 1) as f64 * 1e9 / (b - a) as f64,
            _ => 0.0,
        }
    }

    pub fn json(&self) -> Value {
        let us = |h: &LatencyHistogram, p: f64| (h.count() > 0).then(|| h.percentile_ns(p) as f64 / 1000.0);
        let p50 = us(&self.tracker, 50.0);
        json!({
            "samples": self.samples,
            "cycles": self.cycle.count(),
            "cycle_us_p50": us(&self.cycle, 50.0),
            "cycle_us_p99": us(&self.cycle, 99.0),
            "tracker_cycles": self.tracker.count(),
            "tracker_update_us_p50": p50,
            "tracker_update_us_p99": us(&self.tracker, 99.0),
            "tracker_update_us_max": (self.tracker.count() > 0).then(|| self.tracker.max_ns() as f64 / 1000.0),
            "tracker_rate_hz": p50.filter(|&p| p > 0.0).map(|p| 1e6 / p),
            "cycles_per_s": self.rate(false),
            "tracked_fps": self.rate(true),
        })
    }
}

/// The panel shown in a terminal, one string per line.
fn panel(t: &Telemetry, stats: &TelemetryStats, domain: &str) -> Vec<String> {
    let mut lines = vec![format!(
        "daemon in '{domain}': frame {}  phase {}{}  {}",
        if t.frame_id == NO_FRAME { "-".to_owned() } else { t.frame_id.to_string() },
        Phase::from_u32(t.phase).map_or("unknown", Phase::name),
        if t.planning == 1 { " (planning)" } else { "" },
        t.reason_text()
    )];
    lines.push(format!("{:<14} {:<9} {:>5} {:>10}  corners (px)", "tracker", "state", "conf", "update µs"));
    for i in 0..TELEMETRY_TRACKERS {
        let corners: Vec<String> = t.tracker_corners_px[i]
            .iter()
            .filter(|c| c[0].is_finite() && c[1].is_finite())
            .map(|c| format!("({:.0},{:.0})", c[0], c[1]))
            .collect();
        let update = t.tracker_update_ns[i];
        lines.push(format!(
            "{:<14} {:<9} {:>5.2} {:>10}  {}",
            TRACKER_NAMES[i].replace('_', " "),
            state_name(t.tracker_state[i]),
            t.tracker_confidence[i],
            if update > 0 { format!("{:.1}", update as f64 / 1000.0) } else { "-".to_owned() },
            corners.join(" ")
        ));
    }
    let names = ["π1", "π2", "π3", "s-s*", "t-t*", "ρ"];
    let errors: Vec<String> = (0..SERVO_ERROR_LEN)
        .filter(|&k| t.servo_error[k].is_finite())
        .map(|k| format!("{} {:+.3}", names[k], t.servo_error[k]))
        .collect();
    lines.push(format!(
        "servo error    {}  (steps {})",
        if errors.is_empty() { "-".to_owned() } else { errors.join("  ") },
        t.servo_steps
    ));
    let s = stats.json();
    let num = |k: &str| s[k].as_f64().map_or("-".to_owned(), |v| format!("{v:.1}"));
    lines.push(format!(
        "cycle          p50 {} µs  p99 {} µs  {} cycles/s  deadline misses {}",
        num("cycle_us_p50"),
        num("cycle_us_p99"),
        num("cycles_per_s"),
        t.deadline_misses
    ));
    lines.push(format!(
        "tracker update p50 {} µs  p99 {} µs  allows {} updates/s; tracked {} frames/s",
        num("tracker_update_us_p50"),
        num("tracker_update_us_p99"),
        s["tracker_rate_hz"].as_f64().map_or("-".to_owned(), |v| format!("{v:.0}")),
        num("tracked_fps")
    ));
    lines
}

/// Redraws the panel in place: up over the previous one, each line cleared before writing.
struct InPlace {
    drawn: usize,
}

impl InPlace {
    fn draw(&mut self, out: &mut impl Write, lines: &[String]) -> std::io::Result<()> {
        if self.drawn > 0 {
            write!(out, "\x1b[{}A", self.drawn)?;
        }
        for l in lines {
            write!(out, "\x1b[2K{l}\n")?;
        }
        self.drawn = lines.len();
        out.flush()
    }
}

/// `handeye monitor --telemetry`.
pub fn run(args: &TelemetryOptions<'_>) -> Result<()> {
    let domain = args.domain;
    let node = WireNode::create(domain, "handeye-monitor-telemetry")?;
    let mut sub = MessageSubscriber::<Telemetry>::create(&node)?;
    eprintln!("monitor: listening on handeye/telemetry in domain '{domain}'");
    let idle_limit = (args.timeout_s > 0.0).then(|| Duration::from_secs_f64(args.timeout_s));
    let progress_every = Duration::from_secs_f64(args.progress_s);
    let terminal = !args.json && std::io::stdout().is_terminal();
    let mut in_place = InPlace { drawn: 0 };
    let mut stdout = std::io::stdout().lock();
    let mut stats = TelemetryStats::default();
    let mut last: Option<Telemetry> = None;
    let mut last_activity = Instant::now();
    let mut next_draw = Instant::now();
    let mut ended_by = "interrupted";
    loop {
        if args.count > 0 && stats.samples >= args.count {
            ended_by = "count";
            break;
        }
        let mut slice = Duration::from_millis(250);
        if let Some(limit) = idle_limit {
            let left = limit.saturating_sub(last_activity.elapsed());
            if left.is_zero() {
                ended_by = "timeout";
                break;
            }
            slice = slice.min(left);
        }
        match sub.wait(slice)? {
            MessageEvent::Message(t) => {
                last_activity = Instant::now();
                stats.add(&t);
                last = Some(t);
                if args.json {
                    let mut v = telemetry_json(&t);
                    v["stats"] = stats.json();
                    writeln!(stdout, "{v}").context("writing to stdout")?;
                }
            }
            MessageEvent::PublisherUp => eprintln!("monitor: the daemon's telemetry is up"),
            MessageEvent::PublisherGone => {
                if last.is_some() {
                    ended_by = "publisher_gone";
                    break;
                }
            }
            MessageEvent::Timeout => {}
            MessageEvent::Interrupted => break,
        }
        if let Some(t) = &last
            && !args.json
            && Instant::now() >= next_draw
        {
            if terminal {
                next_draw = Instant::now() + Duration::from_millis(100);
                in_place.draw(&mut stdout, &panel(t, &stats, domain.name())).context("writing to stdout")?;
            } else if !progress_every.is_zero() {
                next_draw = Instant::now() + progress_every;
                writeln!(stdout, "{}", panel(t, &stats, domain.name()).join("\n")).context("writing to stdout")?;
            }
        }
    }
    let mut summary = stats.json();
    summary["ended_by"] = json!(ended_by);
    if let Some(path) = args.report {
        std::fs::write(path, format!("{summary:#}\n")).with_context(|| format!("cannot write the report {}", path.display()))?;
    }
    match (&last, args.json) {
        (Some(t), false) if terminal => in_place.draw(&mut stdout, &panel(t, &stats, domain.name()))?,
        (Some(t), false) => writeln!(stdout, "{}", panel(t, &stats, domain.name()).join("\n"))?,
        (None, _) if ended_by == "timeout" => {
            bail!("no telemetry for {} s: is a daemon running in domain '{domain}'?", args.timeout_s)
        }
        _ => {}
    }
    eprintln!("monitor: {} telemetry samples, ended by {ended_by}", stats.samples);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(frame_id: u64, time_ms: u64, loop_us: u64, update_us: [u64; 4]) -> Telemetry {
        Telemetry {
            frame_id,
            time_ns: time_ms * 1_000_000,
            loop_ns: loop_us * 1000,
            tracker_update_ns: update_us.map(|u| u * 1000),
            tracker_state: update_us.map(|u| u32::from(u > 0)),
            ..Telemetry::default()
        }
    }

    #[test]
    fn the_stereo_update_is_the_sum_of_the_trackers_and_idle_cycles_do_not_count() {
        let mut s = TelemetryStats::default();
        for k in 0..10 {
            s.add(&sample(k, 100 + 33 * k, 200, [10, 12, 0, 0])); // 22 µs a cycle
        }
        s.add(&sample(10, 430, 150, [0; 4])); // nothing tracked this cycle
        s.add(&sample(NO_FRAME, 440, 999_999, [0; 4])); // a safety stop: no cycle
        let j = s.json();
        assert_eq!(j["samples"], 12);
        assert_eq!(j["cycles"], 11);
        assert_eq!(j["tracker_cycles"], 10);
        let p50 = j["tracker_update_us_p50"].as_f64().unwrap();
        assert!((22.0..=22.0 * 17.0 / 16.0).contains(&p50), "{p50}");
        assert!((j["tracker_rate_hz"].as_f64().unwrap() - 1e6 / p50).abs() < 1e-6);
        // 10 tracked cycles 33 ms apart: 30.3 frames/s; 11 cycles over 330 ms: 33.3 cycles/s.
        assert!((j["tracked_fps"].as_f64().unwrap() - 1000.0 / 33.0).abs() < 1e-6);
        assert!((j["cycles_per_s"].as_f64().unwrap() - 10.0 * 1000.0 / 330.0).abs() < 1e-6);
    }

    #[test]
    fn percentiles_match_the_daemons_histogram_on_the_same_values() {
        let mut s = TelemetryStats::default();
        let mut daemon = LatencyHistogram::new(u64::MAX);
        for k in 0..200u64 {
            let (a, b) = (20 + k % 7, 30 + (k * 13) % 11);
            s.add(&sample(k, k * 33, 100, [a, b, 0, 0]));
            daemon.record_ns((a + b) * 1000);
        }
        let j = s.json();
        assert_eq!(j["tracker_update_us_p50"].as_f64().unwrap(), daemon.percentile_ns(50.0) as f64 / 1000.0);
        assert_eq!(j["tracker_update_us_p99"].as_f64().unwrap(), daemon.percentile_ns(99.0) as f64 / 1000.0);
    }

    #[test]
    fn json_names_trackers_and_drops_unused_numbers() {
        let mut t = sample(7, 1, 100, [15, 0, 0, 0]);
        t.phase = Phase::Servo as u32;
        t.tracker_corners_px[0][0] = [10.0, 20.0];
        t.servo_error[0] = 0.5;
        t.set_reason("servoing");
        let v = telemetry_json(&t);
        assert_eq!(v["phase"], "servo");
        assert_eq!(v["reason"], "servoing");
        assert_eq!(v["trackers"][0]["tracker"], "gripper_left");
        assert_eq!(v["trackers"][0]["state"], "tracking");
        assert_eq!(v["trackers"][0]["update_ns"], 15_000);
        assert_eq!(v["trackers"][0]["corners_px"], json!([[10.0, 20.0]]));
        assert_eq!(v["trackers"][1]["state"], "off");
        assert_eq!(v["servo_error"][0], 0.5);
        assert_eq!(v["servo_error"][1], Value::Null);
        assert_eq!(telemetry_json(&Telemetry::default())["frame_id"], Value::Null);
    }

    #[test]
    fn the_panel_shows_phase_trackers_and_rates() {
        let mut s = TelemetryStats::default();
        let t = sample(3, 5, 120, [40, 0, 0, 0]);
        s.add(&t);
        let text = panel(&t, &s, "d").join("\n");
        assert!(text.contains("phase idle") && text.contains("gripper left") && text.contains("40.0"), "{text}");
        assert!(text.contains("allows 25000 updates/s"), "{text}");
    }
}
