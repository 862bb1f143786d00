//! What a tracker reports after each update: its state, why it was lost, how confident it is.

use std::fmt;

/// Why a tracker stopped tracking. A lost tracker stays lost (and keeps its last good
/// position) until it is re-initialised: the servo must stop rather than act on a guess.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LostReason {
    /// Too many search lines left the image (`outside_fraction` of them).
    LeftImage { outside_fraction: f64 },
    /// Too few points found any edge.
    TooFewEdges { edge_fraction: f64 },
    /// Too few points agree with the fitted motion.
    TooFewInliers { inlier_fraction: f64 },
    /// The agreeing points do not pin the contour down in every direction (e.g. only the
    /// top and bottom sides found their edges: it could be anywhere along them).
    Unconstrained { direction_support: f64 },
    /// The share of agreeing points fell abruptly below its recent level (`recent`): the
    /// contour jumped off its object, or something covered much of it at once.
    SuddenDrop { inlier_fraction: f64, recent: f64 },
    /// The agreeing points scatter too much about the fit.
    ResidualTooLarge { rms_px: f64 },
    /// The frame is collapsing: squashed (`squash` = singular value ratio of the deformation
    /// since initialisation) or grown/shrunk by `area_ratio`.
    DegenerateBasis { squash: f64, area_ratio: f64 },
    /// The frame turned over (its determinant changed sign): a mirror image is no result.
    FlippedBasis,
    /// A computation produced a non-finite number.
    NotFinite,
    /// Wrong lock: on `updates` more wide passes than not (since the last time there were
    /// none), `side` (corner `side` to `side + 1`)
    /// sat on an edge `support` of its points found while another straight edge `offset_px`
    /// away at the side's middle (outward positive), `turn_px` further out at the side's end
    /// than at its start (0: parallel), was found by `rival` of them, at least
    /// [`rival_margin_points`](super::TrackerConfig::rival_margin_points) more and most of
    /// the side's points: the side slid
    /// onto a texture or neighbouring edge and the face's own edge is beside it.
    WrongLock { side: usize, offset_px: f64, turn_px: f64, support: usize, rival: usize, updates: usize },
    /// The band just inside a stretch of a side looks like what that stretch had learnt lies
    /// outside it, on `updates` updates in a row (`share` of its samples nearer the learnt
    /// outside grey level than the inside one): the side crossed onto a neighbouring surface
    /// while keeping an edge (`tracker::side_bands`). Reported as a wrong lock.
    CrossedSide { side: usize, stretch: usize, share: f64, inside: f64, outside: f64, updates: usize },
}

impl LostReason {
    /// A short stable name, e.g. for JSON output and telemetry.
    pub fn code(&self) -> &'static str {
        match self {
            LostReason::LeftImage { .. } => "left_image",
            LostReason::TooFewEdges { .. } => "too_few_edges",
            LostReason::TooFewInliers { .. } => "too_few_inliers",
            LostReason::Unconstrained { .. } => "unconstrained",
            LostReason::SuddenDrop { .. } => "sudden_drop",
            LostReason::ResidualTooLarge { .. } => "residual_too_large",
            LostReason::DegenerateBasis { .. } => "degenerate_basis",
            LostReason::FlippedBasis => "flipped_basis",
            LostReason::NotFinite => "not_finite",
            LostReason::WrongLock { .. } | LostReason::CrossedSide { .. } => "wrong_lock",
        }
    }
}

impl fmt::Display for LostReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LostReason::LeftImage { outside_fraction } => {
                write!(f, "left the image ({:.0} % of search lines outside)", outside_fraction * 100.0)
            }
            LostReason::TooFewEdges { edge_fraction } => {
                write!(f, "too few edges ({:.0} % of points found one)", edge_fraction * 100.0)
            }
            LostReason::TooFewInliers { inlier_fraction } => {
                write!(f, "too few inliers ({:.0} % of points agree with the fit)", inlier_fraction * 100.0)
            }
            LostReason::Unconstrained { direction_support } => write!(
                f,
                "position unconstrained in one direction ({:.0} % of the full contour's support)",
                direction_support * 100.0
            ),
            LostReason::SuddenDrop { inlier_fraction, recent } => write!(
                f,
                "support dropped abruptly ({:.0} % of points agree, recently {:.0} %)",
                inlier_fraction * 100.0,
                recent * 100.0
            ),
            LostReason::ResidualTooLarge { rms_px } => write!(f, "residual too large ({rms_px:.2} px RMS)"),
            LostReason::DegenerateBasis { squash, area_ratio } => {
                write!(f, "degenerate frame (squash {squash:.1}, area x{area_ratio:.2})")
            }
            LostReason::FlippedBasis => write!(f, "frame flipped over"),
            LostReason::NotFinite => write!(f, "non-finite numbers in the fit"),
            LostReason::WrongLock { side, offset_px, turn_px, support, rival, updates } => {
                write!(f, "wrong lock: side {side} is on an edge {support} of its points found, ")?;
                if *turn_px == 0.0 {
                    write!(f, "a parallel edge {offset_px:+.0} px away")?;
                } else {
                    write!(f, "an edge {offset_px:+.0} px away at its middle and turned {turn_px:+.0} px over its length")?;
                }
                write!(f, " was found by {rival}, on {updates} more updates than not")
            }
            LostReason::CrossedSide { side, stretch, share, inside, outside, updates } => write!(
                f,
                "wrong lock: inside side {side} (stretch {stretch}) {:.0} % of the grey levels are nearer the {outside:.0} \
                 learnt outside it than the {inside:.0} learnt inside, on {updates} updates in a row",
                share * 100.0
            ),
        }
    }
}

/// Tracker state after an update.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum TrackState {
    Tracking,
    Lost(LostReason),
}

impl TrackState {
    pub fn is_tracking(&self) -> bool {
        matches!(self, TrackState::Tracking)
    }

    /// `"tracking"` or `"lost"`.
    pub fn code(&self) -> &'static str {
        match self {
            TrackState::Tracking => "tracking",
            TrackState::Lost(_) => "lost",
        }
    }

    pub fn lost_reason(&self) -> Option<LostReason> {
        match self {
            TrackState::Tracking => None,
            TrackState::Lost(r) => Some(*r),
        }
    }
}

/// How well the last update went.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Confidence {
    /// Share of points whose search found at least one acceptable edge.
    pub edge_fraction: f64,
    /// Share of points whose chosen edge lies within `inlier_px` of the fitted contour.
    pub inlier_fraction: f64,
    /// RMS distance of the inliers' edges from the fitted contour, px.
    pub residual_px: f64,
    /// Share of search lines that left the image.
    pub outside_fraction: f64,
    /// How well the inliers pin the contour down in its worst direction, relative to all its
    /// points: the smallest eigenvalue of `Σ n nᵀ` over the inliers over that over all points
    /// (1 when every point agrees, 0 when no inlier constrains some direction).
    pub direction_support: f64,
    /// One number in 0..1: `inlier_fraction · exp(−(residual_px / inlier_px)²)`.
    pub score: f64,
}
