//! One tracked contour in one view, watched over the stream: acquired from a hint
//! (converging, its corners refined from the image's edges, then verified), tracking, lost
//! (searched for around its last pose and where its motion predicts it, with
//! [`crate::track_search`]) and found again (confirmed over a few frames before it counts).
//! It keeps the counts `observe.json` reports.

use handeye_vision::image::ImageView;
use handeye_vision::tracker::{ContourTracker, TemplateFrame, TrackState};
use nalgebra::Vector2;
use serde::{Deserialize, Serialize};

use crate::track_search::{SearchSettings, SearchStep, ShiftSearch};

/// Frames a re-found contour must track before it counts as found.
pub const CONFIRM_FRAMES: u32 = 6;
/// Confidence a search candidate needs to be taken.
pub const FOUND_SCORE: f64 = 0.6;
/// How a lost contour is searched for: the tracker's default grid, and a looser size check
/// than the plate's (a hand-held camera changes a face's size between losing and finding
/// it; the plate's dark border, which the default guards against, is not in play here).
const SEARCH: SearchSettings = SearchSettings { max_shift_px: 160.0, step_px: 10.0, candidates_per_frame: 120, max_area_ratio: 1.5, good_enough_score: 0.8 };

/// Largest predicted shift a search is centred on, px (the prediction grows with the time
/// lost; past this it is a guess).
const MAX_PREDICTED_SHIFT_PX: f64 = 120.0;

/// Where a watched contour stands.
pub enum WatchState {
    /// No tracker in this slot (e.g. the right view of a mono stream).
    Off,
    /// Converging from the hint for `frames` frames.
    Acquiring { frames: u32 },
    Tracking,
    /// Lost: searched for (`searches`: searches finished without finding it).
    Lost { search: Box<ShiftSearch>, searches: u32 },
    /// Found again, confirming for `frames` frames.
    Confirming { frames: u32 },
}

/// What changed this frame, for the report's key moments.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WatchEvent {
    Acquired,
    Lost,
    Refound,
}

/// The counts of one watched contour (`observe.json`, `trackers[]`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WatchCounts {
    /// `target_left`, `target_right`, `gripper_left`, `gripper_right`.
    pub name: String,
    /// Frame id at which the hint's contour was verified (`None`: never).
    pub acquired_frame_id: Option<u64>,
    /// Frames it tracked (acquiring and confirming included) and frames it was lost.
    pub tracked_frames: u64,
    pub lost_frames: u64,
    /// Frame ids at which it was lost, and at which it was found again.
    pub losses: Vec<u64>,
    pub refinds: Vec<u64>,
    /// Why each of `losses` happened: the tracker's lost reason (e.g. "wrong lock: …"), or
    /// its confidence under the minimum.
    #[serde(default)]
    pub loss_reasons: Vec<String>,
}

/// One watched contour.
pub struct TrackWatch {
    pub state: WatchState,
    pub counts: WatchCounts,
    /// The last template frame it tracked confidently, and when (camera ns).
    last_good: Option<(TemplateFrame, u64)>,
    /// Image velocity of the frame's origin while tracking, px/s (smoothed).
    velocity_px_s: Vector2<f64>,
    /// Frames to converge from the hint; confidence it must hold.
    converge_frames: u32,
    min_score: f64,
}

impl TrackWatch {
    pub fn off(name: &str) -> Self {
        Self::new(name, WatchState::Off, 0, 0.0)
    }

    pub fn acquiring(name: &str, converge_frames: u32, min_score: f64) -> Self {
        Self::new(name, WatchState::Acquiring { frames: 0 }, converge_frames, min_score)
    }

    fn new(name: &str, state: WatchState, converge_frames: u32, min_score: f64) -> Self {
        Self {
            state,
            counts: WatchCounts { name: name.to_string(), ..WatchCounts::default() },
            last_good: None,
            velocity_px_s: Vector2::zeros(),
            converge_frames,
            min_score,
        }
    }

