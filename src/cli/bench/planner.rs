//! `handeye bench planner`: planner time per stage on a 640x480 stereo pair.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_vision::affine::AffineStereo;
use handeye_vision::image::ImageBuf;
use handeye_vision::planner::synth::SynthScene;
use handeye_vision::planner::{Planner, PlannerConfig, Stage, EpipolarGeometry};
use nalgebra::Vector3;
use serde_json::{json, Value};

use crate::cli::plan::{geometry_from_points, load_gray, load_points, timed_plan};

const BENCH_HELP: &str = "\
Times the planner, stage by stage, on one 640x480 stereo pair and prints the medians (only
release builds give meaningful numbers). Budgets: 100 ms per pair, 2.5 ms for edges +
segments per image.

By default the pair is frames 0 and 40 of the real visp-cube sequence (a textured cube, about
200 segments per view), with the epipolar constraint fitted from face corners annotated by
eye in both frames; without the data set, or with --synthetic, a rendered scene of five
boxes seen by two affine cameras; with --snapshot, a simulator snapshot folder (left.png,
right.png and cage.json, as `handeye snapshot` writes them), calibrated from its cage as
`handeye plan --points cage.json` does.

Examples:
  cargo build --release && target/release/handeye bench planner --iterations 50 --json
  target/release/handeye snapshot scenarios/clutter3.toml --out /tmp/clutter3
  target/release/handeye bench planner --snapshot /tmp/clutter3 --iterations 200";

/// Arguments of `handeye bench planner` (see `BENCH_HELP`).
#[derive(Args, Debug)]
#[command(after_long_help = BENCH_HELP)]
pub struct PlannerArgs {
    /// The visp-cube folder (image0000.png ... and faces-frame0.json) [default:
    /// $HANDEYE_DATA/visp-cube, HANDEYE_DATA defaulting to ../shared/data].
    #[arg(long, default_value_os_t = super::visp_cube_dir(), hide_default_value = true, value_name = "DIR")]
    pub data: PathBuf,
    /// Use the rendered five-box scene even when the real pair is available.
    #[arg(long, conflicts_with = "snapshot")]
    pub synthetic: bool,
    /// Time a simulator snapshot instead: a folder with left.png, right.png and cage.json.
    #[arg(long, value_name = "DIR")]
    pub snapshot: Option<PathBuf>,
    /// Timed runs (after two warm-up runs); the median is reported.
    #[arg(long, default_value_t = 30, value_name = "N")]
    pub iterations: usize,
    /// Print one JSON object (`total_ms_p50`, `total_ms_min`, per-stage medians, segment
    /// counts).
    #[arg(long)]
    pub json: bool,
}

/// Face corners of the visp-cube frames, as annotated (`faces-frame0.json` in the data set,
/// the frame-40 file in `tests/data`).
const FRAME40: &str = include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/visp-cube-faces-frame40.json"));

/// Corresponding face corners `(u, v, u', v')` of two annotation files with the same faces in
/// the same order. Annotations name the pixel a corner falls in; its centre is at +0.5.
pub fn face_correspondences(a: &Value, b: &Value, a_name: &str, b_name: &str) -> Result<Vec<[f64; 4]>> {
    let fa = a.get("faces").and_then(Value::as_object).with_context(|| format!("{a_name}: missing object `faces`"))?;
    let fb = b.get("faces").and_then(Value::as_object).with_context(|| format!("{b_name}: missing object `faces`"))?;
    let corner = |v: &Value, name: &str, face: &str, i: usize| -> Result<[f64; 2]> {
        let p = v.as_array().filter(|p| p.len() == 2).with_context(|| format!("{name}: faces.{face}[{i}] must be [u, v]"))?;
        let u = p[0].as_f64().with_context(|| format!("{name}: faces.{face}[{i}][0] is not a number"))?;
        let w = p[1].as_f64().with_context(|| format!("{name}: faces.{face}[{i}][1] is not a number"))?;
        Ok([u + 0.5, w + 0.5])
    };
    let mut out = Vec::new();
    for (face, ca) in fa {
        let cb = fb.get(face).and_then(Value::as_array).with_context(|| format!("{b_name}: missing face `{face}`"))?;
        let ca = ca.as_array().with_context(|| format!("{a_name}: faces.{face} must be a list"))?;
        if ca.len() != cb.len() {
            bail!("face `{face}` has {} corners in {a_name} but {} in {b_name}", ca.len(), cb.len());
        }
        for i in 0..ca.len() {
            let (p, q) = (corner(&ca[i], a_name, face, i)?, corner(&cb[i], b_name, face, i)?);
            out.push([p[0], p[1], q[0], q[1]]);
        }
    }
    Ok(out)
}

fn real_pair(dir: &Path) -> Result<(ImageBuf, ImageBuf, EpipolarGeometry, String)> {
    let left = load_gray(&dir.join("image0000.png"))?;
    let right = load_gray(&dir.join("image0040.png"))?;
    let f0_path = dir.join("faces-frame0.json");
    let f0: Value = serde_json::from_str(&std::fs::read_to_string(&f0_path).with_context(|| format!("cannot read {}", f0_path.display()))?)
        .with_context(|| format!("{} is not valid JSON", f0_path.display()))?;
    let f40: Value = serde_json::from_str(FRAME40).context("built-in frame-40 annotation")?;
    let pts = face_correspondences(&f0, &f40, "faces-frame0.json", "visp-cube-faces-frame40.json")?;
    let geo = EpipolarGeometry::from_correspondences(&pts, 0.5, 10.0).context("epipolar constraint from the annotated corners")?;
    Ok((left, right, geo, format!("visp-cube frames 0 and 40 ({})", dir.display())))
}

