//! `handeye plan` as a user runs it: PNG views and a points file in, JSON and an overlay out,
//! clear errors for bad input.

use std::path::{Path, PathBuf};
use std::process::Command;

use handeye_vision::image::ImageBuf;
use handeye_vision::planner::geom;
use handeye_vision::planner::synth::{BoxSpec, StereoPair, SynthScene};
use serde_json::{json, Value};

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("handeye-plan-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).expect("temp dir");
    d
}

fn save(img: &ImageBuf, path: &Path) {
    image::GrayImage::from_raw(img.width as u32, img.height as u32, img.data.clone()).expect("buffer").save(path).expect("write png");
}

/// A one-box scene written as `left.png`, `right.png` and a cage `points.json`.
fn write_scene(dir: &Path, with_robot: bool) -> StereoPair {
    let scene = SynthScene::new(vec![BoxSpec { center_m: [0.0, 0.01, 0.02], size_m: [0.05, 0.06, 0.04], yaw_rad: 0.35 }]);
    let pair = scene.render(9);
    save(&pair.left, &dir.join("left.png"));
    save(&pair.right, &dir.join("right.png"));
    let points: Vec<Value> = pair
        .cage
        .iter()
        .map(|(x, w)| if with_robot { json!({ "robot_m": x, "left": [w[0], w[1]], "right": [w[2], w[3]] }) } else { json!({ "left": [w[0], w[1]], "right": [w[2], w[3]] }) })
        .collect();
    std::fs::write(dir.join("points.json"), serde_json::to_string(&json!({ "points": points })).expect("json")).expect("write points");
    pair
}

fn plan(dir: &Path, extra: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_handeye"))
        .arg("plan")
        .arg("--left")
        .arg(dir.join("left.png"))
        .arg("--right")
        .arg(dir.join("right.png"))
        .args(extra)
        .output()
        .expect("run handeye")
}

