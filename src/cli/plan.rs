//! `handeye plan`: planar facets and matched edges from one stereo pair.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_vision::affine::AffineStereo;
use handeye_vision::image::ImageBuf;
use handeye_vision::planner::segments::Segment;
use handeye_vision::planner::{Plan, Planner, PlannerConfig, Stage, EpipolarGeometry};
use nalgebra::{Matrix4x3, Vector3, Vector4};
use serde_json::{json, Value};

// An explicit path: `tests/fuzz_geometry.rs` includes this file with `#[path]`, where a bare
// `mod replay;` would be looked for beside it (src/cli/replay.rs) instead of under plan/.
#[path = "plan/replay.rs"]
mod replay;

const PLAN_HELP: &str = "\
Finds planar facets in a stereo pair (thesis chapter 5): sub-pixel edges, line segments,
junctions, matches under a weak epipolar constraint, coplanar groups (left-to-right affine
transfers), facets with concavity-bridging boundaries, and their 3-D corners.

The stereo geometry comes either from a saved affine stereo model (--calib) or from point
correspondences (--points), such as the simulator snapshot's cage.json: with robot
coordinates the affine model is fitted and facet corners come out in robot coordinates
(metres); without them only the epipolar constraint and the disparity limits are fitted.
The epipolar constraint is then refined from matched junctions (--bootstrap-rounds).