    /// Telemetry's tracker state: 0 off, 1 tracking (or acquiring, confirming), 2 lost.
    pub fn telemetry_state(&self) -> u32 {
        match self.state {
            WatchState::Off => 0,
            WatchState::Lost { .. } => 2,
            _ => 1,
        }
    }

    pub fn is_lost(&self) -> bool {
        matches!(self.state, WatchState::Lost { .. })
    }

    /// Whether the tracker should run on this frame (it rests while searched for).
    pub fn runs(&self) -> bool {
        !matches!(self.state, WatchState::Off | WatchState::Lost { .. })
    }

    /// After the frame's tracker update (`state`: what it reported, `None` if it did not
    /// run): advances the watch, searching on `image` when lost. `frame_id` names the frame,
    /// `now_ns` its camera time. Returns what changed.
    pub fn step(&mut self, tracker: &mut ContourTracker, state: Option<&TrackState>, image: &ImageView<'_>, frame_id: u64, now_ns: u64) -> Option<WatchEvent> {
        let score = tracker.confidence().score;
        let confident = matches!(state, Some(s) if s.is_tracking()) && score.is_finite() && score >= self.min_score;
        let min_score = self.min_score;
        let why = || match state.and_then(|s| s.lost_reason()) {
            Some(reason) => reason.to_string(),
            None => format!("confidence {score:.2} under {min_score:.2}"),
        };
        let predicted = self.predicted_shift_px(now_ns);
        let event = match &mut self.state {
            WatchState::Off => return None,
            WatchState::Acquiring { frames } => {
                *frames += 1;
                // Twice while converging: refine the hinted corners from the image's edges and
                // restart on them (the hint's corner errors would otherwise stay).
                let third = self.converge_frames / 3;
                if third > 0 && (*frames == third || *frames == 2 * third) && let Some(corners) = crate::gripper::refine_polygon(tracker) {
                    let _ = tracker.reinit(&corners);
                }
                if *frames < self.converge_frames.max(1) {
                    None
                } else if confident {
                    self.state = WatchState::Tracking;
                    self.counts.acquired_frame_id = Some(frame_id);
                    Some(WatchEvent::Acquired)
                } else {
                    self.lose(tracker, frame_id, now_ns, why());
                    Some(WatchEvent::Lost)
                }
            }
            WatchState::Tracking => {
                if confident {
                    None
                } else {
                    self.lose(tracker, frame_id, now_ns, why());
                    Some(WatchEvent::Lost)
                }
            }
            WatchState::Confirming { frames } => {
                *frames += 1;
                if !confident {
                    self.lose(tracker, frame_id, now_ns, why());
                    None // still the same loss
                } else if *frames >= CONFIRM_FRAMES {
                    self.state = WatchState::Tracking;
                    self.counts.refinds.push(frame_id);
                    Some(WatchEvent::Refound)
                } else {
                    None
                }
            }
            WatchState::Lost { search, searches } => {
                match search.step(tracker, image) {
                    SearchStep::Searching => {}
                    SearchStep::Done(Some(best)) if best.score >= FOUND_SCORE => {
                        let _ = tracker.reinit_at(ShiftSearch::shifted(&search.frame(), best.shift_px));
                        self.state = WatchState::Confirming { frames: 0 };
                    }
                    SearchStep::Done(_) => {
                        // Nothing there now: search again, alternately where the motion
                        // predicts it and where it was last seen.
                        *searches += 1;
                        let centre = if *searches % 2 == 0 { predicted } else { Vector2::zeros() };
                        **search = ShiftSearch::new(SEARCH, search.frame(), centre);
                    }
                }
                None
            }
        };
        if matches!(self.state, WatchState::Lost { .. }) {
            self.counts.lost_frames += 1;
        } else {
            self.counts.tracked_frames += 1;
        }
        if matches!(self.state, WatchState::Tracking) && confident {
            self.note_good(tracker.frame(), now_ns);
        }
        event
    }

