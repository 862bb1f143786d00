//! Plan (thesis ch. 5-6, DESIGN "Daemon phases"): with the arm parked clear of the blocks
//! but in view, one stereo pair goes to the planner on the worker thread
//! ([`crate::planning`]), the gripper's image region masked out; the hard loop meanwhile
//! keeps tracking the gripper at frame rate and answering every frame (the thesis's robot
//! was blind while it planned). The grasp site nearest the indicated point is chosen; its
//! facet's outline becomes the target for `acquire_target`, and its width, site and height
//! go to the servo and the grasp.
//!
//! The result is taken no earlier than [`super::job::WORKER_DELAY_FRAMES`] after the pair was
//! handed over (a fixed pipeline delay keeps lockstep runs repeatable whatever the
//! worker's speed); if it is late the loop keeps waiting, tracking and answering.

use std::fmt;

use handeye_vision::image::ImageBuf;
use handeye_vision::tracker::{Role, View};
use handeye_wire::report::FailureKind;
use handeye_wire::{robot_flags, RejectReason};
use nalgebra::Vector3;

use super::job::PendingJob;
use super::step::{timed_out, Cmd, Cycle, MovePoll, MoveWait, Step};
use crate::gripper::tool_from_reference;
use crate::mission::{Mission, PlanningStats, TargetSource, TargetSpec};
use crate::planning::{nearest_facet_distance_m, plan_request, PlanCalibration, PlanMoment, PlanOutput, PlannedTarget};

/// Times a pointed point that picks no one block sends the operator back to point before the
/// run fails: each answer is a new gesture from wherever the operator stands.
pub const MAX_REPOINTS: u32 = 2;

enum Stage {
    /// Going to the park pose (if not there).
    Park { wait: Option<MoveWait> },
    /// Arm still for this many frames.
    Settle { still: u32 },
    /// The pair is with the planner.
    Planning { job: PendingJob<Box<PlanOutput>> },
}

/// The stage as the time-out's failure names it (the plan job by the frame it was submitted).
impl fmt::Debug for Stage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Park { wait } => f.debug_struct("Park").field("wait", wait).finish(),
            Self::Settle { still } => f.debug_struct("Settle").field("still", still).finish(),
            Self::Planning { job } => f.debug_struct("Planning").field("submitted", &job.submitted_frame()).finish(),
        }
    }
}

pub struct PlanPhase {
    start_ns: u64,
    stage: Stage,
    /// Gripper tracker update counts when the pair was handed over.
    updates_at_submit: [u64; 2],
    /// Pairs handed to the planner so far.
    looks: u32,
    /// What each look that refused the pointed block said.
    refusals: Vec<String>,
}

/// What the plan does after a look that chose no site.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum NextLook {
    /// Look at a fresh pair.
    Again,
    /// Refuse the pointed block: looks enough have refused it.
    Refuse,
    /// No site, no refusal: the run fails saying so.
    GiveUp,
}

/// After look number `looks` (1-based) chose no site: `refused`, whether it refused the
/// pointed block; `refusing_looks`, how many looks refused so far, this one included. A
/// refusal needs two refusing looks (one, when only one look is allowed); otherwise the plan
/// looks again while `max_looks` allows.
fn after_look(refused: bool, looks: u32, refusing_looks: u32, max_looks: u32) -> NextLook {
    if refused && refusing_looks >= max_looks.min(2) {
        NextLook::Refuse
    } else if looks < max_looks {
        NextLook::Again
    } else {
        NextLook::GiveUp
    }
}

