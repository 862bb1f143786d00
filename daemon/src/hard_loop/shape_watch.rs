//! Which tracked frames may serve as a lost contour's search base. A contour that is being
//! lost often stays confident for a few frames while its shape goes wrong: an occluder's edge
//! sliding over the plate snaps one side onto it in a single frame (seed 9 of the `--disturb`
//! batch: 13 % narrower at confidence 0.999, lost the next frame), or squeezes it over a
//! dozen frames (seed 16: one axis down to 14 % of its length, still tracking). A search from
//! such a frame looks for the wrong shape and rejects the true contour by its area.
//!
//! A contour's shape (its frame's linear part: size, turn, skew) may change fast while it is
//! tracked truly — the servo's approach turns the plate out of its plane and changes its image
//! aspect by ~1.6 % a frame for seconds (`pick_cube_bump`) — but it changes *smoothly*: the
//! arm and the blocks are rigid and the arm's speed changes over many frames. An occluder's
//! edge changes it by a step within a few frames, against that trend. So the watch keeps the
//! shape's trend (its change per frame) and a reference that moves along it: a frame is a base
//! when, over the last few frames, its shape is where the trend took it, and it is close to
//! the reference.

use handeye_vision::tracker::TemplateFrame;
use nalgebra::Vector4;

/// Largest departure of a contour's shape from where its trend predicted it, over each of the
/// last [`STEP_WINDOW`] frames, that is still steady tracking: a norm relative to the shape's
/// norm (the approach's steps vary by ~0.2 % a frame about its trend; a side snapping onto an
/// occluder moves it by > 9 %, a 10 % squeeze of one side in 2 frames by 7 %).
const MAX_SHAPE_STEP: f64 = 0.04;
/// Frames over which a step is looked for: an occluder's edge squeezes the outline within 1-3
/// frames (0.1 s at 30 Hz), while the approach's trend holds for seconds.
const STEP_WINDOW: usize = 3;
/// Share of each steady frame's change taken into the trend: a time constant of 4 frames,
/// longer than an occluder's step is short (so [`STEP_WINDOW`] predicts from the trend before
/// the step) and short enough that the reference lags the approach's onset by ~4 × 1.6 % =
/// 6.4 %, within [`MAX_SHAPE_DRIFT`].
const TREND_RATE: f64 = 0.25;
/// Frames a contour's shape must have been steady before its frame is a base.
const STEADY_FRAMES: u32 = 3;
/// Largest distance from the contour's reference shape (see [`REFERENCE_RATE`]) for a base.
const MAX_SHAPE_DRIFT: f64 = 0.10;
/// Share of each base frame's shape taken into the reference, which moves along the trend
/// every frame besides (a time constant of ~20 frames, 0.7 s at 30 Hz).
const REFERENCE_RATE: f64 = 0.05;
/// Steady frames away from the reference after which the new shape is taken as the
/// contour's own (a true change the drift test would otherwise refuse for ever), 2 s at 30 Hz.
const RESEED_FRAMES: u32 = 60;

/// A frame's linear part (e1, e2) as one vector.
fn linear(f: &TemplateFrame) -> Vector4<f64> {
    Vector4::new(f.e1.x, f.e1.y, f.e2.x, f.e2.y)
}

/// `change`'s norm relative to `base`'s (infinite for a degenerate base).
fn relative(base: &Vector4<f64>, change: &Vector4<f64>) -> f64 {
    let n = base.norm();
    if n > 0.0 { change.norm() / n } else { f64::INFINITY }
}

/// One contour's shape history.
#[derive(Debug, Clone, Copy, Default)]
pub struct ShapeWatch {
    /// The last tracked frames' shapes and the trend as it stood after each, newest first.
    recent: [(Vector4<f64>, Vector4<f64>); STEP_WINDOW],
    /// How many of `recent` are consecutive tracked frames.
    tracked: usize,
    /// The shape's change per frame.
    trend: Vector4<f64>,
    reference: Option<Vector4<f64>>,
    steady: u32,
    off_reference: u32,
    updates: u64,
}

