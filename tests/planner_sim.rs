//! The planner on the simulator's snapshots (issue #6 acceptance): the shipped scenarios and
//! 25 seeded random layouts of 2-5 blocks (clutter3's cameras, cage, light and arm, rendered
//! antialiased as the pick scenarios are; blocks placed where both cameras see them whole),
//! rendered by `handeye snapshot` with
//! perspective cameras (~1.6 m, f = 1800 px), calibrated from the snapshot's cage as
//! `handeye plan --points cage.json` does (the affine model for matching, pinhole cameras
//! fitted to the same eight points for robot coordinates), scored against `truth.json`.
//!
//! - A face is considered when the simulator counts more than 400 visible pixels of it in
//!   both views (`visible_px`: pixels where it is what the camera sees).
//! - Found: a facet's polygon has IoU >= 0.7 with the face's visible region in each view.
//! - The gripper is in view: a facet on its plate (truth.json has the plate's polygon) is a
//!   plate facet, one whose reconstructed centre is off the work surface (the arm's links,
//!   palm and fingers) an arm facet; both are real planes, listed and not spurious. Any other
//!   facet that overlaps no block face is spurious.
//! - Corners: per corner of a found face that shows in both views, the distance to the
//!   nearest reconstructed corner of its facet, robot frame.
//!
//! The same layouts are also measured under clutter3's own dark table, the closed loop's
//! lighting (`dark_table_population_keeps_its_found_rate`; `DARK=1` switches the `diag_*`
//! tests to it).
//!
//! See `planner_sim_support::score` for the details. Each run prints one line per scene and
//! one per missed face or spurious facet.

mod planner_sim_support;

use std::path::Path;

use handeye_vision::planner::{Planner, PlannerConfig};
use planner_sim_support::*;

fn scenarios_dir() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/scenarios"))
}

/// The lighting of the random layouts.
#[derive(Clone, Copy, PartialEq)]
enum Population {
    /// The grey table the issue-6 acceptance population was defined with.
    GreyTable,
    /// clutter3's own dark table, the closed loop's lighting since issue 7.
    DarkTable,
}

/// Snapshots of every shipped scenario and of `random` seeded layouts (antialiased unless
/// `ALIASED` is set: a diagnostic switch, not used by the asserted tests).
fn snapshots(dir: &Path, random: u64) -> Vec<Snapshot> {
    let population = if std::env::var_os("DARK").is_some() { Population::DarkTable } else { Population::GreyTable };
    snapshots_with(dir, random, std::env::var("ALIASED").is_err(), population)
}

fn snapshots_with(dir: &Path, random: u64, antialias: bool, population: Population) -> Vec<Snapshot> {
    let mut shipped: Vec<_> = std::fs::read_dir(scenarios_dir()).expect("scenarios/").filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.extension().is_some_and(|x| x == "toml")).collect();
    shipped.sort();
    let base_name = "clutter3";
    let shipped_base = std::fs::read_to_string(scenarios_dir().join("clutter3.toml")).expect("clutter3.toml");
    let base = match population {
        Population::DarkTable => shipped_base,
        Population::GreyTable => population_lighting(&shipped_base),
    };
    let light = Lighting::of_scenario(&base);
    let mut out = Vec::new();
    for p in &shipped {
        let name = p.file_stem().unwrap().to_string_lossy().to_string();
        let d = dir.join(&name);
        snapshot(p, &d);
        out.push(Snapshot::load(&name, &d));
    }
    // The random layouts share clutter3's cameras: blocks go where both see them whole.
    // Their edges are antialiased (a camera gives a pixel an edge crosses the mixed grey).
    let cams = out.iter().find(|s: &&Snapshot| s.name == base_name).expect("base snapshot").cameras.clone();
    let (w, h) = (out[0].left.width as f64, out[0].left.height as f64);
    let visible = |b: &BlockLayout| in_view(b, &cams, w, h, 5.0);
    for seed in 1..=random {
        let count = 2 + (seed as usize % 4);
        let name = format!("random{seed:02}");
        let toml = scenario_toml(&base, &name, seed, &random_layout(seed, count, &light, &visible), antialias);
        let file = dir.join(format!("{name}.toml"));
        std::fs::write(&file, toml).expect("write scenario");
        let d = dir.join(&name);
        snapshot(&file, &d);
        out.push(Snapshot::load(&name, &d));
    }
    out
}