    fn note_good(&mut self, frame: TemplateFrame, now_ns: u64) {
        if let Some((last, t)) = self.last_good {
            let dt_s = now_ns.saturating_sub(t) as f64 * 1e-9;
            if dt_s > 0.0 {
                let v = (frame.origin - last.origin) / dt_s;
                self.velocity_px_s = self.velocity_px_s * 0.5 + v * 0.5;
            }
        }
        self.last_good = Some((frame, now_ns));
    }

    /// Where the motion seen so far puts the contour now, relative to its last good frame.
    fn predicted_shift_px(&self, now_ns: u64) -> Vector2<f64> {
        let Some((_, t)) = self.last_good else { return Vector2::zeros() };
        let d = self.velocity_px_s * (now_ns.saturating_sub(t) as f64 * 1e-9);
        if d.norm() > MAX_PREDICTED_SHIFT_PX { d * (MAX_PREDICTED_SHIFT_PX / d.norm()) } else { d }
    }

    fn lose(&mut self, tracker: &ContourTracker, frame_id: u64, now_ns: u64, why: String) {
        if !matches!(self.state, WatchState::Confirming { .. }) {
            tracing::info!(tracker = %self.counts.name, frame_id, reason = %why, "observe: lost");
            self.counts.losses.push(frame_id);
            self.counts.loss_reasons.push(why);
        }
        let frame = self.last_good.map_or_else(|| tracker.frame(), |(f, _)| f);
        let search = ShiftSearch::new(SEARCH, frame, self.predicted_shift_px(now_ns));
        self.state = WatchState::Lost { search: Box::new(search), searches: 0 };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::image::ImageBuf;
    use handeye_vision::tracker::TrackerConfig;
    use crate::track_search::square_at;

    #[test]
    fn a_contour_is_acquired_lost_while_hidden_and_found_again_where_it_reappears() {
        let square = [[58.0, 61.0], [101.0, 59.0], [99.5, 99.5], [59.5, 101.0]];
        let mut t = ContourTracker::new(TrackerConfig::default(), &square).unwrap();
        let mut w = TrackWatch::acquiring("target_left", 6, 0.5);
        let (mut frame_id, mut now) = (0u64, 0u64);
        let mut run = |t: &mut ContourTracker, w: &mut TrackWatch, img: &ImageBuf| {
            frame_id += 1;
            now += 33_333_333;
            let state = w.runs().then(|| t.update(&img.view(), 0.033));
            w.step(t, state.as_ref(), &img.view(), frame_id, now)
        };
        let seen = square_at(0, 0);
        let events: Vec<_> = (0..8).filter_map(|_| run(&mut t, &mut w, &seen)).collect();
        assert_eq!(events, vec![WatchEvent::Acquired]);
        assert_eq!(w.counts.acquired_frame_id, Some(6));
        // Hidden for ten frames: lost at once, searched for, reported lost meanwhile.
        let blank = ImageBuf::filled(320, 240, 200);
        let events: Vec<_> = (0..10).filter_map(|_| run(&mut t, &mut w, &blank)).collect();
        assert_eq!(events, vec![WatchEvent::Lost]);
        assert!(w.is_lost() && w.telemetry_state() == 2);
        // It reappears 70 px to the right: found, confirmed, tracking there.
        let moved = square_at(70, 10);
        let events: Vec<_> = (0..30).filter_map(|_| run(&mut t, &mut w, &moved)).collect();
        assert_eq!(events, vec![WatchEvent::Refound]);
        assert!(matches!(w.state, WatchState::Tracking));
        let c = t.corners().next().unwrap();
        assert!((c.x - 129.5).abs() < 1.5 && (c.y - 69.5).abs() < 1.5, "{c:?}");
        assert_eq!((w.counts.losses.len(), w.counts.refinds.len()), (1, 1));
        assert!(w.counts.lost_frames >= 10, "{:?}", w.counts);
    }
}
