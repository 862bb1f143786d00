//! Lockstep determinism: the same scenario, seed and commands give bit-identical frames
//! (physics, controller, events, rendering and sensor noise), run in process on the library.
//! (The same check through `handeye sim --lockstep --json` lives with the transport tests.)

use handeye_sim::run::{NoTransport, RunOptions, Runner, run_lockstep};
use handeye_sim::referee::script::GroundTruthPick;
use handeye_sim::{Scenario, Simulator};

fn scenario(name: &str) -> Scenario {
    Scenario::load(format!("{}/scenarios/{name}", env!("CARGO_MANIFEST_DIR"))).expect("scenario")
}

/// 100 lockstep frames of `scenario` with the arm driven by a scripted pick (a stand-in
/// daemon answering every frame); returns every frame's hash and the tool's travel.
fn run(scenario: Scenario, frames: u64) -> (Vec<u64>, f64) {
    let mut runner = Runner::new(Simulator::new(scenario).expect("simulator")).expect("renderer (lavapipe installed?)");
    runner.keep_frame_hashes = true;
    let target = runner.sim.target_index();
    let mut script = GroundTruthPick::new(&runner.sim, target, 0.07, 2.0);
    let start = runner.sim.arm_reading().tool_m;
    let mut frame = vec![0u8; runner.renderer.frame_bytes()];
    for n in 0..frames {
        assert_eq!(runner.meta().frame_id, n);
        runner.render_into(&mut frame).expect("render");
        let cmd = script.next_command(&mut runner.sim, n);
        runner.sim.command(&cmd);
        runner.sim.step_frame();
    }
    let travel = (runner.sim.arm_reading().tool_m - start).length();
    (runner.frame_hashes, travel)
}

#[test]
fn two_lockstep_runs_give_identical_frames_for_100_frames() {
    let (a, travel) = run(scenario("pick_cube.toml"), 100);
    let (b, _) = run(scenario("pick_cube.toml"), 100);
    assert_eq!(a.len(), 100);
    for (i, (x, y)) in a.iter().zip(&b).enumerate() {
        assert_eq!(x, y, "frame {i} differs between two runs of the same scenario and seed");
    }
    // Not a still picture: the arm moved and the frames change.
    assert!(travel > 0.05, "the arm moved {travel} m");
    let distinct: std::collections::HashSet<_> = a.iter().collect();
    assert!(distinct.len() > 90, "only {} distinct frames", distinct.len());
}

#[test]
fn the_seed_changes_the_sensor_noise_and_nothing_else_changes_without_it() {
    let base = scenario("pick_cube.toml");
    let mut reseeded = base.clone();
    reseeded.seed += 1;
    let (a, _) = run(base.clone(), 5);
    let (b, _) = run(reseeded.clone(), 5);
    assert!(a.iter().zip(&b).all(|(x, y)| x != y), "a different seed must give different noise");

    // Without noise the seed has no effect on these scenes (shades are given explicitly).
    let quiet = |mut s: Scenario| {
        for c in &mut s.cameras {
            c.noise_sigma = 0.0;
        }
        s
    };
    let (c, _) = run(quiet(base), 5);
    let (d, _) = run(quiet(reseeded), 5);
    assert_eq!(c, d);
    assert_ne!(a, c, "noise is really applied");
}

#[test]
fn lockstep_loop_without_a_daemon_steps_on_and_hashes_every_frame() {
    let mut runner = Runner::new(Simulator::new(scenario("clutter3.toml")).expect("simulator")).expect("renderer");
    let options = RunOptions { frames: Some(12), reply_timeout: std::time::Duration::from_secs(5), stop_on_success: false };
    let stats = run_lockstep(&mut runner, &mut NoTransport::new(), &options, None).expect("run");
    assert_eq!(stats.frames, 12);
    assert_eq!(stats.reply_timeouts, 0, "no daemon attached: no waiting");
    assert_eq!(runner.sim.frames(), 12);
    assert_eq!(runner.hash.frames, 12);
    // Same again gives the same hash.
    let mut again = Runner::new(Simulator::new(scenario("clutter3.toml")).expect("simulator")).expect("renderer");
    let stats2 = run_lockstep(&mut again, &mut NoTransport::new(), &options, None).expect("run");
    assert_eq!(stats.frames_hash, stats2.frames_hash);
}