/// `base` with the table shade and light the acceptance population was defined with (grey
/// table 0.5, light 0.7, ambient 0.3: clutter3's until issue 7 darkened its table for the
/// closed loop). The random layouts' shades are drawn against this lighting, so a change to a
/// shipped scenario's lighting would otherwise silently swap the population being measured.
/// The dark-table population is measured too (`dark_table_population_keeps_its_found_rate`).
fn population_lighting(base: &str) -> String {
    let mut doc: toml::Table = base.parse().expect("clutter3.toml is valid TOML");
    let table = doc.get_mut("table").and_then(|t| t.as_table_mut()).expect("[table]");
    table.insert("shade".into(), toml::Value::Float(0.5));
    let light = doc.get_mut("light").and_then(|t| t.as_table_mut()).expect("[light]");
    light.insert("intensity".into(), toml::Value::Float(0.7));
    light.insert("ambient".into(), toml::Value::Float(0.3));
    toml::to_string(&doc).expect("TOML")
}

/// Random layouts in the acceptance test.
const RANDOM_LAYOUTS: u64 = 25;

/// What the planner found on one population of snapshots.
struct Measure {
    rate: f64,
    spurious_per_scene: f64,
    corner_median_m: f64,
    /// One line per scene, missed face and spurious facet, and the totals.
    text: String,
}

fn measure(population: Population, scratch_name: &str) -> Measure {
    let scratch = Scratch::new(scratch_name);
    let snaps = snapshots_with(&scratch.0, RANDOM_LAYOUTS, true, population);
    let mut planner = Planner::new(PlannerConfig::default());
    let (mut considered, mut found, mut spurious) = (0, 0, 0);
    let (mut corners, mut corners_affine) = (Vec::new(), Vec::new());
    let mut text = String::new();
    for snap in &snaps {
        let plan = planner.plan(&snap.left.view(), &snap.right.view(), &snap.geometry(0.5, 10.0));
        let s = score(snap, &plan);
        text += &report(snap, &plan, &s);
        considered += s.considered();
        found += s.found();
        spurious += s.spurious();
        corners.extend(s.corner_errors_m);
        corners_affine.extend(s.corner_errors_affine_m);
    }
    let rate = found as f64 / considered as f64;
    let spurious_per_scene = spurious as f64 / snaps.len() as f64;
    let corner_median_m = median(&corners).expect("corners");
    text += &format!(
        "total: {} scenes, found {found} of {considered} faces ({:.1}%), {spurious} spurious ({spurious_per_scene:.2} per scene), corner median {:.2} mm over {} (through the affine model: {:.2} mm)\n",
        snaps.len(),
        rate * 100.0,
        corner_median_m * 1e3,
        corners.len(),
        median(&corners_affine).unwrap_or(f64::NAN) * 1e3,
    );
    eprintln!("{text}");
    Measure { rate, spurious_per_scene, corner_median_m, text }
}

impl Measure {
    /// The found rate and spurious facets within their bounds, and corners within 3 mm.
    fn assert_within(&self, min_rate: f64, max_spurious_per_scene: f64) {
        assert!(self.rate >= min_rate, "found rate {:.3}:\n{}", self.rate, self.text);
        assert!(self.spurious_per_scene <= max_spurious_per_scene, "spurious facets:\n{}", self.text);
        assert!(self.corner_median_m <= 0.003, "median corner error {:.2} mm:\n{}", self.corner_median_m * 1e3, self.text);
    }
}

