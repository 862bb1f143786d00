//! The folder `handeye record` writes and `handeye feed --dir` replays: one PNG per view and
//! frame (`left/<id>.png`, `right/<id>.png`), `frames.jsonl` (one line per kept frame: its
//! id, times and files, and what was lost before it), `robot_state.jsonl` and
//! `telemetry.jsonl` (the messages that arrived meanwhile) and `recording.json` (the summary,
//! written at the end). The format is defined here once, for the writer and the reader.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value};

/// One line per kept frame, in the order received.
pub const FRAMES_FILE: &str = "frames.jsonl";
/// One line per robot state sample received.
pub const ROBOT_STATE_FILE: &str = "robot_state.jsonl";
/// One line per telemetry sample received.
pub const TELEMETRY_FILE: &str = "telemetry.jsonl";
/// The summary, written when the recording ends.
pub const SUMMARY_FILE: &str = "recording.json";

/// A line of `frames.jsonl`: one kept frame.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FrameRecord {
    /// The publisher's frame id (strictly increasing; gaps are frames not in the recording).
    pub id: u64,
    /// The header's capture and publish stamps, `CLOCK_MONOTONIC` ns of the publishing host.
    pub capture_time_ns: u64,
    pub publish_time_ns: u64,
    /// When the recorder took the frame, `CLOCK_MONOTONIC` ns.
    pub receive_time_ns: u64,
    /// The views' PNG files, relative to the recording folder (`right` is absent for a
    /// one-camera stream).
    pub left: String,
    pub right: Option<String>,
    /// Frame ids between the previous line and this one that never reached the recorder
    /// (the publisher dropped them for it, or sent none).
    pub missed_before: u64,
    /// Frames between the previous line and this one that reached the recorder but could not
    /// be kept (the writer was behind, or the frame had another size).
    pub not_kept_before: u64,
}

impl FrameRecord {
    /// The PNG file names of frame `id`: zero-padded so that name order is id order.
    pub fn file_names(id: u64, cameras: usize) -> (String, Option<String>) {
        (format!("left/{id:08}.png"), (cameras > 1).then(|| format!("right/{id:08}.png")))
    }
}

/// `recording.json`: what the recorder kept, and what it could not keep and why.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingSummary {
    /// Frames written (PNGs and a `frames.jsonl` line each).
    pub frames: u64,
    /// Valid frames received (kept or not).
    pub received: u64,
    /// Frame ids that never arrived, between the first and the last frame received.
    pub missed: u64,
    /// Frames received but not kept, by reason (`writer_behind`, `size_changed`,
    /// `write_failed`).
    pub not_kept: u64,
    pub not_kept_by_reason: Map<String, Value>,
    /// Samples the stereo subscriber rejected as malformed (see `handeye monitor`).
    pub rejected: u64,
    pub robot_states: u64,
    pub telemetry: u64,
    /// Messages that arrived but were not written (the file could not be written).
    pub messages_not_kept: u64,
    pub first_frame_id: Option<u64>,
    pub last_frame_id: Option<u64>,
    /// Geometry of the kept frames (`null` without frames).
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub cameras: Option<u32>,
    /// FNV-1a 64 over the kept frames' pixels, in order (as `handeye monitor --checksum`).
    pub checksum: String,
    /// Why the recording ended: `count`, `publisher_gone`, `timeout`, `interrupted`,
    /// `new_publisher`, `write_failed`.
    pub ended_by: String,
    /// The first error the writer met, if any (the file and the reason).
    pub error: Option<String>,
    pub duration_s: f64,
}

/// A recorded frame's id and capture time: what a replay reproduces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RecordedStamp {
    pub id: u64,
    pub capture_time_ns: u64,
}

/// What a replay needs of one `frames.jsonl` line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RecordedFrame {
    pub stamp: RecordedStamp,
    pub left: PathBuf,
    pub right: Option<PathBuf>,
}

