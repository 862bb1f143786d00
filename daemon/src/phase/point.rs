//! Point (thesis ch. 4, METHOD.md §4, issue 19): without an indicated point the daemon asks
//! the operator for one. The arm parks out of the hand's way (`[point] park_m`, towards its
//! base, where no hand comes from) and settles; the scene without the hand is the gesture
//! tracker's background. Every frame then goes, copied, to the gesture tracker on its own
//! thread ([`crate::gesture_thread`]: its ~1.1 ms update stays out of the 1 ms cycle, the
//! gripper trackers keep running at frame rate), and its result comes back a fixed number
//! of frames later.
//!
//! The plane maps carry each view's finger line onto the working plane (the height of the
//! lowest cage points: the plane the indicated point of `--point-m` lies on). They are fitted
//! from the daemon's own calibration: pinhole cameras fitted to the cage (the plate's
//! reference point at each tool position, the tool/plate lever taken off, as the planner
//! does), which then give the pixels of the four lowest cage *tool* points. No ground truth.
//!
//! An answer (`Indicated`) becomes the targeting's indicated point; the daemon waits for the
//! hand to go (the planner must not see it), returns the arm to where the calibration left
//! it, and goes on to plan. A refusal (degenerate, uncertain, unsteady, no line) does not end
//! the watch of a hand that still holds: its window may settle into an answer (a window first
//! uncertain, then steadier), which is taken. A hand that goes unanswered is recorded with its
//! newest refusal and its numbers, and the daemon waits for the next gesture.
//! `[point] timeout_s` ends the run naming every gesture seen. A hand that passes in front of
//! the parked plate does not stop the watching: the arm holds while the plate is searched for
//! ([`crate::recovery`]), and the frames meanwhile still go to the gesture tracker
//! ([`PointPhase::keep_watching`]).

use handeye_vision::pointing::{GestureConfig, GestureState, PlaneHomography, Pointing, PointingTracker};
use handeye_vision::planner::projective::ProjectiveStereo;
use handeye_vision::tracker::{Role, View};
use handeye_wire::report::FailureKind;
use handeye_wire::{robot_flags, RejectReason};
use nalgebra::Vector3;

use super::step::{timed_out, Cmd, Cycle, MovePoll, MoveWait, Step};
use handeye_vision::image::ImageView;

use crate::gesture_thread::{GestureResult, GestureThread};
use crate::gripper::tool_from_reference;
use crate::mission::pointing::GestureRecord;
use crate::mission::Mission;

/// After an answer, how long the daemon waits for the hand to go before it returns the arm
/// and plans anyway, s of camera time.
const WITHDRAW_WAIT_S: f64 = 10.0;

/// How long the arm waits for a lost plate before returning for the plan, s of camera time.
const PLATE_WAIT_S: f64 = 2.0;

#[derive(Debug)]
enum Stage {
    /// Going to the park pose.
    Park { wait: Option<MoveWait> },
    /// Arm still for this many frames.
    Settle { still: u32 },
    /// Watching for gestures; `refusal`: the hand in view was refused so far (the newest
    /// refusal, one from a steady window before any other), recorded when it goes. A hand that still holds may settle into an answer
    /// (a window first uncertain, then steadier): its later states are the same gesture's,
    /// and one that indicates is answered.
    Watch { refusal: Option<Box<GestureRecord>> },
    /// Answered; waiting for the hand to go, since `since_ns`; `gone`: it went.
    Withdraw { since_ns: u64, gone: bool },
    /// Returning the arm to where the calibration left it.
    Return { wait: Option<MoveWait>, since_ns: u64 },
}

pub struct PointPhase {
    start_ns: u64,
    stage: Stage,
    thread: Option<GestureThread>,
    plane_z_m: f64,
}

/// The plane maps of both views from the calibration (module docs), the plane's height and
/// the pinhole fit's RMS residual, px.
pub fn plane_maps(m: &Mission) -> Result<(Pointing, f64, f64), String> {
    let cal = m.calibration.get().ok_or("not calibrated")?;
    let yaw = m.calibration.yaw_rad().ok_or("no calibration yaw")?;
    plane_maps_from(&cal.cage_robot_m, &cal.cage_image_px, &tool_from_reference(&m.cfg.gripper, yaw))
}

