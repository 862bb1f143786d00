//! `handeye hint` on a simulator snapshot: the hint for the facet at a pixel has that face's
//! corners (ground truth, `truth.json`) within 3 px in both views, vertex for vertex, and
//! the depth of the block behind it; a pixel on the table, no stereo model, or no robot
//! coordinates for the depth without `--depth-mm`, is an error that says what to supply, and
//! writes no hint.
//!
//! Needs a Vulkan (or GL) adapter for the snapshot: lavapipe on GPU-less machines (`make
//! setup` installs it).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use handeye_wire::hint::OperatorHint;
use serde_json::Value;

/// A scratch directory removed when dropped.
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn snapshot(scenario: &str, name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("handeye-hint-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let xdg = dir.join("xdg");
    std::fs::create_dir_all(&xdg).expect("scratch dir");
    let out = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .args(["snapshot", &format!("{}/scenarios/{scenario}", env!("CARGO_MANIFEST_DIR")), "--out"])
        .arg(&dir)
        .env("XDG_RUNTIME_DIR", &xdg)
        .output()
        .expect("run handeye snapshot");
    assert!(out.status.success(), "handeye snapshot failed (is a Vulkan driver such as lavapipe installed?): {}", String::from_utf8_lossy(&out.stderr));
    Scratch(dir)
}

fn hint(dir: &Path, at: [f64; 2], geometry: &[&str], out: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_handeye"))
        .arg("hint")
        .arg("--left")
        .arg(dir.join("left.png"))
        .arg("--right")
        .arg(dir.join("right.png"))
        .arg("--at")
        .arg(format!("{},{}", at[0], at[1]))
        .args(geometry)
        .arg("--out")
        .arg(out)
        .output()
        .expect("run handeye hint")
}

type Poly = Vec<[f64; 2]>;

fn poly(v: &Value) -> Poly {
    v.as_array().expect("polygon").iter().map(|p| [p[0].as_f64().expect("u"), p[1].as_f64().expect("v")]).collect()
}

/// A target face of `truth.json`: name, polygon per view (pixel centres at integers, as in
/// hint.json), smaller visible pixel count of the two views, 3-D corners and normal.
struct TruthFace {
    name: String,
    views: [Poly; 2],
    visible_px: f64,
    normal: [f64; 3],
    corners_m: Vec<[f64; 3]>,
}

fn target_faces(dir: &Path) -> (Vec<TruthFace>, Vec<Poly>, Vec<[f64; 3]>) {
    let truth: Value = serde_json::from_str(&std::fs::read_to_string(dir.join("truth.json")).expect("truth.json")).expect("truth.json is JSON");
    let target = truth["target"].as_u64().expect("target");
    let p3 = |v: &Value| -> [f64; 3] { [0, 1, 2].map(|k| v[k].as_f64().expect("coordinate")) };
    let mut faces = Vec::new();
    let mut all_left = Vec::new();
    let mut block_corners = Vec::new();
    for f in truth["faces"].as_array().expect("faces") {
        all_left.push(poly(&f["views"][0]["polygon_px"]));
        if f["block"].as_u64() != Some(target) {
            continue;
        }
        let corners_m: Vec<[f64; 3]> = f["corners_m"].as_array().expect("corners_m").iter().map(p3).collect();
        block_corners.extend(corners_m.iter().copied());
        faces.push(TruthFace {
            name: f["name"].as_str().expect("name").to_string(),
            views: [poly(&f["views"][0]["polygon_px"]), poly(&f["views"][1]["polygon_px"])],
            visible_px: (0..2).map(|k| f["views"][k]["visible_px"].as_f64().expect("visible_px")).fold(f64::INFINITY, f64::min),
            normal: p3(&f["normal"]),
            corners_m,
        });
    }
    (faces, all_left, block_corners)
}

fn centroid(p: &[[f64; 2]]) -> [f64; 2] {
    let n = p.len() as f64;
    p.iter().fold([0.0, 0.0], |s, q| [s[0] + q[0] / n, s[1] + q[1] / n])
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Even-odd point-in-polygon.
fn inside(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut odd = false;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
        if (a[1] > p[1]) != (b[1] > p[1]) && p[0] < a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]) {
            odd = !odd;
        }
    }
    odd
}

/// Index of the truth corner nearest each hint corner, checking it is within `tol` px.
fn corner_map(hint: &[[f64; 2]], truth: &[[f64; 2]], tol: f64, what: &str) -> Vec<usize> {
    assert_eq!(hint.len(), truth.len(), "{what}: hint has {} corners, the face {}: {hint:?} vs {truth:?}", hint.len(), truth.len());
    hint.iter()
        .map(|h| {
            let (k, d) = truth.iter().enumerate().map(|(k, t)| (k, dist(*h, *t))).min_by(|a, b| a.1.total_cmp(&b.1)).expect("corners");
            assert!(d <= tol, "{what}: hint corner {h:?} is {d:.2} px from the nearest true corner {:?}", truth[k]);
            k
        })
        .collect()
}

