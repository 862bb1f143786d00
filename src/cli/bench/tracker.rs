//! `handeye bench tracker`: update time of one contour and of a 4-contour stereo set on real
//! frames.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_vision::image::ImageBuf;
use handeye_vision::tracker::{ContourTracker, Role, StereoTrackerSet, TrackerConfig, View};
use serde_json::json;

use crate::cli::track::{face_corners, list_frames, load_faces, load_gray};

/// Shown after the options in `--help`.
const BENCH_HELP: &str = "\
Time the affine contour tracker on a real image sequence.

Contour update: one tracker (default settings: 100 points, ±10 px search plus a ±2.5 px
refinement pass) follows `--face` through every frame, `--repeats` times. Stereo update:
a gripper and a target contour in a left and a right view (4 contours) updated in one call,
with frame k as the left view and frame k+1 as the right one (the faces `--face` and
`--target-face`). Prints the median and 99th percentile of the time per update and the
stereo rate it allows. Build with `--release` for numbers worth recording.

Example:

  cargo run --release -- bench tracker --json      # frames from $HANDEYE_DATA/visp-cube
  cargo run --release -- bench tracker --dir ../shared/data/visp-cube --json";

/// Arguments of `handeye bench tracker`.
#[derive(Args, Debug)]
#[command(after_help = BENCH_HELP)]
pub struct TrackerArgs {
    /// Folder of frames (PNG), read in file-name order [default: $HANDEYE_DATA/visp-cube,
    /// HANDEYE_DATA defaulting to ../shared/data].
    #[arg(long, value_name = "DIR", default_value_os_t = super::visp_cube_dir(), hide_default_value = true)]
    dir: PathBuf,

    /// Init JSON with the polygons under "faces" [default: DIR/faces-frame0.json].
    #[arg(long, value_name = "FILE")]
    init: Option<PathBuf>,

    /// Face tracked as the gripper (and alone for the single-contour figure).
    #[arg(long, value_name = "NAME", default_value = "top")]
    face: String,

    /// Face tracked as the target in the stereo set.
    #[arg(long, value_name = "NAME", default_value = "left")]
    target_face: String,

    /// Passes over the sequence for each measurement.
    #[arg(long, value_name = "N", default_value_t = 5)]
    repeats: usize,

    /// Skip a contour's refinement pass when its first pass moved no corner this far, px
    /// (0 = always refine, the default). About a quarter faster, but markedly less robust on
    /// real frames (see `TrackerConfig::refine_skip_px`): for measuring the trade-off only.
    #[arg(long, value_name = "PX", default_value_t = 0.0)]
    refine_skip_px: f64,

    /// Search passes per update (1..=8; default 2: a ±10 px search, then a ±2.5 px refinement).
    /// 1 costs about 65 % of 2 but loses the real top face far more often (see
    /// `TrackerConfig::passes`): for measuring the trade-off only.
    #[arg(long, value_name = "N", default_value_t = 2)]
    passes: usize,

    /// Search only every N-th point of each side in the first (wide) pass (1..=8; default 1:
    /// all). 2 is about a fifth faster but locks on to wrong edges of the real top face far
    /// more often (see `TrackerConfig::coarse_stride`): for measuring the trade-off only.
    #[arg(long, value_name = "N", default_value_t = 1)]
    coarse_stride: usize,

    /// Search the short range around the prediction first and skip the wide pass when that
    /// moves no corner this far, px (0 = never, the default). 1 px halves the time but loses
    /// the real top face or strays >= 4 px over ten times as often (see
    /// `TrackerConfig::short_first_px`): for measuring the trade-off only.
    #[arg(long, value_name = "PX", default_value_t = 0.0)]
    short_first_px: f64,

    /// Print one JSON object: contour_update_us_p50, contour_update_us_p99,
    /// stereo_update_us_p50, stereo_update_us_p99, stereo_hz and the run's details (the
    /// minima are the least disturbed by other load on the machine).
    #[arg(long)]
    json: bool,
}