/// The same from the cage: tool positions (robot frame, m), the plate reference point's
/// images `(u, v, u', v')` at each, and the lever `tool − reference` at the calibration yaw.
pub fn plane_maps_from(cage_robot_m: &[Vector3<f64>], cage_image_px: &[[f64; 4]], lever_m: &Vector3<f64>) -> Result<(Pointing, f64, f64), String> {
    let reference_m: Vec<Vector3<f64>> = cage_robot_m.iter().map(|x| x - lever_m).collect();
    let cams = ProjectiveStereo::fit(&reference_m, cage_image_px).map_err(|e| format!("pinhole cameras from the cage: {e}"))?;
    let z = cage_robot_m.iter().map(|p| p.z).fold(f64::INFINITY, f64::min);
    let lowest: Vec<&Vector3<f64>> = cage_robot_m.iter().filter(|p| p.z < z + 1e-3).collect();
    if lowest.len() < 4 {
        return Err(format!("{} cage points at the lowest height {z:.3} m: the plane maps need 4", lowest.len()));
    }
    let plane: Vec<[f64; 2]> = lowest.iter().map(|p| [p.x, p.y]).collect();
    let px: Vec<[f64; 4]> = lowest.iter().map(|p| cams.project(&Vector3::new(p.x, p.y, z))).collect();
    let fit = |k: usize| {
        let view: Vec<[f64; 2]> = px.iter().map(|w| [w[2 * k], w[2 * k + 1]]).collect();
        PlaneHomography::fit(&plane, &view).map_err(|e| format!("plane map of the {} view: {e}", ["left", "right"][k]))
    };
    Ok((Pointing::new(fit(0)?, fit(1)?), z, cams.residual_rms_px))
}

/// How much a refusal says about the gesture, for keeping the most telling one of a hand:
/// one from a steady window (the hand held still: uncertain, degenerate, disagree) most, then
/// "unsteady" (lines in both views that never held still), then "no line" (which a hand that
/// was read in both views also ends with as it withdraws through one view first).
fn refusal_rank(outcome: &str) -> u8 {
    match outcome {
        "uncertain" | "degenerate" | "disagree" => 2,
        "unsteady" => 1,
        _ => 0,
    }
}

/// Both plate trackers track on this frame.
fn plate_tracked(c: &Cycle<'_>) -> bool {
    View::ALL.into_iter().all(|v| c.states.get(Role::Gripper, v).is_some_and(|s| s.is_tracking()))
}

/// The refusal or the answer of a gesture that ended, for the record; `None` while it goes on.
pub(crate) fn record(r: &GestureResult, time_ns: u64, plane_z_m: f64) -> Option<GestureRecord> {
    let base = |outcome: &str, detail: String| GestureRecord {
        frame_id: r.frame_id,
        time_s: time_ns as f64 * 1e-9,
        outcome: outcome.into(),
        point_m: None,
        sigma_mm: None,
        crossing_deg: None,
        tip_px: None,
        line_px: None,
        detail,
    };
    Some(match r.state {
        GestureState::Absent | GestureState::Moving { .. } => return None,
        GestureState::Indicated(p) => GestureRecord {
            point_m: Some([p.point_m[0], p.point_m[1], plane_z_m]),
            sigma_mm: Some(p.sigma_m * 1e3),
            crossing_deg: Some(p.crossing_rad.to_degrees()),
            tip_px: Some([p.axes[0].tip_px, p.axes[1].tip_px]),
            line_px: Some([0, 1].map(|v| [p.axes[v].line.0[0], p.axes[v].line.0[1], p.axes[v].line.0[2]])),
            ..base(
                "indicated",
                format!(
                    "({:.3}, {:.3}) m, sigma {:.1} mm, lines crossing at {:.0}°",
                    p.point_m[0],
                    p.point_m[1],
                    p.sigma_m * 1e3,
                    p.crossing_rad.to_degrees()
                ),
            )
        },
        GestureState::Degenerate { crossing_rad } => GestureRecord {
            crossing_deg: Some(crossing_rad.to_degrees()),
            ..base("degenerate", format!("the finger's line lies nearly in a plane through both cameras (plane lines crossing at {:.1}°)", crossing_rad.to_degrees()))
        },
        GestureState::Uncertain { sigma_m } => GestureRecord {
            sigma_mm: Some(sigma_m * 1e3),
            ..base("uncertain", format!("too little of the finger measured (one-sigma radius {:.1} mm)", sigma_m * 1e3))
        },
        GestureState::Disagree { view, behind_px } => base(
            "disagree",
            format!("the views disagree: the point lies {behind_px:.0} px behind the fingertip in the {} view", if view == 0 { "left" } else { "right" }),
        ),
        GestureState::Unsteady { frames } => base("unsteady", format!("the hand did not hold still in {frames} frames")),
        GestureState::NoLine { frames, views } => {
            base("no_line", format!("no finger line in {} view(s) over {frames} frames (seen end-on, hidden or cut by the border)", 2 - views))
        }
    })
}