/// Largest id or capture time a recording may hold, 2^60 (36 years of nanoseconds): a replay
/// adds a pass's span to each for every `--loop` pass, which must not overflow.
pub const MAX_RECORDED_VALUE: u64 = 1 << 60;

/// Reads `frames.jsonl` of the recording folder `dir`. Every error names the file, the line
/// (from 1) and the field: a missing or mistyped field, ids that do not increase, capture
/// times that go back.
pub fn read_frames(dir: &Path) -> Result<Vec<RecordedFrame>> {
    let path = dir.join(FRAMES_FILE);
    let text = std::fs::read_to_string(&path).with_context(|| format!("cannot read {}", path.display()))?;
    parse_frames(&text, &path, dir)
}

/// [`read_frames`] on the text of `path`; files are taken relative to `dir`.
pub fn parse_frames(text: &str, path: &Path, dir: &Path) -> Result<Vec<RecordedFrame>> {
    let mut frames: Vec<RecordedFrame> = Vec::new();
    for (index, line) in text.lines().enumerate() {
        let at = || format!("{} line {}", path.display(), index + 1);
        if line.trim().is_empty() {
            continue;
        }
        let value: Value = serde_json::from_str(line).with_context(|| format!("{}: not a JSON object", at()))?;
        let Value::Object(object) = value else { bail!("{}: not a JSON object", at()) };
        let id = field_u64(&object, "id").with_context(at)?;
        let capture_time_ns = field_u64(&object, "capture_time_ns").with_context(at)?;
        for (name, value) in [("id", id), ("capture_time_ns", capture_time_ns)] {
            if value > MAX_RECORDED_VALUE {
                bail!("{}: field `{name}`: {value} is beyond 2^60, where a replay's ids and times could not count on", at());
            }
        }
        let left = field_file(&object, "left", false).with_context(at)?.unwrap_or_default();
        let right = field_file(&object, "right", true).with_context(at)?;
        if let Some(prev) = frames.last() {
            if id <= prev.stamp.id {
                bail!("{}: field `id`: {id} does not follow {} (ids must increase)", at(), prev.stamp.id);
            }
            if capture_time_ns < prev.stamp.capture_time_ns {
                bail!(
                    "{}: field `capture_time_ns`: {capture_time_ns} is before the previous frame's {}",
                    at(),
                    prev.stamp.capture_time_ns
                );
            }
        }
        frames.push(RecordedFrame {
            stamp: RecordedStamp { id, capture_time_ns },
            left: dir.join(left),
            right: right.map(|r| dir.join(r)),
        });
    }
    if frames.is_empty() {
        bail!("{} holds no frames", path.display());
    }
    Ok(frames)
}

fn field_u64(object: &Map<String, Value>, name: &str) -> Result<u64> {
    match object.get(name) {
        None => bail!("field `{name}` is missing"),
        Some(v) => v.as_u64().with_context(|| format!("field `{name}`: expected a whole number >= 0, found {v}")),
    }
}

/// A file name field; `optional` ones may be absent or `null`.
fn field_file(object: &Map<String, Value>, name: &str, optional: bool) -> Result<Option<String>> {
    match object.get(name) {
        None | Some(Value::Null) if optional => Ok(None),
        None => bail!("field `{name}` is missing"),
        Some(Value::String(s)) if !s.is_empty() => Ok(Some(s.clone())),
        Some(v) => bail!("field `{name}`: expected a file name, found {v}"),
    }
}

/// Frame ids and capture times of a replay: the recorded ones, shifted so that the first
/// frame is captured when the replay starts. Capture-time differences and id gaps are kept
/// exactly; each pass of `--loop` goes on after the previous one (ids after its last id,
/// times one mean frame period after its last frame).
#[derive(Debug, Clone)]
pub struct ReplayClock {
    stamps: Vec<RecordedStamp>,
    id_span: u64,
    time_span_ns: u64,
}

