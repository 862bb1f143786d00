//! Which tracked frames may serve as a lost contour's search base. A contour that is being
//! lost often stays confident for a few frames while its shape goes wrong: an occluder's edge
//! sliding over the plate snaps one side onto it in a single frame (seed 9 of the `--disturb`
//! batch: 13 % narrower at confidence 0.999, lost the next frame), or squeezes it over a
//! dozen frames (seed 16: one axis down to 14 % of its length, still tracking). A search from
//! such a frame looks for the wrong shape and rejects the true contour by its area. A
//! contour's shape (its frame's linear part: size, turn, skew) changes slowly while it is
//! tracked truly — the arm and the blocks are rigid, the views move little between frames —
//! so a frame is a base only when its shape is steady from frame to frame and close to the
//! contour's recent shape.

use handeye_vision::tracker::TemplateFrame;

/// Largest frame-to-frame change of a contour's shape that is still steady tracking: the norm
/// of the change of the frame's linear part over its norm (an arm at full speed changes it by
/// ~0.5 % a frame; a side snapping onto an occluder by > 10 %).
const MAX_SHAPE_STEP: f64 = 0.04;
/// Frames a contour's shape must have been steady before its frame is a base.
const STEADY_FRAMES: u32 = 3;
/// Largest change from the contour's recent shape (see [`REFERENCE_RATE`]) for a base.
const MAX_SHAPE_DRIFT: f64 = 0.10;
/// Share of each base frame's shape taken into the recent shape (a time constant of ~20
/// frames, 0.7 s at 30 Hz).
const REFERENCE_RATE: f64 = 0.05;
/// Steady frames away from the recent shape after which the new shape is taken as the
/// contour's own (a true change the drift test would otherwise refuse for ever), 2 s at 30 Hz.
const RESEED_FRAMES: u32 = 60;

/// Relative change of the linear part (e1, e2) from `a` to `b`.
pub fn shape_change(a: &TemplateFrame, b: &TemplateFrame) -> f64 {
    let d = (b.e1 - a.e1).norm_squared() + (b.e2 - a.e2).norm_squared();
    let n = a.e1.norm_squared() + a.e2.norm_squared();
    if n > 0.0 { (d / n).sqrt() } else { f64::INFINITY }
}

/// One contour's shape history.
#[derive(Debug, Clone, Copy, Default)]
pub struct ShapeWatch {
    prev: Option<TemplateFrame>,
    reference: Option<TemplateFrame>,
    steady: u32,
    off_reference: u32,
    updates: u64,
}

impl ShapeWatch {
    /// Takes this cycle's frame of the contour (`tracking`: its tracker tracked this frame;
    /// `updates`: its update count, which a re-initialised tracker starts again) and says
    /// whether the frame may be a search base.
    pub fn observe(&mut self, frame: TemplateFrame, updates: u64, tracking: bool) -> bool {
        if updates < self.updates {
            // Re-initialised (a new template or a new place): its old shape means nothing.
            *self = Self::default();
        }
        self.updates = updates;
        if !tracking {
            self.prev = None;
            self.steady = 0;
            return false;
        }
        self.steady = match self.prev {
            Some(p) if shape_change(&p, &frame) <= MAX_SHAPE_STEP => self.steady.saturating_add(1),
            _ => 0,
        };
        self.prev = Some(frame);
        if self.steady < STEADY_FRAMES {
            return false;
        }
        let Some(r) = self.reference else {
            self.reference = Some(frame);
            return true;
        };
        if shape_change(&r, &frame) <= MAX_SHAPE_DRIFT {
            let mix = |a: nalgebra::Vector2<f64>, b: nalgebra::Vector2<f64>| a + (b - a) * REFERENCE_RATE;
            self.reference = Some(TemplateFrame::new(frame.origin, mix(r.e1, frame.e1), mix(r.e2, frame.e2)));
            self.off_reference = 0;
            return true;
        }
        self.off_reference += 1;
        if self.off_reference >= RESEED_FRAMES && self.steady >= RESEED_FRAMES {
            self.reference = Some(frame);
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

    fn square(size: f64, squeeze: f64, x: f64) -> TemplateFrame {
        TemplateFrame::new(Vector2::new(x, 100.0), Vector2::new(size * squeeze, 0.0), Vector2::new(0.0, size))
    }

    #[test]
    fn a_snap_or_a_slow_squeeze_is_no_base_a_steady_move_is() {
        let mut w = ShapeWatch::default();
        // Tracked steadily, moving 3 px and growing 0.2 % a frame: a base from the 4th frame.
        let good: Vec<bool> = (0..40).map(|k| w.observe(square(47.0 * (1.0 + 0.002 * k as f64), 1.0, 3.0 * k as f64), k + 1, true)).collect();
        assert!(!good[..3].iter().any(|&g| g) && good[3..].iter().all(|&g| g), "{good:?}");
        // One side snaps 13 % inwards (seed 9): not a base, nor while it holds there briefly.
        assert!(!w.observe(square(47.0 * 1.078, 0.87, 120.0), 41, true));
        assert!(!w.observe(square(47.0 * 1.078, 0.87, 120.0), 42, true));
        // A squeeze of 2 % a frame (each step "steady") stops being a base once it drifts
        // 10 % from the recent shape.
        let mut w = ShapeWatch::default();
        for k in 0..20 {
            assert!(w.observe(square(50.0, 1.0, 0.0), k + 1, true) || k < 3);
        }
        let squeezed: Vec<bool> = (1..30).map(|k| w.observe(square(50.0, 1.0 - 0.02 * k as f64, 0.0), 20 + k, true)).collect();
        let last_base = squeezed.iter().rposition(|&g| g).unwrap();
        assert!(last_base < 10, "a base at {}% squeeze: {squeezed:?}", 2 * (last_base + 1));
        // Re-initialised on another contour (the update count starts again): its shape is
        // taken after it has been steady.
        assert!(!w.observe(square(30.0, 1.0, 0.0), 1, true));
        for k in 2..5 {
            w.observe(square(30.0, 1.0, 0.0), k, true);
        }
        assert!(w.observe(square(30.0, 1.0, 0.0), 5, true));
    }
}