pub fn run(args: TrackerArgs) -> Result<()> {
    if args.repeats == 0 {
        bail!("--repeats must be at least 1");
    }
    let init = args.init.clone().unwrap_or_else(|| args.dir.join("faces-frame0.json"));
    let faces = load_faces(&init)?;
    let gripper = face_corners(&faces, &init, &args.face)?;
    let target = face_corners(&faces, &init, &args.target_face)?;
    let paths = list_frames(&args.dir)?;
    if paths.len() < 3 {
        bail!("{} holds {} frames; the benchmark needs at least 3", args.dir.display(), paths.len());
    }
    let frames: Vec<ImageBuf> = paths.iter().map(|p| load_gray(p)).collect::<Result<_>>()?;
    let config = TrackerConfig {
        refine_skip_px: args.refine_skip_px,
        passes: args.passes,
        coarse_stride: args.coarse_stride,
        short_first_px: args.short_first_px,
        ..TrackerConfig::default()
    };
    config.validate().context("bad --refine-skip-px, --passes, --coarse-stride or --short-first-px")?;
    let dt_s = 1.0 / 30.0;

    // One contour through the sequence.
    let mut tracker = ContourTracker::new(config, &gripper).context("gripper face")?;
    let mut contour_us = Vec::with_capacity(frames.len() * args.repeats);
    let mut contour_lost = 0;
    for pass in 0..=args.repeats {
        tracker.reinit(&gripper).context("gripper face")?;
        for (k, frame) in frames.iter().enumerate() {
            let started = Instant::now();
            let state = tracker.update(&frame.view(), if k == 0 { 0.0 } else { dt_s });
            let us = started.elapsed().as_secs_f64() * 1e6;
            if !state.is_tracking() {
                contour_lost += usize::from(pass > 0);
                break;
            }
            if pass > 0 {
                contour_us.push(us); // pass 0 warms caches and branch predictors
            }
        }
    }

    // Four contours: gripper and target in a left (frame k) and right (frame k+1) view.
    let make = |corners: &[[f64; 2]]| ContourTracker::new(config, corners);
    let mut set = StereoTrackerSet::new();
    set.insert(Role::Gripper, View::Left, make(&gripper)?);
    set.insert(Role::Gripper, View::Right, make(&gripper)?);
    set.insert(Role::Target, View::Left, make(&target)?);
    set.insert(Role::Target, View::Right, make(&target)?);
    let mut stereo_us = Vec::with_capacity(frames.len() * args.repeats);
    let mut stereo_lost = 0;
    for pass in 0..=args.repeats {
        for role in Role::ALL {
            for view in View::ALL {
                let corners = if role == Role::Gripper { &gripper } else { &target };
                if let Some(t) = set.get_mut(role, view) {
                    t.reinit(corners).context("stereo set")?;
                }
            }
        }
        for k in 0..frames.len() - 1 {
            let (left, right) = (frames[k].view(), frames[k + 1].view());
            let started = Instant::now();
            let states = set.update(&left, &right, if k == 0 { 0.0 } else { dt_s });
            let us = started.elapsed().as_secs_f64() * 1e6;
            if !states.all_active_tracking() {
                stereo_lost += usize::from(pass > 0);
                break;
            }
            if pass > 0 {
                stereo_us.push(us);
            }
        }
    }

    let (c50, c99) = percentiles(&mut contour_us);
    let (s50, s99) = percentiles(&mut stereo_us);
    let (cmin, smin) = (contour_us.first().copied().unwrap_or(0.0), stereo_us.first().copied().unwrap_or(0.0));
    let hz = if s50 > 0.0 { 1e6 / s50 } else { 0.0 };
    let points = config.points;
    if args.json {
        let out = json!({
            "contour_update_us_p50": round3(c50),
            "contour_update_us_p99": round3(c99),
            "stereo_update_us_p50": round3(s50),
            "stereo_update_us_p99": round3(s99),
            "stereo_hz": hz.round(),
            "contour_update_us_min": round3(cmin),
            "stereo_update_us_min": round3(smin),
            "refine_skip_px": config.refine_skip_px,
            "coarse_stride": config.coarse_stride,
            "short_first_px": config.short_first_px,
            "ns_per_point_stereo_p50": round3(s50 * 1e3 / (4 * points) as f64),
            "points": points,
            "search_px": config.search_px,
            "passes": config.passes,
            "contour_updates": contour_us.len(),
            "stereo_updates": stereo_us.len(),
            "passes_that_lost_a_contour": contour_lost + stereo_lost,
            "frames": frames.len(),
            "optimised_build": !cfg!(debug_assertions),
        });
        println!("{out}");
    } else {
        if cfg!(debug_assertions) {
            println!("note: debug build; record numbers from `cargo run --release -- bench tracker`");
        }
        println!(
            "tracker on {} frames of {} ({} points, ±{} px search, {} passes per update):",
            frames.len(),
            args.dir.display(),
            points,
            config.search_px,
            config.passes
        );
        println!(
            "  contour update:            median {c50:7.2} µs   p99 {c99:7.2} µs   min {cmin:7.2} µs   ({} updates)",
            contour_us.len()
        );
        println!(
            "  stereo update, 4 contours: median {s50:7.2} µs   p99 {s99:7.2} µs   min {smin:7.2} µs   ({} updates) -> {hz:.0} Hz",
            stereo_us.len()
        );
        println!("  per sampling point:        {:.1} ns (stereo median / 400 points)", s50 * 1e3 / (4 * points) as f64);
        if contour_lost + stereo_lost > 0 {
            println!("  warning: {} passes lost a contour before the end (their remaining frames are not timed)", contour_lost + stereo_lost);
        }
    }
    Ok(())
}

fn percentiles(values: &mut [f64]) -> (f64, f64) {
    if values.is_empty() {
        return (0.0, 0.0);
    }
    values.sort_by(f64::total_cmp);
    let at = |q: f64| values[((values.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.99))
}

fn round3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}