Robot coordinates: from >= 6 calibration points with robot coordinates, not all on one
plane (the simulator's eight-point cage), each camera's full 3x4 projection is fitted too
(direct linear transform) and corners are triangulated through it: ~1 mm at 1.6 m. With
--calib, or fewer points, they come from the affine model, whose weak-perspective error is
several millimetres at that distance (5-9 mm on the simulator's scenes).

Image coordinates are continuous: pixel (i, j) covers [i, i+1) x [j, j+1).

Output: a summary per facet (polygon in each view, transfer, corners), or with --json one
object: `facets` (each with `left` and `right` polygons as [[u, v], ...], `transfer`,
`corners_cyclopean_disparity_px`, and `corners_robot_m` when calibrated), `matches`
(segment pairs, how each was reconstructed, `ends_robot_m` when calibrated), `timings_ms`
(one key per stage and `total`), `geometry` (`calibrated`, `pinhole_cameras`, the epipolar
constraint) and `bootstrap`.

The calibration file (--calib) is the affine stereo model w = M X + c as the daemon saves it
(the same object may also sit under a \"model\" key):
  {
    \"m\": [[au, bu, cu], [av, bv, cv], [au2, bu2, cu2], [av2, bv2, cv2]],
                        rows u, v (left) and u', v' (right) as linear functions of the robot
                        point (x, y, z): pixels per metre
    \"c\": [u0, v0, u0', v0'],      pixels: the image of the robot origin
    \"disparity_range_px\": [lo, hi], u' - u over the calibration points, pixels
    \"residual_rms_px\": 0.4         optional: RMS residual of the calibration fit
  }

Replay (--run DIR): the daemon's whole plan, not only the planner's facets: the grasp scene,
the faces hypothesised below top edges, the rear edges looked for in the images, the grasp
rules and the chosen site, rerun on the pair a run saved (DIR/plan_left.png, plan_right.png)
with its configuration (DIR/daemon.toml) and the geometry in DIR/plan.json (model, cage,
lever, indicated point, gripper mask). DIR is a `handeye run --out DIR` report or a batch's
DIR/<scenario>/seed-<S>. Prints the facets, rear edges, rejections and the chosen site
(--json: the plan.json the daemon would write); --overlay draws the plan as the report does.

Examples:
  handeye batch scenarios/clutter3.toml --first-seed 23 --seeds 1 --disturb --out out/b
  handeye plan --run out/b/clutter3/seed-23
  handeye plan --run out/b/clutter3/seed-23 --json --overlay replay.png
  handeye snapshot scenarios/pick_cube.toml --out snap
  handeye plan --left snap/left.png --right snap/right.png --points snap/cage.json --overlay plan.png
  handeye plan --left l.png --right r.png --calib calib.json --json > plan.json";

/// Arguments of `handeye plan` (see `PLAN_HELP`).
#[derive(Args, Debug)]
#[command(after_long_help = PLAN_HELP)]
pub struct PlanArgs {
    /// Left view, PNG (any bit depth; converted to 8-bit grey).
    #[arg(long, value_name = "PNG", required_unless_present = "run")]
    pub left: Option<PathBuf>,
    /// Right view, PNG, same size as the left.
    #[arg(long, value_name = "PNG", required_unless_present = "run")]
    pub right: Option<PathBuf>,
    /// Replay the daemon's plan of a run's report folder (see "Replay" below).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["left", "right", "calib", "points"])]
    pub run: Option<PathBuf>,
    /// Affine stereo model as saved by the daemon: JSON object with `m` (4 rows of 3:
    /// pixels per metre for u, v, u', v'), `c` (4 numbers, pixels), `disparity_range_px`
    /// ([lo, hi] pixels) and optionally `residual_rms_px` (see the format below).
    #[arg(long, value_name = "JSON", conflicts_with = "points", required_unless_present_any = ["points", "run"])]
    pub calib: Option<PathBuf>,
    /// Point correspondences: the simulator snapshot's cage.json as written (`points_m`,
    /// `left_px`, `right_px`: index-aligned lists; its pixel centres are at integers, so 0.5 px
    /// is added to match the planner's convention), or a JSON list (or an object with a
    /// `points` or `cage` list) of objects with `left` and `right` ([u, v] pixels, pixel (i, j)
    /// covering [i, i+1) x [j, j+1)) and optionally `robot_m` ([x, y, z] metres). At least 4
    /// points; robot coordinates, when given for all, must not be coplanar.
    #[arg(long, value_name = "JSON")]
    pub points: Option<PathBuf>,
    /// Print one JSON object (facets, matches, every segment found in each view, timings) instead of a summary.
    #[arg(long)]
    pub json: bool,
    /// Write both views side by side with the facets drawn in distinct colours (PNG).
    #[arg(long, value_name = "PNG")]
    pub overlay: Option<PathBuf>,
    /// Tolerance of the weak epipolar constraint, pixels: how far a match may lie off its
    /// epipolar line.
    #[arg(long, default_value_t = 3.0, value_name = "PX")]
    pub epipolar_tol_px: f64,
    /// Widen the calibration's disparity range by this fraction of it on each side (objects
    /// lie outside the calibration cage).
    #[arg(long, default_value_t = 0.5, value_name = "FRACTION")]
    pub disparity_margin: f64,
    /// ... plus this many pixels on each side.
    #[arg(long, default_value_t = 10.0, value_name = "PX")]
    pub disparity_margin_px: f64,
    /// Rounds of re-fitting the epipolar constraint from matched junctions (0: trust it).
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub bootstrap_rounds: usize,
}

pub fn run(args: PlanArgs) -> Result<()> {
    if let Some(dir) = &args.run {
        let out = replay::replay(dir)?;
        if let Some(path) = &args.overlay {
            let img = handeye_daemon::report::plan_overlay(&out);
            img.save(path).with_context(|| format!("cannot write {}", path.display()))?;
        }
        let text = if args.json { serde_json::to_string_pretty(&out.summary)? + "\n" } else { replay::replay_summary(&out) };
        return write_stdout(&text);
    }
    let (Some(left_path), Some(right_path)) = (&args.left, &args.right) else { bail!("give --left and --right, or --run DIR") };
    let left = load_gray(left_path)?;
    let right = load_gray(right_path)?;
    if (left.width, left.height) != (right.width, right.height) {
        bail!(
            "{} is {}x{} but {} is {}x{}: the views must be the same size",
            left_path.display(),
            left.width,
            left.height,
            right_path.display(),
            right.width,
            right.height
        );
    }
    let (geo, source) = match (&args.calib, &args.points) {
        (Some(c), _) => (EpipolarGeometry::from_model(load_calib(c)?, args.disparity_margin, args.disparity_margin_px), "calibration"),
        (None, Some(p)) => geometry_from_points(&load_points(p)?, args.disparity_margin, args.disparity_margin_px, p)?,
        (None, None) => bail!("give --calib or --points"),
    };
    let mut config = PlannerConfig::default();
    config.matching.epipolar_tol_px = args.epipolar_tol_px;
    config.bootstrap_rounds = args.bootstrap_rounds;
    let mut planner = Planner::new(config);
    let (plan, timings) = timed_plan(&mut planner, &left, &right, &geo);
    if let Some(out) = &args.overlay {
        write_overlay(out, &left, &right, &plan)?;
    }
    let mut text = if args.json {
        serde_json::to_string_pretty(&plan_json(&plan, &timings, &geo, source))? + "\n"
    } else {
        summary(&plan, &timings, source)
    };
    if let (false, Some(out)) = (args.json, &args.overlay) {
        text += &format!("overlay written to {}\n", out.display());
    }
    write_stdout(&text)
}

fn write_stdout(text: &str) -> Result<()> {
    // A closed pipe (`| head`) ends the output quietly rather than with a panic.
    use std::io::Write;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(()),
    }
}

/// Runs the planner, returning per-stage times (milliseconds, stage name → time) and `total`.
pub fn timed_plan(planner: &mut Planner, left: &ImageBuf, right: &ImageBuf, geo: &EpipolarGeometry) -> (Plan, BTreeMap<&'static str, f64>) {
    let mut timings: BTreeMap<&'static str, f64> = Stage::ALL.iter().map(|s| (s.name(), 0.0)).collect();
    let start = Instant::now();
    let mut last = start;
    let plan = planner.plan_with(&left.view(), &right.view(), geo, &mut |stage| {
        let now = Instant::now();
        *timings.entry(stage.name()).or_insert(0.0) += (now - last).as_secs_f64() * 1e3;
        last = now;
    });
    timings.insert("total", start.elapsed().as_secs_f64() * 1e3);
    (plan, timings)
}

/// Loads a PNG as 8-bit grey.
pub fn load_gray(path: &Path) -> Result<ImageBuf> {
    let img = super::png::read_gray(path)?;
    let (w, h) = img.dimensions();
    ImageBuf::from_vec(img.into_raw(), w as usize, h as usize).with_context(|| format!("image {} is empty", path.display()))
}

fn read_json(path: &Path) -> Result<Value> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    serde_json::from_str(&text).with_context(|| format!("{} is not valid JSON", path.display()))
}

fn numbers(v: &Value, n: usize, path: &Path, field: &str) -> Result<Vec<f64>> {
    let arr = v.as_array().with_context(|| format!("{}: field `{field}` must be a list of {n} numbers", path.display()))?;
    if arr.len() != n {
        bail!("{}: field `{field}` has {} numbers, expected {n}", path.display(), arr.len());
    }
    arr.iter()
        .enumerate()
        .map(|(i, x)| {
            x.as_f64().filter(|f| f.is_finite()).with_context(|| format!("{}: field `{field}[{i}]` is not a finite number", path.display()))
        })
        .collect()
}

/// Loads an affine stereo model (see `--calib`).
pub fn load_calib(path: &Path) -> Result<AffineStereo> {
    let v = read_json(path)?;
    let v = v.get("model").unwrap_or(&v);
    let rows = v.get("m").with_context(|| format!("{}: missing field `m` (4 rows of 3 numbers)", path.display()))?;
    let rows = rows.as_array().with_context(|| format!("{}: field `m` must be 4 rows of 3 numbers", path.display()))?;
    if rows.len() != 4 {
        bail!("{}: field `m` has {} rows, expected 4", path.display(), rows.len());
    }
    let mut m = Matrix4x3::zeros();
    for (r, row) in rows.iter().enumerate() {
        let row = numbers(row, 3, path, &format!("m[{r}]"))?;
        for c in 0..3 {
            m[(r, c)] = row[c];
        }
    }
    let c = numbers(v.get("c").with_context(|| format!("{}: missing field `c` (4 numbers)", path.display()))?, 4, path, "c")?;
    let c = Vector4::new(c[0], c[1], c[2], c[3]);
    let residual_rms_px = v.get("residual_rms_px").and_then(Value::as_f64).unwrap_or(0.0);
    let disparity_range_px = match v.get("disparity_range_px") {
        Some(d) => {
            let d = numbers(d, 2, path, "disparity_range_px")?;
            [d[0].min(d[1]), d[0].max(d[1])]
        }
        None => bail!("{}: missing field `disparity_range_px` ([lo, hi] pixels of u' − u over the calibration)", path.display()),
    };
    let model = AffineStereo { m, c, residual_rms_px, disparity_range_px };
    if (model.m.transpose() * model.m).try_inverse().is_none() {
        bail!("{}: field `m` is singular (the cameras see no depth)", path.display());
    }
    Ok(model)
}

/// One correspondence: `(u, v, u', v')` and the robot point if known.
pub type Correspondence = ([f64; 4], Option<[f64; 3]>);

/// The simulator's pixel coordinates (`cage.json`, `truth.json`) put pixel centres at integers;
/// the planner's put pixel `(i, j)` over `[i, i+1) x [j, j+1)`, centre at `(i + 0.5, j + 0.5)`.
pub const SIMULATOR_TO_PLANNER_PX: f64 = 0.5;

/// Loads correspondences (see `--points`): a list of point objects, an object with such a list
/// under `points` or `cage`, or the simulator's `cage.json` (parallel lists `points_m`,
/// `left_px`, `right_px`, pixel centres at integers: shifted by [`SIMULATOR_TO_PLANNER_PX`]).
pub fn load_points(path: &Path) -> Result<Vec<Correspondence>> {
    let v = read_json(path)?;
    let out = if v.get("left_px").is_some_and(Value::is_array) && v.get("right_px").is_some_and(Value::is_array) {
        load_simulator_cage(&v, path)?
    } else {
        load_point_list(&v, path)?
    };
    if out.len() < 4 {
        bail!("{}: {} correspondences, need at least 4", path.display(), out.len());
    }
    Ok(out)
}

/// The simulator's `cage.json`: `points_m` (optional), `left_px`, `right_px`, index-aligned.
fn load_simulator_cage(v: &Value, path: &Path) -> Result<Vec<Correspondence>> {
    let list = |field: &str| -> Result<Option<&Vec<Value>>> {
        match v.get(field) {
            None => Ok(None),
            Some(x) => x.as_array().map(Some).with_context(|| format!("{}: field `{field}` must be a list", path.display())),
        }
    };
    let empty = Vec::new();
    let (left, right) = (list("left_px")?.unwrap_or(&empty), list("right_px")?.unwrap_or(&empty));
    let robot = list("points_m")?;
    if left.len() != right.len() {
        bail!("{}: `left_px` has {} points but `right_px` has {}", path.display(), left.len(), right.len());
    }
    if let Some(r) = robot
        && r.len() != left.len()
    {
        bail!("{}: `points_m` has {} points but `left_px` has {}", path.display(), r.len(), left.len());
    }
    let s = SIMULATOR_TO_PLANNER_PX;
    let mut out = Vec::with_capacity(left.len());
    for i in 0..left.len() {
        let l = numbers(&left[i], 2, path, &format!("left_px[{i}]"))?;
        let r = numbers(&right[i], 2, path, &format!("right_px[{i}]"))?;
        let x = match robot {
            Some(rb) => {
                let x = numbers(&rb[i], 3, path, &format!("points_m[{i}]"))?;
                Some([x[0], x[1], x[2]])
            }
            None => None,
        };
        out.push(([l[0] + s, l[1] + s, r[0] + s, r[1] + s], x));
    }
    Ok(out)
}

/// A list of `{left, right, robot_m?}` objects (or an object holding one as `points`/`cage`).
fn load_point_list(v: &Value, path: &Path) -> Result<Vec<Correspondence>> {
    let list = if v.is_array() { v } else { v.get("points").or_else(|| v.get("cage")).with_context(|| format!("{}: expected a list of points, an object with a `points` or `cage` list, or the simulator's cage.json (`points_m`, `left_px`, `right_px`)", path.display()))? };
    let list = list.as_array().with_context(|| format!("{}: `points` must be a list", path.display()))?;
    let mut out = Vec::with_capacity(list.len());
    for (i, p) in list.iter().enumerate() {
        let get = |names: &[&str]| names.iter().find_map(|n| p.get(*n));
        let l = get(&["left", "left_px"]).with_context(|| format!("{}: point {i} has no `left` ([u, v])", path.display()))?;
        let r = get(&["right", "right_px"]).with_context(|| format!("{}: point {i} has no `right` ([u, v])", path.display()))?;
        let l = numbers(l, 2, path, &format!("points[{i}].left"))?;
        let r = numbers(r, 2, path, &format!("points[{i}].right"))?;
        let robot = match get(&["robot_m", "robot", "xyz_m"]) {
            Some(x) => {
                let x = numbers(x, 3, path, &format!("points[{i}].robot_m"))?;
                Some([x[0], x[1], x[2]])
            }
            None => None,
        };
        out.push(([l[0], l[1], r[0], r[1]], robot));
    }
    Ok(out)
}

/// Stereo geometry from correspondences: the affine model (and, from >= 6 non-coplanar
/// points, the pinhole cameras) when all have robot coordinates, else the epipolar
/// constraint alone.
pub fn geometry_from_points(points: &[Correspondence], margin: f64, margin_px: f64, path: &Path) -> Result<(EpipolarGeometry, &'static str)> {
    let image: Vec<[f64; 4]> = points.iter().map(|p| p.0).collect();
    if points.iter().all(|p| p.1.is_some()) {
        let robot: Vec<Vector3<f64>> = points.iter().filter_map(|p| p.1).map(Vector3::from).collect();
        let geo = EpipolarGeometry::from_calibration_points(&robot, &image, margin, margin_px).with_context(|| format!("{}: cannot fit the affine stereo model", path.display()))?;
        let source = if geo.projective.is_some() {
            "points with robot coordinates (affine model; pinhole cameras for the robot coordinates)"
        } else {
            "points with robot coordinates (affine model; too few or coplanar points for pinhole cameras)"
        };
        Ok((geo, source))
    } else {
        let geo = EpipolarGeometry::from_correspondences(&image, margin, margin_px).with_context(|| format!("{}: cannot fit the epipolar constraint", path.display()))?;
        Ok((geo, "image correspondences (epipolar constraint only)"))
    }
}

fn r3(x: f64) -> f64 {
    (x * 1000.0).round() / 1000.0
}

fn pts(p: &[[f64; 2]]) -> Value {
    Value::from(p.iter().map(|q| vec![r3(q[0]), r3(q[1])]).collect::<Vec<_>>())
}

/// One view's segments: ends (as in `matches`) and mean contrast.
fn segment_lines(segments: &[Segment]) -> Value {
    segments.iter().map(|s| json!({ "ends": pts(&[s.p0, s.p1]), "contrast": (s.contrast * 10.0).round() / 10.0 })).collect()
}

fn pts3(p: &[[f64; 3]], scale: f64) -> Value {
    Value::from(p.iter().map(|q| vec![(q[0] * scale).round() / scale, (q[1] * scale).round() / scale, (q[2] * scale).round() / scale]).collect::<Vec<_>>())
}

/// The `--json` object.
pub fn plan_json(plan: &Plan, timings: &BTreeMap<&'static str, f64>, geo: &EpipolarGeometry, source: &str) -> Value {
    let facets: Vec<Value> = plan
        .facets
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let t = &f.facet.transfer;
            let members: Vec<usize> = plan.matches.iter().enumerate().filter(|(_, m)| m.facets.contains(&(i as u32))).map(|(k, _)| k).collect();
            let mut o = json!({
                "id": i,
                "plane": f.facet.plane,
                "component": f.facet.component,
                "left": pts(&f.facet.left),
                "right": pts(&f.facet.right),
                "transfer": { "a": [[t.a[0][0], t.a[0][1]], [t.a[1][0], t.a[1][1]]], "b": [t.b[0], t.b[1]] },
                "matches": members,
                "corners_cyclopean_disparity_px": pts3(&f.corners_cyclopean_disparity, 1e3),
            });
            if let Some(c) = &f.corners_robot_m {
                o["corners_robot_m"] = pts3(c, 1e6);
            }
            o
        })
        .collect();
    let matches: Vec<Value> = plan
        .matches
        .iter()
        .map(|m| {
            let (l, r) = (&plan.left_segments[m.left as usize], &plan.right_segments[m.right as usize]);
            let mut o = json!({
                "left": pts(&[l.p0, l.p1]),
                "right": pts(&[r.p0, r.p1]),
                "facets": m.facets,
                "planes": m.planes,
            });
            if let Some(rec) = &m.reconstruction {
                o["method"] = json!(rec.method.name());
                o["ends_left"] = pts(&rec.left);
                o["ends_right"] = pts(&rec.right);
                o["ends_cyclopean_disparity_px"] = pts3(&rec.cyclopean_disparity, 1e3);
                if let Some(x) = &rec.robot_m {
                    o["ends_robot_m"] = pts3(x, 1e6);
                }
            } else {
                o["method"] = json!("unreconstructed");
            }
            o
        })
        .collect();
    let timings_ms: serde_json::Map<String, Value> = timings.iter().map(|(k, v)| (k.to_string(), json!((v * 1e3).round() / 1e3))).collect();
    let e = &plan.epipolar;
    json!({
        "facets": facets,
        "matches": matches,
        "timings_ms": timings_ms,
        "segments": { "left": plan.left_segments.len(), "right": plan.right_segments.len() },
        "segment_lines": { "left": segment_lines(&plan.left_segments), "right": segment_lines(&plan.right_segments) },
        "candidates": plan.candidates.list.len(),
        "planes": plan.planes.len(),
        "geometry": {
            "source": source,
            "calibrated": geo.model.is_some(),
            "pinhole_cameras": geo.projective.is_some(),
            "disparity_px": geo.disparity_px,
            "epipolar_n": [e.n[0], e.n[1], e.n[2], e.n[3]],
            "epipolar_n0": e.n0,
        },
        "bootstrap": plan.bootstrap.map(|b| json!({ "points": b.points, "rms_before_px": b.rms_before_px, "rms_after_px": b.rms_after_px, "rematched": b.rematched })),
    })
}

