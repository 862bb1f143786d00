//! The least-squares fit of Appendix A, made robust: translation (A.1), then deformation
//! (A.2 or A.3, optionally with perspective), inside an iteratively reweighted loop that also
//! re-chooses, for every point, which of its candidate edges the current fit explains best.
//!
//! Speed: all points of one polygon side share its normal `n` and the value `c = n·p` (the
//! side is straight), so each point's row of the least-squares system is affine in its
//! position `p`. The normal equations therefore follow from nine weighted moments per side
//! (`Σw, Σw p, Σw p pᵀ, Σw h, Σw h p`) instead of an outer product per point, and the
//! predicted offset along a side is `α + β·p`: a few flops per point and iteration.

use crate::cpu::has_avx2;
use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

use super::search::{Candidate, MAX_CANDIDATES};
use super::simd::F32x4;

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
/// order; applied exactly as a homography by [`Placement::moved`](super::Placement::moved)).
#[derive(Debug, Clone, Copy)]
pub(crate) struct FitResult {
    pub t: Vector2<f64>,
    pub a: Matrix2<f64>,
    pub g: Vector2<f64>,
}

/// Per-point data the fit writes, and its working copies; all sized at construction.
///
/// The working copies are f32, one array per quantity so the loops run four or eight points
/// at a time ([`F32x4`], or AVX where the processor has it), padded to whole groups of
/// [`LANES`] with points that have no candidate. The
/// tracker fills them as it searches ([`set_point`](Self::set_point),
/// [`set_candidates`](Self::set_candidates)); nothing is copied between search and fit.
#[derive(Debug, Clone, Default)]
pub(crate) struct FitBuffers {
    /// Chosen candidate index per point, -1 for none (after [`finish`](Self::finish)).
    pub chosen: Vec<i8>,
    /// Residual of the chosen candidate after the fit, px (0 for none).
    pub residual: Vec<f64>,
    /// Final robust weight (0 for none).
    pub weight: Vec<f64>,
    /// Points, and lanes (points rounded up to a multiple of 4).
    n: usize,
    lanes: usize,
    // Position relative to the centre, normal and c = n·p of the point's side.
    x: Vec<f32>,
    y: Vec<f32>,
    nx: Vec<f32>,
    ny: Vec<f32>,
    c: Vec<f32>,
    /// Candidates' offsets and penalties, slot-major (slot k of point i at `k * lanes + i`, so
    /// four neighbouring points of one slot load together); +∞ penalty for an empty slot.
    cand_h: Vec<f32>,
    cand_pen: Vec<f32>,
    /// Per iteration: the chosen offset, its residual, whether there was one (a lane mask),
    /// and the robust weight.
    h: Vec<f32>,
    r: Vec<f32>,
    valid: Vec<f32>,
    w: Vec<f32>,
    /// The chosen candidate per lane (-1: none), from the final association.
    chosen_lane: Vec<f32>,
    /// The last fit's motion, robust scale and loss, for [`finish`](Self::finish).
    last: Option<(Vec8, f64, RobustLoss)>,
    /// The residual histogram, kept here: clearing all of it per fit would cost more than
    /// the counting.
    bins: ResidualBins,
    /// The processor has AVX2: the association runs eight points at a time.
    avx2: bool,
}

impl FitBuffers {
    pub fn with_capacity(n: usize) -> Self {
        let lanes = n.div_ceil(LANES) * LANES;
        Self {
            chosen: Vec::with_capacity(n),
            residual: Vec::with_capacity(n),
            weight: Vec::with_capacity(n),
            n: 0,
            lanes: 0,
            x: Vec::with_capacity(lanes),
            y: Vec::with_capacity(lanes),
            nx: Vec::with_capacity(lanes),
            ny: Vec::with_capacity(lanes),
            c: Vec::with_capacity(lanes),
            cand_h: Vec::with_capacity(lanes * MAX_CANDIDATES),
            cand_pen: Vec::with_capacity(lanes * MAX_CANDIDATES),
            h: Vec::with_capacity(lanes),
            r: Vec::with_capacity(lanes),
            valid: Vec::with_capacity(lanes),
            w: Vec::with_capacity(lanes),
            chosen_lane: Vec::with_capacity(lanes),
            last: None,
            bins: ResidualBins::default(),
            avx2: has_avx2(),
        }
    }

    /// Sets the number of points to `n` (no allocation within capacity). The padding lanes
    /// get no candidate; the points' own data is left for the caller to set.
    pub fn resize(&mut self, n: usize) {
        let lanes = n.div_ceil(LANES) * LANES;
        self.chosen.resize(n, -1);
        self.residual.resize(n, 0.0);
        self.weight.resize(n, 0.0);
        for v in [&mut self.x, &mut self.y, &mut self.nx, &mut self.ny, &mut self.c, &mut self.h, &mut self.r, &mut self.valid, &mut self.w, &mut self.chosen_lane] {
            v.resize(lanes, 0.0);
        }
        self.cand_h.resize(lanes * MAX_CANDIDATES, 0.0);
        self.cand_pen.resize(lanes * MAX_CANDIDATES, f32::INFINITY);
        (self.n, self.lanes) = (n, lanes);
        for i in n..lanes {
            self.set_point(i, 0.0, 0.0, 0.0, 0.0, 0.0);
            self.set_candidates(i, &[]);
        }
        self.last = None;
    }

    /// Points the buffers hold now.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Asserts the layout the four-lane loops rely on to read without bounds checks: every
    /// working array holds `lanes` values (per candidate slot), a multiple of 4.
    #[inline]
    fn check_lanes(&self) {
        let l = self.lanes;
        assert!(
            l.is_multiple_of(LANES)
                && [&self.x, &self.y, &self.nx, &self.ny, &self.c, &self.h, &self.r, &self.valid, &self.w, &self.chosen_lane]
                    .iter()
                    .all(|v| v.len() == l)
                && self.cand_h.len() == l * MAX_CANDIDATES
                && self.cand_pen.len() == l * MAX_CANDIDATES,
            "fit buffers out of shape"
        );
    }

