//! End to end, two processes, lockstep (`handeye run`): the daemon rides out a disturbance
//! mid-task and still picks the block (issue 18). Each scenario loses a tracker (an
//! occluder, a nudged block, a knocked camera) or changes the light; the daemon must hold the
//! arm while a tracker it works with is lost, find the contour again and finish: the block
//! lifted (ground truth), the plate within 2 mm / 1° of the facet at convergence, and the
//! simulator's judge saw no move command answer a frame on which such a tracker was lost.

mod e2e_support;

use e2e_support::{run, RunResult};

/// Picked (as `e2e_pick.rs` judges it) and never moved on a lost track.
fn assert_picked_safely(r: &RunResult) {
    let why = r.explain();
    assert_eq!(r.summary["success"], true, "{why}");
    assert_eq!(r.summary["phase_reached"], "done", "{why}");
    let (plane, angle) = (r.f("final_plane_error_mm"), r.f("final_angle_error_deg"));
    assert!(plane <= 2.0, "plate {plane:.2} mm off the facet plane at convergence\n{why}");
    assert!(angle <= 1.0, "plate {angle:.2}° off parallel at convergence\n{why}");
    assert!(r.f("max_lift_mm") >= 50.0, "{why}");
    assert_eq!(r.sim.daemon.moves_on_lost_track, 0, "the arm was moved on a lost track (first on frame {:?})\n{why}", r.sim.daemon.first_move_on_lost_track_frame);
    assert_eq!(r.daemon["moves_refused"], 0, "a phase asked for a move on a lost track\n{why}");
    assert_eq!(r.sim.reply_timeouts, 0, "{why}");
}

/// The losses the daemon recovered from, and how long it held for them.
fn recovered(r: &RunResult) -> (u64, f64) {
    (r.daemon["recoveries"].as_u64().unwrap_or(0), r.daemon["held_s"].as_f64().unwrap_or(0.0))
}

/// A box crosses in front of the cube mid-servo: the arm stops within three frames of the
/// facet being hidden, holds while the box passes, and the servo finishes on the facet
/// found again.
#[test]
fn an_occluder_crossing_mid_servo_is_waited_out_and_the_cube_lifted() {
    let r = run("pick_cube_occluder.toml", &[]);
    assert_picked_safely(&r);
    let why = r.explain();
    let w = &r.sim.daemon;
    let hidden = w.target_hidden_frame.expect("the occluder hid the target");
    let stop = w.first_stop_command_frame.expect("a Stop command when the target was lost");
    assert!(stop <= hidden + 3, "hidden on frame {hidden}, Stop answered frame {stop}\n{why}");
    let (n, held_s) = recovered(&r);
    assert!(n >= 1 && held_s > 0.0, "recoveries {n}, held {held_s:.2} s\n{why}");
    // The run's own report (run.json, the summary printed) names the loss: the target's
    // tracker lost in the servo, searched for and recovered, and the time held.
    let rec = &r.summary["recovery"];
    let named = rec["losses"].as_array().is_some_and(|losses| {
        losses.iter().any(|l| {
            l["phase"] == "servo"
                && l["what"].as_str().is_some_and(|w| w.contains("target tracker"))
                && l["outcome"].as_str().is_some_and(|o| o.starts_with("recovered"))
                && l["search_passes"].as_u64().is_some()
        })
    });
    assert!(named, "run.json does not name the recovered target loss: {rec}\n{why}");
    assert_eq!(rec["held_s"].as_f64(), Some(held_s), "run.json's held time is the daemon's\n{why}");
}

/// The cube is pushed 25 mm and turned 15° mid-servo: the servo starts again on the facet
/// where it went and picks the cube there.
#[test]
fn a_cube_nudged_mid_servo_is_followed_and_lifted() {
    let r = run("pick_cube_nudge.toml", &[]);
    assert_picked_safely(&r);
}

/// The light dims by 30 % over a second mid-servo: the pick still succeeds.
#[test]
fn a_light_dimmed_mid_servo_does_not_stop_the_pick() {
    let r = run("pick_cube_light.toml", &[]);
    assert_picked_safely(&r);
}

/// The right camera is knocked 2° during the calibration: the plate is found again in the
/// moved view and the cage visited again, and the cube is picked.
#[test]
fn a_camera_knocked_during_calibration_is_recalibrated_and_the_cube_lifted() {
    let r = run("pick_cube_bump_calibrate.toml", &[]);
    assert_picked_safely(&r);
    let (n, _) = recovered(&r);
    assert!(n >= 1, "recoveries {n}\n{}", r.explain());
}