#[test]
fn snapshots_meet_the_acceptance_measure() {
    // 25 layouts (~200 faces with the shipped scenes) rather than the minimum of 10:
    // the found rate of ~90 faces moves by a few percent with the seeds.
    measure(Population::GreyTable, "planner-sim").assert_within(0.9, 1.0);
}

/// The same layouts under clutter3's dark table, the lighting the closed loop plans in: the
/// blocks stand out from the table, but under its stronger ambient light a block's faces
/// differ less from each other (the L-block's tops above all), so this is where edge seeding
/// and facet joining are weakest. 181 of 209 faces (86.6 %) since the edge seed threshold
/// went from 4 to 3 grey levels per pixel and loose segments join a facet within 8 px (174,
/// 83.3 % before); the bound keeps that gain.
#[test]
fn dark_table_population_keeps_its_found_rate() {
    measure(Population::DarkTable, "planner-sim-dark").assert_within(0.86, 0.5);
}

/// `handeye plan --points cage.json` on a snapshot as the simulator writes it: the pinhole
/// cameras are fitted from the cage, and the cube's top face comes out with its corners in
/// robot coordinates within 3 mm of the truth.
#[test]
fn plan_cli_reads_the_snapshot_cage() {
    let scratch = Scratch::new("planner-sim-cli");
    let dir = scratch.0.join("pick_cube");
    snapshot(&scenarios_dir().join("pick_cube.toml"), &dir);
    let snap = Snapshot::load("pick_cube", &dir);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_handeye"))
        .args(["plan", "--json", "--left"])
        .arg(dir.join("left.png"))
        .arg("--right")
        .arg(dir.join("right.png"))
        .arg("--points")
        .arg(dir.join("cage.json"))
        .output()
        .expect("run handeye plan");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(v["geometry"]["pinhole_cameras"], serde_json::json!(true), "{}", v["geometry"]);
    let top = snap.faces.iter().find(|f| f.label == "cube/top").expect("cube/top in truth.json");
    let poly = |p: &serde_json::Value| -> Vec<[f64; 2]> { p.as_array().expect("polygon").iter().map(|q| [q[0].as_f64().unwrap(), q[1].as_f64().unwrap()]).collect() };
    let facets = v["facets"].as_array().expect("facets");
    let best = facets
        .iter()
        .max_by(|a, b| {
            let iou = |f: &serde_json::Value| handeye_vision::planner::geom::polygon_iou(&poly(&f["left"]), &top.polygon[0], 4);
            iou(a).total_cmp(&iou(b))
        })
        .expect("some facet");
    let iou = handeye_vision::planner::geom::polygon_iou(&poly(&best["left"]), &top.polygon[0], 4);
    assert!(iou >= 0.7, "best facet on the cube's top: IoU {iou:.2}");
    let corners: Vec<[f64; 3]> = best["corners_robot_m"].as_array().expect("corners_robot_m").iter().map(|c| [c[0].as_f64().unwrap(), c[1].as_f64().unwrap(), c[2].as_f64().unwrap()]).collect();
    let errs: Vec<f64> = top.corners_m.iter().map(|t| corners.iter().map(|c| ((c[0] - t[0]).powi(2) + (c[1] - t[1]).powi(2) + (c[2] - t[2]).powi(2)).sqrt()).fold(f64::INFINITY, f64::min)).collect();
    assert!(median(&errs).unwrap() <= 0.003, "top corners {:?} mm off", errs.iter().map(|e| (e * 1e4).round() / 10.0).collect::<Vec<_>>());
}

