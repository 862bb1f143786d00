//! Holding the arm while lost contours are searched for, and resuming the phase when they
//! are back (issue 18 item 1). Any tracker a phase needs that is lost or unsure, in any
//! phase that needs one (calibrate, plan, acquire_target, servo), starts a recovery instead
//! of ending the run: the hard loop stops the arm and holds it; each lost contour is searched
//! for with [`crate::track_search`] over a grid of image translations of its **last good**
//! template frame (the frame it last tracked confidently, before it drifted off, with a shape
//! steady and its own: `hard_loop/shape_watch.rs`), centred in
//! turn on where it was and where its filter's velocity predicts it, the grid widening with
//! every pass that found nothing (±40, ±80, then ±160 px, repeated). A candidate must pass
//! the acquisition's verification (the tracker's confidence, its area within ±11 % of the
//! template's; not back on the corners a tracker lost to a wrong lock was refused on: the
//! last good frame can itself be that lock; a plate on the calibration's epipolar constraint
//! with the other view's plate, tracked or as it was before the loss: a look-alike elsewhere
//! passes the area check); when every lost contour is back, all must track
//! confidently for
//! [`CONFIRM_FRAMES`] frames (the target's outline refined from its edges halfway, as at
//! acquisition) before the phase resumes from fresh frames. After `safety.loss_patience_s`
//! of camera time the run fails, naming what was lost, why, and how the search went. A plate
//! the search does not find is located by the jaws' motion instead (the hard loop drives
//! that, `hard_loop/hold.rs`; [`Recovery::plates_found_by_jaws`]).
//!
//! A camera knocked is the special case where both contours of one view are lost at once:
//! the plate (the highest-contrast contour) is searched for and the target follows it by
//! the same shift (a knocked camera shifts the whole view); the phase is told the shift so
//! that the servo's affine model moves with the image.
//!
//! Allocates (tracker clones per candidate, the failure text): it runs only while the arm is
//! held.

use handeye_vision::image::ImageView;
use handeye_vision::tracker::{ContourTracker, LostReason, Role, StereoTrackerSet, TemplateFrame, View};
use nalgebra::Vector2;

use crate::candidate_check::{other, plausible, same_lock, tracked};
pub use crate::candidate_check::{EpipolarCheck, REFUSED_LOCK_TOL_PX};
use crate::track_search::{SearchSettings, SearchStep, ShiftSearch};

/// Widest shift searched, px (a 3° pan at f = 1800 px is ~94 px).
pub const MAX_SHIFT_PX: f64 = 160.0;
/// The first pass's half-width, px; each pass that finds nothing doubles it up to
/// [`MAX_SHIFT_PX`].
pub const FIRST_SHIFT_PX: f64 = 40.0;
/// Grid step of the search, px (the tracker's own search covers ±12 px).
pub const STEP_PX: f64 = 10.0;
/// Candidates tried per frame and lost contour.
pub const CANDIDATES_PER_FRAME: usize = 120;
/// Confidence a plate candidate needs to be taken (the plate's contrast is high; its dark
/// border's outer edge is told apart by the area check).
pub const MIN_PLATE_SCORE: f64 = 0.8;
/// Confidence a target candidate needs (a block face 30 px across with one low-contrast side
/// tracks at 0.5-0.7).
pub const MIN_TARGET_SCORE: f64 = 0.6;
/// Frames every recovered contour must track before the phase resumes.
pub const CONFIRM_FRAMES: u32 = 12;
/// Largest predicted shift a search is centred on, px.
const MAX_PREDICTED_SHIFT_PX: f64 = 120.0;
/// Why a contour a phase needs counts as lost (`hard_loop/hold.rs`): typed, so that the
/// recovery tells a wrong lock from other losses by what the tracker measured, not by how it
/// words it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LossCause {
    /// The tracker stopped, for this reason.
    Tracker(LostReason),
    /// The tracker did not run this cycle.
    DidNotRun,
    /// Tracking, but below the confidence the safety checks want.
    Unsure { score: f64, min: f64 },
}

