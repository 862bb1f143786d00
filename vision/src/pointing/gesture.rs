//! The pointing gesture frame by frame: wait for an arm to come into both views, wait until
//! it holds still, then carry both views' finger lines onto the working plane and report
//! where they meet, with an uncertainty. A hand that never settles, and a finger whose line
//! lies nearly in a plane through both cameras (the two plane lines then barely cross), are
//! reported as such, never answered with a guess.
//!
//! Per frame: one difference image and one line fit per view (buffers reused), a
//! few dozen flops for the plane lines. The background is the scene before the arm came:
//! given by the caller, and renewed from frames in which nothing changed.

use nalgebra::{Matrix2, Vector2, Vector3};

use super::geometry::{ImageLine, Pointing, PointingError};
use super::silhouette::{ArmAxis, SilhouetteConfig, SilhouetteError, SilhouetteFinder};
use crate::image::{ImageBuf, ImageView};

/// Tuning of the gesture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GestureConfig {
    pub silhouette: SilhouetteConfig,
    /// Frames the lines must hold still before a point is reported (10 at 30 Hz: 1/3 s).
    pub steady_frames: usize,
    /// Still: over those frames, the arm's silhouette (its centroid) moved no more than this
    /// in either view, and its end at the fingertip (the silhouette's, not the fitted
    /// line's: [`ArmAxis::end_px`]) no more than three times this, pixels.
    pub steady_px: f64,
    /// An arm in view this many frames without holding still is an unsteady hand, or one
    /// without a line (90 at 30 Hz: 3 s).
    pub unsteady_after_frames: usize,
    /// Fewer changed pixels than this in both views: the scene is quiet and becomes the
    /// background.
    pub quiet_pixels: usize,
    /// A point less certain than this (one-sigma radius, metres) is reported as uncertain,
    /// not as the answer: a finger line measured on too little of the arm. 15 mm: a point
    /// picks a block (the blocks a gripper takes are 30-60 mm across), and whether it picks
    /// one is the plan's to judge against the blocks it sees (`handeye-daemon`'s
    /// `point_ambiguity`); beyond 15 mm its 3-sigma circle would cover the 60 mm the plan
    /// looks for a site in. 8 mm refused gestures that pick their block (BENCHMARKS.md).
    pub max_sigma_m: f64,
}

impl Default for GestureConfig {
    fn default() -> Self {
        Self { silhouette: SilhouetteConfig::default(), steady_frames: 10, steady_px: 1.5, unsteady_after_frames: 90, quiet_pixels: 30, max_sigma_m: 0.015 }
    }
}

/// The indicated point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PointedAt {
    /// Robot `x, y` on the working plane, metres.
    pub point_m: [f64; 2],
    /// One-sigma radius of the point's uncertainty (from both lines' fit errors and their
    /// jitter while steady), metres.
    pub sigma_m: f64,
    /// Angle at which the two plane lines cross, radians.
    pub crossing_rad: f64,
    /// The finger in the left and right views (averaged over the steady frames).
    pub axes: [ArmAxis; 2],
    /// The two views' finger lines carried onto the plane: `a x + b y + c = 0`.
    pub plane_lines: [[f64; 3]; 2],
}

/// What one frame showed. Returned by value every frame: boxing the large variant would
/// allocate on every steady frame, which the per-frame update avoids.
#[derive(Debug, Clone, Copy, PartialEq)]
#[allow(clippy::large_enum_variant)]
pub enum GestureState {
    /// No arm in view (of both cameras): nothing to do.
    Absent,
    /// An arm in view (in `views` of the two), not yet still; `frames` since it came.
    Moving { frames: usize, views: usize },
    /// Still, and the two plane lines meet here.
    Indicated(PointedAt),
    /// Still, but the finger's line lies nearly in a plane through both cameras: the plane
    /// lines cross at only `crossing_rad`, and the point is not determined.
    Degenerate { crossing_rad: f64 },
    /// Still, but the point's one-sigma radius `sigma_m` is over `max_sigma_m`: too little
    /// of the finger's line was measured to trust where it meets the plane.
    Uncertain { sigma_m: f64 },
    /// Still, but the views disagree: the plane lines meet at a point whose image in view
    /// `view` (0 left, 1 right) lies `behind_px` behind the fingertip, against the finger's
    /// direction there. A finger points ahead of its tip; such a point is a wrong line in one
    /// view (a stub's direction, a fit on the hand), not an answer.
    Disagree { view: usize, behind_px: f64 },
    /// In view for `frames` without holding still.
    Unsteady { frames: usize },
    /// In view for `frames`, but with no finger line in one view or both (`views` have one):
    /// seen end-on, hidden, or not shaped like an arm.
    NoLine { frames: usize, views: usize },
}