#[test]
#[ignore]
fn diag_floor() {
    let scratch = Scratch::new("planner-sim-diag");
    let snaps = snapshots(&scratch.0, 10);
    for snap in &snaps {
        let model = snap.model();
        let geo = snap.geometry(0.5, 10.0);
        let (mut errs, mut epi) = (Vec::new(), Vec::new());
        for f in &snap.faces {
            for c in &f.corners_m {
                let l = snap.cameras[0].project(*c);
                let r = snap.cameras[1].project(*c);
                let w = [l[0], l[1], r[0], r[1]];
                let x = model.reconstruct(&w);
                errs.push(((x[0] - c[0]).powi(2) + (x[1] - c[1]).powi(2) + (x[2] - c[2]).powi(2)).sqrt());
                epi.push(geo.epipolar.residual_px(&w).abs());
            }
        }
        let mx = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
        eprintln!("{:<14} cage rms {:.2} px disp {:?}; floor median {:.2} mm max {:.2} mm; epipolar |res| median {:.2} max {:.2} px", snap.name, model.residual_rms_px, geo.disparity_px, median(&errs).unwrap() * 1e3, mx(&errs) * 1e3, median(&epi).unwrap(), mx(&epi));
    }
}

#[test]
#[ignore]
fn diag_pixel_convention() {
    use handeye_vision::planner::geom;
    let scratch = Scratch::new("planner-sim-diag2");
    let snaps = snapshots(&scratch.0, 3);
    let mut planner = Planner::new(PlannerConfig::default());
    for snap in &snaps {
        let plan = planner.plan(&snap.left.view(), &snap.right.view(), &snap.geometry(0.5, 10.0));
        // For each long left segment, find the truth polygon edge it lies on: signed offset along x and y.
        let (mut dx, mut dy) = (Vec::new(), Vec::new());
        for s in plan.left_segments.iter().filter(|s| s.length() > 25.0) {
            let mut best = (f64::INFINITY, [0.0, 0.0]);
            for f in &snap.faces {
                let p = &f.polygon[0];
                for k in 0..p.len() {
                    let (a, b) = (p[k], p[(k + 1) % p.len()]);
                    let d = geom::point_segment_distance(s.p0, a, b) + geom::point_segment_distance(s.p1, a, b);
                    if d < best.0 {
                        let dir = geom::sub(b, a);
                        let n = [-dir[1] / geom::norm(dir), dir[0] / geom::norm(dir)];
                        let m = s.midpoint();
                        let off = geom::dot(geom::sub(m, a), n);
                        best = (d, [off * n[0], off * n[1]]);
                    }
                }
            }
            if best.0 < 3.0 {
                // Offset of the segment from the truth edge, projected onto x and y.
                let n = best.1;
                let l = geom::norm(n).max(1e-9);
                if (n[0] / l).abs() > 0.9 { dx.push(n[0]); }
                if (n[1] / l).abs() > 0.9 { dy.push(n[1]); }
            }
        }
        eprintln!("{}: near-vertical edges: median dx {:?} ({}), near-horizontal: median dy {:?} ({})", snap.name, median(&dx), dx.len(), median(&dy), dy.len());
    }
}

#[test]
#[ignore]
fn diag_overlays() {
    let dir = std::path::PathBuf::from("/tmp/pl/diag");
    std::fs::create_dir_all(&dir).unwrap();
    let env = |k: &str| std::env::var(k).ok().and_then(|v| v.parse::<f64>().ok());
    let snaps = snapshots(&dir, env("N").unwrap_or(10.0) as u64);
    let quiet = env("QUIET").is_some();
    let cfg = config_from_env();
    let margin = env("DISP_MARGIN").unwrap_or(0.5);
    let mut planner = Planner::new(cfg);
    let (mut c, mut f, mut sp) = (0, 0, 0);
    let mut corners = Vec::new();
    for snap in &snaps {
        let plan = planner.plan(&snap.left.view(), &snap.right.view(), &snap.geometry(margin, 10.0));
        let s = score(snap, &plan);
        if !quiet { eprint!("{}", report(snap, &plan, &s)); }
        c += s.considered(); f += s.found(); sp += s.spurious();
        corners.extend(s.corner_errors_m.iter().copied());
        if quiet { continue; }
        debug_overlay(snap, &plan, &dir.join(format!("{}.png", snap.name)));
        for f in s.faces.iter().filter(|f| !f.found) {
            debug_face(snap, &plan, f.face, f.facet, &dir.join(format!("{}-{}.png", snap.name, snap.faces[f.face].label.replace('/', "-"))));
        }
    }
    eprintln!("TOTAL found {f}/{c} = {:.1}%, spurious {sp}, corners median {:.2} mm", 100.0 * f as f64 / c as f64, median(&corners).unwrap_or(0.0) * 1e3);
}

