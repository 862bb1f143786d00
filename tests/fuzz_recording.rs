//! Fuzzing the recording reader that `handeye feed --dir` replays (`src/cli/recording.rs`,
//! compiled into this test from its source file: the CLI is a binary crate): `frames.jsonl`
//! lines built from fuzzed ids, capture times and file fields (steps of one, huge jumps,
//! values near `u64::MAX`, missing and mistyped fields), with byte edits, and random text.
//! An accepted recording then drives the replay clock over several `--loop` passes, as
//! `feed` does. Nothing may panic or allocate without bound; every refusal names its field.
//!
//! `make test` runs the short test; `make fuzz` the `#[ignore]`d long one.

// Decoders take `&S::Value` of their proptest strategy (`&String`).
#![allow(clippy::ptr_arg)]

mod fuzz_support;

#[path = "../src/cli/recording.rs"]
#[allow(dead_code)]
mod recording;

use std::path::Path;

use fuzz_support::mutate::{byte_edits, edit_text};
use fuzz_support::{assert_coverage, Fuzz, Outcome};
use proptest::prelude::*;

/// A number of a line: a step after the previous line's, or an absolute value.
#[derive(Debug, Clone)]
enum Num {
    Step(u64),
    Abs(u64),
    Text(&'static str),
}

fn num() -> impl Strategy<Value = Num> {
    prop_oneof![
        20 => (0u64..40_000_000).prop_map(Num::Step),
        1 => prop::sample::select(vec![0u64, 1, 1 << 62, (1 << 62) + 1, u64::MAX - 1, u64::MAX]).prop_map(Num::Abs),
        1 => any::<u64>().prop_map(Num::Abs),
        1 => prop::sample::select(vec!["-1", "1.5", "1e3", "18446744073709551616", "null", "\"7\"", "[]"]).prop_map(Num::Text),
    ]
}

fn file() -> impl Strategy<Value = Option<&'static str>> {
    prop_oneof![20 => Just(Some("\"left/00000001.png\"")), 1 => Just(None), 1 => prop::sample::select(vec!["\"\"", "null", "3", "{}"]).prop_map(Some)]
}

fn lines() -> impl Strategy<Value = String> {
    let line = (num(), num(), file(), file());
    let built = (prop::collection::vec(line, 0..12), prop_oneof![3 => Just(vec![]), 1 => byte_edits(2)]).prop_map(|(lines, edits)| {
        let (mut id, mut t) = (0u64, 0u64);
        let mut text = String::new();
        for (i, c, l, r) in lines {
            let mut fields = Vec::new();
            for (name, n, last) in [("id", i, &mut id), ("capture_time_ns", c, &mut t)] {
                let v = match n {
                    Num::Step(s) => last.saturating_add(s).to_string(),
                    Num::Abs(a) => a.to_string(),
                    Num::Text(x) => x.to_string(),
                };
                if let Ok(x) = v.parse() {
                    *last = x;
                }
                fields.push(format!("\"{name}\":{v}"));
            }
            if let Some(l) = l {
                fields.push(format!("\"left\":{l}"));
            }
            if let Some(r) = r {
                fields.push(format!("\"right\":{r}"));
            }
            text += &format!("{{{}}}\n", fields.join(","));
        }
        edit_text(&text, &edits)
    });
    prop_oneof![1 => prop::collection::vec(any::<u8>(), 0..300).prop_map(|b| String::from_utf8_lossy(&b).into_owned()), 8 => built]
}

fn decode(text: &String) -> Outcome {
    let frames = match recording::parse_frames(text, Path::new("rec/frames.jsonl"), Path::new("rec")) {
        Ok(f) => f,
        Err(e) => {
            let msg = format!("{e:#}");
            return Err(if let Some(rest) = msg.split("field `").nth(1) {
                rest.split('`').next().unwrap_or("field").to_string()
            } else if msg.contains("not a JSON object") {
                "json".into()
            } else if msg.contains("holds no frames") {
                "empty".into()
            } else {
                String::new()
            });
        }
    };
    // What `feed --dir DIR --loop` does with the recording: stamps of every frame, pass after
    // pass, and the due time of each from a replay start.
    let clock = recording::ReplayClock::new(frames.iter().map(|f| f.stamp).collect());
    let _ = clock.mean_period_ns();
    let replay_start_ns: u64 = 1 << 50;
    let mut previous: Option<u64> = None;
    for pass in [0u64, 1, 2] {
        for index in 0..frames.len() {
            let (id, offset_ns) = clock.stamp(index, pass);
            assert!(previous.is_none_or(|p| id > p), "ids must increase from frame to frame and pass to pass");
            previous = Some(id);
            replay_start_ns.checked_add(offset_ns).expect("a due time that fits in u64");
        }
    }
    // A loop that ran on for ever: no overflow.
    let _ = clock.stamp(frames.len() - 1, u64::MAX / 2);
    Ok(())
}

fn alloc_bound(text: &String) -> usize {
    (1 << 20) + 64 * text.len()
}

#[test]
fn recording_frames_jsonl() {
    let counts = Fuzz::short("recording", 5000).run(lines(), alloc_bound, decode);
    assert_coverage("recording", &counts, &["json", "empty", "id", "capture_time_ns", "left"]);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn recording_frames_jsonl_long() {
    Fuzz::long("recording").run(lines(), alloc_bound, decode);
}