#[test]
fn hint_at_a_facet_pixel_has_the_facets_corners_in_both_views() {
    let snap = snapshot("pick_cube.toml", "facet");
    let (faces, _, block_corners) = target_faces(&snap.0);
    // The target's faces that both cameras see well (front and top of the cube), most
    // visible first.
    let mut seen: Vec<&TruthFace> = faces.iter().filter(|f| f.visible_px > 800.0).collect();
    seen.sort_by(|a, b| b.visible_px.total_cmp(&a.visible_px));
    assert!(seen.len() >= 2, "pick_cube should show two target faces well in both views");
    let cage = snap.0.join("cage.json");
    for face in seen {
        let at = centroid(&face.views[0]).map(f64::round);
        let out = snap.0.join(format!("hint-{}.json", face.name));
        let o = hint(&snap.0, at, &["--points", cage.to_str().unwrap()], &out);
        assert!(o.status.success(), "face {} at {at:?}: {}", face.name, String::from_utf8_lossy(&o.stderr));
        let h = OperatorHint::load(&out).expect("the daemon reads the hint");
        // Within 3 px of the face's corners in both views, and the same physical corner at
        // each index of the two lists (the daemon pairs them vertex for vertex).
        let left = corner_map(&h.left_px, &face.views[0], 3.0, &format!("face {} left", face.name));
        let right = corner_map(&h.right_px, &face.views[1], 3.0, &format!("face {} right", face.name));
        assert_eq!(left, right, "face {}: the left and right corners are not the same physical corners", face.name);
        let mut distinct = left.clone();
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), left.len(), "face {}: two hint corners on one true corner", face.name);
        // The block's true extent behind the face along its normal.
        let c = face.corners_m[0];
        let depth_mm = block_corners.iter().map(|q| (0..3).map(|k| face.normal[k] * (c[k] - q[k])).sum::<f64>().abs()).fold(0.0, f64::max) * 1e3;
        assert!((h.depth_mm - depth_mm).abs() < 5.0, "face {}: depth {:.1} mm, true {depth_mm:.1} mm", face.name, h.depth_mm);
    }
}

#[test]
fn a_table_pixel_no_stereo_model_or_an_unmeasurable_depth_is_an_error_not_a_hint() {
    let snap = snapshot("pick_cube.toml", "table");
    let (faces, all_left, _) = target_faces(&snap.0);
    let front = faces.iter().max_by(|a, b| a.visible_px.total_cmp(&b.visible_px)).expect("a target face");
    // Beside the cube on the table: inside no face of any block.
    let c = centroid(&front.views[0]);
    let table = [(c[0] + 150.0).round(), c[1].round()];
    assert!(table[0] < 630.0 && all_left.iter().all(|p| !inside(p, table)), "{table:?} must be on the table");
    let cage = snap.0.join("cage.json");
    let out = snap.0.join("table-hint.json");
    let o = hint(&snap.0, table, &["--points", cage.to_str().unwrap()], &out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "a table pixel gave a hint: {}", String::from_utf8_lossy(&o.stdout));
    assert!(err.contains("no facet at") && err.contains("Nearest: facet"), "{err}");
    assert!(!out.exists(), "no hint may be written");

    // Correspondences without robot coordinates: the facet is found but its depth cannot be
    // measured, and the error says to give it; with --depth-mm the hint is written.
    let cage_json: Value = serde_json::from_str(&std::fs::read_to_string(&cage).expect("cage.json")).expect("cage.json is JSON");
    let pixels_only = snap.0.join("cage-pixels-only.json");
    std::fs::write(&pixels_only, serde_json::json!({ "left_px": cage_json["left_px"], "right_px": cage_json["right_px"] }).to_string()).expect("write points");
    let at = centroid(&front.views[0]).map(f64::round);
    let o = hint(&snap.0, at, &["--points", pixels_only.to_str().unwrap()], &out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--depth-mm") && err.contains("robot coordinates"), "{err}");
    assert!(!out.exists(), "no hint may be written");
    let o = hint(&snap.0, at, &["--points", pixels_only.to_str().unwrap(), "--depth-mm", "40"], &out);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(OperatorHint::load(&out).expect("hint").depth_mm, 40.0);
    std::fs::remove_file(&out).expect("remove hint");

    // No stereo model: the error names the flags and where the file comes from.
    let o = hint(&snap.0, centroid(&front.views[0]).map(f64::round), &[], &out);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("no stereo model") && err.contains("--points") && err.contains("cage.json") && err.contains("--calib"), "{err}");
    assert!(!out.exists(), "no hint may be written");
}