/// For each missed face: which of its edges were found as segments in each view, matched as
/// candidates, friends, plane members, facet members.
#[test]
#[ignore]
fn diag_trace() {
    use handeye_vision::planner::geom;
    let dir = std::path::PathBuf::from("/tmp/pl/diag");
    std::fs::create_dir_all(&dir).unwrap();
    let snaps = snapshots(&dir, std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(10));
    let only = std::env::var("SCENE").ok();
    let mut planner = Planner::new(config_from_env());
    for snap in snaps.iter().filter(|s| only.as_ref().is_none_or(|o| &s.name == o)) {
        let geo = snap.geometry(0.5, 10.0);
        let plan = planner.plan(&snap.left.view(), &snap.right.view(), &geo);
        let s = score(snap, &plan);
        eprint!("{}", report(snap, &plan, &s));
        eprintln!("  bootstrap {:?}", plan.bootstrap);
        let ef = handeye_vision::planner::matching::EpipolarFrame::new(&plan.epipolar);
        for fs in s.faces.iter().filter(|f| !f.found) {
            let face = &snap.faces[fs.face];
            eprintln!("  face {}:", face.label);
            let n = face.polygon[0].len();
            for k in 0..n {
                let (a, b) = (face.polygon[0][k], face.polygon[0][(k + 1) % n]);
                let (a2, b2) = (face.polygon[1][k], face.polygon[1][(k + 1) % n]);
                let on = |segs: &[handeye_vision::planner::segments::Segment], a: [f64; 2], b: [f64; 2]| -> Vec<usize> {
                    segs.iter().enumerate().filter(|(_, s)| geom::point_segment_distance(s.p0, a, b) < 1.5 && geom::point_segment_distance(s.p1, a, b) < 1.5).map(|(i, _)| i).collect()
                };
                let ls = on(&plan.left_segments, a, b);
                let rs = on(&plan.right_segments, a2, b2);
                // Epipolar residual of the true corner correspondence under the final constraint.
                let res = ef.residual(a, a2);
                let mut info = Vec::new();
                for &l in &ls {
                    for &r in &rs {
                        let c = plan.candidates.find(l as u32, r as u32);
                        let planes: Vec<usize> = c.map(|c| plan.planes.iter().enumerate().filter(|(_, p)| p.members.contains(&(c as u32))).map(|(i, _)| i).collect()).unwrap_or_default();
                        let friends = c.map(|c| plan.friends.iter().filter(|f| f.a == c as u32 || f.b == c as u32).count()).unwrap_or(0);
                        let facets: Vec<usize> = c.map(|c| plan.facets.iter().enumerate().filter(|(_, f)| f.facet.members.contains(&(c as u32))).map(|(i, _)| i).collect()).unwrap_or_default();
                        info.push(format!("L{l}-R{r}: cand {:?} friends {friends} planes {planes:?} facets {facets:?}", c));
                    }
                }
                eprintln!("    edge {k} len {:.0}/{:.0} px, corner epi res {res:.2}: left segs {ls:?} right segs {rs:?} {}", geom::dist(a, b), geom::dist(a2, b2), info.join("; "));
            }
            // The face's true transfer (least squares through its projected corners) and the
            // line residuals under it of the segments on its edges.
            let mut fit = handeye_vision::planner::transfer::TransferFit::new(face.polygon[0][0]);
            for k in 0..n {
                fit.add_point(face.polygon[0][k], face.polygon[1][k], 1.0);
            }
            if let Some(t) = fit.solve() {
                let worst = (0..n).map(|k| geom::dist(t.apply(face.polygon[0][k]), face.polygon[1][k])).fold(0.0, f64::max);
                let mut res = Vec::new();
                for c in &plan.candidates.list {
                    let (l, r) = (&plan.left_segments[c.left as usize], &plan.right_segments[c.right as usize]);
                    let on = |s: &handeye_vision::planner::segments::Segment, p: &[[f64; 2]]| (0..p.len()).any(|k| geom::point_segment_distance(s.p0, p[k], p[(k + 1) % p.len()]) < 1.5 && geom::point_segment_distance(s.p1, p[k], p[(k + 1) % p.len()]) < 1.5);
                    if on(l, &face.polygon[0]) && on(r, &face.polygon[1]) {
                        let (rr, _) = handeye_vision::planner::transfer::line_residuals(&t, l, r);
                        res.push(format!("L{}R{} {:.2}/{:.2}", c.left, c.right, rr[0], rr[1]));
                    }
                }
                eprintln!("    true transfer: corner misfit {worst:.2} px; edge matches {}", res.join(", "));
            }
        }
    }
}