    /// Point `i`'s position relative to the fit's centre, its side's normal and `c = n·p`.
    #[inline]
    pub fn set_point(&mut self, i: usize, x: f32, y: f32, nx: f32, ny: f32, c: f32) {
        self.x[i] = x;
        self.y[i] = y;
        self.nx[i] = nx;
        self.ny[i] = ny;
        self.c[i] = c;
    }

    /// The points `first..first + x.len()` of one side: positions relative to the fit's
    /// centre, and the side's normal and `c = n·p` as `(n.x, n.y, c)`.
    pub fn set_side(&mut self, first: usize, x: &[f64], y: &[f64], (nx, ny, c): (f32, f32, f32)) {
        let range = first..first + x.len();
        for (d, s) in self.x[range.clone()].iter_mut().zip(x) {
            *d = *s as f32;
        }
        for (d, s) in self.y[range.clone()].iter_mut().zip(y) {
            *d = *s as f32;
        }
        self.nx[range.clone()].fill(nx);
        self.ny[range.clone()].fill(ny);
        self.c[range].fill(c);
    }

    /// Where the search writes the candidates directly: offsets and penalties, slot-major.
    pub fn candidate_slots(&mut self) -> super::batch::FitSlots<'_> {
        super::batch::FitSlots { h: &mut self.cand_h, penalty: &mut self.cand_pen, stride: self.lanes }
    }

    /// Point `i`'s candidate edges (at most [`MAX_CANDIDATES`]): offsets and penalties.
    #[inline]
    pub fn set_candidates(&mut self, i: usize, candidates: &[Candidate]) {
        let lanes = self.lanes;
        for k in 0..MAX_CANDIDATES {
            let (h, pen) = match candidates.get(k) {
                Some(c) => (c.h_px, c.penalty_px),
                None => (0.0, f32::INFINITY),
            };
            self.cand_h[k * lanes + i] = h;
            self.cand_pen[k * lanes + i] = pen;
        }
    }

    /// Fills the working copies from a pass's points (the tracker sets them as it searches
    /// instead).
    #[cfg(test)]
    fn load(&mut self, points: &FitPoints<'_>, edges: &[super::search::PointEdges]) {
        self.resize(points.px.len());
        for side in points.sides {
            for i in side.first..side.first + side.count {
                let (nx, ny, c) = (side.normal.x as f32, side.normal.y as f32, side.np as f32);
                self.set_point(i, points.px[i] as f32, points.py[i] as f32, nx, ny, c);
            }
        }
        for (i, e) in edges.iter().enumerate() {
            self.set_candidates(i, e.as_slice());
        }
    }

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
/// candidates are in the [`FitBuffers`]).
pub(crate) struct FitPoints<'a> {
    pub px: &'a [f64],
    pub py: &'a [f64],
    pub sides: &'a [FitSide],
}

/// Parameters `θ = (t.x, t.y, a11, a12, a21, a22, g.x, g.y)`.
type Vec8 = SVector<f64, 8>;
type Mat8 = SMatrix<f64, 8, 8>;

/// Positions of a side's coefficient vector `u = (n.x, n.y, −c)` in `θ` for the `p.x` and the
/// `p.y` part of a point's row `J = J0 + p.x·Jx + p.y·Jy`.
const IX: [usize; 3] = [2, 4, 6];
const IY: [usize; 3] = [3, 5, 7];

/// Weighted moments of one side's points.
#[derive(Debug, Clone, Copy, Default)]
struct Moments {
    w: f64,
    x: f64,
    y: f64,
    xx: f64,
    xy: f64,
    yy: f64,
    h: f64,
    hx: f64,
    hy: f64,
}

// Candidate indices are masked with MAX_CANDIDATES - 1 in the hot loop.
const _: () = assert!(MAX_CANDIDATES.is_power_of_two());

/// Residual histogram bins: 1/16 px wide up to 16 px, for the median absolute residual.
const HIST_BINS: usize = 256;
const HIST_PER_PX: f64 = 16.0;

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