fn summary(plan: &Plan, timings: &BTreeMap<&'static str, f64>, source: &str) -> String {
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(s, "geometry: {source}");
    let _ = writeln!(s, 
        "segments: {} left, {} right; candidates {}; friends {}; planes {}; matches {}; facets {}",
        plan.left_segments.len(),
        plan.right_segments.len(),
        plan.candidates.list.len(),
        plan.friends.len(),
        plan.planes.len(),
        plan.matches.len(),
        plan.facets.len()
    );
    if let Some(b) = plan.bootstrap {
        let _ = writeln!(s, "epipolar bootstrap: {} junctions, rms {:.2} → {:.2} px{}", b.points, b.rms_before_px, b.rms_after_px, if b.rematched { ", re-matched" } else { "" });
    }
    for (i, f) in plan.facets.iter().enumerate() {
        let poly = |p: &[[f64; 2]]| p.iter().map(|q| format!("({:.1}, {:.1})", q[0], q[1])).collect::<Vec<_>>().join(" ");
        let _ = writeln!(s, "facet {i} (plane {}, object {}, {} edges)", f.facet.plane, f.facet.component, f.facet.members.len());
        let _ = writeln!(s, "  left:  {}", poly(&f.facet.left));
        let _ = writeln!(s, "  right: {}", poly(&f.facet.right));
        if let Some(c) = &f.corners_robot_m {
            let _ = writeln!(s, "  corners (robot, mm): {}", c.iter().map(|x| format!("({:.1}, {:.1}, {:.1})", x[0] * 1e3, x[1] * 1e3, x[2] * 1e3)).collect::<Vec<_>>().join(" "));
        }
    }
    let reconstructed = plan.matches.iter().filter(|m| m.reconstruction.is_some()).count();
    let _ = writeln!(s, "matched segments: {} ({} reconstructed)", plan.matches.len(), reconstructed);
    let t: Vec<String> = timings.iter().map(|(k, v)| format!("{k} {v:.2}")).collect();
    let _ = writeln!(s, "timings (ms): {}", t.join(", "));
    s
}

