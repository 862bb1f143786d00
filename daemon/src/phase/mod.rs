//! The daemon's phases (METHOD.md §1, §3, §4, §6): acquire gripper → calibrate → point
//! (unless an indicated point or a hint was given: the operator points at the block) → plan
//! (unless an operator hint names the target) → acquire target → servo → grasp → lift → done, each
//! with a time-out and a typed failure; `failed` and `stopped` end a run. One file per
//! phase; what they share lives in modules of its own ([`step`]: commands, steps, moves;
//! [`job`]: worker jobs; [`crate::mission`]: the state across phases). A phase never
//! names another phase; this module only dispatches.
//!
//! A phase's `step` runs once per frame, after the trackers were updated on that frame, and
//! returns what to send now and whether to move on. Nothing here allocates in the servo's
//! steady state; the moments that do (copying frames for gripper location, snapshots for the
//! report) are marked.

pub mod acquire_gripper;
pub mod acquire_target;
pub mod calibrate;
pub mod grasp;
pub mod job;
pub mod plan;
pub mod point;
pub mod servo;
pub mod step;

pub use job::WORKER_DELAY_FRAMES;
pub use step::{timed_out, Cmd, Cycle, MovePoll, MoveWait, Resumed, Step};

use handeye_vision::tracker::View;
use handeye_wire::Phase;

use crate::mission::Mission;

/// The phase state machine's current phase with its local state.
pub enum PhaseState {
    AcquireGripper(acquire_gripper::AcquireGripper),
    Calibrate(calibrate::Calibrate),
    Point(point::PointPhase),
    Plan(plan::PlanPhase),
    AcquireTarget(acquire_target::AcquireTarget),
    Servo(Box<servo::ServoPhase>),
    Grasp(grasp::Grasp),
    Lift(grasp::Lift),
    Done { since_ns: u64 },
    Failed,
    Stopped,
}

impl PhaseState {
    pub fn phase(&self) -> Phase {
        match self {
            Self::AcquireGripper(_) => Phase::AcquireGripper,
            Self::Calibrate(_) => Phase::Calibrate,
            Self::Point(_) => Phase::Point,
            Self::Plan(_) => Phase::Plan,
            Self::AcquireTarget(_) => Phase::AcquireTarget,
            Self::Servo(_) => Phase::Servo,
            Self::Grasp(_) => Phase::Grasp,
            Self::Lift(_) => Phase::Lift,
            Self::Done { .. } => Phase::Done,
            Self::Failed => Phase::Failed,
            Self::Stopped => Phase::Stopped,
        }
    }

    pub fn is_terminal(&self) -> bool {
        matches!(self, Self::Done { .. } | Self::Failed | Self::Stopped)
    }

