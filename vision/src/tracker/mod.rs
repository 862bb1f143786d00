//! The affine template active contour tracker (thesis Appendix A, `METHOD.md` §2), made
//! robust and fast.
//!
//! A polygon (a facet outline, the gripper's tracked face) is held as ~100 sampling points in
//! template coordinates `(s, t)` of a frame `o, e1, e2` ([`TemplateFrame`]), optionally with a
//! perspective term ([`Placement`]). Each update:
//! 1. **Predict** the placement with a first-order filter scaled by the real time between
//!    frames.
//! 2. **Search** each point's normal, `±search_px`, for gradient maxima ([`search`]): on the
//!    pixel grid along the row or column nearest the normal (no interpolation), two-sided or
//!    one-sided ([`EdgeSign`]), with sub-pixel peaks, keeping up to four candidates and the
//!    grey level just inside each.
//! 3. **Fit** translation (A.1) then shape (A.2, optionally with perspective; A.3 as an
//!    option) by iteratively reweighted least squares (Tukey or Huber). Each iteration every
//!    point re-chooses the candidate the current fit explains best, with a penalty when the
//!    grey level inside it differs from what the point has learnt. The normal equations come
//!    from nine moments per polygon side, not an outer product per point.
//! 4. **Refine**: search again with a short range around the fitted contour and refit.
//! 5. **Judge**: share of points with an edge, share of inliers and whether they pin the
//!    contour down in every direction, a sudden collapse of that share, the inlier residual,
//!    frame degeneracy, leaving the image, and a wrong lock (`wrong_lock`: after each wide
//!    pass, a side whose own points see another straight edge, parallel or turned, 5 px or
//!    more away at an end more often than the edge the fit put it on, on 10 more updates than
//!    not), and a side crossed onto a neighbouring surface (`side_bands`: the band just inside
//!    a stretch of a side looks like what it learnt lies outside it, on
//!    `max_crossed_side_updates` updates in a row). Failing any is the *lost* state with
//!    its [`LostReason`]; the servo must stop on it. Otherwise the points' polarity, contrast
//!    and inside grey level are learnt.
//!
//! Choices the thesis leaves open, and why (all measured on the real `visp-cube` sequence and
//! the synthetic tests in `vision/tests/`):
//! - **Projective by default** (A.2 plus a ridge-damped perspective term): the cube's faces
//!   are up to 10° off a parallelogram, and an affine fit then sacrifices one side; the
//!   affine frame `o, e1, e2` stays the contour's local affine frame at its origin.
//! - **Staged solve** as in the thesis (translation, then shape given it), jumping to the joint
//!   solution only in the last iteration: solving jointly throughout let a side swing onto a
//!   neighbouring face's silhouette.
//! - **Two-sided search plus a learnt inside grey level**, not one-sided: where a neighbouring
//!   face comes into view beside a side, that side's true polarity flips and a one-sided point
//!   follows the silhouette instead; the grey level inside the edge (the tracked surface)
//!   does not change, provided it is learnt slowly and only from edges that already match.
//!
//! Zero heap allocations per update after construction (`vision/tests/no_alloc.rs`).
//!
//! Speed (`handeye bench tracker`; `vision/examples/tracker_profile.rs` counts instructions
//! and checks robustness). About 60 % of the time is the edge search, 25 % the fit:
//! - The search runs all of a contour's lines at once, sixteen side by side (`batch`): each
//!   line's samples go into one lane of a table (a memory copy for a line along a row, a
//!   gather for a column, then a byte transpose), and the differences, scores, peak flags
//!   and the strongest-four network run table row by table row on sixteen lanes (AVX2 where
//!   the processor has it, detected once per tracker); per kept peak a few loads from the
//!   tables, and the sub-pixel steps four at a time. The candidates go straight into the
//!   fit's arrays.
//! - The fit works on f32 arrays padded to whole lanes; the association runs four points at
//!   a time (eight with AVX2), also for the final choice of each point's candidate, the
//!   residual histogram is per lane and only as long as the robust scale needs, and the
//!   small solves are written out.
//! - Every vector path computes exactly what the scalar code does, lane by lane and in the
//!   same order (tests compare them bit for bit), and a portable fallback serves other
//!   processors; the tracker's results do not depend on the path taken.
//! - What does not help: fewer points in the wide pass (`coarse_stride`), a short search
//!   first (`short_first_px`), one pass, fewer reweighting iterations, a refinement pass on
//!   the first pass's pixel lines or on half the points all lose the real top face markedly
//!   more often (numbers at those settings and in `BENCHMARKS.md`, Tracker rounds 2-4).

mod batch;
mod config;
mod contour;
mod contour_tracker;
mod filter;
mod fit;
mod frame;
pub mod search;
mod side_bands;
mod simd;
mod state;
mod stereo;
pub mod synth;
mod wrong_lock;

pub use config::{TrackerConfigError, EdgeSign, TrackerConfig};
pub use contour::{Template, TemplateError, MIN_POINTS};
pub use contour_tracker::{ContourTracker, SearchLine, TrackerError};
pub use fit::{DeformationModel, RobustLoss};
pub use frame::{TemplateFrame, Placement};
pub use search::{Candidate, Polarity};
pub use side_bands::Crossing;
pub use state::{Confidence, LostReason, TrackState};
pub use stereo::{Role, StereoStates, StereoTrackerSet, View};
