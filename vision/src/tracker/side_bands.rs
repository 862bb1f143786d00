//! Evidence across the contour's sides: what lies just inside and just outside each stretch
//! of a side, against what that stretch has learnt lies there (issue 18 item 5).
//!
//! A contour that slides along one of its sides (on the real `visp-cube` sequence the top
//! face's bottom corner slides along the crease with the left face, sides 0 and 2 turning
//! about the other corners) keeps every side on *an* edge, so edge counts, residuals and
//! polarity see nothing (BENCHMARKS.md, s6-slide and s7-crease). What changes is which
//! surface lies on which side of a side: where the turned side 2 now runs 7 px beyond the
//! crease, the band just *inside* it is the right face, at the grey level that stretch had
//! learnt lay *outside* it. A true side never has its outside's appearance on its inside: the
//! face itself is what lies there. The opposite test (the outside turning like the inside) is
//! not used: on the same sequence's fast turn (frames 186-193) the face beyond side 0 darkens to
//! the top face's own level on good tracks, a real fade the test cannot tell from a slide.
//!
//! Per side, [`STRETCHES`] stretches between 10 % and 90 % of its length (off the corners,
//! where two sides' bands mix); per stretch, [`POSITIONS`] positions and the depths
//! [`DEPTHS_PX`] inside and outside the side: the learnt inside and outside levels follow the
//! stretch's mean levels at [`LEARNING_RATE`] per update (only while the stretch is not
//! flagged, so a wrong inside cannot teach itself), and its *spread*, the inside samples' mean
//! distance from the learnt inside level, at the same rate. A stretch is *crossed* when at
//! least half of its inside samples are nearer the learnt outside level than the learnt
//! inside one, and the two levels differ by at least [`MIN_GAP_SPREADS`] times the stretch's
//! own spread (and `min_contrast`): a stretch whose two sides look alike, or whose inside is
//! textured as much as the step across it, proves nothing.

use nalgebra::Vector2;

use crate::image::ImageView;

/// Stretches per side.
pub(super) const STRETCHES: usize = 4;
/// Sample positions per stretch, evenly spread over it.
const POSITIONS: usize = 6;
/// Depths of the bands inside and outside the side, px: clear of the edge's blur (1-2 px on
/// the real frames) and within the 5-8 px a slid side moves before it is 6 px off.
const DEPTHS_PX: [f64; 3] = [2.0, 3.0, 4.0];
/// Per-update learning rate of a stretch's levels and spread: about a second of frames, slow
/// against a slide (2-3 updates) and fast against the camera circling the object.
const LEARNING_RATE: f32 = 0.1;
/// The learnt levels must differ by this many of the stretch's own spreads.
const MIN_GAP_SPREADS: f32 = 3.0;
/// Updates a stretch learns before it can be crossed (its spread is a mean over them).
const MIN_LEARNT_UPDATES: u32 = 10;

const SAMPLES: usize = POSITIONS * DEPTHS_PX.len();

/// What one stretch has learnt.
#[derive(Debug, Clone, Copy, Default)]
struct Stretch {
    inside: f32,
    outside: f32,
    spread: f32,
    learnt: u32,
    /// This update's means and spread (to learn from), and whether it was crossed.
    now_inside: f32,
    now_outside: f32,
    now_spread: f32,
    valid: bool,
    crossed: bool,
}

/// The most crossed stretch of an update.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Crossing {
    /// Side index (from corner `side` to corner `side + 1`).
    pub side: usize,
    /// Stretch along it, 0 nearest corner `side`.
    pub stretch: usize,
    /// Share of the stretch's inside samples nearer its learnt outside level.
    pub share: f64,
    /// The stretch's learnt inside and outside grey levels.
    pub inside: f64,
    pub outside: f64,
}

/// Per-stretch appearance across the contour's sides and the count of updates in a row on
/// which a stretch was crossed.
#[derive(Debug, Clone)]
pub(super) struct SideBands {
    stretches: Vec<Stretch>,
    /// Updates in a row with a crossed stretch.
    pub streak: usize,
    /// The most crossed stretch of the last update (share 0 when none was measurable).
    pub worst: Crossing,
}

impl SideBands {
    pub fn new(sides: usize) -> Self {
        Self { stretches: vec![Stretch::default(); sides * STRETCHES], streak: 0, worst: Crossing::default() }
    }

    /// Sides this was made for.
    pub fn sides(&self) -> usize {
        self.stretches.len() / STRETCHES
    }

    /// Forget everything (re-initialisation).
    pub fn reset(&mut self) {
        self.stretches.iter_mut().for_each(|s| *s = Stretch::default());
        self.streak = 0;
        self.worst = Crossing::default();
    }