#[test]
#[ignore]
fn diag_epipolar() {
    use handeye_vision::affine::EpipolarConstraint;
    let dir = std::path::PathBuf::from("/tmp/pl/diag");
    let snaps = snapshots(&dir, std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(10));
    for snap in &snaps {
        let geo = snap.geometry(0.5, 10.0);
        let mut w = Vec::new();
        for f in &snap.faces {
            if f.visible_px[0] < 50.0 { continue; }
            for c in &f.corners_m {
                let l = snap.cameras[0].project(*c);
                let r = snap.cameras[1].project(*c);
                w.push([l[0], l[1], r[0], r[1]]);
            }
        }
        let e = EpipolarConstraint::fit(&w).unwrap();
        let ef = handeye_vision::planner::matching::EpipolarFrame::new(&e);
        let ef0 = handeye_vision::planner::matching::EpipolarFrame::new(&geo.epipolar);
        let mx = |ef: &handeye_vision::planner::matching::EpipolarFrame| w.iter().map(|w| ef.residual([w[0], w[1]], [w[2], w[3]]).abs()).fold(0.0, f64::max);
        let mean = |ef: &handeye_vision::planner::matching::EpipolarFrame| w.iter().map(|w| ef.residual([w[0], w[1]], [w[2], w[3]])).sum::<f64>() / w.len() as f64;
        eprintln!("{:<14} oracle fit max {:.2} px; cage constraint max {:.2} mean {:.2} px", snap.name, mx(&ef), mx(&ef0), mean(&ef0));
    }
}

