//! The least-squares fit of Appendix A, made robust: translation (A.1), then deformation
//! (A.2 or A.3, optionally with perspective), inside an iteratively reweighted loop that also
//! re-chooses, for every point, which of its candidate edges the current fit explains best.
//!
//! Speed: all points of one polygon side share its normal `n` and the value `c = n·p` (the
//! side is straight), so each point's row of the least-squares system is affine in its
//! position `p`. The normal equations therefore follow from nine weighted moments per side
//! (`Σw, Σw p, Σw p pᵀ, Σw h, Σw h p`) instead of an outer product per point, and the
//! predicted offset along a side is `α + β·p`: a few flops per point and iteration.

use nalgebra::{Matrix2, SMatrix, SVector, Vector2};

use super::search::{PointEdges, MAX_CANDIDATES};

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
#[derive(Debug, Clone, Default)]
pub(crate) struct FitBuffers {
    /// Chosen candidate index per point, -1 for none.
    pub chosen: Vec<i8>,
    /// Residual of the chosen candidate after the fit, px (0 for none).
    pub residual: Vec<f64>,
    /// Final robust weight (0 for none).
    pub weight: Vec<f64>,
    // Working copies in f32, one array per quantity so the loops vectorise: position,
    // normal and c = n·p of each point's side, the candidates' offsets and penalties
    // (+∞ for an empty slot), and per iteration the chosen offset, residual and weight.
    x: Vec<f32>,
    y: Vec<f32>,
    nx: Vec<f32>,
    ny: Vec<f32>,
    c: Vec<f32>,
    /// Slot-major: slot k of point i at `k * n + i`, so four neighbouring points of one slot
    /// load together.
    cand_h: Vec<f32>,
    cand_pen: Vec<f32>,
    h: Vec<f32>,
    r: Vec<f32>,
    w: Vec<f32>,
}

impl FitBuffers {
    pub fn with_capacity(n: usize) -> Self {
        Self {
            chosen: Vec::with_capacity(n),
            residual: Vec::with_capacity(n),
            weight: Vec::with_capacity(n),
            x: Vec::with_capacity(n),
            y: Vec::with_capacity(n),
            nx: Vec::with_capacity(n),
            ny: Vec::with_capacity(n),
            c: Vec::with_capacity(n),
            cand_h: Vec::with_capacity(n * MAX_CANDIDATES),
            cand_pen: Vec::with_capacity(n * MAX_CANDIDATES),
            h: Vec::with_capacity(n),
            r: Vec::with_capacity(n),
            w: Vec::with_capacity(n),
        }
    }

    /// Sets the length to `n` (no allocation within capacity).
    pub fn resize(&mut self, n: usize) {
        self.chosen.resize(n, -1);
        self.residual.resize(n, 0.0);
        self.weight.resize(n, 0.0);
        for v in [&mut self.x, &mut self.y, &mut self.nx, &mut self.ny, &mut self.c, &mut self.h, &mut self.r, &mut self.w] {
            v.resize(n, 0.0);
        }
        self.cand_h.resize(n * MAX_CANDIDATES, 0.0);
        self.cand_pen.resize(n * MAX_CANDIDATES, f32::INFINITY);
    }

