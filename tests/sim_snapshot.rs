//! `handeye snapshot` end to end: the PNGs it writes show the cube and the gripper, and the
//! face polygons in `truth.json` lie on the rendered edges (within 1 px, checked with the
//! image gradient across every well-contrasted edge of every fully visible face).
//!
//! Needs a Vulkan (or GL) adapter: lavapipe on GPU-less machines (`make setup` installs it).

use std::path::{Path, PathBuf};
use std::process::Command;

use serde_json::Value;

fn snapshot(scenario: &str, extra: &[&str]) -> PathBuf {
    let root = env!("CARGO_MANIFEST_DIR");
    static RUN: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let run = RUN.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let out = std::env::temp_dir().join(format!("handeye-snap-{}-{run}-{scenario}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let xdg = std::env::temp_dir().join(format!("handeye-xdg-{}", std::process::id()));
    std::fs::create_dir_all(&xdg).expect("xdg dir");
    let status = Command::new(env!("CARGO_BIN_EXE_handeye"))
        .args(["snapshot", &format!("{root}/scenarios/{scenario}"), "--out"])
        .arg(&out)
        .args(extra)
        .env("XDG_RUNTIME_DIR", &xdg)
        .status()
        .expect("run handeye snapshot");
    assert!(status.success(), "handeye snapshot failed (is a Vulkan driver such as lavapipe installed?)");
    out
}

struct Gray {
    w: usize,
    h: usize,
    px: Vec<u8>,
}

impl Gray {
    fn load(path: &Path) -> Self {
        let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_luma8();
        let (w, h) = img.dimensions();
        Self { w: w as usize, h: h as usize, px: img.into_raw() }
    }

    fn at(&self, x: usize, y: usize) -> f64 {
        f64::from(self.px[y * self.w + x])
    }

    /// Bilinear sample; pixel centres at integers.
    fn sample(&self, x: f64, y: f64) -> Option<f64> {
        if x < 0.0 || y < 0.0 || x > (self.w - 1) as f64 || y > (self.h - 1) as f64 {
            return None;
        }
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(self.w - 1), (y0 + 1).min(self.h - 1));
        let (fx, fy) = (x - x0 as f64, y - y0 as f64);
        let top = self.at(x0, y0) * (1.0 - fx) + self.at(x1, y0) * fx;
        let bottom = self.at(x0, y1) * (1.0 - fx) + self.at(x1, y1) * fx;
        Some(top * (1.0 - fy) + bottom * fy)
    }
}

fn polygon(v: &Value) -> Vec<[f64; 2]> {
    v["polygon_px"].as_array().expect("polygon").iter().map(|p| [p[0].as_f64().unwrap(), p[1].as_f64().unwrap()]).collect()
}

/// Signed offsets (px, along the edge normal) between the projected edge a→b and the
/// gradient centroid across it, at samples spaced ~2 px along the middle of the edge where
/// the two sides differ by at least `min_contrast` grey levels.
fn edge_offsets(img: &Gray, a: [f64; 2], b: [f64; 2], min_contrast: f64) -> Vec<f64> {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len = dx.hypot(dy);
    if len < 12.0 {
        return Vec::new();
    }
    let (tx, ty) = (dx / len, dy / len);
    let (nx, ny) = (-ty, tx);
    let mut out = Vec::new();
    let samples = (len / 2.0) as usize;
    for k in 0..=samples {
        let t = 0.2 + 0.6 * k as f64 / samples.max(1) as f64;
        let (cx, cy) = (a[0] + dx * t, a[1] + dy * t);
        let profile: Option<Vec<f64>> = (-16..=16).map(|i| img.sample(cx + nx * i as f64 * 0.25, cy + ny * i as f64 * 0.25)).collect();
        let Some(p) = profile else { continue };
        let side_a = (p[0] + p[1] + p[2]) / 3.0; // s = -4 .. -3.5 px
        let side_b = (p[30] + p[31] + p[32]) / 3.0; // s = +3.5 .. +4 px
        if (side_a - side_b).abs() < min_contrast {
            continue;
        }
        // Gradient along the normal; its strongest point within 1.5 px of the polygon edge,
        // and the centroid of the contiguous run of strong gradient around it (a neighbouring
        // edge a few pixels away must not pull the estimate).
        let g: Vec<f64> = (1..32).map(|i| (p[i + 1] - p[i - 1]).abs()).collect();
        let s_of = |j: usize| (j as f64 + 1.0 - 16.0) * 0.25;
        let Some(best) = (0..g.len()).filter(|&j| s_of(j).abs() <= 1.5).max_by(|&x, &y| g[x].total_cmp(&g[y])) else {
            continue;
        };
        let floor = 0.3 * g[best];
        let (mut lo, mut hi) = (best, best);
        while lo > 0 && g[lo - 1] >= floor {
            lo -= 1;
        }
        while hi + 1 < g.len() && g[hi + 1] >= floor {
            hi += 1;
        }
        let (mut sw, mut sws) = (0.0, 0.0);
        for (j, &gj) in g.iter().enumerate().take(hi + 1).skip(lo) {
            sw += gj;
            sws += gj * s_of(j);
        }
        out.push(sws / sw);
    }
    out
}

fn check_view(img: &Gray, polygons: &[(String, Vec<[f64; 2]>)]) -> usize {
    let mut tested = 0;
    for (name, poly) in polygons {
        for i in 0..poly.len() {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            let offsets = edge_offsets(img, a, b, 12.0);
            if offsets.len() < 4 {
                continue;
            }
            let worst = offsets.iter().fold(0.0f64, |m, o| m.max(o.abs()));
            let mean = offsets.iter().sum::<f64>() / offsets.len() as f64;
            assert!(worst <= 1.0, "{name} edge {i} ({a:?} -> {b:?}): rendered edge up to {worst:.2} px off the polygon");
            // A half-pixel convention slip would show as a consistent shift.
            assert!(mean.abs() <= 0.3, "{name} edge {i}: mean offset {mean:.2} px");
            tested += offsets.len();
        }
    }
    tested
}

#[test]
fn snapshot_writes_pngs_whose_edges_match_the_truth_polygons() {
    let out = snapshot("pick_cube.toml", &[]);
    let truth: Value = serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).expect("truth.json")).expect("json");
    let cage: Value = serde_json::from_str(&std::fs::read_to_string(out.join("cage.json")).expect("cage.json")).expect("json");
    let views = [Gray::load(&out.join("left.png")), Gray::load(&out.join("right.png"))];
    for v in &views {
        assert_eq!((v.w, v.h), (640, 480));
    }

    // The cube: faces plainly visible in both views, two of them larger than 400 px in both.
    let target = truth["target"].as_u64().unwrap();
    let faces = truth["faces"].as_array().unwrap();
    let cube_faces: Vec<&Value> = faces.iter().filter(|f| f["block"].as_u64() == Some(target)).collect();
    let big_in_both =
        cube_faces.iter().filter(|f| (0..2).all(|v| f["views"][v]["visible_px"].as_u64().unwrap() > 400)).count();
    assert!(big_in_both >= 2, "cube faces > 400 px in both views: {big_in_both}");
    // The gripper plate: big, and its light rectangle clearly lighter than its border.
    for v in 0..2 {
        let plate = &truth["gripper"]["plate_views"][v];
        assert!(plate["visible_px"].as_u64().unwrap() > 2000, "plate in view {v}: {plate}");
    }

    // Every face (and the plate) that is fully in view: its edges must be where truth says.
    let mut tested = 0;
    for (v, img) in views.iter().enumerate() {
        let mut polys = Vec::new();
        for f in faces {
            let fv = &f["views"][v];
            let area = fv["projected_area_px"].as_f64().unwrap();
            let visible = fv["visible_px"].as_f64().unwrap();
            if fv["front_facing"].as_bool().unwrap() && area > 50.0 && visible >= 0.97 * area {
                polys.push((format!("view {v} block {} face {}", f["block"], f["name"]), polygon(fv)));
            }
        }
        polys.push((format!("view {v} gripper plate"), polygon(&truth["gripper"]["plate_views"][v])));
        tested += check_view(img, &polys);
    }
    assert!(tested >= 150, "only {tested} edge samples had enough contrast to test");

    // The cage projects inside both images.
    for key in ["left_px", "right_px"] {
        let pts = cage[key].as_array().unwrap();
        assert_eq!(pts.len(), 8);
        for p in pts {
            let (u, v) = (p[0].as_f64().unwrap(), p[1].as_f64().unwrap());
            assert!((0.0..640.0).contains(&u) && (0.0..480.0).contains(&v), "cage point off-image: {p}");
        }
    }
    let _ = std::fs::remove_dir_all(out);
}

