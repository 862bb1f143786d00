//! The least-squares fit of Appendix A, made robust: translation (A.1), then deformation
//! (A.2 or A.3, optionally with perspective), inside an iteratively reweighted loop that also
//! re-chooses, for every point, which of its candidate edges the current fit explains best.
//!
//! Speed: all points of one polygon side share its normal `n` and the value `c = n·p` (the
//! side is straight), so each point's row of the least-squares system is affine in its
//! position `p`. The normal equations therefore follow from nine weighted moments per side
//! (`Σw, Σw p, Σw p pᵀ, Σw h, Σw h p`) instead of an outer product per point, and the
//! predicted offset along a side is `α + β·p`: a few flops per point and iteration.
//!
//! By concern:
//! - this module: the reweighting loop that drives the rest ([`fit_motion`]) and the final
//!   association and weights ([`FitBuffers::finish`]);
//! - [`types`]: the models, settings and result, the points, the parameter vector;
//! - [`buffers`]: the per-point working arrays the search fills and the fit reads;
//! - [`histogram`]: the residual histogram behind the robust scale;
//! - [`associate`]: every point's choice of candidate under the current motion (four or
//!   eight points at a time);
//! - [`robust`]: the robust scale from the residual histogram, and the weights;
//! - [`normal_equations`]: the weighted moments of a side and its share of `M θ = b`;
//! - [`solve`]: the small solves of A.1, A.2 (with perspective) and A.3.

mod associate;
mod buffers;
mod histogram;
mod normal_equations;
mod robust;
mod solve;
mod types;

#[cfg(test)]
mod tests;

use nalgebra::{Matrix2, Vector2};

use super::search::MAX_CANDIDATES;
use associate::associate;

pub(crate) use buffers::FitBuffers;
use histogram::{HIST_BINS, HIST_PER_PX};
use normal_equations::{accumulate_side, side_moments};
use robust::{weigh, MAD_TO_SIGMA};
use solve::{solve_full_vector, solve_joint, solve_shape, solve_translation};
pub use types::{DeformationModel, RobustLoss};
pub(crate) use types::{FitPoints, FitResult, FitSettings, FitSide};
use types::{Mat8, Vec8};

// Candidate indices are masked with MAX_CANDIDATES - 1 in the hot loop.
const _: () = assert!(MAX_CANDIDATES.is_power_of_two());

/// Fits translation then shape to the candidate edges by iteratively reweighted least
/// squares. Each iteration every point takes the candidate closest to the current fit's
/// prediction (distance plus the candidate's appearance penalty), so a nearer texture edge
/// cannot hold a point once the others agree elsewhere; the robust scale is re-estimated from
/// the median absolute residual and the weights follow.
pub(crate) fn fit_motion(points: &FitPoints<'_>, settings: &FitSettings, buf: &mut FitBuffers) -> FitResult {
    #[cfg(target_arch = "x86_64")]
    if buf.avx2 {
        // SAFETY: the processor has AVX2 (checked when the buffers were made).
        return unsafe { fit_motion_avx2(points, settings, buf) };
    }
    fit_motion_body(points, settings, buf)
}

/// [`fit_motion`] compiled for AVX2: the same operations (no FMA contraction), with the
/// shorter VEX forms and wider loads around the association. Same results bit for bit.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fit_motion_avx2(points: &FitPoints<'_>, settings: &FitSettings, buf: &mut FitBuffers) -> FitResult {
    fit_motion_body(points, settings, buf)
}