/// Follows one pointing gesture after another.
#[derive(Debug, Clone)]
pub struct PointingTracker {
    pub pointing: Pointing,
    pub config: GestureConfig,
    background: Option<[ImageBuf; 2]>,
    finders: [SilhouetteFinder; 2],
    /// The last `steady_frames` axes of each view (a ring).
    history: Vec<[ArmAxis; 2]>,
    next: usize,
    frames_in_view: usize,
}

impl PointingTracker {
    pub fn new(pointing: Pointing, config: GestureConfig) -> Self {
        let finder = SilhouetteFinder::new(config.silhouette);
        Self {
            pointing,
            config,
            background: None,
            finders: [finder.clone(), finder],
            history: Vec::with_capacity(config.steady_frames.max(1)),
            next: 0,
            frames_in_view: 0,
        }
    }

    /// The scene without the arm (both views), e.g. the frame before the gesture is awaited.
    pub fn set_background(&mut self, left: &ImageView, right: &ImageView) {
        match self.background.as_mut() {
            Some([l, r]) if l.width == left.width() && l.height == left.height() => {
                copy_into(l, left);
                copy_into(r, right);
            }
            _ => self.background = Some([left.to_owned(), right.to_owned()]),
        }
    }

    /// Frames the arm has been in view of both cameras.
    pub fn frames_in_view(&self) -> usize {
        self.frames_in_view
    }

    /// One stereo frame. Without a background yet, this frame becomes it.
    pub fn update(&mut self, left: &ImageView, right: &ImageView) -> GestureState {
        let Some([bl, br]) = self.background.as_ref() else {
            self.set_background(left, right);
            return GestureState::Absent;
        };
        let found = [self.finders[0].find(&bl.view(), left), self.finders[1].find(&br.view(), right)];
        let quiet = self.finders.iter().all(|f| f.changed_pixels() < self.config.quiet_pixels);
        let views = found.iter().filter(|f| f.is_ok()).count();
        let [Ok(l), Ok(r)] = found else {
            let gone = found.iter().all(|f| matches!(f, Err(SilhouetteError::NothingThere { .. })));
            self.history.clear();
            self.next = 0;
            if gone {
                self.frames_in_view = 0;
                if quiet {
                    self.set_background(left, right); // follow slow changes of the light
                }
                return GestureState::Absent;
            }
            self.frames_in_view += 1;
            if self.frames_in_view > self.config.unsteady_after_frames {
                return GestureState::NoLine { frames: self.frames_in_view, views };
            }
            return GestureState::Moving { frames: self.frames_in_view, views };
        };
        self.frames_in_view += 1;
        let n = self.config.steady_frames.max(1);
        if self.history.len() < n {
            self.history.push([l, r]);
        } else {
            self.history[self.next] = [l, r];
        }
        self.next = (self.next + 1) % n;
        if self.history.len() < n || !self.steady() {
            if self.frames_in_view > self.config.unsteady_after_frames {
                return GestureState::Unsteady { frames: self.frames_in_view };
            }
            return GestureState::Moving { frames: self.frames_in_view, views: 2 };
        }
        self.indicate()
    }

    /// Every silhouette of the window within `steady_px` of the newest one (centroid), and
    /// its end at the fingertip within three times that. The silhouette, not the fitted line:
    /// a hand held still whose fit turns between the finger's and the whole arm's midline
    /// from frame to frame (the fitted tip then jumps several pixels across) is still; how far
    /// those lines spread is the point's uncertainty (the window's jitter), not unsteadiness.
    fn steady(&self) -> bool {
        let newest = self.history[(self.next + self.history.len() - 1) % self.history.len()];
        self.history.iter().all(|h| {
            (0..2).all(|v| {
                let (a, b) = (&h[v], &newest[v]);
                let moved = |p: [f64; 2], q: [f64; 2]| (p[0] - q[0]).hypot(p[1] - q[1]);
                moved(a.centroid_px, b.centroid_px) <= self.config.steady_px && moved(a.end_px, b.end_px) <= 3.0 * self.config.steady_px
            })
        })
    }