/// Gives every point the candidate closest to the motion's prediction (distance plus the
/// candidate's penalty; the first of equals) and records its offset, residual and whether it
/// had one; with `BIN`, bins the absolute residuals of those that did. Returns their number.
/// Four points at a time, branch-free over the candidate slots.
#[inline]
fn associate<const BIN: bool, const CHOSEN: bool>(theta: &Vec8, buf: &mut FitBuffers) -> usize {
    #[cfg(target_arch = "x86_64")]
    if buf.avx2 {
        // SAFETY: the processor has AVX2 (checked when the buffers were made).
        return unsafe { associate_avx2::<BIN, CHOSEN>(theta, buf) };
    }
    let th: [F32x4; 8] = std::array::from_fn(|k| F32x4::splat(theta[k] as f32));
    let lanes = buf.lanes;
    buf.check_lanes();
    let (x, y, nx, ny, c) = (buf.x.as_ptr(), buf.y.as_ptr(), buf.nx.as_ptr(), buf.ny.as_ptr(), buf.c.as_ptr());
    let (cand_h, cand_pen) = (buf.cand_h.as_ptr(), buf.cand_pen.as_ptr());
    let (h, r_out, valid_out) = (buf.h.as_mut_ptr(), buf.r.as_mut_ptr(), buf.valid.as_mut_ptr());
    let chosen_out = buf.chosen_lane.as_mut_ptr();
    let inf = F32x4::splat(f32::INFINITY);
    let scale = F32x4::splat(HIST_PER_PX as f32);
    let top = F32x4::splat(buf.bins.top as f32);
    let bins = &mut buf.bins.counts;
    let mut found = 0usize;
    for i in (0..lanes).step_by(4) {
        // SAFETY: i + 4 <= lanes and every array holds `lanes` values per slot (checked
        // above), so every access below is in bounds.
        unsafe {
            let (px, py) = (F32x4::load_ptr(x.add(i)), F32x4::load_ptr(y.add(i)));
            // n·(t + A p) − c (g·p), in the order of `associate_scalar`.
            let along_x = th[0].add(th[2].mul(px)).add(th[3].mul(py));
            let along_y = th[1].add(th[4].mul(px)).add(th[5].mul(py));
            let perspective = th[6].mul(px).add(th[7].mul(py));
            let pred = F32x4::load_ptr(nx.add(i))
                .mul(along_x)
                .add(F32x4::load_ptr(ny.add(i)).mul(along_y))
                .sub(F32x4::load_ptr(c.add(i)).mul(perspective));
            let (mut best, mut best_h, mut best_k) = (inf, F32x4::splat(0.0), F32x4::splat(-1.0));
            for k in 0..MAX_CANDIDATES {
                let hk = F32x4::load_ptr(cand_h.add(k * lanes + i));
                let cost = hk.sub(pred).abs().add(F32x4::load_ptr(cand_pen.add(k * lanes + i)));
                let better = cost.lt(best);
                best = better.select(cost, best);
                best_h = better.select(hk, best_h);
                if CHOSEN {
                    best_k = better.select(F32x4::splat(k as f32), best_k);
                }
            }
            if CHOSEN {
                best_k.store_ptr(chosen_out.add(i));
            }
            let valid = best.lt(inf);
            let r = best_h.sub(pred);
            best_h.store_ptr(h.add(i));
            r.store_ptr(r_out.add(i));
            valid.store_ptr(valid_out.add(i));
            let bits = valid.mask_bits();
            found += bits.count_ones() as usize;
            if BIN {
                // Bin |r| · 16, the top bin taking everything beyond (and a NaN residual,
                // which only a non-finite motion makes, and the tracker declares that lost).
                let scaled = r.abs().mul(scale);
                let lane_bins = scaled.lt(top).select(scaled, top).to_i32_array();
                for (l, bin) in lane_bins.iter().enumerate() {
                    bins[*bin as usize][l] += ((bits >> l) & 1) as u16;
                }
            }
        }
    }
    found
}

/// [`associate`] eight points at a time with AVX (the same f32 operations per lane, so the
/// same results).
///
/// # Safety
/// The processor supports AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn associate_avx2<const BIN: bool, const CHOSEN: bool>(theta: &Vec8, buf: &mut FitBuffers) -> usize {
    use std::arch::x86_64::*;
    let lanes = buf.lanes;
    buf.check_lanes();
    let (x, y, nx, ny, c) = (buf.x.as_ptr(), buf.y.as_ptr(), buf.nx.as_ptr(), buf.ny.as_ptr(), buf.c.as_ptr());
    let (cand_h, cand_pen) = (buf.cand_h.as_ptr(), buf.cand_pen.as_ptr());
    let (h, r_out, valid_out) = (buf.h.as_mut_ptr(), buf.r.as_mut_ptr(), buf.valid.as_mut_ptr());
    let chosen_out = buf.chosen_lane.as_mut_ptr();
    let top_bin = buf.bins.top;
    let bins = &mut buf.bins.counts;
    let th: [__m256; 8] = std::array::from_fn(|k| _mm256_set1_ps(theta[k] as f32));
    let inf = _mm256_set1_ps(f32::INFINITY);
    let sign_bit = _mm256_set1_ps(-0.0);
    let scale = _mm256_set1_ps(HIST_PER_PX as f32);
    let top = _mm256_set1_ps(top_bin as f32);
    let mut found = 0usize;
    for i in (0..lanes).step_by(8) {
        // SAFETY: i + 8 <= lanes (lanes is a multiple of 8) and every array holds `lanes`
        // values per slot (checked above).
        unsafe {
            let (px, py) = (_mm256_loadu_ps(x.add(i)), _mm256_loadu_ps(y.add(i)));
            let along_x = _mm256_add_ps(_mm256_add_ps(th[0], _mm256_mul_ps(th[2], px)), _mm256_mul_ps(th[3], py));
            let along_y = _mm256_add_ps(_mm256_add_ps(th[1], _mm256_mul_ps(th[4], px)), _mm256_mul_ps(th[5], py));
            let perspective = _mm256_add_ps(_mm256_mul_ps(th[6], px), _mm256_mul_ps(th[7], py));
            let pred = _mm256_sub_ps(
                _mm256_add_ps(
                    _mm256_mul_ps(_mm256_loadu_ps(nx.add(i)), along_x),
                    _mm256_mul_ps(_mm256_loadu_ps(ny.add(i)), along_y),
                ),
                _mm256_mul_ps(_mm256_loadu_ps(c.add(i)), perspective),
            );
            let (mut best, mut best_h, mut best_k) = (inf, _mm256_setzero_ps(), _mm256_set1_ps(-1.0));
            for k in 0..MAX_CANDIDATES {
                let hk = _mm256_loadu_ps(cand_h.add(k * lanes + i));
                let distance = _mm256_andnot_ps(sign_bit, _mm256_sub_ps(hk, pred));
                let cost = _mm256_add_ps(distance, _mm256_loadu_ps(cand_pen.add(k * lanes + i)));
                let better = _mm256_cmp_ps::<_CMP_LT_OQ>(cost, best);
                best = _mm256_blendv_ps(best, cost, better);
                best_h = _mm256_blendv_ps(best_h, hk, better);
                if CHOSEN {
                    best_k = _mm256_blendv_ps(best_k, _mm256_set1_ps(k as f32), better);
                }
            }
            if CHOSEN {
                _mm256_storeu_ps(chosen_out.add(i), best_k);
            }
            let valid = _mm256_cmp_ps::<_CMP_LT_OQ>(best, inf);
            let r = _mm256_sub_ps(best_h, pred);
            _mm256_storeu_ps(h.add(i), best_h);
            _mm256_storeu_ps(r_out.add(i), r);
            _mm256_storeu_ps(valid_out.add(i), valid);
            let bits = _mm256_movemask_ps(valid) as u32;
            found += bits.count_ones() as usize;
            if BIN {
                let scaled = _mm256_mul_ps(_mm256_andnot_ps(sign_bit, r), scale);
                let capped = _mm256_blendv_ps(top, scaled, _mm256_cmp_ps::<_CMP_LT_OQ>(scaled, top));
                let mut lane_bins = [0i32; 8];
                _mm256_storeu_si256(lane_bins.as_mut_ptr() as *mut __m256i, _mm256_cvttps_epi32(capped));
                for (l, bin) in lane_bins.iter().enumerate() {
                    bins[*bin as usize][l] += ((bits >> l) & 1) as u16;
                }
            }
        }
    }
    found
}

