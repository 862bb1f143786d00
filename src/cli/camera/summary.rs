//! What `handeye camera` counts while it runs, its progress line, and its summary.

use serde_json::{json, Value};

use super::pipeline::Side;
use super::source::{SourceEnd, SourceEvent};

/// A source's end as the command reported it.
pub struct ReportedEnd {
    pub side: Side,
    pub event: SourceEvent,
    /// CLOCK_MONOTONIC ns when the command reported it.
    pub reported_ns: u64,
}

impl ReportedEnd {
    /// From GStreamer posting the end to the command reporting it.
    pub fn detection_ns(&self) -> u64 {
        self.reported_ns.saturating_sub(self.event.posted_ns)
    }
}

/// Counters of one run. Frame ids: one per left frame captured (per frame with --mono),
/// whether it was published or dropped, so that a gap in the ids is a dropped frame.
#[derive(Default)]
pub struct CameraStats {
    pub published: u64,
    pub first_frame_id: Option<u64>,
    pub last_frame_id: Option<u64>,
    /// Frames that reached the command from each source.
    pub left_frames: u64,
    pub right_frames: u64,
    /// Left frames without a right frame within --max-skew-ms (their ids are skipped).
    pub dropped_skew: u64,
    /// Left frames dropped because the right source delivered nothing meanwhile, or was
    /// restarted (ids skipped).
    pub dropped_stale: u64,
    /// Frames a live source delivered while the command's queue was full (left: ids skipped).
    pub dropped_busy_left: u64,
    pub dropped_busy_right: u64,
    /// Frames that could not be published (no free shared-memory slot; ids skipped).
    pub dropped_publish: u64,
    /// Right frames that were not paired (each left frame is paired at most once).
    pub right_unpaired: u64,
    /// Frames whose capture time is their arrival because the buffer had no timestamp.
    pub arrival_stamped: u64,
    pub unreadable: u64,
    pub reconnects: u64,
    /// Frames still waiting for a partner when the run ended (neither published nor dropped).
    pub pending_left: u64,
    pub pending_right: u64,
    /// The id the next frame would have had: every id below it was published or dropped.
    pub next_frame_id: u64,
    /// Left/right capture time difference of each published pair, ns.
    pub skews_ns: Vec<u64>,
    /// Capture stamp to the return of publish, per published frame, ns.
    pub latencies_ns: Vec<u64>,
    pub ends: Vec<ReportedEnd>,
    /// CLOCK_MONOTONIC ns of the first and last publish.
    pub first_publish_ns: Option<u64>,
    pub last_publish_ns: Option<u64>,
}

/// Latencies and skews kept for the percentiles: the newest 2^20 at least (about 10 hours at
/// 30 frames/s); beyond that the older half is forgotten, so a camera left running for days
/// keeps a bounded memory.
const KEPT_SAMPLES: usize = 1 << 21;

/// Appends `value`, forgetting the older half of `values` when it is full.
pub fn record(values: &mut Vec<u64>, value: u64) {
    if values.len() >= KEPT_SAMPLES {
        values.drain(..KEPT_SAMPLES / 2);
    }
    values.push(value);
}

/// Nearest-rank percentile of unsorted values (sorted on a copy).
pub fn percentile(values: &[u64], p: f64) -> Option<u64> {
    let mut v = values.to_vec();
    v.sort_unstable();
    crate::cli::stats::percentile_sorted(&v, p)
}

impl CameraStats {
    pub fn dropped_ids(&self) -> u64 {
        self.dropped_skew + self.dropped_stale + self.dropped_busy_left + self.dropped_publish
    }

    pub fn fps(&self) -> f64 {
        match (self.first_publish_ns, self.last_publish_ns) {
            (Some(a), Some(b)) if b > a && self.published > 1 => (self.published - 1) as f64 * 1e9 / (b - a) as f64,
            _ => 0.0,
        }
    }

    /// One progress line (over the last 1000 frames for the percentiles).
    pub fn progress_line(&self, mono: bool) -> String {
        let recent = |v: &[u64]| v[v.len().saturating_sub(1000)..].to_vec();
        let ms = |x: Option<u64>| x.map_or("-".to_owned(), |v| format!("{:.1} ms", v as f64 / 1e6));
        let lat = recent(&self.latencies_ns);
        let skew = if mono {
            String::new()
        } else {
            let s = recent(&self.skews_ns);
            format!(", skew p50 {} max {}", ms(percentile(&s, 50.0)), ms(s.iter().max().copied()))
        };
        format!(
            "camera: {} frames, {:.1} frames/s{skew}, dropped {} (skew {}, stale {}, busy {}, publish {}), latency p50 {}",
            self.published,
            self.fps(),
            self.dropped_ids() + self.dropped_busy_right,
            self.dropped_skew,
            self.dropped_stale,
            self.dropped_busy_left + self.dropped_busy_right,
            self.dropped_publish,
            ms(percentile(&lat, 50.0)),
        )
    }

