//! What stops the arm: a robot fault or a reading that makes no sense, a lost tracker in a
//! phase that needs it. (A stale or vanished camera stream is caught by the transport loop,
//! which knows the wall clock.) Each check returns the fault, worded for the operator.

use handeye_vision::tracker::{Role, StereoStates, StereoTrackerSet, TrackState, View};
use handeye_wire::report::FailureKind;
use handeye_wire::{robot_flags, Phase, RobotState};

use crate::config::SafetyConfig;
use crate::fault::Fault;

/// Which phases need which trackers tracking, `(gripper, target)` (a lost one stops the arm).
pub fn needs_trackers(phase: Phase) -> (bool, bool) {
    match phase {
        // While the target trackers converge the arm holds still: acquire_target judges them
        // itself at the end (and may try the plan's next grasp site instead).
        // Point: a hand passing in front of the parked plate holds the arm while the plate is
        // searched for; the gesture is watched meanwhile (`PhaseState::keep_watching`).
        Phase::Calibrate | Phase::Point | Phase::Plan | Phase::AcquireTarget => (true, false),
        Phase::Servo => (true, true),
        _ => (false, false),
    }
}

/// A reading that makes no sense.
fn nonsense(detail: String) -> Fault {
    Fault::new(FailureKind::RobotState, detail)
}

/// Checks one robot state reading against the previous one.
pub fn check_robot(cfg: &SafetyConfig, previous: Option<&RobotState>, s: &RobotState) -> Result<(), Fault> {
    if s.flags & robot_flags::FAULT != 0 {
        return Err(Fault::new(FailureKind::RobotFault, format!("robot fault (code {})", s.fault)));
    }
    // The watchdog's flag stays up until the next move. Raised before this daemon's first
    // reading it is the previous commander's (a daemon killed mid-move): the arm is already
    // still, and the next move clears it. Only a flag raised while this daemon commands is its
    // own fault (its commands arrived late).
    let watchdog_raised = |r: &RobotState| r.flags & robot_flags::WATCHDOG_STOP != 0;
    if watchdog_raised(s) && previous.is_some_and(|p| !watchdog_raised(p)) {
        return Err(Fault::new(FailureKind::RobotFault, "robot watchdog stopped the arm (commands arrived late)"));
    }
    let p = s.tool_pos_m.map(f64::from);
    if (0..3).any(|i| !(p[i] >= cfg.workspace_min_m[i] && p[i] <= cfg.workspace_max_m[i])) {
        return Err(nonsense(format!("nonsense robot state: tool at ({:.3}, {:.3}, {:.3}) m, outside the workspace", p[0], p[1], p[2])));
    }
    if let Some(prev) = previous {
        let q = prev.tool_pos_m.map(f64::from);
        let jump = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
        if jump > cfg.max_state_jump_m {
            return Err(nonsense(format!("nonsense robot state: tool jumped {:.0} mm between readings", jump * 1e3)));
        }
        if s.seq <= prev.seq && s.time_ns < prev.time_ns {
            return Err(nonsense("nonsense robot state: sequence went backwards".into()));
        }
    }
    Ok(())
}

