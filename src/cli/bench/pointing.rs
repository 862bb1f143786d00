//! `handeye bench pointing`: the pointing gesture tracker's update per stereo frame.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::Args;
use handeye_sim::render::Renderer;
use handeye_sim::{Scenario, Simulator};
use handeye_vision::image::ImageView;
use handeye_vision::pointing::{GestureConfig, GestureState, PlaneHomography, Pointing, PointingTracker};

/// Measure the pointing gesture tracker (issue 19): one update over both views of a
/// 640x480 stereo frame (differencing against the scene without the hand, the arm's
/// silhouette and its axis in each view, the two plane lines' crossing), the work the
/// daemon's point phase does on its gesture thread for every frame.
///
/// Renders the scenario's pointing gesture (scenarios/point_clutter3.toml by default; with
/// --seed, that seed's random layout and gesture) with the arm parked where the daemon parks
/// it for pointing: the scene before the hand, then every frame of the hand coming in and
/// holding still. Each update is timed on those frames in turn, --frames times; prints the
/// time per update (p50, p99, max, µs), the share of a 30 Hz frame period it takes, and what
/// the tracker made of the gesture. Use a release build for numbers to write down:
///
///   cargo run --release -- bench pointing --json
///   cargo run --release -- bench pointing --seed 7 --frames 1000
#[derive(Args)]
pub struct PointingArgs {
    /// Scenario file with a [pointer] (TOML).
    #[arg(default_value = "scenarios/point_clutter3.toml")]
    scenario: PathBuf,
    /// A random layout and gesture (as `handeye run --seed N --random-layout`).
    #[arg(long)]
    seed: Option<u64>,
    /// Updates to time.
    #[arg(long, default_value_t = 600)]
    frames: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

pub fn run(args: PointingArgs) -> Result<()> {
    crate::cli::sim::quiet_mesa();
    let mut scenario = Scenario::load(&args.scenario)?;
    if let Some(seed) = args.seed
        && !scenario.randomise_layout(seed)
    {
        bail!("seed {seed}: no random layout");
    }
    let Some(pointer) = scenario.pointer.as_mut() else { bail!("{}: no [pointer] section: nothing points", args.scenario.display()) };
    pointer.at_s = 1.0; // early: only the gesture's timing changes
    let park = handeye_daemon::DaemonConfig::default().point().park_m.clone();
    if park.len() == 3 {
        scenario.arm.home_m = [park[0], park[1], park[2]];
    }
    let mut sim = Simulator::new(scenario)?;
    let mut r = Renderer::for_scene_with(&sim.scene, &sim.events.cameras, sim.scenario.render.antialias).context("starting the renderer")?;
    let (w, h) = (r.width() as usize, r.height() as usize);
    let gesture = sim.pointer.clone().context("no gesture")?;
    let [_, hold_to] = gesture.hold_s();
    let t = |sim: &Simulator| sim.now_ns() as f64 * 1e-9;
    let mut poses = Vec::new();
    let mut render = |sim: &Simulator| -> Result<Vec<u8>> {
        let mut gray = vec![0u8; r.frame_bytes()];
        sim.object_poses(&mut poses);
        r.render(&sim.frame_input(&poses), &mut gray)?;
        Ok(gray)
    };
    while t(&sim) < 0.9 {
        sim.step_frame();
    }
    let background = render(&sim)?;
    let mut frames = Vec::new();
    while t(&sim) < hold_to {
        sim.step_frame();
        if t(&sim) >= 1.0 {
            frames.push(render(&sim)?);
        }
    }
    // Plane maps from the lowest cage points' true images (the bench times, it does not score).
    let z = sim.scenario.cage.points_m.iter().map(|p| p[2]).fold(f64::INFINITY, f64::min);
    let lower: Vec<[f64; 3]> = sim.scenario.cage.points_m.iter().copied().filter(|p| p[2] < z + 1e-9).collect();
    let plane: Vec<[f64; 2]> = lower.iter().map(|p| [p[0], p[1]]).collect();
    let fit = |v: usize| -> Result<PlaneHomography> {
        let px: Vec<[f64; 2]> = lower.iter().map(|p| sim.events.cameras[v].project(handeye_sim::glam::DVec3::from_array(*p)).context("cage point out of view")).collect::<Result<_>>()?;
        Ok(PlaneHomography::fit(&plane, &px)?)
    };
    let pointing = Pointing::new(fit(0)?, fit(1)?);
    fn views(g: &[u8], w: usize, h: usize) -> Result<[ImageView<'_>; 2]> {
        Ok([ImageView::new(&g[..w * h], w, h, w)?, ImageView::new(&g[w * h..], w, h, w)?])
    }
    let mut tracker = PointingTracker::new(pointing, GestureConfig::default());
    let [bl, br] = views(&background, w, h)?;
    let mut times_us = Vec::with_capacity(args.frames);
    let mut answers = 0usize;
    let mut last = GestureState::Absent;
    for i in 0..args.frames.max(1) {
        if i % frames.len() == 0 {
            // Each pass over the gesture starts from the scene without the hand.
            tracker = PointingTracker::new(tracker.pointing.clone(), tracker.config);
            tracker.set_background(&bl, &br);
        }
        let [l, rv] = views(&frames[i % frames.len()], w, h)?;
        let t0 = Instant::now();
        last = tracker.update(&l, &rv);
        times_us.push(t0.elapsed().as_secs_f64() * 1e6);
        answers += usize::from(matches!(last, GestureState::Indicated(_)));
    }
    times_us.sort_by(f64::total_cmp);
    let rank = |q: f64| times_us[((q * times_us.len() as f64).ceil() as usize).clamp(1, times_us.len()) - 1];
    let (p50, p99, max) = (rank(0.5), rank(0.99), *times_us.last().unwrap_or(&0.0));
    let state = match last {
        GestureState::Indicated(p) => format!("indicated ({:.3}, {:.3}) m, sigma {:.1} mm", p.point_m[0], p.point_m[1], p.sigma_m * 1e3),
        other => format!("{other:?}"),
    };
    let frame_ms = 1e3 / f64::from(sim.scenario.render.frame_rate_hz);
    if args.json {
        let out = serde_json::json!({
            "scenario": sim.scenario.name,
            "seed": args.seed,
            "width": w,
            "height": h,
            "gesture_frames": frames.len(),
            "updates": times_us.len(),
            "update_us_p50": p50,
            "update_us_p99": p99,
            "update_us_max": max,
            "frame_period_share_p50": p50 * 1e-3 / frame_ms,
            "indicated_updates": answers,
            "last_state": state,
        });
        println!("{out}");
    } else {
        println!("pointing: {} updates over {} frames of the gesture ({w}x{h} x2)", times_us.len(), frames.len());
        println!("  update p50 {p50:.0} µs, p99 {p99:.0} µs, max {max:.0} µs: {:.1} % of a {frame_ms:.1} ms frame at p50", 100.0 * p50 * 1e-3 / frame_ms);
        println!("  {answers} updates answered with a point; the last: {state}");
    }
    Ok(())
}