    /// The summary as one JSON object (keys listed in the command's help).
    pub fn json(&self, delivery: &str, live: (bool, Option<bool>), completed: bool, duration_s: f64) -> Value {
        let ends: Vec<Value> = self
            .ends
            .iter()
            .map(|e| {
                json!({
                    "side": e.side.to_string(),
                    "kind": match e.event.end {
                        SourceEnd::Eos => "eos",
                        SourceEnd::Error { .. } => "error",
                        SourceEnd::Stalled { .. } => "stalled",
                    },
                    "message": e.event.end.to_string(),
                    "posted_ns": e.event.posted_ns,
                    "reported_ns": e.reported_ns,
                    "detection_ns": e.detection_ns(),
                })
            })
            .collect();
        json!({
            "frames": self.published,
            "first_frame_id": self.first_frame_id,
            "last_frame_id": self.last_frame_id,
            "left_frames": self.left_frames,
            "right_frames": self.right_frames,
            "dropped": self.dropped_ids(),
            "dropped_skew": self.dropped_skew,
            "dropped_stale": self.dropped_stale,
            "dropped_busy_left": self.dropped_busy_left,
            "dropped_busy_right": self.dropped_busy_right,
            "dropped_publish": self.dropped_publish,
            "right_unpaired": self.right_unpaired,
            "arrival_stamped": self.arrival_stamped,
            "unreadable": self.unreadable,
            "reconnects": self.reconnects,
            "pending_left": self.pending_left,
            "pending_right": self.pending_right,
            "next_frame_id": self.next_frame_id,
            "fps": self.fps(),
            "skew_ns_p50": percentile(&self.skews_ns, 50.0),
            "skew_ns_p99": percentile(&self.skews_ns, 99.0),
            "skew_ns_max": self.skews_ns.iter().max(),
            "latency_ns_p50": percentile(&self.latencies_ns, 50.0),
            "latency_ns_p99": percentile(&self.latencies_ns, 99.0),
            "latency_ns_max": self.latencies_ns.iter().max(),
            "delivery": delivery,
            "left_live": live.0,
            "right_live": live.1,
            "source_ends": ends,
            "completed": completed,
            "duration_s": duration_s,
        })
    }

    /// The summary as text, for a person.
    pub fn text(&self, mono: bool, completed: bool, duration_s: f64) -> String {
        let ms = |x: Option<u64>| x.map_or("-".to_owned(), |v| format!("{:.2} ms", v as f64 / 1e6));
        let mut out = format!(
            "frames:    {} published in {duration_s:.2} s ({:.1} frames/s), ids {}..{}{}\n",
            self.published,
            self.fps(),
            self.first_frame_id.map_or("-".into(), |v| v.to_string()),
            self.last_frame_id.map_or("-".into(), |v| v.to_string()),
            if completed { ", --count reached" } else { "" }
        );
        out += &format!(
            "dropped:   {} ids skipped (skew {}, stale {}, busy {}, publish {})",
            self.dropped_ids(),
            self.dropped_skew,
            self.dropped_stale,
            self.dropped_busy_left,
            self.dropped_publish
        );
        if !mono {
            out += &format!("; right: {} frames, {} unpaired, {} busy", self.right_frames, self.right_unpaired, self.dropped_busy_right);
            out += &format!(
                "\nskew:      p50 {} p99 {} max {}",
                ms(percentile(&self.skews_ns, 50.0)),
                ms(percentile(&self.skews_ns, 99.0)),
                ms(self.skews_ns.iter().max().copied())
            );
        }
        out += &format!(
            "\nlatency:   p50 {} p99 {} (capture stamp to publish)\n",
            ms(percentile(&self.latencies_ns, 50.0)),
            ms(percentile(&self.latencies_ns, 99.0))
        );
        for e in &self.ends {
            out += &format!("source:    {} {} (reported {:.1} ms after GStreamer posted it)\n", e.side, e.event.end, e.detection_ns() as f64 / 1e6);
        }
        if self.reconnects > 0 {
            out += &format!("reconnects: {}\n", self.reconnects);
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_nearest_rank() {
        let v: Vec<u64> = (1..=100).rev().collect();
        assert_eq!(percentile(&v, 50.0), Some(50));
        assert_eq!(percentile(&v, 99.0), Some(99));
        assert_eq!(percentile(&[], 50.0), None);
    }

    #[test]
    fn dropped_ids_count_every_skipped_id_and_not_right_frames() {
        let s = CameraStats { dropped_skew: 2, dropped_stale: 1, dropped_busy_left: 3, dropped_publish: 4, dropped_busy_right: 100, ..Default::default() };
        assert_eq!(s.dropped_ids(), 10);
    }
}