/// Checks the trackers a phase depends on.
pub fn check_trackers(cfg: &SafetyConfig, phase: Phase, states: &StereoStates, trackers: &StereoTrackerSet) -> Result<(), Fault> {
    let (gripper, target) = needs_trackers(phase);
    for (role, needed, name) in [(Role::Gripper, gripper, "gripper"), (Role::Target, target, "target")] {
        if !needed || !View::ALL.iter().all(|&v| trackers.is_active(role, v)) {
            continue;
        }
        for view in View::ALL {
            let side = if view == View::Left { "left" } else { "right" };
            match states.get(role, view) {
                Some(TrackState::Lost(why)) => return Err(Fault::new(FailureKind::TrackerLost, format!("{name} tracker lost ({side} view): {why}"))),
                None => return Err(Fault::new(FailureKind::TrackerLost, format!("{name} tracker ({side} view) did not run"))),
                Some(TrackState::Tracking) => {}
            }
            let score = trackers.get(role, view).map_or(0.0, |t| t.confidence().score);
            let min = if role == Role::Target { cfg.min_target_score } else { cfg.min_tracker_score };
            if score.is_nan() || score < min {
                return Err(Fault::new(FailureKind::TrackerUnsure, format!("{name} tracker ({side} view) confidence {score:.2} < {min}")));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_wire::WIRE_VERSION;

    fn state(p: [f32; 3]) -> RobotState {
        RobotState { version: WIRE_VERSION, seq: 1, time_ns: 10, tool_pos_m: p, gripper_width_m: 0.08, ..Default::default() }
    }

    #[test]
    fn faults_and_nonsense_readings_stop() {
        let cfg = SafetyConfig::default();
        let ok = state([0.3, 0.0, 0.2]);
        assert_eq!(check_robot(&cfg, None, &ok), Ok(()));
        let fault = RobotState { flags: robot_flags::FAULT, fault: 7, ..ok };
        assert_eq!(check_robot(&cfg, None, &fault).unwrap_err(), Fault::new(FailureKind::RobotFault, "robot fault (code 7)"));
        let wd = RobotState { flags: robot_flags::WATCHDOG_STOP, seq: 2, time_ns: 20, ..ok };
        let err = check_robot(&cfg, Some(&ok), &wd).unwrap_err();
        assert!(err.kind == FailureKind::RobotFault && err.detail.contains("watchdog"), "{err:?}");
        // Up before the first reading: the previous commander's, not this daemon's; it stays
        // no fault while it stays up, and is one when it comes back after a move cleared it.
        assert_eq!(check_robot(&cfg, None, &wd), Ok(()));
        let still_up = RobotState { seq: 3, time_ns: 30, ..wd };
        assert_eq!(check_robot(&cfg, Some(&wd), &still_up), Ok(()));
        let far = state([5.0, 0.0, 0.2]);
        let err = check_robot(&cfg, None, &far).unwrap_err();
        assert!(err.kind == FailureKind::RobotState && err.detail.contains("outside the workspace"), "{err:?}");
        let jumped = RobotState { seq: 2, time_ns: 20, ..state([0.3, 0.1, 0.2]) };
        assert!(check_robot(&cfg, Some(&ok), &jumped).unwrap_err().detail.contains("jumped 100 mm"));
        let moved = RobotState { seq: 2, time_ns: 20, ..state([0.301, 0.0, 0.2]) };
        assert_eq!(check_robot(&cfg, Some(&ok), &moved), Ok(()));
    }

    #[test]
    fn lost_trackers_stop_only_phases_that_need_them() {
        use handeye_vision::image::ImageBuf;
        use handeye_vision::tracker::{ContourTracker, TrackerConfig};
        let mut img = ImageBuf::filled(160, 120, 200);
        for y in 40..80 {
            for x in 60..100 {
                img.set(x, y, 50);
            }
        }
        let square = [[59.5, 39.5], [99.5, 39.5], [99.5, 79.5], [59.5, 79.5]];
        let mut set = StereoTrackerSet::new();
        for v in View::ALL {
            set.insert(Role::Target, v, ContourTracker::new(TrackerConfig::default(), &square).unwrap());
            set.insert(Role::Gripper, v, ContourTracker::new(TrackerConfig::default(), &square).unwrap());
        }
        let cfg = SafetyConfig::default();
        let states = set.update(&img.view(), &img.view(), 0.03);
        assert_eq!(check_trackers(&cfg, Phase::Servo, &states, &set), Ok(()));
        // The target disappears (a blank image): lost in servo, irrelevant in calibrate.
        let blank = ImageBuf::filled(160, 120, 200);
        let states = set.update(&blank.view(), &blank.view(), 0.03);
        let err = check_trackers(&cfg, Phase::Servo, &states, &set).unwrap_err();
        assert!(err.kind == FailureKind::TrackerLost && err.detail.contains("tracker lost"), "{err:?}");
        assert_eq!(check_trackers(&cfg, Phase::Grasp, &states, &set), Ok(()));
    }
}
