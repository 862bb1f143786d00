//! Searching for a lost contour: restart a copy of its tracker at its last good template
//! frame moved by each of a grid of image translations around a predicted shift, nearest
//! first, a bounded number of candidates per frame, and keep the one that tracks most
//! confidently. Used by the camera-knock recovery ([`crate::recovery`], the gripper plate
//! after a knocked view) and by observe mode ([`crate::observe`], any lost track, searched
//! around its last pose and where its motion predicts it).
//!
//! Allocates (a tracker clone per candidate): it runs only while a track is lost.

use handeye_vision::image::ImageView;
use handeye_vision::tracker::{ContourTracker, TemplateFrame};
use nalgebra::Vector2;

/// How a search looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SearchSettings {
    /// Largest shift from the centre searched, px.
    pub max_shift_px: f64,
    /// Grid step, px (the tracker's own normal search covers about ±12 px).
    pub step_px: f64,
    /// Candidates tried per frame.
    pub candidates_per_frame: usize,
    /// A candidate whose area changed by more than this factor (either way) is another
    /// contour (a plate's dark border has an outer edge too, tracked just as confidently).
    pub max_area_ratio: f64,
    /// Confidence at which the search stops early: nothing better is to be expected.
    pub good_enough_score: f64,
}

impl Default for SearchSettings {
    fn default() -> Self {
        Self { max_shift_px: 160.0, step_px: 10.0, candidates_per_frame: 120, max_area_ratio: 1.11, good_enough_score: 0.95 }
    }
}

/// What one search cycle concluded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SearchStep {
    /// Candidates are left to try.
    Searching,
    /// Every candidate was tried (or one was good enough): the best, `None` if none tracked.
    Done(Option<Candidate>),
}

/// The best candidate found: its confidence, the shift of the template frame it
/// converged to (finer than the grid), px, and that frame (restart a tracker there: it
/// carries the turn and scale the candidate converged to as well).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Candidate {
    pub score: f64,
    pub shift_px: Vector2<f64>,
    pub frame: TemplateFrame,
}

/// One search over the grid around a centre shift.
pub struct ShiftSearch {
    settings: SearchSettings,
    /// The contour's last good template frame.
    frame: TemplateFrame,
    candidates: Vec<Vector2<f64>>,
    next: usize,
    best: Option<Candidate>,
}

impl ShiftSearch {
    /// A search for the contour last seen at `frame`, around `centre_px` (the predicted
    /// shift; zero = where it was).
    pub fn new(settings: SearchSettings, frame: TemplateFrame, centre_px: Vector2<f64>) -> Self {
        let step = settings.step_px.max(1.0);
        let n = (settings.max_shift_px / step).floor() as i32;
        let mut candidates: Vec<Vector2<f64>> =
            (-n..=n).flat_map(|i| (-n..=n).map(move |j| Vector2::new(f64::from(i) * step, f64::from(j) * step))).collect();
        // Nearest the centre first: a small miss is found quickly.
        candidates.sort_by(|a, b| a.norm().total_cmp(&b.norm()));
        for c in &mut candidates {
            *c += centre_px;
        }
        Self { settings, frame, candidates, next: 0, best: None }
    }

    /// The frame the search restarts trackers from.
    pub fn frame(&self) -> TemplateFrame {
        self.frame
    }

    /// `frame` moved by `shift_px`.
    pub fn shifted(frame: &TemplateFrame, shift_px: Vector2<f64>) -> TemplateFrame {
        TemplateFrame::new(frame.origin + shift_px, frame.e1, frame.e2)
    }

    /// Tries this frame's share of the candidates on `image` with copies of `base` (the
    /// lost tracker: its template and settings).
    pub fn step(&mut self, base: &ContourTracker, image: &ImageView<'_>) -> SearchStep {
        self.step_where(base, image, |_| true)
    }

    /// [`Self::step`], taking only candidates `accept` agrees to (e.g. not on another tracked
    /// contour, consistent with the other view).
    pub fn step_where(&mut self, base: &ContourTracker, image: &ImageView<'_>, accept: impl Fn(&ContourTracker) -> bool) -> SearchStep {
        let end = (self.next + self.settings.candidates_per_frame).min(self.candidates.len());
        for &d in &self.candidates[self.next..end] {
            let mut t: ContourTracker = base.clone();
            if t.reinit_at(Self::shifted(&self.frame, d)).is_err() {
                continue;
            }
            if !t.update(image, 0.0).is_tracking() || !t.update(image, 0.0).is_tracking() {
                continue;
            }
            let ratio = t.frame().det() / self.frame.det();
            let max = self.settings.max_area_ratio.max(1.0);
            if !(1.0 / max..=max).contains(&ratio) {
                continue;
            }
            if !accept(&t) {
                continue;
            }
            let score = t.confidence().score;
            if self.best.is_none_or(|b| score > b.score) {
                self.best = Some(Candidate { score, shift_px: t.frame().origin - self.frame.origin, frame: t.frame() });
            }
        }
        self.next = end;
        if self.next < self.candidates.len() && self.best.is_none_or(|b| b.score < self.settings.good_enough_score) {
            return SearchStep::Searching;
        }
        SearchStep::Done(self.best)
    }
}

/// A scene for the search's tests and observe's watch tests: a dark 40 px square on a light
/// 320x240 image, its top-left corner at (60 + dx, 60 + dy).
#[cfg(test)]
pub(crate) fn square_at(dx: usize, dy: usize) -> handeye_vision::image::ImageBuf {
    let mut img = handeye_vision::image::ImageBuf::filled(320, 240, 200);
    for y in 60 + dy..100 + dy {
        for x in 60 + dx..100 + dx {
            img.set(x, y, 50);
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use handeye_vision::image::ImageBuf;
    use handeye_vision::tracker::TrackerConfig;

    #[test]
    fn a_square_that_jumped_is_found_near_the_predicted_shift() {
        let square = [[59.5, 59.5], [99.5, 59.5], [99.5, 99.5], [59.5, 99.5]];
        let mut t = ContourTracker::new(TrackerConfig::default(), &square).unwrap();
        let before = square_at(0, 0);
        for _ in 0..3 {
            assert!(t.update(&before.view(), 0.03).is_tracking());
        }
        let frame = t.frame();
        // It jumped 130 px right, 45 px down; predicted 120 px right: found within a few frames.
        let after = square_at(130, 45);
        let mut search = ShiftSearch::new(SearchSettings::default(), frame, Vector2::new(120.0, 0.0));
        let mut found = None;
        for _ in 0..10 {
            if let SearchStep::Done(best) = search.step(&t, &after.view()) {
                found = best;
                break;
            }
        }
        let best = found.expect("found");
        assert!((best.shift_px.x - 130.0).abs() < 1.0 && (best.shift_px.y - 45.0).abs() < 1.0, "{best:?}");
        // Nothing there: done, with nothing.
        let blank = ImageBuf::filled(320, 240, 200);
        let settings = SearchSettings { max_shift_px: 30.0, ..SearchSettings::default() };
        let mut search = ShiftSearch::new(settings, frame, Vector2::zeros());
        assert_eq!(search.step(&t, &blank.view()), SearchStep::Done(None));
    }
}