/// Distinct, saturated colours for facets.
const PALETTE: [[u8; 3]; 10] = [
    [230, 25, 75],
    [60, 180, 75],
    [0, 130, 200],
    [245, 130, 48],
    [145, 30, 180],
    [70, 240, 240],
    [240, 50, 230],
    [210, 245, 60],
    [255, 225, 25],
    [0, 128, 128],
];

/// Draws a line of width ~2 px.
fn draw_line(img: &mut image::RgbImage, a: [f64; 2], b: [f64; 2], dx: u32, col: [u8; 3], thick: bool) {
    let n = (((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt() * 2.0).ceil() as usize + 1;
    for k in 0..=n {
        let t = k as f64 / n as f64;
        let (x, y) = (a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]));
        let offsets: &[(f64, f64)] = if thick { &[(0.0, 0.0), (0.5, 0.0), (0.0, 0.5), (-0.5, 0.0), (0.0, -0.5)] } else { &[(0.0, 0.0)] };
        for (ox, oy) in offsets {
            let (px, py) = ((x + ox).floor(), (y + oy).floor());
            if px >= 0.0 && py >= 0.0 && (px as u32) < img.width() / 2 && (py as u32) < img.height() {
                img.put_pixel(px as u32 + dx, py as u32, image::Rgb(col));
            }
        }
    }
}