/// [`associate`] one point at a time, also recording the chosen candidate's index: the
/// reference the vector paths are tested against.
#[cfg(test)]
fn associate_scalar(theta: &Vec8, buf: &mut FitBuffers) {
    let th: [f32; 8] = std::array::from_fn(|k| theta[k] as f32);
    let lanes = buf.lanes;
    for i in 0..buf.n {
        let (px, py) = (buf.x[i], buf.y[i]);
        let pred = buf.nx[i] * (th[0] + th[2] * px + th[3] * py) + buf.ny[i] * (th[1] + th[4] * px + th[5] * py)
            - buf.c[i] * (th[6] * px + th[7] * py);
        let (mut best, mut best_h, mut best_k) = (f32::INFINITY, 0.0f32, -1i8);
        for k in 0..MAX_CANDIDATES {
            let hk = buf.cand_h[k * lanes + i];
            let cost = (hk - pred).abs() + buf.cand_pen[k * lanes + i];
            if cost < best {
                (best, best_h, best_k) = (cost, hk, k as i8);
            }
        }
        buf.h[i] = best_h;
        buf.r[i] = best_h - pred;
        buf.valid[i] = f32::from_bits(if best_k >= 0 { u32::MAX } else { 0 });
        buf.chosen[i] = best_k;
    }
}

/// Robust weights of every point (0 without a candidate) into `buf.w`.
#[inline]
fn weigh(loss: RobustLoss, sigma: f64, buf: &mut FitBuffers) {
    buf.check_lanes();
    let (r, valid, w) = (buf.r.as_ptr(), buf.valid.as_ptr(), buf.w.as_mut_ptr());
    let one = F32x4::splat(1.0);
    let (inv_tukey, k_huber) = (F32x4::splat((1.0 / (4.685 * sigma)) as f32), F32x4::splat((1.345 * sigma) as f32));
    for i in (0..buf.lanes).step_by(4) {
        // SAFETY: i + 4 <= lanes, the length of all three arrays (checked above).
        unsafe {
            let r = F32x4::load_ptr(r.add(i));
            let weight = match loss {
                RobustLoss::Tukey => {
                    let u = r.mul(inv_tukey);
                    let t = one.sub(u.mul(u)).max(F32x4::splat(0.0));
                    t.mul(t)
                }
                RobustLoss::Huber => {
                    let a = r.abs();
                    a.le(k_huber).select(one, k_huber.div(a))
                }
                RobustLoss::LeastSquares => one,
            };
            weight.and(F32x4::load_ptr(valid.add(i))).store_ptr(w.add(i));
        }
    }
}

/// Moments of one side's weighted points, summed four lanes at a time.
#[inline]
fn side_moments(side: &FitSide, buf: &FitBuffers) -> Moments {
    let (first, end) = (side.first, side.first + side.count);
    let full = first + side.count / 4 * 4;
    let zero = F32x4::splat(0.0);
    let mut acc = [zero; 9];
    buf.check_lanes();
    assert!(end <= buf.lanes, "side beyond the points");
    let (x, y, h, w) = (buf.x.as_ptr(), buf.y.as_ptr(), buf.h.as_ptr(), buf.w.as_ptr());
    for j in (first..full).step_by(4) {
        // SAFETY: j + 4 <= full <= end <= lanes, the arrays' length (checked above).
        let (xi, yi, hi, wi) =
            unsafe { (F32x4::load_ptr(x.add(j)), F32x4::load_ptr(y.add(j)), F32x4::load_ptr(h.add(j)), F32x4::load_ptr(w.add(j))) };
        let (wx, wy, wh) = (wi.mul(xi), wi.mul(yi), wi.mul(hi));
        let add = [wi, wx, wy, wx.mul(xi), wx.mul(yi), wy.mul(yi), wh, wh.mul(xi), wh.mul(yi)];
        for (a, v) in acc.iter_mut().zip(add) {
            *a = a.add(v);
        }
    }
    let mut sum = [0.0f64; 9];
    for (s, a) in sum.iter_mut().zip(&acc) {
        *s = a.to_array().iter().map(|v| *v as f64).sum();
    }
    for j in full..end {
        let (xi, yi, hi, wi) = (buf.x[j] as f64, buf.y[j] as f64, buf.h[j] as f64, buf.w[j] as f64);
        let (wx, wy, wh) = (wi * xi, wi * yi, wi * hi);
        let add = [wi, wx, wy, wx * xi, wx * yi, wy * yi, wh, wh * xi, wh * yi];
        for (s, a) in sum.iter_mut().zip(add) {
            *s += a;
        }
    }
    Moments { w: sum[0], x: sum[1], y: sum[2], xx: sum[3], xy: sum[4], yy: sum[5], h: sum[6], hx: sum[7], hy: sum[8] }
}

