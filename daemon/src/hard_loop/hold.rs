//! Holding the arm for lost trackers, from the hard loop's side: which trackers a phase has
//! lost, starting a [`Recovery`] and stepping it, resuming the phase or ending the run, the
//! per-loss record, and the one check every command passes before it is stamped (never a
//! move on a lost track).

use handeye_vision::tracker::{Role, StereoStates, StereoTrackerSet, TrackState, View};
use handeye_wire::report::FailureKind;
use handeye_wire::Phase;

use super::HardLoop;
use crate::config::SafetyConfig;
use crate::fault::Fault;
use crate::outcome::LossRecord;
use crate::phase::acquire_gripper::AcquireGripper;
use crate::phase::{Cmd, Cycle, Step};
use crate::recovery::{slot_index, EpipolarCheck, LastGood, LossCause, Recovery, RecoveryStep};
use crate::safety::{check_trackers, needs_trackers};

/// Camera time a target lost in the servo (and nothing else) is searched for before the
/// scene is planned again from a fresh pair, s: a target turned by a nudge does not come back
/// by a shifted search, and an occluder crossing it has passed by then (they cross in 1-2 s).
pub const TARGET_SEARCH_S: f64 = 4.0;
/// Camera time a lost plate is searched for before the jaws open and close to locate it, s
/// (a knocked camera's plate is found within 0.5 s; an occluder has passed within 2 s), and
/// counted from when the operator's hand was last seen while it points.
pub const JAWS_AFTER_S: f64 = 3.0;
/// A target displacement measured larger than this is not believed (the indicated point
/// stays), m.
const MAX_TARGET_MOVE_M: f64 = 0.1;
/// ... nor one with a height change over this (a block slides on the table), m ...
const MAX_TARGET_RISE_M: f64 = 0.01;
/// ... nor one from views last tracked this far apart in time (one view followed the block a
/// while, the other did not: the pair is not one moment), ns.
const MAX_VIEW_SKEW_NS: u64 = 100_000_000;

/// The trackers `phase` needs that are lost or below their confidence this cycle (active
/// ones only), with what is wrong with each.
fn lost_trackers(cfg: &SafetyConfig, phase: Phase, states: &StereoStates, trackers: &StereoTrackerSet) -> Vec<(Role, View, LossCause)> {
    let (gripper, target) = needs_trackers(phase);
    let mut lost = Vec::new();
    for (role, needed) in [(Role::Gripper, gripper), (Role::Target, target)] {
        for view in View::ALL {
            if !needed || !trackers.is_active(role, view) {
                continue;
            }
            let min = if role == Role::Target { cfg.min_target_score } else { cfg.min_tracker_score };
            let score = trackers.get(role, view).map_or(0.0, |t| t.confidence().score);
            match states.get(role, view) {
                Some(TrackState::Lost(why)) => lost.push((role, view, LossCause::Tracker(why))),
                None => lost.push((role, view, LossCause::DidNotRun)),
                Some(TrackState::Tracking) if score.is_nan() || score < min => lost.push((role, view, LossCause::Unsure { score, min })),
                Some(TrackState::Tracking) => {}
            }
        }
    }
    lost
}

impl HardLoop {
    /// Remembers each confidently tracking contour's frame: a later search starts there
    /// rather than where a contour drifted to while it was being lost (nor from a candidate still
    /// being confirmed), and only from a frame
    /// whose shape was steady and the contour's own ([`super::shape_watch::ShapeWatch`]), in
    /// every phase (the servo's approach changes the plate's shape fast but smoothly, which
    /// the rule follows).
    pub(super) fn note_good_frames(&mut self, states: &StereoStates, now_ns: u64) {
        let cfg = &self.mission.cfg.safety;
        for role in [Role::Gripper, Role::Target] {
            let min = if role == Role::Target { cfg.min_target_score } else { cfg.min_tracker_score };
            for view in View::ALL {
                let i = slot_index(role, view);
                let Some(t) = self.mission.trackers.get(role, view) else { continue };
                if self.recovery.as_ref().is_some_and(|r| r.holds_for(role, view)) {
                    // A candidate being confirmed is not known good: a search after a relapse
                    // starts from the frame before the loss, not from the candidate.
                    continue;
                }
                let tracking = matches!(states.get(role, view), Some(TrackState::Tracking));
                let frame = t.frame();
                let shape_ok = self.shapes[i].observe(frame, t.update_count(), tracking);
                if tracking && shape_ok && t.confidence().score >= min {
                    self.last_good[i] = Some(LastGood { frame, time_ns: now_ns, velocity_px_s: t.velocity_px_per_s() });
                }
            }
        }
    }