/// Writes both views side by side, matched segments in grey-white, facets in colour.
pub fn write_overlay(path: &Path, left: &ImageBuf, right: &ImageBuf, plan: &Plan) -> Result<()> {
    let (w, h) = (left.width as u32, left.height as u32);
    let mut img = image::RgbImage::new(2 * w, h);
    for (view, dx) in [(left, 0), (right, w)] {
        for y in 0..h {
            for x in 0..w {
                let g = view.get(x as usize, y as usize) / 2 + 30;
                img.put_pixel(x + dx, y, image::Rgb([g, g, g]));
            }
        }
    }
    for m in &plan.matches {
        let (l, r) = (&plan.left_segments[m.left as usize], &plan.right_segments[m.right as usize]);
        draw_line(&mut img, l.p0, l.p1, 0, [200, 200, 200], false);
        draw_line(&mut img, r.p0, r.p1, w, [200, 200, 200], false);
    }
    for (i, f) in plan.facets.iter().enumerate() {
        let col = PALETTE[i % PALETTE.len()];
        for (poly, dx) in [(&f.facet.left, 0), (&f.facet.right, w)] {
            for k in 0..poly.len() {
                draw_line(&mut img, poly[k], poly[(k + 1) % poly.len()], dx, col, true);
            }
        }
    }
    img.save(path).with_context(|| format!("cannot write overlay {}", path.display()))
}