impl ShapeWatch {
    /// Takes this cycle's frame of the contour (`tracking`: its tracker tracked this frame;
    /// `updates`: its update count, which a re-initialised tracker starts again) and says
    /// whether the frame may be a search base. Called once a camera frame.
    pub fn observe(&mut self, frame: TemplateFrame, updates: u64, tracking: bool) -> bool {
        if updates < self.updates {
            // Re-initialised (a new template or a new place): its old shape means nothing.
            *self = Self::default();
        }
        self.updates = updates;
        // A frame has passed: the reference moves along the trend whether or not this one is
        // tracked or a base.
        if let Some(r) = self.reference.as_mut() {
            *r += self.trend;
        }
        if !tracking {
            self.tracked = 0;
            self.steady = 0;
            return false;
        }
        let shape = linear(&frame);
        // Where the trend at each of the last few frames predicted this one.
        let steady_now = self.tracked > 0
            && self.recent[..self.tracked].iter().enumerate().all(|(j, (past, trend))| {
                let predicted = past + trend * (j + 1) as f64;
                relative(past, &(shape - predicted)) <= MAX_SHAPE_STEP
            });
        if steady_now {
            // Only a steady change teaches the trend: a step must not become the motion.
            self.trend += (shape - self.recent[0].0 - self.trend) * TREND_RATE;
            self.steady = self.steady.saturating_add(1);
        } else {
            self.steady = 0;
        }
        self.recent.rotate_right(1);
        self.recent[0] = (shape, self.trend);
        self.tracked = (self.tracked + 1).min(STEP_WINDOW);
        if self.steady < STEADY_FRAMES {
            return false;
        }
        let Some(r) = self.reference else {
            self.reference = Some(shape);
            return true;
        };
        if relative(&r, &(shape - r)) <= MAX_SHAPE_DRIFT {
            self.reference = Some(r + (shape - r) * REFERENCE_RATE);
            self.off_reference = 0;
            return true;
        }
        self.off_reference += 1;
        if self.off_reference >= RESEED_FRAMES && self.steady >= RESEED_FRAMES {
            self.reference = Some(shape);
            self.off_reference = 0;
            return true;
        }
        false
    }
}
#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector2;

    /// A contour `size` px tall whose width is `size * squeeze`, at x = `x`.
    fn square(size: f64, squeeze: f64, x: f64) -> TemplateFrame {
        TemplateFrame::new(Vector2::new(x, 100.0), Vector2::new(size * squeeze, 0.0), Vector2::new(0.0, size))
    }

    fn change(a: &TemplateFrame, b: &TemplateFrame) -> f64 {
        relative(&linear(a), &(linear(b) - linear(a)))
    }

    #[test]
    fn a_snap_is_no_base_a_steady_move_is() {
        let mut w = ShapeWatch::default();
        // Tracked steadily, moving 3 px and growing 0.2 % a frame: a base from the 4th frame.
        let good: Vec<bool> = (0..40).map(|k| w.observe(square(47.0 * (1.0 + 0.002 * k as f64), 1.0, 3.0 * k as f64), k + 1, true)).collect();
        assert!(!good[..3].iter().any(|&g| g) && good[3..].iter().all(|&g| g), "{good:?}");
        // One side snaps 13 % inwards (seed 9): not a base, nor while it holds there briefly.
        assert!(!w.observe(square(47.0 * 1.078, 0.87, 120.0), 41, true));
        assert!(!w.observe(square(47.0 * 1.078, 0.87, 120.0), 42, true));
        // Re-initialised on another contour (the update count starts again): its shape is
        // taken after it has been steady.
        assert!(!w.observe(square(30.0, 1.0, 0.0), 1, true));
        for k in 2..5 {
            w.observe(square(30.0, 1.0, 0.0), k, true);
        }
        assert!(w.observe(square(30.0, 1.0, 0.0), 5, true));
    }

    /// The servo's approach (pick_cube_bump): the plate, still until then, changes its image
    /// aspect from one frame to the next by 1.6 % of its shape (the measured steps were
    /// 0.013-0.017) for a second. Its frames are bases after a few frames of the onset, every
    /// one of them; a squeeze of one side by 10 % within 2 frames on top of that trend (an
    /// occluder's edge) is not, nor are the frames just after it.
    #[test]
    fn the_approach_trend_is_the_plates_own_shape_an_occluders_step_is_not() {
        let mut w = ShapeWatch::default();
        for k in 0..20 {
            w.observe(square(50.0, 1.0, 0.0), k + 1, true);
        }
        // One side narrowing linearly: each step 1.6 % of the shape at the start, 2.1 % at
        // the end (a width of 1.0 down to 0.32 of the height).
        let width = |k: u64| 1.0 - 0.0226 * k as f64;
        let frames: Vec<TemplateFrame> = (1..=30).map(|k| square(50.0, width(k), 2.0 * k as f64)).collect();
        let first_step = change(&square(50.0, 1.0, 0.0), &frames[0]);
        assert!((first_step - 0.016).abs() < 0.001, "{first_step}");
        let good: Vec<bool> = frames.iter().zip(21..).map(|(f, k)| w.observe(*f, k, true)).collect();
        let onset = STEP_WINDOW + STEADY_FRAMES as usize;
        assert!(good[onset..].iter().all(|&g| g), "the approach's frames refused: {good:?}");
        // Mid-trend, the long side squeezed 10 % within 2 frames, then following the trend.
        let squeezed: Vec<bool> = (31..40)
            .map(|k| {
                let step = if k == 31 { 0.95 } else { 0.90 };
                w.observe(square(50.0 * step, width(k) / step, 2.0 * k as f64), 20 + k, true)
            })
            .collect();
        assert!(!squeezed[..2 + STEP_WINDOW].iter().any(|&g| g), "a base in or just after the squeeze: {squeezed:?}");
        // The same step with no trend (the plate standing still): its first half (5 %, 3.5 %
        // of the shape) is within a steady frame's change, the frame that completes it and
        // those after it while it is in the window are refused.
        let mut w = ShapeWatch::default();
        for k in 0..20 {
            w.observe(square(50.0, 1.0, 0.0), k + 1, true);
        }
        w.observe(square(47.5, 1.0 / 0.95, 0.0), 21, true);
        let squeezed: Vec<bool> = (22..22 + STEP_WINDOW as u64).map(|k| w.observe(square(45.0, 1.0 / 0.90, 0.0), k, true)).collect();
        assert!(!squeezed.iter().any(|&g| g), "{squeezed:?}");
    }

    /// Seed 16: an occluder squeezes one side down to 14 % of its length over a dozen frames
    /// while it is still tracked. None of those frames is a base.
    #[test]
    fn a_fast_squeeze_is_no_base() {
        let mut w = ShapeWatch::default();
        for k in 0..20 {
            w.observe(square(50.0, 1.0, 0.0), k + 1, true);
        }
        let squeezed: Vec<bool> = (1..=12).map(|k| w.observe(square(50.0, 1.0 - 0.86 * k as f64 / 12.0, 0.0), 20 + k, true)).collect();
        assert!(!squeezed.iter().any(|&g| g), "{squeezed:?}");
    }
}