    /// Picks the phase up again after the arm held `held_ns` of camera time while lost
    /// trackers were searched for ([`crate::recovery`]); `knock`: a camera moved, its view and
    /// image shift; `shifts_px`: how far each re-found contour was from its last good frame
    /// (by `recovery::slot_index`: gripper left, right, target left, right). Says what the
    /// phase did, for the loss's record.
    ///
    /// A plate re-found [`calibrate::CAMERA_MOVED_PX`] or more from where it was lost (the arm
    /// held still) after the calibration and before the servo means a camera moved: the
    /// stereo model, the plan and the target's pixels all belong to the camera as it was, so
    /// the cameras are calibrated again and, for a planned target, the scene planned again
    /// (the servo moves its own model with a knocked view instead).
    /// `tool_m`: the arm's tool position now (calibration checks a far plate against it).
    pub fn resume(&mut self, m: &mut Mission, now_ns: u64, held_ns: u64, knock: Option<(View, [f64; 2])>, shifts_px: [Option<[f64; 2]>; 4], tool_m: [f64; 3]) -> Resumed {
        let far = |d: Option<[f64; 2]>| d.map_or(0.0, |d| d[0].hypot(d[1]));
        let plate_px = far(shifts_px[0]).max(far(shifts_px[1]));
        match self {
            Self::Plan(_) | Self::AcquireTarget(_) if plate_px > calibrate::CAMERA_MOVED_PX => {
                let (view, shift) = if far(shifts_px[0]) >= far(shifts_px[1]) { (View::Left, shifts_px[0]) } else { (View::Right, shifts_px[1]) };
                let shift_px = shift.unwrap_or([0.0; 2]);
                let phase = self.phase();
                tracing::warn!(?view, plate_px, phase = phase.name(), "the plate came back elsewhere after the calibration: a camera moved; calibrating again");
                m.camera_moved(view, shift_px);
                *self = Self::Calibrate(calibrate::Calibrate::new(now_ns));
                Resumed::Recalibrate { view, shift_px }
            }
            Self::Calibrate(p) => {
                let (now_px, max_residual_px) = (calibrate::plate_px(m), m.cfg.calibration.max_residual_px);
                if p.resume(now_ns, held_ns, plate_px, now_px, tool_m.into(), max_residual_px) {
                    Resumed::CageAgain { plate_shift_px: plate_px }
                } else {
                    Resumed::Resumed
                }
            }
            Self::Point(p) => {
                p.resume(held_ns);
                Resumed::Resumed
            }
            Self::Plan(p) => {
                p.resume(held_ns);
                Resumed::Resumed
            }
            Self::AcquireTarget(p) => {
                p.resume(held_ns);
                Resumed::Resumed
            }
            Self::Servo(p) => p.resume(m, held_ns, knock, far(shifts_px[2]).max(far(shifts_px[3]))),
            Self::AcquireGripper(_) | Self::Grasp(_) | Self::Lift(_) | Self::Done { .. } | Self::Failed | Self::Stopped => Resumed::Resumed,
        }
    }

    /// Goes back to the plan phase for a target that was lost and not found again, or could
    /// not be acquired (`why`), if the mission allows it ([`Mission::replan`]; the indicated
    /// point moves by `moved_m` with the target). Only from acquire_target and the servo.
    pub fn replan(&mut self, m: &mut Mission, now_ns: u64, why: &str, moved_m: [f64; 2]) -> bool {
        if !matches!(self, Self::AcquireTarget(_) | Self::Servo(_)) || !m.replan(why, moved_m) {
            return false;
        }
        *self = Self::Plan(plan::PlanPhase::new(now_ns));
        true
    }

    /// On a frame the arm holds for lost trackers: the point phase goes on watching the
    /// operator's gesture (a hand in front of the plate is why it was lost); the other phases
    /// wait.
    pub fn keep_watching(&mut self, m: &mut Mission, c: &Cycle<'_>) {
        if let Self::Point(p) = self {
            p.keep_watching(m, c.frame_index, c.frame_id, c.time_ns, c.left, c.right);
        }
    }