fn snapshot_pair(dir: &Path) -> Result<(ImageBuf, ImageBuf, EpipolarGeometry, String)> {
    let left = load_gray(&dir.join("left.png"))?;
    let right = load_gray(&dir.join("right.png"))?;
    let cage = dir.join("cage.json");
    let (geo, _) = geometry_from_points(&load_points(&cage)?, 0.5, 10.0, &cage)?;
    Ok((left, right, geo, format!("simulator snapshot {}", dir.display())))
}

fn synthetic_pair() -> Result<(ImageBuf, ImageBuf, EpipolarGeometry, String)> {
    let scene = SynthScene::random(5, 7);
    let pair = scene.render(7);
    let robot: Vec<Vector3<f64>> = pair.cage.iter().map(|c| Vector3::from(c.0)).collect();
    let image: Vec<[f64; 4]> = pair.cage.iter().map(|c| c.1).collect();
    let model = AffineStereo::fit(&robot, &image).context("affine model of the synthetic cage")?;
    Ok((pair.left, pair.right, EpipolarGeometry::from_model(model, 0.5, 10.0), "synthetic: five boxes, two affine cameras (seed 7)".into()))
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() { f64::NAN } else { v[v.len() / 2] }
}

pub fn run(args: PlannerArgs) -> Result<()> {
    let (left, right, geo, what) = if let Some(dir) = &args.snapshot {
        snapshot_pair(dir)?
    } else if args.synthetic || !args.data.join("image0040.png").exists() {
        if !args.synthetic {
            eprintln!("note: {} not found; timing the synthetic scene instead", args.data.join("image0040.png").display());
        }
        synthetic_pair()?
    } else {
        real_pair(&args.data)?
    };
    if args.iterations == 0 {
        bail!("--iterations must be at least 1");
    }
    let mut planner = Planner::new(PlannerConfig::default());
    for _ in 0..2 {
        let _ = timed_plan(&mut planner, &left, &right, &geo);
    }
    let mut samples: BTreeMap<&'static str, Vec<f64>> = BTreeMap::new();
    let mut last = None;
    for _ in 0..args.iterations {
        let (plan, t) = timed_plan(&mut planner, &left, &right, &geo);
        for (k, v) in t {
            samples.entry(k).or_default().push(v);
        }
        last = Some(plan);
    }
    let plan = last.context("no run")?;
    let p50: BTreeMap<&'static str, f64> = samples.iter_mut().map(|(k, v)| (*k, median(v))).collect();
    // The fastest run: what the code costs when no other process takes the core (the dev
    // machine is shared, so medians drift with its load).
    let min: BTreeMap<&'static str, f64> = samples.iter().map(|(k, v)| (*k, v.iter().copied().fold(f64::INFINITY, f64::min))).collect();
    // Edges and segments run once per view: per image is half the stage time.
    let per_image = (p50.get(Stage::Edges.name()).copied().unwrap_or(0.0) + p50.get(Stage::Segments.name()).copied().unwrap_or(0.0)) / 2.0;
    let per_image_min = (min.get(Stage::Edges.name()).copied().unwrap_or(0.0) + min.get(Stage::Segments.name()).copied().unwrap_or(0.0)) / 2.0;
    if args.json {
        let stages: serde_json::Map<String, Value> = p50.iter().filter(|(k, _)| **k != "total").map(|(k, v)| (format!("{k}_ms_p50"), json!(round3(*v)))).collect();
        let v = json!({
            "pair": what,
            "width": left.width,
            "height": left.height,
            "iterations": args.iterations,
            "segments_left": plan.left_segments.len(),
            "segments_right": plan.right_segments.len(),
            "candidates": plan.candidates.list.len(),
            "planes": plan.planes.len(),
            "facets": plan.facets.len(),
            "total_ms_p50": round3(p50.get("total").copied().unwrap_or(f64::NAN)),
            "total_ms_min": round3(min.get("total").copied().unwrap_or(f64::NAN)),
            "edges_segments_per_image_ms_p50": round3(per_image),
            "edges_segments_per_image_ms_min": round3(per_image_min),
            "stages": stages,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        println!("planner on {what}: {}x{}, {} runs", left.width, left.height, args.iterations);
        println!(
            "segments {} + {}, candidates {}, planes {}, facets {}",
            plan.left_segments.len(),
            plan.right_segments.len(),
            plan.candidates.list.len(),
            plan.planes.len(),
            plan.facets.len()
        );
        println!("  {:<15} {:>9} {:>9}", "stage", "median", "fastest");
        for s in Stage::ALL {
            println!("  {:<15} {:>6.3} ms {:>6.3} ms", s.name(), p50.get(s.name()).copied().unwrap_or(0.0), min.get(s.name()).copied().unwrap_or(0.0));
        }
        println!("  {:<15} {:>6.3} ms {:>6.3} ms (budget 100 ms)", "total", p50.get("total").copied().unwrap_or(f64::NAN), min.get("total").copied().unwrap_or(f64::NAN));
        println!("  edges + segments per 640x480 image: {per_image:.3} ms median, {per_image_min:.3} ms fastest (budget 2.5 ms)");
    }
    Ok(())
}

fn round3(x: f64) -> f64 {
    (x * 1e3).round() / 1e3
}