#[inline(always)]
fn fit_motion_body(points: &FitPoints<'_>, settings: &FitSettings, buf: &mut FitBuffers) -> FitResult {
    let n = points.px.len();
    debug_assert_eq!(n, buf.n, "the buffers hold this pass's points");
    buf.last = None;
    let mut theta = Vec8::zeros();
    // Scale of the template for the ridges: mean |p|².
    let mut p2 = 0.0;
    for i in 0..n {
        p2 += points.px[i] * points.px[i] + points.py[i] * points.py[i];
    }
    let p2 = (p2 / n.max(1) as f64).max(1.0);
    let sigma_max = settings.sigma_max_px.max(settings.sigma_min_px);
    let mut sigma = sigma_max;
    let iterations = settings.iterations.max(1);
    // Medians of 1.4826 · median > sigma_max all give sigma_max: the residual histogram
    // only needs its bins below that, the last one taking everything beyond.
    let mut top_bin = ((sigma_max / MAD_TO_SIGMA * HIST_PER_PX - 0.5).ceil().max(0.0) as usize).min(HIST_BINS - 1);
    while top_bin > 0 && MAD_TO_SIGMA * ((top_bin - 1) as f64 + 0.5) / HIST_PER_PX >= sigma_max {
        top_bin -= 1;
    }
    while top_bin < HIST_BINS - 1 && MAD_TO_SIGMA * (top_bin as f64 + 0.5) / HIST_PER_PX < sigma_max {
        top_bin += 1;
    }
    for iter in 0..iterations {
        // 1. Association and residuals under the current motion, with their histogram
        // (the first iteration uses the largest scale whatever the residuals).
        let found = if iter == 0 {
            associate::<false, false>(&theta, buf)
        } else {
            buf.bins.clear(top_bin);
            associate::<true, false>(&theta, buf)
        };
        if found == 0 {
            buf.last = Some((theta, sigma, settings.loss));
            return result(&theta);
        }
        // 2. Robust scale 1.4826·MAD within bounds; the first iteration starts at the top so
        // that points far from the prediction still get a say.
        sigma = if iter == 0 { sigma_max } else { MAD_TO_SIGMA * buf.bins.median(found) };
        sigma = sigma.clamp(settings.sigma_min_px, sigma_max);
        // 3. Weights and the moments of each side.
        let mut m = Mat8::zeros();
        let mut b = Vec8::zeros();
        let mut wsum = 0.0;
        let mut pp = Matrix2::zeros(); // Σ w p pᵀ, for A.3
        let mut a3_rhs = Matrix2::zeros(); // Σ w h n pᵀ, for A.3
        weigh(settings.loss, sigma, buf);
        for side in points.sides {
            let mo = side_moments(side, buf);
            if mo.w == 0.0 {
                continue;
            }
            wsum += mo.w;
            accumulate_side(&mut m, &mut b, side, &mo);
            if settings.model == DeformationModel::FullVector {
                let (nx, ny) = (side.normal.x, side.normal.y);
                pp += Matrix2::new(mo.xx, mo.xy, mo.xy, mo.yy);
                // Rows of A: Σ w (h − n·t) n_k p; the h part here, the n·t part once t is known.
                a3_rhs += Matrix2::new(nx * mo.hx, nx * mo.hy, ny * mo.hx, ny * mo.hy);
            }
        }
        if wsum == 0.0 {
            break;
        }
        // 4. The thesis's two stages: translation (A.1) with the current shape's share
        // removed, then the shape given that translation. Alternating them converges to the
        // joint least-squares solution, but the shape lags the translation while the points
        // are still choosing their edges, which the thesis found (and the real sequence
        // confirms) makes the tracker markedly more stable: one side cannot swing off to a
        // neighbouring edge within a single update. The last iteration, with the choices
        // settled, jumps to the joint solution instead of creeping towards it.
        let previous = theta;
        let (ridge_a, ridge_g) = (wsum * p2 * settings.deformation_ridge, wsum * p2 * p2 * settings.perspective_ridge);
        let last = iter + 1 == iterations;
        let t = solve_translation(&m, &b, &theta, wsum);
        theta[0] = t.x;
        theta[1] = t.y;
        match settings.model {
            DeformationModel::NormalOnly if last => {
                solve_joint::<6>(&m, &b, &mut theta, wsum, ridge_a, 0.0)
            }
            DeformationModel::Projective if last => {
                solve_joint::<8>(&m, &b, &mut theta, wsum, ridge_a, ridge_g)
            }
            DeformationModel::None => {}
            DeformationModel::NormalOnly => solve_shape::<4>(&m, &b, &mut theta, ridge_a, 0.0),
            DeformationModel::Projective => {
                solve_shape::<6>(&m, &b, &mut theta, ridge_a, ridge_g)
            }
            DeformationModel::FullVector => {
                let a = solve_full_vector(points, buf, pp, a3_rhs, &t, wsum * p2 * settings.deformation_ridge);
                theta[2] = a[(0, 0)];
                theta[3] = a[(0, 1)];
                theta[4] = a[(1, 0)];
                theta[5] = a[(1, 1)];
            }
        }
        let d = theta - previous;
        let change = d[0].hypot(d[1]) + d.rows(2, 4).norm() * p2.sqrt() + d.rows(6, 2).norm() * p2;
        if change < 1e-6 && iter > 0 {
            break;
        }
    }
    // The final association, residuals and weights (for the confidence) wait for
    // `FitBuffers::finish`: a pass that is followed by another does not need them.
    buf.last = Some((theta, sigma, settings.loss));
    result(&theta)
}

fn result(theta: &Vec8) -> FitResult {
    FitResult {
        t: Vector2::new(theta[0], theta[1]),
        a: Matrix2::new(theta[2], theta[3], theta[4], theta[5]),
        g: Vector2::new(theta[6], theta[7]),
    }
}

impl FitBuffers {
    /// The per-point results of the last fit: every point's chosen candidate, residual and
    /// weight against the final motion. Does nothing before a fit or when already done.
    pub fn finish(&mut self) {
        let Some((theta, sigma, loss)) = self.last.take() else {
            return;
        };
        associate::<false, true>(&theta, self);
        weigh(loss, sigma, self);
        for i in 0..self.n {
            self.chosen[i] = self.chosen_lane[i] as i8;
            self.residual[i] = self.r[i] as f64;
            self.weight[i] = self.w[i] as f64;
        }
    }
}