    /// Runs the current phase for one cycle; on `Next` builds the following phase.
    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        let step = match self {
            Self::AcquireGripper(p) => p.step(m, c),
            Self::Calibrate(p) => p.step(m, c),
            Self::Point(p) => p.step(m, c),
            Self::Plan(p) => p.step(m, c),
            Self::AcquireTarget(p) => p.step(m, c),
            Self::Servo(p) => p.step(m, c),
            Self::Grasp(p) => p.step(m, c),
            Self::Lift(p) => p.step(m, c),
            Self::Done { .. } | Self::Failed | Self::Stopped => return Step::Stay(Cmd::HOLD),
        };
        // A target that cannot be acquired or served: the plan's next grasp site, if any, else
        // the scene planned again from a fresh pair (it may have moved).
        if let Step::Fail(fault) = &step
            && matches!(self, Self::AcquireTarget(_))
        {
            if m.next_target(&fault.detail) {
                *self = Self::AcquireTarget(acquire_target::AcquireTarget::new(c.time_ns));
                return Step::Stay(Cmd::HOLD);
            }
            if self.replan(m, c.time_ns, &fault.detail, [0.0; 2]) {
                return Step::Stay(Cmd::HOLD);
            }
        }
        if let Step::Next(_) = step {
            *self = match self {
                Self::AcquireGripper(_) => Self::Calibrate(calibrate::Calibrate::new(c.time_ns)),
                // With a target from the operator hint there is nothing to plan.
                Self::Calibrate(_) if m.targeting.target().is_some() => Self::AcquireTarget(acquire_target::AcquireTarget::new(c.time_ns)),
                // Without an indicated point the operator is asked to point.
                Self::Calibrate(_) if m.targeting.indicated_m().is_none() => Self::Point(point::PointPhase::new(c.time_ns)),
                Self::Calibrate(_) | Self::Point(_) => Self::Plan(plan::PlanPhase::new(c.time_ns)),
                // A pointed point that picked no one block was forgotten: point again.
                Self::Plan(_) if m.targeting.target().is_none() && m.targeting.indicated_m().is_none() => Self::Point(point::PointPhase::new(c.time_ns)),
                Self::Plan(_) => Self::AcquireTarget(acquire_target::AcquireTarget::new(c.time_ns)),
                Self::AcquireTarget(_) => match servo::ServoPhase::new(m, c) {
                    Ok(p) => Self::Servo(Box::new(p)),
                    Err(fault) if m.next_target(&fault.detail) => Self::AcquireTarget(acquire_target::AcquireTarget::new(c.time_ns)),
                    Err(fault) if m.replan(&fault.detail, [0.0; 2]) => Self::Plan(plan::PlanPhase::new(c.time_ns)),
                    Err(fault) => return Step::Fail(fault),
                },
                Self::Servo(p) => Self::Grasp(grasp::Grasp::new(c.time_ns, p.approach_m)),
                Self::Grasp(_) => Self::Lift(grasp::Lift::new(c.time_ns)),
                Self::Lift(_) => Self::Done { since_ns: c.time_ns },
                Self::Done { .. } | Self::Failed | Self::Stopped => Self::Failed,
            };
        }
        step
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mission::{TargetSource, TargetSpec};
    use handeye_vision::tracker::{ContourTracker, Role, TrackerConfig};
    use handeye_wire::hint::OperatorHint;

    fn square(x: f64) -> Vec<[f64; 2]> {
        vec![[x, 100.0], [x + 40.0, 100.0], [x + 40.0, 140.0], [x, 140.0]]
    }

    fn mission(hint: Option<&OperatorHint>) -> Mission {
        let mut m = Mission::new(crate::config::DaemonConfig::default(), hint).unwrap();
        for v in View::ALL {
            m.trackers.insert(Role::Target, v, ContourTracker::new(TrackerConfig::default(), &square(100.0)).unwrap());
        }
        m
    }

    fn planned() -> TargetSpec {
        TargetSpec { source: TargetSource::Plan, left_px: square(100.0), right_px: square(90.0), depth_m: 0.03, site_px: None, site_template: None, grasp_tool_z_m: None }
    }