fn result(theta: &Vec8) -> FitResult {
    FitResult {
        t: Vector2::new(theta[0], theta[1]),
        a: Matrix2::new(theta[2], theta[3], theta[4], theta[5]),
        g: Vector2::new(theta[6], theta[7]),
    }
}

/// The working arrays are padded to a multiple of this many points (the widest loop).
const LANES: usize = 8;

/// 1.4826 · MAD estimates the standard deviation of normally distributed residuals.
const MAD_TO_SIGMA: f64 = 1.4826;

/// The histogram of absolute residuals behind the robust scale: 1/16 px bins, `top` taking
/// everything from there on. One count per lane of [`associate`], so that the lanes'
/// increments (often of the same bin) do not wait on each other.
#[derive(Debug, Clone)]
struct ResidualBins {
    counts: [[u16; LANES]; HIST_BINS],
    top: usize,
}

impl Default for ResidualBins {
    fn default() -> Self {
        Self { counts: [[0; LANES]; HIST_BINS], top: HIST_BINS - 1 }
    }
}

impl ResidualBins {
    /// Empties the bins up to `top` and makes that the last one.
    fn clear(&mut self, top: usize) {
        self.top = top.min(HIST_BINS - 1);
        self.counts[..=self.top].fill([0; LANES]);
    }

    /// Median of the `count` binned values (bin centre), px.
    fn median(&self, count: usize) -> f64 {
        let half = count.div_ceil(2);
        let mut seen = 0usize;
        for (bin, c) in self.counts[..=self.top].iter().enumerate() {
            seen += c.iter().map(|v| *v as usize).sum::<usize>();
            if seen >= half {
                return (bin as f64 + 0.5) / HIST_PER_PX;
            }
        }
        HIST_BINS as f64 / HIST_PER_PX
    }
}

/// Adds one side's share to the normal equations `M θ = b`. A point's row is
/// `J = J0 + p.x Jx + p.y Jy` with `J0 = (n, 0…)` and `u = (n.x, n.y, −c)` at `IX` / `IY`.
#[inline]
fn accumulate_side(m: &mut Mat8, b: &mut Vec8, side: &FitSide, mo: &Moments) {
    let n = [side.normal.x, side.normal.y];
    let u = [side.normal.x, side.normal.y, -side.np];
    for i in 0..2 {
        for j in 0..2 {
            m[(i, j)] += mo.w * n[i] * n[j];
        }
        for k in 0..3 {
            let vx = mo.x * n[i] * u[k];
            let vy = mo.y * n[i] * u[k];
            m[(i, IX[k])] += vx;
            m[(IX[k], i)] += vx;
            m[(i, IY[k])] += vy;
            m[(IY[k], i)] += vy;
        }
        b[i] += mo.h * n[i];
    }
    for k in 0..3 {
        for l in 0..3 {
            let uu = u[k] * u[l];
            m[(IX[k], IX[l])] += mo.xx * uu;
            m[(IY[k], IY[l])] += mo.yy * uu;
            m[(IX[k], IY[l])] += mo.xy * uu;
            m[(IY[l], IX[k])] += mo.xy * uu;
        }
        b[IX[k]] += mo.hx * u[k];
        b[IY[k]] += mo.hy * u[k];
    }
}

/// A.1: `M_tt t = b_t − M_ts s` with the shape `s` of `theta` held.
///
/// The small solves here are written out rather than left to nalgebra's general routines
/// (views, copies and loops sized at run time cost more than the arithmetic); the order of
/// operations is nalgebra's, so the results are the same.
fn solve_translation(m: &Mat8, b: &Vec8, theta: &Vec8, wsum: f64) -> Vector2<f64> {
    // rhs = b_t − M_ts s, the product column by column.
    let rhs: [f64; 2] = std::array::from_fn(|i| {
        let mut p = m[(i, 2)] * theta[2];
        for j in 3..8 {
            p += m[(i, j)] * theta[j];
        }
        b[i] - p
    });
    // A tiny ridge keeps the motion along a lone straight side (unobservable) at zero.
    let (m11, m12, m21, m22) = (m[(0, 0)] + 1e-6 * wsum, m[(0, 1)], m[(1, 0)], m[(1, 1)] + 1e-6 * wsum);
    let det = m11 * m22 - m21 * m12;
    if det == 0.0 {
        return Vector2::new(theta[0], theta[1]);
    }
    let inv = [[m22 / det, -m12 / det], [-m21 / det, m11 / det]];
    Vector2::new(inv[0][0] * rhs[0] + inv[0][1] * rhs[1], inv[1][0] * rhs[0] + inv[1][1] * rhs[1])
}

/// Solves `a x = rhs` for a symmetric positive definite `a` (only its lower triangle is read)
/// by Cholesky factorisation in place; `rhs` becomes `x`. False, with `rhs` left part-way,
/// when `a` is not positive definite.
// Two indices into one matrix read more plainly than iterator chains here.
#[allow(clippy::needless_range_loop)]
fn cholesky_solve<const K: usize>(a: &mut [[f64; K]; K], rhs: &mut [f64; K]) -> bool {
    for j in 0..K {
        for k in 0..j {
            let f = a[j][k];
            for i in j..K {
                a[i][j] += -f * a[i][k];
            }
        }
        let d = a[j][j];
        if d <= 0.0 || d.is_nan() {
            return false;
        }
        let d = d.sqrt();
        a[j][j] = d;
        for i in j + 1..K {
            a[i][j] /= d;
        }
    }
    // L y = rhs, then Lᵀ x = y.
    for i in 0..K {
        let y = rhs[i] / a[i][i];
        rhs[i] = y;
        for r in i + 1..K {
            rhs[r] += -y * a[r][i];
        }
    }
    for i in (0..K).rev() {
        let mut dot = 0.0;
        for r in i + 1..K {
            dot += a[r][i] * rhs[r];
        }
        rhs[i] = (rhs[i] - dot) / a[i][i];
    }
    true
}