impl ReplayClock {
    /// `stamps` in order, not empty (as [`read_frames`] returns them).
    pub fn new(stamps: Vec<RecordedStamp>) -> Self {
        let (first, last) = (stamps[0], stamps[stamps.len() - 1]);
        let span_ns = last.capture_time_ns - first.capture_time_ns;
        // One pass lasts its span plus the mean frame period (30 frames/s for one frame).
        let period_ns = if stamps.len() > 1 { span_ns / (stamps.len() as u64 - 1) } else { 1_000_000_000 / 30 };
        Self { id_span: last.id - first.id + 1, time_span_ns: span_ns + period_ns.max(1), stamps }
    }

    /// The mean time between recorded frames, ns (1/30 s for a one-frame recording).
    pub fn mean_period_ns(&self) -> u64 {
        self.time_span_ns - (self.stamps[self.stamps.len() - 1].capture_time_ns - self.stamps[0].capture_time_ns)
    }

    /// Frame `index` of pass `pass` (0 = the first): its id and its capture time in ns after
    /// the replay's first frame.
    pub fn stamp(&self, index: usize, pass: u64) -> (u64, u64) {
        let (first, s) = (self.stamps[0], self.stamps[index]);
        // Read values are at most MAX_RECORDED_VALUE, so a few passes fit; a loop that ran
        // on for longer than u64 counts stays at the largest value rather than wrapping.
        let id = s.id.saturating_add(pass.saturating_mul(self.id_span));
        let offset_ns = (s.capture_time_ns - first.capture_time_ns).saturating_add(pass.saturating_mul(self.time_span_ns));
        (id, offset_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<Vec<RecordedFrame>> {
        parse_frames(text, Path::new("rec/frames.jsonl"), Path::new("rec"))
    }

    const GOOD: &str = r#"{"id":3,"capture_time_ns":1000,"publish_time_ns":1100,"receive_time_ns":1200,"left":"left/00000003.png","right":"right/00000003.png","missed_before":0,"not_kept_before":0}
{"id":5,"capture_time_ns":67000,"left":"left/00000005.png","right":"right/00000005.png","missed_before":1,"not_kept_before":0}
"#;

    #[test]
    fn ids_and_times_a_replay_cannot_count_on_from_are_refused() {
        // Found by fuzzing (tests/fuzz_recording.rs): ids or capture times near u64::MAX made
        // the replay clock overflow (a panic in debug builds, wrapped ids in release).
        for (id, t, field) in [(u64::MAX, 5, "id"), (3, (1u64 << 60) + 1, "capture_time_ns")] {
            let text = format!("{{\"id\":1,\"capture_time_ns\":1,\"left\":\"l.png\"}}\n{{\"id\":{id},\"capture_time_ns\":{t},\"left\":\"l.png\"}}\n");
            let err = format!("{:#}", parse(&text).unwrap_err());
            assert!(err.contains("line 2") && err.contains(field) && err.contains("2^60"), "{err}");
        }
        // At the limit a replay loops without overflow, ids increasing.
        let text = format!("{{\"id\":0,\"capture_time_ns\":0,\"left\":\"l.png\"}}\n{{\"id\":{m},\"capture_time_ns\":{m},\"left\":\"l.png\"}}\n", m = MAX_RECORDED_VALUE);
        let frames = parse(&text).unwrap();
        let clock = ReplayClock::new(frames.iter().map(|f| f.stamp).collect());
        let ids: Vec<u64> = (0..3).flat_map(|pass| (0..2).map(move |i| (i, pass))).map(|(i, pass)| clock.stamp(i, pass).0).collect();
        assert!(ids.windows(2).all(|w| w[0] < w[1]), "{ids:?}");
        assert_eq!(clock.stamp(1, u64::MAX), (u64::MAX, u64::MAX));
    }

    #[test]
    fn lines_give_ids_capture_times_and_files_under_the_folder() {
        let frames = parse(GOOD).unwrap();
        assert_eq!(frames.len(), 2);
        assert_eq!(frames[1].stamp, RecordedStamp { id: 5, capture_time_ns: 67000 });
        assert_eq!(frames[0].left, Path::new("rec/left/00000003.png"));
        assert_eq!(frames[0].right.as_deref(), Some(Path::new("rec/right/00000003.png")));
    }

    #[test]
    fn a_bad_line_names_the_file_the_line_and_the_field() {
        let cases = [
            (r#"{"capture_time_ns":1,"left":"l.png"}"#, "line 1", "field `id` is missing"),
            (r#"{"id":"7","capture_time_ns":1,"left":"l.png"}"#, "line 1", "field `id`: expected a whole number"),
            (r#"{"id":-1,"capture_time_ns":1,"left":"l.png"}"#, "line 1", "field `id`"),
            (r#"{"id":1,"capture_time_ns":1.5,"left":"l.png"}"#, "line 1", "field `capture_time_ns`"),
            (r#"{"id":1,"capture_time_ns":1,"left":3}"#, "line 1", "field `left`: expected a file name"),
            (r#"{"id":1,"capture_time_ns":1}"#, "line 1", "field `left` is missing"),
            (r#"{"id":1,"capture_time_ns":1,"left":"l.png","right":false}"#, "line 1", "field `right`"),
            ("[1,2]", "line 1", "not a JSON object"),
            ("{\"id\":1,", "line 1", "not a JSON object"),
        ];
        for (line, where_, what) in cases {
            let text = format!("{}\n{line}\n", GOOD.lines().next().unwrap().replace("\"id\":3", "\"id\":0"));
            let err = format!("{:#}", parse(&text).unwrap_err());
            let where_ = where_.replace("line 1", "line 2");
            assert!(err.contains("rec/frames.jsonl") && err.contains(&where_) && err.contains(what), "{line}: {err}");
        }
    }

    #[test]
    fn ids_must_increase_and_capture_times_must_not_go_back() {
        let text = GOOD.replace("\"id\":5", "\"id\":3");
        let err = format!("{:#}", parse(&text).unwrap_err());
        assert!(err.contains("line 2") && err.contains("field `id`") && err.contains("does not follow 3"), "{err}");
        let text = GOOD.replace("67000", "999");
        let err = format!("{:#}", parse(&text).unwrap_err());
        assert!(err.contains("line 2") && err.contains("field `capture_time_ns`"), "{err}");
        let err = format!("{:#}", parse("\n").unwrap_err());
        assert!(err.contains("holds no frames"), "{err}");
    }

    #[test]
    fn a_replay_keeps_id_gaps_and_capture_time_differences_and_loops_after_the_last_frame() {
        let stamps = [(10, 5_000), (11, 38_000), (14, 105_000)].map(|(id, t)| RecordedStamp { id, capture_time_ns: t });
        let clock = ReplayClock::new(stamps.to_vec());
        assert_eq!(clock.stamp(0, 0), (10, 0));
        assert_eq!(clock.stamp(1, 0), (11, 33_000));
        assert_eq!(clock.stamp(2, 0), (14, 100_000));
        // The second pass: ids 15.., one mean period (50 µs) after the last frame.
        assert_eq!(clock.stamp(0, 1), (15, 150_000));
        assert_eq!(clock.stamp(2, 1), (19, 250_000));
        assert_eq!(clock.mean_period_ns(), 50_000);
    }

    #[test]
    fn file_names_sort_in_id_order() {
        assert_eq!(FrameRecord::file_names(7, 2), ("left/00000007.png".to_owned(), Some("right/00000007.png".to_owned())));
        assert_eq!(FrameRecord::file_names(7, 1).1, None);
        assert!(FrameRecord::file_names(9, 2).0 < FrameRecord::file_names(10, 2).0);
    }
}
