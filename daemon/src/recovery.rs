//! Re-acquiring the trackers of one view after its camera moved (a knock): both the plate
//! and the target are lost in that view at once while the other view still tracks both. The
//! arm is stopped; the plate tracker (the highest-contrast contour) is searched for over a
//! grid of image translations of its last good frame ([`crate::track_search`]: a few
//! hundred candidates, spread over frames, `CANDIDATES_PER_FRAME` per cycle); the best one
//! restarts it, the target tracker restarts at its last good frame moved by the same
//! translation (a knocked camera shifts the whole view), and both must track confidently
//! for a while before the servo resumes with fresh measurements. The coplanarity servo
//! compares gripper and target in the same images, so the stale calibration of the moved
//! camera only makes its Jacobian less exact.
//!
//! Allocates (tracker clones per candidate): it runs only while the arm is stopped.

use handeye_vision::image::ImageView;
use handeye_vision::tracker::{Role, StereoTrackerSet, TemplateFrame, View};
use nalgebra::Vector2;

use crate::track_search::{SearchSettings, SearchStep, ShiftSearch};

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
    target_frame: TemplateFrame,
    search: ShiftSearch,
    /// The plate's shift, once found.
    found: Option<Vector2<f64>>,
    confirmed: Option<u32>,
}

/// What a recovery cycle concluded.
#[derive(Debug, Clone, PartialEq)]
pub enum RecoveryStep {
    Searching,
    /// Both trackers of the view are back and steady.
    Recovered { shift_px: [f64; 2] },
    Failed(RecoveryError),
}

/// Why the trackers of the moved view were not re-acquired.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RecoveryError {
    #[error("the other view lost its trackers too")]
    OtherViewLost,
    #[error("the re-acquired trackers did not hold")]
    DidNotHold,
    #[error("no gripper tracker")]
    NoGripperTracker,
    #[error("the plate was not found within ±{:.0} px (best confidence {best_score:.2})", MAX_SHIFT_PX)]
    NotFound { best_score: f64 },
}

impl Recovery {
    /// Starts re-acquiring `view`; `None` if its trackers are missing.
    pub fn start(trackers: &StereoTrackerSet, view: View, frame_index: u64) -> Option<Self> {
        let g = trackers.get(Role::Gripper, view)?.frame();
        let t = trackers.get(Role::Target, view)?.frame();
        let settings = SearchSettings {
            max_shift_px: MAX_SHIFT_PX,
            step_px: STEP_PX,
            candidates_per_frame: CANDIDATES_PER_FRAME,
            ..SearchSettings::default()
        };
        let search = ShiftSearch::new(settings, g, Vector2::zeros());
        Some(Self { view, start_frame: frame_index, target_frame: t, search, found: None, confirmed: None })
    }

