//! Acquire the target: one tracker per view on the target facet's polygon (the operator
//! hint's, or the planned facet's outline, thesis §6.3.4: "the image locations of the facet
//! associated with the chosen grasp site were used to initialise a pair of active
//! contours"), checked against the epipolar constraint (corners that break it are not the
//! same facet in both views), left to converge with the arm still, then verified. The grasp
//! site, if planned, is then expressed in each tracker's template coordinates, so that it
//! follows the facet.

use handeye_vision::tracker::{ContourTracker, Role, View};
use handeye_wire::report::FailureKind;

use super::step::{timed_out, Cmd, Cycle, Step};
use crate::mission::{Mission, TargetSource};

pub struct AcquireTarget {
    start_ns: u64,
    started: bool,
    frames: u32,
    /// The target polygon the trackers started on, per view (left, right).
    planned_px: [Vec<[f64; 2]>; 2],
}

impl AcquireTarget {
    pub fn new(time_ns: u64) -> Self {
        Self { start_ns: time_ns, started: false, frames: 0, planned_px: [Vec::new(), Vec::new()] }
    }

    /// Picks up after the arm held `held_ns` for the gripper's trackers: the time held does
    /// not count (the target's trackers kept converging meanwhile).
    pub fn resume(&mut self, held_ns: u64) {
        self.start_ns = self.start_ns.saturating_add(held_ns);
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(self.start_ns, c.time_ns, m.cfg.target.timeout_s) {
            return Step::fail(FailureKind::TimedOut, format!("acquire_target: timed out after {} s", m.cfg.target.timeout_s));
        }
        if !self.started {
            self.started = true;
            m.targeting.begin_attempt();
            let Some(hint) = m.targeting.target() else {
                return Step::fail(FailureKind::Internal, "acquire_target: no target (no operator hint and no plan)");
            };
            let what = match hint.source {
                TargetSource::Hint => "the hint's corners",
                TargetSource::Plan => "the planned facet's corners",
            };
            let Some(cal) = m.calibration.get() else { return Step::fail(FailureKind::Internal, "acquire_target: not calibrated") };
            let n = hint.left_px.len();
            let rms = (hint
                .left_px
                .iter()
                .zip(&hint.right_px)
                .map(|(l, r)| cal.model.epipolar().residual_px(&[l[0], l[1], r[0], r[1]]).powi(2))
                .sum::<f64>()
                / n as f64)
                .sqrt();
            if rms > m.cfg.target.max_epipolar_px {
                return Step::fail(FailureKind::TargetNotAcquired, format!(
                    "acquire_target: {what} break the epipolar constraint ({rms:.1} px RMS > {} px): not the same facet in both views?",
                    m.cfg.target.max_epipolar_px
                ));
            }
            let max_depth = m.cfg.gripper.max_opening_m;
            if hint.depth_m >= max_depth {
                return Step::fail(FailureKind::TargetNotAcquired, format!(
                    "acquire_target: the target is {:.0} mm deep, wider than the jaws open ({:.0} mm)",
                    hint.depth_m * 1e3,
                    max_depth * 1e3
                ));
            }
            self.planned_px = [hint.left_px.clone(), hint.right_px.clone()];
            for (view, poly) in [(View::Left, &hint.left_px), (View::Right, &hint.right_px)] {
                match ContourTracker::new(m.cfg.tracker.target_tracker_config(), poly) {
                    Ok(t) => {
                        m.trackers.insert(Role::Target, view, t);
                    }
                    Err(e) => return Step::fail(FailureKind::TargetNotAcquired, format!("acquire_target: target polygon ({view:?}): {e}")),
                }
            }
            m.reporting.set_status("acquire target: trackers on the target facet converging");
            return Step::Stay(Cmd::HOLD);
        }
        self.frames += 1;
        // Twice while converging: refine the hinted corners from the image's edges and restart
        // the trackers on them (the hint's corner errors would otherwise stay in the template),
        // each side within what the plan allows (`target_outline`): the planner matched its
        // edges within its epipolar tolerance, and the tracker finds an edge within its inlier
        // band; a side further off in one view only slid onto another edge there (a
        // same-shade neighbour's outer edge) and is held on the plan's line.
        let half = m.cfg.target.converge_frames / 3;
        if half > 0 && (self.frames == half || self.frames == 2 * half) {
            match (m.trackers.remove(Role::Target, View::Left), m.trackers.remove(Role::Target, View::Right)) {
                (Some(mut left), Some(mut right)) => {
                    let max_shift_px = m.cfg.plan.stereo.epipolar_tol_px + left.config().inlier_px;
                    let planned = [&self.planned_px[0][..], &self.planned_px[1][..]];
                    let held = crate::target_outline::refine_held_to_plan([&mut left, &mut right], planned, max_shift_px);
                    if held.iter().any(|h| !h.is_empty()) {
                        tracing::info!(left = ?held[0], right = ?held[1], "acquire_target: sides held on the plan's outline (no edge of theirs near it in that view)");
                    }
                    m.trackers.insert(Role::Target, View::Left, left);
                    m.trackers.insert(Role::Target, View::Right, right);
                }
                (left, right) => {
                    for (view, t) in [(View::Left, left), (View::Right, right)] {
                        if let Some(t) = t {
                            m.trackers.insert(Role::Target, view, t);
                        }
                    }
                }
            }
        }
        // A held side is placed by the sides still measured; where they do not hold the face,
        // it drifts off its planned line with the outline, and is measured again.
        if self.frames > half {
            let max_shift_px = m.cfg.plan.stereo.epipolar_tol_px + m.cfg.tracker.target_tracker_config().inlier_px;
            for (k, view) in View::ALL.into_iter().enumerate() {
                if let Some(t) = m.trackers.get_mut(Role::Target, view) {
                    let released = crate::target_outline::release_adrift(t, &self.planned_px[k], max_shift_px);
                    if !released.is_empty() {
                        tracing::info!(?view, sides = ?released, frame = self.frames, "acquire_target: held sides drifted off the plan's outline with the face: measured again");
                    }
                }
            }
        }
        if self.frames < m.cfg.target.converge_frames {
            return Step::Stay(Cmd::HOLD);
        }
        for view in View::ALL {
            let Some(t) = m.trackers.get(Role::Target, view) else { return Step::fail(FailureKind::Internal, "acquire_target: tracker missing") };
            let score = t.confidence().score;
            // The servo will need the safety's score; the arm is still until then, so a shaky
            // tracker is judged here, at the end, rather than stopping the run on its way in.
            let min = m.cfg.target.min_score.max(m.cfg.safety.min_target_score);
            if score.is_nan() || score < min {
                return Step::fail(FailureKind::TrackerUnsure, format!("acquire_target: target tracker ({view:?}) confidence {score:.2} < {min}"));
            }
        }
        // The planned site, in each tracker's template coordinates.
        if let Some(site_px) = m.targeting.target().and_then(|t| t.site_px) {
            let mut st = [[0.0; 2]; 2];
            for (k, view) in View::ALL.into_iter().enumerate() {
                let Some(p) = m.trackers.get(Role::Target, view).and_then(|t| t.template_from_image(nalgebra::Vector2::new(site_px[k][0], site_px[k][1]))) else {
                    return Step::fail(FailureKind::TargetNotAcquired, "acquire_target: the grasp site has no place in the target tracker's frame");
                };
                st[k] = [p.x, p.y];
            }
            if let Some(t) = m.targeting.target_mut() {
                t.site_template = Some(st);
            }
        }
        if let (Some(l), Some(r)) = (m.trackers.get(Role::Target, View::Left), m.trackers.get(Role::Target, View::Right)) {
            let (l, r) = (l.frame().origin, r.frame().origin);
            m.targeting.set_acquired_px([l.x, l.y, r.x, r.y]);
        }
        m.reporting.snapshot("target_acquired");
        m.reporting.set_status("target acquired");
        Step::Next(Cmd::HOLD)
    }
}
