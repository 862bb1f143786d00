//! The affine template active contour tracker (thesis Appendix A, `METHOD.md` §2), made
//! robust and fast.
//!
//! A polygon (a facet outline, the gripper's tracked face) is held as ~100 sampling points in
//! affine coordinates `(s, t)` of a frame `o, e1, e2` ([`AffineFrame`]). Each update:
//! 1. **Predict** the frame with a first-order filter scaled by the real time between frames.
//! 2. **Search** each point's normal, `±search_px`, for gradient maxima ([`search`]): on the
//!    pixel grid along the row or column nearest the normal (no interpolation), two-sided
//!    or one-sided ([`EdgeSign`]), with sub-pixel peaks, keeping up to four candidates.
//! 3. **Fit** translation (A.1) then deformation (A.2 by default, A.3 as an option) by
//!    iteratively reweighted least squares (Tukey or Huber), re-choosing each point's
//!    candidate by the current fit so that nearby texture edges lose to the consistent ones.
//! 4. **Refine**: search again with a short range around the fitted contour and refit.
//! 5. **Judge**: share of points with an edge, share of inliers, inlier residual, frame
//!    degeneracy, leaving the image. Failing any is the *lost* state with its [`LostReason`];
//!    the servo must stop on it. Otherwise the per-point polarity and contrast are learnt.
//!
//! Choices the thesis leaves open, and why:
//! - A.2 (normal-only) by default: A.3 ignores the aperture problem and so recovers only part
//!   of a rotation or shear per step; with a refinement pass and a robust fit the instability
//!   the thesis saw in A.2 (contours squashed by an occluder) is handled by the outlier
//!   weights and a small ridge on the deformation.
//! - Per-point learnt polarity: the face boundaries of real objects change sign along their
//!   length; one polarity per contour rejects half of a textured face's boundary.
//!
//! Zero heap allocations per update after construction (tested in `vision/tests/no_alloc.rs`).

mod config;
mod contour;
mod contour_tracker;
mod filter;
mod fit;
mod frame;
pub mod search;
mod state;
mod stereo;
pub mod synth;

pub use config::{ConfigError, EdgeSign, TrackerConfig};
pub use contour::{Template, TemplateError, MIN_POINTS};
pub use contour_tracker::{ContourTracker, SearchLine, TrackerError};
pub use fit::{DeformationModel, RobustLoss};
pub use frame::{AffineFrame, Placement};
pub use search::{Candidate, Polarity};
pub use state::{Confidence, LostReason, TrackState};
pub use stereo::{Role, StereoStates, StereoTrackerSet, View};