    /// The point the window's mean lines indicate, with its uncertainty.
    fn indicate(&self) -> GestureState {
        let axes: [ArmAxis; 2] = std::array::from_fn(|v| mean_axis(self.history.iter().map(|h| &h[v])));
        let hit = match self.pointing.indicate(&axes[0].line, &axes[1].line) {
            Ok(hit) => hit,
            Err(PointingError::NearlyParallel { angle_rad }) => return GestureState::Degenerate { crossing_rad: angle_rad },
            Err(_) => return GestureState::Degenerate { crossing_rad: 0.0 },
        };
        // Uncertainty: each view's line turned by its angle error about its pivot, and
        // shifted by its offset error, carried through the intersection; the four effects
        // add in quadrature. The pivot is where the line is located: the sections' centre for
        // a line fitted along the arm (its angle and offset errors are independent there),
        // the fingertip for a stub (`sections` 0: a tip and a direction from the root). A stub
        // seen end-on has its ray through the tip close to the indicated point, so turning it
        // about the tip moves the point little, and its large angle sigma costs little. Each
        // error is the fit's own or the window's jitter, whichever is larger: the frames' lines
        // scattered about the mean line in offset (at the centre) and in angle. The angle's
        // jitter matters where the fit turns between the finger's midline and the whole arm's
        // from frame to frame (a finger over the robot or cut by the border): the centres stay
        // put, the lines fan out, and the mean line is no surer than that fan.
        let mut var = 0.0;
        let count = self.history.len() as f64;
        for v in 0..2 {
            let jitter = self.history.iter().map(|h| distance(&axes[v].line, &h[v].centre_px).powi(2)).sum::<f64>() / count;
            let turn_jitter = self.history.iter().map(|h| angle_between(&axes[v].line, &h[v].line).powi(2)).sum::<f64>() / count;
            let pivot = if axes[v].sections == 0 { axes[v].tip_px } else { axes[v].centre_px };
            let shift = axes[v].offset_sigma_px.max(jitter.sqrt()).max(0.1);
            let turn = axes[v].angle_sigma_rad.max(turn_jitter.sqrt()).max(1e-4);
            for (dturn, dshift) in [(turn, 0.0), (0.0, shift)] {
                let moved = perturbed(&axes[v], pivot, dturn, dshift);
                let lines = if v == 0 { (moved, axes[1].line) } else { (axes[0].line, moved) };
                if let Ok(other) = self.pointing.indicate(&lines.0, &lines.1) {
                    var += (other.point_m[0] - hit.point_m[0]).powi(2) + (other.point_m[1] - hit.point_m[1]).powi(2);
                }
            }
        }
        let plane = |h: &super::geometry::PlaneHomography, l: &ImageLine| {
            let p = h.line_to_plane(l);
            let p = p / p.xy().norm();
            [p[0], p[1], p[2]]
        };
        let sigma_m = var.sqrt();
        if sigma_m > self.config.max_sigma_m {
            return GestureState::Uncertain { sigma_m };
        }
        if let Some((view, behind_px)) = self.behind_a_tip(&axes, hit.point_m, sigma_m) {
            return GestureState::Disagree { view, behind_px };
        }
        GestureState::Indicated(PointedAt {
            point_m: hit.point_m,
            sigma_m,
            crossing_rad: hit.crossing_rad,
            axes,
            plane_lines: [plane(&self.pointing.left, &axes[0].line), plane(&self.pointing.right, &axes[1].line)],
        })
    }

