//! The pointing interface (METHOD.md §4, thesis ch. 4): the operator points at a block with a
//! finger, and the system finds where on the working plane.
//!
//! - `geometry`: each camera's view of the working plane as a homography fitted from four or
//!   more plane points with their pixels, and the intersection of the two views' finger lines
//!   carried onto the plane (no 3-D reconstruction);
//! - `silhouette`: the arm in one view by differencing against the scene before it, and the
//!   axis of its silhouette with the fingertip end;
//! - `finger`: the finger as a part of its own when the whole silhouette is a blob (a hand
//!   seen from the front): the thin protrusion an opening takes off the hand;
//! - `gesture`: frame by frame, wait for the arm in both views, wait until it holds still,
//!   and report the indicated point with its uncertainty, or why there is none (unsteady
//!   hand, a finger line nearly in a plane through both cameras).
//!
//! Inside: `gesture` → `silhouette` → `finger`, `line_fit`, `geometry`.

mod finger;
mod geometry;
mod gesture;
mod line_fit;
mod silhouette;
#[cfg(test)]
mod tests;

pub use geometry::{ImageLine, Indicated, PlaneHomography, Pointing, PointingError};
pub use gesture::{GestureConfig, GestureState, PointedAt, PointingTracker};
pub use silhouette::{ArmAxis, SilhouetteConfig, SilhouetteError, SilhouetteFinder};