    /// The one place every command passes before it is stamped: a move while a tracker the
    /// phase that asked for it needs is lost, unsure, or being searched for never goes out
    /// (it becomes a hold, and is counted and logged as the bug it would be).
    pub(super) fn refuse_blind_moves(&mut self, cmd: Cmd, phase: Phase, states: &StereoStates) -> Cmd {
        if !cmd.is_move() {
            return cmd;
        }
        let blind = if self.recovery.is_some() {
            Err(Fault::new(FailureKind::TrackerLost, "holding for a lost tracker"))
        } else {
            check_trackers(&self.mission.cfg.safety, phase, states, &self.mission.trackers)
        };
        match blind {
            Ok(()) => cmd,
            Err(why) => {
                self.moves_refused += 1;
                tracing::error!(phase = phase.name(), reason = %why, "a move was asked for on a lost track: holding instead");
                Cmd::HOLD
            }
        }
    }

    /// A tracker `phase` needs is lost (the safety check failed): stops the arm and starts
    /// searching, unless holding is switched off (`safety.loss_patience_s` = 0) or nothing
    /// searchable was lost; `false` then (the caller ends the run).
    pub(super) fn start_hold(&mut self, phase: Phase, frame_id: u64, now_ns: u64, states: &StereoStates) -> bool {
        let lost = lost_trackers(&self.mission.cfg.safety, phase, states, &self.mission.trackers);
        let patience_s = self.mission.cfg.safety.loss_patience_s;
        if patience_s > 0.0 && !lost.is_empty() {
            let cfg = &self.mission.cfg.safety;
            let min_scores = [cfg.min_tracker_score, cfg.min_target_score];
            let rec = Recovery::start(&mut self.mission.trackers, &lost, &self.last_good, now_ns, patience_s, min_scores);
            let what = rec.what();
            tracing::warn!(phase = phase.name(), %what, "tracker lost: holding the arm and searching");
            // Both contours of one view at once: that camera has most likely moved.
            let moved = View::ALL.into_iter().find(|&v| [Role::Gripper, Role::Target].iter().all(|&r| lost.iter().any(|l| l.0 == r && l.1 == v)));
            match moved {
                Some(View::Left) => self.mission.reporting.set_status("left camera moved: holding, re-acquiring"),
                Some(View::Right) => self.mission.reporting.set_status("right camera moved: holding, re-acquiring"),
                None => self.mission.reporting.set_status(&format!("holding: {what}; searching")),
            }
            self.mission.reporting.snapshot(if moved.is_some() { "camera_moved" } else { "lost" });
            self.recovery = Some(rec);
            self.jaws = None;
            self.jaws_tried = false;
            self.loss_began = (phase, frame_id);
            return true;
        }
        false
    }

    /// How far the target moved on the table (x, y, m) between its acquisition and the last
    /// frame its trackers held it confidently in both views, through the stereo model; zero
    /// when unknown.
    fn target_moved_m(&self) -> [f64; 2] {
        let (Some(acquired), Some(cal)) = (self.mission.targeting.acquired_px(), self.mission.calibration.get()) else { return [0.0; 2] };
        let (Some(l), Some(r)) = (self.last_good[slot_index(Role::Target, View::Left)], self.last_good[slot_index(Role::Target, View::Right)]) else {
            return [0.0; 2];
        };
        let now = [l.frame.origin.x, l.frame.origin.y, r.frame.origin.x, r.frame.origin.y];
        let d = cal.model.reconstruct(&now) - cal.model.reconstruct(&acquired);
        let skew_ns = l.time_ns.abs_diff(r.time_ns);
        tracing::debug!(?acquired, ?now, moved_m = ?d, skew_ns, "target's last tracked displacement");
        if !(d.x.is_finite() && d.y.is_finite()) || d.x.hypot(d.y) > MAX_TARGET_MOVE_M || d.z.abs() > MAX_TARGET_RISE_M || skew_ns > MAX_VIEW_SKEW_NS {
            return [0.0; 2];
        }
        [d.x, d.y]
    }