#[test]
fn truth_polygons_follow_a_bumped_camera() {
    // pick_cube_bump knocks the left camera 3° at 24.3 s (frame 729): after the bump the left
    // view's polygons (and its camera matrix) must still match what is rendered.
    let out = snapshot("pick_cube_bump.toml", &["--frames", "740"]);
    let truth: Value = serde_json::from_str(&std::fs::read_to_string(out.join("truth.json")).unwrap()).unwrap();
    let left = Gray::load(&out.join("left.png"));
    let mut polys = Vec::new();
    for f in truth["faces"].as_array().unwrap() {
        let fv = &f["views"][0];
        let area = fv["projected_area_px"].as_f64().unwrap();
        if fv["front_facing"].as_bool().unwrap() && area > 50.0 && fv["visible_px"].as_f64().unwrap() >= 0.97 * area {
            polys.push((format!("bumped view block face {}", f["name"]), polygon(fv)));
        }
    }
    polys.push(("bumped view gripper plate".into(), polygon(&truth["gripper"]["plate_views"][0])));
    assert!(check_view(&left, &polys) >= 50);
    // The bump moved the image: the cube's top face is ~94 px (1800 px · tan 3°) away from
    // where an unbumped snapshot of the same scene shows it.
    let plain = snapshot("pick_cube.toml", &[]);
    let t0: Value = serde_json::from_str(&std::fs::read_to_string(plain.join("truth.json")).unwrap()).unwrap();
    let top = |t: &Value| {
        let f = t["faces"].as_array().unwrap().iter().find(|f| f["name"] == "top").unwrap().clone();
        polygon(&f["views"][0])[0]
    };
    let shift = (top(&truth)[0] - top(&t0)[0]).abs();
    assert!((80.0..110.0).contains(&shift), "left view shifted by {shift:.1} px after a 3° pan");
    let _ = std::fs::remove_dir_all(out);
    let _ = std::fs::remove_dir_all(plain);
}