    /// Fills the working copies from the pass's points.
    fn prepare(&mut self, points: &FitPoints<'_>) {
        self.resize(points.px.len());
        for side in points.sides {
            for i in side.first..side.first + side.count {
                self.nx[i] = side.normal.x as f32;
                self.ny[i] = side.normal.y as f32;
                self.c[i] = side.np as f32;
            }
        }
        let n = points.px.len();
        for (i, e) in points.edges.iter().enumerate() {
            self.x[i] = points.px[i] as f32;
            self.y[i] = points.py[i] as f32;
            for k in 0..MAX_CANDIDATES {
                let (h, pen) = match e.as_slice().get(k) {
                    Some(cand) => (cand.h_px, cand.penalty_px),
                    None => (0.0, f32::INFINITY),
                };
                self.cand_h[k * n + i] = h;
                self.cand_pen[k * n + i] = pen;
            }
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

/// Point geometry of one pass: positions relative to the centre, grouped by side.
pub(crate) struct FitPoints<'a> {
    pub px: &'a [f64],
    pub py: &'a [f64],
    pub sides: &'a [FitSide],
    pub edges: &'a [PointEdges],
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
    let n = points.px.len();
    buf.prepare(points);
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
    for iter in 0..iterations {
        // 1. Association and residuals under the current motion, with their histogram.
        let mut hist = [0u16; HIST_BINS];
        let found = associate(&theta, buf, Some(&mut hist));
        if found == 0 {
            buf.weight.iter_mut().for_each(|w| *w = 0.0);
            return result(&theta);
        }
        // 2. Robust scale 1.4826·MAD within bounds; the first iteration starts at the top so
        // that points far from the prediction still get a say.
        let median = histogram_median(&hist, found);
        let mad_sigma = 1.4826 * median;
        sigma = if iter == 0 { mad_sigma.max(sigma_max) } else { mad_sigma };
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
    // Final association, residuals and weights against the final motion (for confidence).
    associate(&theta, buf, None);
    weigh(settings.loss, sigma, buf);
    for i in 0..n {
        buf.residual[i] = buf.r[i] as f64;
        buf.weight[i] = buf.w[i] as f64;
    }
    result(&theta)
}

/// Gives every point the candidate closest to the motion's prediction (distance plus the
/// candidate's penalty) and records its offset, residual and index; counts the points with a
/// candidate and, if asked, bins their absolute residuals. Branch-free over the candidate
/// slots, so the loop vectorises.
#[inline]
fn associate(theta: &Vec8, buf: &mut FitBuffers, hist: Option<&mut [u16; HIST_BINS]>) -> usize {
    let th: [f32; 8] = std::array::from_fn(|k| theta[k] as f32);
    let n = buf.x.len();
    let (x, y, nx, ny, c) = (&buf.x[..n], &buf.y[..n], &buf.nx[..n], &buf.ny[..n], &buf.c[..n]);
    let (cand_h, cand_pen) = (&buf.cand_h[..n * MAX_CANDIDATES], &buf.cand_pen[..n * MAX_CANDIDATES]);
    let (h, r, chosen) = (&mut buf.h[..n], &mut buf.r[..n], &mut buf.chosen[..n]);
    for i in 0..n {
        // n·(t + A p) − c (g·p): the normal offset the motion predicts at the point.
        let (px, py) = (x[i], y[i]);
        let pred = nx[i] * (th[0] + th[2] * px + th[3] * py) + ny[i] * (th[1] + th[4] * px + th[5] * py)
            - c[i] * (th[6] * px + th[7] * py);
        let (mut best, mut best_h, mut best_k) = (f32::INFINITY, 0.0f32, -1i8);
        for k in 0..MAX_CANDIDATES {
            let hk = cand_h[k * n + i];
            let cost = (hk - pred).abs() + cand_pen[k * n + i];
            if cost < best {
                (best, best_h, best_k) = (cost, hk, k as i8);
            }
        }
        h[i] = best_h;
        r[i] = best_h - pred;
        chosen[i] = best_k;
    }
    let mut found = 0usize;
    match hist {
        Some(hist) => {
            for (&ri, &k) in r.iter().zip(chosen.iter()) {
                let valid = (k >= 0) as u16;
                hist[((ri.abs() * HIST_PER_PX as f32) as usize).min(HIST_BINS - 1)] += valid;
                found += valid as usize;
            }
        }
        None => found = chosen.iter().filter(|k| **k >= 0).count(),
    }
    found
}

/// Robust weights of every point (0 without a candidate) into `buf.w`.
#[inline]
fn weigh(loss: RobustLoss, sigma: f64, buf: &mut FitBuffers) {
    let n = buf.x.len();
    let (r, chosen, w) = (&buf.r[..n], &buf.chosen[..n], &mut buf.w[..n]);
    match loss {
        RobustLoss::Tukey => {
            let inv = (1.0 / (4.685 * sigma)) as f32;
            for ((w, &r), &k) in w.iter_mut().zip(r).zip(chosen) {
                let u = r * inv;
                let t = (1.0 - u * u).max(0.0);
                *w = if k >= 0 { t * t } else { 0.0 };
            }
        }
        RobustLoss::Huber => {
            let k_px = (1.345 * sigma) as f32;
            for ((w, &r), &k) in w.iter_mut().zip(r).zip(chosen) {
                let a = r.abs();
                *w = if k < 0 { 0.0 } else if a <= k_px { 1.0 } else { k_px / a };
            }
        }
        RobustLoss::LeastSquares => {
            for (w, &k) in w.iter_mut().zip(chosen) {
                *w = if k >= 0 { 1.0 } else { 0.0 };
            }
        }
    }
}

/// Moments of one side's weighted points, summed four lanes at a time.
#[inline]
fn side_moments(side: &FitSide, buf: &FitBuffers) -> Moments {
    let range = side.first..side.first + side.count;
    let (x, y, h, w) = (&buf.x[range.clone()], &buf.y[range.clone()], &buf.h[range.clone()], &buf.w[range]);
    const L: usize = 4;
    let mut acc = [[0.0f32; L]; 9];
    let full = x.len() / L * L;
    for j in (0..full).step_by(L) {
        for l in 0..L {
            let (xi, yi, hi, wi) = (x[j + l], y[j + l], h[j + l], w[j + l]);
            let (wx, wy, wh) = (wi * xi, wi * yi, wi * hi);
            acc[0][l] += wi;
            acc[1][l] += wx;
            acc[2][l] += wy;
            acc[3][l] += wx * xi;
            acc[4][l] += wx * yi;
            acc[5][l] += wy * yi;
            acc[6][l] += wh;
            acc[7][l] += wh * xi;
            acc[8][l] += wh * yi;
        }
    }
    let mut sum = [0.0f64; 9];
    for (s, a) in sum.iter_mut().zip(&acc) {
        *s = a.iter().map(|v| *v as f64).sum();
    }
    for j in full..x.len() {
        let (xi, yi, hi, wi) = (x[j] as f64, y[j] as f64, h[j] as f64, w[j] as f64);
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

/// Median of the values binned in `hist` (bin centre), `count` values in all.
fn histogram_median(hist: &[u16; HIST_BINS], count: usize) -> f64 {
    let half = count.div_ceil(2);
    let mut seen = 0usize;
    for (bin, &c) in hist.iter().enumerate() {
        seen += c as usize;
        if seen >= half {
            return (bin as f64 + 0.5) / HIST_PER_PX;
        }
    }
    HIST_BINS as f64 / HIST_PER_PX
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
fn solve_translation(m: &Mat8, b: &Vec8, theta: &Vec8, wsum: f64) -> Vector2<f64> {
    let mut mtt = m.fixed_view::<2, 2>(0, 0).into_owned();
    let rhs = b.fixed_rows::<2>(0) - m.fixed_view::<2, 6>(0, 2) * theta.fixed_rows::<6>(2);
    // A tiny ridge keeps the motion along a lone straight side (unobservable) at zero.
    mtt[(0, 0)] += 1e-6 * wsum;
    mtt[(1, 1)] += 1e-6 * wsum;
    mtt.try_inverse().map(|inv| inv * rhs).unwrap_or_else(|| Vector2::new(theta[0], theta[1]))
}

/// Translation with A.2 (`K = 6`) or with A.2 and perspective (`K = 8`) solved together:
/// the fixed point the two stages converge to, reached in one step once the association has
/// settled; same ridges and prior as the staged solve.
fn solve_joint<const K: usize>(m: &Mat8, b: &Vec8, theta: &mut Vec8, wsum: f64, ridge_a: f64, ridge_g: f64) {
    let mut mk = m.fixed_view::<K, K>(0, 0).into_owned();
    let rhs = b.fixed_rows::<K>(0).into_owned();
    for k in 0..K {
        mk[(k, k)] += match k {
            0 | 1 => 1e-6 * wsum,
            2..=5 => ridge_a,
            _ => ridge_g,
        };
    }
    if let Some(ch) = mk.cholesky() {
        theta.fixed_rows_mut::<K>(0).copy_from(&ch.solve(&rhs));
    }
}

/// A.2 (`K = 4`: `A`) or A.2 with perspective (`K = 6`: `A, g`) given the translation in
/// `theta`, ridge-regularised towards no change of shape.
fn solve_shape<const K: usize>(m: &Mat8, b: &Vec8, theta: &mut Vec8, ridge_a: f64, ridge_g: f64) {
    let mut mss = m.fixed_view::<K, K>(2, 2).into_owned();
    let rhs = b.fixed_rows::<K>(2) - m.fixed_view::<K, 2>(2, 0) * theta.fixed_rows::<2>(0);
    for k in 0..K {
        mss[(k, k)] += if k < 4 { ridge_a } else { ridge_g };
    }
    if let Some(ch) = mss.cholesky() {
        theta.fixed_rows_mut::<K>(2).copy_from(&ch.solve(&rhs));
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
    use super::super::search::Candidate;
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
        let pts = FitPoints { px: &px, py: &py, sides: &sides, edges: &edges };
        let fit = fit_motion(&pts, &settings(DeformationModel::NormalOnly, RobustLoss::Tukey), &mut buf);
        assert!((fit.t - t).norm() < 1e-3, "{:?}", fit.t);
        assert!((fit.a - a).norm() < 1e-4, "{:?}", fit.a);
        // Perspective too (first-order model: exact for exact first-order data).
        let g = Vector2::new(4e-4, -3e-4);
        let edges = exact_edges(&px, &py, &sides, t, a, g);
        let pts = FitPoints { px: &px, py: &py, sides: &sides, edges: &edges };
        // On this symmetric rectangle translation and perspective are strongly coupled, so the
        // alternating stages need many iterations to converge (a tracker gets them over frames).
        let many = FitSettings { iterations: 400, ..settings(DeformationModel::Projective, RobustLoss::Tukey) };
        let fit = fit_motion(&pts, &many, &mut buf);
        assert!((fit.t - t).norm() < 1e-3 && (fit.a - a).norm() < 1e-4, "{:?} {:?}", fit.t, fit.a);
        assert!((fit.g - g).norm() < 1e-6, "{:?}", fit.g);
    }

    #[test]
    fn full_vector_model_is_exact_for_translation_and_sluggish_for_rotation() {
        let (px, py, sides) = rectangle();
        let s = settings(DeformationModel::FullVector, RobustLoss::LeastSquares);
        let mut buf = FitBuffers::with_capacity(px.len());
        let edges = exact_edges(&px, &py, &sides, Vector2::new(3.0, 1.0), Matrix2::zeros(), Vector2::zeros());
        let fit = fit_motion(&FitPoints { px: &px, py: &py, sides: &sides, edges: &edges }, &s, &mut buf);
        assert!((fit.t - Vector2::new(3.0, 1.0)).norm() < 1e-4);
        assert!(fit.a.norm() < 1e-6);
        // A scaling and a rotation are recovered only in part: A.3 takes each normal offset
        // for the whole displacement and so misses the part along the side (aperture problem).
        let scale = Matrix2::new(0.02, 0.0, 0.0, 0.02);
        let edges = exact_edges(&px, &py, &sides, Vector2::zeros(), scale, Vector2::zeros());
        let fit = fit_motion(&FitPoints { px: &px, py: &py, sides: &sides, edges: &edges }, &s, &mut buf);
        assert!(fit.a[(0, 0)] > 0.005 && fit.a[(0, 0)] < 0.019, "{:?}", fit.a);
        let rot = Matrix2::new(0.0, -0.02, 0.02, 0.0);
        let edges = exact_edges(&px, &py, &sides, Vector2::zeros(), rot, Vector2::zeros());
        let fit = fit_motion(&FitPoints { px: &px, py: &py, sides: &sides, edges: &edges }, &s, &mut buf);
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
        let pts = FitPoints { px: &px, py: &py, sides: &sides, edges: &edges };
        let mut buf = FitBuffers::with_capacity(px.len());
        let fit = fit_motion(&pts, &settings(DeformationModel::NormalOnly, RobustLoss::Tukey), &mut buf);
        assert!((fit.t - t).norm() < 0.05 && fit.a.norm() < 1e-3, "{:?} {:?}", fit.t, fit.a);
        let wrong_choice = (0..px.len()).filter(|i| i % 5 != 2 && buf.chosen[*i] != (i % 3 == 0) as i8).count();
        assert_eq!(wrong_choice, 0);
        let outliers_weighted = (0..px.len()).filter(|i| i % 5 == 2 && buf.weight[*i] > 0.0).count();
        assert_eq!(outliers_weighted, 0);
        // Plain least squares is dragged off by the same data.
        let ls = fit_motion(&pts, &settings(DeformationModel::NormalOnly, RobustLoss::LeastSquares), &mut buf);
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
            let pts = FitPoints { px: &[10.0], py: &[0.0], sides: &[side], edges };
            buf.prepare(&pts);
            associate(&Vec8::zeros(), buf, None)
        };
        assert_eq!(run(&edges, &mut buf), 1);
        assert_eq!((buf.chosen[0], buf.r[0]), (1, 1.2));
        edges[0].candidates[0].penalty_px = 0.0;
        run(&edges, &mut buf);
        assert_eq!((buf.chosen[0], buf.r[0]), (0, -1.0));
    }
}
