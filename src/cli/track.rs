//! `handeye track`: one affine contour tracker over a folder of images.

use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{anyhow, bail, Context, Result};
use clap::{Args, ValueEnum};
use handeye_vision::image::{ImageBuf, ImageView};
use handeye_vision::tracker::{
    ContourTracker, DeformationModel, EdgeSign, Polarity, TrackState, TrackerConfig,
};
use serde_json::{json, Value};

/// Shown after the options in `--help` (the subcommand's one-line summary lives in main.rs).
const TRACK_HELP: &str = "\
The folder's PNG files are read in file-name order (other files are skipped). The tracker
starts from the polygon named `--face` in the `--init` JSON, placed on the first frame, and
prints one line per frame: corners, confidence and state. A lost tracker stays lost (its
last good corners are printed) and the reason is given.

Defaults are the library's: 100 points, two-sided search with each point's learnt inside
grey level as a tie-breaker, a robust projective fit (A.2 plus perspective), and a
refinement pass. The first frame may be off by a few pixels; the tracker pulls it in.

The init JSON looks like `{\"faces\": {\"top\": [[315, 234], [385, 205], ...], ...}}`: corners
in pixels (u right, v down), in order around each polygon, at least 3.

Example:

  handeye track --dir ../shared/data/visp-cube --init ../shared/data/visp-cube/faces-frame0.json \\
      --face top --overlay /tmp/top
  handeye track --dir ../shared/data/visp-cube --init ../shared/data/visp-cube/faces-frame0.json \\
      --face left --json > left.jsonl";

/// Arguments of `handeye track`.
#[derive(Args, Debug)]
#[command(after_help = TRACK_HELP)]
pub struct TrackArgs {
    /// Folder of frames (PNG, 8-bit grey or colour; colour is converted to grey).
    #[arg(long, value_name = "DIR")]
    dir: PathBuf,

    /// JSON file with the initial polygons under "faces" (e.g. faces-frame0.json).
    #[arg(long, value_name = "FILE")]
    init: PathBuf,

    /// Name of the polygon in the JSON's "faces" to track.
    #[arg(long, value_name = "NAME")]
    face: String,

    /// Print one JSON object per line: frame, image, corners [[u, v], ...], confidence,
    /// state ("tracking" or "lost"), reason (null while tracking), and the confidence parts.
    #[arg(long)]
    json: bool,

    /// Write a PNG per frame into this folder (created if missing) with the contour drawn:
    /// green while tracking, red once lost; yellow dots are the edges that agreed with the fit.
    #[arg(long, value_name = "OUT")]
    overlay: Option<PathBuf>,

    /// Half-length of the normal search, pixels (1..=40).
    #[arg(long, value_name = "PX", default_value_t = 10.0)]
    search_px: f64,

    /// One-sided search: each point accepts only edges of the sign it locked on to in the
    /// first frames (or of `--polarity` if given). Rejects clutter of the other sign, but a
    /// side whose polarity flips (a neighbouring face coming into view) is then lost to it.
    #[arg(long)]
    one_sided: bool,

    /// With --one-sided: one polarity for the whole contour instead of learning it per point.
    #[arg(long, value_enum, requires = "one_sided")]
    polarity: Option<PolarityArg>,

    /// Frame rate of the sequence, frames per second: the predictive filter scales its
    /// velocity by the real time between frames, 1/frame-rate-hz here.
    #[arg(long, value_name = "HZ", default_value_t = 30.0)]
    frame_rate_hz: f64,

    /// Sampling points around the polygon.
    #[arg(long, value_name = "N", default_value_t = 100)]
    points: usize,

