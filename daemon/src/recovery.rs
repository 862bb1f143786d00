//! Re-acquiring the trackers of one view after its camera moved (a knock): both the plate
//! and the target are lost in that view at once while the other view still tracks both. The
//! arm is stopped; the plate tracker (the highest-contrast contour) is searched for over a
//! grid of image translations of its last good frame (a few hundred candidates, spread over
//! frames, `CANDIDATES_PER_FRAME` per cycle); the best one restarts it, the target tracker
//! restarts at its last good frame moved by the same translation (a knocked camera shifts
//! the whole view), and both must track confidently for a while before the servo resumes
//! with fresh measurements. The coplanarity servo compares gripper and target in the same
//! images, so the stale calibration of the moved camera only makes its Jacobian less exact.
//!
//! Allocates (tracker clones per candidate): it runs only while the arm is stopped.

use handeye_vision::image::ImageView;
use handeye_vision::tracker::{AffineFrame, ContourTracker, Role, StereoTrackerSet, View};
use nalgebra::Vector2;

/// Largest view shift searched for, px (a 3° pan at f = 1800 px is ~94 px).
pub const MAX_SHIFT_PX: f64 = 160.0;
/// Grid step of the search, px (the tracker's own search covers ±12 px).
pub const STEP_PX: f64 = 10.0;
/// Candidates tried per frame.
pub const CANDIDATES_PER_FRAME: usize = 120;
/// Confidence a candidate needs to be taken.
pub const MIN_SCORE: f64 = 0.8;
/// Frames both restarted trackers must track before the servo resumes.
pub const CONFIRM_FRAMES: u32 = 12;

/// The state of one re-acquisition.
pub struct Recovery {
    pub view: View,
    pub start_frame: u64,
    gripper_frame: AffineFrame,
    target_frame: AffineFrame,
    candidates: Vec<Vector2<f64>>,
    next: usize,
    best: Option<(f64, Vector2<f64>)>,
    confirmed: Option<u32>,
}

/// What a recovery cycle concluded.
#[derive(Debug, Clone, PartialEq)]
pub enum RecoveryStep {
    Searching,
    /// Both trackers of the view are back and steady.
    Recovered { shift_px: [f64; 2] },
    Failed(String),
}

impl Recovery {
    /// Starts re-acquiring `view`; `None` if its trackers are missing.
    pub fn start(trackers: &StereoTrackerSet, view: View, frame_index: u64) -> Option<Self> {
        let g = trackers.get(Role::Gripper, view)?.frame();
        let t = trackers.get(Role::Target, view)?.frame();
        // Nearest shifts first: a small knock is found quickly.
        let n = (MAX_SHIFT_PX / STEP_PX) as i32;
        let mut candidates: Vec<Vector2<f64>> =
            (-n..=n).flat_map(|i| (-n..=n).map(move |j| Vector2::new(f64::from(i) * STEP_PX, f64::from(j) * STEP_PX))).collect();
        candidates.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
        Some(Self { view, start_frame: frame_index, gripper_frame: g, target_frame: t, candidates, next: 0, best: None, confirmed: None })
    }

    fn shifted(f: &AffineFrame, d: Vector2<f64>) -> AffineFrame {
        AffineFrame::new(f.origin + d, f.e1, f.e2)
    }

    /// One cycle on `image` (the moved view).
    pub fn step(&mut self, trackers: &mut StereoTrackerSet, image: &ImageView<'_>, other_tracking: bool) -> RecoveryStep {
        if !other_tracking {
            return RecoveryStep::Failed("the other view lost its trackers too".into());
        }
        if let Some(frames) = self.confirmed.as_mut() {
            let ok = [Role::Gripper, Role::Target].iter().all(|&r| {
                trackers.get(r, self.view).is_some_and(|t| t.state().is_tracking() && t.confidence().score >= 0.6)
            });
            if !ok {
                return RecoveryStep::Failed("the re-acquired trackers did not hold".into());
            }
            *frames += 1;
            // Halfway, refine the target's outline from its edges and restart it there: the
            // shift is the plate's, and a knock also turns the view a little.
            if *frames == CONFIRM_FRAMES / 2
                && let Some(t) = trackers.get_mut(Role::Target, self.view)
                && let Some(corners) = crate::gripper::refine_polygon(t)
            {
                let _ = t.reinit(&corners);
            }
            if *frames >= CONFIRM_FRAMES {
                let d = self.best.map(|b| b.1).unwrap_or_default();
                return RecoveryStep::Recovered { shift_px: [d.x, d.y] };
            }
            return RecoveryStep::Searching;
        }
        let Some(base) = trackers.get(Role::Gripper, self.view).cloned() else {
            return RecoveryStep::Failed("no gripper tracker".into());
        };
        let end = (self.next + CANDIDATES_PER_FRAME).min(self.candidates.len());
        for &d in &self.candidates[self.next..end] {
            let mut t: ContourTracker = base.clone();
            if t.reinit_at(Self::shifted(&self.gripper_frame, d)).is_err() {
                continue;
            }
            if !t.update(image, 0.0).is_tracking() || !t.update(image, 0.0).is_tracking() {
                continue;
            }
            // Same size as before the knock: the plate's dark border has an outer edge too, and
            // a contour grown onto it tracks just as confidently.
            let ratio = t.frame().det() / self.gripper_frame.det();
            if !(0.9..=1.11).contains(&ratio) {
                continue;
            }
            let score = t.confidence().score;
            if self.best.is_none_or(|b| score > b.0) {
                // The shift the tracker converged to, finer than the grid.
                self.best = Some((score, t.frame().origin - self.gripper_frame.origin));
            }
        }
        self.next = end;
        if self.next < self.candidates.len() && self.best.is_none_or(|b| b.0 < 0.95) {
            return RecoveryStep::Searching;
        }
        match self.best {
            Some((score, d)) if score >= MIN_SCORE => {
                for (role, frame) in [(Role::Gripper, self.gripper_frame), (Role::Target, self.target_frame)] {
                    if let Some(t) = trackers.get_mut(role, self.view) {
                        let _ = t.reinit_at(Self::shifted(&frame, d));
                        trackers.set_active(role, self.view, true);
                    }
                }
                self.confirmed = Some(0);
                RecoveryStep::Searching
            }
            _ => RecoveryStep::Failed(format!(
                "the plate was not found within ±{MAX_SHIFT_PX:.0} px (best confidence {:.2})",
                self.best.map_or(0.0, |b| b.0)
            )),
        }
    }
}