/// Details of one face's segments, junctions and candidates (FACE=label, SCENE=name).
#[test]
#[ignore]
fn diag_face() {
    use handeye_vision::planner::geom;
    let dir = std::path::PathBuf::from("/tmp/pl/diag");
    let snaps = snapshots(&dir, std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(40));
    let scene = std::env::var("SCENE").unwrap();
    let label = std::env::var("FACE").unwrap();
    let mut planner = Planner::new(config_from_env());
    let snap = snaps.iter().find(|s| s.name == scene).unwrap();
    let plan = planner.plan(&snap.left.view(), &snap.right.view(), &snap.geometry(0.5, 10.0));
    let ef = handeye_vision::planner::matching::EpipolarFrame::new(&plan.epipolar);
    let face = snap.faces.iter().find(|f| f.label == label).unwrap();
    for v in 0..2 {
        let segs = if v == 0 { &plan.left_segments } else { &plan.right_segments };
        let rel = if v == 0 { &plan.left_relations } else { &plan.right_relations };
        let p = &face.polygon[v];
        eprintln!("view {v} polygon {:?}", p.iter().map(|q| [q[0].round(), q[1].round()]).collect::<Vec<_>>());
        let near: Vec<usize> = segs.iter().enumerate().filter(|(_, s)| geom::contains(p, s.midpoint(), 3.0)).map(|(i, _)| i).collect();
        for &i in &near {
            let s = &segs[i];
            let js: Vec<String> = rel.junctions_of(i as u32).iter().map(|&j| { let j = &rel.junctions[j as usize]; format!("{}{:?}@({:.0},{:.0})", j.other(i as u32).0, j.kind, j.point[0], j.point[1]) }).collect();
            let eta = if v == 0 { (ef.eta_left(s.p0), ef.eta_left(s.p1)) } else { (ef.eta_right(s.p0), ef.eta_right(s.p1)) };
            eprintln!("  seg {i}: ({:.1},{:.1})-({:.1},{:.1}) len {:.0} rms {:.2} contrast {:.1} eta {:.1}..{:.1} junctions {js:?}", s.p0[0], s.p0[1], s.p1[0], s.p1[1], s.length(), s.rms_px, s.contrast, eta.0, eta.1);
            if v == 0 {
                for c in plan.candidates.of_left(i as u32) {
                    let cd = &plan.candidates.list[c];
                    let planes: Vec<usize> = plan.planes.iter().enumerate().filter(|(_, p)| p.members.contains(&(c as u32))).map(|(k, _)| k).collect();
                    let fr: Vec<String> = plan.friends.iter().filter(|f| f.a == c as u32 || f.b == c as u32).map(|f| { let o = if f.a == c as u32 { f.b } else { f.a }; let oc = &plan.candidates.list[o as usize]; format!("L{}R{}", oc.left, oc.right) }).collect();
                    eprintln!("      cand {c}: R{} overlap {:.1} along {} planes {planes:?} friends {fr:?}", cd.right, cd.overlap_px, cd.along_epipolar);
                }
            }
        }
    }
    for (k, p) in plan.planes.iter().enumerate() {
        let ls: Vec<String> = p.members.iter().map(|&m| { let c = &plan.candidates.list[m as usize]; format!("L{}R{}", c.left, c.right) }).collect();
        eprintln!("plane {k}: rms {:.2} support {:.0} members {ls:?}", p.rms_px, p.support_px);
    }
}

#[test]
#[ignore]
fn diag_edges_at() {
    use handeye_vision::planner::edges::{EdgeConfig, EdgeDetector};
    use handeye_vision::planner::segments::{SegmentConfig, SegmentDetector};
    let scene = std::env::var("SCENE").unwrap();
    let xy: Vec<f64> = std::env::var("AT").unwrap().split(',').map(|v| v.parse().unwrap()).collect();
    let view: usize = std::env::var("VIEW").ok().and_then(|v| v.parse().ok()).unwrap_or(0);
    let img = load_gray(&std::path::Path::new("/tmp/pl/diag").join(&scene).join(if view == 0 { "left.png" } else { "right.png" }));
    let mut e = EdgeDetector::new(EdgeConfig::default());
    let map = e.detect(&img.view());
    for p in map.points.iter().filter(|p| (p.x as f64 - xy[0]).abs() < 6.0 && (p.y as f64 - xy[1]).abs() < 6.0) {
        eprintln!("edge ({:.2},{:.2}) g ({:.1},{:.1})", p.x, p.y, p.gx, p.gy);
    }
    let mut s = SegmentDetector::new(SegmentConfig::default());
    for seg in s.detect(map).iter().filter(|s| handeye_vision::planner::geom::point_segment_distance([xy[0], xy[1]], s.p0, s.p1) < 15.0) {
        eprintln!("seg {:?}", seg);
    }
}