/// Translation with A.2 (`K = 6`) or with A.2 and perspective (`K = 8`) solved together:
/// the fixed point the two stages converge to, reached in one step once the association has
/// settled; same ridges and prior as the staged solve.
fn solve_joint<const K: usize>(m: &Mat8, b: &Vec8, theta: &mut Vec8, wsum: f64, ridge_a: f64, ridge_g: f64) {
    let mut mk: [[f64; K]; K] = std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)]));
    let mut rhs: [f64; K] = std::array::from_fn(|i| b[i]);
    for (k, row) in mk.iter_mut().enumerate() {
        row[k] += match k {
            0 | 1 => 1e-6 * wsum,
            2..=5 => ridge_a,
            _ => ridge_g,
        };
    }
    if cholesky_solve(&mut mk, &mut rhs) {
        for (k, v) in rhs.iter().enumerate() {
            theta[k] = *v;
        }
    }
}

/// A.2 (`K = 4`: `A`) or A.2 with perspective (`K = 6`: `A, g`) given the translation in
/// `theta`, ridge-regularised towards no change of shape.
fn solve_shape<const K: usize>(m: &Mat8, b: &Vec8, theta: &mut Vec8, ridge_a: f64, ridge_g: f64) {
    let mut mss: [[f64; K]; K] = std::array::from_fn(|i| std::array::from_fn(|j| m[(2 + i, 2 + j)]));
    // rhs = b_s − M_st t, the product column by column.
    let mut rhs: [f64; K] = std::array::from_fn(|i| b[2 + i] - (m[(2 + i, 0)] * theta[0] + m[(2 + i, 1)] * theta[1]));
    for (k, row) in mss.iter_mut().enumerate() {
        row[k] += if k < 4 { ridge_a } else { ridge_g };
    }
    if cholesky_solve(&mut mss, &mut rhs) {
        for (k, v) in rhs.iter().enumerate() {
            theta[2 + k] = *v;
        }
    }
}

/// A.3: `(h_i − n_i·t) n_i = A p_i`: each row of `A` is a 2-parameter fit with the normal
/// matrix `Σ w p pᵀ`.
fn solve_full_vector(
    points: &FitPoints<'_>,
    buf: &FitBuffers,
    mut pp: Matrix2<f64>,
    h_rhs: Matrix2<f64>,
    t: &Vector2<f64>,
    ridge: f64,
) -> Matrix2<f64> {
    // The n·t part of the right-hand side, per side: (n·t) n (Σ w p)ᵀ.
    let mut t_rhs = Matrix2::zeros();
    for side in points.sides {
        let nt = side.normal.dot(t);
        let mut sp = Vector2::zeros();
        for i in side.first..side.first + side.count {
            sp += Vector2::new(points.px[i], points.py[i]) * buf.w[i] as f64;
        }
        t_rhs += side.normal * sp.transpose() * nt;
    }
    pp[(0, 0)] += ridge;
    pp[(1, 1)] += ridge;
    match pp.try_inverse() {
        // Row k of A solves pp a_k = Σ w (h − n·t) n_k p, i.e. A = R pp⁻¹ (pp symmetric).
        Some(inv) => (h_rhs - t_rhs) * inv,
        None => Matrix2::zeros(),
    }
}

#[cfg(test)]
mod tests {
    use super::super::search::{Candidate, PointEdges};
    use super::*;

    /// Points around a 100x60 rectangle centred on the origin, grouped by side.
    fn rectangle() -> (Vec<f64>, Vec<f64>, Vec<FitSide>) {
        let (mut px, mut py, mut sides) = (vec![], vec![], vec![]);
        let corners: [(f64, f64); 4] = [(-50.0, -30.0), (50.0, -30.0), (50.0, 30.0), (-50.0, 30.0)];
        for j in 0..4 {
            let (a, b) = (corners[j], corners[(j + 1) % 4]);
            let d = (b.0 - a.0, b.1 - a.1);
            let len = f64::hypot(d.0, d.1);
            // (d.y, −d.x) points away from the centre for this corner order.
            let normal = Vector2::new(d.1 / len, -d.0 / len);
            let first = px.len();
            for k in 0..25 {
                let f = (k as f64 + 0.5) / 25.0;
                px.push(a.0 + f * d.0);
                py.push(a.1 + f * d.1);
            }
            let np = normal.x * px[first] + normal.y * py[first];
            sides.push(FitSide { first, count: 25, normal, np });
        }
        assert!(sides.iter().all(|s| s.np > 0.0), "normals must point outward");
        (px, py, sides)
    }

    /// A whole fit as the tracker runs it: candidates in, fit, per-point results out.
    fn run_fit(pts: &FitPoints<'_>, edges: &[PointEdges], settings: &FitSettings, buf: &mut FitBuffers) -> FitResult {
        buf.load(pts, edges);
        let fit = fit_motion(pts, settings, buf);
        buf.finish();
        fit
    }

    fn settings(model: DeformationModel, loss: RobustLoss) -> FitSettings {
        FitSettings {
            model,
            loss,
            iterations: 10,
            sigma_min_px: 0.3,
            sigma_max_px: 3.0,
            deformation_ridge: 1e-6,
            perspective_ridge: 1e-6,
        }
    }