impl LossCause {
    /// The tracker was declared locked on something that is not its contour: the shape it
    /// holds now is that wrong lock. A crossed side (`LostReason::CrossedSide`, also reported
    /// as `wrong_lock`) is not counted: it fires within two updates of a side starting to
    /// cross (the shape still within a few px of the face) and also when an occluder of the
    /// outside's grey covers a stretch, so the shape it leaves is usually the face's own and
    /// refusing it would refuse the recovery itself.
    pub fn is_wrong_lock(&self) -> bool {
        matches!(self, LossCause::Tracker(LostReason::WrongLock { .. }))
    }
}

impl std::fmt::Display for LossCause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LossCause::Tracker(why) => write!(f, "{why}"),
            LossCause::DidNotRun => write!(f, "did not run"),
            LossCause::Unsure { score, min } => write!(f, "confidence {score:.2} < {min}"),
        }
    }
}

/// The last template frame a contour tracked confidently, when (camera ns), and its image
/// velocity then (px/s).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LastGood {
    pub frame: TemplateFrame,
    pub time_ns: u64,
    pub velocity_px_s: [f64; 2],
}

/// One lost contour.
struct Slot {
    role: Role,
    view: View,
    /// What the tracker said when it was lost (or why it counted as unsure).
    why: String,
    /// The frame searched around.
    base: TemplateFrame,
    lost_ns: u64,
    velocity_px_s: Vector2<f64>,
    search: ShiftSearch,
    passes: u32,
    /// Its shift from `base` once found.
    found: Option<Vector2<f64>>,
    /// The corners it was declared wrongly locked on, when that is why it was lost: a
    /// candidate back on them is refused.
    refused: Option<Vec<Vector2<f64>>>,
}

/// The state of one hold-and-search.
pub struct Recovery {
    start_ns: u64,
    /// Camera time not counted against the patience (the jaws opening and closing), ns.
    excused_ns: u64,
    patience_s: f64,
    min_scores: [f64; 2],
    slots: Vec<Slot>,
    confirmed: Option<u32>,
    best_score: f64,
    /// Contours re-found that then did not hold, and searched for again.
    relapses: u32,
    /// The plate was located by the jaws' motion, not by the search.
    by_jaws: bool,
}

/// What a recovery cycle concluded.
#[derive(Debug, Clone, PartialEq)]
pub enum RecoveryStep {
    /// Still holding: searching or confirming.
    Searching,
    /// Every lost contour is back and steady. `knock`: one view lost both contours and they
    /// came back shifted alike (a moved camera): that view and the shift, px.
    /// `shifts_px`: each re-found contour's shift from its last good frame, by
    /// [`slot_index`] (`None`: it was not lost): a target that came back elsewhere moved.
    Recovered { knock: Option<(View, [f64; 2])>, held_s: f64, shifts_px: [Option<[f64; 2]>; 4] },
    Failed(RecoveryError),
}

/// Why the lost contours were not found again.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RecoveryError {
    #[error("{what}; not found again within {patience_s:.1} s of camera time (searched ±{MAX_SHIFT_PX:.0} px around the last pose {passes} times, best candidate confidence {best_score:.2})")]
    NotFound { what: String, patience_s: f64, passes: u32, best_score: f64 },
    #[error("{what}: no tracker to search with")]
    NoTracker { what: String },
}

fn name(role: Role, view: View) -> String {
    let r = if role == Role::Gripper { "gripper" } else { "target" };
    let v = if view == View::Left { "left" } else { "right" };
    format!("{r} tracker ({v} view)")
}

fn settings(passes: u32) -> SearchSettings {
    let max = (FIRST_SHIFT_PX * f64::from(1u32 << passes.min(4))).min(MAX_SHIFT_PX);
    SearchSettings { max_shift_px: max, step_px: STEP_PX, candidates_per_frame: CANDIDATES_PER_FRAME, ..SearchSettings::default() }
}

fn role_index(role: Role) -> usize {
    usize::from(role == Role::Target)
}

/// Index of a (role, view) slot, in telemetry order: gripper left, gripper right, target
/// left, target right.
pub fn slot_index(role: Role, view: View) -> usize {
    2 * role_index(role) + usize::from(view == View::Right)
}