impl PointPhase {
    pub fn new(time_ns: u64) -> Self {
        Self { start_ns: time_ns, stage: Stage::Park { wait: None }, thread: None, plane_z_m: f64::NAN }
    }

    /// Picks up after the arm held `held_ns` for a lost tracker: the time held does not
    /// count; a move under way is sent again, a settle starts over; a gesture under way goes
    /// on (the frames missed meanwhile were not handed over).
    pub fn resume(&mut self, held_ns: u64) {
        self.start_ns = self.start_ns.saturating_add(held_ns);
        match &mut self.stage {
            Stage::Park { wait } | Stage::Return { wait, .. } => *wait = None,
            Stage::Settle { still } => *still = 0,
            Stage::Watch { .. } => {}
            Stage::Withdraw { since_ns, .. } => *since_ns = since_ns.saturating_add(held_ns),
        }
    }

    /// What the gestures so far were, for the time-out's failure.
    fn seen(m: &Mission) -> String {
        let g = m.pointing.gestures();
        if g.is_empty() {
            return "no gesture seen".into();
        }
        let each: Vec<String> = g.iter().map(|g| format!("{}: {}", g.outcome, g.detail)).collect();
        format!("{} gesture(s), none answered: {}", g.len(), each.join("; "))
    }

    /// One frame of watching the operator (the watch and withdraw stages): hands it to the
    /// gesture tracker, takes the result that is due and acts on it. Also called by the hard
    /// loop on the frames the arm holds for a lost plate (the hand passing in front of it):
    /// the arm stands still either way, and the gesture goes on.
    pub fn keep_watching(&mut self, m: &mut Mission, frame_index: u64, frame_id: u64, time_ns: u64, left: &ImageView<'_>, right: &ImageView<'_>) {
        let (Stage::Watch { .. } | Stage::Withdraw { gone: false, .. }) = self.stage else { return };
        let Some(t) = self.thread.as_mut() else { return };
        let result = t.poll(frame_index);
        if t.submit(frame_index, frame_id, left, right) {
            m.pointing.submitted();
        }
        let Some(r) = result else { return };
        m.pointing.result(&r);
        let absent = matches!(r.state, GestureState::Absent);
        m.pointing.hand_at(time_ns, !absent);
        match &mut self.stage {
            Stage::Withdraw { gone, .. } => *gone = absent,
            Stage::Watch { refusal } if absent => {
                // The hand has gone: a refusal it never made good is the gesture's outcome.
                if let Some(g) = refusal.take() {
                    m.pointing.gesture(*g);
                    m.reporting.set_status("point: gesture refused; waiting for the next one");
                }
            }
            Stage::Watch { refusal } => {
                let Some(mut g) = record(&r, time_ns, self.plane_z_m) else {
                    if refusal.is_none() {
                        m.reporting.set_status("point: a hand in view");
                    }
                    return;
                };
                match g.point_m {
                    Some(p) => {
                        if let Some(first) = refusal.take() {
                            g.detail = format!("{} (after {}: {} while the hand settled)", g.detail, first.outcome, first.detail);
                        }
                        tracing::info!(outcome = %g.outcome, detail = %g.detail, frame = g.frame_id, "pointing gesture");
                        let sigma_m = g.sigma_mm.map_or(0.0, |s| s * 1e-3);
                        m.pointing.gesture(g);
                        m.targeting.set_pointed_m(p, sigma_m);
                        m.reporting.set_status("point: indicated; waiting for the hand to go");
                        m.reporting.snapshot("pointed");
                        self.stage = Stage::Withdraw { since_ns: time_ns, gone: false };
                    }
                    None => {
                        if refusal.is_none() {
                            tracing::info!(outcome = %g.outcome, detail = %g.detail, frame = g.frame_id, "pointing gesture refused while the hand is there");
                            m.reporting.set_status("point: gesture refused so far; watching it while the hand holds");
                            m.reporting.snapshot("point_refused");
                        }
                        // The most telling refusal of the hand stands (`refusal_rank`), the
                        // newest of equal rank.
                        if refusal.as_ref().is_none_or(|old| refusal_rank(&g.outcome) >= refusal_rank(&old.outcome)) {
                            *refusal = Some(Box::new(g));
                        }
                    }
                }
            }
            _ => {}
        }
    }