    /// Shape model: projective (A.2 plus perspective, default), a2 (affine, normal offsets
    /// only: Appendix A.2), a3 (affine, the thesis's A.3 simplification: sluggish to deform),
    /// translation (no shape change).
    #[arg(long, value_enum, default_value_t = ModelArg::Projective)]
    model: ModelArg,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum PolarityArg {
    /// The polygon is darker than its surroundings.
    DarkInside,
    /// The polygon is brighter than its surroundings.
    BrightInside,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum ModelArg {
    Projective,
    A2,
    A3,
    Translation,
}

pub fn run(args: TrackArgs) -> Result<()> {
    if !(args.frame_rate_hz > 0.0 && args.frame_rate_hz.is_finite()) {
        bail!("--frame-rate-hz must be a positive number of frames per second, got {}", args.frame_rate_hz);
    }
    let config = TrackerConfig {
        points: args.points,
        search_px: args.search_px,
        edge_sign: match (args.one_sided, args.polarity) {
            (false, _) => EdgeSign::Either,
            (true, None) => EdgeSign::Learned,
            (true, Some(PolarityArg::DarkInside)) => EdgeSign::Fixed(Polarity::DarkInside),
            (true, Some(PolarityArg::BrightInside)) => EdgeSign::Fixed(Polarity::BrightInside),
        },
        model: match args.model {
            ModelArg::Projective => DeformationModel::Projective,
            ModelArg::A2 => DeformationModel::NormalOnly,
            ModelArg::A3 => DeformationModel::FullVector,
            ModelArg::Translation => DeformationModel::None,
        },
        ..TrackerConfig::default()
    };
    config.validate().context("bad tracker setting from the command line")?;
    let faces = load_faces(&args.init)?;
    let corners = face_corners(&faces, &args.init, &args.face)?;
    let frames = list_frames(&args.dir)?;
    if let Some(named) = faces.get("image").and_then(Value::as_str) {
        let first = frames[0].file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        if named != first {
            tracing::warn!("{} says its polygons belong to {named}, but the first frame is {first}", args.init.display());
        }
    }
    if let Some(out) = &args.overlay {
        fs::create_dir_all(out).with_context(|| format!("cannot create overlay folder {}", out.display()))?;
    }
    let mut tracker = ContourTracker::new(config, &corners)
        .with_context(|| format!("{}: face \"{}\" is not a usable polygon", args.init.display(), args.face))?;

    let dt_s = 1.0 / args.frame_rate_hz;
    let stdout = std::io::stdout();
    let mut out = stdout.lock();
    let mut update_us = Vec::with_capacity(frames.len());
    let mut lost_at = None;
    for (index, path) in frames.iter().enumerate() {
        let image = load_gray(path)?;
        let started = Instant::now();
        let state = tracker.update(&image.view(), if index == 0 { 0.0 } else { dt_s });
        if state.is_tracking() || lost_at.is_none() {
            update_us.push(started.elapsed().as_secs_f64() * 1e6);
        }
        if !state.is_tracking() && lost_at.is_none() {
            lost_at = Some(index);
        }
        let name = path.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_default();
        let corners: Vec<[f64; 2]> = tracker.corners().map(|c| [c.x, c.y]).collect();
        let conf = tracker.confidence();
        if args.json {
            let line = json!({
                "frame": index,
                "image": name,
                "corners": corners.iter().map(|c| [round2(c[0]), round2(c[1])]).collect::<Vec<_>>(),
                "confidence": round3(conf.score),
                "state": state.code(),
                "reason": state.lost_reason().map(|r| r.code()),
                "detail": state.lost_reason().map(|r| r.to_string()),
                "edge_fraction": round3(conf.edge_fraction),
                "inlier_fraction": round3(conf.inlier_fraction),
                "residual_px": round3(conf.residual_px),
                "direction_support": round3(conf.direction_support),
            });
            writeln!(out, "{line}")?;
        } else {
            let pts: Vec<String> = corners.iter().map(|c| format!("({:.1}, {:.1})", c[0], c[1])).collect();
            let reason = state.lost_reason().map(|r| format!("  [{r}]")).unwrap_or_default();
            writeln!(
                out,
                "{index:4} {name}  {:8}  conf {:.2} (inliers {:3.0} %, {:.2} px)  {}{reason}",
                state.code(),
                conf.score,
                conf.inlier_fraction * 100.0,
                conf.residual_px,
                pts.join(" "),
            )?;
        }
        if let Some(dir) = &args.overlay {
            let png = dir.join(&name).with_extension("png");
            write_overlay(&image.view(), &tracker, state, &png)?;
        }
    }
    if !args.json {
        update_us.sort_by(f64::total_cmp);
        let median = update_us.get(update_us.len() / 2).copied().unwrap_or(0.0);
        match lost_at {
            None => writeln!(out, "tracked all {} frames; median update {median:.1} µs (this build)", frames.len())?,
            Some(k) => writeln!(
                out,
                "lost at frame {k} of {} ({}); median update {median:.1} µs (this build)",
                frames.len(),
                tracker.state().lost_reason().map(|r| r.to_string()).unwrap_or_default()
            )?,
        }
    }
    Ok(())
}

fn round2(v: f64) -> f64 {
    (v * 100.0).round() / 100.0
}

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// Reads and parses an init JSON file.
pub(crate) fn load_faces(path: &Path) -> Result<Value> {
    let text = fs::read_to_string(path).with_context(|| format!("cannot read init file {}", path.display()))?;
    let value: Value = serde_json::from_str(&text).with_context(|| format!("{} is not valid JSON", path.display()))?;
    if !value.get("faces").is_some_and(Value::is_object) {
        bail!("{}: missing field \"faces\" (an object of name -> [[u, v], ...])", path.display());
    }
    Ok(value)
}

/// The corners of face `name`, with errors that name the file and the field.
pub(crate) fn face_corners(faces: &Value, path: &Path, name: &str) -> Result<Vec<[f64; 2]>> {
    let all = faces["faces"].as_object().ok_or_else(|| anyhow!("{}: \"faces\" is not an object", path.display()))?;
    let Some(face) = all.get(name) else {
        let names: Vec<&str> = all.keys().map(String::as_str).collect();
        bail!("{}: no face \"{name}\" under \"faces\"; available: {}", path.display(), names.join(", "));
    };
    let list = face
        .as_array()
        .ok_or_else(|| anyhow!("{}: faces.{name} must be a list of [u, v] corners", path.display()))?;
    let mut corners = Vec::with_capacity(list.len());
    for (k, c) in list.iter().enumerate() {
        let pair = c.as_array().filter(|a| a.len() == 2);
        let uv = pair.and_then(|a| Some([a[0].as_f64()?, a[1].as_f64()?]));
        match uv {
            Some(uv) if uv[0].is_finite() && uv[1].is_finite() => corners.push(uv),
            _ => bail!("{}: faces.{name}[{k}] must be [u, v] (two numbers), got {c}", path.display()),
        }
    }
    if corners.len() < 3 {
        bail!("{}: faces.{name} has {} corners, a polygon needs at least 3", path.display(), corners.len());
    }
    Ok(corners)
}

/// PNG files in `dir`, sorted by file name. Errors when there are none.
pub(crate) fn list_frames(dir: &Path) -> Result<Vec<PathBuf>> {
    let entries = fs::read_dir(dir).with_context(|| format!("cannot read folder {}", dir.display()))?;
    let mut frames = Vec::new();
    for entry in entries {
        let path = entry.with_context(|| format!("cannot list folder {}", dir.display()))?.path();
        let is_png = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("png"));
        if is_png && path.is_file() {
            frames.push(path);
        }
    }
    if frames.is_empty() {
        bail!("{} holds no PNG frames", dir.display());
    }
    frames.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(frames)
}

/// Loads a frame as 8-bit grey.
pub(crate) fn load_gray(path: &Path) -> Result<ImageBuf> {
    let img = super::png::read_gray(path)?;
    let (w, h) = (img.width() as usize, img.height() as usize);
    ImageBuf::from_vec(img.into_raw(), w, h).ok_or_else(|| anyhow!("{}: empty image", path.display()))
}

/// Writes `image` with the tracker's contour drawn on it.
pub(crate) fn write_overlay(image: &ImageView<'_>, tracker: &ContourTracker, state: TrackState, path: &Path) -> Result<()> {
    let (w, h) = (image.width(), image.height());
    let mut rgb = image::RgbImage::new(w as u32, h as u32);
    for y in 0..h {
        for (x, &v) in image.row(y).iter().enumerate() {
            rgb.put_pixel(x as u32, y as u32, image::Rgb([v, v, v]));
        }
    }
    let colour = if state.is_tracking() { [0, 255, 0] } else { [255, 0, 0] };
    let corners: Vec<_> = tracker.corners().collect();
    for k in 0..corners.len() {
        let (a, b) = (corners[k], corners[(k + 1) % corners.len()]);
        let steps = ((b - a).norm().ceil() as usize).max(1) * 2;
        for s in 0..=steps {
            let p = a + (b - a) * (s as f64 / steps as f64);
            put(&mut rgb, p.x, p.y, colour);
        }
    }
    if state.is_tracking() {
        for p in tracker.inlier_edges() {
            put(&mut rgb, p.x, p.y, [255, 255, 0]);
        }
    }
    rgb.save(path).with_context(|| format!("cannot write overlay {}", path.display()))
}

fn put(img: &mut image::RgbImage, x: f64, y: f64, colour: [u8; 3]) {
    let (xi, yi) = (x.round(), y.round());
    if xi >= 0.0 && yi >= 0.0 && (xi as u32) < img.width() && (yi as u32) < img.height() {
        img.put_pixel(xi as u32, yi as u32, image::Rgb(colour));
    }
}