impl Recovery {
    /// Starts holding for the contours in `lost` (role, view, why), each searched for around
    /// its last good frame (`last_good`, by [`slot_index`]; the tracker's current frame when it
    /// never tracked confidently). `min_scores` (gripper, target): the confidence each must
    /// hold again, as the safety checks want it. Gives up after `patience_s` of camera time.
    pub fn start(
        trackers: &mut StereoTrackerSet,
        lost: &[(Role, View, LossCause)],
        last_good: &[Option<LastGood>; 4],
        now_ns: u64,
        patience_s: f64,
        min_scores: [f64; 2],
    ) -> Self {
        let mut r = Self { start_ns: now_ns, excused_ns: 0, patience_s, min_scores, slots: Vec::with_capacity(4), confirmed: None, best_score: 0.0, relapses: 0, by_jaws: false };
        for (role, view, why) in lost {
            r.add(trackers, *role, *view, *why, last_good, now_ns);
        }
        r
    }

    /// Adds a contour lost while holding (no-op if it is searched for already, or has no
    /// tracker). Its tracker rests (inactive) while it is searched for.
    pub fn add(&mut self, trackers: &mut StereoTrackerSet, role: Role, view: View, why: LossCause, last_good: &[Option<LastGood>; 4], now_ns: u64) {
        if self.slots.iter().any(|s| s.role == role && s.view == view) {
            return;
        }
        let Some(tracker) = trackers.get(role, view) else { return };
        tracing::debug!(who = %name(role, view), %why, has_good = last_good[slot_index(role, view)].is_some(), base = ?last_good[slot_index(role, view)].map(|g| g.frame), "joins the search");
        let (base, lost_ns, velocity_px_s) = match last_good[slot_index(role, view)] {
            Some(g) => (g.frame, g.time_ns, Vector2::from(g.velocity_px_s)),
            None => (tracker.frame(), now_ns, Vector2::zeros()),
        };
        let refused = why.is_wrong_lock().then(|| tracker.corners().collect());
        trackers.set_active(role, view, false);
        let search = ShiftSearch::new(settings(0), base, Vector2::zeros());
        self.slots.push(Slot { role, view, why: why.to_string(), base, lost_ns, velocity_px_s, search, passes: 0, found: None, refused });
        self.confirmed = None;
    }

    /// Whether the contour in this slot is being searched for (telemetry reports it lost).
    pub fn is_searching(&self, role: Role, view: View) -> bool {
        self.slots.iter().any(|s| s.role == role && s.view == view && s.found.is_none())
    }

    /// When the hold began, camera ns.
    pub fn start_ns(&self) -> u64 {
        self.start_ns
    }

    /// Camera time that does not count against the patience (the jaws located the plate
    /// meanwhile: the search did not run).
    pub fn excuse(&mut self, ns: u64) {
        self.excused_ns = self.excused_ns.saturating_add(ns);
    }

    /// Whether a plate is still being searched for (not found yet).
    pub fn plate_missing(&self) -> bool {
        self.slots.iter().any(|s| s.role == Role::Gripper && s.found.is_none())
    }

    /// The plate was found another way (the jaws opened and closed, their motion located it,
    /// and fresh trackers converged on it): each searched-for plate counts as found at its
    /// tracker's frame now; the confirmation follows as after a search.
    pub fn plates_found_by_jaws(&mut self, trackers: &mut StereoTrackerSet) {
        for s in self.slots.iter_mut().filter(|s| s.role == Role::Gripper && s.found.is_none()) {
            let Some(t) = trackers.get(s.role, s.view) else { continue };
            s.found = Some(t.frame().origin - s.base.origin);
            trackers.set_active(s.role, s.view, true);
        }
        self.by_jaws = true;
    }

    /// Whether the plate was located by the jaws' motion.
    pub fn by_jaws(&self) -> bool {
        self.by_jaws
    }

    /// Whether the contour in this slot is being searched for or confirmed (its frames are
    /// not known good until the recovery ends).
    pub fn holds_for(&self, role: Role, view: View) -> bool {
        self.slots.iter().any(|s| s.role == role && s.view == view)
    }

    /// Whether every contour searched for is `role`'s.
    pub fn only(&self, role: Role) -> bool {
        self.slots.iter().all(|s| s.role == role)
    }

    /// Search passes over the grid so far (the most of any lost contour).
    pub fn passes(&self) -> u32 {
        self.slots.iter().map(|s| s.passes).max().unwrap_or(0)
    }