    /// The servo's target (and nothing else) lost for [`TARGET_SEARCH_S`]: plans the scene
    /// again from a fresh pair (the arm parked in view), the indicated point moved with the
    /// target's last tracked displacement; `false` when not due or not allowed.
    fn replan_for_lost_target(&mut self, phase: Phase, now_ns: u64) -> bool {
        let Some(rec) = self.recovery.as_ref() else { return false };
        if phase != Phase::Servo || !rec.only(Role::Target) || !crate::phase::timed_out(rec.start_ns(), now_ns, TARGET_SEARCH_S) {
            return false;
        }
        let (what, start_ns, search_passes, relapses) = (rec.what(), rec.start_ns(), rec.passes(), rec.relapses());
        let outcome = format!("not found again within {TARGET_SEARCH_S:.1} s");
        let moved_m = self.target_moved_m();
        if !self.phase.replan(&mut self.mission, now_ns, &format!("{what}; {outcome}"), moved_m) {
            return false;
        }
        let held_ns = now_ns.saturating_sub(start_ns);
        let (p, frame_id) = self.loss_began;
        let resumed = format!("planning again from a fresh pair; indicated point moved {:.0} mm with the target's last tracked position", moved_m[0].hypot(moved_m[1]) * 1e3);
        self.losses.push(LossRecord { phase: p.name().into(), frame_id, what, held_s: held_ns as f64 * 1e-9, outcome, shifts_px: [None; 4], resumed, search_passes, relapses });
        self.recovery = None;
        self.held_ns += held_ns;
        true
    }

    /// A plate not found by search for [`JAWS_AFTER_S`]: the jaws open and close (as at
    /// start-up, `phase/acquire_gripper.rs`), their motion locates the plate in both views, and
    /// fresh plate trackers converge on it; the search waits meanwhile and the time does not
    /// count against the patience. `Some(cmd)` while the jaws work (gripper commands only:
    /// the arm holds); a failure ends the hold with its reason.
    fn jaws_for_lost_plate(&mut self, c: &Cycle<'_>) -> Option<Cmd> {
        let rec = self.recovery.as_mut()?;
        if self.jaws.is_none() {
            // An operator's hand in view (the point phase) is what hides the plate, and it
            // holds still for seconds: the jaws' motion waits until it has gone (their motion
            // is found by differencing, which the hand's own motion would spoil).
            let since_ns = rec.start_ns().max(self.mission.pointing.hand_seen_ns().unwrap_or(0));
            if self.jaws_tried || !rec.plate_missing() || !crate::phase::timed_out(since_ns, c.time_ns, JAWS_AFTER_S) {
                return None;
            }
            tracing::warn!(what = %rec.what(), "plate not found by search: opening and closing the jaws to locate it");
            self.mission.reporting.set_status("holding: plate not found by search; opening and closing the jaws to locate it");
            self.jaws = Some((AcquireGripper::new(c.time_ns), c.time_ns));
            self.jaws_tried = true;
        }
        let (jaws, since_ns) = self.jaws.as_mut()?;
        let since_ns = *since_ns;
        match jaws.step(&mut self.mission, c) {
            Step::Stay(cmd) => Some(cmd),
            Step::Next(cmd) => {
                self.jaws = None;
                rec.plates_found_by_jaws(&mut self.mission.trackers);
                rec.excuse(c.time_ns.saturating_sub(since_ns));
                tracing::warn!("plate located by the jaws' motion: confirming");
                self.mission.reporting.set_status("holding: plate located by the jaws' motion; confirming");
                Some(cmd)
            }
            Step::Fail(fault) => {
                self.jaws = None;
                let reason = format!("{}; not found by search, and the jaws' motion did not locate it: {}", rec.what(), fault.detail);
                Some(self.end_hold_failed(c.time_ns, reason))
            }
        }
    }