    /// Samples every stretch of the polygon `corners` (image px, in order) in `image`, marks
    /// the crossed ones and advances [`Self::streak`]. `min_gap` is the least difference of
    /// the learnt levels that can mark a stretch (grey levels).
    pub fn measure(&mut self, image: &ImageView<'_>, corners: &[Vector2<f64>], min_gap: f32) {
        let n = corners.len();
        if n < 3 || self.stretches.len() != n * STRETCHES {
            return;
        }
        // Outward normals: the polygon's orientation from its signed area.
        let area: f64 = (0..n).map(|i| corners[i].perp(&corners[(i + 1) % n])).sum();
        let orientation = if area >= 0.0 { 1.0 } else { -1.0 };
        let (w, h) = (image.width() as f32, image.height() as f32);
        let (data, stride) = (image.data(), image.stride());
        // Nearest pixel; `None` outside the image. Truncation is the floor of the
        // non-negative `x + 0.5` (`floor` itself is a library call without SSE4.1).
        let grey = |x: f32, y: f32| {
            let (x, y) = (x + 0.5, y + 0.5);
            (x >= 0.0 && y >= 0.0 && x < w && y < h).then(|| f32::from(data[y as usize * stride + x as usize]))
        };
        let mut worst = Crossing::default();
        let mut any = false;
        for side in 0..n {
            let (a, b) = (corners[side], corners[(side + 1) % n]);
            let along = b - a;
            let length = along.norm();
            if length < 1e-6 {
                continue;
            }
            // With the polygon counter-clockwise in image axes (y down: area > 0), the outward
            // normal of a -> b is (t.y, -t.x).
            let normal = Vector2::new(along.y, -along.x) * (orientation / length);
            let (nx, ny) = (normal.x as f32, normal.y as f32);
            for k in 0..STRETCHES {
                let s = &mut self.stretches[side * STRETCHES + k];
                let (learnt_in, learnt_out) = (s.inside, s.outside);
                // Sums over this update's samples: inside, outside, the inside's distance from
                // the learnt inside level, and the inside samples nearer the learnt outside.
                let (mut sum_in, mut sum_out, mut sum_spread) = (0f32, 0f32, 0f32);
                let (mut n_in, mut n_out, mut nearer_outside) = (0usize, 0usize, 0usize);
                for j in 0..POSITIONS {
                    let u = 0.1 + 0.8 * (k as f64 + (j as f64 + 0.5) / POSITIONS as f64) / STRETCHES as f64;
                    let p = a + along * u;
                    let (px, py) = (p.x as f32, p.y as f32);
                    for d in DEPTHS_PX {
                        let d = d as f32;
                        if let Some(g) = grey(px - nx * d, py - ny * d) {
                            sum_in += g;
                            sum_spread += (g - learnt_in).abs();
                            nearer_outside += usize::from((g - learnt_out).abs() < (g - learnt_in).abs());
                            n_in += 1;
                        }
                        if let Some(g) = grey(px + nx * d, py + ny * d) {
                            sum_out += g;
                            n_out += 1;
                        }
                    }
                }
                s.crossed = false;
                s.valid = 2 * n_in >= SAMPLES && 2 * n_out >= SAMPLES;
                if !s.valid {
                    continue;
                }
                s.now_inside = sum_in / n_in as f32;
                s.now_outside = sum_out / n_out as f32;
                if s.learnt == 0 {
                    continue;
                }
                s.now_spread = sum_spread / n_in as f32;
                let gap = (learnt_out - learnt_in).abs();
                if s.learnt < MIN_LEARNT_UPDATES || gap < min_gap || gap < MIN_GAP_SPREADS * s.spread {
                    continue;
                }
                let share = nearer_outside as f64 / n_in as f64;
                s.crossed = 2 * nearer_outside >= n_in;
                any |= s.crossed;
                if share > worst.share {
                    worst = Crossing { side, stretch: k, share, inside: f64::from(learnt_in), outside: f64::from(learnt_out) };
                }
            }
        }
        self.worst = worst;
        self.streak = if any { self.streak + 1 } else { 0 };
    }

