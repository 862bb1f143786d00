//! `handeye bench render`: simulator stereo frames per second in lockstep.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Args;
use handeye_sim::run::{Runner, Transport};
use handeye_sim::transport::WireTransport;
use handeye_wire::Domain;
use handeye_sim::referee::script::GroundTruthPick;
use handeye_sim::{Scenario, Simulator};

/// Measure the simulator's lockstep frame rate: physics + render + publish per stereo frame.
///
/// Runs the scenario in lockstep with the arm driven by a scripted pick (so physics includes
/// a moving arm, contacts and a grasp), renders both views every frame straight into a
/// loaned shared-memory sample and publishes it on handeye/stereo (with the robot state every
/// control tick), in a private domain with no daemon attached. Prints stereo frames per second
/// and the time per stage. Use a release build:
///
///   cargo run --release -- bench render scenarios/pick_cube.toml --json
///
/// Budget (DESIGN.md): >= 200 stereo frames/s on the 2-core GPU-less dev machine.
#[derive(Args)]
pub struct RenderArgs {
    /// Scenario file (TOML).
    scenario: PathBuf,
    /// Frames to measure (after the warm-up).
    #[arg(long, default_value_t = 600)]
    frames: u64,
    /// Frames rendered before measuring (device and pipeline warm-up).
    #[arg(long, default_value_t = 30)]
    warmup: u64,
    /// Keep the arm still instead of running the scripted pick.
    #[arg(long)]
    idle: bool,
    /// Print one JSON object (stereo_fps, per-stage ms, adapter) instead of text.
    #[arg(long)]
    json: bool,
}

pub fn run(args: RenderArgs) -> Result<()> {
    crate::cli::sim::quiet_mesa();
    let scenario = Scenario::load(&args.scenario)?;
    let name = scenario.name.clone();
    let mut runner = Runner::new(Simulator::new(scenario)?).context("starting the renderer")?;
    let adapter = runner.renderer.adapter();
    let target = runner.sim.target_index();
    let mut script = GroundTruthPick::new(&runner.sim, target, 0.07, 1e6);
    let domain = Domain::unique("bench-render");
    let mut transport = WireTransport::new(&domain, runner.renderer.width(), runner.renderer.height())?;
    let (mut publish_s, mut physics_s) = (0.0, 0.0);
    let mut measured = 0u64;
    let mut start = Instant::now();
    for n in 0..args.warmup + args.frames {
        if n == args.warmup {
            start = Instant::now();
            (publish_s, physics_s) = (0.0, 0.0);
        }
        let t0 = Instant::now();
        runner.publish(&mut transport as &mut dyn Transport)?;
        let t1 = Instant::now();
        if !args.idle {
            let cmd = script.next_command(&mut runner.sim, n);
            runner.sim.command(&cmd);
        }
        for _ in 0..runner.sim.scenario.substeps_per_frame() {
            runner.sim.step();
            let state = runner.sim.robot_state();
            transport.publish_state(&state)?;
        }
        runner.sim.count_frame();
        let t2 = Instant::now();
        publish_s += (t1 - t0).as_secs_f64();
        physics_s += (t2 - t1).as_secs_f64();
        if n >= args.warmup {
            measured += 1;
        }
    }
    let wall = start.elapsed().as_secs_f64();
    drop(transport);
    let _ = handeye_wire::domain::remove_domain_files(&domain);
    let fps = measured as f64 / wall;
    let per = |s: f64| s * 1e3 / measured.max(1) as f64;
    if args.json {
        let out = serde_json::json!({
            "scenario": name,
            "frames": measured,
            "stereo_fps": fps,
            "ms_per_frame": per(wall),
            "render_publish_ms": per(publish_s),
            "physics_state_ms": per(physics_s),
            "physics_steps_per_frame": runner.sim.scenario.substeps_per_frame(),
            "width": runner.renderer.width(),
            "height": runner.renderer.height(),
            "adapter": adapter,
            "transport": "iceoryx2 handeye/stereo + handeye/robot/state, private domain, no subscribers",
        });
        println!("{out}");
    } else {
        println!("scenario {name}: {measured} stereo frames {}x{} x2 in {wall:.2} s", runner.renderer.width(), runner.renderer.height());
        println!("  {fps:.1} stereo frames/s ({:.2} ms/frame: render+publish {:.2} ms, physics+state {:.2} ms for {} steps)",
            per(wall), per(publish_s), per(physics_s), runner.sim.scenario.substeps_per_frame());
        println!("  adapter: {adapter}");
    }
    Ok(())
}