#[test]
#[ignore]
fn diag_final_epipolar() {
    let dir = std::path::PathBuf::from("/tmp/pl/diag");
    let snaps = snapshots(&dir, std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(10));
    let mut planner = Planner::new(PlannerConfig::default());
    for snap in &snaps {
        let plan = planner.plan(&snap.left.view(), &snap.right.view(), &snap.geometry(0.5, 10.0));
        let ef = handeye_vision::planner::matching::EpipolarFrame::with_correction(&plan.epipolar, plan.epipolar_correction);
        let ef0 = snap.geometry(0.5, 10.0).frame();
        let (mut r, mut r0) = (Vec::new(), Vec::new());
        for f in &snap.faces {
            if f.visible_px[0] < 50.0 { continue; }
            for c in &f.corners_m {
                let (l, rr) = (snap.cameras[0].project(*c), snap.cameras[1].project(*c));
                r.push(ef.residual(l, rr).abs());
                r0.push(ef0.residual(l, rr).abs());
            }
        }
        let mx = |v: &[f64]| v.iter().cloned().fold(0.0, f64::max);
        eprintln!("{:<14} final |res| median {:.2} max {:.2}; cage median {:.2} max {:.2}; {:?} corr {:?}", snap.name, median(&r).unwrap(), mx(&r), median(&r0).unwrap(), mx(&r0), plan.bootstrap, plan.epipolar_correction.map(|c| c.coef));
    }
}

/// Grey-level step across every edge of each missed face, per view (inside minus outside,
/// sampled 2.5 px either side of the middle 60% of the edge).
#[test]
#[ignore]
fn diag_contrast() {
    use handeye_vision::planner::geom;
    let dir = std::path::PathBuf::from("/tmp/pl/diag");
    let snaps = snapshots(&dir, std::env::var("N").ok().and_then(|v| v.parse().ok()).unwrap_or(10));
    let mut planner = Planner::new(PlannerConfig::default());
    for snap in &snaps {
        let plan = planner.plan(&snap.left.view(), &snap.right.view(), &snap.geometry(0.5, 10.0));
        let s = score(snap, &plan);
        for fs in s.faces.iter().filter(|f| !f.found) {
            let face = &snap.faces[fs.face];
            let mut line = format!("{} {}:", snap.name, face.label);
            for v in 0..2 {
                let img = if v == 0 { &snap.left } else { &snap.right };
                let p = &face.polygon[v];
                let c = p.iter().fold([0.0, 0.0], |a, q| [a[0] + q[0] / p.len() as f64, a[1] + q[1] / p.len() as f64]);
                let mut steps = Vec::new();
                for k in 0..p.len() {
                    let (a, b) = (p[k], p[(k + 1) % p.len()]);
                    let d = geom::sub(b, a);
                    let len = geom::norm(d);
                    let mut n = [-d[1] / len, d[0] / len];
                    if geom::dot(n, geom::sub(c, a)) < 0.0 { n = [-n[0], -n[1]]; }
                    let (mut si, mut so, mut cnt) = (0.0, 0.0, 0.0);
                    for i in 0..=20 {
                        let t = 0.2 + 0.6 * i as f64 / 20.0;
                        let q = geom::add(a, geom::scale(d, t));
                        let (pi, po) = (geom::add(q, geom::scale(n, 2.5)), geom::sub(q, geom::scale(n, 2.5)));
                        let g = |x: [f64; 2]| img.get((x[0] as usize).min(img.width - 1), (x[1] as usize).min(img.height - 1)) as f64;
                        si += g(pi); so += g(po); cnt += 1.0;
                    }
                    steps.push(format!("{:.0}({:.0}px)", (si - so) / cnt, len));
                }
                line += &format!("  v{v}: {}", steps.join(" "));
            }
            eprintln!("{line}");
        }
    }
}