    /// The first view in which the plane point `point_m` (its image: on that view's line)
    /// lies behind the fingertip against the finger's direction (tail to tip), by more than
    /// the point's uncertainty there (`sigma_m` twice, in that view's pixels) and 2 px for
    /// the tip's own; with how far behind, px.
    fn behind_a_tip(&self, axes: &[ArmAxis; 2], point_m: [f64; 2], sigma_m: f64) -> Option<(usize, f64)> {
        let maps = [&self.pointing.left, &self.pointing.right];
        (0..2).find_map(|v| {
            let a = &axes[v];
            let d = Vector2::new(a.tip_px[0] - a.tail_px[0], a.tip_px[1] - a.tail_px[1]).try_normalize(1e-9)?;
            let seen = maps[v].project(&point_m)?;
            let ahead = (Vector2::from(seen) - Vector2::from(a.tip_px)).dot(&d);
            let px_per_m = [[sigma_m, 0.0], [0.0, sigma_m]]
                .iter()
                .filter_map(|o| maps[v].project(&[point_m[0] + o[0], point_m[1] + o[1]]))
                .map(|q| (q[0] - seen[0]).hypot(q[1] - seen[1]))
                .fold(0.0, f64::max);
            let margin_px = 2.0 + 2.0 * px_per_m;
            (ahead < -margin_px).then_some((v, -ahead))
        })
    }
}

fn copy_into(dst: &mut ImageBuf, src: &ImageView) {
    for y in 0..src.height() {
        dst.data[y * dst.width..(y + 1) * dst.width].copy_from_slice(&src.row(y)[..src.width()]);
    }
}

/// Distance of a point from a line, pixels.
fn distance(l: &ImageLine, p: &[f64; 2]) -> f64 {
    (l.0[0] * p[0] + l.0[1] * p[1] + l.0[2]).abs()
}

/// The angle between two lines' directions (sign ignored), radians.
fn angle_between(a: &ImageLine, b: &ImageLine) -> f64 {
    let (na, nb) = (Vector2::new(a.0[0], a.0[1]), Vector2::new(b.0[0], b.0[1]));
    let cross = na[0] * nb[1] - na[1] * nb[0];
    cross.abs().atan2(na.dot(&nb).abs())
}

/// The axes' mean: the mean direction (signs aligned) through the mean centre.
fn mean_axis<'a>(axes: impl Iterator<Item = &'a ArmAxis>) -> ArmAxis {
    let mut first: Option<ArmAxis> = None;
    let (mut n, mut dir, mut centre, mut tip, mut tail, mut end) = (0.0, Vector2::zeros(), Vector2::zeros(), Vector2::zeros(), Vector2::zeros(), Vector2::zeros());
    for a in axes {
        let d = Vector2::new(a.tip_px[0] - a.tail_px[0], a.tip_px[1] - a.tail_px[1]);
        let along = Vector2::new(-a.line.0[1], a.line.0[0]);
        dir += if along.dot(&d) >= 0.0 { along } else { -along };
        centre += Vector2::from(a.centre_px);
        tip += Vector2::from(a.tip_px);
        tail += Vector2::from(a.tail_px);
        end += Vector2::from(a.end_px);
        n += 1.0;
        first.get_or_insert(*a);
    }
    let mut out = first.expect("a steady window is never empty");
    let centre_px = [centre[0] / n, centre[1] / n];
    if let Ok(line) = ImageLine::along(&centre_px, &[dir[0], dir[1]]) {
        out.line = line;
    }
    out.centre_px = centre_px;
    out.tip_px = [tip[0] / n, tip[1] / n];
    out.tail_px = [tail[0] / n, tail[1] / n];
    out.end_px = [end[0] / n, end[1] / n];
    out
}

/// `axis`'s line turned by `turn_rad` about `pivot_px` (a point on it) and shifted across by
/// `shift_px`.
fn perturbed(axis: &ArmAxis, pivot_px: [f64; 2], turn_rad: f64, shift_px: f64) -> ImageLine {
    let n = Vector2::new(axis.line.0[0], axis.line.0[1]);
    // The pivot's foot on the line (the tip is on it already; the centre too).
    let q = Vector2::from(pivot_px);
    let q = q - n * (n.dot(&q) + axis.line.0[2]);
    let (s, c) = turn_rad.sin_cos();
    let n = Matrix2::new(c, -s, s, c) * n;
    let p = q + n * shift_px;
    ImageLine(Vector3::new(n[0], n[1], -n.dot(&p)))
}
