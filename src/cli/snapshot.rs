//! `handeye snapshot`: render a scenario's stereo pair to PNGs, with ground truth.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use clap::Args;
use handeye_sim::render::Renderer;
use handeye_sim::referee::script::GroundTruthPick;
use handeye_sim::referee::truth::{CageTruth, GroundTruth};
use handeye_sim::{Scenario, Simulator};

/// Render a scenario's stereo pair to PNGs, with ground truth for testing.
///
/// Writes into DIR:
///   left.png, right.png  the two camera views (GRAY8, exactly what `handeye sim` publishes)
///   truth.json           block poses, camera matrices (3x4, robot frame to pixels, pixel
///                        centres at integers), the image polygon and visible pixel area of
///                        every block face and of the gripper plate in both views, 3-D edges
///   cage.json            the 8 calibration-cage points (robot frame) and their projections
///
/// Ground truth is for judging and testing only; the daemon never sees it.
///
/// Examples:
///   handeye snapshot scenarios/pick_cube.toml --out out/snap
///   handeye snapshot scenarios/random.toml --seed 7 --randomize --out out/cell7
///       (the work cell `handeye run --seed 7 --randomize` and `handeye batch --randomize`
///        draw for seed 7: cameras, light, shades, blocks, noise and blur)
#[derive(Args)]
pub struct SnapshotArgs {
    /// Scenario file (TOML), e.g. scenarios/pick_cube.toml.
    scenario: PathBuf,
    /// Output directory (created if missing).
    #[arg(long)]
    out: PathBuf,
    /// Simulate this many frames (1/frame_rate_hz s each) before rendering, e.g. to let
    /// events fire. The arm holds still unless --scripted-pick.
    #[arg(long, default_value_t = 0)]
    frames: u64,
    /// During those frames, drive the arm with the scripted pick that reads the target's pose
    /// from ground truth (a physics demo, not vision), e.g. `--frames 170` shows the target
    /// lifted in the gripper.
    #[arg(long)]
    scripted_pick: bool,
    /// Lay the scenario out as `handeye sim --seed N` does: the target moved a little, or with
    /// --random-layout / --randomize the layout or whole work cell that seed draws.
    #[arg(long)]
    seed: Option<u64>,
    /// With --seed: a random layout of the scenario's blocks (as `handeye batch` runs).
    #[arg(long, requires = "seed", conflicts_with = "randomize")]
    random_layout: bool,
    /// With --seed: draw the whole work cell from the scenario's [randomize] ranges (as
    /// `handeye batch --randomize` runs; see scenarios/random.toml).
    #[arg(long, requires = "seed")]
    randomize: bool,
}

pub fn run(args: SnapshotArgs) -> Result<()> {
    crate::cli::sim::quiet_mesa();
    let mut scenario = Scenario::load(&args.scenario)?;
    crate::cli::sim::lay_out(&mut scenario, &args.scenario, args.seed, args.random_layout, args.randomize, false)?;
    let mut sim = Simulator::new(scenario)?;
    let target = sim.target_index();
    let mut script = args.scripted_pick.then(|| GroundTruthPick::new(&sim, target, 0.07, 1e6));
    for n in 0..args.frames {
        if let Some(s) = script.as_mut() {
            let cmd = s.next_command(&mut sim, n);
            sim.command(&cmd);
        }
        sim.step_frame();
    }
    let mut renderer =
        Renderer::for_scene_with(&sim.scene, &sim.events.cameras, sim.scenario.render.antialias).context("starting the renderer")?;
    eprintln!("renderer: {}", renderer.adapter());
    let (w, h) = (renderer.width(), renderer.height());
    let mut poses = Vec::new();
    sim.object_poses(&mut poses);
    let mut gray = vec![0u8; renderer.frame_bytes()];
    let mut ids = vec![0u32; renderer.frame_bytes()];
    {
        let frame = sim.frame_input(&poses);
        renderer.render(&frame, &mut gray)?;
        renderer.render_ids(&frame, &mut ids)?;
    }
    let truth = GroundTruth::compute(&sim, &ids);
    let cage = CageTruth::compute(&sim);

    std::fs::create_dir_all(&args.out).with_context(|| format!("creating {}", args.out.display()))?;
    let view = (w * h) as usize;
    for (i, name) in ["left.png", "right.png"].into_iter().enumerate() {
        let img = image::GrayImage::from_raw(w, h, gray[i * view..(i + 1) * view].to_vec()).context("image size")?;
        let path = args.out.join(name);
        img.save(&path).with_context(|| format!("writing {}", path.display()))?;
    }
    write_json(&args.out.join("truth.json"), &truth)?;
    write_json(&args.out.join("cage.json"), &cage)?;
    let target = &truth.blocks[truth.target];
    println!(
        "wrote {}/{{left,right}}.png ({w}x{h}), truth.json, cage.json; target {:?}: {} faces visible in both views",
        args.out.display(),
        target.name,
        truth.faces.iter().filter(|f| f.block == truth.target && f.views.iter().all(|v| v.visible_px > 0)).count()
    );
    Ok(())
}

fn write_json<T: serde::Serialize>(path: &Path, value: &T) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}