/// Convex hull (Andrew's monotone chain), counter-clockwise in image axes.
pub fn convex_hull(points: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = points.iter().copied().filter(|q| q[0].is_finite() && q[1].is_finite()).collect();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
    let mut hull: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = hull.len();
        let pts: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 { Box::new(p.iter()) } else { Box::new(p.iter().rev()) };
        for &q in pts {
            while hull.len() >= start + 2 && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0 {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    hull
}

/// The gripper's image region in each view (tracker pixels): the plate trackers' corners and
/// the configured box around the reference point, projected with the calibrated model
/// from the tracked reference point (only directions go through the model).
fn gripper_masks(m: &Mission, yaw_rad: f64) -> Option<[Vec<[f64; 2]>; 2]> {
    let cal = m.calibration.get()?;
    let n0 = m.cfg.gripper.normal_at_zero_yaw;
    let (s, c) = yaw_rad.sin_cos();
    let n = Vector3::new(c * n0[0] - s * n0[1], s * n0[0] + c * n0[1], 0.0).try_normalize(1e-12)?;
    let up = Vector3::z();
    let a = up.cross(&n);
    let b = &m.cfg.plan.mask.mask_box_m;
    let mut masks: [Vec<[f64; 2]>; 2] = [Vec::new(), Vec::new()];
    for (k, view) in View::ALL.into_iter().enumerate() {
        let t = m.trackers.get(Role::Gripper, view)?;
        let reference = t.image_from_template(nalgebra::Vector2::new(m.plate.reference_st[0], m.plate.reference_st[1]));
        let mut pts: Vec<[f64; 2]> = t.corners().map(|p| [p.x, p.y]).collect();
        for ia in 0..2 {
            for ib in 0..2 {
                for i_n in 0..2 {
                    let d = a * b[0][ia] + up * b[1][ib] + n * b[2][i_n];
                    let w = cal.model.m * d;
                    let (du, dv) = if k == 0 { (w[0], w[1]) } else { (w[2], w[3]) };
                    pts.push([reference.x + du, reference.y + dv]);
                }
            }
        }
        masks[k] = convex_hull(&pts);
    }
    Some(masks)
}

impl PlanPhase {
    pub fn new(time_ns: u64) -> Self {
        Self { start_ns: time_ns, stage: Stage::Park { wait: None }, updates_at_submit: [0; 2], looks: 0, refusals: Vec::new() }
    }

    fn gripper_updates(m: &Mission) -> [u64; 2] {
        View::ALL.map(|v| m.trackers.get(Role::Gripper, v).map_or(0, |t| t.update_count()))
    }

    /// Picks up after the arm held `held_ns` for a lost tracker: the time held does not count;
    /// a park move under way is sent again, a settle starts over; a pair already with the
    /// planner stays there (it was taken before the loss).
    pub fn resume(&mut self, held_ns: u64) {
        self.start_ns = self.start_ns.saturating_add(held_ns);
        match &mut self.stage {
            Stage::Park { wait } => *wait = None,
            Stage::Settle { still } => *still = 0,
            Stage::Planning { .. } => {}
        }
    }

    /// Hands the pair to the planner on the worker (allocates the request: once a look), or
    /// waits a frame when the worker is busy.
    fn submit(&mut self, m: &mut Mission, c: &Cycle<'_>, images: [ImageBuf; 2]) -> Step {
        let Some(cal) = m.calibration.get() else { return Step::fail(FailureKind::Internal, "plan: not calibrated") };
        let yaw = f64::from(c.robot.tool_yaw_rad);
        let Some(masks) = gripper_masks(m, yaw) else {
            return Step::fail(FailureKind::Internal, "plan: no gripper trackers to mask the gripper with");
        };
        let lever = tool_from_reference(&m.cfg.gripper, m.calibration.yaw_rad().unwrap_or(yaw));
        let moment = PlanMoment {
            images,
            calibration: PlanCalibration {
                model: cal.model.clone(),
                cage_robot_m: cal.cage_robot_m.clone(),
                cage_image_px: cal.cage_image_px.clone(),
                lever_m: [lever.x, lever.y, lever.z],
            },
            masks,
            indicated_m: m.targeting.indicated_m(),
            indicated_sigma_m: m.targeting.indicated_sigma_m(),
            max_height_m: f64::from(c.robot.tool_pos_m[2]) - m.cfg.plan.scene.arm_clearance_m,
        };
        let request = plan_request(&m.cfg, moment);
        match PendingJob::submit(&mut m.worker, c.frame_index, move || Box::new(crate::planning::plan(request))) {
            Some(job) => {
                self.looks += 1;
                self.updates_at_submit = Self::gripper_updates(m);
                self.stage = Stage::Planning { job };
                m.reporting.set_status("plan: planning; gripper tracked meanwhile");
                m.reporting.snapshot("planning");
            }
            None => {
                // The worker is busy (the pair went with the refused job): the arm is still
                // settled, so the next frame starts a new pair.
                m.reporting.set_status("plan: worker busy, waiting");
                self.stage = Stage::Settle { still: m.cfg.plan.settle_frames };
            }
        }
        Step::Stay(Cmd::HOLD)
    }

    pub fn step(&mut self, m: &mut Mission, c: &Cycle<'_>) -> Step {
        if timed_out(self.start_ns, c.time_ns, m.cfg.plan.timeout_s) {
            return Step::fail(FailureKind::TimedOut, format!("plan: timed out after {} s at {:?}", m.cfg.plan.timeout_s, self.stage));
        }
        match &mut self.stage {
            Stage::Park { wait } => {
                let Some(w) = wait else {
                    let park = m.cfg.plan.park_m.clone();
                    if park.len() != 3 {
                        // Where the calibration parked it.
                        self.stage = Stage::Settle { still: 0 };
                        return Step::Stay(Cmd::HOLD);
                    }
                    *wait = Some(MoveWait::new(c.seq, c.frame_index));
                    m.reporting.set_status("plan: parking clear of the blocks");
                    return Step::Stay(Cmd::move_to([park[0], park[1], park[2]], f64::from(c.robot.tool_yaw_rad), m.cfg.calibration.speed_mps));
                };
                match w.poll(c, 1) {
                    MovePoll::Pending => Step::Stay(Cmd::HOLD),
                    MovePoll::Rejected(code) => {
                        Step::fail(FailureKind::RobotRefused, format!("plan: the robot refused the park pose: {}", RejectReason::text_of(code)))
                    }
                    MovePoll::Done => {
                        self.stage = Stage::Settle { still: 0 };
                        Step::Stay(Cmd::HOLD)
                    }
                }
            }
            Stage::Settle { still } => {
                let moving = c.robot.flags & robot_flags::MOVING != 0;
                *still = if moving { 0 } else { *still + 1 };
                if *still <= m.cfg.plan.settle_frames {
                    m.reporting.set_status("plan: arm parked, settling");
                    return Step::Stay(Cmd::HOLD);
                }
                // Allocates once a look: the pair the planner works on.
                self.submit(m, c, [c.left.to_owned(), c.right.to_owned()])
            }
            Stage::Planning { job } => {
                let Some(out) = job.poll(&mut m.worker, c.frame_index) else { return Step::Stay(Cmd::HOLD) };
                let now = Self::gripper_updates(m);
                let stats = PlanningStats {
                    frames: c.frame_index - job.submitted_frame(),
                    gripper_updates: [now[0] - self.updates_at_submit[0], now[1] - self.updates_at_submit[1]],
                    planner_ms: out.summary.timing.planner_ms,
                    total_ms: out.summary.timing.total_ms,
                    looks: self.looks,
                };
                let summary = out.summary.clone();
                let target = out.target.clone();
                let refusal = out.refusal.clone();
                let unjudged = out.unjudged.clone();
                let ambiguous = out.ambiguous.clone();
                m.targeting.set_alternatives(out.alternatives.iter().map(target_spec).collect());
                m.planning.record(summary.clone(), stats);
                m.reporting.plan(out);
                let Some(t) = target else {
                    // A pointed point between blocks: the operator is asked to point again
                    // (the dispatcher goes back to the point phase when the point is gone).
                    if let Some(why) = ambiguous {
                        m.pointing.turned_down("ambiguous", why.clone());
                        return point_again(m, &why, "plan: the point does not pick one block; point again");
                    }
                    // A refusal names the rules the pointed block fails, from this plan's own
                    // facets, so that the user can tell a right refusal from a blind one. It is
                    // claimed only when two looks refuse (a marginal edge read as an obstacle
                    // refuses on one frame's noise and not on the next).
                    let refused = refusal.is_some();
                    if let Some(why) = refusal {
                        let elsewhere = summary
                            .sites
                            .candidates
                            .first()
                            .and_then(|c| c.place.distance_mm)
                            .map(|d| format!(" (the nearest site, on another block, is {d:.0} mm from the indicated point)"))
                            .unwrap_or_default();
                        self.refusals.push(format!("{why}{elsewhere}"));
                    }
                    match after_look(refused, self.looks, self.refusals.len() as u32, m.cfg.plan.max_looks) {
                        NextLook::Refuse => {
                            let why = self.refusals.last().cloned().unwrap_or_default();
                            return Step::fail(FailureKind::Refused, format!("plan: refused: the pointed block has no graspable facet pair: {why}"));
                        }
                        NextLook::Again => {
                            // Nothing settled: many of the edges that decide it are near the
                            // noise, so another frame may settle it. Look again at a fresh
                            // pair, the arm still.
                            tracing::info!(looks = self.looks, refused, "plan: no grasp site settled; looking again at a fresh pair");
                            m.reporting.set_status("plan: no grasp site settled; looking again");
                            self.stage = Stage::Settle { still: 0 };
                            return Step::Stay(Cmd::HOLD);
                        }
                        NextLook::GiveUp => {}
                    }
                    if let Some(why) = self.refusals.first() {
                        return Step::fail(FailureKind::NoGraspSite, format!(
                            "plan: no grasp site, and no refusal confirmed: one of {} pairs looked at refused the pointed block ({why}), the others did not; not a refusal",
                            self.looks
                        ));
                    }
                    let looks = match self.looks {
                        1 => String::new(),
                        n => format!(" (the last of {n} pairs looked at)"),
                    };
                    if let Some(seen) = unjudged {
                        return Step::fail(FailureKind::NoGraspSite, format!(
                            "plan: no grasp site: what was seen of the pointed block does not settle whether it can be grasped ({seen}); not a refusal{looks}"
                        ));
                    }
                    if let (Some(nearest), Some(point)) = (summary.sites.candidates.first(), m.targeting.indicated_m()) {
                        let reach_m = m.cfg.plan.grasp.max_site_distance_m;
                        let why = format!(
                            "no grasp site within {:.0} mm of the indicated point (the nearest is {:.0} mm away){looks}",
                            reach_m * 1e3,
                            nearest.place.distance_mm.unwrap_or(f64::NAN)
                        );
                        // A pointed point that lies on no block the plan saw either (a finger
                        // line read off the finger: 60-100 mm off on point_clutter3 seeds 47,
                        // 51) is the operator's to give again, as a point between blocks is. One
                        // on or next to a block whose sites all failed is the plan's failure.
                        let off_blocks = nearest_facet_distance_m(&summary.scene.facets, [point[0], point[1]]).is_none_or(|d| d > reach_m);
                        if off_blocks && m.targeting.indicated_sigma_m() > 0.0 {
                            let why = format!("the point lies on no block: no facet within {:.0} mm of it, and {why}", reach_m * 1e3);
                            m.pointing.turned_down("off_blocks", why.clone());
                            // The same place pointed at again: a block there the plan does not
                            // see (its failure), not a missed aim.
                            if let Some(apart_m) = m.targeting.off_blocks_again() {
                                return Step::fail(FailureKind::NoGraspSite, format!(
                                    "plan: {why}; pointed at the same place again ({:.0} mm from the last point), so the plan does not see the block there",
                                    apart_m * 1e3
                                ));
                            }
                            return point_again(m, &why, "plan: the point lies on no block; point again");
                        }
                        return Step::fail(FailureKind::NoGraspSite, format!("plan: {why}"));
                    }
                    let reasons: Vec<String> = summary.sites.rejected_by_reason.iter().map(|(k, v)| format!("{k} {v}")).collect();
                    return Step::fail(FailureKind::NoGraspSite, format!(
                        "plan: no grasp site ({} facets; rejected: {}){looks}",
                        summary.scene.facets.len(),
                        if reasons.is_empty() { "none found".into() } else { reasons.join(", ") }
                    ));
                };
                m.targeting.set_target(target_spec(&t));
                m.reporting.set_status("plan: grasp chosen");
                Step::Next(Cmd::HOLD)
            }
        }
    }
}

/// Asks the operator to point again (the dispatcher goes back to the point phase once the
/// point is forgotten), or fails after `MAX_REPOINTS` such requests; `why` the plan turned the
/// point down.
fn point_again(m: &mut Mission, why: &str, status: &str) -> Step {
    if m.targeting.point_again(MAX_REPOINTS) {
        tracing::warn!(%why, "plan: asking the operator to point again");
        m.reporting.set_status(status);
        return Step::Next(Cmd::HOLD);
    }
    Step::fail(FailureKind::NoGraspSite, format!("plan: {why} (asked to point again {} times)", m.targeting.repoints()))
}

/// The target for the later phases. The grasp goes down to the configured height above the
/// table (the robot's own kinematics are exact), not to the plan's low-water mark: the plan's
/// heights come from the affine model extrapolated 10-15 cm below the cage of reference
/// points, and came out ~2 cm high on 30-40 mm blocks (fingers closing above a bar). The
/// plan's width sets how far the jaws go past the facet.
fn target_spec(t: &PlannedTarget) -> TargetSpec {
    TargetSpec {
        source: TargetSource::Plan,
        left_px: t.left_px.clone(),
        right_px: t.right_px.clone(),
        depth_m: t.width_m,
        site_px: Some(t.site_px),
        site_template: None,
        grasp_tool_z_m: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_refusal_needs_two_looks_that_refuse_and_unsettled_looks_look_again() {
        use NextLook::*;
        // Refused, refused: refused on the second look.
        assert_eq!(after_look(true, 1, 1, 3), Again);
        assert_eq!(after_look(true, 2, 2, 3), Refuse);
        // Refused then unsettled twice: no refusal.
        assert_eq!(after_look(false, 2, 1, 3), Again);
        assert_eq!(after_look(false, 3, 1, 3), GiveUp);
        // Unsettled, refused, refused.
        assert_eq!(after_look(false, 1, 0, 3), Again);
        assert_eq!(after_look(true, 2, 1, 3), Again);
        assert_eq!(after_look(true, 3, 2, 3), Refuse);
        // Unsettled twice, then a refusal nothing can confirm.
        assert_eq!(after_look(true, 3, 1, 3), GiveUp);
        // One look allowed: it decides alone, as before looks were counted.
        assert_eq!(after_look(true, 1, 1, 1), Refuse);
        assert_eq!(after_look(false, 1, 0, 1), GiveUp);
    }

    #[test]
    fn hull_of_a_square_with_inner_points() {
        let h = convex_hull(&[[0.0, 0.0], [2.0, 0.0], [1.0, 1.0], [2.0, 2.0], [0.0, 2.0], [1.0, 0.5]]);
        assert_eq!(h.len(), 4, "{h:?}");
        for corner in [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]] {
            assert!(h.contains(&corner));
        }
    }
}