    #[test]
    fn a_plate_found_elsewhere_after_the_calibration_calibrates_and_plans_again() {
        let mut m = mission(None);
        m.targeting.set_target(planned());
        m.targeting.set_alternatives(vec![planned()]);
        // The right view's plate came back 60 px away with the arm held: that camera moved.
        let shifts = [None, Some([-58.0, -15.5]), None, None];
        let mut phase = PhaseState::AcquireTarget(acquire_target::AcquireTarget::new(0));
        let resumed = phase.resume(&mut m, 5_000_000_000, 400_000_000, None, shifts, [0.3, 0.0, 0.18]);
        assert_eq!(resumed, Resumed::Recalibrate { view: View::Right, shift_px: [-58.0, -15.5] });
        assert_eq!(phase.phase(), Phase::Calibrate);
        assert!(m.targeting.target().is_none() && m.targeting.alternatives_left() == 0, "the planned target is planned again");
        assert!(View::ALL.iter().all(|&v| m.trackers.get(Role::Target, v).is_none()), "the old target's trackers go");
        assert_eq!(m.calibration.recalibrations(), 1);
        assert!(resumed.to_string().contains("right camera moved (plate 60 px away)"), "{resumed}");
        // A few pixels (an arm stopping) is no camera move: the phase goes on.
        let mut phase = PhaseState::Plan(plan::PlanPhase::new(0));
        let resumed = phase.resume(&mut m, 5_000_000_000, 400_000_000, None, [Some([3.0, 1.0]), None, None, None], [0.3, 0.0, 0.18]);
        assert_eq!((resumed, phase.phase()), (Resumed::Resumed, Phase::Plan));
    }

    #[test]
    fn a_hints_outline_follows_the_moved_views_image() {
        let hint = OperatorHint { version: handeye_wire::hint::HINT_VERSION, left_px: square(100.0), right_px: square(90.0), depth_mm: 30.0, note: String::new() };
        let mut m = mission(Some(&hint));
        let mut phase = PhaseState::AcquireTarget(acquire_target::AcquireTarget::new(0));
        phase.resume(&mut m, 5_000_000_000, 0, None, [Some([20.0, -30.0]), None, None, None], [0.3, 0.0, 0.18]);
        assert_eq!(phase.phase(), Phase::Calibrate);
        let t = m.targeting.target().expect("the hint stays the target");
        assert_eq!(t.left_px[0], [120.0, 70.0]);
        assert_eq!(t.right_px, square(90.0));
    }

    #[test]
    fn a_lost_planned_target_is_planned_again_with_the_point_moved_and_only_so_often() {
        let mut m = mission(None);
        m.targeting.set_indicated_m(Some([0.40, 0.02, 0.06]));
        m.targeting.set_target(planned());
        let mut phase = PhaseState::AcquireTarget(acquire_target::AcquireTarget::new(0));
        assert!(phase.replan(&mut m, 1, "target tracker (Right) confidence 0.00 < 0.45", [0.02, -0.01]));
        assert_eq!(phase.phase(), Phase::Plan);
        assert!(m.targeting.target().is_none() && View::ALL.iter().all(|&v| m.trackers.get(Role::Target, v).is_none()));
        let p = m.targeting.indicated_m().unwrap();
        assert!((p[0] - 0.42).abs() < 1e-12 && (p[1] - 0.01).abs() < 1e-12 && p[2] == 0.06, "{p:?}");
        // Not from the plan phase itself, and at most MAX_REPLANS a run.
        assert!(!phase.replan(&mut m, 2, "again", [0.0; 2]));
        for k in 1..crate::mission::MAX_REPLANS {
            m.targeting.set_target(planned());
            let mut phase = PhaseState::AcquireTarget(acquire_target::AcquireTarget::new(0));
            assert!(phase.replan(&mut m, 3, "again", [0.0; 2]), "re-plan {k}");
        }
        m.targeting.set_target(planned());
        let mut phase = PhaseState::AcquireTarget(acquire_target::AcquireTarget::new(0));
        assert!(!phase.replan(&mut m, 4, "once too often", [0.0; 2]));
        assert_eq!(phase.phase(), Phase::AcquireTarget);
        // An operator hint names one facet: nothing to plan again.
        let hint = OperatorHint { version: handeye_wire::hint::HINT_VERSION, left_px: square(100.0), right_px: square(90.0), depth_mm: 30.0, note: String::new() };
        let mut m = mission(Some(&hint));
        m.targeting.set_indicated_m(Some([0.40, 0.02, 0.06]));
        assert!(!phase.replan(&mut m, 5, "hint", [0.0; 2]));
    }
}