    /// One cycle on `image` (the moved view).
    pub fn step(&mut self, trackers: &mut StereoTrackerSet, image: &ImageView<'_>, other_tracking: bool) -> RecoveryStep {
        if !other_tracking {
            return RecoveryStep::Failed(RecoveryError::OtherViewLost);
        }
        if let Some(frames) = self.confirmed.as_mut() {
            let ok = [Role::Gripper, Role::Target].iter().all(|&r| {
                trackers.get(r, self.view).is_some_and(|t| t.state().is_tracking() && t.confidence().score >= 0.6)
            });
            if !ok {
                return RecoveryStep::Failed(RecoveryError::DidNotHold);
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
                let d = self.found.unwrap_or_default();
                return RecoveryStep::Recovered { shift_px: [d.x, d.y] };
            }
            return RecoveryStep::Searching;
        }
        let Some(base) = trackers.get(Role::Gripper, self.view) else {
            return RecoveryStep::Failed(RecoveryError::NoGripperTracker);
        };
        match self.search.step(base, image) {
            SearchStep::Searching => RecoveryStep::Searching,
            SearchStep::Done(Some(best)) if best.score >= MIN_SCORE => {
                let d = best.shift_px;
                for (role, frame) in [(Role::Gripper, self.search.frame()), (Role::Target, self.target_frame)] {
                    if let Some(t) = trackers.get_mut(role, self.view) {
                        let _ = t.reinit_at(ShiftSearch::shifted(&frame, d));
                        trackers.set_active(role, self.view, true);
                    }
                }
                self.found = Some(d);
                self.confirmed = Some(0);
                RecoveryStep::Searching
            }
            SearchStep::Done(best) => RecoveryStep::Failed(RecoveryError::NotFound { best_score: best.map_or(0.0, |b| b.score) }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::image::ImageBuf;
    use handeye_vision::tracker::{ContourTracker, TrackerConfig};

    /// A bright plate in a dark border (the gripper) and a grey square (the target), shifted
    /// by `(dx, dy)`.
    fn scene(dx: i64, dy: i64) -> ImageBuf {
        let mut img = ImageBuf::filled(400, 300, 90);
        let mut rect = |x0: i64, y0: i64, x1: i64, y1: i64, v: u8| {
            for y in (y0 + dy).max(0)..(y1 + dy).min(300) {
                for x in (x0 + dx).max(0)..(x1 + dx).min(400) {
                    img.set(x as usize, y as usize, v);
                }
            }
        };
        rect(150, 60, 210, 120, 10);
        rect(158, 68, 202, 112, 220);
        rect(160, 190, 200, 230, 170);
        img
    }

    fn trackers(img: &ImageBuf) -> StereoTrackerSet {
        let plate = [[157.5, 67.5], [201.5, 67.5], [201.5, 111.5], [157.5, 111.5]];
        let target = [[159.5, 189.5], [199.5, 189.5], [199.5, 229.5], [159.5, 229.5]];
        let mut set = StereoTrackerSet::new();
        for v in View::ALL {
            set.insert(Role::Gripper, v, ContourTracker::new(TrackerConfig::default(), &plate).unwrap());
            set.insert(Role::Target, v, ContourTracker::new(TrackerConfig::default(), &target).unwrap());
        }
        for _ in 0..3 {
            let s = set.update(&img.view(), &img.view(), 0.03);
            assert!(s.all_active_tracking());
        }
        set
    }

    #[test]
    fn a_knocked_view_is_found_again_at_its_shift() {
        let still = scene(0, 0);
        let mut set = trackers(&still);
        // The left camera is knocked: its whole image moves 63 px left and 7 px down.
        let knocked = scene(-63, 7);
        let states = set.update(&knocked.view(), &still.view(), 0.03);
        assert!(!states.get(Role::Gripper, View::Left).unwrap().is_tracking(), "a 63 px jump loses the tracker");
        let mut rec = Recovery::start(&set, View::Left, 10).unwrap();
        let mut shift = None;
        for _ in 0..40 {
            set.update(&knocked.view(), &still.view(), 0.03);
            match rec.step(&mut set, &knocked.view(), true) {
                RecoveryStep::Searching => {}
                RecoveryStep::Recovered { shift_px } => {
                    shift = Some(shift_px);
                    break;
                }
                RecoveryStep::Failed(why) => panic!("{why}"),
            }
        }
        let shift = shift.expect("recovered");
        assert!((shift[0] + 63.0).abs() < 1.0 && (shift[1] - 7.0).abs() < 1.0, "{shift:?}");
        // Both trackers of the view sit on their shapes again.
        let g = set.get(Role::Gripper, View::Left).unwrap();
        assert!(g.state().is_tracking());
        let c = g.corners().next().unwrap();
        assert!((c.x - (157.5 - 63.0)).abs() < 1.0 && (c.y - (67.5 + 7.0)).abs() < 1.0, "{c:?}");
        assert!(set.get(Role::Target, View::Left).unwrap().state().is_tracking());
    }

    #[test]
    fn nothing_to_find_fails_with_a_reason() {
        let still = scene(0, 0);
        let mut set = trackers(&still);
        let blank = ImageBuf::filled(400, 300, 90);
        set.update(&blank.view(), &still.view(), 0.03);
        let mut rec = Recovery::start(&set, View::Left, 0).unwrap();
        let mut outcome = RecoveryStep::Searching;
        for _ in 0..20 {
            outcome = rec.step(&mut set, &blank.view(), true);
            if outcome != RecoveryStep::Searching {
                break;
            }
        }
        assert!(matches!(&outcome, RecoveryStep::Failed(RecoveryError::NotFound { .. })), "{outcome:?}");
        if let RecoveryStep::Failed(why) = &outcome {
            assert!(why.to_string().contains("not found"), "{why}");
        }
        // And it gives up at once when the other view is lost too.
        let mut rec = Recovery::start(&set, View::Left, 0).unwrap();
        assert!(matches!(rec.step(&mut set, &blank.view(), false), RecoveryStep::Failed(_)));
    }
}
