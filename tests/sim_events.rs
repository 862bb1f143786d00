//! Scripted disturbances fire on simulated time and do what they say.

use handeye_sim::glam::DVec3;
use handeye_sim::run::Runner;
use handeye_sim::scenario::Event;
use handeye_sim::{Scenario, Simulator};

fn scenario(name: &str) -> Scenario {
    Scenario::load(format!("{}/scenarios/{name}", env!("CARGO_MANIFEST_DIR"))).expect("scenario")
}

fn optical_axis(sim: &Simulator, cam: usize) -> DVec3 {
    sim.events.cameras[cam].camera_from_robot_rot.row(2)
}

#[test]
fn camera_bump_turns_one_camera_by_its_angle_at_its_time() {
    let mut sim = Simulator::new(scenario("pick_cube_bump.toml")).expect("simulator");
    let (left0, right0) = (optical_axis(&sim, 0), optical_axis(&sim, 1));
    // At the event's time (frames at 30 frames/s): unchanged through the frame before,
    // bumped once the frame at that time starts.
    let at_s = sim.scenario.events.iter().find_map(|e| matches!(e, Event::CameraBump { .. }).then(|| e.at_s())).expect("a bump");
    let at_frame = (at_s * f64::from(sim.scenario.render.frame_rate_hz)).round() as usize;
    for _ in 0..at_frame {
        sim.step_frame();
    }
    assert_eq!(optical_axis(&sim, 0), left0, "not before {at_s} s");
    sim.step_frame();
    let angle = optical_axis(&sim, 0).angle_between(left0).to_degrees();
    assert!((angle - 3.0).abs() < 1e-6, "left camera turned {angle}°");
    assert_eq!(optical_axis(&sim, 1), right0, "the right camera stays");
    let bumped = optical_axis(&sim, 0);
    for _ in 0..30 {
        sim.step_frame();
    }
    assert_eq!(optical_axis(&sim, 0), bumped, "a bump happens once");
}

#[test]
fn target_nudge_moves_and_turns_the_block() {
    let mut s = scenario("pick_cube.toml");
    s.events.push(Event::TargetNudge { at_s: 0.5, block: "cube".into(), translate_mm: [20.0, -10.0], rotate_deg: 15.0 });
    let mut sim = Simulator::new(s).expect("simulator");
    let (_, before) = sim.block_pose(0);
    for _ in 0..45 {
        sim.step_frame();
    }
    let (_, after) = sim.block_pose(0);
    let moved = after.translation - before.translation;
    assert!((moved - DVec3::new(0.02, -0.01, 0.0)).length() < 1e-3, "moved {moved}");
    let yaw = |m: &handeye_sim::glam::DAffine3| m.matrix3.x_axis.y.atan2(m.matrix3.x_axis.x).to_degrees();
    assert!((yaw(&after) - yaw(&before) - 15.0).abs() < 0.5, "turned {}°", yaw(&after) - yaw(&before));
}

fn mean(pixels: &[u8]) -> f64 {
    pixels.iter().map(|&p| f64::from(p)).sum::<f64>() / pixels.len() as f64
}

#[test]
fn occluder_crosses_the_left_view_and_leaves() {
    let mut s = scenario("pick_cube.toml");
    for c in &mut s.cameras {
        c.noise_sigma = 0.0;
    }
    // Multisampling shows the resting bodies' last sub-pixel settling as changed edge greys;
    // this test is about the occluder, so every pixel must come back exactly.
    s.render.antialias = false;
    // A dark bar sweeping across in front of the left camera between 0.2 s and 0.8 s.
    s.events.push(Event::Occluder {
        at_s: 0.2,
        duration_s: 0.6,
        from_m: [1.2, -0.45, 0.55],
        to_m: [1.2, 0.05, 0.55],
        size_mm: [30.0, 80.0, 400.0],
        shade: 0.1,
    });
    let mut runner = Runner::new(Simulator::new(s).expect("simulator")).expect("renderer");
    let view = (runner.renderer.width() * runner.renderer.height()) as usize;
    let mut frame = vec![0u8; runner.renderer.frame_bytes()];
    runner.render_into(&mut frame).expect("render");
    let clear_left = frame[..view].to_vec();
    let mut max_changed = 0usize;
    for n in 1..=30 {
        runner.sim.step_frame();
        runner.render_into(&mut frame).expect("render");
        let changed = frame[..view].iter().zip(&clear_left).filter(|(a, b)| a != b).count();
        if (8..=22).contains(&n) {
            max_changed = max_changed.max(changed);
        }
        if n >= 26 {
            assert_eq!(changed, 0, "frame {n}: the occluder has gone, the (still) scene is as before");
        }
    }
    assert!(max_changed > 5000, "occluder covered only {max_changed} px");
}

#[test]
fn light_change_ramps_the_brightness() {
    let mut s = scenario("pick_cube.toml");
    for c in &mut s.cameras {
        c.noise_sigma = 0.0;
    }
    s.events.push(Event::LightChange { at_s: 0.1, ramp_s: 0.5, intensity: 0.2, ambient: 0.15, direction: None });
    let mut runner = Runner::new(Simulator::new(s).expect("simulator")).expect("renderer");
    let mut frame = vec![0u8; runner.renderer.frame_bytes()];
    let mut means = Vec::new();
    for _ in 0..25 {
        runner.render_into(&mut frame).expect("render");
        means.push(mean(&frame));
        runner.sim.step_frame();
    }
    let lighting = runner.sim.events.lighting;
    assert!((lighting.intensity - 0.2).abs() < 1e-12 && (lighting.ambient - 0.15).abs() < 1e-12);
    // Before: bright; during the ramp: falling every frame; after: dark and steady.
    assert!(means[2] > means[24] + 20.0, "{means:?}");
    for w in means[4..18].windows(2) {
        assert!(w[1] < w[0], "brightness falls during the ramp: {means:?}");
    }
    assert_eq!(means[20], means[24]);
}
