//! Fuzzing the stereo-model files that `handeye plan` and `handeye hint` read
//! (`src/cli/plan.rs`, compiled into this test from its source file: the CLI is a binary
//! crate): `--points` (point correspondences, with or without robot coordinates, in the
//! simulator's `cage.json` layout or as a list) and `--calib` (an affine stereo model), each
//! then fitted as the commands do (the affine model, the pinhole cameras, the epipolar
//! constraint) — so degenerate, huge and non-finite numbers reach the fitting code too.
//! Nothing may panic or allocate without bound; every refusal names its field.
//!
//! `make test` runs the short tests; `make fuzz` the `#[ignore]`d long ones.

// Decoders take `&S::Value` of their proptest strategy (`&String`).
#![allow(clippy::ptr_arg)]

mod fuzz_support;

#[path = "../src/cli/plan.rs"]
#[allow(dead_code)]
mod plan;
// `plan.rs` reads PNGs through `super::png`.
#[path = "../src/cli/png.rs"]
#[allow(dead_code)]
mod png;

use std::path::PathBuf;

use fuzz_support::mutate::{byte_edits, edit_json, edit_text, node_edit};
use fuzz_support::{assert_coverage, Fuzz, Outcome};
use handeye_vision::planner::EpipolarGeometry;
use proptest::prelude::*;
use serde_json::{json, Value};

/// JSON text where a number or token breaks.
const JSON_RAW: &[&str] = &["1e999", "-1e999", "NaN", "-", "18446744073709551616", "-0", "1.", "[", "}", "null"];

/// Eight cage points (a 20 cm box) seen by two affine cameras, as `cage.json` holds them.
fn cage() -> Value {
    let mut points = Vec::new();
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for k in 0..8 {
        let x = [0.3 + 0.2 * (k & 1) as f64, -0.1 + 0.2 * ((k >> 1) & 1) as f64, 0.05 + 0.2 * ((k >> 2) & 1) as f64];
        points.push(json!(x));
        left.push(json!([320.0 + 900.0 * x[1] - 80.0 * x[0], 240.0 - 900.0 * x[2] + 60.0 * x[0]]));
        right.push(json!([330.0 + 880.0 * x[1] + 120.0 * x[0], 238.0 - 905.0 * x[2] + 55.0 * x[0]]));
    }
    json!({ "points_m": points, "left_px": left, "right_px": right })
}

/// The same points as a list of `{left, right, robot_m}`.
fn point_list() -> Value {
    let c = cage();
    let list: Vec<Value> = (0..8).map(|i| json!({ "left": c["left_px"][i], "right": c["right_px"][i], "robot_m": c["points_m"][i] })).collect();
    json!({ "points": list })
}

fn calib() -> Value {
    json!({ "m": [[-80.0, 900.0, 0.0], [60.0, 0.0, -900.0], [120.0, 880.0, 0.0], [55.0, 0.0, -905.0]], "c": [320.0, 240.0, 330.0, 238.0], "disparity_range_px": [-20.0, 60.0], "residual_rms_px": 0.3 })
}

/// Random text, or one of `bases` with a tree edit and/or byte edits.
fn json_inputs(bases: Vec<Value>) -> impl Strategy<Value = String> {
    let n = bases.len();
    let b2 = bases.clone();
    let tree = (0..n, any::<usize>(), node_edit(JSON_RAW)).prop_map(move |(i, pick, edit)| edit_json(&bases[i], pick, &edit));
    let tree2 = (0..n, any::<usize>(), node_edit(JSON_RAW), any::<usize>(), node_edit(JSON_RAW)).prop_map(move |(i, p1, e1, p2, e2)| {
        let once: Value = serde_json::from_str(&edit_json(&b2[i], p1, &e1)).unwrap_or_else(|_| b2[i].clone());
        edit_json(&once, p2, &e2)
    });
    prop_oneof![
        1 => prop::collection::vec(any::<u8>(), 0..200).prop_map(|b| String::from_utf8_lossy(&b).into_owned()),
        4 => tree,
        3 => tree2,
        1 => (Just(cage().to_string()), byte_edits(3)).prop_map(|(t, e)| edit_text(&t, &e)),
    ]
}

/// This test thread's scratch folder: the loaders read files.
fn scratch_dir() -> PathBuf {
    let thread = format!("{:?}", std::thread::current().id()).replace(|c: char| !c.is_ascii_alphanumeric(), "");
    std::env::temp_dir().join(format!("handeye-fuzz-geometry-{}-{thread}", std::process::id()))
}

fn scratch(name: &str, text: &str) -> PathBuf {
    let dir = scratch_dir();
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let path = dir.join(format!("{name}.json"));
    std::fs::write(&path, text).expect("write scratch file");
    path
}

/// Removes the thread's scratch folder when a test ends.
struct CleanUp;

impl Drop for CleanUp {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(scratch_dir());
    }
}

/// The reason of a refusal: the field it names (between backticks), or what failed.
fn reason(e: &anyhow::Error) -> String {
    let msg = format!("{e:#}");
    if msg.contains("not valid JSON") {
        return "json".into();
    }
    if let Some(rest) = msg.split('`').nth(1) {
        // `points[3].left[1]` counts as `points[].left`.
        let field: String = rest.split('[').next().unwrap_or(rest).to_string();
        let tail = rest.rsplit(']').next().filter(|t| t.starts_with('.')).unwrap_or("");
        return format!("{field}{tail}").trim_end_matches(|c: char| c.is_ascii_digit()).to_string();
    }
    for (needle, key) in [("need at least", "too_few"), ("cannot fit", "fit"), ("expected a list", "shape"), ("singular", "singular")] {
        if msg.contains(needle) {
            return key.into();
        }
    }
    String::new()
}

fn check(geo: &EpipolarGeometry) {
    // What the planner reads first: the disparity window and the epipolar constraint.
    let _ = (geo.disparity_px, geo.epipolar.n, geo.epipolar.n0);
}

fn decode_points(text: &String) -> Outcome {
    let path = scratch("points", text);
    let points = plan::load_points(&path).map_err(|e| reason(&e))?;
    let (geo, _) = plan::geometry_from_points(&points, 0.5, 10.0, &path).map_err(|e| reason(&e))?;
    check(&geo);
    Ok(())
}

fn decode_calib(text: &String) -> Outcome {
    let path = scratch("calib", text);
    let model = plan::load_calib(&path).map_err(|e| reason(&e))?;
    check(&EpipolarGeometry::from_model(model, 0.5, 10.0));
    Ok(())
}

fn alloc_bound(text: &String) -> usize {
    (1 << 20) + 64 * text.len()
}

#[test]
fn points_json() {
    let _clean = CleanUp;
    let counts = Fuzz::short("points_json", 3000).run(json_inputs(vec![cage(), point_list()]), alloc_bound, decode_points);
    assert_coverage("points_json", &counts, &["json", "too_few", "left_px", "points_m"]);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn points_json_long() {
    let _clean = CleanUp;
    Fuzz::long("points_json").run(json_inputs(vec![cage(), point_list()]), alloc_bound, decode_points);
}

#[test]
fn calib_json() {
    let _clean = CleanUp;
    let counts = Fuzz::short("calib_json", 3000).run(json_inputs(vec![calib()]), alloc_bound, decode_calib);
    assert_coverage("calib_json", &counts, &["json", "m", "c", "disparity_range_px"]);
}

#[test]
#[ignore = "long fuzz run: make fuzz"]
fn calib_json_long() {
    let _clean = CleanUp;
    Fuzz::long("calib_json").run(json_inputs(vec![calib()]), alloc_bound, decode_calib);
}