    fn start_watching(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Result<(), String> {
        let (pointing, z, rms) = plane_maps(m)?;
        let config = GestureConfig { max_sigma_m: m.cfg.point().max_sigma_m, ..GestureConfig::default() };
        let wait = std::time::Duration::from_millis(m.cfg.timing.worker_wait_ms);
        let mut thread = GestureThread::spawn(PointingTracker::new(pointing, config), c.left.width(), c.left.height(), wait)
            .map_err(|e| format!("cannot start the gesture thread: {e}"))?;
        if !thread.set_background(c.left, c.right) {
            return Err("the gesture thread took no background".into());
        }
        self.thread = Some(thread);
        self.plane_z_m = z;
        m.pointing.start(z, rms);
        Ok(())
    }

    /// Moves the arm to `to` and waits for it: `Ok(true)` when there. Only while both plate
    /// trackers track: the safety check does not hold the arm for a lost plate in this
    /// phase (see `safety::needs_trackers`), so the phase does: no move goes out, and one under
    /// way is stopped and sent again once the plate is back.
    fn move_to(&mut self, m: &mut Mission, c: &Cycle<'_>, to: [f64; 3], what: &str) -> Result<bool, Step> {
        let wait = match &mut self.stage {
            Stage::Park { wait } | Stage::Return { wait, .. } => wait,
            _ => return Ok(true),
        };
        if !plate_tracked(c) {
            m.reporting.set_status("point: plate not tracked; arm held");
            return Err(Step::Stay(if wait.take().is_some() { Cmd::STOP } else { Cmd::HOLD }));
        }
        let Some(w) = wait else {
            *wait = Some(MoveWait::new(c.seq, c.frame_index));
            return Err(Step::Stay(Cmd::move_to(to, f64::from(c.robot.tool_yaw_rad), m.cfg.calibration.speed_mps)));
        };
        match w.poll(c, 1) {
            MovePoll::Pending => Ok(false),
            MovePoll::Rejected(code) => Err(Step::fail(FailureKind::RobotRefused, format!("point: the robot refused the {what} pose: {}", RejectReason::text_of(code)))),
            MovePoll::Done => Ok(true),
        }
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(self.start_ns, c.time_ns, m.cfg.point().timeout_s) {
            if let Stage::Watch { refusal: Some(g) } = &mut self.stage {
                m.pointing.gesture((**g).clone());
            }
            return Step::fail(FailureKind::TimedOut, format!("point: no pointing gesture answered in {} s ({})", m.cfg.point().timeout_s, Self::seen(m)));
        }
        match self.stage {
            Stage::Park { .. } => {
                let park = m.cfg.point().park_m.clone();
                if park.len() == 3 {
                    m.reporting.set_status("point: parking out of the hand's way");
                    match self.move_to(m, c, [park[0], park[1], park[2]], "park") {
                        Ok(true) => {}
                        Ok(false) => return Step::Stay(Cmd::HOLD),
                        Err(step) => return step,
                    }
                }
                self.stage = Stage::Settle { still: 0 };
                Step::Stay(Cmd::HOLD)
            }
            Stage::Settle { still } => {
                let moving = c.robot.flags & robot_flags::MOVING != 0;
                let still = if moving { 0 } else { still + 1 };
                self.stage = Stage::Settle { still };
                if still <= m.cfg.point().settle_frames {
                    m.reporting.set_status("point: arm parked, settling");
                    return Step::Stay(Cmd::HOLD);
                }
                if let Err(why) = self.start_watching(m, c) {
                    return Step::fail(FailureKind::Internal, format!("point: {why}"));
                }
                m.reporting.set_status("point: waiting for the operator to point");
                m.reporting.snapshot("point_background");
                self.stage = Stage::Watch { refusal: None };
                Step::Stay(Cmd::HOLD)
            }
            Stage::Watch { .. } => {
                self.keep_watching(m, c.frame_index, c.frame_id, c.time_ns, c.left, c.right);
                Step::Stay(Cmd::HOLD)
            }
            Stage::Withdraw { since_ns, gone } => {
                if !gone {
                    self.keep_watching(m, c.frame_index, c.frame_id, c.time_ns, c.left, c.right);
                }
                let gone = matches!(self.stage, Stage::Withdraw { gone: true, .. });
                if !gone && !timed_out(since_ns, c.time_ns, WITHDRAW_WAIT_S) {
                    return Step::Stay(Cmd::HOLD);
                }
                if !gone {
                    tracing::warn!("the hand stayed in view {WITHDRAW_WAIT_S} s after pointing: planning with it there");
                }
                self.thread = None; // joins the gesture thread
                m.pointing.stop();
                self.stage = Stage::Return { wait: None, since_ns: c.time_ns };
                Step::Stay(Cmd::HOLD)
            }
            Stage::Return { since_ns, .. } => {
                // Where the calibration parked it: the plan's view is the one it always had.
                let cal_park = &m.cfg.calibration.park_m;
                let back = if cal_park.len() == 3 { Some([cal_park[0], cal_park[1], cal_park[2]]) } else { m.calibration.start_pose().map(|(p, _)| p) };
                if let Some(p) = back.filter(|_| m.cfg.point().park_m.len() == 3) {
                    m.reporting.set_status("point: arm returning for the plan");
                    match self.move_to(m, c, p, "return") {
                        Ok(true) => {}
                        Ok(false) => return Step::Stay(Cmd::HOLD),
                        // The plate still not tracked after a while: the plan phase holds
                        // the arm and searches for it; it plans from where the arm stands.
                        Err(_) if !plate_tracked(c) && timed_out(since_ns, c.time_ns, PLATE_WAIT_S) => return Step::Next(Cmd::HOLD),
                        Err(step) => return step,
                    }
                }
                Step::Next(Cmd::HOLD)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::pointing::ImageLine;
    use crate::test_cameras::{camera, px};

    #[test]
    fn a_hand_read_unsteady_is_not_recorded_as_its_withdrawal() {
        // Lines in both views that never held still, then one view loses the hand first as it
        // goes: the gesture's refusal is "unsteady" (seed 57 reported three "no line"s), and a
        // steady window's refusal outranks both.
        assert!(refusal_rank("unsteady") > refusal_rank("no_line"));
        assert!(refusal_rank("uncertain") > refusal_rank("unsteady"));
        assert_eq!(refusal_rank("degenerate"), refusal_rank("disagree"));
    }

    #[test]
    fn the_plane_maps_carry_finger_lines_to_the_point_on_the_lowest_cage_plane() {
        let at = Vector3::new(0.35, 0.0, 0.16);
        let cams = [camera(Vector3::new(1.695, -0.241, 0.9), at), camera(Vector3::new(1.695, 0.241, 0.9), at)];
        let cage: Vec<Vector3<f64>> = crate::config::CalibrationConfig::default().cage_m.iter().map(|p| Vector3::from(*p)).collect();
        // The plate's reference point 0.1 m above and 0.056 m in front of the tool point:
        // the cameras see it, not the tool point the robot reports.
        let lever = Vector3::new(0.056, 0.0, -0.1);
        let images: Vec<[f64; 4]> = cage
            .iter()
            .map(|x| {
                let (l, r) = (px(&cams[0], &(x - lever)), px(&cams[1], &(x - lever)));
                [l[0], l[1], r[0], r[1]]
            })
            .collect();
        let (pointing, z, rms) = plane_maps_from(&cage, &images, &lever).unwrap();
        assert!((z - 0.06).abs() < 1e-12 && rms < 1e-6, "z {z}, rms {rms}");
        // A finger line through the point's image in each view, from different directions.
        let x = Vector3::new(0.41, 0.03, z);
        let through = |v: usize, other: Vector3<f64>| ImageLine::through(&px(&cams[v], &x), &px(&cams[v], &other)).unwrap();
        let hit = pointing.indicate(&through(0, Vector3::new(0.5, 0.15, 0.25)), &through(1, Vector3::new(0.3, 0.12, 0.3))).unwrap();
        let err = (hit.point_m[0] - x.x).hypot(hit.point_m[1] - x.y);
        assert!(err < 1e-4, "indicated {:?}, {:.2} mm from {x:?}", hit.point_m, err * 1e3);
        // Fitted to the tool positions as if the cameras saw them (the lever ignored), the
        // same lines land centimetres away.
        let (naive, _, _) = plane_maps_from(&cage, &images, &Vector3::zeros()).unwrap();
        let off = naive.indicate(&through(0, Vector3::new(0.5, 0.15, 0.25)), &through(1, Vector3::new(0.3, 0.12, 0.3))).unwrap();
        assert!((off.point_m[0] - x.x).hypot(off.point_m[1] - x.y) > 0.01, "{:?}", off.point_m);
    }
}