#[test]
fn json_output_has_facets_matches_segments_and_timings() {
    let dir = scratch("json");
    let pair = write_scene(&dir, true);
    let points = dir.join("points.json");
    let overlay = dir.join("overlay.png");
    let out = plan(&dir, &["--points", points.to_str().unwrap(), "--json", "--overlay", overlay.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).expect("stdout is one JSON object");

    let facets = v["facets"].as_array().expect("facets");
    assert_eq!(facets.len(), 3, "one box shows three faces");
    let poly = |p: &Value| -> Vec<[f64; 2]> { p.as_array().expect("polygon").iter().map(|q| [q[0].as_f64().unwrap(), q[1].as_f64().unwrap()]).collect() };
    for truth in &pair.faces {
        let best = facets.iter().map(|f| geom::polygon_iou(&poly(&f["left"]), &truth.left, 4).min(geom::polygon_iou(&poly(&f["right"]), &truth.right, 4))).fold(0.0, f64::max);
        assert!(best > 0.9, "face {} best IoU {best:.3}", truth.face);
    }
    // Calibrated from robot coordinates: corners in metres, on the true box corners (median
    // within 1.5 mm; a vertex where a segment end had no junction may sit a little off).
    let mut errs = Vec::new();
    for f in facets {
        let corners = f["corners_robot_m"].as_array().expect("corners_robot_m when calibrated");
        assert_eq!(corners.len(), f["left"].as_array().unwrap().len());
        for c in corners {
            let c = [c[0].as_f64().unwrap(), c[1].as_f64().unwrap(), c[2].as_f64().unwrap()];
            let nearest = pair.faces.iter().flat_map(|t| t.corners_m.iter()).map(|t| ((t[0] - c[0]).powi(2) + (t[1] - c[1]).powi(2) + (t[2] - c[2]).powi(2)).sqrt()).fold(f64::INFINITY, f64::min);
            assert!(nearest < 0.006, "corner {c:?} is {:.1} mm from any box corner", nearest * 1e3);
            errs.push(nearest);
        }
    }
    errs.sort_by(f64::total_cmp);
    assert!(errs[errs.len() / 2] < 0.0015, "median corner error {:.2} mm", errs[errs.len() / 2] * 1e3);
    let matches = v["matches"].as_array().expect("matches");
    assert!(matches.len() >= 9, "{} matches", matches.len());
    // Every segment found, in each view: as many as counted, and each match's among them.
    let lines = |view: &str| v["segment_lines"][view].as_array().expect("segment_lines").clone();
    for view in ["left", "right"] {
        assert_eq!(lines(view).len() as u64, v["segments"][view].as_u64().expect("segment count"), "{view}");
    }
    for m in matches {
        for view in ["left", "right"] {
            assert!(lines(view).iter().any(|s| s["ends"] == m[view]), "the match's {view} segment {} is not listed", m[view]);
        }
    }
    let timings = v["timings_ms"].as_object().expect("timings_ms");
    for k in ["edges", "segments", "relations", "matching", "planes", "bootstrap", "facets", "reconstruction", "total"] {
        assert!(timings.get(k).and_then(Value::as_f64).is_some_and(|t| t >= 0.0), "timings_ms.{k}");
    }
    // The stages run one after another inside `total`; each value is rounded to 1e-3 ms, so
    // their sum may exceed the rounded total by up to half of that per rounded value.
    let stages: Vec<f64> = timings.iter().filter(|(k, _)| *k != "total").map(|(_, t)| t.as_f64().unwrap()).collect();
    let rounding_ms = 0.5e-3 * (stages.len() + 1) as f64;
    assert!(stages.iter().sum::<f64>() <= timings["total"].as_f64().unwrap() + rounding_ms + 1e-9, "{timings:?}");

    let img = image::open(&overlay).expect("overlay written").to_rgb8();
    assert_eq!(img.dimensions(), (2 * pair.left.width as u32, pair.left.height as u32));
    // Facets are drawn in colour on both halves.
    let coloured = |x0: u32| img.enumerate_pixels().filter(|(x, _, p)| (*x >= x0 && *x < x0 + pair.left.width as u32) && (p[0] != p[1] || p[1] != p[2])).count();
    assert!(coloured(0) > 200 && coloured(pair.left.width as u32) > 200);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn points_without_robot_coordinates_give_facets_but_no_metric_corners() {
    let dir = scratch("uncal");
    write_scene(&dir, false);
    let points = dir.join("points.json");
    let out = plan(&dir, &["--points", points.to_str().unwrap(), "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: Value = serde_json::from_slice(&out.stdout).expect("json");
    assert_eq!(v["facets"].as_array().unwrap().len(), 3);
    assert!(v["facets"][0].get("corners_robot_m").is_none());
    assert!(v["facets"][0]["corners_cyclopean_disparity_px"].is_array());
    assert_eq!(v["geometry"]["calibrated"], json!(false));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_input_names_the_file_and_field() {
    let dir = scratch("bad");
    write_scene(&dir, true);
    let run = |extra: &[&str]| {
        let out = plan(&dir, extra);
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).to_string()
    };
    // A missing calibration file.
    let missing = dir.join("nope.json");
    let err = run(&["--calib", missing.to_str().unwrap()]);
    assert!(err.contains("nope.json"), "{err}");
    // A point with a non-numeric coordinate.
    let bad = dir.join("bad.json");
    std::fs::write(&bad, r#"{"points": [{"left": [1, 2], "right": [3, "x"]}, {"left": [1, 2], "right": [3, 4]}, {"left": [1, 2], "right": [3, 4]}, {"left": [1, 2], "right": [3, 4]}]}"#).unwrap();
    let err = run(&["--points", bad.to_str().unwrap()]);
    assert!(err.contains("bad.json") && err.contains("points[0].right[1]"), "{err}");
    // Too few points.
    std::fs::write(&bad, r#"[{"left": [1, 2], "right": [3, 4]}]"#).unwrap();
    let err = run(&["--points", bad.to_str().unwrap()]);
    assert!(err.contains("need at least 4"), "{err}");
    // A calibration without its matrix.
    std::fs::write(&bad, r#"{"c": [1, 2, 3, 4], "disparity_range_px": [0, 10]}"#).unwrap();
    let err = run(&["--calib", bad.to_str().unwrap()]);
    assert!(err.contains("missing field `m`"), "{err}");
    // Neither geometry source.
    let err = run(&[]);
    assert!(err.contains("--calib") || err.contains("--points"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}