    /// Contours re-found that then did not hold while confirming.
    pub fn relapses(&self) -> u32 {
        self.relapses
    }

    /// What was lost and why, for the operator: "target tracker (left view) lost: …; …".
    pub fn what(&self) -> String {
        self.slots.iter().map(|s| format!("{} lost: {}", name(s.role, s.view), s.why)).collect::<Vec<_>>().join("; ")
    }

    /// Where the other view's plate is, to check a plate candidate in `view` against: its
    /// tracker's origin while it tracks; its frame before the loss while it is searched for too
    /// (the arm holds: both plates were lost together under something, e.g. the operator's
    /// hand, and the first candidate found must not go unchecked). `None`, no check, when this
    /// view or the other lost its target as well: the sign of a knocked camera, which shifts
    /// its whole view off the constraint. A knocked view whose target was not lost (or is not
    /// tracked) is refused here and found by the jaws' motion instead: when in doubt the arm
    /// holds.
    fn mate_plate(&self, trackers: &StereoTrackerSet, view: View) -> Option<Vector2<f64>> {
        // A view with two slots has lost both its contours (one slot per role and view).
        if View::ALL.into_iter().any(|v| self.slots.iter().filter(|s| s.view == v).count() == 2) {
            return None;
        }
        match self.slots.iter().find(|s| s.role == Role::Gripper && s.view == other(view)) {
            Some(s) if s.found.is_none() => Some(s.base.origin),
            _ => tracked(trackers, Role::Gripper, other(view)).map(|t| t.frame().origin),
        }
    }

    fn min_candidate(&self, role: Role) -> f64 {
        if role == Role::Gripper { MIN_PLATE_SCORE.max(self.min_scores[0]) } else { MIN_TARGET_SCORE.max(self.min_scores[1]) }
    }

    fn holds(&self, trackers: &StereoTrackerSet, role: Role, view: View) -> bool {
        trackers.get(role, view).is_some_and(|t| {
            let s = t.confidence().score;
            t.state().is_tracking() && s.is_finite() && s >= self.min_scores[role_index(role)]
        })
    }

    /// One cycle while holding, after the frame's tracker update, on the frame's images.
    /// `epipolar`: the calibration's constraint, when there is one, to verify re-found targets.
    pub fn step(
        &mut self,
        trackers: &mut StereoTrackerSet,
        left: &ImageView<'_>,
        right: &ImageView<'_>,
        now_ns: u64,
        epipolar: Option<&EpipolarCheck>,
    ) -> RecoveryStep {
        if crate::phase::timed_out(self.start_ns.saturating_add(self.excused_ns), now_ns, self.patience_s) {
            let passes = self.slots.iter().map(|s| s.passes).max().unwrap_or(0);
            return RecoveryStep::Failed(RecoveryError::NotFound { what: self.what(), patience_s: self.patience_s, passes, best_score: self.best_score });
        }
        if let Some(frames) = self.confirmed {
            return self.confirm(trackers, frames, now_ns);
        }
        for i in 0..self.slots.len() {
            if self.slots[i].found.is_some() {
                continue;
            }
            let (role, view) = (self.slots[i].role, self.slots[i].view);
            // Both contours of a view lost: the target follows the plate's shift (a moved
            // camera), unless the plate's own search has come up empty a few times.
            if role == Role::Target
                && let Some(g) = self.slots.iter().find(|s| s.role == Role::Gripper && s.view == view)
                && (g.found.is_some() || g.passes < 3)
            {
                let Some(d) = g.found else { continue };
                let frame = ShiftSearch::shifted(&self.slots[i].base, d);
                if let Some(t) = trackers.get_mut(role, view) {
                    let _ = t.reinit_at(frame);
                    trackers.set_active(role, view, true);
                }
                self.slots[i].found = Some(d);
                continue;
            }
            let image = if view == View::Left { left } else { right };
            let Some(base) = trackers.get(role, view) else {
                return RecoveryStep::Failed(RecoveryError::NoTracker { what: self.what() });
            };
            let min = self.min_candidate(role);
            let mate_plate = if role == Role::Gripper { self.mate_plate(trackers, view) } else { None };
            let slot = &mut self.slots[i];
            let set: &StereoTrackerSet = trackers;
            let refused = slot.refused.as_deref();
            let accept = |cand: &ContourTracker| plausible(cand, role, view, set, epipolar, mate_plate) && !refused.is_some_and(|r| same_lock(cand, r));
            match slot.search.step_where(base, image, accept) {
                SearchStep::Searching => {}
                SearchStep::Done(Some(best)) if best.score >= min => {
                    tracing::debug!(who = %name(role, view), score = best.score, shift = ?best.shift_px, "candidate taken");
                    let frame = best.frame;
                    slot.found = Some(best.shift_px);
                    self.best_score = self.best_score.max(best.score);
                    if let Some(t) = trackers.get_mut(role, view) {
                        let _ = t.reinit_at(frame);
                        trackers.set_active(role, view, true);
                    }
                }
                SearchStep::Done(best) => {
                    tracing::debug!(who = %name(role, view), passes = slot.passes, best = ?best, min, "search pass: nothing good enough");
                    self.best_score = self.best_score.max(best.map_or(0.0, |b| b.score));
                    slot.passes += 1;
                    // Alternately around where it was and where its motion predicts it.
                    let centre = if slot.passes % 2 == 1 {
                        let lost_s = now_ns.saturating_sub(slot.lost_ns) as f64 * 1e-9;
                        let p = slot.velocity_px_s * lost_s;
                        if p.norm() > MAX_PREDICTED_SHIFT_PX { p * (MAX_PREDICTED_SHIFT_PX / p.norm()) } else { p }
                    } else {
                        Vector2::zeros()
                    };
                    slot.search = ShiftSearch::new(settings(slot.passes), slot.base, centre);
                }
            }
        }
        if self.slots.iter().all(|s| s.found.is_some()) {
            self.confirmed = Some(0);
        }
        RecoveryStep::Searching
    }

