//! The planner (thesis chapter 5, METHOD.md §5): from one stereo pair and a weak epipolar
//! constraint to planar facets and reconstructed edges.
//!
//! Coordinates: continuous image coordinates in which pixel `(i, j)` covers
//! `[i, i+1) x [j, j+1)`, u right, v down (the simulator's ground-truth convention).

pub mod edges;
pub mod geom;
pub mod synth;
pub mod segments;
pub mod relations;
