//! End to end, two processes over shared memory, lockstep: the simulator and the daemon
//! pick blocks (`handeye run`). The simulator judges from ground truth.

mod e2e_support;

use e2e_support::{run, RunResult};

/// What every successful pick must show: lifted and held (ground truth), the daemon done,
/// a converged servo with the plate near-coplanar, the loop's timing, and a full report.
fn assert_picked(r: &RunResult, max_plane_mm: f64, max_angle_deg: f64) {
    let why = r.explain();
    assert_eq!(r.summary["success"], true, "{why}");
    assert_eq!(r.status, 0, "{why}");
    assert_eq!(r.summary["phase_reached"], "done", "{why}");
    assert!(r.summary["failure_reason"].is_null(), "{why}");
    assert!(r.f("servo_steps") >= 1.0, "{why}");
    let (plane, angle) = (r.f("final_plane_error_mm"), r.f("final_angle_error_deg"));
    assert!(plane <= max_plane_mm, "plate {plane:.2} mm off the facet plane at convergence\n{why}");
    assert!(angle <= max_angle_deg, "plate {angle:.2}° off parallel at convergence\n{why}");
    assert!(r.f("loop_us_p50") > 0.0 && r.f("loop_us_p99") >= r.f("loop_us_p50"), "{why}");
    assert!(r.f("max_lift_mm") >= 50.0, "{why}");
    // The report: overlays at key moments, the servo plot, both JSONs and both logs.
    let files: Vec<String> = std::fs::read_dir(&r.out.0).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    for want in ["servo_convergence.svg", "daemon.json", "sim.json", "run.json", "hint.json", "daemon.toml", "sim.stderr.log", "daemon.stderr.log"] {
        assert!(files.iter().any(|f| f == want), "{want} missing from the report: {files:?}");
    }
    for moment in ["gripper_acquired", "calibrated", "servo_converged", "grasped", "lifted"] {
        assert!(files.iter().any(|f| f.ends_with(&format!("_{moment}.png"))), "no overlay at {moment}: {files:?}");
    }
    // Every frame the simulator published was answered by the daemon's command for it.
    assert_eq!(r.sim.reply_timeouts, 0, "{why}");
    assert_eq!(r.sim.commands_rejected, 0, "{why}");
}

// Bounds: the issue's, <= 2 mm off the facet's plane and <= 1° from parallel at convergence,
// for every pick. Measured (BENCHMARKS.md, "Closed loop"): 0.02-0.9 mm and 0.01-0.54° over
// the scenarios and ten seeds of pick_cube; a goal imaged once from one look at the wedge's
// small triangle had left the plate 3.8 mm and 4.6° off.

#[test]
fn pick_cube_grasps_and_lifts() {
    let r = run("pick_cube.toml", &[]);
    assert_picked(&r, 2.0, 1.0);
    // Calibration: 8 cage points, residual a few pixels (weak perspective over the cage).
    assert_eq!(r.daemon["calibration"]["points"], 8, "{}", r.explain());
    assert!(r.daemon["calibration"]["residual_rms_px"].as_f64().unwrap() < 8.0);
}

/// With the operator hint: the planner does not find the wedge's triangular ends (dark
/// faces on the dark table), the only faces a grasp from above can use, so the daemon
/// cannot plan this one itself (see BENCHMARKS.md, "Closed loop"); the servo on a
/// triangle is what this test is about.
#[test]
fn pick_wedge_grasps_and_lifts() {
    let r = run("pick_wedge.toml", &["--hint"]);
    assert_picked(&r, 2.0, 1.0);
}

/// The left camera is knocked 3° mid-servo: the daemon stops the arm, re-acquires the view,
/// corrects that camera's model by the image shift and finishes the servo and the grasp.
#[test]
fn pick_cube_bump_recovers_from_the_knocked_camera() {
    let r = run("pick_cube_bump.toml", &[]);
    assert_picked(&r, 2.0, 1.0);
    assert_eq!(r.daemon["recoveries"], 1, "{}", r.explain());
    let files: Vec<String> = std::fs::read_dir(&r.out.0).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(files.iter().any(|f| f.ends_with("_camera_moved.png")) && files.iter().any(|f| f.ends_with("_reacquired.png")), "{files:?}");
}

/// Seeds move the cube (±20 mm, ±15°) and change noise and hint errors; a few run in CI,
/// all ten in `ten_seeds_of_pick_cube` (ignored: about a minute).
#[test]
fn pick_cube_succeeds_over_three_seeds() {
    for seed in [2, 3, 5] {
        let r = run("pick_cube.toml", &["--seed", &seed.to_string()]);
        assert_eq!(r.summary["seed"], seed, "{}", r.explain());
        assert_picked(&r, 2.0, 1.0);
    }
}

#[test]
#[ignore = "about a minute; its numbers are in BENCHMARKS.md"]
fn ten_seeds_of_pick_cube() {
    let mut ok = 0;
    for seed in 1..=10u64 {
        let r = run("pick_cube.toml", &["--seed", &seed.to_string()]);
        let s = &r.summary;
        eprintln!(
            "seed {seed}: success {} plane {:.2} mm angle {:.2}° steps {} p50 {:.0} µs p99 {:.0} µs wall {:.1} s {}",
            s["success"],
            r.f("final_plane_error_mm"),
            r.f("final_angle_error_deg"),
            s["servo_steps"],
            r.f("loop_us_p50"),
            r.f("loop_us_p99"),
            r.f("wall_s"),
            s["failure_reason"]
        );
        ok += usize::from(s["success"] == true);
    }
    assert!(ok >= 9, "{ok}/10 seeds succeeded");
}
