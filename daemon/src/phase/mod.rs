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
pub use step::{timed_out, Cmd, Cycle, MovePoll, MoveWait, Step};

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
    /// (by `recovery::slot_index`: gripper left, right, target left, right).
    pub fn resume(&mut self, m: &mut Mission, now_ns: u64, held_ns: u64, knock: Option<(View, [f64; 2])>, shifts_px: [Option<[f64; 2]>; 4]) {
        let far = |d: Option<[f64; 2]>| d.map_or(0.0, |d| d[0].hypot(d[1]));
        match self {
            Self::Calibrate(p) => p.resume(now_ns, held_ns, far(shifts_px[0]).max(far(shifts_px[1]))),
            Self::Point(p) => p.resume(held_ns),
            Self::Plan(p) => p.resume(held_ns),
            Self::AcquireTarget(p) => p.resume(held_ns),
            Self::Servo(p) => p.resume(m, held_ns, knock, far(shifts_px[2]).max(far(shifts_px[3]))),
            Self::AcquireGripper(_) | Self::Grasp(_) | Self::Lift(_) | Self::Done { .. } | Self::Failed | Self::Stopped => {}
        }
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
        // A target that cannot be acquired or served: the plan's next grasp site, if any.
        if let Step::Fail(fault) = &step
            && matches!(self, Self::AcquireTarget(_))
            && m.next_target(&fault.detail)
        {
            *self = Self::AcquireTarget(acquire_target::AcquireTarget::new(c.time_ns));
            return Step::Stay(Cmd::HOLD);
        }
        if let Step::Next(_) = step {
            *self = match self {
                Self::AcquireGripper(_) => Self::Calibrate(calibrate::Calibrate::new(c.time_ns)),
                // With a target from the operator hint there is nothing to plan.
                Self::Calibrate(_) if m.targeting.target().is_some() => Self::AcquireTarget(acquire_target::AcquireTarget::new(c.time_ns)),
                // Without an indicated point the operator is asked to point.
                Self::Calibrate(_) if m.targeting.indicated_m().is_none() => Self::Point(point::PointPhase::new(c.time_ns)),
                Self::Calibrate(_) | Self::Point(_) => Self::Plan(plan::PlanPhase::new(c.time_ns)),
                Self::Plan(_) => Self::AcquireTarget(acquire_target::AcquireTarget::new(c.time_ns)),
                Self::AcquireTarget(_) => match servo::ServoPhase::new(m, c) {
                    Ok(p) => Self::Servo(Box::new(p)),
                    Err(fault) if m.next_target(&fault.detail) => Self::AcquireTarget(acquire_target::AcquireTarget::new(c.time_ns)),
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