    fn normal_of(sides: &[FitSide], i: usize) -> Vector2<f64> {
        sides.iter().find(|s| (s.first..s.first + s.count).contains(&i)).unwrap().normal
    }

    /// One exact candidate per point for the motion `(t, A, g)`.
    fn exact_edges(px: &[f64], py: &[f64], sides: &[FitSide], t: Vector2<f64>, a: Matrix2<f64>, g: Vector2<f64>) -> Vec<PointEdges> {
        (0..px.len())
            .map(|i| {
                let p = Vector2::new(px[i], py[i]);
                let d = t + a * p - p * g.dot(&p);
                let mut e = PointEdges::default();
                e.candidates[0] = Candidate { h_px: normal_of(sides, i).dot(&d) as f32, contrast: 50.0, ..Default::default() };
                e.count = 1;
                e
            })
            .collect()
    }

    #[test]
    fn recovers_an_exact_motion_with_the_normal_only_and_projective_models() {
        let (px, py, sides) = rectangle();
        let t = Vector2::new(1.5, -2.0);
        let a = Matrix2::new(0.02, -0.03, 0.025, -0.01);
        let mut buf = FitBuffers::with_capacity(px.len());
        let edges = exact_edges(&px, &py, &sides, t, a, Vector2::zeros());
        let pts = FitPoints { px: &px, py: &py, sides: &sides };
        let fit = run_fit(&pts, &edges, &settings(DeformationModel::NormalOnly, RobustLoss::Tukey), &mut buf);
        assert!((fit.t - t).norm() < 1e-3, "{:?}", fit.t);
        assert!((fit.a - a).norm() < 1e-4, "{:?}", fit.a);
        // Perspective too (first-order model: exact for exact first-order data).
        let g = Vector2::new(4e-4, -3e-4);
        let edges = exact_edges(&px, &py, &sides, t, a, g);
        let pts = FitPoints { px: &px, py: &py, sides: &sides };
        // On this symmetric rectangle translation and perspective are strongly coupled, so the
        // alternating stages need many iterations to converge (a tracker gets them over frames).
        let many = FitSettings { iterations: 400, ..settings(DeformationModel::Projective, RobustLoss::Tukey) };
        let fit = run_fit(&pts, &edges, &many, &mut buf);
        assert!((fit.t - t).norm() < 1e-3 && (fit.a - a).norm() < 1e-4, "{:?} {:?}", fit.t, fit.a);
        assert!((fit.g - g).norm() < 1e-6, "{:?}", fit.g);
    }

    #[test]
    fn full_vector_model_is_exact_for_translation_and_sluggish_for_rotation() {
        let (px, py, sides) = rectangle();
        let s = settings(DeformationModel::FullVector, RobustLoss::LeastSquares);
        let mut buf = FitBuffers::with_capacity(px.len());
        let edges = exact_edges(&px, &py, &sides, Vector2::new(3.0, 1.0), Matrix2::zeros(), Vector2::zeros());
        let fit = run_fit(&FitPoints { px: &px, py: &py, sides: &sides }, &edges, &s, &mut buf);
        assert!((fit.t - Vector2::new(3.0, 1.0)).norm() < 1e-4);
        assert!(fit.a.norm() < 1e-6);
        // A scaling and a rotation are recovered only in part: A.3 takes each normal offset
        // for the whole displacement and so misses the part along the side (aperture problem).
        let scale = Matrix2::new(0.02, 0.0, 0.0, 0.02);
        let edges = exact_edges(&px, &py, &sides, Vector2::zeros(), scale, Vector2::zeros());
        let fit = run_fit(&FitPoints { px: &px, py: &py, sides: &sides }, &edges, &s, &mut buf);
        assert!(fit.a[(0, 0)] > 0.005 && fit.a[(0, 0)] < 0.019, "{:?}", fit.a);
        let rot = Matrix2::new(0.0, -0.02, 0.02, 0.0);
        let edges = exact_edges(&px, &py, &sides, Vector2::zeros(), rot, Vector2::zeros());
        let fit = run_fit(&FitPoints { px: &px, py: &py, sides: &sides }, &edges, &s, &mut buf);
        let got = fit.a[(1, 0)] - fit.a[(0, 1)];
        assert!(got > 0.0 && got < 0.04 * 0.9, "rotation part {got}");
    }

    #[test]
    fn robust_fit_ignores_outliers_and_picks_the_consistent_candidate() {
        let (px, py, sides) = rectangle();
        let t = Vector2::new(2.0, 1.0);
        let edges: Vec<PointEdges> = (0..px.len())
            .map(|i| {
                let h = normal_of(&sides, i).dot(&t);
                let mut e = PointEdges::default();
                // One point in five sees only a wild outlier; every third point also sees a
                // stronger clutter edge 3-6 px away, on either side.
                let clutter = [3.0, -4.5, 6.0, -3.5, 5.0][i % 5];
                let cand = |h: f64, contrast: f32| Candidate { h_px: h as f32, contrast, ..Default::default() };
                if i % 5 == 2 {
                    e.candidates[0] = cand(h + 7.0 * if i % 10 == 2 { 1.0 } else { -1.0 }, 80.0);
                    e.count = 1;
                } else if i % 3 == 0 {
                    e.candidates[0] = cand(h + clutter, 90.0);
                    e.candidates[1] = cand(h, 50.0);
                    e.count = 2;
                } else {
                    e.candidates[0] = cand(h, 50.0);
                    e.count = 1;
                }
                e
            })
            .collect();
        let pts = FitPoints { px: &px, py: &py, sides: &sides };
        let mut buf = FitBuffers::with_capacity(px.len());
        let fit = run_fit(&pts, &edges, &settings(DeformationModel::NormalOnly, RobustLoss::Tukey), &mut buf);
        assert!((fit.t - t).norm() < 0.05 && fit.a.norm() < 1e-3, "{:?} {:?}", fit.t, fit.a);
        let wrong_choice = (0..px.len()).filter(|i| i % 5 != 2 && buf.chosen[*i] != (i % 3 == 0) as i8).count();
        assert_eq!(wrong_choice, 0);
        let outliers_weighted = (0..px.len()).filter(|i| i % 5 == 2 && buf.weight[*i] > 0.0).count();
        assert_eq!(outliers_weighted, 0);
        // Plain least squares is dragged off by the same data.
        let ls = run_fit(&pts, &edges, &settings(DeformationModel::NormalOnly, RobustLoss::LeastSquares), &mut buf);
        assert!((ls.t - t).norm() > 0.1 || ls.a.norm() > 1e-2, "{:?} {:?}", ls.t, ls.a);
    }