    /// Every contour found: all must hold for [`CONFIRM_FRAMES`]; one that does not is
    /// searched for again.
    fn confirm(&mut self, trackers: &mut StereoTrackerSet, frames: u32, now_ns: u64) -> RecoveryStep {
        let mut relapsed = false;
        for i in 0..self.slots.len() {
            let (role, view) = (self.slots[i].role, self.slots[i].view);
            if !self.holds(trackers, role, view) {
                relapsed = true;
                if let Some(t) = trackers.get(role, view) {
                    tracing::debug!(who = %name(role, view), frames, state = ?t.state(), score = t.confidence().score, "re-found contour did not hold");
                }
                let s = &mut self.slots[i];
                s.found = None;
                s.passes = 0;
                s.search = ShiftSearch::new(settings(0), s.base, Vector2::zeros());
                trackers.set_active(role, view, false);
            }
        }
        if relapsed {
            self.relapses += 1;
            self.confirmed = None;
            return RecoveryStep::Searching;
        }
        let frames = frames + 1;
        self.confirmed = Some(frames);
        // Halfway, refine the re-found targets' outlines from their edges and restart them
        // there (as at acquisition: a knock or a nudge also turns the face a little).
        if frames == CONFIRM_FRAMES / 2 {
            for s in self.slots.iter().filter(|s| s.role == Role::Target) {
                if let Some(t) = trackers.get_mut(s.role, s.view)
                    && let Some(corners) = crate::gripper::refine_polygon(t)
                {
                    let _ = t.reinit(&corners);
                }
            }
        }
        if frames < CONFIRM_FRAMES {
            return RecoveryStep::Searching;
        }
        let knock = View::ALL.into_iter().find_map(|v| {
            let g = self.slots.iter().find(|s| s.role == Role::Gripper && s.view == v)?.found?;
            let t = self.slots.iter().find(|s| s.role == Role::Target && s.view == v)?.found?;
            ((g - t).norm() < 1e-9 && g.norm() > 0.0).then_some((v, [g.x, g.y]))
        });
        let mut shifts_px = [None; 4];
        for s in &self.slots {
            shifts_px[slot_index(s.role, s.view)] = s.found.map(|d| [d.x, d.y]);
        }
        RecoveryStep::Recovered { knock, held_s: now_ns.saturating_sub(self.start_ns) as f64 * 1e-9, shifts_px }
    }
}

#[cfg(test)]
#[path = "recovery_tests.rs"]
mod tests;