    /// Ends the hold under way as a failure (`reason`): recorded, the run stopped.
    fn end_hold_failed(&mut self, now_ns: u64, reason: String) -> Cmd {
        let Some(rec) = self.recovery.take() else { return Cmd::STOP };
        let (p, frame_id) = self.loss_began;
        let held_s = now_ns.saturating_sub(rec.start_ns()) as f64 * 1e-9;
        let (search_passes, relapses) = (rec.passes(), rec.relapses());
        self.losses.push(LossRecord {
            phase: p.name().into(),
            frame_id,
            what: rec.what(),
            held_s,
            outcome: reason.clone(),
            shifts_px: [None; 4],
            resumed: String::new(),
            search_passes,
            relapses,
        });
        self.jaws = None;
        self.stop_reason(Phase::Stopped, Fault::new(FailureKind::TrackerLost, reason));
        Cmd::STOP
    }

    /// A cycle while holding for lost trackers: contours the phase needs that are lost now
    /// join the search; the search runs (or the jaws locate a plate it did not find); the
    /// phase resumes when all are back, the run stops when the patience is spent.
    pub(super) fn hold_and_search(&mut self, phase: Phase, c: &Cycle<'_>) -> Cmd {
        let (states, now_ns, left, right) = (&c.states, c.time_ns, c.left, c.right);
        if self.replan_for_lost_target(phase, now_ns) {
            return Cmd::HOLD;
        }
        if let Some(cmd) = self.jaws_for_lost_plate(c) {
            return cmd;
        }
        let Some(rec) = self.recovery.as_mut() else { return Cmd::HOLD };
        for (role, view, why) in lost_trackers(&self.mission.cfg.safety, phase, states, &self.mission.trackers) {
            rec.add(&mut self.mission.trackers, role, view, why, &self.last_good, now_ns);
        }
        let epipolar = self.mission.calibration.get().map(|cal| EpipolarCheck {
            constraint: cal.model.epipolar(),
            tol_px: 2.0 * self.mission.cfg.target.max_epipolar_px,
            plate_tol_px: crate::candidate_check::plate_tol_px(cal.stats.residual_rms_px, cal.stats.epipolar_rms_px),
        });
        match rec.step(&mut self.mission.trackers, left, right, now_ns, epipolar.as_ref()) {
            RecoveryStep::Searching => Cmd::HOLD,
            RecoveryStep::Recovered { knock, held_s, shifts_px } => {
                tracing::warn!(?knock, held_s, what = %rec.what(), "lost trackers re-acquired: resuming");
                let held_ns = now_ns.saturating_sub(rec.start_ns());
                let (p, frame_id) = self.loss_began;
                let outcome = match (knock.is_some(), rec.by_jaws()) {
                    (_, true) => "recovered (the plate located by opening and closing the jaws)",
                    (true, false) => "recovered (a camera moved)",
                    (false, false) => "recovered",
                };
                let (what, search_passes, relapses) = (rec.what(), rec.passes(), rec.relapses());
                self.recovery = None;
                self.recoveries += 1;
                self.held_ns += held_ns;
                self.mission.reporting.snapshot("reacquired");
                let resumed = self.phase.resume(&mut self.mission, now_ns, held_ns, knock, shifts_px, c.robot.tool_pos_m.map(f64::from));
                let record = LossRecord { phase: p.name().into(), frame_id, what, held_s, outcome: outcome.into(), shifts_px, resumed: resumed.to_string(), search_passes, relapses };
                self.losses.push(record);
                Cmd::HOLD
            }
            RecoveryStep::Failed(reason) => self.end_hold_failed(now_ns, reason.to_string()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::image::ImageBuf;
    use handeye_vision::tracker::{ContourTracker, TrackerConfig};

    /// A dark square on a light ground, and a loop whose four trackers sit on it.
    fn tracking_loop() -> (HardLoop, ImageBuf) {
        let mut img = ImageBuf::filled(160, 120, 200);
        for y in 40..80 {
            for x in 60..100 {
                img.set(x, y, 50);
            }
        }
        let square = [[59.5, 39.5], [99.5, 39.5], [99.5, 79.5], [59.5, 79.5]];
        let mut hl = HardLoop::new(crate::config::DaemonConfig::default(), None).unwrap();
        for role in [Role::Gripper, Role::Target] {
            for v in View::ALL {
                hl.mission.trackers.insert(role, v, ContourTracker::new(TrackerConfig::default(), &square).unwrap());
            }
        }
        (hl, img)
    }

    #[test]
    fn a_move_on_a_lost_or_searched_track_becomes_a_hold() {
        let (mut hl, img) = tracking_loop();
        let go = Cmd::move_by([0.01, 0.0, 0.0], 0.0, 0.05);
        let states = hl.mission.trackers.update(&img.view(), &img.view(), 0.03);
        // Everything tracks: the servo's move goes out.
        assert_eq!(hl.refuse_blind_moves(go, Phase::Servo, &states), go);
        // The right view goes blank (both its trackers lost): the servo may not move.
        let blank = ImageBuf::filled(160, 120, 200);
        let (s_left, s_right) = (img.view(), blank.view());
        let states = hl.mission.trackers.update(&s_left, &s_right, 0.03);
        assert_eq!(hl.refuse_blind_moves(go, Phase::Servo, &states), Cmd::HOLD);
        assert_eq!(hl.moves_refused(), 1);
        // A hold or a stop always passes.
        assert_eq!(hl.refuse_blind_moves(Cmd::STOP, Phase::Servo, &states), Cmd::STOP);
        // While lost trackers are searched for, no move goes out in any phase.
        let lost = lost_trackers(&hl.mission.cfg.safety, Phase::Servo, &states, &hl.mission.trackers);
        assert!(!lost.is_empty() && lost.iter().all(|l| l.1 == View::Right), "{lost:?}");
        assert!(hl.start_hold(Phase::Servo, 7, 0, &states));
        assert!(hl.recovery.as_ref().is_some_and(|r| r.is_searching(Role::Target, View::Right)));
        assert_eq!(hl.refuse_blind_moves(go, Phase::Calibrate, &states), Cmd::HOLD);
        assert_eq!(hl.moves_refused(), 2);
    }

    #[test]
    fn the_jaws_wait_for_the_operators_hand_to_go() {
        // The parked plate lost in the point phase, behind the operator's hand (seeds 4 and 5
        // of the pointing batch: the jaws moved while the hand held still, their motion was
        // not found among the hand's, and the run stopped before the next gesture).
        let (mut hl, _) = tracking_loop();
        let blank = ImageBuf::filled(160, 120, 200);
        let (l, r) = (blank.view(), blank.view());
        let states = hl.mission.trackers.update(&l, &r, 0.03);
        assert!(hl.start_hold(Phase::Point, 7, 0, &states));
        assert!(hl.recovery.as_ref().is_some_and(|r| r.plate_missing()));
        let robot = handeye_wire::RobotState::default();
        let s = |t: f64| (t * 1e9) as u64;
        let cycle = |t_ns: u64| Cycle { frame_index: t_ns / 33_333_333, time_ns: t_ns, frame_id: 0, robot: &robot, rejected_seq: None, seq: 1, left: &l, right: &r, states };
        // The hand was seen until 2.5 s: 3.5 s into the hold the jaws still wait ...
        hl.mission.pointing.hand_at(s(2.5), true);
        assert_eq!(hl.jaws_for_lost_plate(&cycle(s(3.5))), None);
        assert!(hl.jaws.is_none() && !hl.jaws_tried);
        // ... and move once it has been gone JAWS_AFTER_S.
        assert!(hl.jaws_for_lost_plate(&cycle(s(2.5 + JAWS_AFTER_S + 0.05))).is_some());
        assert!(hl.jaws_tried);
    }
}