    #[test]
    fn appearance_penalty_steers_the_choice_between_equally_near_candidates() {
        let mut e = PointEdges::default();
        e.candidates[0] = Candidate { h_px: -1.0, contrast: 60.0, penalty_px: 3.0, ..Default::default() };
        e.candidates[1] = Candidate { h_px: 1.2, contrast: 40.0, penalty_px: 0.0, ..Default::default() };
        e.count = 2;
        let side = FitSide { first: 0, count: 1, normal: Vector2::new(1.0, 0.0), np: 10.0 };
        let mut buf = FitBuffers::with_capacity(1);
        buf.resize(1);
        let mut edges = vec![e];
        let run = |edges: &[PointEdges], buf: &mut FitBuffers| {
            let pts = FitPoints { px: &[10.0], py: &[0.0], sides: &[side] };
            buf.load(&pts, edges);
            // The four-lane association and the final one agree.
            let found = associate::<true, false>(&Vec8::zeros(), buf);
            let (h, r) = (buf.h[0], buf.r[0]);
            associate_scalar(&Vec8::zeros(), buf);
            assert_eq!((h, r), (buf.h[0], buf.r[0]));
            found
        };
        assert_eq!(run(&edges, &mut buf), 1);
        assert_eq!((buf.chosen[0], buf.r[0]), (1, 1.2));
        edges[0].candidates[0].penalty_px = 0.0;
        run(&edges, &mut buf);
        assert_eq!((buf.chosen[0], buf.r[0]), (0, -1.0));
    }

    #[test]
    fn every_association_path_gives_the_same_choices_residuals_and_histogram() {
        // Random points and candidates (some slots empty, some tied), a random motion: the
        // four-lane, the eight-lane (where the processor has it) and the one-at-a-time
        // association must agree bit for bit.
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        let n = 61;
        let (px, py): (Vec<f64>, Vec<f64>) = (0..n).map(|_| (next() * 200.0 - 100.0, next() * 120.0 - 60.0)).unzip();
        let sides = [
            FitSide { first: 0, count: 30, normal: Vector2::new(0.6, 0.8), np: 12.0 },
            FitSide { first: 30, count: 31, normal: Vector2::new(-1.0, 0.0), np: -40.0 },
        ];
        let edges: Vec<PointEdges> = (0..n)
            .map(|_| {
                let mut e = PointEdges { count: (next() * 5.0) as u8, ..Default::default() };
                for c in &mut e.candidates[..e.count as usize] {
                    c.h_px = ((next() * 20.0 - 10.0) * 4.0).round() as f32 / 4.0;
                    c.penalty_px = if next() < 0.3 { (next() * 3.0) as f32 } else { 0.0 };
                }
                e
            })
            .collect();
        let theta = Vec8::from_fn(|k, _| [1.3, -0.7, 0.02, -0.01, 0.015, 0.03, 2e-4, -1e-4][k]);
        let pts = FitPoints { px: &px, py: &py, sides: &sides };
        let run = |avx2: bool| {
            let mut buf = FitBuffers::with_capacity(n);
            buf.avx2 = avx2 && buf.avx2;
            buf.load(&pts, &edges);
            buf.bins.clear(40);
            let found = associate::<true, false>(&theta, &mut buf);
            (found, buf.h.clone(), buf.r.clone(), buf.valid.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), buf)
        };
        let (found4, h4, r4, valid4, mut buf4) = run(false);
        let (found8, h8, r8, valid8, buf8) = run(true);
        assert_eq!((found4, &h4, &r4, &valid4), (found8, &h8, &r8, &valid8));
        let total = |b: &FitBuffers| -> Vec<usize> { b.bins.counts[..=40].iter().map(|c| c.iter().map(|v| *v as usize).sum()).collect() };
        assert_eq!(total(&buf4), total(&buf8));
        assert!(found4 > 30 && found4 < n, "the data must mix points with and without candidates");
        associate_scalar(&theta, &mut buf4);
        assert_eq!((&buf4.h, &buf4.r), (&h4, &r4));
        assert_eq!(buf4.valid.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), valid4);
        // The final association's choices too, on both vector paths.
        let scalar_chosen = buf4.chosen.clone();
        for avx2 in [false, true] {
            let mut buf = FitBuffers::with_capacity(n);
            buf.avx2 = avx2 && buf.avx2;
            buf.load(&pts, &edges);
            associate::<false, true>(&theta, &mut buf);
            let chosen: Vec<i8> = buf.chosen_lane[..n].iter().map(|k| *k as i8).collect();
            assert_eq!(chosen, scalar_chosen, "avx2 {avx2}");
            assert_eq!((&buf.h, &buf.r), (&h4, &r4));
        }
        assert!(scalar_chosen.iter().any(|k| *k > 0) && scalar_chosen.contains(&-1));
    }
}