    /// After an update that kept tracking: every measured stretch not crossed learns this
    /// update's levels.
    pub fn learn(&mut self) {
        for s in self.stretches.iter_mut().filter(|s| s.valid && !s.crossed) {
            if s.learnt == 0 {
                (s.inside, s.outside) = (s.now_inside, s.now_outside);
            } else {
                s.inside += LEARNING_RATE * (s.now_inside - s.inside);
                s.outside += LEARNING_RATE * (s.now_outside - s.outside);
                // The first spread is a full step: a mean over the first updates.
                let rate = if s.learnt == 1 { 1.0 } else { LEARNING_RATE.max(1.0 / s.learnt as f32) };
                s.spread += rate * (s.now_spread - s.spread);
            }
            s.learnt = s.learnt.saturating_add(1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::image::ImageBuf;

    /// The tracked face A (`face(x, y)` grey) on `[40, 100)²`, a neighbouring face B
    /// (`neighbour`) on `[100, 110) × [40, 100)` beyond its right side, background 60.
    fn scene(face: impl Fn(usize, usize) -> u8, neighbour: u8) -> ImageBuf {
        let mut img = ImageBuf::filled(160, 140, 60);
        for y in 40..100 {
            for x in 40..100 {
                img.set(x, y, face(x, y));
            }
            for x in 100..110 {
                img.set(x, y, neighbour);
            }
        }
        img
    }

    fn v(c: [[f64; 2]; 4]) -> Vec<Vector2<f64>> {
        c.iter().map(|p| Vector2::new(p[0], p[1])).collect()
    }

    /// A's outline (pixel x covers x-0.5..x+0.5) and the same with its right side turned
    /// about the top right corner 8 px out at the bottom: across the crease onto B, on B's
    /// outer edge's line, as the real top face's side 2 on the frame-150 slides.
    const TRUE: [[f64; 2]; 4] = [[39.5, 39.5], [99.5, 39.5], [99.5, 99.5], [39.5, 99.5]];
    const TURNED: [[f64; 2]; 4] = [[39.5, 39.5], [99.5, 39.5], [107.5, 99.5], [39.5, 99.5]];

    fn learnt_on(img: &ImageBuf, corners: &[Vector2<f64>]) -> SideBands {
        let mut bands = SideBands::new(4);
        for _ in 0..15 {
            bands.measure(&img.view(), corners, 12.0);
            assert_eq!(bands.streak, 0, "crossed on the true outline: {:?}", bands.worst);
            bands.learn();
        }
        bands
    }

    #[test]
    fn a_side_turned_across_the_crease_onto_the_neighbouring_face_is_crossed() {
        let img = scene(|_, _| 170, 120);
        // Either orientation of the polygon.
        for reversed in [false, true] {
            let order = |c: [[f64; 2]; 4]| {
                let mut c = v(c);
                if reversed {
                    c.reverse();
                }
                c
            };
            let mut bands = learnt_on(&img, &order(TRUE));
            bands.measure(&img.view(), &order(TURNED), 12.0);
            assert_eq!(bands.streak, 1, "reversed {reversed}: {:?}", bands.worst);
            let w = bands.worst;
            // The right side (corners 1-2, or 1-2 of the reversed order: its side 1 again).
            assert_eq!(w.side, 1, "{w:?}");
            assert!(w.share >= 0.5 && (w.inside - 170.0).abs() < 1.0 && (w.outside - 120.0).abs() < 1.0, "{w:?}");
            // Twice in a row, and a crossed stretch does not learn its wrong inside.
            bands.learn();
            bands.measure(&img.view(), &order(TURNED), 12.0);
            assert_eq!(bands.streak, 2, "{:?}", bands.worst);
            // Back on the outline: the streak ends.
            bands.learn();
            bands.measure(&img.view(), &order(TRUE), 12.0);
            assert_eq!(bands.streak, 0, "{:?}", bands.worst);
        }
    }

    /// What the opposite test would trip on: the neighbouring face turning to the tracked
    /// face's own level (on the real sequence's fast turn, frames 186-193) changes the outside,
    /// not the inside.
    #[test]
    fn the_neighbour_fading_to_the_faces_own_level_is_no_crossing() {
        let mut bands = learnt_on(&scene(|_, _| 170, 120), &v(TRUE));
        let faded = scene(|_, _| 170, 170);
        for _ in 0..5 {
            bands.measure(&faded.view(), &v(TRUE), 12.0);
            assert_eq!(bands.streak, 0, "{:?}", bands.worst);
            bands.learn();
        }
    }

    /// A face textured as strongly as the step to its neighbour (stripes 130 / 210, mean 170,
    /// against B at 120) gives no evidence: its own spread rules the stretch out.
    #[test]
    fn a_face_textured_as_much_as_the_step_across_its_side_proves_nothing() {
        let img = scene(|x, _| if (x / 2) % 2 == 0 { 130 } else { 210 }, 120);
        let mut bands = learnt_on(&img, &v(TRUE));
        for _ in 0..3 {
            bands.measure(&img.view(), &v(TURNED), 12.0);
            assert_eq!(bands.streak, 0, "{:?}", bands.worst);
            bands.learn();
        }
    }
}
