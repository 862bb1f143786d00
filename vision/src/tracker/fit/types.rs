//! The fit's shared vocabulary: the models, settings and result, the points it reads, the
//! parameter vector and the lane width. Every part of the fit depends on this module; it
//! depends on none of them.

use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

/// Which least-squares problem estimates the shape change (Appendix A).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DeformationModel {
    /// A.2: `h_i − n_i·t = n_i·(A p_i)`: only the normal component of each offset is used,
    /// which is what the edge search measures (the aperture problem). Unbiased; the fit is
    /// regularised so a long thin contour cannot blow up.
    NormalOnly,
    /// A.3: `(h_i − n_i·t) n_i = A p_i`: the thesis's simplification that treats the normal
    /// offset as the whole displacement. More stable under occlusion, but sluggish to deform.
    FullVector,
    /// A.2 plus a two-parameter perspective term `g` (displacement `−(g·p) p`), solved with
    /// `A` after the translation: the contour follows a plane seen under full perspective (a
    /// homography) instead of weak perspective. Beyond the thesis; ridge-regularised towards
    /// no change of perspective. The default: real cameras close to an object are not affine
    /// (the `visp-cube` faces are up to 10° off a parallelogram), and an affine fit then
    /// sacrifices one side to the others.
    #[default]
    Projective,
    /// Translation only (`A = 0`): for contours whose shape is known not to change.
    None,
}

/// The robust weight function of the iteratively reweighted fit.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum RobustLoss {
    /// Plain least squares (the thesis): every point weighs the same.
    LeastSquares,
    /// Huber: quadratic within `k·σ`, linear beyond (k = 1.345).
    Huber,
    /// Tukey's biweight: points beyond `c·σ` (c = 4.685) get no weight at all.
    #[default]
    Tukey,
}

/// Settings of one fit.
#[derive(Debug, Clone, Copy)]
pub(crate) struct FitSettings {
    pub model: DeformationModel,
    pub loss: RobustLoss,
    pub iterations: usize,
    /// Bounds of the robust scale `σ` (px).
    pub sigma_min_px: f64,
    pub sigma_max_px: f64,
    /// Ridge on the deformation, relative to the data's own scale.
    pub deformation_ridge: f64,
    /// Ridge on the perspective term, relative.
    pub perspective_ridge: f64,
}

/// The fit's result: the motion `x ↦ x + t + A p − (g·p) p`, `p = x − centre` (to first
/// order; applied exactly as a homography by [`Placement::moved`](crate::tracker::Placement::moved)).
#[derive(Debug, Clone, Copy)]
pub(crate) struct FitResult {
    pub t: Vector2<f64>,
    pub a: Matrix2<f64>,
    pub g: Vector2<f64>,
}

/// One straight side: its points are `first..first + count`, all with outward normal
/// `normal` and the same `np = normal·p`.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct FitSide {
    pub first: usize,
    pub count: usize,
    pub normal: Vector2<f64>,
    pub np: f64,
}

/// Point geometry of one pass: positions relative to the centre, grouped by side (the
/// candidates are in the [`FitBuffers`](super::FitBuffers)).
pub(crate) struct FitPoints<'a> {
    pub px: &'a [f64],
    pub py: &'a [f64],
    pub sides: &'a [FitSide],
}

/// Parameters `θ = (t.x, t.y, a11, a12, a21, a22, g.x, g.y)`.
pub(super) type Vec8 = SVector<f64, 8>;
pub(super) type Mat8 = SMatrix<f64, 8, 8>;

/// The working arrays are padded to a multiple of this many points (the widest loop).
pub(super) const LANES: usize = 8;
